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
#include <reflex/msg/systemPubSubTypes.h>
#include <reflex/msg/visionPubSubTypes.h>

#include <fastcdr/exceptions/Exception.h>

namespace reflex::bus {

/// The generated type support with a deserializer that never throws: fastddsgen 2.3 code catches only
/// NotEnoughMemoryException, so a malformed payload (bad encapsulation, a boolean byte of 2, ...)
/// let a fastcdr BadParamException escape through DataReader::take into the process (a fuzz finding:
/// one rogue sample ended reflex_controller). Here every fastcdr exception makes deserialize return
/// false, and Fast DDS drops the sample.
template <class Generated>
class SafePubSubType final : public Generated {
 public:
  bool deserialize(eprosima::fastrtps::rtps::SerializedPayload_t* payload, void* data) override {
    try {
      return Generated::deserialize(payload, data);
    } catch (const eprosima::fastcdr::exception::Exception&) {
      return false;
    }
  }
};

/// Specialized for every topic type; using a type without a specialization does not compile.
template <class T>
struct TopicTraits;

// Profile names (bringup/dds/reflex_profiles.xml).
inline constexpr const char* kProfileState = "reflex_state";                 // 200 Hz controller output
inline constexpr const char* kProfileBehavior = "reflex_behavior";           // behavior module outputs
inline constexpr const char* kProfileObjectTargets = "reflex_object_targets";  // vision output
inline constexpr const char* kProfileHeartbeat = "reflex_heartbeat";         // module heartbeats
inline constexpr const char* kProfileRecord = "reflex_record";               // reader only: recorders
inline constexpr const char* kProfileRecordReliable = "reflex_record_reliable";  // reader only: recorders, reliable topics

template <>
struct TopicTraits<reflex::msg::ObjectTargets> {
  using PubSubType = SafePubSubType<reflex::msg::ObjectTargetsPubSubType>;
  static constexpr const char* kTopicName = "reflex/object_targets";
  static constexpr const char* kProfile = kProfileObjectTargets;
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

}  // namespace reflex::bus
