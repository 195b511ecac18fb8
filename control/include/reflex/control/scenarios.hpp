// The paper's experiments as simulation scenarios (Sec. 8.2, 8.3, 8.5) and the runner that drives
// the controller with the kinematic robot. Used by reflex_sim, the experiment tests and benchmarks.
#pragma once

#include "reflex/control/controller.hpp"
#include "reflex/control/simulation.hpp"

#include <Eigen/Core>

#include <functional>
#include <ostream>
#include <string>
#include <vector>

namespace reflex::control {

/// What a scenario script may do each cycle besides setting the hand commands.
struct ScenarioContext {
  const Model& model;
  ControllerData& data;
  const ControllerModel& cm;
  const Eigen::VectorXd& q;          ///< the robot's current configuration
  /// Attaches a capsule to a link (body schema, Sec. 8.5.1) or, with is_virtual, a virtual segment
  /// (occlusion, Sec. 8.5.2). Endpoints in the link frame. Throws ConfigError naming a link or an
  /// ignored segment the robot does not have. Returns false for other bad arguments, and for a
  /// physical segment that findUnresolvableContact refuses (it overlaps, within d_r +
  /// estop_release_margin, a segment that no arm can move away from it; the slot stays as it was).
  bool attach(int slot, const std::string& link, const Eigen::Vector3d& a_L, const Eigen::Vector3d& b_L,
              double radius, bool is_virtual, const std::vector<std::string>& ignore = {});
  void detach(int slot);
};

struct Scenario {
  std::string name;
  std::string description;
  std::string paper;                 ///< section / figure it reproduces
  double duration = 5.0;             ///< seconds
  double walk_distance = 0.0;        ///< metres walked forward from t = walk_start
  double walk_speed = 0.0;
  double walk_start = 0.0;
  /// Sets the hand commands (and body schema) at time t. Called every cycle before the controller.
  std::function<void(double t, ControlInput& input, ScenarioContext& ctx)> script;
};

struct SimOptions {
  AvoidanceMode mode = AvoidanceMode::kOneDof;
  bool estop = true;                 ///< the red-zone e-stop (a switch of its own: mode kOff keeps it)
  bool record = true;                ///< keep one SimSample per cycle
};

struct SimSample {
  double t = 0.0;
  std::array<ArmStatus, 2> arms;
  std::array<HandCommand, 2> commands;
  EstopState estop = EstopState::kClear;
  double min_distance = 0.0;         ///< closest physical pair (m)
  int min_pair = -1;
  double virtual_distance = 0.0;     ///< closest pair with a virtual segment (m), +inf if none
  double arm_distance = 0.0;         ///< closest pair between the two arms (m), the paper's Fig. 13
  double wall_time = 0.0;            ///< system clock (s since the epoch) when logged by a process; 0 in simulation
  Eigen::VectorXd q;
  Eigen::VectorXd qdot;
};

struct SimResult {
  std::vector<SimSample> samples;
  double min_distance = 0.0;         ///< over the run, physical pairs
  double min_time = 0.0;
  int min_pair = -1;
  double min_virtual_distance = 0.0;
  bool estop_fired = false;
  std::uint64_t guard_cycles = 0;    ///< cycles whose step the predictive guard shortened
  std::uint64_t walking_holds = 0;   ///< walking steps the walking guard held (checkWalkingStep)
  bool non_finite = false;           ///< a NaN/Inf reached the robot (must never happen)
  double max_joint_speed_ratio = 0.0;  ///< max over cycles and joints of |qdot_i| / v_max_i (commanded) and
                                       ///< |dq_i| / (v_max_i dt) (what the plant did, walking joints included)
  std::array<double, 2> reach_time{{-1.0, -1.0}};  ///< first time within 1 cm of the final target, -1 never
  std::array<double, 2> final_error{{0.0, 0.0}};   ///< |hand - target| at the end (m)
  std::uint64_t cycles = 0;
};

/// Runs a scenario from the robot's rest posture. Throws ConfigError if the scenario refers to
/// names the model does not have.
SimResult runScenario(const Model& model, const ControllerModel& cm, const Scenario& scenario,
                      const SimOptions& options = {});

/// The rest configuration: zeros (clamped to limits) with the arms at their rest postures.
Eigen::VectorXd restConfiguration(const Model& model, const ControllerModel& cm);

/// The built-in scenarios (the paper's experiments), for reflex_sim --list.
const std::vector<Scenario>& builtinScenarios();
const Scenario* findScenario(const std::string& name);

/// The closest distance between a segment of the left arm and one of the right arm (m), +inf if none:
/// data.closest_between_arms of the last computeControl (the pairs are not scanned again).
double armToArmDistance(const Model& model, const ControllerModel& cm, const ControllerData& data);

/// Writes the time series as CSV: header row, one row per cycle.
void writeTimeseriesCsv(const Model& model, const ControllerModel& cm, const SimResult& result,
                        const std::string& path);

/// The CSV header row of writeTimeseriesCsv (with its newline), and one data row: the pieces a
/// streaming writer (reflex_controller --log) uses. Stream errors are left in `out`'s state.
void writeTimeseriesCsvHeader(const Model& model, std::ostream& out);
void writeTimeseriesCsvRow(const Model& model, const SimSample& sample, std::ostream& out);

}  // namespace reflex::control
