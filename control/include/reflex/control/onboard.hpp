// The onboard controller without the bus: everything reflex_controller does per
// 5 ms cycle, as one object. Inputs arrive by value between cycles (hand targets with the time they
// arrived, motion priority, body-schema changes by name, walk commands, an e-stop reset); step(now)
// runs input staleness (hold, then retract), motion priority, computeControl, the plant through a
// RobotPort, and returns one CycleReport. reflex_controller is a thin adapter between DDS samples and
// this object; runScenario (and so reflex_sim, the experiments and the soak) drives the same object,
// so the plant loop exists once (stepPlant inside step()).
//
// The robot port: the controller computes from the positions the port says were
// MEASURED this cycle and hands the port one command: the positions the driven joints should reach
// at the end of the cycle (measured + qdot dt for the arm joints, rate-limited to v_max and clamped to
// the position limits; for the walking joints the walking pattern's positions, which continue the
// controller's OWN last command, never the measured value: a state cannot move the legs; the measured
// value elsewhere) and the velocities over the cycle ((q_end - q_measured) / dt, clamped to +-v_max).
// While the e-stop is latched (kFrozen) every driven joint is commanded where the last command put it,
// whatever the state says. The hold is anchored at the measured state at the first computed cycle and
// again at the first one after a cycle without a state (the robot held itself meanwhile). Whatever the
// state, a command never lies outside the position limits and never has a velocity above v_max. KinematicPort is today's in-process
// plant: the command's end positions become the next measured state exactly. The robot over DDS
// (control/node, reflex_controller --robot dds) implements the same port. A port without a usable
// state (missing, stale) returns nullptr: the cycle computes nothing and commands nothing (the robot
// holds on its own); CycleReport::robot_state_ok says so and the counts say how often.
//
// Input staleness (the same rule as reflex_controller with its in-process robot): the target source's last sign
// of life is the later of its last hand-target sample and its last heartbeat (noteSourceHeartbeat).
// Until input_timeout has passed since then the last targets are HELD (followed as they are);
// strictly later than input_timeout both hands get "no target" and retract to rest. Before any sign
// of life the inputs are stale.
//
// Motion priority: the priority last set (setPriority); when that is "equal", a physical body-schema
// segment attached with a positive motion_priority on a link of one arm (a grasped object) makes that
// arm the higher one (Sec. 7.2, 8.5.1).
//
// Hot path: step() and every input call except the first attach of a name longer than 255 bytes
// allocate nothing and never throw; no NaN reaches the port (computeControl's contract). Set-up (the
// constructor) throws ConfigError naming the bad value.
#pragma once

#include "reflex/control/controller.hpp"
#include "reflex/control/model.hpp"
#include "reflex/control/simulation.hpp"

#include <Eigen/Core>

#include <array>
#include <cmath>
#include <cstdint>
#include <string>
#include <vector>

namespace reflex::control {

/// Where the onboard controller reads the robot's measured joint state and sends each cycle's command.
/// Both calls are made from the control cycle: allocation-free and noexcept in every implementation.
class RobotPort {
 public:
  virtual ~RobotPort() = default;
  /// The measured joint positions to compute this cycle from (nq entries, model joint order, finite),
  /// or nullptr when the robot's state is missing or stale: the cycle then commands nothing.
  /// now: the controller's monotonic clock (s).
  virtual const Eigen::VectorXd* measuredPositions(double now) noexcept = 0;
  /// The cycle's command (nq entries each, model joint order): q_end the positions at the end of the
  /// cycle (rad or m), qdot the velocity over it (rad/s or m/s, |qdot_i| <= v_max_i), dt the period (s).
  /// Joints no arm and no walking moves carry their measured position and 0.
  virtual void command(const Eigen::VectorXd& q_end, const Eigen::VectorXd& qdot, double dt) noexcept = 0;
};

/// The in-process kinematic plant (the default of reflex_controller, runScenario, the soak): the
/// commanded end positions are the next measured state, exactly (no lag, no gravity).
class KinematicPort final : public RobotPort {
 public:
  explicit KinematicPort(const Eigen::VectorXd& q0) : q_(q0) {}
  const Eigen::VectorXd* measuredPositions(double /*now*/) noexcept override { return &q_; }
  void command(const Eigen::VectorXd& q_end, const Eigen::VectorXd& /*qdot*/, double /*dt*/) noexcept override {
    q_ = q_end;
  }
  /// The robot's current positions (a reference that stays valid: ScenarioContext::q points here).
  const Eigen::VectorXd& positions() const { return q_; }

