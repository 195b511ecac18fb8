// The reactive controller of the paper: whole-body motion (Eq. 2-5) and collision avoidance
// (Eq. 6-12) blended by the risk level f(d) (Eq. 1, 13), with merged virtual forces per arm
// (Eq. 14-18), the red-zone emergency stop (Sec. 7.1), motion priority between the arms (Sec. 7.2),
// linear trajectories to new targets (Sec. 8) and body-schema / virtual segments (Sec. 8.5).
//
// Scope of the controlled joints: like the paper's Sec. 8.1, avoidance and reaching act on the arm
// joints (five per arm on the shipped robot); legs, heel and the virtual heel->body link belong to
// walking and balance, the head to gaze. Those joints move the segments the arms avoid, but the
// controller never commands them (their output velocity is 0).
//
// Sign convention (see distance.hpp): row = nhat^T (J_pa - J_pb) is the rate of the distance, so the
// collision-avoidance task asks for row * qdot = +k (d_a - d) > 0, i.e. separation. The paper's
// Eq. 5 gradient -alpha J_row^T (d_safe - d) is written in its own y-axis convention; here it is
// +alpha_ca * row^T (d_safe - d), which increases d.
//
// Usage (Model/Data split as in pinocchio):
//   ControllerModel cm = makeControllerModel(model, loadControllerConfig(path));   // set-up, throws
//   ControllerData data(model, cm);
//   every 5 ms: computeControl(model, cm, data, q, input);  // allocation-free, never throws, no NaN
//               -> data.qdot (nq), data.arms[i] status, data.estop
//               then the plant: stepPlant (simulation.hpp) applies data.qdot and advances walking
//               only on kOk (walkingMayAdvance) and only by steps checkWalkingStep accepts
// Extending: a new criterion in the nullspace goes into the xi terms of blendControllers() in controller.cpp.
#pragma once

#include "reflex/common/error.hpp"
#include "reflex/control/distance.hpp"
#include "reflex/control/kinematics.hpp"
#include "reflex/control/model.hpp"
#include "reflex/control/redundancy.hpp"

#include <Eigen/Core>

#include <array>
#include <cstdint>
#include <stdexcept>
#include <string>
#include <vector>

