// The physics-simulated humanoid: MuJoCo 2.2 running the robot built by makeMjcf
// from the project's Model, with a PD servo per joint, the hold rule of idl/robot.idl, and MuJoCo's
// collision detection as the independent judge of the collision model. No DDS here: the process
// wrapper (robot_node.hpp) moves samples in and out; everything below is testable in one process.
//
// Per period (MujocoRobot::step, e.g. 1 ms):
//   1. the caller offers the newest commands (offerCommand); each is checked and either becomes the
//      active command or is rejected and counted (CommandCounters);
//   2. if the active command's deadline has passed (or there is none) the robot HOLDS: the servo
//      reference of every joint becomes its measured position at the moment the hold began, with zero
//      velocity reference; `holding` is true and applied_command_seq is 0;
//   3. `substeps` physics steps. Per step the servo reference moves towards the commanded position at
//      no more than the joint's velocity limit (Model::v_max), whatever the command (the joint follows
//      the reference with the servo's dynamics: mujoco_model_test measures its overshoot);
//      qdot_ref is the commanded velocity while q_ref still travels, 0 once it reached the target;
//      the actuator gets ctrl = kp q_ref + kd qdot_ref + the bias force (gravity and Coriolis, as
//      drives with gravity feed-forward do), its force clamped to ±effort;
//   4. the measured state (positions, velocities) and the segment pairs MuJoCo reports closer than
//      the margin, both at the same instant: the start of the last physics step (one collision pass
//      serves the judge and the physics); the efforts are the drive torques applied from then on.
// step() allocates nothing and never throws.
#pragma once

#include "reflex/control/model.hpp"
#include "reflex/mujoco/mjcf.hpp"

#include <mujoco/mujoco.h>

#include <cstdint>
#include <memory>
#include <stdexcept>
#include <string>
#include <unordered_map>
#include <vector>

namespace reflex::mujoco {

struct MjModelDeleter {
  void operator()(mjModel* m) const { mj_deleteModel(m); }
};
struct MjDataDeleter {
  void operator()(mjData* d) const { mj_deleteData(d); }
};
using MjModelPtr = std::unique_ptr<mjModel, MjModelDeleter>;
using MjDataPtr = std::unique_ptr<mjData, MjDataDeleter>;

/// Compiles MJCF text with MuJoCo (through its virtual file system, no temporary file). Throws
/// std::runtime_error with MuJoCo's compiler message.
MjModelPtr compileMjcf(const std::string& mjcf);

/// One pair of segments MuJoCo reports closer than the margin (the smallest distance over the
/// segments' primitive pairs). seg_a < seg_b (Model segment indices); distance [m] < 0: penetrating.
struct SegmentContact {
  int seg_a = -1, seg_b = -1;
  double distance = 0.0;
};

/// A joint command as the robot receives it (idl/robot.idl JointCommand, without DDS types).
struct CommandInput {
  const std::vector<std::string>* names = nullptr;
  const std::vector<double>* positions = nullptr;
  const std::vector<double>* velocities = nullptr;
  std::int64_t valid_until_ns = 0;  ///< CLOCK_REALTIME [ns]
  std::uint64_t seq = 0;
  std::int64_t state_stamp_ns = 0;  ///< stamp of the state it answers (0: none)
};

enum class CommandVerdict {
  kAccepted,
  kEmpty,           ///< no names
  kLengthMismatch,  ///< names, positions, velocities of different lengths
  kUnknownName,     ///< a name that is not a movable joint of this robot
  kDuplicateName,
  kNotFinite,  ///< a NaN or infinite position or velocity
  kExpired,    ///< valid_until_ns already passed on arrival
};
const char* verdictName(CommandVerdict v);

/// Counts since start. rejected_* never changed any servo reference.
struct CommandCounters {
  std::uint64_t accepted = 0;
  std::uint64_t rejected_empty = 0, rejected_length = 0, rejected_unknown = 0, rejected_duplicate = 0,
                rejected_not_finite = 0, rejected_expired = 0;
  std::uint64_t position_clamped = 0;  ///< accepted commands with a position outside the joint limits (clamped)
  std::uint64_t holds = 0;             ///< times the robot began to hold
  std::uint64_t rejected() const {
    return rejected_empty + rejected_length + rejected_unknown + rejected_duplicate + rejected_not_finite +
           rejected_expired;
  }
};

/// What the robot measured at the end of the last step() (sized from the Model: q index order).
struct RobotMeasurement {
  Eigen::VectorXd q, qdot, effort;        ///< [rad|m], [rad/s|m/s], actuator force [N m|N]
  std::vector<SegmentContact> contacts;   ///< capacity reserved; pairs below the margin now
  std::uint64_t applied_command_seq = 0;  ///< 0 while holding
  bool holding = true;
  std::uint64_t steps = 0;           ///< physics steps since start
  std::uint64_t contact_steps = 0;   ///< physics steps whose collision detection reported a pair
  std::uint64_t hold_steps = 0;      ///< physics steps spent holding
  std::uint64_t unstable_steps = 0;  ///< MuJoCo reported a bad acceleration (simulation reset)
};

class MujocoRobot {
 public:
  /// Builds the MJCF (makeMjcf with servoGains), compiles it, sets q = q0 (q index order; empty:
  /// every joint at 0, or at the nearest limit) at rest and holding. Throws reflex::Error (a model MuJoCo
  /// refuses) / std::invalid_argument (a q0 of the wrong size) naming the bad value.
  MujocoRobot(const control::Model& model, const MjcfOptions& options, const Eigen::VectorXd& q0 = {});