 private:
  Eigen::VectorXd q_;
};

struct OnboardOptions {
  double input_timeout = 1.0;        ///< s of silence from the target source before the hands retract (> 0)
  double max_target_distance = 2.0;  ///< m from the base origin; a farther (or non-finite) target is rejected (> 0)
  double max_walk_speed = 0.5;       ///< m/s: walk commands are capped here (> 0)
};

/// One body-schema change as a behavior module sends it (reflex/body_schema), by segment name.
struct BodySchemaRequest {
  enum class Operation : std::uint8_t { kAttach, kDetach };
  Operation operation = Operation::kAttach;
  bool enabled = true;                            ///< kAttach with false: detached but the name keeps its slot
  const std::string* name = nullptr;              ///< segment name (must outlive the call)
  const std::string* parent_link = nullptr;       ///< link the endpoints are given in (must outlive the call)
  Eigen::Vector3d a_L = Eigen::Vector3d::Zero();  ///< capsule core endpoints in the link frame (m)
  Eigen::Vector3d b_L = Eigen::Vector3d::Zero();  ///< equal to a_L for a sphere
  double radius = 0.0;                            ///< m
  bool is_virtual = false;                        ///< virtual (occlusion) segment: avoided, never an e-stop
  int motion_priority = 0;                        ///< > 0 on a physical segment of an arm: that arm gets priority
};

/// What changeBodySchema did. A refusal names its reason in `text` (a NUL-terminated line without a
/// process prefix, e.g. "body-schema segment 'pack' rejected: no free slot (link 'chest')").
struct BodySchemaOutcome {
  enum class Kind : std::uint8_t {
    kAttached,
    kDetached,
    kUnknownName,           ///< kUnknownName: a detach of a name never attached (ignored, not counted)
    kRejectedCheck,         ///< checkBodySchemaSegment refused it (check.fault, value, limit, key)
    kRejectedNoSlot,        ///< every slot is taken by another name
    kRejectedUnresolvable,  ///< findUnresolvableContact refused it (attach.refusing_pair ...)
  };
  Kind kind = Kind::kUnknownName;
  int slot = -1;
  BodySchemaCheck check;
  SegmentAttach attach;
  bool rejected() const { return kind >= Kind::kRejectedCheck; }
  char text[400] = {};
};

/// Why an input was refused: one counter per cause (OnboardCounts::rejected).
enum class RejectCause : std::uint8_t {
  kHandTargetNotFinite,  ///< a given hand target with a NaN / Inf coordinate (per hand)
  kHandTargetTooFar,     ///< a given hand target farther than max_target_distance from the base origin (per hand)
  kSchemaBadSegment,     ///< checkBodySchemaSegment refused the segment (BodySchemaOutcome::kRejectedCheck)
  kSchemaNoSlot,         ///< every body-schema slot is taken by another name
  kSchemaUnresolvable,   ///< the segment would touch one that no arm can move away from it
  kWalkBadValue,         ///< a walk command with a non-finite goal_x or speed, or speed <= 0
  kWalkUnsupportedGoal,  ///< a walk command whose goal_y or goal_yaw is not 0: the walking pattern walks
                         ///< along the base x axis only (|goal_y| and |goal_yaw| <= kWalkGoalTolerance)
};
inline constexpr int kRejectCauses = 7;
/// The cause's name as the exit line and reflex/control_status (last_rejection) print it, e.g.
/// "hand_target_too_far".
const char* rejectCauseName(RejectCause cause) noexcept;
/// goal_y [m] and goal_yaw [rad] of a walk command up to this magnitude count as 0: 1 mm / 1 mrad, far
/// below what walking achieves, so a relative goal computed on the behavior side from a measured heel_y
/// (rounding, a physics robot's drift) still walks; anything larger is kWalkUnsupportedGoal.
inline constexpr double kWalkGoalTolerance = 1e-3;

/// Counters since construction (the node's exit line, tests).
struct OnboardCounts {
  std::uint64_t cycles = 0;                 ///< step() calls
  std::uint64_t computed_cycles = 0;        ///< cycles with a robot state (control computed, command sent)
  std::uint64_t targets_received = 0;       ///< setHandTargets calls
  std::uint64_t targets_rejected = 0;       ///< every rejected input: the three groups below summed
  std::uint64_t hand_targets_rejected = 0;  ///< non-finite or farther than max_target_distance (per hand)
  std::uint64_t schema_rejected = 0;        ///< body-schema changes refused
  std::uint64_t walk_rejected = 0;          ///< walk commands refused (kWalkBadValue + kWalkUnsupportedGoal)
  std::array<std::uint64_t, kRejectCauses> rejected{};  ///< per RejectCause (index = the enum's value)
  int last_rejection = -1;                              ///< the RejectCause of the latest refusal, -1 none yet
  std::uint64_t stale_events = 0;                       ///< transitions to "inputs stale" (hands retract)
  std::uint64_t robot_stale_cycles = 0;                 ///< cycles without a robot state
  std::uint64_t robot_stale_events = 0;                 ///< transitions from "robot state ok" to "no robot state"
  std::uint64_t estop_count = 0;                        ///< ControllerData::estop_count
  std::uint64_t guard_count = 0;                        ///< ControllerData::guard_count
  std::uint64_t walking_holds = 0;                      ///< ControllerData::walking_hold_count
  std::uint64_t bad_input_count = 0;                    ///< ControllerData::bad_input_count
};

/// One arm in the cycle report.
struct ArmReport {
  double f = 0.0;                                             ///< blending coefficient, Eq. 13
  double distance = std::numeric_limits<double>::infinity();  ///< closest pair of this arm (m)
  Zone zone = Zone::kFree;
  int closest_pair = -1;  ///< index into Model::pairs, -1 none
  /// The closest pair's segments: segment_a is THIS arm's segment (whichever side of Model::pairs it
  /// is on; for a pair of two segments of this arm, the pair's first), segment_b the other one.
  /// Both nullptr exactly when closest_pair is -1 (no pair of the arm was considered this cycle).
  const char* segment_a = nullptr;
  const char* segment_b = nullptr;
};

/// The outcome of one step().
struct CycleReport {
  double now = 0.0;             ///< the step's time (s, the caller's monotonic clock)
  bool robot_state_ok = false;  ///< false: no usable robot state: nothing computed or commanded;
                                ///< every field below but inputs_stale/commands/priority/counts is the last cycle's
  bool inputs_stale = true;     ///< the target source is silent: both hands retract
  ControlResult result = ControlResult::kOk;
  EstopState estop = EstopState::kClear;
  bool walking_advanced = false;                     ///< walking took a step this cycle
  std::array<HandCommand, 2> commands;               ///< the hand commands the controller followed (after staleness)
  MotionPriority priority = MotionPriority::kEqual;  ///< the priority it applied
  std::array<ArmReport, 2> arms;
  double min_distance = std::numeric_limits<double>::infinity();  ///< closest physical pair (m)
  int min_pair = -1;
  double virtual_distance = std::numeric_limits<double>::infinity();  ///< closest pair with a virtual segment (m)
  int virtual_pair = -1;
  double arm_distance = std::numeric_limits<double>::infinity();  ///< closest left-arm/right-arm pair (m), Fig. 13
  OnboardCounts counts;
};

/// How far a MEASURED position may lie past joint i's limit and still be accepted (rad or m): what the
/// joint covers in one control cycle at its velocity limit, v_max_i * period. An encoder reading a hair
/// past a soft limit (a servo overshooting a command at the limit) is accepted, and the next command,
/// clamped to the limits, brings it back within one cycle at no more than v_max; a reading further out
/// is not a state the controller can answer within v_max and the limits, and is refused (the robot
/// port rejects the whole state).
inline double stateLimitTolerance(const Model& model, int i, double period) noexcept { return model.v_max[i] * period; }
/// A joint without position limits (continuous) accepts a measured |position| up to this (rad or m):
/// larger finite values are absurd (and lose the precision the kinematics needs).
inline constexpr double kMaxUnlimitedPosition = 1e4;

/// The measured position range a robot port accepts per model joint: the limits widened by
/// stateLimitTolerance, +-kMaxUnlimitedPosition for a joint without limits (every port's rule).
inline void acceptedStateRange(const Model& model, double period, Eigen::VectorXd& lower, Eigen::VectorXd& upper) {
  lower.resize(model.nq);
  upper.resize(model.nq);
  for (int i = 0; i < model.nq; ++i) {
    const double tol = stateLimitTolerance(model, i, period);
    lower[i] = std::isfinite(model.q_lower[i]) ? model.q_lower[i] - tol : -kMaxUnlimitedPosition;
    upper[i] = std::isfinite(model.q_upper[i]) ? model.q_upper[i] + tol : kMaxUnlimitedPosition;
  }
}

/// The robot segments a physical body-schema segment held by `link` (a grasped object) is never
/// checked against (bit i: segment i): every segment on the rigid body of `link` (the links joined to
/// it by fixed joints, up or down); when `link` is on an arm, also every segment below it that no ARM
/// joint of `cm` separates from it (the fingers of a hand); and the nearest segment above that rigid
/// body (the wrist it hangs from). Allocation-free.
std::uint64_t graspIgnoreMask(const Model& model, const ControllerModel& cm, int link) noexcept;

/// The joints the onboard controller drives, as q indices: every arm's joints (left, then right, in
/// the configuration's order), then the walking pattern's joints (WalkingPattern::joints()).
std::vector<int> drivenJoints(const Model& model, const ControllerModel& cm);

class OnboardController {
 public:
  /// `model`, `cm` and `port` must outlive the controller; q0 (nq, finite) is the configuration
  /// assumed until the first measured state (body-schema checks, walk goals). Throws ConfigError
  /// naming the bad value for an option out of range or a q0 of the wrong size or not finite.
  OnboardController(const Model& model, const ControllerModel& cm, RobotPort& port, const Eigen::VectorXd& q0,
                    const OnboardOptions& options = {});
  OnboardController(const OnboardController&) = delete;
  OnboardController& operator=(const OnboardController&) = delete;

