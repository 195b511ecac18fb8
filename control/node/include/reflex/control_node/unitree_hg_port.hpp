// The robot over Unitree's "hg" low-level interface: reflex_controller --robot unitree_hg. A
// control::RobotPort that reads every joint from rt/lowstate (LowState_) and commands the arms on
// rt/arm_sdk (LowCmd_) beside the robot's own walking controller (unitree_hg.hpp: types, crc, joint
// map; idl/README.md "Robots that already have an interface").
//
// State in: poll() takes every LowState_ that arrived. A sample is REJECTED and counted by cause (the
// causes of bus_robot_port.hpp, named in the exit line and reflex/control_status like DdsRobotPort's):
//   robot_state_bad_crc      its crc is not Crc32Core of its C layout (a corrupted or foreign sample);
//   robot_state_motor_count  a payload of another size than LowState_'s 35 motors (the type support
//                            refuses to decode it; counted from unitree_hg::undecodableLowStates());
//   robot_state_old_tick     its tick does not advance over the held state's (repeated, reordered, or
//                            a robot whose counter stands still; a tick that wrapped past 2^32 advances);
//   robot_state_not_finite / _outside_limits  a mapped motor's q or dq not finite / q outside the
//                            joint's limits by more than v_max * period (as DdsRobotPort);
//   robot_state_other_writer another DataWriter than the bound robot writer (as DdsRobotPort: the
//                            first accepted writer is bound; replaced after 1 s of its silence).
// LowState_ carries no time: a state is "measured" when this host took it (stateStampNs()); it is
// stale (measuredPositions() nullptr: nothing is computed or commanded) when none was accepted for
// `timeout`, so a robot whose tick stands still goes stale too. Joints the map lists as fixed get
// their fixed value in every state.
//
// Command out (rt/arm_sdk): one LowCmd_ per computed cycle. Every mapped motor in 12..28 (waist and
// arms; the slots the arm_sdk weight blends) gets mode 1, q = the cycle's end position q_end, dq =
// qdot, tau 0, kp / kd from the map (a joint the controller does not drive carries its measured
// position, per RobotPort::command). Legs (0..11) and slots beyond 29 are never commanded (mode 0,
// all zero). motor_cmd[29].q is the WEIGHT: it rises from 0 by dt / ramp_time per command (ramp in,
// never a jump) to 1, and after the last cycle finish() lowers it the same way to 0 while sending the
// last command's positions (ramp out). With sendThrough (reflex_controller) the commands go through the
// loop's outbox, written by its thread; without (reflex_sim's plant) on the calling thread. A weight change dw moves each blended joint by dw times the
// distance between Reflex's command and the robot's own target, which is taken to be where the robot
// held the joint before the first command: the weight never changes by more than
// kBlendSpeedShare * v_max * dt / that distance per command, so the blend alone moves no joint faster
// than half its velocity limit (the ramp then takes longer than ramp_time). crc = Crc32Core of the C
// layout. The command is written on the
// calling thread (a reliable writer with keep-last 1 does not wait for readers).
#pragma once

#include "reflex/control/model.hpp"
#include "reflex/control_node/bus_robot_port.hpp"
#include "reflex/control_node/unitree_hg.hpp"

#include <reflex/bus/bus.hpp>
#include <reflex/bus/outbox.hpp>

#include <array>
#include <cstdint>
#include <vector>

namespace reflex::control_node {

class UnitreeHgPort final : public BusRobotPort {
 public:
  struct Options {
    double timeout = 0.050;       ///< s without an accepted state before the state is stale
    double period = 0.005;        ///< s: the control period (limit tolerance v_max * period)
    double ramp_time = 3.0;       ///< s for the arm_sdk weight from 0 to 1 and back (> 0)
    double rebind_silence = 1.0;  ///< s the bound writer must be silent before another may replace it
    std::string command_topic = unitree_hg::kArmSdkTopic;
  };

  /// Makes the reader (rt/lowstate) and writer (rt/arm_sdk) on `bus`. `map` resolved against `model`
  /// (resolveHgJointMap); `driven` the q indices the controller commands. Throws control::ConfigError
  /// when no driven joint is on a motor the arm_sdk weight blends (12..28), naming the map; bus::BusError
  /// naming a DDS entity.
  UnitreeHgPort(const control::Model& model, const std::vector<int>& driven, const unitree_hg::HgJointMap& map,
                bus::Participant& bus, const Options& options);

