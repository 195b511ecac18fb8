// Test samples of every Reflex topic type with distinctive values in every field (non-default
// enums, negative numbers, empty and long strings, several sequence elements), and a field-by-field
// comparison that lists every difference. Used by the in-process round-trip test and by the
// two-process publisher / subscriber programs (which do not link gtest).
#pragma once

#include <reflex/msg/behavior.h>
#include <reflex/msg/control.h>
#include <reflex/msg/robot.h>
#include <reflex/msg/system.h>
#include <reflex/msg/vision.h>

#include <cstdint>
#include <sstream>
#include <string>
#include <vector>

namespace reflex::bus::test {

using Diffs = std::vector<std::string>;

template <class V>
void diffValue(const std::string& path, const V& expected, const V& actual, Diffs& out) {
  if (!(expected == actual)) {
    std::ostringstream s;
    s << path << ": expected " << expected << ", got " << actual;
    out.push_back(s.str());
  }
}
// Enums print as their integer value.
template <class E>
void diffEnum(const std::string& path, E expected, E actual, Diffs& out) {
  diffValue(path, static_cast<std::int64_t>(expected), static_cast<std::int64_t>(actual), out);
}
template <class V>
void diffVector(const std::string& path, const std::vector<V>& expected, const std::vector<V>& actual, Diffs& out) {
  diffValue(path + ".size()", expected.size(), actual.size(), out);
  for (std::size_t i = 0; i < expected.size() && i < actual.size(); ++i) {
    diffValue(path + "[" + std::to_string(i) + "]", expected[i], actual[i], out);
  }
}

inline std::string join(const Diffs& d) {
  std::string s;
  for (const auto& line : d) s += line + "\n";
  return s;
}

// ---- field-by-field comparison ---------------------------------------------------------------

inline void diff(const std::string& p, const msg::Header& e, const msg::Header& a, Diffs& out) {
  diffValue(p + ".stamp_ns", e.stamp_ns(), a.stamp_ns(), out);
  diffValue(p + ".seq", e.seq(), a.seq(), out);
  diffValue(p + ".source", e.source(), a.source(), out);
}
inline void diff(const std::string& p, const msg::Vector3& e, const msg::Vector3& a, Diffs& out) {
  diffValue(p + ".x", e.x(), a.x(), out);
  diffValue(p + ".y", e.y(), a.y(), out);
  diffValue(p + ".z", e.z(), a.z(), out);
}
inline void diff(const std::string& p, const msg::ObjectTarget& e, const msg::ObjectTarget& a, Diffs& out) {
  diffValue(p + ".name", e.name(), a.name(), out);
  diffValue(p + ".tag_id", e.tag_id(), a.tag_id(), out);
  diff(p + ".position_base", e.position_base(), a.position_base(), out);
  diff(p + ".position_camera", e.position_camera(), a.position_camera(), out);
  diffValue(p + ".confidence", e.confidence(), a.confidence(), out);
}
inline void diff(const std::string& p, const msg::ObjectTargets& e, const msg::ObjectTargets& a, Diffs& out) {
  diff(p + ".header", e.header(), a.header(), out);
  diffValue(p + ".capture_stamp_ns", e.capture_stamp_ns(), a.capture_stamp_ns(), out);
  diffValue(p + ".image_index", e.image_index(), a.image_index(), out);
  diffValue(p + ".frame_id", e.frame_id(), a.frame_id(), out);
  diffValue(p + ".objects.size()", e.objects().size(), a.objects().size(), out);
  for (std::size_t i = 0; i < e.objects().size() && i < a.objects().size(); ++i) {
    diff(p + ".objects[" + std::to_string(i) + "]", e.objects()[i], a.objects()[i], out);
  }
}
inline void diff(const std::string& p, const msg::HandTarget& e, const msg::HandTarget& a, Diffs& out) {
  diffEnum(p + ".status", e.status(), a.status(), out);
  diff(p + ".position_base", e.position_base(), a.position_base(), out);
  diffValue(p + ".object_name", e.object_name(), a.object_name(), out);
}
inline void diff(const std::string& p, const msg::HandTargets& e, const msg::HandTargets& a, Diffs& out) {
  diff(p + ".header", e.header(), a.header(), out);
  diff(p + ".left", e.left(), a.left(), out);
  diff(p + ".right", e.right(), a.right(), out);
}
inline void diff(const std::string& p, const msg::MotionPriority& e, const msg::MotionPriority& a, Diffs& out) {
  diff(p + ".header", e.header(), a.header(), out);
  diffEnum(p + ".priority", e.priority(), a.priority(), out);
}
inline void diff(const std::string& p, const msg::BodySchemaChange& e, const msg::BodySchemaChange& a, Diffs& out) {
  diff(p + ".header", e.header(), a.header(), out);
  diffValue(p + ".segment_name", e.segment_name(), a.segment_name(), out);
  diffEnum(p + ".operation", e.operation(), a.operation(), out);
  diffValue(p + ".parent_link", e.parent_link(), a.parent_link(), out);
  diffEnum(p + ".shape", e.shape(), a.shape(), out);
  diff(p + ".point_a", e.point_a(), a.point_a(), out);
  diff(p + ".point_b", e.point_b(), a.point_b(), out);
  diffValue(p + ".radius", e.radius(), a.radius(), out);
  diffValue(p + ".motion_priority", e.motion_priority(), a.motion_priority(), out);
  diffValue(p + ".enabled", e.enabled(), a.enabled(), out);
  diffValue(p + ".virtual_segment", e.virtual_segment(), a.virtual_segment(), out);
}
inline void diff(const std::string& p, const msg::WalkCommand& e, const msg::WalkCommand& a, Diffs& out) {
  diff(p + ".header", e.header(), a.header(), out);
  diffValue(p + ".goal_x", e.goal_x(), a.goal_x(), out);
  diffValue(p + ".goal_y", e.goal_y(), a.goal_y(), out);
  diffValue(p + ".goal_yaw", e.goal_yaw(), a.goal_yaw(), out);
  diffValue(p + ".speed", e.speed(), a.speed(), out);
  diffValue(p + ".stop", e.stop(), a.stop(), out);
}
inline void diff(const std::string& p, const msg::JointState& e, const msg::JointState& a, Diffs& out) {
  diff(p + ".header", e.header(), a.header(), out);
  diffVector(p + ".names", e.names(), a.names(), out);
  diffVector(p + ".positions", e.positions(), a.positions(), out);
  diffVector(p + ".velocities", e.velocities(), a.velocities(), out);
}
inline void diff(const std::string& p, const msg::ArmStatus& e, const msg::ArmStatus& a, Diffs& out) {
  diffValue(p + ".blend_f", e.blend_f(), a.blend_f(), out);
  diffValue(p + ".closest_segment_a", e.closest_segment_a(), a.closest_segment_a(), out);
  diffValue(p + ".closest_segment_b", e.closest_segment_b(), a.closest_segment_b(), out);
  diffValue(p + ".distance", e.distance(), a.distance(), out);
  diffEnum(p + ".zone", e.zone(), a.zone(), out);
  diffValue(p + ".estop_latched", e.estop_latched(), a.estop_latched(), out);
}
inline void diff(const std::string& p, const msg::ControlStatus& e, const msg::ControlStatus& a, Diffs& out) {
  diff(p + ".header", e.header(), a.header(), out);
  diff(p + ".left", e.left(), a.left(), out);
  diff(p + ".right", e.right(), a.right(), out);
  diffValue(p + ".cycle_period_us", e.cycle_period_us(), a.cycle_period_us(), out);
  diffValue(p + ".compute_time_us", e.compute_time_us(), a.compute_time_us(), out);
  diffValue(p + ".lateness_us", e.lateness_us(), a.lateness_us(), out);
  diffValue(p + ".overrun_count", e.overrun_count(), a.overrun_count(), out);
  diffValue(p + ".arm_distance", e.arm_distance(), a.arm_distance(), out);
  diffValue(p + ".rejected_hand_targets", e.rejected_hand_targets(), a.rejected_hand_targets(), out);
  diffValue(p + ".rejected_body_schema", e.rejected_body_schema(), a.rejected_body_schema(), out);
  diffValue(p + ".rejected_walk_commands", e.rejected_walk_commands(), a.rejected_walk_commands(), out);
  diffValue(p + ".rejected_robot_states", e.rejected_robot_states(), a.rejected_robot_states(), out);
  diffValue(p + ".last_rejection", e.last_rejection(), a.last_rejection(), out);
}
inline void diff(const std::string& p, const msg::Heartbeat& e, const msg::Heartbeat& a, Diffs& out) {
  diff(p + ".header", e.header(), a.header(), out);
  diffValue(p + ".module_name", e.module_name(), a.module_name(), out);
  diffValue(p + ".host", e.host(), a.host(), out);
  diffValue(p + ".pid", e.pid(), a.pid(), out);
  diffEnum(p + ".state", e.state(), a.state(), out);
  diffValue(p + ".period_ms", e.period_ms(), a.period_ms(), out);
  diffValue(p + ".detail", e.detail(), a.detail(), out);
}
inline void diff(const std::string& p, const msg::ControllerProtection& e, const msg::ControllerProtection& a,
                 Diffs& out) {
  diff(p + ".header", e.header(), a.header(), out);
  diffValue(p + ".avoidance", e.avoidance(), a.avoidance(), out);
  diffValue(p + ".estop", e.estop(), a.estop(), out);
  diffValue(p + ".reason", e.reason(), a.reason(), out);
  diffValue(p + ".period", e.period(), a.period(), out);
  diffValue(p + ".robot", e.robot(), a.robot(), out);
}

inline void diff(const std::string& p, const msg::RobotState& e, const msg::RobotState& a, Diffs& out) {
  diff(p + ".header", e.header(), a.header(), out);
  diffVector(p + ".names", e.names(), a.names(), out);
  diffVector(p + ".positions", e.positions(), a.positions(), out);
  diffVector(p + ".velocities", e.velocities(), a.velocities(), out);
  diffVector(p + ".efforts", e.efforts(), a.efforts(), out);
  diffValue(p + ".applied_command_seq", e.applied_command_seq(), a.applied_command_seq(), out);
  diffValue(p + ".holding", e.holding(), a.holding(), out);
}
inline void diff(const std::string& p, const msg::JointCommand& e, const msg::JointCommand& a, Diffs& out) {
  diff(p + ".header", e.header(), a.header(), out);
  diffVector(p + ".names", e.names(), a.names(), out);
  diffVector(p + ".positions", e.positions(), a.positions(), out);
  diffVector(p + ".velocities", e.velocities(), a.velocities(), out);
  diffValue(p + ".valid_until_ns", e.valid_until_ns(), a.valid_until_ns(), out);
  diffValue(p + ".state_seq", e.state_seq(), a.state_seq(), out);
  diffValue(p + ".state_stamp_ns", e.state_stamp_ns(), a.state_stamp_ns(), out);
}
inline void diff(const std::string& p, const msg::RobotContacts& e, const msg::RobotContacts& a, Diffs& out) {
  diff(p + ".header", e.header(), a.header(), out);
  diffValue(p + ".state_seq", e.state_seq(), a.state_seq(), out);
  diffValue(p + ".contacts.size()", e.contacts().size(), a.contacts().size(), out);
  for (std::size_t i = 0; i < e.contacts().size() && i < a.contacts().size(); ++i) {
    const std::string c = p + ".contacts[" + std::to_string(i) + "]";
    diffValue(c + ".segment_a", e.contacts()[i].segment_a(), a.contacts()[i].segment_a(), out);
    diffValue(c + ".segment_b", e.contacts()[i].segment_b(), a.contacts()[i].segment_b(), out);
    diffValue(c + ".distance", e.contacts()[i].distance(), a.contacts()[i].distance(), out);
  }
  diffValue(p + ".total_contact_steps", e.total_contact_steps(), a.total_contact_steps(), out);
}
inline void diff(const std::string& p, const msg::CameraImage& e, const msg::CameraImage& a, Diffs& out) {
  diff(p + ".header", e.header(), a.header(), out);
  diffValue(p + ".capture_stamp_ns", e.capture_stamp_ns(), a.capture_stamp_ns(), out);
  diffValue(p + ".image_index", e.image_index(), a.image_index(), out);
  diffValue(p + ".frame_id", e.frame_id(), a.frame_id(), out);
  diffValue(p + ".format", e.format(), a.format(), out);
  diffValue(p + ".width", e.width(), a.width(), out);
  diffValue(p + ".height", e.height(), a.height(), out);
  diffValue(p + ".data.size()", e.data().size(), a.data().size(), out);
  diffValue(p + ".data", e.data() == a.data(), true, out);
}

template <class T>
Diffs diffSample(const T& expected, const T& actual) {
  Diffs out;
  diff("sample", expected, actual, out);
  return out;
}

// ---- distinctive samples ---------------------------------------------------------------------
// `k` varies the values so that consecutive samples differ (k >= 0). The header is filled too
// (tests that publish() overwrite it; tests that write() keep it).

inline msg::Vector3 vec(double x, double y, double z) {
  msg::Vector3 v;
  v.x(x);
  v.y(y);
  v.z(z);
  return v;
}

inline msg::Header header(int k) {
  msg::Header h;
  h.stamp_ns(1'700'000'000'123'456'789LL + k);
  h.seq(1000u + static_cast<std::uint64_t>(k));
  h.source("test-source");
  return h;
}

inline msg::ObjectTargets objectTargets(int k) {
  msg::ObjectTargets m;
  m.header(header(k));
  m.capture_stamp_ns(-42 - k);  // negative on purpose: sign must survive
  m.image_index(0xFFFF'FFFF'0000'0001ULL + static_cast<std::uint64_t>(k));
  m.frame_id("base_link");
  for (int i = 0; i < 3; ++i) {
    msg::ObjectTarget o;
    o.name(i == 1 ? std::string() : "object_" + std::to_string(i) + "_" + std::string(40, 'x'));
    o.tag_id(7 * i - 1);
    o.position_base(vec(0.25 + i, -0.125 * i, 1.0e-9 + k));
    o.position_camera(vec(-1.5, 2.5 * i, 3.75));
    o.confidence(0.3333333333333333 + 0.1 * i);
    m.objects().push_back(o);
  }
  return m;
}

inline msg::HandTargets handTargets(int k) {
  msg::HandTargets m;
  m.header(header(k));
  m.left().status(msg::TARGET_GIVEN);
  m.left().position_base(vec(0.45, 0.2 + 0.01 * k, 0.9));
  m.left().object_name("red_cup");
  m.right().status(msg::TARGET_NONE);
  m.right().position_base(vec(-0.0, -1e300, 5e-324));  // extremes, incl. a denormal
  m.right().object_name("");
  return m;
}

inline msg::MotionPriority motionPriority(int k) {
  msg::MotionPriority m;
  m.header(header(k));
  m.priority(k % 2 == 0 ? msg::PRIORITY_RIGHT_HIGHER : msg::PRIORITY_LEFT_HIGHER);
  return m;
}

inline msg::BodySchemaChange bodySchemaChange(int k) {
  msg::BodySchemaChange m;
  m.header(header(k));
  m.segment_name("gaze_line_" + std::to_string(k));
  m.operation(msg::SCHEMA_DETACH);
  m.parent_link("head_link");
  m.shape(msg::SHAPE_CAPSULE);
  m.point_a(vec(0.05, 0.0, 0.1));
  m.point_b(vec(0.8, -0.3, -0.2));
  m.radius(0.035);
  m.motion_priority(-3 + k);
  m.enabled(false);
  m.virtual_segment(true);
  return m;
}

inline msg::WalkCommand walkCommand(int k) {
  msg::WalkCommand m;
  m.header(header(k));
  m.goal_x(1.5 + k);
  m.goal_y(-0.75);
  m.goal_yaw(-3.141592653589793);
  m.speed(0.3);
  m.stop(true);
  return m;
}

inline msg::JointState jointState(int k) {
  msg::JointState m;
  m.header(header(k));
  for (int i = 0; i < 21; ++i) {
    m.names().push_back("joint_" + std::to_string(i));
    m.positions().push_back(0.01 * i - 1.0 + 1e-3 * k);
    m.velocities().push_back(-0.5 * i);
  }
  return m;
}

inline msg::ControlStatus controlStatus(int k) {
  msg::ControlStatus m;
  m.header(header(k));
  m.left().blend_f(0.625);
  m.left().closest_segment_a("left_forearm");
  m.left().closest_segment_b("torso");
  m.left().distance(0.0125);
  m.left().zone(msg::ZONE_ORANGE);
  m.left().estop_latched(false);
  m.right().blend_f(1.0);
  m.right().closest_segment_a("right_hand");
  m.right().closest_segment_b("left_hand");
  m.right().distance(-0.001);
  m.right().zone(msg::ZONE_RED);
  m.right().estop_latched(true);
  m.cycle_period_us(5003.25);
  m.compute_time_us(812.5 + k);
  m.lateness_us(-3.5);
  m.overrun_count(0xFFFF'FFFF'FFFF'FFF0ULL);
  m.arm_distance(0.0375 + k);
  m.rejected_hand_targets(7);
  m.rejected_body_schema(0xFFFF'FFFF'FFFF'FFFEULL);
  m.rejected_walk_commands(2);
  m.rejected_robot_states(3);
  m.last_rejection("walk_goal_y_or_yaw_not_zero");
  return m;
}

inline msg::Heartbeat heartbeat(int k) {
  msg::Heartbeat m;
  m.header(header(k));
  m.module_name("vision_" + std::to_string(k));
  m.host("host-ü-42");  // UTF-8 bytes must pass through unchanged
  m.pid(-1);
  m.state(msg::STATE_STOPPING);
  m.period_ms(500);
  m.detail(std::string(300, 'd'));  // longer than the 255 bytes fastddsgen assumes for unbounded strings
  return m;
}

inline msg::ControllerProtection controllerProtection(int k) {
  msg::ControllerProtection m;
  m.header(header(k));
  m.avoidance(k % 2 == 0);
  m.estop(true);
  m.reason("collision avoidance OFF by 'avoidance: off' in /tmp/c" + std::to_string(k) + ".yaml");
  m.period(0.005);
  m.robot("asimo_like");
  return m;
}

// The robot boundary (idl/robot.idl): 64 joints (the IDL's bound) in the state, a few in the command.
inline msg::RobotState robotState(int k) {
  msg::RobotState m;
  m.header(header(k));
  for (int i = 0; i < 64; ++i) {
    m.names().push_back(i == 5 ? "l_shoulder_pitch" : "joint_" + std::to_string(i));
    m.positions().push_back(-3.0 + 0.1 * i + 1e-6 * k);
    m.velocities().push_back(i % 2 == 0 ? -0.25 * i - 0.125 : 1e-308);  // no -0.0: JSON (the reference reader) has none
    if (i < 63) m.efforts().push_back(-100.0 + 3.5 * i);                // one short: efforts need not be complete here
  }
  m.applied_command_seq(0xFFFF'FFFF'FFFF'FFFEULL - static_cast<std::uint64_t>(k));
  m.holding(k % 2 == 1);
  return m;
}

inline msg::JointCommand jointCommand(int k) {
  msg::JointCommand m;
  m.header(header(k));
  for (int i = 0; i < 10; ++i) {
    m.names().push_back((i < 5 ? "l_" : "r_") + std::to_string(i));
    m.positions().push_back(0.5 - 0.125 * i);
    m.velocities().push_back(-2.0 + 0.5 * i + 1e-3 * k);
  }
  m.valid_until_ns(-1 - k);  // negative on purpose: the sign must survive
  m.state_seq(77u + static_cast<std::uint64_t>(k));
  m.state_stamp_ns(1'700'000'000'000'000'001LL + k);
  return m;
}

inline msg::RobotContacts robotContacts(int k) {
  msg::RobotContacts m;
  m.header(header(k));
  m.state_seq(123456789u + static_cast<std::uint64_t>(k));
  for (int i = 0; i < 3; ++i) {
    msg::SegmentContact c;
    c.segment_a(i == 2 ? std::string() : "l_forearm_" + std::to_string(i));
    c.segment_b("torso");
    c.distance(i == 0 ? -0.0015 : 0.004 + 1e-4 * i);  // negative: penetration
    m.contacts().push_back(c);
  }
  m.total_contact_steps(0xFFFF'FFFF'0000'0000ULL + static_cast<std::uint64_t>(k));
  return m;
}

inline msg::CameraImage cameraImage(int k) {
  msg::CameraImage m;
  m.header(header(k));
  m.capture_stamp_ns(-7 - k);  // negative on purpose: sign must survive
  m.image_index(0xFFFF'FFFF'0000'0002ULL + static_cast<std::uint64_t>(k));
  m.frame_id("left_camera_optical");
  m.format(k % 2 == 0 ? "jpeg" : "png");
  m.width(640u + static_cast<std::uint32_t>(k));
  m.height(0xFFFF'FFFFu);
  // 200 kB (several fragments on UDP) of every byte value, 0 and 255 included.
  m.data().resize(200'000);
  for (std::size_t i = 0; i < m.data().size(); ++i) m.data()[i] = static_cast<std::uint8_t>((i * 131 + k) & 0xFF);
  return m;
}

}  // namespace reflex::bus::test
