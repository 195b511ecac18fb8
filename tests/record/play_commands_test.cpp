// reflex_play publishes observations only unless --commands is given, as a real
// process on domain 212. A recording with hand targets, a walk command and the control status,
// written here with the generated types: played by default, a subscriber on the domain receives the
// status and no hand target and no walk command (no writer for them is ever matched); with
// --commands it receives the hand targets too, with the recorded values. `-x reflex/hand_targets` is
// accepted and changes nothing (a note says so); `-t reflex/hand_targets` without --commands is an
// error naming the option. The independent answer is the topic list of the contract (bringup/security/README.md:
// "observations, never commands") and the recorded sample values.
#include "support/child_process.hpp"

#include "reflex/record/recorder.hpp"

#include <reflex/bus/bus.hpp>

#include "record_support.hpp"
#include "samples.hpp"
#include "../bus/bus_test_util.hpp"

#include <gtest/gtest.h>

#include <fstream>
#include <thread>

namespace reflex::record {
namespace {

constexpr int kDomain = 212;
using namespace std::chrono_literals;

std::string bin(const std::string& name) { return std::string(REFLEX_BIN_DIR) + "/" + name; }
std::string tempPath(const std::string& name) { return ::testing::TempDir() + "play_commands_test_" + name; }
std::string slurp(const std::string& path) {
  std::ifstream in(path);
  return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
}

/// 2 s: a status, a hand-target and a walk-command sample every 50 ms.
std::string recording() {
  const std::string file = tempPath("with_commands.rfx");
  const std::int64_t t0 = 1'700'000'000'000'000'000LL;
  RecordWriter w(file);
  for (int k = 0; k < 40; ++k) {
    const std::int64_t t = t0 + 50'000'000LL * k;
    w.append(test::encodeEntry(bus::test::controlStatus(k), t));
    w.append(test::encodeEntry(bus::test::handTargets(k), t + 1000));
    w.append(test::encodeEntry(bus::test::walkCommand(k), t + 2000));
  }
  w.close();
  return file;
}

struct Watch {
  std::unique_ptr<bus::Participant> bus;
  bus::Reader<msg::ControlStatus>* status = nullptr;
  bus::Reader<msg::HandTargets>* hands = nullptr;
  bus::Reader<msg::WalkCommand>* walk = nullptr;
  std::vector<msg::ControlStatus> got_status;
  std::vector<msg::HandTargets> got_hands;
  std::vector<msg::WalkCommand> got_walk;
  Watch() {
    bus = std::make_unique<bus::Participant>(bus::test::testConfig("play_watch", kDomain));
    status = &bus->makeReader<msg::ControlStatus>("reflex/control_status", bus::kProfileRecord);
    hands = &bus->makeReader<msg::HandTargets>("reflex/hand_targets", bus::kProfileRecord);
    walk = &bus->makeReader<msg::WalkCommand>("reflex/walk_command", bus::kProfileRecord);
  }
  void drain() {
    status->takeAll(got_status);
    hands->takeAll(got_hands);
    walk->takeAll(got_walk);
  }
  /// Drains until the player process exits (or 30 s).
  int follow(testing::ChildProcess& player, bool& hands_matched) {
    const auto end = std::chrono::steady_clock::now() + 30s;
    int rc = -1;
    while (std::chrono::steady_clock::now() < end) {
      drain();
      hands_matched |= hands->waitForWriters(1, 0ms);
      rc = player.wait(50ms);
      if (rc != -1) break;
    }
    std::this_thread::sleep_for(300ms);
    drain();
    return rc;
  }
};

TEST(PlayCommands, ADefaultReplayPublishesTheObservationsAndNoHandTargetOrWalkCommand) {
  const std::string file = recording();
  Watch watch;
  const std::string log = tempPath("default.log");
  // -x of a command topic: accepted, a no-op with a note.
  testing::ChildProcess player({bin("reflex_play"), file, "--domain", std::to_string(kDomain), "--delay", "2",
                                "--quiet", "-x", "reflex/hand_targets"},
                               log);
  ASSERT_TRUE(player.started());
  bool hands_matched = false;
  const int rc = watch.follow(player, hands_matched);
  const std::string out = slurp(log);
  EXPECT_EQ(rc, 0) << out;
  EXPECT_GT(watch.got_status.size(), 20u) << "the observations are played\n" << out;
  EXPECT_TRUE(watch.got_hands.empty()) << "a default replay publishes no hand target";
  EXPECT_TRUE(watch.got_walk.empty()) << "nor a walk command";
  EXPECT_FALSE(hands_matched) << "no hand-target writer exists at all";
  EXPECT_NE(out.find("command topics not played (observations only; --commands plays them): reflex/hand_targets, "
                     "reflex/walk_command"),
            std::string::npos)
      << out;
  EXPECT_NE(out.find("-x reflex/hand_targets changes nothing"), std::string::npos) << out;
  EXPECT_NE(out.find("published 40 samples"), std::string::npos) << out;
}

TEST(PlayCommands, CommandsArePlayedOnlyWithTheExplicitFlag) {
  const std::string file = recording();
  {
    Watch watch;
    const std::string log = tempPath("commands.log");
    testing::ChildProcess player(
        {bin("reflex_play"), file, "--domain", std::to_string(kDomain), "--delay", "2", "--quiet", "--commands"}, log);
    ASSERT_TRUE(player.started());
    bool hands_matched = false;
    EXPECT_EQ(watch.follow(player, hands_matched), 0) << slurp(log);
    EXPECT_NE(slurp(log).find("published 120 samples"), std::string::npos) << slurp(log);
    ASSERT_GT(watch.got_hands.size(), 20u) << "with --commands the hand targets are played";
    // The recorded values (samples.hpp handTargets(k)), sample by sample.
    for (const msg::HandTargets& h : watch.got_hands) {
      const int k = static_cast<int>(h.header().seq()) - 1000;
      ASSERT_GE(k, 0);
      ASSERT_LT(k, 40);
      const msg::HandTargets expected = bus::test::handTargets(k);
      EXPECT_EQ(h.left().position_base().x(), expected.left().position_base().x());
      EXPECT_EQ(h.right().object_name(), expected.right().object_name());
    }
    EXPECT_GT(watch.got_walk.size(), 20u);
  }
  // -t of a command topic without --commands: refused at start, naming the topic and the option.
  const std::string log = tempPath("refused.log");
  testing::ChildProcess player(
      {bin("reflex_play"), file, "--domain", std::to_string(kDomain), "--quiet", "-t", "reflex/hand_targets"}, log);
  ASSERT_TRUE(player.started());
  const int rc = player.wait(30s);
  const std::string out = slurp(log);
  EXPECT_EQ(rc, 2) << out;  // refused at start
  EXPECT_NE(out.find("topic 'reflex/hand_targets' is a command topic"), std::string::npos) << out;
  EXPECT_NE(out.find("--commands"), std::string::npos) << out;
  EXPECT_EQ(out.find("published"), std::string::npos) << out;
}

}  // namespace
}  // namespace reflex::record
