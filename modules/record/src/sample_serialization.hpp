// A Reflex sample <-> the XCDR1 bytes of a recording, through the type's Fast DDS type support
// (fastddsgen PubSubType): what the codecs (codecs.cpp) and the scene channels (scene_channels.cpp)
// decode recorded payloads with. Private to modules/record.
#pragma once

#include "reflex/record/record_file.hpp"

#include <reflex/bus/topics.hpp>

#include <algorithm>
#include <cstdint>
#include <exception>
#include <string>
#include <vector>

namespace reflex::record {

/// The serialized bytes (encapsulation header included) of `sample`. Throws RecordError naming the type
/// if the type support refuses it.
template <class T>
inline std::vector<std::uint8_t> serializeSample(const T& sample) {
  typename bus::TopicTraits<T>::PubSubType type;
  void* data = const_cast<T*>(&sample);  // the type support only reads it
  const std::uint32_t size = type.getSerializedSizeProvider(data)();
  eprosima::fastrtps::rtps::SerializedPayload_t payload(size);
  if (!type.serialize(data, &payload))
    throw RecordError(std::string("cannot serialize a ") + type.getName() + " sample (" + std::to_string(size) + " bytes)");
  return std::vector<std::uint8_t>(payload.data, payload.data + payload.length);
}

/// Decodes `bytes` into `out`; false (never throws) if they are not a valid sample of T.
template <class T>
bool deserializeSample(const std::vector<std::uint8_t>& bytes, T& out) {
  typename bus::TopicTraits<T>::PubSubType type;
  eprosima::fastrtps::rtps::SerializedPayload_t payload(static_cast<std::uint32_t>(bytes.size()));
  std::copy(bytes.begin(), bytes.end(), payload.data);
  payload.length = static_cast<std::uint32_t>(bytes.size());
  try {
    return type.deserialize(&payload, &out);
  } catch (const std::exception&) {  // fastcdr throws BadParamException on inconsistent lengths
    return false;
  }
}

}  // namespace reflex::record
