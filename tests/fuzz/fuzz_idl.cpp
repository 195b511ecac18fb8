// libFuzzer target: bytes from the network -> every Reflex topic type's deserializer
// (TopicTraits<T>::PubSubType::deserialize, what Fast DDS runs on every received sample): the
// generated ones, and the field-by-field readers of the robot states (reflex/robot_state and ROS 2's
// sensor_msgs/JointState, bus/cdr_read.hpp), whose round trip through the generated serializer also
// checks that they read the layout the generated code writes.
// Input: byte 0 picks the type, the rest is the serialized payload (CDR encapsulation + body).
// Contract: deserialize either fails (returns false) or yields a sample that serializes again and
// round-trips to the same bytes; never a crash, a sanitizer report or an exception.
// (What a consumer does with a decoded sample — NaN / far / unknown values — is covered by the
// bad-input tests against the real processes, tests/bad_input/.)
#include "fuzz_util.hpp"

#include <reflex/bus/ros2_topics.hpp>
#include <reflex/bus/topics.hpp>

#include <cstring>
#include <vector>

namespace {

using eprosima::fastrtps::rtps::SerializedPayload_t;

template <class T>
void roundTrip(const std::uint8_t* data, std::size_t size) {
  typename reflex::bus::TopicTraits<T>::PubSubType type;
  SerializedPayload_t in(static_cast<std::uint32_t>(size));
  if (size > 0) std::memcpy(in.data, data, size);
  in.length = static_cast<std::uint32_t>(size);
  T sample;
  if (!type.deserialize(&in, &sample)) return;  // rejected: fine

  auto encode = [&](T& s, SerializedPayload_t& out) {
    if (!type.serialize(&s, &out)) {
      std::fprintf(stderr, "FUZZ FINDING: a decoded %s does not serialize again\n", type.getName());
      std::abort();
    }
  };
  SerializedPayload_t once(type.getSerializedSizeProvider(&sample)());
  encode(sample, once);
  T again;
  if (!type.deserialize(&once, &again)) {
    std::fprintf(stderr, "FUZZ FINDING: a re-serialized %s does not deserialize\n", type.getName());
    std::abort();
  }
  SerializedPayload_t twice(type.getSerializedSizeProvider(&again)());
  encode(again, twice);
  if (once.length != twice.length || std::memcmp(once.data, twice.data, once.length) != 0) {
    std::fprintf(stderr, "FUZZ FINDING: %s does not round-trip\n", type.getName());
    std::abort();
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size < 1) return 0;
  const std::uint8_t which = data[0] % 11;
  ++data;
  --size;
  try {
    switch (which) {
      case 0: roundTrip<reflex::msg::ObjectTargets>(data, size); break;
      case 1: roundTrip<reflex::msg::HandTargets>(data, size); break;
      case 2: roundTrip<reflex::msg::MotionPriority>(data, size); break;
      case 3: roundTrip<reflex::msg::BodySchemaChange>(data, size); break;
      case 4: roundTrip<reflex::msg::WalkCommand>(data, size); break;
      case 5: roundTrip<reflex::msg::JointState>(data, size); break;
      case 6: roundTrip<reflex::msg::ControlStatus>(data, size); break;
      case 8: roundTrip<reflex::msg::RobotState>(data, size); break;
      case 9: roundTrip<reflex::ros2::JointState>(data, size); break;
      case 10: roundTrip<reflex::msg::CameraImage>(data, size); break;
      default: roundTrip<reflex::msg::Heartbeat>(data, size); break;
    }
  } catch (const std::exception& e) {
    reflex::fuzz::undocumentedException("PubSubType::deserialize", e);
  }
  return 0;
}
