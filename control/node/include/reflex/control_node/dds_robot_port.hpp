// The robot over DDS (issue 13, item 2): reflex_controller --robot dds. A control::RobotPort that
// reads the robot's measured state from reflex/robot_state and answers each control cycle with one
// reflex/joint_command (idl/robot.idl; the contract for driver authors: idl/README.md "Writing a
// robot driver").
//
// State in: poll() takes every RobotState that arrived. A sample is REJECTED and counted (by cause,
// the last one named in lastRejection()) when its names, positions, velocities (and efforts, if not
// empty) differ in length; when it lacks a joint of the model (the controller computes every
// distance from every joint); when a position or velocity of a model joint is not finite; when its
// Header.stamp_ns lies more than kFutureTolerance ahead of this host's system clock; or when it is
// not newer (stamp) than the state already held. The robot's joint names are mapped to the model's
// joint order once, and again only when the robot's name list changes.
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
#include <reflex/bus/outbox.hpp>

#include <reflex/bus/bus.hpp>

#include <cstdint>
#include <string>
#include <vector>

namespace reflex::control_node {

class DdsRobotPort final : public control::RobotPort {
 public:
  static constexpr double kFutureTolerance = 0.002;  ///< s a state's stamp may lie ahead of this host's clock

  struct Options {
    double timeout = 0.050;   ///< s: a newest state older than this is stale (--robot-timeout; NodeConfig says why 50 ms)
    double deadline = 0.015;  ///< s: valid_until_ns = now + this (--command-deadline)
  };

  struct Counts {
    std::uint64_t accepted = 0;
    std::uint64_t rejected_length = 0;       ///< names / positions / velocities / efforts lengths differ
    std::uint64_t rejected_missing = 0;      ///< a model joint is not in the state
    std::uint64_t rejected_non_finite = 0;   ///< NaN / Inf position or velocity of a model joint
    std::uint64_t rejected_future = 0;       ///< stamp ahead of this host's clock by more than kFutureTolerance
    std::uint64_t rejected_old = 0;          ///< not newer than the state held (reordered or repeated)
    std::uint64_t commands = 0;              ///< JointCommand samples published (with sendThrough: queued)
    std::uint64_t rejected() const {
      return rejected_length + rejected_missing + rejected_non_finite + rejected_future + rejected_old;
    }
  };

  /// Makes the reader and the writer on `bus` (throws bus::BusError naming the entity). `driven`: the
  /// q indices the controller commands (OnboardController::drivenJoints()).
  DdsRobotPort(const control::Model& model, const std::vector<int>& driven, bus::Participant& bus, const Options& options);

  /// Takes every state that arrived since the last call (once per cycle, before step()). Returns the
  /// number of samples rejected by this call; lastRejection() names the last one.
  int poll() noexcept;
  const Eigen::VectorXd* measuredPositions(double now) noexcept override;
  void command(const Eigen::VectorXd& q_end, const Eigen::VectorXd& qdot, double dt) noexcept override;
  /// From now on command() queues each JointCommand (stamped at once: its time and sequence number
  /// are the cycle's) for `outbox`'s writer thread instead of writing it on the control thread
  /// (reflex/bus/outbox.hpp: a DDS write can block for a second). Call before outbox.start().
  void sendThrough(bus::Outbox& outbox);

  const Counts& counts() const { return counts_; }
  const char* lastRejection() const { return rejection_; }
  /// The cause of the last rejection: 0 lengths, 1 missing joint, 2 non-finite, 3 future stamp, 4 old.
  static constexpr int kCauses = 5;
  int lastCause() const { return cause_; }
  bool haveState() const { return have_state_; }
  /// Age (s) of the newest accepted state now, +inf without one.
  double stateAge() const noexcept;
  std::uint64_t stateSeq() const { return state_seq_; }
  /// Header.stamp_ns of the newest accepted state (system clock, ns), 0 without one.
  std::int64_t stateStampNs() const { return state_stamp_ns_; }

 private:
  bool accept(const msg::RobotState& s) noexcept;

  const control::Model& model_;
  Options options_;
  bus::Reader<msg::RobotState>* reader_ = nullptr;
  bus::Writer<msg::JointCommand>* writer_ = nullptr;
  bus::OutboxQueue<msg::JointCommand>* queue_ = nullptr;  ///< set by sendThrough
  bus::Outbox* outbox_ = nullptr;
  msg::RobotState sample_;
  msg::JointCommand cmd_;
  std::vector<int> driven_;
  std::vector<std::string> robot_names_;  ///< the robot's name list the map was built for
  std::vector<int> index_;                ///< per model joint: its index in the robot's lists, -1 if absent
  Eigen::VectorXd q_;                     ///< the newest accepted measured positions (model order)
  bool have_state_ = false;
  std::uint64_t state_seq_ = 0;
  std::int64_t state_stamp_ns_ = 0;
  Counts counts_;
  char rejection_[300] = {};
  int cause_ = 0;
};

}  // namespace reflex::control_node
