#include "reflex/control_node/dds_robot_port.hpp"

#include <cmath>
#include <cstdio>
#include <cstring>
#include <limits>

namespace reflex::control_node {

namespace {

JointStateIntake::Options intakeOptions(const DdsRobotPort::Options& o) {
  JointStateIntake::Options io = JointStateIntake::optionsOf(o);
  io.identities = o.identities;
  io.sample_name = "robot state seq";
  return io;
}

}  // namespace

DdsRobotPort::DdsRobotPort(const control::Model& model, const std::vector<int>& driven, bus::Participant& bus,
                           const Options& options)
    : NamedJointPort(model, intakeOptions(options)), options_(options), driven_(driven) {
  reader_ = &bus.makeReader<msg::RobotState>();
  writer_ = &bus.makeWriter<msg::JointCommand>();
  std::vector<std::string> names;
  for (const int j : driven_) names.push_back(model.q_names[j]);
  cmd_.names(names);
  cmd_.positions().assign(driven_.size(), 0.0);
  cmd_.velocities().assign(driven_.size(), 0.0);
}

int DdsRobotPort::poll() noexcept {
  int rejected = 0;
  bus::dds::SampleInfo info;
  while (reader_->takeNext(sample_, &info)) {
    const JointStateIntake::View view{sample_.names(),   sample_.positions(),         sample_.velocities(),
                                      sample_.efforts(), sample_.header().stamp_ns(), sample_.header().seq()};
    if (!intake_.take(view, info, bus::nowNs())) ++rejected;
  }
  return rejected;
}

bool DdsRobotPort::waitForState(std::chrono::nanoseconds timeout) noexcept {
  try {
    return reader_->waitForData(timeout);
  } catch (...) {
    return false;  // the caller's cycle runs as on a timeout
  }
}

void DdsRobotPort::command(const Eigen::VectorXd& q_end, const Eigen::VectorXd& qdot, double /*dt*/) noexcept {
  for (std::size_t k = 0; k < driven_.size(); ++k) {
    cmd_.positions()[k] = q_end[driven_[k]];
    cmd_.velocities()[k] = qdot[driven_[k]];
  }
  cmd_.valid_until_ns(bus::nowNs() + static_cast<std::int64_t>(std::llround(options_.deadline * 1e9)));
  cmd_.state_seq(intake_.stateSeq());
  cmd_.state_stamp_ns(intake_.stateStampNs());
  if (queue_ != nullptr) {
    if (queue_->push(cmd_)) ++commands_;
    outbox_->notify();
  } else if (writer_->publish(cmd_)) {
    ++commands_;
  }
}

void DdsRobotPort::sendThrough(bus::Outbox& outbox) {
  queue_ = &outbox.add(*writer_, cmd_, 16);
  outbox_ = &outbox;
}

}  // namespace reflex::control_node