namespace reflex::control {

inline constexpr int kLeft = 0;
inline constexpr int kRight = 1;

/// The controller's configuration errors are the YAML reader's: one ConfigError type in Reflex.
using ConfigError = common::ConfigError;

enum class AvoidanceMode { kOneDof, kThreeDof, kOff };
enum class Zone : std::uint8_t { kFree = 0, kYellow = 1, kOrange = 2, kRed = 3 };
enum class HandStatus : std::uint8_t { kNoTarget = 0, kGiven = 1 };
enum class MotionPriority : std::uint8_t { kEqual = 0, kLeftHigher = 1, kRightHigher = 2 };
enum class EstopState : std::uint8_t { kClear = 0, kLatched = 1, kRecovering = 2 };

/// Controller parameters; defaults are the paper's (Sec. 8) where it gives them. Every field has a
/// sane range (in brackets; an end written with another key depends on it), enforced by
/// validateControllerParams and listed with its reason by controllerParamRanges and in
/// control/README.md ("Controller parameters"). A value outside it is a ConfigError naming the file,
/// key, value and range: a configuration that validates can work.
struct ControllerParams {
  double d_a = 0.040;        ///< yellow zone boundary (m): virtual force and blending start, Eq. 6, 13. (d_b, 0.2]
  double d_b = 0.010;        ///< orange zone boundary (m): f(d) = 1 below, Eq. 13. (d_r, 0.1]
  double d_r = 0.005;        ///< red zone (m): emergency stop, Sec. 7.1. (0, 0.05]
  double period = 0.005;     ///< control period (s). [0.001, 0.1]
  double k_virtual = 5.0;    ///< virtual force gain k (1/s): separation speed k (d_a - d), Eq. 6. [0.5, 0.5/period]
  double alpha_ca = 1.0;     ///< step width of the avoidance gradient in the WBM nullspace (1/(m s)), Eq. 5. [0, 100]
  double d_safe = 0.10;      ///< d_safe of Eq. 5 (m); pairs closer than this feed the gradient. [d_a, 0.5]
  double alpha_t = 60.0;     ///< step width of target reaching in the CA nullspace (1/s), Eq. 12. [1, 1/period]
  double alpha_jla = 0.2;    ///< joint-limit-avoidance gradient step (1/s), Eq. 4. [0, 10]
  double alpha_rest = 1.5;   ///< attraction to the rest posture when a hand has no target (1/s). [0, 1/period]
  double damping = 0.02;     ///< singularity-robust inverse damping lambda (m). [0.001, 0.2]
  double reach_gain = 10.0;  ///< trajectory tracking gain (1/s). [1, 1/period]
  double max_task_speed = 0.6;  ///< task-space speed limit of the reaching task (m/s). [0.05, 2]
  double trajectory_speed =
      0.35;                  ///< speed of the linear trajectory to a new target (m/s), Sec. 8. [0.01, max_task_speed]
  double guard_rate = 50.0;  ///< safety filter: max approach speed per metre above the floor (1/s). [1, 0.5/period]
  double guard_margin = 0.001;          ///< safety filter floor above d_r (m). [0, d_b - d_r)
  double estop_release_margin = 0.001;  ///< recovery ends when every pair is above d_r + this (m). [0, d_b - d_r]
  /// Predictive guard (not in the paper): the commanded step is checked at the configuration it
  /// leads to, and shortened until no physical pair ends below d_r + predict_margin closer than it
  /// is now (or than holding the arms still would leave it). Below guard_margin, it acts only where
  /// the first-order filter above leaves a gap. (m) [0, d_b - d_r)
  double predict_margin = 0.0005;
  AvoidanceMode mode = AvoidanceMode::kOneDof;
  /// The red-zone emergency stop (Sec. 7.1), a switch of its own: `mode = kOff` (no avoidance) keeps
  /// it. Not read from the controller YAML: only a program sets it false (reflex_controller
  /// --disable-estop, reflex_sim --no-avoidance for the paper's comparison plots).
  bool estop = true;
};

/// The sane range of one numeric parameter, evaluated for a given set of parameters (ends that
/// depend on other keys, e.g. k_virtual <= 0.5 / period, carry the other keys' current values).
struct ParamRange {
  const char* key;
  double value;  ///< the parameter's value in the set it was evaluated for
  double lo;
  bool lo_open;         ///< true: value > lo; false: value >= lo
  std::string lo_text;  ///< how the lower end is written ("0.001", "d_r", "d_b - d_r")
  double hi;
  bool hi_open;
  std::string hi_text;
  const char* unit;
  const char* why;                ///< the reason for the range, one sentence
  bool contains(double v) const;  ///< finite and inside the range
  std::string describe() const;   ///< e.g. "[0.5, 0.5 / period = 100] 1/s"
};

/// Every numeric ControllerParams field with its range, in the order validateControllerParams checks them.
std::vector<ParamRange> controllerParamRanges(const ControllerParams& params);

/// The field of `params` that the numeric YAML key `key` sets (the names of controllerParamRanges),
/// nullptr for any other key. The one key-to-field table: loadControllerConfig reads through it.
double* controllerParamField(ControllerParams& params, const std::string& key);

/// One arm as the configuration names it.
struct ArmConfig {
  std::string name;
  std::vector<std::string> joints;  ///< controlled joints, shoulder to wrist
  std::string hand_link;
  Eigen::Vector3d hand_point_L = Eigen::Vector3d::Zero();  ///< reaching point in the hand link frame
  std::vector<double> rest;                                ///< rest posture (rad), one per joint
};

struct ControllerConfig {
  ControllerParams params;
  std::array<ArmConfig, 2> arms;  ///< [kLeft], [kRight]
  /// The head camera's link: where the gaze line of the occlusion experiment starts (Sec. 8.5.2,
  /// reflex_sim). Checked by whoever uses it (a scenario names it if the robot lacks it).
  std::string camera_link = "head_camera";
  std::string source = "<defaults>";
};

/// Defaults for the shipped asimo_like robot.
ControllerConfig defaultControllerConfig();

/// Reads a YAML file on top of the defaults. Throws ConfigError naming the file, key and bad value.
ControllerConfig loadControllerConfig(const std::string& yaml_path);

/// `<URDF without extension>.controller.yaml` (the robot's own controller configuration, beside it
/// like its collision configuration).
std::string defaultControllerConfigPath(const std::string& urdf_path);

/// The one rule by which every process taking `--urdf URDF [--controller FILE]` finds its controller
/// configuration (reflex_controller, reflex_sim, reflex_view, reflex_scene, reflex_record's scene
/// channels, bench_soak): FILE if given (a FILE that does not exist is a ConfigError naming it and
/// --controller); else defaultControllerConfigPath(URDF) if anything exists there (read and checked like
/// any other); else the defaults (the shipped asimo_like robot's arms; source "<defaults>").
ControllerConfig loadControllerConfigFor(const std::string& urdf_path, const std::string& yaml_path);

/// For a process banner: which configuration loadControllerConfigFor used and the arms it names, e.g.
/// "controller configuration bringup/robots/small_humanoid.controller.yaml (beside the URDF): arm left
/// to hand 'l_hand' (6 joints), arm right to hand 'r_hand' (6 joints)", or "controller configuration:
/// built-in defaults (no r.controller.yaml beside the URDF): ...".
std::string describeControllerConfig(const ControllerConfig& config, const std::string& urdf_path);

/// Checks every parameter against its range (controllerParamRanges, in table order). Throws
/// ConfigError "<source>: <key> = <value> is outside its range <range> <unit>: <why>".
void validateControllerParams(const ControllerParams& params, const std::string& source);

/// The configuration resolved against a robot model (immutable).
struct ControllerModel {
  struct Arm {
    std::string name;
    int n = 0;                        ///< number of controlled joints
    std::array<int, kMaxArmDof> q{};  ///< their q indices
    int hand_link = -1;
    Eigen::Vector3d hand_point_L = Eigen::Vector3d::Zero();
    Eigen::Matrix<double, kMaxArmDof, 1> rest = Eigen::Matrix<double, kMaxArmDof, 1>::Zero();
    std::vector<bool> link_in_arm;     ///< per link: moved by this arm's joints
    std::uint64_t segment_mask = 0;    ///< robot segments moved by this arm
    std::vector<int> candidate_pairs;  ///< pairs that involve this arm (or a body-schema slot)
  };
  ControllerParams params;
  std::array<Arm, 2> arms;
  /// Which arm moves each link: kLeft, kRight or -1 (neither; the left arm wins if both configured
  /// chains contain the link). Computed once here; a body-schema slot belongs to its link's arm.
  std::vector<int> link_owner;
  /// Which arm moves each robot segment (link_owner of its link), per index < num_robot_segments.
  std::vector<int> segment_owner;
  /// The distance broad phase (DistanceOptions::prune_distance): pairs whose bounding spheres are
  /// farther apart than max(d_safe, d_a) (d_b for the walking guard) are not computed exactly, as
  /// they take part in no term; and the predictive guard predicts only the pairs whose distance minus
  /// the most their links can move in one step is below its floor. The control output is the same
  /// either way (tested bit for bit); false (only a program sets it: tests, benchmarks) computes
  /// every pair exactly and predicts every physical pair an arm moves.
  bool broad_phase = true;
};

/// Resolves names against the model. Throws ConfigError for unknown joints/links, wrong rest size,
/// an arm with more than kMaxArmDof joints, joints shared between arms, or a model with more than
/// kMaxSegments segments (naming the count and the limit).
ControllerModel makeControllerModel(const Model& model, const ControllerConfig& config);

/// The rest configuration: zeros (clamped to limits) with the arms at their rest postures.
Eigen::VectorXd restConfiguration(const Model& model, const ControllerModel& cm);

/// Throws ConfigError (prefixed with `source`) when the rest posture (restConfiguration: the arms'
/// rest, every other joint at 0 clamped to its limits) has a pair closer than d_r +
/// estop_release_margin: the e-stop would latch whenever the arms rest, and for a pair no arm moves
/// (the feet, the thighs) never release. makeControllerModel calls it; a configuration with
/// params.estop false is not checked (no e-stop to latch).
void checkRestPostureClearOfRedZone(const Model& model, const ControllerModel& cm, const std::string& source);

struct HandCommand {
  HandStatus status = HandStatus::kNoTarget;
  Eigen::Vector3d target_B = Eigen::Vector3d::Zero();  ///< hand target in the root frame (m)
};

struct ControlInput {
  std::array<HandCommand, 2> hands;
  MotionPriority priority = MotionPriority::kEqual;
  bool reset_estop = false;  ///< request to leave a latched e-stop (only separating motion allowed)
  /// s the cycle spans when it is shorter than ControllerParams::period (a cycle per arriving robot
  /// state, e.g. 2 ms at 500 Hz): the trajectory advances and the velocity of the joints the
  /// controller does not command is estimated over it. Anything not in (0, period] (0 by default,
  /// NaN) means one period. Every other use of the period (the guard's look-ahead, the joint-range
  /// limit) keeps the full period: with a shorter cycle they only look further ahead than needed.
  double dt = 0.0;
};

struct ArmStatus {
  double f = 0.0;                                             ///< blending coefficient f(d), Eq. 13
  double distance = std::numeric_limits<double>::infinity();  ///< closest distance of this arm (m)
  int closest_pair = -1;                                      ///< index into Model::pairs
  Zone zone = Zone::kFree;
  double force = 0.0;                                       ///< |F_virtual^all| (m/s), Eq. 17
  Eigen::Vector3d force_dir_B = Eigen::Vector3d::Zero();    ///< unit direction of F^all
  Eigen::Vector3d force_point_B = Eigen::Vector3d::Zero();  ///< P_cp1^all, Eq. 18
  Eigen::Vector3d hand_B = Eigen::Vector3d::Zero();
  Eigen::Vector3d reference_B = Eigen::Vector3d::Zero();  ///< point on the linear trajectory
  /// The virtual-force term of the collision controller alone (rad/s, the arm's joints in
  /// ControllerModel::Arm::q order): row^+ |F^all| (Eq. 8 with the merged force of Eq. 17-18; in
  /// three_dof mode J_ca^+ F^all), before blending (Eq. 1), the safety filter and the limits. Zero
  /// when no pair of the arm is inside the yellow zone, and during a latched e-stop.
  ArmVector qdot_force;
};

/// Per-arm linear trajectory state (Sec. 8).
struct Trajectory {
  bool active = false;
  Eigen::Vector3d goal_B = Eigen::Vector3d::Zero();
  Eigen::Vector3d ref_B = Eigen::Vector3d::Zero();
};

enum class ControlResult { kOk, kFrozen, kRecovering, kBadInput };

/// Sum of the virtual forces acting on one arm (Eq. 14-18), accumulated pair by pair.
struct VirtualForceSum {
  Eigen::Vector3d weighted_force = Eigen::Vector3d::Zero();  ///< sum |F_ij| F_ij
  Eigen::Vector3d weighted_point = Eigen::Vector3d::Zero();  ///< sum |F_ij| P_cp1,ij
  double weight = 0.0;                                       ///< sum |F_ij|

