// Writes one serialized sample of every Reflex topic type, prefixed with the type selector byte of
// fuzz_idl.cpp, into the folder given as argument: the seed corpus of fuzz_idl.
#include <reflex/bus/ros2_topics.hpp>
#include <reflex/bus/topics.hpp>

#include <cstdio>
#include <fstream>
#include <string>
#include <type_traits>

namespace {

using eprosima::fastrtps::rtps::SerializedPayload_t;

template <class T>
bool writeSeed(const std::string& dir, std::uint8_t selector, T sample) {
  typename reflex::bus::TopicTraits<T>::PubSubType type;
  if constexpr (std::is_same_v<T, reflex::ros2::JointState>) {  // ROS 2's header: stamp and frame
    sample.header().stamp().sec(1700000000);
    sample.header().frame_id("base_link");
  } else {
    sample.header().stamp_ns(1700000000000000000LL);
    sample.header().seq(7);
    sample.header().source("seed");
  }
  SerializedPayload_t out(type.getSerializedSizeProvider(&sample)());
  if (!type.serialize(&sample, &out)) return false;
  std::ofstream f(dir + "/seed_" + std::to_string(selector), std::ios::binary | std::ios::trunc);
  f.put(static_cast<char>(selector));
  f.write(reinterpret_cast<const char*>(out.data), out.length);
  return static_cast<bool>(f);
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 2 || std::string(argv[1]) == "--help") {
    std::fprintf(stderr, "usage: %s DIR\nWrites the seed corpus of fuzz_idl into DIR (which must exist).\n", argv[0]);
    return argc == 2 ? 0 : 2;
  }
  const std::string dir = argv[1];
  using namespace reflex::msg;
  ObjectTargets objects;
  objects.frame_id("base_link");
  ObjectTarget cup;
  cup.name("cup");
  cup.tag_id(3);
  cup.position_base().x(0.4);
  cup.confidence(0.9);
  objects.objects().push_back(cup);
  HandTargets hands;
  hands.left().status(TARGET_GIVEN);
  hands.left().position_base().x(0.3);
  hands.left().object_name("cup");
  MotionPriority priority;
  priority.priority(PRIORITY_LEFT_HIGHER);
  BodySchemaChange schema;
  schema.segment_name("grasped_bar");
  schema.parent_link("l_hand");
  schema.shape(SHAPE_CAPSULE);
  schema.radius(0.02);
  schema.enabled(true);
  WalkCommand walk;
  walk.goal_x(1.0);
  walk.speed(0.2);
  JointState joints;
  joints.names({"l_elbow", "r_elbow"});
  joints.positions({-0.5, -0.5});
  joints.velocities({0.0, 0.1});
  ControlStatus status;
  status.left().closest_segment_a("l_hand");
  status.cycle_period_us(5000.0);
  Heartbeat hb;
  hb.module_name("vision");
  hb.host("robot");
  hb.state(STATE_RUNNING);
  RobotState robot;  // read field by field (bus/cdr_read.hpp), not by the generated code
  robot.names({"l_shoulder_pitch", "l_elbow"});
  robot.positions({0.1, -0.5});
  robot.velocities({0.0, 0.1});
  reflex::ros2::JointState ros_joints;  // likewise, sensor_msgs/JointState from a ROS 2 robot
  ros_joints.name({"l_shoulder_pitch", "l_elbow", "gripper_joint"});
  ros_joints.position({0.1, -0.5, 0.01});
  CameraImage image;  // an unbounded octet sequence
  image.frame_id("left_camera_optical");
  image.format("jpeg");
  image.width(2);
  image.height(1);
  image.data({0xFF, 0xD8, 0xFF, 0xE0, 0x00, 0x10, 0xFF, 0xD9});
  const bool ok = writeSeed(dir, 0, objects) && writeSeed(dir, 1, hands) && writeSeed(dir, 2, priority) &&
                  writeSeed(dir, 3, schema) && writeSeed(dir, 4, walk) && writeSeed(dir, 5, joints) &&
                  writeSeed(dir, 6, status) && writeSeed(dir, 7, hb) && writeSeed(dir, 8, robot) &&
                  writeSeed(dir, 9, ros_joints) && writeSeed(dir, 10, image);
  if (!ok) {
    std::fprintf(stderr, "error: cannot write the seeds into '%s'\n", dir.c_str());
    return 1;
  }
  return 0;
}
