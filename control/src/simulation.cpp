#include "reflex/control/simulation.hpp"

#include <algorithm>
#include <cmath>

namespace reflex::control {

KinematicRobot::KinematicRobot(const Model& model, const Eigen::VectorXd& q0) : model_(model), q_(q0) {}

void KinematicRobot::command(const Eigen::Ref<const Eigen::VectorXd>& qdot, double dt) {
  for (int i = 0; i < model_.nq; ++i) {
    const double v = std::clamp(std::isfinite(qdot[i]) ? qdot[i] : 0.0, -model_.v_max[i], model_.v_max[i]);
    q_[i] = std::clamp(q_[i] + v * dt, model_.q_lower[i], model_.q_upper[i]);
  }
}

void KinematicRobot::setWalkingJoints(const Eigen::Ref<const Eigen::VectorXd>& q_walk,
                                      const std::vector<int>& indices) {
  for (const int i : indices) q_[i] = std::clamp(q_walk[i], model_.q_lower[i], model_.q_upper[i]);
}

WalkingPattern::WalkingPattern(const Model& model) {
  auto find = [&](const char* name) {
    const int i = model.qIndex(name);
    if (i >= 0) joints_.push_back(i);
    return i;
  };
  heel_x_ = find("heel_x");
  body_z_ = find("body_z");
  const char* hips[2] = {"l_hip_pitch", "r_hip_pitch"};
  const char* knees[2] = {"l_knee", "r_knee"};
  const char* ankles[2] = {"l_ankle_pitch", "r_ankle_pitch"};
  for (int s = 0; s < 2; ++s) {
    hip_[s] = find(hips[s]);
    knee_[s] = find(knees[s]);
    ankle_[s] = find(ankles[s]);
  }
}

void WalkingPattern::start(double distance, double speed, double step_period) {
  walking_ = distance > 0.0 && speed > 0.0;
  distance_ = distance;
  speed_ = speed;
  period_ = step_period;
  phase_ = 0.0;
  travelled_ = 0.0;
  amplitude_ = 0.0;
  started_ = false;
}

void WalkingPattern::step(double dt, Eigen::Ref<Eigen::VectorXd> q) {
  if (!started_ && heel_x_ >= 0) {
    x0_ = q[heel_x_];
    started_ = true;
  }
  if (walking_) {
    travelled_ = std::min(distance_, travelled_ + speed_ * dt);
    if (travelled_ >= distance_) walking_ = false;
  }
  // The leg motion fades in over the first half step and out over the half step after the goal,
  // as a walking controller starts and stops (no joint jumps: the arms avoid the legs reactively).
  const double ramp = 0.5 * period_;
  amplitude_ = std::clamp(amplitude_ + (walking_ ? dt : -dt) / ramp, 0.0, 1.0);
  if (amplitude_ > 0.0) phase_ += 2.0 * M_PI * dt / period_;
  const double amplitude = amplitude_ * amplitude_ * (3.0 - 2.0 * amplitude_);  // smoothstep
  if (heel_x_ >= 0) q[heel_x_] = x0_ + travelled_;
  // Legs swing in anti-phase; the stance knee stays slightly bent; the body bobs with the step.
  for (int s = 0; s < 2; ++s) {
    const double ph = std::sin(phase_ + (s == 0 ? 0.0 : M_PI));
    const double swing = amplitude * 0.30 * ph;                                      // hip pitch (rad)
    const double lift = amplitude * 0.45 * std::max(0.0, std::sin(phase_ + (s == 0 ? 0.0 : M_PI) + M_PI / 2));
    if (hip_[s] >= 0) q[hip_[s]] = -swing - 0.5 * lift;
    if (knee_[s] >= 0) q[knee_[s]] = 0.1 * amplitude + lift;
    if (ankle_[s] >= 0) q[ankle_[s]] = swing - 0.5 * lift - 0.1 * amplitude;  // foot stays level
  }
  if (body_z_ >= 0) q[body_z_] = -0.02 * amplitude * (1.0 - std::cos(2.0 * phase_)) * 0.5;
}

}  // namespace reflex::control
