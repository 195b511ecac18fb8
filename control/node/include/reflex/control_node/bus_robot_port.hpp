// A robot port on the bus: what reflex_controller and reflex_sim need of a robot over DDS, whichever
// interface it speaks. Implemented by DdsRobotPort (Reflex's own reflex/robot_state and
// reflex/joint_command) and UnitreeHgPort (Unitree's rt/lowstate and rt/arm_sdk).
//
// Rejection causes are numbered once for every port (robotStateCauseName in controller_node.hpp
// prints them): 0-7 as DdsRobotPort lists them, then the causes of robots' own interfaces.
#pragma once

#include "reflex/control/onboard.hpp"

#include <array>
#include <chrono>
#include <cstdint>
#include <cstring>

namespace reflex::bus {
class Outbox;
}

namespace reflex::control_node {

/// 0 lengths, 1 missing joint, 2 non-finite, 3 future stamp, 4 old stamp, 5 duplicate name, 6 outside
/// the limits, 7 another writer (DdsRobotPort); 8 bad crc, 9 motor count (a sample of another size),
/// 10 tick not advancing (UnitreeHgPort).
inline constexpr int kRobotStateCauses = 11;
inline constexpr int kRobotCauseOtherWriter = 7;
inline constexpr int kCauseBadCrc = 8;
inline constexpr int kCauseMotorCount = 9;
inline constexpr int kCauseOldTick = 10;

/// A port's rejection texts kept for its readers: the latest of each cause (every cause a cycle
/// rejected can be named, not only the last) and the latest that was not another writer's sample
/// (the heartbeat's). Fixed arrays: keeping one never allocates.
class RejectionTexts {
 public:
  static constexpr std::size_t kBytes = 300;
  /// After the port formatted `text` for a state it rejects with `cause`.
  void keep(int cause, const char (&text)[kBytes]) noexcept {
    std::memcpy(by_cause_[static_cast<std::size_t>(cause)].data(), text, kBytes);
    if (cause != kRobotCauseOtherWriter) last_bad_ = cause;
  }
  /// The latest rejection of `cause` (0 <= cause < kRobotStateCauses; "" none yet).
  const char* of(int cause) const noexcept { return by_cause_[static_cast<std::size_t>(cause)].data(); }
  /// The latest rejection that was not another writer's sample ("" none).
  const char* lastBad() const noexcept { return last_bad_ < 0 ? "" : of(last_bad_); }

 private:
  std::array<std::array<char, kBytes>, kRobotStateCauses> by_cause_{};
  int last_bad_ = -1;
};

class BusRobotPort : public control::RobotPort {
 public:
  using CauseCounts = std::array<std::uint64_t, kRobotStateCauses>;

  /// Takes every state that arrived since the last call (once per cycle, before step()); returns the
  /// number rejected by this call (lastRejection() names the last one, rejectionOf() the latest of
  /// each cause: a cycle that takes several bad states can name each kind). No allocation, no throw.
  virtual int poll() noexcept = 0;
  /// Hands the commands to `outbox`'s writer thread, if the port's type can go through it.
  virtual void sendThrough(bus::Outbox& outbox) = 0;
  /// After the last cycle: whatever the interface needs to leave the robot (UnitreeHgPort: the arm_sdk
  /// weight ramped out over its ramp time, `period` s per step). Blocks for that long at most.
  virtual void finish(double /*period*/) noexcept {}

  virtual const char* lastRejection() const = 0;
  /// The latest rejection of `cause` (0 <= cause < kRobotStateCauses; "" none yet).
  virtual const char* rejectionOf(int cause) const = 0;
  /// The latest rejection that was not another writer's sample ("" none).
  virtual const char* lastBadRejection() const = 0;
  virtual int lastCause() const = 0;
  virtual bool haveState() const = 0;
  /// The robot's counter of the newest accepted state (RobotState seq, LowState_ tick).
  virtual std::uint64_t stateSeq() const = 0;
  /// When the newest accepted state was measured (system clock, ns; 0 without one).
  virtual std::int64_t stateStampNs() const = 0;
  virtual const char* boundWriter() const = 0;
  virtual const char* otherWriter() const = 0;
  /// Blocks until a state sample is there (not yet taken) or `timeout` passes; true if one is
  /// (--trigger state). Allocation-free.
  virtual bool waitForState(std::chrono::nanoseconds timeout) noexcept = 0;
  /// The robot's state interval (s) between the two newest accepted states; 0 while unknown.
  virtual double stateInterval() const noexcept = 0;
  /// The state topic, for messages ("reflex/robot_state", "rt/lowstate").
  virtual const char* stateTopic() const = 0;

  virtual std::uint64_t acceptedStates() const = 0;
  virtual CauseCounts rejectedByCause() const = 0;
  virtual std::uint64_t writerChanges() const = 0;
  virtual std::uint64_t commandsSent() const = 0;
  std::uint64_t rejectedTotal() const {
    std::uint64_t n = 0;
    for (const std::uint64_t c : rejectedByCause()) n += c;
    return n;
  }
};

}  // namespace reflex::control_node
