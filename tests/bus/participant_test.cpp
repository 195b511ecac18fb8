// reflex::bus::Participant's run loop (domain 41): onData callbacks and every() timers are
// dispatched from run(); runFor() times out; stop() from another thread ends run(); configuration
// resolution (domain id and profiles file from the environment).
#include <gtest/gtest.h>

#include <reflex/bus/participant.hpp>

#include <chrono>
#include <cstdlib>
#include <thread>

#include "bus_test_util.hpp"

namespace reflex::bus::test {
namespace {

using namespace std::chrono_literals;
constexpr int kDomain = 41;

TEST(Participant, RunDispatchesTimersAndReaderCallbacks) {
  Participant bus(testConfig("run_loop", kDomain));
  auto& writer = bus.makeWriter<msg::WalkCommand>();
  auto& reader = bus.makeReader<msg::WalkCommand>();
  ASSERT_TRUE(writer.waitForReaders(1, 5s));

  msg::WalkCommand cmd = walkCommand(0);
  int ticks = 0;
  bus.every(5ms, [&] {
    ++ticks;
    writer.publish(cmd);
  });
  std::vector<std::uint64_t> seqs;
  reader.onData([&](const msg::WalkCommand& w) {
    seqs.push_back(w.header().seq());
    if (seqs.size() == 10) bus.stop();
  });
  const auto start = std::chrono::steady_clock::now();
  EXPECT_FALSE(bus.runFor(10s)) << "stop() from the callback ends the loop before the time is up";
  const auto took = std::chrono::steady_clock::now() - start;
  ASSERT_EQ(seqs.size(), 10u);
  for (std::size_t i = 1; i < seqs.size(); ++i) EXPECT_GT(seqs[i], seqs[i - 1]);
  EXPECT_GE(ticks, 10);
  EXPECT_GE(took, 45ms) << "ten 5 ms timer periods";
  EXPECT_LT(took, 5s);
  EXPECT_TRUE(bus.stopRequested());
  EXPECT_FALSE(bus.runFor(1s)) << "stop is sticky";
}

TEST(Participant, RunForReturnsTrueWhenTheTimeIsUp) {
  Participant bus(testConfig("run_for", kDomain));
  auto& reader = bus.makeReader<msg::JointState>();
  int calls = 0;
  reader.onData([&](const msg::JointState&) { ++calls; });
  const auto start = std::chrono::steady_clock::now();
  EXPECT_TRUE(bus.runFor(100ms));
  const auto took = std::chrono::steady_clock::now() - start;
  EXPECT_GE(took, 100ms);
  EXPECT_LT(took, 2s);
  EXPECT_EQ(calls, 0) << "nobody publishes on this topic";
}

TEST(Participant, StopFromAnotherThreadEndsRun) {
  Participant bus(testConfig("stop_thread", kDomain));
  std::thread stopper([&] {
    std::this_thread::sleep_for(100ms);
    bus.stop();
  });
  const auto start = std::chrono::steady_clock::now();
  bus.run();  // no reader, no timer: wakes only through the guard condition
  const auto took = std::chrono::steady_clock::now() - start;
  stopper.join();
  EXPECT_GE(took, 90ms);
  EXPECT_LT(took, 3s);
}

TEST(Participant, ReportsItsConfiguration) {
  Participant bus(testConfig("configured", kDomain));
  EXPECT_EQ(bus.moduleName(), "configured");
  EXPECT_EQ(bus.domainId(), kDomain);
  EXPECT_EQ(bus.profilesFile(), kProfilesFile);
  EXPECT_EQ(bus.native().get_domain_id(), kDomain);
  EXPECT_EQ(bus.native().get_qos().name().to_string(), "configured");
}

TEST(Config, DomainIdFromConfigurationEnvironmentOrZero) {
  ::unsetenv("REFLEX_DOMAIN_ID");
  EXPECT_EQ(resolveDomainId(std::nullopt), 0);
  EXPECT_EQ(resolveDomainId(17), 17);
  ::setenv("REFLEX_DOMAIN_ID", "41", 1);
  EXPECT_EQ(resolveDomainId(std::nullopt), 41);
  EXPECT_EQ(resolveDomainId(3), 3) << "the configuration wins over the environment";
  {
    BusConfig c = testConfig("from_env", 0);
    c.domain_id.reset();
    Participant bus(c);
    EXPECT_EQ(bus.domainId(), 41);
  }
  ::unsetenv("REFLEX_DOMAIN_ID");
  EXPECT_EQ(parseDomainId("232", "test"), 232);
  EXPECT_EQ(parseDomainId("0", "test"), 0);
}

TEST(Config, ProfilesFileFromConfigurationEnvironmentOrDefault) {
  ::unsetenv("FASTRTPS_DEFAULT_PROFILES_FILE");
  EXPECT_EQ(resolveProfilesFile(""), std::string(kDefaultProfilesFile));
  EXPECT_EQ(std::string(kDefaultProfilesFile), kProfilesFile) << "the default is this checkout's file";
  EXPECT_EQ(resolveProfilesFile("/a/b.xml"), "/a/b.xml");
  ::setenv("FASTRTPS_DEFAULT_PROFILES_FILE", "/env/profiles.xml", 1);
  EXPECT_EQ(resolveProfilesFile(""), "/env/profiles.xml");
  EXPECT_EQ(resolveProfilesFile("/a/b.xml"), "/a/b.xml");
  ::unsetenv("FASTRTPS_DEFAULT_PROFILES_FILE");
}

TEST(Stamp, NowIsTheSystemClockInNanoseconds) {
  const auto before = std::chrono::duration_cast<std::chrono::nanoseconds>(
                          std::chrono::system_clock::now().time_since_epoch()).count();
  const std::int64_t now = nowNs();
  const auto after = std::chrono::duration_cast<std::chrono::nanoseconds>(
                         std::chrono::system_clock::now().time_since_epoch()).count();
  EXPECT_LE(before, now);
  EXPECT_LE(now, after);
  EXPECT_GT(now, 1'600'000'000'000'000'000LL) << "after September 2020: epoch-based, not steady";
}

}  // namespace
}  // namespace reflex::bus::test
