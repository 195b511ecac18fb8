// The topics of the Reflex system: for every topic type T (generated from idl/*.idl into
// <reflex/msg/*.h>), TopicTraits<T> gives its Fast DDS type support, its default topic name and the
// name of its QoS profile in bringup/dds/reflex_profiles.xml (the same name is used for the
// data_writer and the data_reader profile). idl/README.md has the table with rates and publishers.
//
// To add a topic type: write it in an idl/*.idl file (plain struct starting with `Header header;`),
// add the file to REFLEX_IDL_FILES in idl/CMakeLists.txt if new, specialize TopicTraits below, pick
// or add a profile in the profiles file, and add it to the round-trip test in tests/bus/.
#pragma once

#include <reflex/msg/behaviorPubSubTypes.h>
#include <reflex/msg/controlPubSubTypes.h>
#include <reflex/msg/robotPubSubTypes.h>
#include <reflex/msg/systemPubSubTypes.h>
#include <reflex/msg/visionPubSubTypes.h>

#include <reflex/bus/cdr_read.hpp>

#include <fastcdr/Cdr.h>
#include <fastcdr/FastBuffer.h>
#include <fastcdr/exceptions/Exception.h>

#include <cstddef>
#include <type_traits>

namespace reflex::bus {

/// Longest string (bytes, without the terminating NUL) that may be a DDS key: fastddsgen 2.3 sizes
/// the key buffer of an unbounded `@key string` as 4 (length) + 255 + 1 (NUL) bytes, and a longer
/// key makes getKey throw inside DataWriter::write, which ends the process (SIGABRT).
/// Measured: 255 bytes publish, 256 abort (tests/bus/key_bound_test.cpp).
inline constexpr std::size_t kMaxKeyStringBytes = 255;

/// Length in bytes of the longest @key string of a sample (0 for a type without a key). Every keyed
/// type of idl/ has an overload here; Writer::publish / write refuse a sample above kMaxKeyStringBytes
/// and SafePubSubType rejects one arriving from the wire.
template <class T>
std::size_t keyStringBytes(const T&) noexcept {
  return 0;
}
inline std::size_t keyStringBytes(const reflex::msg::Heartbeat& s) noexcept { return s.module_name().size(); }
inline std::size_t keyStringBytes(const reflex::msg::BodySchemaChange& s) noexcept { return s.segment_name().size(); }

/// SafePubSubType's default: the generated deserializer (Read: a struct with
/// `static void read(eprosima::fastcdr::Cdr&, T&)` reads the sample instead; cdr_read.hpp).
struct GeneratedRead {};

/// The generated type support with a deserializer that never throws: fastddsgen 2.3 code catches only
/// NotEnoughMemoryException, so a malformed payload (bad encapsulation, a boolean byte of 2, ...)
/// let a fastcdr BadParamException escape through DataReader::take into the process (a fuzz finding:
/// one rogue sample ended reflex_controller). Here every fastcdr exception makes deserialize return
/// false, and Fast DDS drops the sample. A sample whose key string is longer than kMaxKeyStringBytes
/// (another vendor's writer does not stop it) is rejected the same way: computing its key would throw.
/// getKey never lets an exception out either (the writer checks first; this is the last line).
template <class Generated, class Read = GeneratedRead>
class SafePubSubType final : public Generated {
 public:
  bool deserialize(eprosima::fastrtps::rtps::SerializedPayload_t* payload, void* data) override {
    try {
      if constexpr (std::is_same_v<Read, GeneratedRead>) {
        if (!Generated::deserialize(payload, data)) return false;
      } else {  // as the generated code, with Read's reader
        eprosima::fastcdr::FastBuffer buffer(reinterpret_cast<char*>(payload->data), payload->length);
        eprosima::fastcdr::Cdr cdr(buffer, eprosima::fastcdr::Cdr::DEFAULT_ENDIAN, eprosima::fastcdr::Cdr::DDS_CDR);
        cdr.read_encapsulation();
        payload->encapsulation = cdr.endianness() == eprosima::fastcdr::Cdr::BIG_ENDIANNESS ? CDR_BE : CDR_LE;
        Read::read(cdr, *static_cast<typename Generated::type*>(data));
      }
    } catch (const eprosima::fastcdr::exception::Exception&) {
      return false;
    }
    return keyStringBytes(*static_cast<const typename Generated::type*>(data)) <= kMaxKeyStringBytes;
  }
  bool getKey(void* data, eprosima::fastrtps::rtps::InstanceHandle_t* handle, bool force_md5) override {
    try {
      return Generated::getKey(data, handle, force_md5);
    } catch (const eprosima::fastcdr::exception::Exception&) {
      return false;
    }
  }
};

/// Specialized for every topic type; using a type without a specialization does not compile.
template <class T>
struct TopicTraits;

// Profile names (bringup/dds/reflex_profiles.xml).
inline constexpr const char* kProfileState = "reflex_state";                   // controller output, every control cycle
inline constexpr const char* kProfileBehavior = "reflex_behavior";             // behavior module outputs
inline constexpr const char* kProfileObjectTargets = "reflex_object_targets";  // vision output
inline constexpr const char* kProfileHeartbeat = "reflex_heartbeat";           // module heartbeats
inline constexpr const char* kProfileRecord = "reflex_record";                 // reader only: recorders
inline constexpr const char* kProfileRecordReliable =
    "reflex_record_reliable";  // reader only: recorders, reliable topics
inline constexpr const char* kProfileControllerInfo = "reflex_controller_info";  // controller protection
inline constexpr const char* kProfileRobot =
    "reflex_robot";  // robot state / joint command (the robot's rate / every control cycle)
inline constexpr const char* kProfileCameraImage = "reflex_camera_image";  // vision's camera image, a few Hz

/// Largest CameraImage::data a writer publishes and a reader takes (a 640 x 480 JPEG is about 50 kB).
inline constexpr std::size_t kMaxCameraImageBytes = 4u << 20;

template <>
struct TopicTraits<reflex::msg::ObjectTargets> {
  using PubSubType = SafePubSubType<reflex::msg::ObjectTargetsPubSubType>;
  static constexpr const char* kTopicName = "reflex/object_targets";
  static constexpr const char* kProfile = kProfileObjectTargets;
};

template <>
struct TopicTraits<reflex::msg::CameraImage> {
  using PubSubType = SafePubSubType<reflex::msg::CameraImagePubSubType>;
  static constexpr const char* kTopicName = "reflex/camera_left";
  static constexpr const char* kProfile = kProfileCameraImage;
};

template <>
struct TopicTraits<reflex::msg::HandTargets> {
  using PubSubType = SafePubSubType<reflex::msg::HandTargetsPubSubType>;
  static constexpr const char* kTopicName = "reflex/hand_targets";
  static constexpr const char* kProfile = kProfileBehavior;
};

template <>
struct TopicTraits<reflex::msg::MotionPriority> {
  using PubSubType = SafePubSubType<reflex::msg::MotionPriorityPubSubType>;
  static constexpr const char* kTopicName = "reflex/motion_priority";
  static constexpr const char* kProfile = kProfileBehavior;
};

template <>
struct TopicTraits<reflex::msg::BodySchemaChange> {
  using PubSubType = SafePubSubType<reflex::msg::BodySchemaChangePubSubType>;
  static constexpr const char* kTopicName = "reflex/body_schema";
  static constexpr const char* kProfile = kProfileBehavior;
};

template <>
struct TopicTraits<reflex::msg::WalkCommand> {
  using PubSubType = SafePubSubType<reflex::msg::WalkCommandPubSubType>;
  static constexpr const char* kTopicName = "reflex/walk_command";
  static constexpr const char* kProfile = kProfileBehavior;
};

// reflex_mujoco's judge (robot.idl RobotContacts), published with each RobotState: same QoS.
template <>
struct TopicTraits<reflex::msg::RobotContacts> {
  using PubSubType = SafePubSubType<reflex::msg::RobotContactsPubSubType>;
  static constexpr const char* kTopicName = "reflex/robot_contacts";
  static constexpr const char* kProfile = kProfileRobot;
};

template <>
struct TopicTraits<reflex::msg::JointState> {
  using PubSubType = SafePubSubType<reflex::msg::JointStatePubSubType>;
  static constexpr const char* kTopicName = "reflex/joint_state";
  static constexpr const char* kProfile = kProfileState;
};

template <>
struct TopicTraits<reflex::msg::ControlStatus> {
  using PubSubType = SafePubSubType<reflex::msg::ControlStatusPubSubType>;
  static constexpr const char* kTopicName = "reflex/control_status";
  static constexpr const char* kProfile = kProfileState;
};

template <>
struct TopicTraits<reflex::msg::Heartbeat> {
  using PubSubType = SafePubSubType<reflex::msg::HeartbeatPubSubType>;
  static constexpr const char* kTopicName = "reflex/heartbeat";
  static constexpr const char* kProfile = kProfileHeartbeat;
};

template <>
struct TopicTraits<reflex::msg::ControllerProtection> {
  using PubSubType = SafePubSubType<reflex::msg::ControllerProtectionPubSubType>;
  static constexpr const char* kTopicName = "reflex/controller_protection";
  static constexpr const char* kProfile = kProfileControllerInfo;
};

// The robot boundary (idl/robot.idl): the robot's measured state and the controller's command.
/// RobotState, field by field as idl/robot.idl and common.idl lay it out, its strings read without
/// allocating (cdr_read.hpp): the controller takes one every cycle.
struct RobotStateRead {
  static void read(eprosima::fastcdr::Cdr& cdr, reflex::msg::RobotState& s) {
    cdr >> s.header().stamp_ns() >> s.header().seq();
    readString(cdr, s.header().source());
    readStrings(cdr, s.names(), 64);
    readDoubles(cdr, s.positions(), 64);
    readDoubles(cdr, s.velocities(), 64);
    readDoubles(cdr, s.efforts(), 64);
    cdr >> s.applied_command_seq() >> s.holding();
  }
};

template <>
struct TopicTraits<reflex::msg::RobotState> {
  using PubSubType = SafePubSubType<reflex::msg::RobotStatePubSubType, RobotStateRead>;
  static constexpr const char* kTopicName = "reflex/robot_state";
  static constexpr const char* kProfile = kProfileRobot;
};

template <>
struct TopicTraits<reflex::msg::JointCommand> {
  using PubSubType = SafePubSubType<reflex::msg::JointCommandPubSubType>;
  static constexpr const char* kTopicName = "reflex/joint_command";
  static constexpr const char* kProfile = kProfileRobot;
};

}  // namespace reflex::bus
