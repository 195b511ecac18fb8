#include "reflex/control_node/dds_robot_port.hpp"

#include <cmath>
#include <cstdio>
#include <limits>

namespace reflex::control_node {

DdsRobotPort::DdsRobotPort(const control::Model& model, const std::vector<int>& driven, bus::Participant& bus,
                           const Options& options)
    : model_(model), options_(options), driven_(driven) {
  reader_ = &bus.makeReader<msg::RobotState>();
  writer_ = &bus.makeWriter<msg::JointCommand>();
  index_.assign(static_cast<std::size_t>(model.nq), -1);
  q_.setZero(model.nq);
  std::vector<std::string> names;
  for (const int j : driven_) names.push_back(model.q_names[j]);
  cmd_.names(names);
  cmd_.positions().assign(driven_.size(), 0.0);
  cmd_.velocities().assign(driven_.size(), 0.0);
}

int DdsRobotPort::poll() noexcept {
  int rejected = 0;
  while (reader_->takeNext(sample_))
    if (!accept(sample_)) ++rejected;
  return rejected;
}

bool DdsRobotPort::accept(const msg::RobotState& s) noexcept {
  const auto seq = static_cast<unsigned long long>(s.header().seq());
  const std::size_t n = s.names().size();
  if (s.positions().size() != n || s.velocities().size() != n || (!s.efforts().empty() && s.efforts().size() != n)) {
    ++counts_.rejected_length;
    cause_ = 0;
    std::snprintf(rejection_, sizeof(rejection_),
                  "robot state seq %llu rejected: %zu names but %zu positions, %zu velocities, %zu efforts", seq, n,
                  s.positions().size(), s.velocities().size(), s.efforts().size());
    return false;
  }
  // The name map, built again only when the robot's list changes (comparing is allocation-free).
  bool same = robot_names_.size() == n;
  for (std::size_t k = 0; same && k < n; ++k) same = robot_names_[k] == s.names()[k];
  if (!same) {
    robot_names_ = s.names();  // a new list: the one allocation, once per change of the robot's joints
    for (int i = 0; i < model_.nq; ++i) {
      index_[static_cast<std::size_t>(i)] = -1;
      for (std::size_t k = 0; k < n; ++k)
        if (robot_names_[k] == model_.q_names[i]) index_[static_cast<std::size_t>(i)] = static_cast<int>(k);
    }
  }
  for (int i = 0; i < model_.nq; ++i) {
    const int k = index_[static_cast<std::size_t>(i)];
    if (k < 0) {
      ++counts_.rejected_missing;
      cause_ = 1;
      std::snprintf(rejection_, sizeof(rejection_), "robot state seq %llu rejected: joint '%s' is missing", seq,
                    model_.q_names[i].c_str());
      return false;
    }
    const double p = s.positions()[static_cast<std::size_t>(k)], v = s.velocities()[static_cast<std::size_t>(k)];
    if (!std::isfinite(p) || !std::isfinite(v)) {
      ++counts_.rejected_non_finite;
      cause_ = 2;
      std::snprintf(rejection_, sizeof(rejection_), "robot state seq %llu rejected: joint '%s' position %g velocity %g",
                    seq, model_.q_names[i].c_str(), p, v);
      return false;
    }
  }
  const std::int64_t now = bus::nowNs();
  const std::int64_t ahead = s.header().stamp_ns() - now;
  if (static_cast<double>(ahead) > kFutureTolerance * 1e9) {
    ++counts_.rejected_future;
    cause_ = 3;
    std::snprintf(rejection_, sizeof(rejection_),
                  "robot state seq %llu rejected: stamped %.1f ms in the future (tolerance %.1f ms)", seq,
                  static_cast<double>(ahead) * 1e-6, kFutureTolerance * 1e3);
    return false;
  }
  if (have_state_ && s.header().stamp_ns() <= state_stamp_ns_) {
    ++counts_.rejected_old;
    cause_ = 4;
    std::snprintf(rejection_, sizeof(rejection_), "robot state seq %llu rejected: stamp not newer than seq %llu's",
                  seq, static_cast<unsigned long long>(state_seq_));
    return false;
  }
  for (int i = 0; i < model_.nq; ++i) q_[i] = s.positions()[static_cast<std::size_t>(index_[static_cast<std::size_t>(i)])];
  have_state_ = true;
  state_seq_ = s.header().seq();
  state_stamp_ns_ = s.header().stamp_ns();
  ++counts_.accepted;
  return true;
}

double DdsRobotPort::stateAge() const noexcept {
  if (!have_state_) return std::numeric_limits<double>::infinity();
  return static_cast<double>(bus::nowNs() - state_stamp_ns_) * 1e-9;
}

const Eigen::VectorXd* DdsRobotPort::measuredPositions(double /*now*/) noexcept {
  if (!have_state_ || !(stateAge() <= options_.timeout)) return nullptr;
  return &q_;
}

void DdsRobotPort::command(const Eigen::VectorXd& q_end, const Eigen::VectorXd& qdot, double /*dt*/) noexcept {
  for (std::size_t k = 0; k < driven_.size(); ++k) {
    cmd_.positions()[k] = q_end[driven_[k]];
    cmd_.velocities()[k] = qdot[driven_[k]];
  }
  cmd_.valid_until_ns(bus::nowNs() + static_cast<std::int64_t>(std::llround(options_.deadline * 1e9)));
  cmd_.state_seq(state_seq_);
  cmd_.state_stamp_ns(state_stamp_ns_);
  if (queue_ != nullptr) {
    if (queue_->push(cmd_)) ++counts_.commands;
    outbox_->notify();
  } else if (writer_->publish(cmd_)) {
    ++counts_.commands;
  }
}

void DdsRobotPort::sendThrough(bus::Outbox& outbox) {
  queue_ = &outbox.add(*writer_, cmd_, 16);
  outbox_ = &outbox;
}

}  // namespace reflex::control_node
