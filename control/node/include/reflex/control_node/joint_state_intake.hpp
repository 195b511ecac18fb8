// The checks every port whose robot reports named joints runs on each state sample (DdsRobotPort's
// reflex/robot_state, Ros2RobotPort's sensor_msgs/JointState): lengths, names, finite values, limits,
// stamps and the one bound robot writer, with the counts and the messages. dds_robot_port.hpp
// describes each rule; a port hands every sample it takes to take() and reads the outcome here.
// Allocation-free except when the robot's list of joint names changes (the name map is rebuilt).
#pragma once

#include "reflex/control/model.hpp"
#include "reflex/control_node/bus_robot_port.hpp"

#include <reflex/bus/bus.hpp>
#include <reflex/bus/identity.hpp>

#include <Eigen/Core>

#include <array>
#include <cstdint>
#include <string>
#include <vector>

namespace reflex::control_node {

class JointStateIntake {
 public:
  static constexpr double kFutureTolerance = 0.002;  ///< s a state's stamp may lie ahead of this host's clock

  struct Options {
    double timeout = 0.050;       ///< s: a newest state older than this is stale
    double period = 0.005;        ///< s: the control period (the limit tolerance is v_max * period)
    double rebind_silence = 1.0;  ///< s the bound robot writer must be silent before another may replace it
    /// Under DDS-Security: the bus's identities (only a writer authenticated as "robot" is bound).
    const bus::WriterIdentities* identities = nullptr;
    /// How a sample is named in messages, before its number: "robot state seq", "rt/joint_states sample".
    std::string sample_name = "robot state seq";
    /// Velocities may be empty (ROS: "not measured"); else they must be as many as the names.
    bool velocities_optional = false;
  };

  /// The intake's options from a port's (its timeout, period and rebind_silence).
  template <class PortOptions>
  static Options optionsOf(const PortOptions& port) {
    Options o;
    o.timeout = port.timeout;
    o.period = port.period;
    o.rebind_silence = port.rebind_silence;
    return o;
  }

  /// One state sample as the port's type carries it.
  struct View {
    const std::vector<std::string>& names;
    const std::vector<double>& positions;
    const std::vector<double>& velocities;
    const std::vector<double>& efforts;
    std::int64_t stamp_ns;  ///< when the joints were measured (system clock)
    std::uint64_t seq;      ///< the sample's number (the robot's counter, or the port's own)
  };

  struct Counts {
    std::uint64_t accepted = 0;
    std::uint64_t rejected_length = 0;        ///< names / positions / velocities / efforts lengths differ
    std::uint64_t rejected_missing = 0;       ///< a model joint is not in the state
    std::uint64_t rejected_non_finite = 0;    ///< NaN / Inf position or velocity of a model joint
    std::uint64_t rejected_future = 0;        ///< stamp ahead of this host's clock by more than kFutureTolerance
    std::uint64_t rejected_old = 0;           ///< not newer than the state held (reordered or repeated)
    std::uint64_t rejected_duplicate = 0;     ///< a joint name listed twice
    std::uint64_t rejected_limits = 0;        ///< a model joint's position outside its limits (+ tolerance)
    std::uint64_t rejected_other_writer = 0;  ///< from a writer other than the bound robot writer (ignored)
    std::uint64_t writer_changes = 0;         ///< a silent bound writer replaced by a new one
    std::uint64_t rejected() const {
      return rejected_length + rejected_missing + rejected_non_finite + rejected_future + rejected_old +
             rejected_duplicate + rejected_limits + rejected_other_writer;
    }
  };
  /// The causes: 0 lengths, 1 missing joint, 2 non-finite, 3 future stamp, 4 old, 5 duplicate name,
  /// 6 outside the limits, 7 another writer.
  static constexpr int kCauseOtherWriter = 7;

  JointStateIntake(const control::Model& model, const Options& options);

  /// Checks one sample taken with `info` (its writer) at `now_ns`; true when accepted (it is then the
  /// state held). Never throws.
  bool take(const View& s, const bus::dds::SampleInfo& info, std::int64_t now_ns) noexcept;

