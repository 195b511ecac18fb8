// ROS 2's messages on DDS as Reflex topic types (idl/ros2.idl): their type support, default DDS topic
// and QoS profile (bringup/dds/reflex_profiles.xml "reflex_ros2"), for reflex_controller --robot ros2
// (control_node/ros2_port.hpp) and the fuzzer of received samples (tests/fuzz/fuzz_idl.cpp).
#pragma once

#include <reflex/bus/topics.hpp>
#include <reflex/msg/ros2PubSubTypes.h>

#include <string>

namespace reflex::ros2 {
using JointState = ::sensor_msgs::msg::dds_::JointState_;
using Float64MultiArray = ::std_msgs::msg::dds_::Float64MultiArray_;
using JointTrajectory = ::trajectory_msgs::msg::dds_::JointTrajectory_;
inline constexpr const char* kProfile = "reflex_ros2";
/// ROS 2's DDS topic of a ROS topic name: "rt/" + the name without its leading '/'.
inline std::string ddsTopic(const std::string& ros_topic) {
  std::size_t start = 0;
  while (start < ros_topic.size() && ros_topic[start] == '/') ++start;
  return "rt/" + ros_topic.substr(start);
}

/// sensor_msgs/JointState field by field (idl/ros2.idl), its strings read without allocating
/// (reflex/bus/cdr_read.hpp): the controller takes one every cycle.
struct JointStateRead {
  static void read(eprosima::fastcdr::Cdr& cdr, JointState& s) {
    cdr >> s.header().stamp().sec() >> s.header().stamp().nanosec();
    bus::readString(cdr, s.header().frame_id());
    bus::readStrings(cdr, s.name(), 256);
    bus::readDoubles(cdr, s.position(), 256);
    bus::readDoubles(cdr, s.velocity(), 256);
    bus::readDoubles(cdr, s.effort(), 256);
  }
};
}  // namespace reflex::ros2

namespace reflex::bus {
template <>
struct TopicTraits<ros2::JointState> {
  using PubSubType = SafePubSubType<::sensor_msgs::msg::dds_::JointState_PubSubType, ros2::JointStateRead>;
  static constexpr const char* kTopicName = "rt/joint_states";
  static constexpr const char* kProfile = ros2::kProfile;
};
template <>
struct TopicTraits<ros2::Float64MultiArray> {
  using PubSubType = SafePubSubType<::std_msgs::msg::dds_::Float64MultiArray_PubSubType>;
  static constexpr const char* kTopicName = "rt/forward_position_controller/commands";
  static constexpr const char* kProfile = ros2::kProfile;
};
template <>
struct TopicTraits<ros2::JointTrajectory> {
  using PubSubType = SafePubSubType<::trajectory_msgs::msg::dds_::JointTrajectory_PubSubType>;
  static constexpr const char* kTopicName = "rt/joint_trajectory_controller/joint_trajectory";
  static constexpr const char* kProfile = ros2::kProfile;
};
}  // namespace reflex::bus
