// reflex_play in secure mode: the real reflex_play process, started with the player's
// generated profiles file (--profiles <dir>/profiles/player.xml), republishes a recording's
// observation topics (object targets, joint state, control status) encrypted; a secure subscriber
// whose permissions grant them (the behavior identity) receives them with the recorded content, an
// unauthenticated participant receives nothing. A recording that also holds a command topic
// (hand targets) is played without it by default (observations only unless
// --commands), which is exactly the player's grant; asked to play it whole (--commands), the player's
// permissions do not grant it, so reflex_play stops at start with an error naming the topic. Domain 111.
#include "support/child_process.hpp"
#include "security_support.hpp"

#include <reflex/record/record_file.hpp>

#include <gtest/gtest.h>

#include <cstdio>
#include <map>
#include <vector>

namespace reflex::security_test {
namespace {

using namespace std::chrono_literals;
constexpr int kDomain =
    216;  // its own (111 is faults_controller_restart_test's: a plain controller there reached the outsider)
constexpr int kSamples = 20;  // per topic, 50 ms apart: a 1 s recording

// Serialized by the type's own Fast DDS type support, as the recorder stores it.
template <class T>
record::RecordEntry encode(const T& s, std::int64_t receive_ns) {
  typename bus::TopicTraits<T>::PubSubType type;
  void* data = const_cast<T*>(&s);
  eprosima::fastrtps::rtps::SerializedPayload_t p(type.getSerializedSizeProvider(data)());
  EXPECT_TRUE(type.serialize(data, &p));
  record::RecordEntry e;
  e.receive_ns = receive_ns;
  e.source_ns = receive_ns;
  e.topic = bus::TopicTraits<T>::kTopicName;
  e.type = type.getName();
  e.payload.assign(p.data, p.data + p.length);
  return e;
}

// The recorded values, a function of the sequence number (the independent answer).
double cupX(std::uint64_t seq) { return 0.30 + 0.01 * static_cast<double>(seq); }
double jointQ(std::uint64_t seq) { return -0.02 * static_cast<double>(seq); }
double cyclePeriod(std::uint64_t seq) { return 5000.0 + static_cast<double>(seq); }

std::string writeRecording(const std::string& path, bool with_hand_targets) {
  record::RecordWriter w(path);
  const std::int64_t t0 = bus::nowNs() - 10'000'000'000LL;
  for (std::uint64_t seq = 1; seq <= kSamples; ++seq) {
    const std::int64_t t = t0 + static_cast<std::int64_t>(seq) * 50'000'000LL;
    msg::ObjectTargets o;
    o.header().stamp_ns(t);
    o.header().seq(seq);
    o.header().source("vision");
    o.capture_stamp_ns(t);
    o.image_index(seq);
    o.frame_id("base_link");
    msg::ObjectTarget cup;
    cup.name("cup");
    cup.tag_id(3);
    cup.position_base().x(cupX(seq));
    cup.position_base().y(-0.1);
    cup.position_base().z(0.95);
    cup.confidence(1.0);
    o.objects().push_back(cup);
    w.append(encode(o, t));
    msg::JointState js;
    js.header().stamp_ns(t + 1000);
    js.header().seq(seq);
    js.header().source("controller");
    js.names({"l_elbow"});
    js.positions({jointQ(seq)});
    js.velocities({0.0});
    w.append(encode(js, t + 1000));
    msg::ControlStatus st;
    st.header().stamp_ns(t + 2000);
    st.header().seq(seq);
    st.header().source("controller");
    st.cycle_period_us(cyclePeriod(seq));
    w.append(encode(st, t + 2000));
    if (with_hand_targets && seq == 1) {
      msg::HandTargets h = handTargets(0.3, 0.2, 0.9);
      h.header().stamp_ns(t + 3000);
      h.header().seq(seq);
      h.header().source("behavior");
      w.append(encode(h, t + 3000));
    }
  }
  w.close();
  return path;
}

std::string play() { return std::string(REFLEX_BIN_DIR) + "/reflex_play"; }

TEST(SecurePlay, AWholeRecordingWithACommandTopicIsRefusedAtStartNamingTheTopic) {
  const std::string dir = makeSecurityMaterial("play_refused");
  const std::string rec = writeRecording(dir + "/with_commands.rfx", true);
  const std::string log = dir + "/play_refused.log";
  testing::ChildProcess player({play(), rec, "--commands", "--domain", std::to_string(kDomain), "--quiet", "--profiles",
                                dir + "/profiles/player.xml"},
                               log);
  ASSERT_TRUE(player.started());
  const int rc = player.wait(60s);
  const std::string out = readFile(log);
  EXPECT_EQ(rc, 2) << "refused at start (-1: did not stop by itself)\n" << out;
  EXPECT_NE(out.find("reflex/hand_targets"), std::string::npos) << out;
  EXPECT_EQ(out.find("published"), std::string::npos) << "nothing was played\n" << out;
}

TEST(SecurePlay, ObservationTopicsReachAPermittedSubscriberAndNoOutsider) {
  const std::string dir = makeSecurityMaterial("play");
  loadProfiles(dir);
  // The same recording with the command topic, played by default (observations only, no -x needed):
  // exactly the player's grant.
  const std::string rec = writeRecording(dir + "/run.rfx", true);

  auto behavior = secureParticipant(dir, "behavior", kDomain);
  auto& objects = behavior->makeReader<msg::ObjectTargets>("reflex/object_targets", bus::kProfileRecord);
  auto& joints = behavior->makeReader<msg::JointState>("reflex/joint_state", bus::kProfileRecord);
  auto& status = behavior->makeReader<msg::ControlStatus>("reflex/control_status", bus::kProfileRecord);
  auto outsider = plainParticipant("outsider", kDomain);
  auto& outsider_objects = outsider->makeReader<msg::ObjectTargets>("reflex/object_targets", bus::kProfileRecord);
  auto& outsider_joints = outsider->makeReader<msg::JointState>("reflex/joint_state", bus::kProfileRecord);

  const std::string log = dir + "/play.log";
  testing::ChildProcess player({play(), rec, "--loop", "--domain", std::to_string(kDomain), "--quiet", "--profiles",
                                dir + "/profiles/player.xml"},
                               log);
  ASSERT_TRUE(player.started());
  ASSERT_TRUE(objects.waitForWriters(1, 30s)) << "the secure player is authenticated\n" << readFile(log);
  ASSERT_TRUE(joints.waitForWriters(1, 10s)) << readFile(log);
  ASSERT_TRUE(status.waitForWriters(1, 10s)) << readFile(log);

  std::vector<msg::ObjectTargets> got_objects, outsider_got_objects;
  std::vector<msg::JointState> got_joints, outsider_got_joints;
  std::vector<msg::ControlStatus> got_status;
  repeatFor(3000ms, 50ms, [&] {
    objects.takeAll(got_objects);
    joints.takeAll(got_joints);
    status.takeAll(got_status);
    outsider_objects.takeAll(outsider_got_objects);
    outsider_joints.takeAll(outsider_got_joints);
  });
  EXPECT_EQ(player.terminate(), 0) << readFile(log);
  const std::string out = readFile(log);
  std::printf("secure play: %zu object targets, %zu joint states, %zu statuses in 3 s (recorded at 20 Hz each)\n",
              got_objects.size(), got_joints.size(), got_status.size());

  // 3 s of a 1 s recording at 20 Hz, looped: ~60 per topic; allow for losses on a loaded machine.
  EXPECT_GE(got_objects.size(), 20u) << out;
  EXPECT_GE(got_joints.size(), 20u) << out;
  EXPECT_GE(got_status.size(), 20u) << out;
  // Every sample is a recorded one, unchanged (header included: no --restamp).
  for (const auto& o : got_objects) {
    const std::uint64_t seq = o.header().seq();
    ASSERT_TRUE(seq >= 1 && seq <= kSamples) << seq;
    EXPECT_EQ(o.header().source(), "vision");
    EXPECT_EQ(o.image_index(), seq);
    EXPECT_EQ(o.frame_id(), "base_link");
    ASSERT_EQ(o.objects().size(), 1u);
    EXPECT_EQ(o.objects()[0].name(), "cup");
    EXPECT_DOUBLE_EQ(o.objects()[0].position_base().x(), cupX(seq));
  }
  for (const auto& js : got_joints) {
    const std::uint64_t seq = js.header().seq();
    ASSERT_TRUE(seq >= 1 && seq <= kSamples) << seq;
    ASSERT_EQ(js.positions().size(), 1u);
    EXPECT_DOUBLE_EQ(js.positions()[0], jointQ(seq));
    EXPECT_EQ(js.names()[0], "l_elbow");
  }
  for (const auto& st : got_status) {
    const std::uint64_t seq = st.header().seq();
    ASSERT_TRUE(seq >= 1 && seq <= kSamples) << seq;
    EXPECT_DOUBLE_EQ(st.cycle_period_us(), cyclePeriod(seq));
  }
  // Every recorded object-target sample came through at least once over the loops.
  std::map<std::uint64_t, int> seen;
  for (const auto& o : got_objects) ++seen[o.header().seq()];
  EXPECT_GE(seen.size(), static_cast<std::size_t>(kSamples * 3 / 4)) << "most recorded samples arrived";

  // The outsider (no credentials) never matched the secure writers and received nothing.
  EXPECT_TRUE(outsider_got_objects.empty());
  EXPECT_TRUE(outsider_got_joints.empty());
  EXPECT_FALSE(outsider_objects.waitForWriters(1, 10ms));
  EXPECT_NE(out.find("reflex_play: published"), std::string::npos) << out;
  EXPECT_NE(out.find("(0 failed)"), std::string::npos) << out;
}

}  // namespace
}  // namespace reflex::security_test