  /// The held positions (model order), nullptr when none was accepted or the newest is older than the
  /// timeout (its stamp against this host's system clock).
  const Eigen::VectorXd* measuredPositions() const noexcept;
  double stateAge() const noexcept;  ///< s since the newest accepted state's stamp, +inf without one
  bool haveState() const { return have_state_; }
  std::uint64_t stateSeq() const { return state_seq_; }
  std::int64_t stateStampNs() const { return state_stamp_ns_; }
  /// The stamps of the newest accepted state and the one before it, of the same writer; 0 while unknown.
  double stateInterval() const noexcept { return 1e-9 * static_cast<double>(state_interval_ns_); }
  const Counts& counts() const { return counts_; }
  const char* lastRejection() const { return rejection_; }
  const char* lastBadRejection() const { return texts_.lastBad(); }
  const char* rejectionOf(int cause) const { return texts_.of(cause); }
  int lastCause() const { return cause_; }
  const char* boundWriter() const { return bound_text_; }
  const char* otherWriter() const { return other_text_; }

 private:
  using Guid = std::array<unsigned char, 16>;
  bool accept(const View& s, const Guid& writer, std::int64_t now_ns) noexcept;
  bool reject(int cause, std::uint64_t& counter) noexcept;

  const control::Model& model_;
  Options options_;
  std::vector<std::string> robot_names_;  ///< the robot's name list the map was built for
  std::vector<int> index_;                ///< per model joint: its index in the robot's lists, -1 if absent
  int duplicate_ = -1;                    ///< index in robot_names_ of a name listed twice, -1 none
  Eigen::VectorXd lower_, upper_;         ///< the accepted position range per model joint (limits + tolerance)
  bool bound_ = false;                    ///< a robot writer is bound
  Guid robot_writer_{};                   ///< the bound writer
  std::int64_t writer_last_ns_ = 0;       ///< when the bound writer's last sample arrived (this host's clock)
  Guid other_{};                          ///< the newest writer ignored
  bool identity_checked_ = false;         ///< candidate_ was checked against the "robot" identity
  Guid candidate_{};                      ///< the last writer checked (secure mode)
  bool candidate_ok_ = false;
  char bound_text_[64] = {};
  char other_text_[64] = {};
  Eigen::VectorXd q_;  ///< the newest accepted measured positions (model order)
  bool have_state_ = false;
  std::uint64_t state_seq_ = 0;
  std::int64_t state_stamp_ns_ = 0;
  std::int64_t state_interval_ns_ = 0;
  Counts counts_;
  char rejection_[RejectionTexts::kBytes] = {};  ///< the rejection being formatted, then the latest
  RejectionTexts texts_;
  int cause_ = 0;
};

/// A robot port whose robot reports named joints (DdsRobotPort, Ros2RobotPort): the intake and what
/// BusRobotPort asks of the state, answered from it once for both. A derived port takes its samples
/// (poll), sends its commands and names its topic.
class NamedJointPort : public BusRobotPort {
 public:
  const Eigen::VectorXd* measuredPositions(double /*now*/) noexcept override { return intake_.measuredPositions(); }
  double stateInterval() const noexcept override { return intake_.stateInterval(); }
  const char* lastRejection() const override { return intake_.lastRejection(); }
  const char* lastBadRejection() const override { return intake_.lastBadRejection(); }
  const char* rejectionOf(int cause) const override { return intake_.rejectionOf(cause); }
  int lastCause() const override { return intake_.lastCause(); }
  bool haveState() const override { return intake_.haveState(); }
  std::uint64_t stateSeq() const override { return intake_.stateSeq(); }
  std::int64_t stateStampNs() const override { return intake_.stateStampNs(); }
  const char* boundWriter() const override { return intake_.boundWriter(); }
  const char* otherWriter() const override { return intake_.otherWriter(); }
  std::uint64_t acceptedStates() const override { return intake_.counts().accepted; }
  std::uint64_t writerChanges() const override { return intake_.counts().writer_changes; }
  CauseCounts rejectedByCause() const override {
    const JointStateIntake::Counts& c = intake_.counts();
    return {c.rejected_length,
            c.rejected_missing,
            c.rejected_non_finite,
            c.rejected_future,
            c.rejected_old,
            c.rejected_duplicate,
            c.rejected_limits,
            c.rejected_other_writer,
            0,
            0,
            0};
  }

 protected:
  NamedJointPort(const control::Model& model, const JointStateIntake::Options& options) : intake_(model, options) {}
  JointStateIntake intake_;
};

}  // namespace reflex::control_node