  /// Checks a command against the robot at wall-clock time now_ns; if accepted it becomes the active
  /// command (its positions are the servo targets of the joints it names, the other joints keep
  /// theirs). Never throws; allocates nothing once the names were seen in this order before.
  CommandVerdict offerCommand(const CommandInput& command, std::int64_t now_ns);

  /// Advances `substeps` physics steps at wall-clock time now_ns (deadline check once, before them).
  void step(int substeps, std::int64_t now_ns);

  const RobotMeasurement& measurement() const { return measured_; }
  const CommandCounters& counters() const { return counters_; }
  const std::vector<ServoGains>& gains() const { return gains_; }
  const std::string& mjcf() const { return mjcf_; }
  const mjModel& mjModelRef() const { return *m_; }
  mjData& mjDataRef() { return *d_; }
  double timestep() const { return m_->opt.timestep; }
  /// The servo reference of every joint (q index order).
  const Eigen::VectorXd& reference() const { return q_ref_; }
  /// The state_stamp_ns of the command accepted last (0: none), for latency measurement.
  std::int64_t lastStateStampNs() const { return last_state_stamp_ns_; }

  /// Sets positions (q index order), zero velocities, recomputes kinematics and contacts (tests).
  void setPositions(const Eigen::VectorXd& q);
  /// Collects the pairs below the margin from the current mjData.contact into `out` (no allocation
  /// beyond its reserved capacity: the number of checked robot pairs).
  void collectContacts(std::vector<SegmentContact>& out) const;

 private:
  void beginHold();
  void readMeasurement();

  const control::Model& model_;
  std::vector<ServoGains> gains_;
  std::string mjcf_;
  MjModelPtr m_;
  MjDataPtr d_;
  std::vector<int> qpos_adr_, dof_adr_, actuator_;  // per q index
  std::vector<int> geom_segment_;                   // per MuJoCo geom: Model segment index or -1
  std::unordered_map<std::string, int> q_of_name_;
  std::vector<int> command_q_;  // q index per name of the last accepted name list
  std::vector<std::string> command_names_;
  Eigen::VectorXd q_target_, qdot_target_, q_ref_, qdot_ref_;
  std::int64_t valid_until_ns_ = 0;
  std::int64_t last_state_stamp_ns_ = 0;
  RobotMeasurement measured_;
  CommandCounters counters_;
};

}  // namespace reflex::mujoco
