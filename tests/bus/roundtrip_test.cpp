// Every Reflex topic type round-trips through a real DDS participant: a writer and a reader of the
// type's default topic and QoS profile on one domain (40) in one process. Every field, including
// strings, sequences and enums, is compared with the sent value; the stamping by publish() is
// checked against the clock and the writer's sequence counter.
#include <gtest/gtest.h>

#include <reflex/bus/participant.hpp>

#include <chrono>

#include "bus_test_util.hpp"

namespace reflex::bus::test {
namespace {

using namespace std::chrono_literals;
constexpr int kDomain = 40;

template <class T>
class RoundTrip : public ::testing::Test {};

using AllTypes =
    ::testing::Types<msg::ObjectTargets, msg::HandTargets, msg::MotionPriority, msg::BodySchemaChange, msg::WalkCommand,
                     msg::JointState, msg::ControlStatus, msg::Heartbeat, msg::ControllerProtection, msg::RobotState,
                     msg::JointCommand, msg::RobotContacts, msg::CameraImage>;
TYPED_TEST_SUITE(RoundTrip, AllTypes);

TYPED_TEST(RoundTrip, EveryFieldSurvivesAndPublishStamps) {
  using T = TypeParam;
  Participant bus(testConfig("roundtrip", kDomain));
  auto& writer = bus.makeWriter<T>();
  auto& reader = bus.makeReader<T>();
  EXPECT_EQ(writer.topicName(), TopicTraits<T>::kTopicName);
  EXPECT_EQ(reader.profileName(), TopicTraits<T>::kProfile);
  ASSERT_TRUE(writer.waitForReaders(1, 5s));
  ASSERT_TRUE(reader.waitForWriters(1, 5s));

  // 1) publish(): the header is stamped (time, seq 1, source = module name), the rest is sent as is.
  T sent = sampleOf<T>(0);
  const std::int64_t before = nowNs();
  ASSERT_TRUE(writer.publish(sent));
  const std::int64_t after = nowNs();
  EXPECT_EQ(sent.header().seq(), 1u);
  EXPECT_EQ(writer.lastSeq(), 1u);
  EXPECT_EQ(sent.header().source(), "roundtrip");
  EXPECT_GE(sent.header().stamp_ns(), before);
  EXPECT_LE(sent.header().stamp_ns(), after);

  ASSERT_TRUE(reader.waitForData(5s));
  T got;
  ASSERT_TRUE(reader.takeNext(got));
  Diffs d = diffSample(sent, got);
  EXPECT_TRUE(d.empty()) << join(d);

  // 2) write(): the header is left exactly as given (replay); a different sample arrives intact.
  const T second = sampleOf<T>(1);
  ASSERT_TRUE(writer.write(second));
  EXPECT_EQ(writer.lastSeq(), 1u);
  ASSERT_TRUE(reader.waitForData(5s));
  T got2;
  ASSERT_TRUE(reader.takeNext(got2));
  d = diffSample(second, got2);
  EXPECT_TRUE(d.empty()) << join(d);

  // 3) the next publish() continues the writer's sequence.
  T third = sampleOf<T>(2);
  ASSERT_TRUE(writer.publish(third));
  EXPECT_EQ(third.header().seq(), 2u);
  ASSERT_TRUE(reader.waitForData(5s));
  T got3;
  ASSERT_TRUE(reader.takeNext(got3));
  EXPECT_EQ(got3.header().seq(), 2u);
  d = diffSample(third, got3);
  EXPECT_TRUE(d.empty()) << join(d);

  EXPECT_FALSE(reader.takeNext(got3)) << "exactly three samples were sent";
  EXPECT_EQ(reader.stats().incompatible_qos, 0u);
  EXPECT_EQ(writer.stats().incompatible_qos, 0u);
}

// The largest sample the IDL allows (32 objects with long names) still goes through: Fast DDS
// sizes its buffers for 255-byte strings and must grow them.
TEST(RoundTripLimits, FullObjectTargetsWithLongNames) {
  Participant bus(testConfig("roundtrip", kDomain));
  auto& writer = bus.makeWriter<msg::ObjectTargets>();
  auto& reader = bus.makeReader<msg::ObjectTargets>();
  ASSERT_TRUE(writer.waitForReaders(1, 5s));
  msg::ObjectTargets sent = objectTargets(3);
  sent.objects().clear();
  for (int i = 0; i < 32; ++i) {
    msg::ObjectTarget o;
    o.name(std::string(1000, static_cast<char>('a' + i % 26)));
    o.tag_id(i);
    o.position_base(vec(i, -i, 0.5 * i));
    o.position_camera(vec(-i, i, 2.0 * i));
    o.confidence(i / 32.0);
    sent.objects().push_back(o);
  }
  ASSERT_TRUE(writer.publish(sent));
  ASSERT_TRUE(reader.waitForData(5s));
  msg::ObjectTargets got;
  ASSERT_TRUE(reader.takeNext(got));
  const Diffs d = diffSample(sent, got);
  EXPECT_TRUE(d.empty()) << join(d);
}

}  // namespace
}  // namespace reflex::bus::test
