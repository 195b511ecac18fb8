// reflex_play on recordings whose receive times jump, as a real process on
// domain 83: two records 100 years apart used to make the player wait 100 years in silence. The
// gap is now played as --max-gap (default 10 s) with a message naming it, and SIGTERM ends the
// player within a second in the middle of such a wait. Expected times come from the contract
// (PlayerOptions::max_gap), not from a run.
#include "support/child_process.hpp"

#include "reflex/record/recorder.hpp"

#include <reflex/bus/bus.hpp>

#include "record_support.hpp"
#include "samples.hpp"

#include <gtest/gtest.h>

#include <chrono>
#include <csignal>
#include <fstream>
#include <thread>

namespace reflex::record {
namespace {

constexpr int kDomain = 83;
using namespace std::chrono_literals;
using SteadyClock = std::chrono::steady_clock;

std::string bin(const std::string& name) { return std::string(REFLEX_BIN_DIR) + "/" + name; }
std::string tempPath(const std::string& name) { return ::testing::TempDir() + "play_gap_test_" + name; }
std::string slurp(const std::string& path) {
  std::ifstream in(path);
  return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
}
double secondsSince(SteadyClock::time_point t0) {
  return std::chrono::duration<double>(SteadyClock::now() - t0).count();
}

// A ControlStatus sample as the recorder stores it (serialized by the generated type itself).
RecordEntry encodeStatus(std::uint64_t k, std::int64_t receive_ns) {
  return test::encodeEntry(bus::test::controlStatus(static_cast<int>(k)), receive_ns);
}

// Three records: t0, t0 + 100 years, and 0.1 s after that (receive times stay within an int64).
std::string hundredYearGap() {
  const std::string file = tempPath("gap.rfx");
  const std::int64_t t0 = 1'700'000'000'000'000'000LL;
  const std::int64_t century = 100LL * 365 * 24 * 3600 * 1'000'000'000LL;
  RecordWriter w(file);
  w.append(encodeStatus(0, t0));
  w.append(encodeStatus(1, t0 + century));
  w.append(encodeStatus(2, t0 + century + 100'000'000LL));
  w.close();
  return file;
}

TEST(PlayGap, AHundredYearGapIsPlayedAsTheMaximumGapAndReported) {
  const std::string file = hundredYearGap();
  const std::string log = tempPath("play.log");
  const auto t0 = SteadyClock::now();
  testing::ChildProcess player(
      {bin("reflex_play"), file, "--domain", std::to_string(kDomain), "--delay", "0", "--quiet"}, log);
  ASSERT_TRUE(player.started());
  // Default max gap 10 s: the pass takes 10 + 0.1 s of playing time (plus process start-up).
  EXPECT_EQ(player.wait(40s), 0) << slurp(log);
  const double took = secondsSince(t0);
  EXPECT_GT(took, 10.0) << "the gap is shortened to max_gap, not dropped";
  EXPECT_LT(took, 30.0);
  const std::string out = slurp(log);
  EXPECT_NE(out.find("1 gap(s) between records longer than --max-gap 10 s are played as 10 s"), std::string::npos)
      << out;
  EXPECT_NE(out.find("longest 3.1536e+09 s"), std::string::npos)
      << "names the gap (100 x 365 days in seconds): " << out;
  EXPECT_NE(out.find("published 3 samples"), std::string::npos) << out;
}

TEST(PlayGap, SigtermEndsThePlayerWithinASecondDuringAWait) {
  const std::string file = hundredYearGap();
  const std::string log = tempPath("term.log");
  testing::ChildProcess player(
      {bin("reflex_play"), file, "--domain", std::to_string(kDomain), "--delay", "0", "--quiet", "--max-gap", "3600"},
      log);
  ASSERT_TRUE(player.started());
  const auto t0 = SteadyClock::now();
  while (slurp(log).find("window") == std::string::npos && secondsSince(t0) < 20.0) std::this_thread::sleep_for(20ms);
  ASSERT_NE(slurp(log).find("window"), std::string::npos) << slurp(log);
  std::this_thread::sleep_for(1s);  // now waiting for the second record (an hour away)
  const auto t_signal = SteadyClock::now();
  player.signal(SIGTERM);
  // Within 3 s, not after the hour: the stop itself is one 50 ms slice; the rest is the participant's
  // teardown, which a loaded machine can stretch past a second.
  EXPECT_EQ(player.wait(3000ms), 0) << slurp(log);
  EXPECT_LT(secondsSince(t_signal), 3.0);
  EXPECT_NE(slurp(log).find("published 1 samples"), std::string::npos) << slurp(log);
}

TEST(PlayGap, ANonPositiveMaximumGapIsRefused) {
  const std::string file = hundredYearGap();
  const std::string log = tempPath("bad.log");
  for (const char* bad : {"0", "-1", "nan"}) {
    testing::ChildProcess player({bin("reflex_play"), file, "--domain", std::to_string(kDomain), "--max-gap", bad},
                                 log);
    EXPECT_NE(player.wait(20s), 0) << bad;
    EXPECT_NE(slurp(log).find("--max-gap"), std::string::npos) << bad << ": " << slurp(log);
  }
}

}  // namespace
}  // namespace reflex::record
