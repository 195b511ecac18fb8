// The paper's experiments as simulation scenarios (Sec. 8.2, 8.3, 8.5) and the runner that drives
// the controller with a plant: the in-process kinematic robot (simulated time), or any robot behind a
// RobotPort in real time (ScenarioPlant; reflex_sim --robot mujoco|dds, whose plant over DDS lives in
// control/node: this library never links DDS). Used by reflex_sim, the experiment tests and benchmarks.
#pragma once

#include "reflex/control/controller.hpp"
#include "reflex/control/onboard.hpp"
#include "reflex/control/simulation.hpp"

#include <Eigen/Core>

#include <array>
#include <cstdint>
#include <functional>
#include <optional>
#include <ostream>
#include <string>
#include <vector>

namespace reflex::control {

/// A robot's frame of reference for the scenarios: landmarks measured on the
/// model at the rest posture (restConfiguration), in the base frame B (metres). The seven scenarios
/// are written in the coordinates of the reference robot (asimo_like: floor, x forward, y left, z up);
/// place() carries a point from there to this robot through its landmarks, so a target at the
/// reference robot's chest lands at this robot's chest, one arm length in front of the reference
/// shoulders lands one arm length in front of this robot's shoulders, and so on.
struct ScenarioFrame {
  std::array<Eigen::Vector3d, 2> shoulder;          ///< [kLeft], [kRight]: origin of the arm's first joint
  Eigen::Vector3d chest = Eigen::Vector3d::Zero();  ///< midpoint of the two shoulders
  double half_width = 0.0;                          ///< half the shoulder-to-shoulder distance
  int trunk_segment = -1;                           ///< the segment the arms hang from (asimo_like: chest)
  double trunk_half_width = 0.0;                    ///< half its width (extent of its primitives to the left)
  double arm_length = 0.0;                          ///< shoulder -> hand point along the chain (joint origins,
                                                    ///< then the hand point): the straight arm's reach
  std::array<Eigen::Vector3d, 2> hand_rest;         ///< hand points at the rest posture
  /// The scales of place(): forward and up by arm_length, sideways by trunk_half_width, each over
  /// the reference robot's. Exactly 1 (and place() the identity, bit for bit) on the reference robot.
  Eigen::Vector3d scale = Eigen::Vector3d::Ones();
  /// The robot's forward, left and up in its root frame (the columns; identity on a robot whose root
  /// is x forward, y left, z up, REP 103): left is the direction from the right shoulder to the left
  /// one, level; up is the root's z. A robot facing its -x (iCub) gets a half turn about z.
  Eigen::Matrix3d axes = Eigen::Matrix3d::Identity();
  bool reference = false;  ///< this robot's landmarks are the reference robot's (1 nm)

