// Record entries made and read with a type's own generated Fast DDS type support (not the
// recorder's codecs), for the record tests: an independent encoding of what the recorder stores.
#pragma once

#include "reflex/record/record_file.hpp"

#include <reflex/bus/bus.hpp>

#include <gtest/gtest.h>

#include <cstdint>

namespace reflex::record::test {

/// `sample` serialized as the recorder stores it (XCDR1 with its encapsulation header), on its
/// type's default topic, received at `receive_ns`.
template <class T>
RecordEntry encodeEntry(const T& sample, std::int64_t receive_ns) {
  typename bus::TopicTraits<T>::PubSubType type;
  void* data = const_cast<T*>(&sample);
  eprosima::fastrtps::rtps::SerializedPayload_t p(type.getSerializedSizeProvider(data)());
  EXPECT_TRUE(type.serialize(data, &p));
  RecordEntry e;
  e.receive_ns = receive_ns;
  e.topic = bus::TopicTraits<T>::kTopicName;
  e.type = type.getName();
  e.payload.assign(p.data, p.data + p.length);
  return e;
}

/// Decodes `e` into `out`; false if its type name is not T's or the payload does not decode.
template <class T>
bool decodeEntry(const RecordEntry& e, T& out) {
  typename bus::TopicTraits<T>::PubSubType type;
  if (e.type != type.getName()) return false;
  eprosima::fastrtps::rtps::SerializedPayload_t p(static_cast<std::uint32_t>(e.payload.size()));
  std::copy(e.payload.begin(), e.payload.end(), p.data);
  p.length = static_cast<std::uint32_t>(e.payload.size());
  return type.deserialize(&p, &out);
}

}  // namespace reflex::record::test