  // ---- inputs (between steps; allocation-free, never throw) ----
  /// A hand-target sample arrived at `now` (a sign of life of the source, even if rejected). A
  /// kGiven hand whose target is non-finite or farther than max_target_distance is rejected
  /// (counted; that hand keeps what it had). Returns the number of hands rejected (0..2).
  int setHandTargets(const std::array<HandCommand, 2>& hands, double now) noexcept;
  /// A heartbeat of the target source arrived at `now` (the caller decides it is that source's).
  void noteSourceHeartbeat(double now) noexcept { last_source_heartbeat_ = now; }
  /// The target source changed (another writer): its earlier heartbeats no longer count.
  void newTargetSource() noexcept { last_source_heartbeat_ = -1.0; }
  /// The whole input from an in-process script (runScenario): hands and priority as given, no range
  /// check (computeControl answers a non-finite target with kBadInput), a sign of life at `now`,
  /// reset_estop forwarded to the next step.
  void setControlInput(const ControlInput& input, double now) noexcept;
  /// Holds both hands where they are (targets at the current hand positions), as a sign of life at
  /// `now`: a controller resumed from a saved robot state waits for its source (at most
  /// input_timeout) instead of retracting at once. False if the configuration is not finite.
  bool holdHandsHere(double now) noexcept;
  void setPriority(MotionPriority priority) noexcept { priority_ = priority; }
  /// Attach (by name; the same name re-places its slot), disable (enabled false: the name keeps its
  /// slot) or detach (frees the slot). A refusal is counted and named in the outcome's text.
  const BodySchemaOutcome& changeBodySchema(const BodySchemaRequest& request) noexcept;
  /// A walk command: stop, or walk to heel_x = goal_x (the base frame's x of the heel joint) at
  /// min(speed, max_walk_speed). False (rejected, counted) for a non-finite goal or speed, or speed <= 0
  /// (kWalkBadValue), and for a goal_y [m] or goal_yaw [rad] that is not 0 within kWalkGoalTolerance
  /// (kWalkUnsupportedGoal: the walking pattern only walks along x; the goal is refused whole, never
  /// walked in x alone). A stop is always accepted (its goal is ignored).
  bool walkCommand(bool stop, double goal_x, double goal_y, double goal_yaw, double speed) noexcept;
  /// The same with goal_y = goal_yaw = 0.
  bool walkCommand(bool stop, double goal_x, double speed) noexcept {
    return walkCommand(stop, goal_x, 0.0, 0.0, speed);
  }
  /// Walks `distance` m forward from where the heel is at the next step (scenarios). See WalkingPattern::start.
  bool startWalking(double distance, double speed) noexcept;
  /// Asks the next step to leave a latched e-stop (only separating motion, Sec. 7.1).
  void requestEstopReset() noexcept { reset_ = true; }