  /// A point of the reference robot's scenario coordinates on this robot, about the chest:
  /// chest + axes * (scale * (p - chest_ref)). For what is about the body: inside it, across its midline.
  Eigen::Vector3d place(const Eigen::Vector3d& p_ref) const;
  /// A length of the reference robot (a bar, a reach) on this robot: times scale.x() (arm lengths).
  double length(double l_ref) const;
};

/// The reference robot's landmarks (asimo_like at its default controller configuration's rest
/// posture; measured by scenarioFrame and written here to 17 digits; the experiments test checks they
/// still agree with the shipped robot).
ScenarioFrame referenceScenarioFrame();

/// Measures a robot's landmarks at restConfiguration(model, cm).
ScenarioFrame scenarioFrame(const Model& model, const ControllerModel& cm);

/// What a scenario script may do each cycle besides setting the hand commands.
struct ScenarioContext {
  const Model& model;
  ControllerData& data;
  const ControllerModel& cm;
  const Eigen::VectorXd& q;  ///< the robot's current configuration
  /// Attaches a capsule to a link (body schema, Sec. 8.5.1) or, with is_virtual, a virtual segment
  /// (occlusion, Sec. 8.5.2). Endpoints in the link frame. Throws ConfigError naming a link or an
  /// ignored segment the robot does not have. Returns false for other bad arguments, and for a
  /// physical segment that findUnresolvableContact refuses (it overlaps, within d_r +
  /// estop_release_margin, a segment that no arm can move away from it; the slot stays as it was).
  bool attach(int slot, const std::string& link, const Eigen::Vector3d& a_L, const Eigen::Vector3d& b_L, double radius,
              bool is_virtual, const std::vector<std::string>& ignore = {});
  void detach(int slot);
  /// The camera link the gaze line starts at (occlusion, Sec. 8.5.2): the controller configuration's
  /// camera_link (ControllerConfig::camera_link, default head_camera).
  std::string camera_link = "head_camera";
  /// This robot's frame of reference (measured once, at the rest posture, on first use).
  const ScenarioFrame& frame();
  /// The link with collision geometry that carries `link` (itself, or its nearest ancestor with a
  /// segment; fixed sensor frames are carried by what they are fixed to), -1 if none.
  int carrierSegment(int link) const;
  /// A target the scenario means `arm` to reach (p_B, placed on this robot): p_B itself if the arm
  /// can put its hand point there within its joint limits (damped least squares from the rest
  /// posture, 2 mm); else the point 90 % of the way from the hand's rest point to the farthest point
  /// towards p_B it can reach (a robot's joint limits differ from the reference robot's: the mesh
  /// humanoid's shoulder rolls 0.2 rad inwards). Computed once per target (not on the control path).
  Eigen::Vector3d reachable(int arm, const Eigen::Vector3d& p_B);
  std::optional<ScenarioFrame> frame_cache{};                    ///< filled by frame()
  std::vector<std::array<Eigen::Vector3d, 2>> reach_cache[2]{};  ///< filled by reachable(): {asked, answer}
};

struct Scenario {
  std::string name;
  std::string description;
  std::string paper;           ///< section / figure it reproduces
  double duration = 5.0;       ///< seconds
  double walk_distance = 0.0;  ///< metres walked forward from t = walk_start
  double walk_speed = 0.0;
  double walk_start = 0.0;
  /// Sets the hand commands (and body schema) at time t. Called every cycle before the controller.
  std::function<void(double t, ControlInput& input, ScenarioContext& ctx)> script;
};

struct SimOptions {
  AvoidanceMode mode = AvoidanceMode::kOneDof;
  bool estop = true;                        ///< the red-zone e-stop (a switch of its own: mode kOff keeps it)
  bool record = true;                       ///< keep one SimSample per cycle
  std::string camera_link = "head_camera";  ///< ScenarioContext::camera_link (ControllerConfig::camera_link)
};

struct SimSample {
  double t = 0.0;
  std::array<ArmStatus, 2> arms;
  std::array<HandCommand, 2> commands;
  EstopState estop = EstopState::kClear;
  double min_distance = 0.0;  ///< closest physical pair (m)
  int min_pair = -1;
  double virtual_distance = 0.0;  ///< closest pair with a virtual segment (m), +inf if none
  double arm_distance = 0.0;      ///< closest pair between the two arms (m), the paper's Fig. 13
  double wall_time = 0.0;         ///< system clock (s since the epoch) when logged by a process; 0 in simulation
  Eigen::VectorXd q;              ///< the configuration this cycle computed from (measured by the plant)
  Eigen::VectorXd qdot;
  bool commanded = true;      ///< a command was sent this cycle (false: no usable robot state)
  Eigen::VectorXd q_command;  ///< the command's end-of-cycle positions (nq; the last one if !commanded)
};

/// The time-series row of one step, the fields every writer takes from the cycle (reflex_controller
/// --log, reflex_sim's timeseries.csv): time, arms, e-stop, closest pairs, joint velocities. The
/// caller sets what differs: the hand commands, min_distance (the log writes IDL's "no pair" value for
/// none), q, wall_time, commanded, q_command. Allocation-free once `s` has held a row of this model.
inline void recordCycle(SimSample& s, double t, const ControllerData& data, const CycleReport& rep) {
  s.t = t;
  s.arms = data.arms;
  s.estop = data.estop;
  s.min_distance = rep.min_distance;
  s.min_pair = rep.min_pair;  // the --log min_pair column (empty in older logs)
  s.virtual_distance = rep.virtual_distance;
  s.arm_distance = rep.arm_distance;
  s.qdot = data.qdot;
}

struct SimResult {
  std::vector<SimSample> samples;
  double min_distance = 0.0;  ///< over the run, physical pairs
  double min_time = 0.0;
  int min_pair = -1;
  double min_virtual_distance = 0.0;
  bool estop_fired = false;
  std::uint64_t guard_cycles = 0;        ///< cycles whose step the predictive guard shortened
  std::uint64_t walking_holds = 0;       ///< walking steps the walking guard held (checkWalkingStep)
  bool non_finite = false;               ///< a NaN/Inf reached the robot (must never happen)
  double max_joint_speed_ratio = 0.0;    ///< max over cycles and joints of |qdot_i| / v_max_i (commanded) and
                                         ///< |dq_i| / (v_max_i dt) (what the plant did, walking joints included)
  double max_command_speed_ratio = 0.0;  ///< max over cycles and joints of |qdot_i| / v_max_i (commanded only)
  std::array<double, 2> reach_time{{-1.0, -1.0}};  ///< first time within 1 cm of the final target, -1 never
  std::array<double, 2> final_error{{0.0, 0.0}};   ///< |hand - target| at the end (m)
  std::uint64_t cycles = 0;
  std::uint64_t robot_stale_cycles = 0;  ///< cycles without a usable robot state (nothing commanded)
  std::uint64_t late_cycles = 0;         ///< real-time plants: cycles that began a whole period late or more
};

/// The robot side runScenario drives. The kinematic plant (KinematicScenarioPlant) runs in simulated
/// time; a real-time plant (a robot over DDS) paces the cycles on the wall clock and reads the robot
/// between them.
class ScenarioPlant {
 public:
  virtual ~ScenarioPlant() = default;
  /// Where the controller reads the measured state and sends each cycle's command.
  virtual RobotPort& port() = 0;
  /// Waits until the cycle at scenario time t (s since the scenario began) is due and takes what the
  /// robot sent since the last call. Returns true if the cycle began a whole period late or more.
  virtual bool awaitCycle(double t, double period) = 0;
  /// The robot's newest configuration (nq, model order): what the next step() computes from if the
  /// port has a usable state. The reference stays valid for the plant's life (ScenarioContext::q).
  virtual const Eigen::VectorXd& positions() const = 0;
  /// Seconds between the states behind the last two awaitCycle calls (what the measured joint speed
  /// is taken over); the kinematic plant: exactly the period.
  virtual double stateInterval(double period) const = 0;
};

/// The in-process kinematic plant (KinematicPort) in simulated time.
class KinematicScenarioPlant final : public ScenarioPlant {
 public:
  explicit KinematicScenarioPlant(const Eigen::VectorXd& q0) : port_(q0) {}
  RobotPort& port() override { return port_; }
  bool awaitCycle(double /*t*/, double /*period*/) override { return false; }
  const Eigen::VectorXd& positions() const override { return port_.positions(); }
  double stateInterval(double period) const override { return period; }

