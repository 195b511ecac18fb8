// A Reflex sample <-> the XCDR1 bytes of a recording, through the type's Fast DDS type support
// (fastddsgen PubSubType): what the codecs (codecs.cpp) and the scene channels (scene_channels.cpp)
// decode recorded payloads with. Private to modules/record.
#pragma once

#include "cdr_check.hpp"
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
    throw RecordError(std::string("cannot serialize a ") + type.getName() + " sample (" + std::to_string(size) +
                      " bytes)");
  return std::vector<std::uint8_t>(payload.data, payload.data + payload.length);
}

/// Decodes `bytes` into `out`; false (never throws) if they are not a valid sample of T, with the reason
/// in `why` if given. The lengths are checked against the bytes present first (cdrLengthProblem): the
/// type support would allocate what a count claims before finding the bytes missing.
template <class T>
bool deserializeSample(const std::vector<std::uint8_t>& bytes, T& out, std::string* why = nullptr) {
  typename bus::TopicTraits<T>::PubSubType type;
  if (const std::string problem = cdrLengthProblem(type.getName(), bytes.data(), bytes.size()); !problem.empty()) {
    if (why) *why = problem;
    return false;
  }
  eprosima::fastrtps::rtps::SerializedPayload_t payload(static_cast<std::uint32_t>(bytes.size()));
  std::copy(bytes.begin(), bytes.end(), payload.data);
  payload.length = static_cast<std::uint32_t>(bytes.size());
  try {
    if (type.deserialize(&payload, &out)) return true;
    if (why) *why = "the type support refuses it";
  } catch (const std::exception& e) {  // fastcdr throws BadParamException on inconsistent lengths
    if (why) *why = e.what();
  }
  return false;
}

}  // namespace reflex::record
