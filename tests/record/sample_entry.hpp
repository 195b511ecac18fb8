// A RecordEntry holding one sample of a Reflex topic type, serialized with the type's own Fast DDS
// type support (the bytes a recorder stores): for the record tests that write recordings by hand.
#pragma once

#include "reflex/record/record_file.hpp"

#include <reflex/bus/bus.hpp>

#include <gtest/gtest.h>

#include <cstdint>

namespace reflex::record::test {

/// The sample on its default topic, received at `receive_ns` (source_ns left 0).
template <class T>
RecordEntry entryOf(const T& sample, std::int64_t receive_ns) {
  typename bus::TopicTraits<T>::PubSubType type;
  void* data = const_cast<T*>(&sample);  // the type support only reads it
  eprosima::fastrtps::rtps::SerializedPayload_t p(type.getSerializedSizeProvider(data)());
  EXPECT_TRUE(type.serialize(data, &p));
  RecordEntry e;
  e.receive_ns = receive_ns;
  e.topic = bus::TopicTraits<T>::kTopicName;
  e.type = type.getName();
  e.payload.assign(p.data, p.data + p.length);
  return e;
}

}  // namespace reflex::record::test
