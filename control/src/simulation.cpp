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

void KinematicRobot::setWalkingJoints(const Eigen::Ref<const Eigen::VectorXd>& q_walk, const std::vector<int>& indices,
                                      double dt) {
  const double step_dt = std::isfinite(dt) && dt > 0.0 ? dt : 0.0;
  for (const int i : indices) {
    if (i < 0 || i >= model_.nq || !std::isfinite(q_walk[i])) continue;
    const double step = model_.v_max[i] * step_dt;
    const double target = std::clamp(q_walk[i], model_.q_lower[i], model_.q_upper[i]);
    q_[i] = std::clamp(q_[i] + std::clamp(target - q_[i], -step, step), model_.q_lower[i], model_.q_upper[i]);
  }
}

WalkingPattern::WalkingPattern(const Model& model) : v_max_(model.v_max.data(), model.v_max.data() + model.nq) {
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

bool WalkingPattern::start(double distance, double speed, double step_period) {
  if (!(std::isfinite(distance) && distance > 0.0 && std::isfinite(speed) && speed > 0.0)) {
    stop();  // the legs fade out from where they are
    return false;
  }
  // A new goal while walking (or while the legs fade out) continues the step cycle: phase and
  // amplitude are kept, so no leg joint jumps (a restart from phase 0 moved the
  // ankle 0.39 rad in one 5 ms cycle). The heel re-anchors where it is at the next step.
  walking_ = true;
  distance_ = distance;
  speed_ = heel_x_ >= 0 ? std::min(speed, v_max_[static_cast<std::size_t>(heel_x_)]) : speed;
  period_ = std::isfinite(step_period) ? std::clamp(step_period, kMinStepPeriod, kMaxStepPeriod) : 0.8;
  travelled_ = 0.0;
  started_ = false;
  return true;
}

WalkingPattern::Snapshot WalkingPattern::snapshot() const {
  return {walking_, started_, distance_, speed_, period_, phase_, travelled_, x0_, amplitude_};
}

void WalkingPattern::restore(const Snapshot& s) {
  walking_ = s.walking;
  started_ = s.started;
  distance_ = s.distance;
  speed_ = s.speed;
  period_ = s.period;
  phase_ = s.phase;
  travelled_ = s.travelled;
  x0_ = s.x0;
  amplitude_ = s.amplitude;
}

void WalkingPattern::step(double dt, Eigen::Ref<Eigen::VectorXd> q) {
  if (!(std::isfinite(dt) && dt > 0.0)) return;
  if (!started_ && heel_x_ >= 0) {
    x0_ = q[heel_x_];
    started_ = true;
  }
  if (walking_) {
    travelled_ = std::min(distance_, travelled_ + speed_ * dt);
    if (travelled_ >= distance_) walking_ = false;
  }
  // The leg motion fades in over the first half step and out over the half step after the goal,
  // as a walking controller starts and stops (the arms avoid the legs reactively).
  const double ramp = 0.5 * period_;
  amplitude_ = std::clamp(amplitude_ + (walking_ ? dt : -dt) / ramp, 0.0, 1.0);
  if (amplitude_ > 0.0) phase_ += 2.0 * M_PI * dt / period_;
  const double amplitude = amplitude_ * amplitude_ * (3.0 - 2.0 * amplitude_);  // smoothstep
  // Every joint follows its pattern value through a rate limit: at most v_max dt per step.
  auto follow = [&](int j, double target) {
    if (j < 0) return;
    const double limit = v_max_[static_cast<std::size_t>(j)] * dt;
    q[j] += std::clamp(target - q[j], -limit, limit);
  };
  if (heel_x_ >= 0) follow(heel_x_, x0_ + travelled_);
  // Legs swing in anti-phase; the stance knee stays slightly bent; the body bobs with the step.
  for (int s = 0; s < 2; ++s) {
    const double ph = std::sin(phase_ + (s == 0 ? 0.0 : M_PI));
    const double swing = amplitude * 0.30 * ph;  // hip pitch (rad)
    const double lift = amplitude * 0.45 * std::max(0.0, std::sin(phase_ + (s == 0 ? 0.0 : M_PI) + M_PI / 2));
    follow(hip_[s], -swing - 0.5 * lift);
    follow(knee_[s], 0.1 * amplitude + lift);
    follow(ankle_[s], swing - 0.5 * lift - 0.1 * amplitude);  // foot stays level
  }
  follow(body_z_, -0.02 * amplitude * (1.0 - std::cos(2.0 * phase_)) * 0.5);
}

bool stepPlant(const Model& model, const ControllerModel& cm, ControllerData& data, ControlResult result,
               KinematicRobot& robot, WalkingPattern* walking, double dt, Eigen::VectorXd& q_scratch) {
  if (result == ControlResult::kFrozen) return false;  // e-stop latched: nothing moves
  // Walking owns its joints: the controller never commands them (its qdot is 0 there), and a
  // velocity on them here would add to the walking step beyond v_max dt.
  if (walking != nullptr)
    for (const int j : walking->joints()) data.qdot[j] = 0.0;
  robot.command(data.qdot, dt);
  if (walking == nullptr || !walkingMayAdvance(result)) return false;
  const WalkingPattern::Snapshot before = walking->snapshot();
  q_scratch = robot.jointPositions();
  walking->step(dt, q_scratch);
  if (!checkWalkingStep(model, cm, data, q_scratch)) {
    walking->restore(before);  // held: the legs stay, the pattern's time does not advance
    ++data.walking_hold_count;
    return false;
  }
  robot.setWalkingJoints(q_scratch, walking->joints(), dt);
  return true;
}

}  // namespace reflex::control
