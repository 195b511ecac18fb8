// The robot over DDS: reflex_controller --robot dds. A control::RobotPort that
// reads the robot's measured state from reflex/robot_state and answers each control cycle with one
// reflex/joint_command (idl/robot.idl; the contract for driver authors: idl/README.md "Writing a
// robot driver").
//
// State in: poll() takes every RobotState that arrived. A sample is REJECTED and counted (by cause,
// the last one named in lastRejection()) when its names, positions, velocities (and efforts, if not
// empty) differ in length; when it lacks a joint of the model (the controller computes every
// distance from every joint); when a name is listed twice (which value is true?); when a position or
// velocity of a model joint is not finite; when a position lies outside the joint's limits by more
// than stateLimitTolerance() (control/onboard.hpp: v_max * period, what one cycle at the velocity
// limit covers; an unlimited joint beyond +-kMaxUnlimitedPosition) — an absurd finite value included;
// when its Header.stamp_ns lies more than kFutureTolerance ahead of this host's system clock; or when
// it is not newer (stamp) than the state already held. The robot's joint names are mapped to the
// model's joint order once, and again only when the robot's name list changes.
//
// The checks are JointStateIntake's (joint_state_intake.hpp), shared with Ros2RobotPort.
//
// One robot writer: the port BINDS to the DataWriter of the first state it accepts (its GUID). A
// sample of any other writer is ignored and counted (cause 7, robot_state_other_writer; the newest
// such writer is named by otherWriter()), whatever it says, while the bound writer may still be alive
// (a sample from it within `rebind_silence`, 1 s: a driver stalled by its host for a few hundred ms
// is not replaced by whoever writes meanwhile; seen: a 166 ms stall under test load). A bound writer
// silent for longer (a driver that died and restarted gets a new GUID) is replaced by the next writer
// whose state is accepted, counted in writer_changes. Under DDS-Security (Options::identities set) only a writer authenticated as the
// identity "robot" is ever bound. Plain DDS authenticates nobody: the binding guards against a second
// driver or a stray replay, not against a writer that starts before the robot (see idl/README.md).
//
// Staleness: measuredPositions() returns nullptr (the controller computes nothing and commands
// nothing) when no state was accepted yet or the newest is older than `timeout` (its stamp against
// this host's system clock). The robot then holds by itself once the last command's deadline passed.
//
// Command out: one JointCommand per computed cycle for the joints the controller drives (the arm
// joints, then the walking joints), positions = q_end (measured + qdot dt, or the walking position),
// velocities over the cycle, valid_until_ns = now + deadline, state_seq / state_stamp_ns of the state
// it answers. Header.seq is the command counter (bus::Writer stamps it).
#pragma once

#include "reflex/control/model.hpp"
#include "reflex/control/onboard.hpp"
#include "reflex/control_node/bus_robot_port.hpp"
#include "reflex/control_node/joint_state_intake.hpp"
#include <reflex/bus/outbox.hpp>

#include <reflex/bus/bus.hpp>
#include <reflex/bus/identity.hpp>

#include <array>
#include <chrono>
#include <cstdint>
#include <string>
#include <vector>

namespace reflex::control_node {

class DdsRobotPort final : public NamedJointPort {
 public:
  static constexpr double kFutureTolerance = JointStateIntake::kFutureTolerance;

  struct Options {
    double timeout =
        0.050;  ///< s: a newest state older than this is stale (--robot-timeout; NodeConfig says why 50 ms)
    double deadline = 0.015;      ///< s: valid_until_ns = now + this (--command-deadline)
    double period = 0.005;        ///< s: the control period (the limit tolerance is v_max * period)
    double rebind_silence = 1.0;  ///< s the bound robot writer must be silent before another may replace it
    /// Under DDS-Security: the identities of the bus (the port binds only a writer authenticated as
    /// "robot"); nullptr on plain DDS (the first writer is bound).
    const bus::WriterIdentities* identities = nullptr;
  };

  /// The state counts (JointStateIntake's) and the commands sent.
  struct Counts : JointStateIntake::Counts {
    std::uint64_t commands = 0;  ///< JointCommand samples published (with sendThrough: queued)
  };

  /// Makes the reader and the writer on `bus` (throws bus::BusError naming the entity). `driven`: the
  /// q indices the controller commands (OnboardController::drivenJoints()).
  DdsRobotPort(const control::Model& model, const std::vector<int>& driven, bus::Participant& bus,
               const Options& options);

  /// Takes every state that arrived since the last call (once per cycle, before step()). Returns the
  /// number of samples rejected by this call; lastRejection() names the last one.
  int poll() noexcept override;
  void command(const Eigen::VectorXd& q_end, const Eigen::VectorXd& qdot, double dt) noexcept override;
  /// From now on command() queues each JointCommand (stamped at once: its time and sequence number
  /// are the cycle's) for `outbox`'s writer thread instead of writing it on the control thread
  /// (reflex/bus/outbox.hpp: a DDS write can block for a second). Call before outbox.start().
  void sendThrough(bus::Outbox& outbox) override;

  Counts counts() const {
    Counts c;
    static_cast<JointStateIntake::Counts&>(c) = intake_.counts();
    c.commands = commands_;
    return c;
  }
  /// The causes of a rejection (lastCause()): 0 lengths, 1 missing joint, 2 non-finite, 3 future stamp,
  /// 4 old, 5 duplicate name, 6 outside the limits, 7 another writer. The state's accessors
  /// (stateSeq: Header.seq; stateStampNs: Header.stamp_ns; stateInterval; boundWriter / otherWriter as
  /// "01.0f.…|0.0.3.3") are NamedJointPort's.
  static constexpr int kCauses = 8;
  static constexpr int kCauseOtherWriter = JointStateIntake::kCauseOtherWriter;
  /// Age (s) of the newest accepted state now, +inf without one.
  double stateAge() const noexcept { return intake_.stateAge(); }
  /// Blocks until a robot state (any sample on reflex/robot_state, not yet taken) is there or `timeout`
  /// passes; true if one is. Allocation-free; for --trigger state, between cycles.
  bool waitForState(std::chrono::nanoseconds timeout) noexcept override;
  const char* stateTopic() const override { return "reflex/robot_state"; }
  std::uint64_t commandsSent() const override { return commands_; }

 private:
  Options options_;
  bus::Reader<msg::RobotState>* reader_ = nullptr;
  bus::Writer<msg::JointCommand>* writer_ = nullptr;
  bus::OutboxQueue<msg::JointCommand>* queue_ = nullptr;  ///< set by sendThrough
  bus::Outbox* outbox_ = nullptr;
  msg::RobotState sample_;
  msg::JointCommand cmd_;
  std::vector<int> driven_;
  std::uint64_t commands_ = 0;
};

}  // namespace reflex::control_node
