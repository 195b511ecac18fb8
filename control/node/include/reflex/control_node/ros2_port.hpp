// The robot behind ROS 2: reflex_controller --robot ros2. A control::RobotPort speaking ROS 2's own
// types on DDS (idl/ros2.idl: pkg::msg::dds_::Type_ on rt/<topic>), so a ROS 2 system (ros2_control
// with its joint_state_broadcaster and a forward or trajectory controller) talks to Reflex with no
// bridge and without ROS 2 installed here (idl/README.md "Robots that already have an interface").
//
// State in: sensor_msgs/JointState on rt/<state_topic> (default rt/joint_states). Every sample goes
// through JointStateIntake's checks (joint_state_intake.hpp, as reflex/robot_state: lengths, a
// model joint missing, a name listed twice, non-finite values, limits, future / old stamps, one
// bound writer), counted and named as "rt/joint_states sample N" (N: this port's count of samples;
// JointState carries no sequence number). Joints the model does not have are ignored (a gripper's);
// velocity may be empty (ROS: not measured). header.stamp is ROS time: the system clock, except a
// stamp of 0 (a driver that does not stamp), taken as the time its writer wrote the sample (the DDS
// source timestamp, else when this host took it). A node on
// simulated time (stamps far from the system clock) is rejected as stamped in the future, or is stale.
//
// Command out, one per computed cycle (Reflex drives the arms; ros2_control's own controllers hold
// the rest):
//   forward     std_msgs/Float64MultiArray on rt/<controller>/commands (default
//               forward_position_controller): one position per joint of the controller's `joints`
//               list (Options::joints, its order; a joint Reflex does not drive carries its measured
//               position), layout empty, as forward_command_controller expects.
//   trajectory  trajectory_msgs/JointTrajectory on rt/<controller>/joint_trajectory (default
//               joint_trajectory_controller): the same joints, one point with positions = the cycle's
//               end, velocities, time_from_start = dt; header.stamp 0 (start at once).
// QoS (bringup/dds/reflex_profiles.xml "reflex_ros2"): writers ROS 2's default (RELIABLE, VOLATILE,
// KEEP_LAST 10); the state reader BEST_EFFORT (it matches a reliable publisher and a sensor-data one
// alike), KEEP_LAST 16. Allocation-free per cycle once the robot's list of joint names is known.
#pragma once

#include "reflex/control/model.hpp"
#include "reflex/control_node/bus_robot_port.hpp"
#include "reflex/control_node/joint_state_intake.hpp"

#include <reflex/bus/bus.hpp>
#include <reflex/bus/outbox.hpp>
#include <reflex/bus/ros2_topics.hpp>

#include <string>
#include <vector>

namespace reflex::control_node {

class Ros2RobotPort final : public NamedJointPort {
 public:
  struct Options {
    double timeout = 0.050;                    ///< s without an accepted state before the state is stale
    double period = 0.005;                     ///< s: the control period (limit tolerance v_max * period)
    double rebind_silence = 1.0;               ///< s the bound writer must be silent before another may replace it
    std::string state_topic = "joint_states";  ///< ROS topic of the JointState
    std::string command = "forward";           ///< "forward" or "trajectory"
    std::string controller;                    ///< ros2_control controller name ("": the default of `command`)
    std::vector<std::string> joints;           ///< the controller's joints in its order (empty: those Reflex drives)
  };

  /// Makes the reader and the writer on `bus`. Throws control::ConfigError for an unknown command kind
  /// or a joint the model does not have (naming it), bus::BusError naming a DDS entity.
  Ros2RobotPort(const control::Model& model, const std::vector<int>& driven, bus::Participant& bus,
                const Options& options);

  int poll() noexcept override;
  void command(const Eigen::VectorXd& q_end, const Eigen::VectorXd& qdot, double dt) noexcept override;
  void sendThrough(bus::Outbox& outbox) override;
  bool waitForState(std::chrono::nanoseconds timeout) noexcept override;
  const char* stateTopic() const override { return state_topic_.c_str(); }
  std::uint64_t commandsSent() const override { return commands_; }
  /// The DDS topic the commands go to ("rt/forward_position_controller/commands").
  const std::string& commandTopic() const { return command_topic_; }
  /// What it speaks, one line: the topics with their DDS types and the commanded joints in order.
  std::string describe() const;

 private:
  void send() noexcept;

  const control::Model& model_;
  Options options_;
  std::string state_topic_, command_topic_;
  bool trajectory_ = false;
  std::vector<int> joint_q_;  ///< q index of each commanded joint (Options::joints' order)
  bus::Reader<ros2::JointState>* reader_ = nullptr;
  bus::Writer<ros2::Float64MultiArray>* forward_writer_ = nullptr;
  bus::Writer<ros2::JointTrajectory>* trajectory_writer_ = nullptr;
  bus::OutboxQueue<ros2::Float64MultiArray>* forward_queue_ = nullptr;
  bus::OutboxQueue<ros2::JointTrajectory>* trajectory_queue_ = nullptr;
  bus::Outbox* outbox_ = nullptr;
  ros2::JointState sample_;
  ros2::Float64MultiArray forward_;
  ros2::JointTrajectory trajectory_msg_;
  std::uint64_t received_ = 0, commands_ = 0;
};

}  // namespace reflex::control_node