 private:
  KinematicPort port_;
};

/// Runs a scenario from the robot's rest posture. Throws ConfigError if the scenario refers to
/// names the model does not have.
SimResult runScenario(const Model& model, const ControllerModel& cm, const Scenario& scenario,
                      const SimOptions& options = {});

/// Runs a scenario on `plant` from where the plant's robot is (plant.positions(), finite, nq). The
/// same loop as above (which is this one on a KinematicScenarioPlant at the rest configuration).
SimResult runScenario(const Model& model, const ControllerModel& cm, const Scenario& scenario,
                      const SimOptions& options, ScenarioPlant& plant);

/// How closely one arm's measured joints followed the commands. The command of
/// cycle k names the positions for the start of cycle k+1; the error of cycle k+1 is measured(k+1) -
/// command(k), over the arm's joints, over cycle pairs that both had a robot state.
struct ArmTracking {
  double max_error = 0.0;    ///< rad (largest |error| of any joint of the arm)
  double rms_error = 0.0;    ///< rad (over joints and cycles)
  double lag = 0.0;          ///< s: the shift of the commands (0 .. 0.2 s, refined between cycles by a
                             ///< parabola through the best three) that best fits the measurement
  std::uint64_t cycles = 0;  ///< cycle pairs counted
};

/// Tracking error and servo lag per arm from recorded samples (SimOptions::record). The kinematic
/// plant gives exactly 0, 0, 0 (its next measured state IS the command).
std::array<ArmTracking, 2> computeTracking(const ControllerModel& cm, const SimResult& result);

/// The built-in scenarios (the paper's experiments), for reflex_sim --list.
const std::vector<Scenario>& builtinScenarios();
const Scenario* findScenario(const std::string& name);

/// Writes the time series as CSV: header row, one row per cycle.
void writeTimeseriesCsv(const Model& model, const ControllerModel& cm, const SimResult& result,
                        const std::string& path);

/// The distance written where there is no pair (+inf in memory): in the time series and on the bus
/// (idl/control.idl's NO_PAIR_DISTANCE, the same value; control_status_test checks that they agree).
inline constexpr double kNoPairDistance = 1.0e9;

/// The CSV header row of writeTimeseriesCsv (with its newline), and one data row: the pieces a
/// streaming writer (reflex_controller --log) uses. Stream errors are left in `out`'s state.
void writeTimeseriesCsvHeader(const Model& model, std::ostream& out);
void writeTimeseriesCsvRow(const Model& model, const SimSample& sample, std::ostream& out);

}  // namespace reflex::control
