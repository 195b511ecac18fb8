// Kinematic simulation of the robot (first order, as the paper's system: Sec. 9.2) and a simple
// walking pattern, behind a robot interface that a real robot's driver could implement.
//
// The controller commands joint velocities of the arms; walking writes the legs, the heel and the
// virtual heel->body link directly (the paper's walking and balancing control owns them, Sec. 8).
#pragma once

#include "reflex/control/model.hpp"

#include <Eigen/Core>

#include <vector>

namespace reflex::control {

/// What the controller needs from a robot. A real robot's driver implements the same two calls.
class RobotInterface {
 public:
  virtual ~RobotInterface() = default;
  /// Measured joint positions (nq).
  virtual const Eigen::VectorXd& jointPositions() const = 0;
  /// Applies joint velocities for one period dt; the driver enforces its own limits.
  virtual void command(const Eigen::Ref<const Eigen::VectorXd>& qdot, double dt) = 0;
  /// Joints owned by walking / balance, written as positions (legs, heel, virtual link).
  virtual void setWalkingJoints(const Eigen::Ref<const Eigen::VectorXd>& q_walk,
                                const std::vector<int>& indices) = 0;
};

/// First-order kinematic robot: q += clamp(qdot, v_max) dt, clamped to the position limits.
class KinematicRobot final : public RobotInterface {
 public:
  KinematicRobot(const Model& model, const Eigen::VectorXd& q0);
  const Eigen::VectorXd& jointPositions() const override { return q_; }
  void command(const Eigen::Ref<const Eigen::VectorXd>& qdot, double dt) override;
  void setWalkingJoints(const Eigen::Ref<const Eigen::VectorXd>& q_walk, const std::vector<int>& indices) override;
  void reset(const Eigen::VectorXd& q) { q_ = q; }

 private:
  const Model& model_;
  Eigen::VectorXd q_;
};

/// A simple walking pattern: the heel moves along x at a constant speed to a goal distance, the legs
/// swing (hip pitch, knee, ankle pitch) with the step phase, the body bobs slightly; the leg motion
/// fades in and out over half a step (no joint jumps). Joints are found
/// by name (heel_x, {l,r}_hip_pitch, {l,r}_knee, {l,r}_ankle_pitch, body_z); missing ones are skipped.
class WalkingPattern {
 public:
  explicit WalkingPattern(const Model& model);
  /// Starts walking `distance` metres forward at `speed` m/s (step period `step_period` s).
  void start(double distance, double speed, double step_period = 0.8);
  void stop() { walking_ = false; }
  bool walking() const { return walking_; }
  /// Advances by dt and writes the walking joints into q (only those joints).
  void step(double dt, Eigen::Ref<Eigen::VectorXd> q);
  const std::vector<int>& joints() const { return joints_; }
  double travelled() const { return travelled_; }

 private:
  int heel_x_ = -1, body_z_ = -1;
  int hip_[2] = {-1, -1}, knee_[2] = {-1, -1}, ankle_[2] = {-1, -1};
  std::vector<int> joints_;
  bool walking_ = false;
  double distance_ = 0.0, speed_ = 0.0, period_ = 0.8, phase_ = 0.0, travelled_ = 0.0, x0_ = 0.0;
  double amplitude_ = 0.0;  ///< leg motion amplitude, 0..1, ramped at start and stop
  bool started_ = false;
};

}  // namespace reflex::control
