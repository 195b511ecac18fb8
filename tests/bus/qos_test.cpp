// The QoS behaviours later issues rely on, each checked against what the profile promises
// (bringup/dds/reflex_profiles.xml), on domains 42-45:
//  - reflex_state: a missed deadline (20 ms) is reported to the reader and the writer once the
//    writer stops publishing;
//  - reflex_behavior: a late joiner receives the last behavior output (transient-local), per key
//    for the keyed body schema;
//  - keep-last 1 drops old samples (reflex_state, reflex_behavior), while the deep reflex_record
//    reader on the same stream keeps them all (the depth, not the transport, drops them);
//  - reflex_object_targets: an unread sample expires after its 300 ms lifespan;
//  - reflex_heartbeat: a writer that stops asserting liveliness is declared not alive (1.5 s lease).
#include <gtest/gtest.h>

#include <reflex/bus/participant.hpp>

#include <chrono>
#include <map>
#include <thread>

#include "bus_test_util.hpp"

namespace reflex::bus::test {
namespace {

using namespace std::chrono_literals;

template <class Pred>
bool eventually(Pred ok, std::chrono::milliseconds timeout) {
  const auto end = std::chrono::steady_clock::now() + timeout;
  while (!ok()) {
    if (std::chrono::steady_clock::now() >= end) return false;
    std::this_thread::sleep_for(5ms);
  }
  return true;
}

TEST(Qos, MissedDeadlineIsReportedWhenTheWriterStops) {
  Participant bus(testConfig("qos_deadline", 42));
  auto& writer = bus.makeWriter<msg::JointState>();
  auto& reader = bus.makeReader<msg::JointState>();
  ASSERT_TRUE(writer.waitForReaders(1, 5s));

  msg::JointState s = jointState(0);
  msg::JointState got;
  std::size_t received = 0;
  for (int i = 0; i < 40; ++i) {  // 200 Hz for 200 ms, like the controller
    ASSERT_TRUE(writer.publish(s));
    while (reader.takeNext(got)) ++received;
    std::this_thread::sleep_for(5ms);
  }
  EXPECT_GE(received, 30u) << "best effort in one process should lose (almost) nothing";
  const auto at_stop = reader.stats().deadline_missed;

  // Silence for 200 ms = 10 deadline periods of 20 ms: the reader is told, repeatedly.
  std::this_thread::sleep_for(200ms);
  const auto after = reader.stats();
  EXPECT_GE(after.deadline_missed - at_stop, 5u) << "expected about 10 missed 20 ms deadlines";
  EXPECT_GE(writer.stats().deadline_missed, 5u) << "the writer is told it missed its offered deadline";
}

TEST(Qos, LateJoinerReceivesTheLastBehaviorOutput) {
  Participant module(testConfig("qos_late_module", 43));
  auto& writer = module.makeWriter<msg::HandTargets>();
  for (int k = 0; k < 5; ++k) {
    msg::HandTargets t = handTargets(k);
    ASSERT_TRUE(writer.publish(t));
  }
  // The controller starts only now, in its own participant.
  Participant controller(testConfig("qos_late_controller", 43));
  auto& reader = controller.makeReader<msg::HandTargets>();
  ASSERT_TRUE(reader.waitForData(5s)) << "transient-local must deliver the current targets";
  std::this_thread::sleep_for(100ms);  // anything else that would come, comes now
  std::vector<msg::HandTargets> got;
  reader.takeAll(got);
  ASSERT_EQ(got.size(), 1u) << "keep-last 1: only the current decision";
  EXPECT_EQ(got[0].header().seq(), 5u);
  msg::HandTargets expected = handTargets(4);
  expected.header(got[0].header());
  const Diffs d = diffSample(expected, got[0]);
  EXPECT_TRUE(d.empty()) << join(d);
}

TEST(Qos, LateJoinerReceivesTheCurrentStateOfEveryBodySchemaSegment) {
  Participant module(testConfig("qos_schema_module", 43));
  auto& writer = module.makeWriter<msg::BodySchemaChange>();
  // Three segments; "gaze_line_1" changes twice, its last change (radius 0.09) must win.
  for (int k : {0, 1, 2}) {
    msg::BodySchemaChange c = bodySchemaChange(k);
    ASSERT_TRUE(writer.publish(c));
  }
  msg::BodySchemaChange update = bodySchemaChange(1);
  update.radius(0.09);
  update.operation(msg::SCHEMA_ATTACH);
  ASSERT_TRUE(writer.publish(update));

  Participant controller(testConfig("qos_schema_controller", 43));
  auto& reader = controller.makeReader<msg::BodySchemaChange>();
  ASSERT_TRUE(reader.waitForData(5s));
  std::map<std::string, msg::BodySchemaChange> by_name;
  ASSERT_TRUE(eventually(
      [&] {
        msg::BodySchemaChange c;
        while (reader.takeNext(c)) by_name[c.segment_name()] = c;
        return by_name.size() >= 3;
      },
      5000ms));
  std::this_thread::sleep_for(100ms);
  msg::BodySchemaChange c;
  while (reader.takeNext(c)) by_name[c.segment_name()] = c;
  ASSERT_EQ(by_name.size(), 3u);
  EXPECT_EQ(by_name["gaze_line_0"].header().seq(), 1u);
  EXPECT_EQ(by_name["gaze_line_2"].header().seq(), 3u);
  EXPECT_EQ(by_name["gaze_line_1"].header().seq(), 4u);
  EXPECT_EQ(by_name["gaze_line_1"].radius(), 0.09);
  EXPECT_EQ(by_name["gaze_line_1"].operation(), msg::SCHEMA_ATTACH);
}

TEST(Qos, KeepLastOneDropsOldSamples) {
  Participant bus(testConfig("qos_keep_last", 44));
  auto& state_writer = bus.makeWriter<msg::ControlStatus>();
  auto& state_reader = bus.makeReader<msg::ControlStatus>();
  auto& record_reader = bus.makeReader<msg::ControlStatus>(TopicTraits<msg::ControlStatus>::kTopicName, kProfileRecord);
  auto& behavior_writer = bus.makeWriter<msg::MotionPriority>();
  auto& behavior_reader = bus.makeReader<msg::MotionPriority>();
  ASSERT_TRUE(state_writer.waitForReaders(2, 5s));
  ASSERT_TRUE(behavior_writer.waitForReaders(1, 5s));

  constexpr int kN = 50;
  msg::ControlStatus status = controlStatus(0);
  msg::MotionPriority priority = motionPriority(0);
  for (int i = 0; i < kN; ++i) {  // as fast as possible, nobody reads meanwhile
    ASSERT_TRUE(state_writer.publish(status));
    ASSERT_TRUE(behavior_writer.publish(priority));
  }
  ASSERT_EQ(behavior_writer.native().wait_for_acknowledgments(eprosima::fastrtps::Duration_t(5, 0)),
            eprosima::fastrtps::types::ReturnCode_t::RETCODE_OK);
  std::this_thread::sleep_for(100ms);

  std::vector<msg::ControlStatus> states;
  state_reader.takeAll(states);
  ASSERT_EQ(states.size(), 1u);
  EXPECT_EQ(states[0].header().seq(), static_cast<std::uint64_t>(kN)) << "the newest one is kept";

  std::vector<msg::MotionPriority> priorities;
  behavior_reader.takeAll(priorities);
  ASSERT_EQ(priorities.size(), 1u);
  EXPECT_EQ(priorities[0].header().seq(), static_cast<std::uint64_t>(kN));

  // Control: the same stream into a 256-deep reader keeps every sample, in order.
  std::vector<msg::ControlStatus> recorded;
  record_reader.takeAll(recorded);
  ASSERT_EQ(recorded.size(), static_cast<std::size_t>(kN));
  for (int i = 0; i < kN; ++i) EXPECT_EQ(recorded[i].header().seq(), static_cast<std::uint64_t>(i + 1));
}

TEST(Qos, ObjectTargetsExpireAfterTheirLifespan) {
  Participant bus(testConfig("qos_lifespan", 45));
  auto& writer = bus.makeWriter<msg::ObjectTargets>();
  auto& reader = bus.makeReader<msg::ObjectTargets>();
  ASSERT_TRUE(writer.waitForReaders(1, 5s));

  // Fresh: read within the lifespan, it is there.
  msg::ObjectTargets fresh = objectTargets(0);
  ASSERT_TRUE(writer.publish(fresh));
  ASSERT_TRUE(reader.waitForData(2s));
  msg::ObjectTargets got;
  ASSERT_TRUE(reader.takeNext(got));
  EXPECT_EQ(got.header().seq(), 1u);

  // Stale: left unread for 500 ms > 300 ms lifespan, it is gone.
  msg::ObjectTargets stale = objectTargets(1);
  ASSERT_TRUE(writer.publish(stale));
  std::this_thread::sleep_for(500ms);
  EXPECT_FALSE(reader.takeNext(got)) << "sample seq " << got.header().seq() << " outlived its lifespan";
}

TEST(Qos, SilentHeartbeatWriterIsDeclaredNotAlive) {
  Participant monitor(testConfig("qos_monitor", 45));
  auto& reader = monitor.makeReader<msg::Heartbeat>();
  Participant module(testConfig("qos_module", 45));
  auto& writer = module.makeWriter<msg::Heartbeat>();
  ASSERT_TRUE(writer.waitForReaders(1, 5s));
  msg::Heartbeat hb = heartbeat(0);
  auto hang = std::chrono::steady_clock::now();
  for (int i = 0; i < 3; ++i) {
    ASSERT_TRUE(writer.publish(hb));
    hang = std::chrono::steady_clock::now();  // the last assertion of liveliness: the lease runs from here
    std::this_thread::sleep_for(100ms);
  }
  ASSERT_TRUE(eventually([&] { return reader.stats().alive_writers == 1; }, 2000ms));
  EXPECT_EQ(reader.stats().liveliness_lost, 0u);
  // The module hangs (its writer still exists but publishes nothing): lease 1.5 s from its last sample.
  ASSERT_TRUE(eventually([&] { return reader.stats().liveliness_lost >= 1; }, 4000ms));
  const auto noticed = std::chrono::steady_clock::now() - hang;
  EXPECT_EQ(reader.stats().alive_writers, 0);
  EXPECT_GE(noticed, 1000ms) << "not before (most of) the 1.5 s lease";
  // The writer's own lease event runs on its participant's timer thread, independent of the reader's:
  // on a loaded machine it was seen to fire after the reader had noticed (a fresh CI clone).
  EXPECT_TRUE(eventually([&] { return writer.stats().liveliness_lost >= 1; }, 2000ms))
      << "the writer was told it lost its liveliness: " << writer.stats().liveliness_lost;
}

}  // namespace
}  // namespace reflex::bus::test