  /// Adds the pair force F_ij = k (d_a - d_ij) e_ij (Eq. 14) applied at p_cp1 (nothing if d >= d_a).
  /// e_ij is the unit direction from the other segment towards the arm (Eq. 16).
  void add(double k, double d_a, double d, const Eigen::Vector3d& e, const Eigen::Vector3d& p_cp1);
  /// F_virtual^all (Eq. 17); zero if no pair contributed.
  Eigen::Vector3d force() const;
  /// P_cp1^all (Eq. 18); zero if no pair contributed.
  Eigen::Vector3d point() const;
};

/// The working state of one arm through the stages of one cycle (controller.cpp, computeArm):
/// trajectory -> pair terms -> merged avoidance Jacobian -> WBM / CA / blend -> joint position
/// limits -> safety filter -> velocity scaling -> step cap. Each stage reads what the earlier ones
/// wrote. The pair lists hold one entry per candidate pair of the arm at most: ControllerData sizes
/// them from ControllerModel::Arm::candidate_pairs at set-up, so no pair is ever dropped.
/// Arm-joint quantities are in ControllerModel::Arm::q order (rad, rad/s); points in B (m).
struct ArmWorkspace {
  /// One pair inside the yellow zone: its share of the merged force (Eq. 14-18).
  struct ForceTerm {
    int pair = -1;        ///< index into Model::pairs
    int side = 1;         ///< +1: the arm's point is p_B_a (force along +nhat_B); -1: p_B_b
    double weight = 0.0;  ///< |F_ij| = k (d_a - d_ij) (m/s)
  };
  // trajectory stage
  ArmVector q;                                                ///< the arm's joint positions
  Eigen::Vector3d hand_B = Eigen::Vector3d::Zero();           ///< reaching point
  TaskJacobian J_hand;                                        ///< 3 x n Jacobian of hand_B
  Eigen::Vector3d hand_velocity_B = Eigen::Vector3d::Zero();  ///< task velocity of Eq. 2 (m/s)
  bool target_given = false;                                  ///< the hand follows a target this cycle
  // pair-term stage
  std::vector<ForceTerm> force_terms;  ///< pairs inside the yellow zone; first num_force_terms valid
  int num_force_terms = 0;
  std::vector<int> guarded_pairs;  ///< pairs inside the orange zone with a row (safety filter)
  int num_guarded = 0;
  std::vector<double> other_rate;  ///< per guarded pair: rate of d from everything but this arm (m/s)
  double other_approach = 0.0;     ///< max over the guarded pairs of -other_rate, at least 0 (m/s)
  VirtualForceSum forces;
  ArmRow avoidance_gradient;  ///< sum of row (d_safe - d) over pairs within d_safe (Eq. 5)
  /// Eq. 5 summed per link (collectPairTerms): the links touched this cycle (first num_grad_links),
  /// and per touched link the sums of +-(d_safe - d) (p x n) and +-(d_safe - d) n over its pairs.
  std::vector<int> grad_link;
  std::vector<Eigen::Vector3d> grad_M, grad_N;
  int num_grad_links = 0;
  double d_other_arm = 0.0;  ///< closest contact with the other arm (m)
  double d_static = 0.0;     ///< closest contact with what no arm moves (m)
  // merged-Jacobian stage (Eq. 17-18)
  TaskJacobian J_avoid;                                   ///< weighted relative Jacobian of the force pairs (3 x n)
  double force_magnitude = 0.0;                           ///< |F^all| (m/s)
  Eigen::Vector3d force_dir_B = Eigen::Vector3d::Zero();  ///< unit direction of F^all
  // blend stage and after
  ArmVector qdot;        ///< the arm's joint velocities, refined stage by stage
  ArmVector v_lo, v_hi;  ///< velocity box that keeps the step inside the joint range
};

/// What one pair is to one arm in the pair-term stage (collectPairTerms). For a robot pair it is
/// fixed by the models, so ControllerData sets it up once and the per-pair pass reads this one
/// small record instead of the segments, the owners and the column masks (a chain of dependent
/// loads per pair); a body-schema slot's pair gets it each cycle (its link can change).
struct ArmPairFacts {
  enum Flag : std::uint8_t {
    kInvolved = 1,  ///< the arm moves one of the pair's segments (else the pair is not the arm's)
    kOtherArm = 2,  ///< the other segment is the other arm's
    kStatic = 4,    ///< the other segment is moved by no arm
    kMovesA = 8,    ///< an arm joint moves seg_a's link (Eq. 5's gradient has a term there)
    kMovesB = 16,   ///< ... seg_b's link
  };
  std::int32_t link_a = -1, link_b = -1;  ///< the links of seg_a, seg_b
  std::uint8_t flags = 0;
  std::int8_t side = 1;  ///< the side of the arm's virtual force: +1 at p_B_a along +nhat_B, -1 at p_B_b
};

/// Per-cycle state and scratch, sized from the model.
struct ControllerData {
  ControllerData(const Model& model, const ControllerModel& cm);

