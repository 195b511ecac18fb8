// DDS key strings are bounded at the bus. Checked against the generated code
// itself (not against our constant): fastddsgen's getKey of Heartbeat (key module_name) and of
// BodySchemaChange (key segment_name) throws for a 256-byte key and not for 255 — inside
// DataWriter::write that exception ended the publishing process (SIGABRT). Then, over real DDS
// (domain 180): Writer::publish / write deliver a 255-byte key and REFUSE (return false, count,
// never abort) 256, 300 and 100,000 bytes; the reader-side type support rejects such a sample from
// the wire; a Participant whose module name (its heartbeat key) is too long is a BusError quoting
// the name and the limit.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <reflex/bus/bus.hpp>

#include <chrono>
#include <string>
#include <thread>

namespace reflex::bus {
namespace {

using namespace std::chrono_literals;
using ::testing::HasSubstr;
constexpr int kDomain = 180;

template <class PubSub, class T>
bool generatedGetKeyThrows(T& sample) {
  PubSub type;
  eprosima::fastrtps::rtps::InstanceHandle_t handle;
  try {
    type.getKey(&sample, &handle, false);
  } catch (const eprosima::fastcdr::exception::Exception&) {
    return true;
  }
  return false;
}

TEST(KeyBound, TheGeneratedKeyCodeThrowsAboveTheBoundAndNotAtIt) {
  msg::Heartbeat hb;
  hb.module_name(std::string(kMaxKeyStringBytes, 'h'));
  EXPECT_FALSE(generatedGetKeyThrows<msg::HeartbeatPubSubType>(hb));
  hb.module_name(std::string(kMaxKeyStringBytes + 1, 'h'));
  EXPECT_TRUE(generatedGetKeyThrows<msg::HeartbeatPubSubType>(hb)) << "the bound is the generated code's limit";
  msg::BodySchemaChange c;
  c.segment_name(std::string(kMaxKeyStringBytes, 's'));
  EXPECT_FALSE(generatedGetKeyThrows<msg::BodySchemaChangePubSubType>(c));
  c.segment_name(std::string(kMaxKeyStringBytes + 1, 's'));
  EXPECT_TRUE(generatedGetKeyThrows<msg::BodySchemaChangePubSubType>(c));
  // Our type support never lets it out (last line behind the writer's check).
  TopicTraits<msg::Heartbeat>::PubSubType safe;
  eprosima::fastrtps::rtps::InstanceHandle_t handle;
  hb.module_name(std::string(100000, 'h'));
  EXPECT_NO_THROW(EXPECT_FALSE(safe.getKey(&hb, &handle, false)));
}

TEST(KeyBound, WritersRefuseAndCountLongKeysAndDeliverTheLongestAllowed) {
  BusConfig config;
  config.domain_id = kDomain;
  config.module_name = "key_writer";
  Participant pub(config);
  config.module_name = "key_reader";
  Participant sub(config);
  auto& hb_writer = pub.makeWriter<msg::Heartbeat>();
  auto& schema_writer = pub.makeWriter<msg::BodySchemaChange>();
  auto& hb_reader = sub.makeReader<msg::Heartbeat>();
  auto& schema_reader = sub.makeReader<msg::BodySchemaChange>();
  ASSERT_TRUE(hb_writer.waitForReaders(1, 10s) && schema_writer.waitForReaders(1, 10s));
  ASSERT_TRUE(hb_reader.waitForWriters(1, 10s) && schema_reader.waitForWriters(1, 10s));

  for (std::size_t n : {kMaxKeyStringBytes + 1, std::size_t{300}, std::size_t{100000}}) {
    msg::Heartbeat hb;
    hb.module_name(std::string(n, 'x'));
    EXPECT_FALSE(hb_writer.publish(hb)) << n << " bytes";
    msg::BodySchemaChange c;
    c.segment_name(std::string(n, 'y'));
    EXPECT_FALSE(schema_writer.write(c)) << n << " bytes";
  }
  EXPECT_EQ(hb_writer.stats().refused_key_too_long, 3U);
  EXPECT_EQ(schema_writer.stats().refused_key_too_long, 3U);
  EXPECT_EQ(hb_writer.lastSeq(), 0U) << "a refused sample takes no sequence number";

  msg::Heartbeat longest;
  longest.module_name(std::string(kMaxKeyStringBytes, 'z'));
  ASSERT_TRUE(hb_writer.publish(longest));
  msg::BodySchemaChange longest_segment;
  longest_segment.segment_name(std::string(kMaxKeyStringBytes, 'w'));
  ASSERT_TRUE(schema_writer.publish(longest_segment));
  ASSERT_TRUE(hb_reader.waitForData(5s));
  ASSERT_TRUE(schema_reader.waitForData(5s));
  msg::Heartbeat got;
  ASSERT_TRUE(hb_reader.takeNext(got));
  EXPECT_EQ(got.module_name(), longest.module_name());
  msg::BodySchemaChange got_segment;
  ASSERT_TRUE(schema_reader.takeNext(got_segment));
  EXPECT_EQ(got_segment.segment_name().size(), kMaxKeyStringBytes);
  EXPECT_FALSE(hb_reader.takeNext(got)) << "nothing else arrived";
}

TEST(KeyBound, TheReaderTypeSupportRejectsALongKeyFromTheWire) {
  // A payload another vendor could send: serialized by the generated code (no key check there).
  msg::Heartbeat hb;
  hb.module_name(std::string(kMaxKeyStringBytes + 1, 'q'));
  msg::HeartbeatPubSubType generated;
  eprosima::fastrtps::rtps::SerializedPayload_t payload(generated.getSerializedSizeProvider(&hb)());
  ASSERT_TRUE(generated.serialize(&hb, &payload));
  TopicTraits<msg::Heartbeat>::PubSubType safe;
  msg::Heartbeat out;
  EXPECT_FALSE(safe.deserialize(&payload, &out));
  hb.module_name(std::string(kMaxKeyStringBytes, 'q'));
  eprosima::fastrtps::rtps::SerializedPayload_t ok(generated.getSerializedSizeProvider(&hb)());
  ASSERT_TRUE(generated.serialize(&hb, &ok));
  EXPECT_TRUE(safe.deserialize(&ok, &out));
}

TEST(KeyBound, AModuleNameAboveTheBoundIsASetupErrorQuotingItAndTheLimit) {
  BusConfig config;
  config.domain_id = kDomain;
  config.module_name = std::string(kMaxKeyStringBytes + 1, 'n');
  try {
    Participant p(config);
    ADD_FAILURE() << "a 256-byte module name was accepted";
  } catch (const BusError& e) {
    EXPECT_THAT(e.what(), HasSubstr(config.module_name));
    EXPECT_THAT(e.what(), HasSubstr("at most 255 bytes"));
  }
  config.module_name = std::string(kMaxKeyStringBytes, 'n');
  Participant longest(config);  // the longest allowed name: its heartbeat goes out
  HeartbeatPublisher heartbeat(longest);
  heartbeat.setState(msg::STATE_RUNNING);
}

}  // namespace
}  // namespace reflex::bus
