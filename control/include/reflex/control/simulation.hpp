// Kinematic simulation of the robot (first order, as the paper's system: Sec. 9.2) and a simple
// walking pattern; the robot side of a real robot is RobotPort (onboard.hpp).
//
// The controller commands joint velocities of the arms; walking writes the legs, the heel and the
// virtual heel->body link directly (the paper's walking and balancing control owns them, Sec. 8).
// stepPlant is the one plant step every loop uses: walking advances only while the controller is
// clear (never while the e-stop is latched or recovering) and never into a pair no arm can move.
#pragma once

#include "reflex/control/controller.hpp"
#include "reflex/control/model.hpp"

#include <Eigen/Core>

#include <vector>

namespace reflex::control {

/// The robot of one plant step (stepPlant), a first-order kinematic integrator: q += clamp(qdot,
/// v_max) dt, clamped to the position limits; a non-finite velocity or walking position is 0 motion.
/// No joint ever moves more than v_max dt per call. It is not a robot interface: OnboardController
/// (onboard.hpp) steps one started from the measured state as its one-cycle prediction and hands the
/// result to a RobotPort, the one way to a robot (a real robot's driver over DDS: idl/README.md,
/// "Writing a robot driver").
class KinematicRobot {
 public:
  KinematicRobot(const Model& model, const Eigen::VectorXd& q0);
  /// Joint positions (nq).
  const Eigen::VectorXd& jointPositions() const { return q_; }
  /// Applies joint velocities for one period dt.
  void command(const Eigen::Ref<const Eigen::VectorXd>& qdot, double dt);
  /// Joints owned by walking / balance, written as positions (legs, heel, virtual link): each listed
  /// joint moves towards q_walk by at most v_max dt in this period of dt seconds (never faster than
  /// its velocity limit, whatever the walking source asks for).
  void setWalkingJoints(const Eigen::Ref<const Eigen::VectorXd>& q_walk, const std::vector<int>& indices, double dt);
  void reset(const Eigen::VectorXd& q) { q_ = q; }
  /// Sets joint j's position (0 <= j < nq), as reset does for every joint.
  void setJointPosition(int j, double q) { q_[j] = q; }

 private:
  const Model& model_;
  Eigen::VectorXd q_;
};

/// A simple walking pattern: the heel moves along x at a constant speed to a goal distance, the legs
/// swing (hip pitch, knee, ankle pitch) with the step phase, the body bobs slightly; the leg motion
/// fades in and out over half a step. Joints are found by name (heel_x, {l,r}_hip_pitch, {l,r}_knee,
/// {l,r}_ankle_pitch, body_z); missing ones are skipped.
///
/// Velocity contract: whatever sequence of start / stop / restart calls arrives,
/// at any time and with any arguments, step() moves no joint by more than its v_max * dt from the q
/// it is given. A start() while walking continues the step cycle where it is (phase and leg
/// amplitude are kept; only the goal and the speed change); the heel speed is at most heel_x's
/// v_max; the leg angles follow the pattern through a rate limit of v_max.
class WalkingPattern {
 public:
  explicit WalkingPattern(const Model& model);
  /// Walks `distance` metres forward from where the heel is at the next step(), at `speed` m/s
  /// (capped at heel_x's v_max), step period `step_period` s (clamped to [kMinStepPeriod,
  /// kMaxStepPeriod]). A distance or speed that is not finite and positive stops walking (the legs
  /// fade out; nothing jumps); returns false then.
  bool start(double distance, double speed, double step_period = 0.8);
  /// Stops walking: the heel stops at once, the legs fade out over half a step.
  void stop() { walking_ = false; }
  bool walking() const { return walking_; }
  /// True while walking or while the legs are still fading out.
  bool moving() const { return walking_ || amplitude_ > 0.0; }
  /// Advances by dt (s; nothing for dt not finite and positive) and writes the walking joints into q
  /// (only those joints; q holds the robot's current positions on entry).
  void step(double dt, Eigen::Ref<Eigen::VectorXd> q);
  const std::vector<int>& joints() const { return joints_; }
  double travelled() const { return travelled_; }

  /// The pattern's time state, to take back a step that must not be applied (the walking guard).
  struct Snapshot {
    bool walking, started;
    double distance, speed, period, phase, travelled, x0, amplitude;
  };
  Snapshot snapshot() const;
  void restore(const Snapshot& s);

  static constexpr double kMinStepPeriod = 0.4;  ///< s
  static constexpr double kMaxStepPeriod = 3.0;  ///< s

 private:
  int heel_x_ = -1, body_z_ = -1;
  int hip_[2] = {-1, -1}, knee_[2] = {-1, -1}, ankle_[2] = {-1, -1};
  std::vector<int> joints_;
  std::vector<double> v_max_;  ///< per q index (rad/s or m/s)
  bool walking_ = false;
  double distance_ = 0.0, speed_ = 0.0, period_ = 0.8, phase_ = 0.0, travelled_ = 0.0, x0_ = 0.0;
  double amplitude_ = 0.0;  ///< leg motion amplitude, 0..1, ramped at start and stop
  bool started_ = false;
};

/// The plant side of one control cycle, the one home of every loop that drives a robot with the
/// controller (reflex_controller, runScenario and so the soak and reflex_sim). After
/// computeControl returned `result`:
/// - kFrozen (e-stop latched): nothing moves, walking holds;
/// - kRecovering, kBadInput: the arms get data.qdot (the separating motion, or zero); walking HOLDS:
///   the legs do not move and the pattern's time does not advance (walkingMayAdvance);
/// - kOk: the arms get data.qdot, then walking (if `walking` is non-null) takes one step,
///   unless the walking guard (checkWalkingStep) refuses it: a held step is taken back
///   (data.walking_hold_count) and tried again next cycle.
/// Allocation-free (q_scratch has nq entries); never throws. Returns true if walking advanced.
bool stepPlant(const Model& model, const ControllerModel& cm, ControllerData& data, ControlResult result,
               KinematicRobot& robot, WalkingPattern* walking, double dt, Eigen::VectorXd& q_scratch);

}  // namespace reflex::control