  // ---- the cycle ----
  /// One control cycle at `now` (s, monotonic): staleness, priority, computeControl, stepPlant on a
  /// one-cycle integrator started from the measured state, the port's command. Allocation-free; never throws.
  const CycleReport& step(double now) noexcept { return step(now, 0.0); }
  /// The same for a cycle that spans `dt` s (0 < dt <= period; anything else is one period): a cycle
  /// per arriving robot state (reflex_controller --trigger state) spans the robot's state interval. The
  /// command then ends dt after the measured state: q_end = measured + qdot dt, velocities
  /// (q_end - measured) / dt within +-v_max, walking advances dt, the trajectory dt (ControlInput::dt):
  /// no joint is asked to cover more than v_max dt, however short the cycle.
  const CycleReport& step(double now, double dt) noexcept;

  const CycleReport& report() const { return report_; }
  /// The measured positions the last computed cycle used.
  const Eigen::VectorXd& measuredPositions() const { return q_measured_; }
  /// The last command (positions at the end of the cycle, velocities over it). The positions are where
  /// the robot is expected next (KinematicPort: its next measured state); body-schema placement checks use them.
  const Eigen::VectorXd& commandedPositions() const { return q_command_; }
  const Eigen::VectorXd& commandedVelocities() const { return qdot_command_; }
  /// The joints this controller drives (arm joints, then walking joints), q indices, model order kept per group.
  const std::vector<int>& drivenJoints() const { return driven_; }
  const Model& model() const { return model_; }
  const ControllerModel& controllerModel() const { return cm_; }
  ControllerData& data() { return data_; }
  const ControllerData& data() const { return data_; }
  const OnboardOptions& options() const { return options_; }
  /// The body-schema slot a name holds (data().dist.slots[s].name), -1 if none (and for "").
  int slotOf(const std::string& name) const noexcept;

 private:
  void fillReport(ControlResult result) noexcept;
  void reject(RejectCause cause) noexcept;
  /// True if `segment` (robot or body-schema slot) is on a link that arm `arm`'s joints move.
  bool segmentMovesWithArm(int segment, int arm) const noexcept;

  const Model& model_;
  const ControllerModel& cm_;
  RobotPort& port_;
  OnboardOptions options_;
  ControllerData data_;
  KinematicRobot integrator_;  ///< the one-cycle plant prediction (stepPlant's robot)
  WalkingPattern walking_;
  bool walk_active_ = false;
  ControlInput input_;
  MotionPriority priority_ = MotionPriority::kEqual;
  bool reset_ = false;
  double last_targets_rx_ = -1.0;
  double last_source_heartbeat_ = -1.0;
  bool stale_ = true;
  bool robot_ok_ = true;  ///< for robot_stale_events (the first missing state counts as an event)
  bool anchor_ = true;    ///< the next computed cycle anchors the last command at the measured state
  Eigen::VectorXd q_measured_, q_command_, qdot_command_, q_scratch_;
  std::vector<int> driven_;
  BodySchemaOutcome schema_outcome_;
  CycleReport report_;
};

}  // namespace reflex::control
