// The replay path: a recording whose Heartbeat and BodySchemaChange samples carry
// key strings longer than the DDS bound (256 bytes, 4 KB) — crafted here, as another vendor's
// writer or an edited file could produce them — is replayed by the real reflex_play (domain 189).
// Before the bound, the first such sample aborted the player (SIGABRT inside the key computation).
// Now each is refused and counted: "published 4 samples (3 failed)", exit code 2 (not a signal),
// and the samples with keys of 255 bytes and less reach a subscriber.
#include "support/child_process.hpp"
#include "../bus/bus_test_util.hpp"

#include <reflex/bus/bus.hpp>
#include <reflex/record/record_file.hpp>

#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <fstream>
#include <iterator>
#include <string>
#include <thread>

namespace reflex::bad_input {
namespace {

using namespace std::chrono_literals;

template <class PubSub, class T>
std::vector<std::uint8_t> serialized(T& sample) {
  PubSub type;  // the generated type support: no key check on this side
  eprosima::fastrtps::rtps::SerializedPayload_t payload(type.getSerializedSizeProvider(&sample)());
  EXPECT_TRUE(type.serialize(&sample, &payload));
  return std::vector<std::uint8_t>(payload.data, payload.data + payload.length);
}

TEST(LongKeyReplay, ARecordingWithLongKeysIsReplayedWithThoseSamplesRefusedAndCounted) {
  const std::string file = ::testing::TempDir() + "long_keys.rfx";
  const std::int64_t t0 = bus::nowNs();
  {
    record::RecordWriter writer(file);
    int k = 0;
    for (std::size_t n : {std::size_t{5}, std::size_t{256}, std::size_t{255}, std::size_t{4096}}) {
      msg::Heartbeat hb;
      hb.module_name(std::string(n, 'h'));
      record::RecordEntry e;
      e.receive_ns = t0 + 10000000LL * k++;
      e.topic = "reflex/heartbeat";
      e.type = "reflex::msg::Heartbeat";
      e.payload = serialized<msg::HeartbeatPubSubType>(hb);
      writer.append(e);
    }
    msg::BodySchemaChange c;
    c.segment_name(std::string(300, 's'));
    record::RecordEntry e;
    e.receive_ns = t0 + 10000000LL * k++;
    e.topic = "reflex/body_schema";
    e.type = "reflex::msg::BodySchemaChange";
    e.payload = serialized<msg::BodySchemaChangePubSubType>(c);
    writer.append(e);
    writer.close();
  }
  bus::Participant watch(bus::test::testConfig("long_key_watch", 189));
  auto& heartbeats = watch.makeReader<msg::Heartbeat>("reflex/heartbeat", bus::kProfileRecord);

  const std::string log = ::testing::TempDir() + "long_key_play.log";
  // --commands: the body schema is a command topic, played only when asked.
  testing::ChildProcess player(
      {std::string(REFLEX_BIN_DIR) + "/reflex_play", file, "--commands", "--domain", "189", "--delay", "2"}, log);
  ASSERT_TRUE(player.started());
  const int rc = player.wait(30s);
  std::ifstream in(log);
  const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  EXPECT_EQ(rc, 2) << "refusals are failures, reported by the exit code (134 = SIGABRT)\n" << text;
  EXPECT_NE(text.find("published 2 samples (3 failed)"), std::string::npos) << text;
  std::this_thread::sleep_for(200ms);
  std::vector<msg::Heartbeat> got;
  heartbeats.takeAll(got);
  std::vector<std::size_t> sizes;
  for (const auto& hb : got) sizes.push_back(hb.module_name().size());
  std::sort(sizes.begin(), sizes.end());  // two instances (keys): taken in instance order
  EXPECT_EQ(sizes, (std::vector<std::size_t>{5, 255})) << "the 5- and 255-byte heartbeats arrive, nothing else";
}

}  // namespace
}  // namespace reflex::bad_input