  KinematicsData kin;
  DistanceData dist;
  Eigen::VectorXd qdot;  ///< output joint velocities (nq); non-arm joints are 0
  std::array<ArmStatus, 2> arms;
  std::array<Trajectory, 2> trajectories;
  EstopState estop = EstopState::kClear;
  int estop_pair = -1;  ///< pair that triggered the last e-stop
  std::uint64_t estop_count = 0;
  /// This cycle's closest physical pair (the red-zone test's; virtual slots never count), closest
  /// pair with a virtual slot, and closest robot pair between a left-arm and a right-arm segment (the
  /// paper's Fig. 13), from data.dist, exact also where the broad phase skipped pairs. Written
  /// whenever the distances are computed (not on kBadInput): callers read them instead of rescanning.
  ClosestPair closest_physical, closest_virtual, closest_between_arms;
  /// Per arm, its closest pair [0] of every pair the arm moves, [1] without the other arm's (what the
  /// arm avoids when it has motion priority), found with the three above (ArmStatus takes one).
  std::array<std::array<ClosestPair, 2>, 2> arm_closest;
  std::uint64_t bad_input_count = 0;
  /// Predictive guard: how many cycles shortened the commanded step.
  std::uint64_t guard_count = 0;
  /// Walking guard (checkWalkingStep): how many walking steps were held.
  std::uint64_t walking_hold_count = 0;
  /// Velocity of the joints the controller does not command (walking, balance, gaze), estimated
  /// from the previous cycle's measured q; zero on the first cycle.
  Eigen::VectorXd qdot_uncontrolled;
  Eigen::VectorXd q_prev;
  bool have_prev = false;
  std::vector<char> arm_joint;  ///< per q index: commanded by one of the arms
  /// Per arm, per link: bit i set if the arm's joint i (ControllerModel::Arm::q[i]) moves the link
  /// (lies on its support path), so a point Jacobian restricted to the arm's columns needs no nq-wide
  /// scratch.
  std::array<std::vector<std::uint64_t>, 2> arm_columns_of_link;
  /// Per q index: how far a point of the robot moves at most per unit of that joint (m/rad, or 1 for
  /// a prismatic joint): the longest path from the joint to a segment surface below it.
  Eigen::VectorXd lever;
  /// Predictive guard scratch, per link: the most any point of it moves in this cycle's step (m).
  std::vector<double> link_sweep;
  /// The robot pairs between a left-arm and a right-arm segment, ascending.
  std::vector<int> between_arm_pairs;
  /// Per arm, per robot pair (index into Model::pairs; a body-schema slot's pair's entry is unused).
  std::array<std::vector<ArmPairFacts>, 2> arm_pair_facts;
  /// Per link: its index in ArmWorkspace::grad_link while collectPairTerms runs, else -1.
  std::vector<int> grad_link_index;
  /// Predictive guard scratch: the pairs its predictions compute (first num_guard_pairs valid; 0
  /// when the guard did not predict this cycle).
  std::vector<int> guard_pairs;
  int num_guard_pairs = 0;
  /// ... how far the step can move each of them (the two segments' sweeps together, m), and their
  /// primitive pairs that can come within the guard's floor at any scale of the step, listed once a
  /// cycle for all its predictions (with the broad phase).
  std::vector<double> guard_reach;
  PairListing guard_listing;
  // scratch of the predictive guard: the configuration one step ahead
  Eigen::VectorXd q_next;
  KinematicsData kin_next;
  DistanceData dist_next;
  DistanceData dist_hold;  ///< arms held still, only the uncontrolled joints moving
  // scratch
  ArmWorkspace arm_ws;     ///< one arm's cycle (reused by both arms)
  Eigen::MatrixXd J_full;  ///< 3 x nq
};

/// The blending coefficient of Eq. 13.
double blendingCoefficient(double d, double d_a, double d_b);

/// The zone of a distance.
Zone zoneOf(double d, const ControllerParams& params);

/// One control cycle: kinematics, every pair, both controllers, blend, e-stop. Writes data.qdot.
/// Allocation-free; never throws; data.qdot is always finite (zero on bad input or e-stop).
ControlResult computeControl(const Model& model, const ControllerModel& cm, ControllerData& data,
                             const Eigen::Ref<const Eigen::VectorXd>& q, const ControlInput& input);

/// The plant's contract for motion the controller does not command (walking, balance): it may
/// advance only when the cycle's result is kOk. While the e-stop is latched (kFrozen) or recovering
/// (kRecovering: only motion that separates every pair below d_r is allowed, and the legs cannot be
/// asked to separate), or the input was bad (kBadInput), it holds. stepPlant (simulation.hpp) keeps it.
inline bool walkingMayAdvance(ControlResult result) { return result == ControlResult::kOk; }

/// True if segment s (a robot segment, or a body-schema slot by its link) is moved by neither arm:
/// a pair of two such segments cannot be changed by any arm motion.
bool isArmIndependent(const Model& model, const ControllerModel& cm, const ControllerData& data, int s);

/// Walking guard. q_next: the robot's configuration after this cycle's arm step
/// with the walking joints moved by the walking step under test. Returns false if, at q_next, some
/// physical pair that no arm can move (both segments arm-independent: a body-schema segment on the
/// root, body, chest, head or legs against the trunk or the legs) would end below
/// d_r + predict_margin AND closer than it is this cycle (data.dist): the arms cannot take such a
/// pair apart, so walking must not close it. Call after computeControl returned kOk; uses
/// data.kin_next / data.dist_next as scratch. Allocation-free; never throws; false for a non-finite q_next.
bool checkWalkingStep(const Model& model, const ControllerModel& cm, ControllerData& data,
                      const Eigen::Ref<const Eigen::VectorXd>& q_next);

/// Body-schema placement check for a PHYSICAL segment just attached to `slot`:
/// the index of a pair between it and a segment such that no arm can move either of them, whose
/// distance at configuration q is below d_r + estop_release_margin; -1 if none (or the slot is
/// disabled or on a link an arm moves). Such a segment would latch the e-stop at once and no arm
/// motion could ever release it: the caller refuses it (detaches it again, names it and counts it).
/// Uses data.kin_next / data.dist_next as scratch; allocation-free; -1 for a non-finite q.
int findUnresolvableContact(const Model& model, const ControllerModel& cm, ControllerData& data, int slot,
                            const Eigen::Ref<const Eigen::VectorXd>& q);

/// What attachControllerSegment did.
struct SegmentAttach {
  bool attached = false;
  int refusing_pair = -1;  ///< the pair findUnresolvableContact found (refused), else -1
  int other_segment = -1;  ///< its segment other than the slot
  double distance = 0.0;   ///< its distance (m)
};

/// Attaches a body-schema segment for the controller (reflex_controller and the scenarios use it):
/// attachBodySchemaSegment (endpoints in the link frame, m), then, for a physical segment,
/// findUnresolvableContact at q. A refused segment leaves the slot exactly as it was; an attached
/// one sets data.dist.slots[slot].is_virtual. Bad arguments (slot, link, non-finite values): not attached,
/// refusing_pair -1. Allocation-free; never throws.
SegmentAttach attachControllerSegment(const Model& model, const ControllerModel& cm, ControllerData& data, int slot,
                                      int link, const Eigen::Vector3d& a_L, const Eigen::Vector3d& b_L, double radius,
                                      std::uint64_t ignore_mask, bool is_virtual,
                                      const Eigen::Ref<const Eigen::VectorXd>& q);

}  // namespace reflex::control