  int poll() noexcept override;
  const Eigen::VectorXd* measuredPositions(double now) noexcept override;
  void command(const Eigen::VectorXd& q_end, const Eigen::VectorXd& qdot, double dt) noexcept override;
  /// From now on command() and the ramp out queue each LowCmd_ for `outbox`'s writer thread (a DDS
  /// write allocates inside Fast DDS and can block; measured: 5 allocations per write). Before
  /// outbox.start().
  void sendThrough(bus::Outbox& outbox) override;
  void finish(double period) noexcept override;
  /// One step of the ramp out: the last command again with the weight lowered by dt / ramp_time.
  /// False once the weight is 0 (that command sent).
  bool rampOutStep(double dt) noexcept;

  bool waitForState(std::chrono::nanoseconds timeout) noexcept override;
  double stateInterval() const noexcept override { return 1e-9 * static_cast<double>(state_interval_ns_); }
  const char* lastRejection() const override { return rejection_; }
  const char* lastBadRejection() const override { return texts_.lastBad(); }
  const char* rejectionOf(int cause) const override { return texts_.of(cause); }
  int lastCause() const override { return cause_; }
  bool haveState() const override { return have_state_; }
  std::uint64_t stateSeq() const override { return tick_; }
  std::int64_t stateStampNs() const override { return state_stamp_ns_; }
  const char* boundWriter() const override { return bound_text_; }
  const char* otherWriter() const override { return other_text_; }
  const char* stateTopic() const override { return unitree_hg::kStateTopic; }
  std::uint64_t acceptedStates() const override { return accepted_; }
  CauseCounts rejectedByCause() const override { return rejected_; }
  std::uint64_t writerChanges() const override { return writer_changes_; }
  std::uint64_t commandsSent() const override { return commands_; }

  /// The arm_sdk weight of the last command sent (0 before the first).
  double weight() const { return weight_; }
  /// The largest change of the weight between two commands (<= dt / ramp_time by construction).
  double maxWeightStep() const { return max_weight_step_; }
  /// The q indices this port commands (mapped to 12..28 and driven by the controller).
  const std::vector<int>& commandedJoints() const { return commanded_; }

 private:
  using Guid = std::array<unsigned char, 16>;
  bool accept(const unitree_hg::LowState& s, const Guid& writer, std::int64_t now_ns) noexcept;
  bool reject(int cause) noexcept;
  void send() noexcept;
  /// The largest weight change this command may make (see the header): kBlendSpeedShare * v_max * dt /
  /// |q_cmd - q_own| over the arm_sdk joints, 1 when they all agree.
  double weightStepLimit(double dt) const noexcept;
  static constexpr double kBlendSpeedShare = 0.5;

  const control::Model& model_;
  Options options_;
  unitree_hg::HgResolvedMap map_;
  std::vector<int> commanded_;
  bus::Reader<unitree_hg::LowState>* reader_ = nullptr;
  bus::Writer<unitree_hg::LowCmd>* writer_ = nullptr;
  bus::OutboxQueue<unitree_hg::LowCmd>* queue_ = nullptr;  ///< set by sendThrough
  bus::Outbox* outbox_ = nullptr;
  unitree_hg::LowState sample_;
  unitree_hg::LowCmd cmd_;
  Eigen::VectorXd q_, lower_, upper_;
  Eigen::VectorXd q_own_;  ///< the measured state when the first command was sent (the robot's own targets)
  bool have_state_ = false;
  std::uint32_t tick_ = 0;
  std::int64_t state_stamp_ns_ = 0, state_interval_ns_ = 0;
  std::uint64_t undecodable_seen_ = 0;
  bool bound_ = false;
  Guid robot_writer_{}, other_{};
  std::int64_t writer_last_ns_ = 0;
  char bound_text_[64] = {};
  char other_text_[64] = {};
  double weight_ = 0.0, max_weight_step_ = 0.0;
  bool sent_ = false;
  std::uint64_t accepted_ = 0, writer_changes_ = 0, commands_ = 0;
  CauseCounts rejected_{};
  char rejection_[RejectionTexts::kBytes] = {};  ///< the rejection being formatted, then the latest
  RejectionTexts texts_;
  int cause_ = 0;
};

}  // namespace reflex::control_node
