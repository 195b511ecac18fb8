// reflex_controller --robot ros2 (ros2_port.hpp).
#include "reflex/control_node/ros2_port.hpp"

#include "reflex/control/controller.hpp"

#include <cmath>

namespace reflex::control_node {

namespace {

JointStateIntake::Options intakeOptions(const Ros2RobotPort::Options& o) {
  JointStateIntake::Options io = JointStateIntake::optionsOf(o);
  io.velocities_optional = true;                               // ROS: velocity may be empty (not measured)
  io.sample_name = ros2::ddsTopic(o.state_topic) + " sample";  // "rt/joint_states sample N"
  return io;
}

}  // namespace

Ros2RobotPort::Ros2RobotPort(const control::Model& model, const std::vector<int>& driven, bus::Participant& bus,
                             const Options& options)
    : NamedJointPort(model, intakeOptions(options)),
      model_(model),
      options_(options),
      state_topic_(ros2::ddsTopic(options.state_topic)) {
  if (options.command != "forward" && options.command != "trajectory")
    throw control::ConfigError("--ros-command: unknown kind '" + options.command +
                               "' (expected forward: std_msgs/Float64MultiArray to a forward controller, or "
                               "trajectory: trajectory_msgs/JointTrajectory)");
  trajectory_ = options.command == "trajectory";
  const std::string controller = !options.controller.empty()
                                     ? options.controller
                                     : (trajectory_ ? "joint_trajectory_controller" : "forward_position_controller");
  command_topic_ = ros2::ddsTopic(controller + (trajectory_ ? "/joint_trajectory" : "/commands"));
  std::vector<std::string> names = options.joints;
  if (names.empty())
    for (const int q : driven) names.push_back(model.q_names[static_cast<std::size_t>(q)]);
  for (const std::string& name : names) {
    int q = -1;
    for (int i = 0; i < model.nq; ++i)
      if (model.q_names[static_cast<std::size_t>(i)] == name) q = i;
    if (q < 0)
      throw control::ConfigError("--ros-joints: joint '" + name + "' is not a joint of the robot '" + model.name + "'");
    for (const int k : joint_q_)
      if (k == q) throw control::ConfigError("--ros-joints: joint '" + name + "' is listed twice");
    joint_q_.push_back(q);
  }
  reader_ = &bus.makeReader<ros2::JointState>(state_topic_, ros2::kProfile);
  if (trajectory_) {
    trajectory_writer_ = &bus.makeWriter<ros2::JointTrajectory>(command_topic_, ros2::kProfile);
    trajectory_msg_.joint_names(names);
    trajectory_msg_.points().resize(1);
    trajectory_msg_.points()[0].positions().assign(names.size(), 0.0);
    trajectory_msg_.points()[0].velocities().assign(names.size(), 0.0);
  } else {
    forward_writer_ = &bus.makeWriter<ros2::Float64MultiArray>(command_topic_, ros2::kProfile);
    forward_.data().assign(names.size(), 0.0);
  }
}

int Ros2RobotPort::poll() noexcept {
  int rejected = 0;
  bus::dds::SampleInfo info;
  while (reader_->takeNext(sample_, &info)) {
    const std::int64_t now = bus::nowNs();
    const auto& stamp = sample_.header().stamp();
    // ROS time; 0: the driver does not stamp, taken as measured when its writer wrote it (the DDS
    // source timestamp: the sender's clock, like its own stamps, so a burst stays in order), else when
    // this host took it.
    std::int64_t stamp_ns =
        static_cast<std::int64_t>(stamp.sec()) * 1000000000LL + static_cast<std::int64_t>(stamp.nanosec());
    if (stamp.sec() == 0 && stamp.nanosec() == 0) {
      const auto& source = info.source_timestamp;
      const std::int64_t written =
          static_cast<std::int64_t>(source.seconds()) * 1000000000LL + static_cast<std::int64_t>(source.nanosec());
      stamp_ns = written > 0 && written <= now ? written : now;
    }
    const JointStateIntake::View view{sample_.name(),   sample_.position(), sample_.velocity(),
                                      sample_.effort(), stamp_ns,           ++received_};
    if (!intake_.take(view, info, now)) ++rejected;
  }
  return rejected;
}

void Ros2RobotPort::command(const Eigen::VectorXd& q_end, const Eigen::VectorXd& qdot, double dt) noexcept {
  if (trajectory_) {
    auto& point = trajectory_msg_.points()[0];
    for (std::size_t k = 0; k < joint_q_.size(); ++k) {
      point.positions()[k] = q_end[joint_q_[k]];
      point.velocities()[k] = qdot[joint_q_[k]];
    }
    const double span = dt > 0.0 && std::isfinite(dt) ? dt : options_.period;
    point.time_from_start().sec(static_cast<std::int32_t>(std::floor(span)));
    point.time_from_start().nanosec(static_cast<std::uint32_t>(std::llround((span - std::floor(span)) * 1e9)));
  } else {
    for (std::size_t k = 0; k < joint_q_.size(); ++k) forward_.data()[k] = q_end[joint_q_[k]];
  }
  send();
}

void Ros2RobotPort::send() noexcept {
  bool sent = false;
  if (trajectory_) {
    sent = trajectory_queue_ != nullptr ? trajectory_queue_->push(trajectory_msg_)
                                        : trajectory_writer_->write(trajectory_msg_);
  } else {
    sent = forward_queue_ != nullptr ? forward_queue_->push(forward_) : forward_writer_->write(forward_);
  }
  if (outbox_ != nullptr) outbox_->notify();
  if (sent) ++commands_;
}

void Ros2RobotPort::sendThrough(bus::Outbox& outbox) {
  if (trajectory_) {
    trajectory_queue_ = &outbox.add(*trajectory_writer_, trajectory_msg_, 16);
  } else {
    forward_queue_ = &outbox.add(*forward_writer_, forward_, 16);
  }
  outbox_ = &outbox;
}

bool Ros2RobotPort::waitForState(std::chrono::nanoseconds timeout) noexcept {
  try {
    return reader_->waitForData(timeout);
  } catch (...) {
    return false;
  }
}

std::string Ros2RobotPort::describe() const {
  std::string joints;
  for (const int q : joint_q_) joints += (joints.empty() ? "" : ", ") + model_.q_names[static_cast<std::size_t>(q)];
  return "ROS 2 on the wire: state " + state_topic_ + " (sensor_msgs::msg::dds_::JointState_), commands " +
         command_topic_ +
         (trajectory_ ? " (trajectory_msgs::msg::dds_::JointTrajectory_)"
                      : " (std_msgs::msg::dds_::Float64MultiArray_)") +
         " for the joints [" + joints + "]";
}

}  // namespace reflex::control_node
