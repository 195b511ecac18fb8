// bus::LogLimiter against hand-counted answers on a fake clock: at most N lines
// per one-second window, the refused ones counted and reported with the next admitted line, a quiet
// call site printing at once again; print() writes the suppressed count into the line.
#include <reflex/bus/log_limit.hpp>

#include <gtest/gtest.h>

#include <cstdio>
#include <string>

namespace reflex::bus {
namespace {

using namespace std::chrono_literals;

TEST(LogLimiter, AdmitsAtMostNPerSecondAndCountsTheRest) {
  LogLimiter lim(3);
  const auto t0 = LogLimiter::Clock::time_point{} + 100s;
  std::uint64_t suppressed = 99;
  int admitted = 0;
  // 1000 calls within 0.5 s: 3 admitted, 997 refused.
  for (int k = 0; k < 1000; ++k) admitted += lim.admit(t0 + k * 500us, suppressed) ? 1 : 0;
  EXPECT_EQ(admitted, 3);
  EXPECT_EQ(suppressed, 0u) << "nothing was suppressed before the third admitted line";
  EXPECT_EQ(lim.suppressedTotal(), 997u);
  // Next window: the first line reports the 997.
  ASSERT_TRUE(lim.admit(t0 + 1s, suppressed));
  EXPECT_EQ(suppressed, 997u);
  ASSERT_TRUE(lim.admit(t0 + 1s + 1ms, suppressed));
  EXPECT_EQ(suppressed, 0u);
  EXPECT_EQ(lim.admittedTotal(), 5u);
  // A flood of 10 s at 10 kHz: at most 3 per second (31 with the window edges), never more.
  LogLimiter flood(3);
  int lines = 0;
  for (int k = 0; k < 100000; ++k) lines += flood.admit(t0 + k * 100us, suppressed) ? 1 : 0;
  EXPECT_LE(lines, 31);
  EXPECT_GE(lines, 30);
  EXPECT_EQ(flood.suppressedTotal() + flood.admittedTotal(), 100000u);
}

TEST(LogLimiter, ANonPositiveLimitStillPrintsOneLinePerSecond) {
  LogLimiter lim(0);
  const auto t0 = LogLimiter::Clock::time_point{} + 5s;
  std::uint64_t s = 0;
  EXPECT_TRUE(lim.admit(t0, s));
  EXPECT_FALSE(lim.admit(t0 + 10ms, s));
  EXPECT_TRUE(lim.admit(t0 + 1s, s));
  EXPECT_EQ(s, 1u);
}

TEST(LogLimiter, PrintWritesTheLineAndTheSuppressedCount) {
  std::FILE* f = std::tmpfile();
  ASSERT_NE(f, nullptr);
  LogLimiter lim(2);
  int printed = 0;
  for (int k = 0; k < 50; ++k) printed += lim.print(f, "bad sample " + std::to_string(k)) ? 1 : 0;
  EXPECT_EQ(printed, 2);  // 50 calls well within one second
  std::rewind(f);
  char buf[4096] = {};
  const std::size_t n = std::fread(buf, 1, sizeof(buf) - 1, f);
  std::fclose(f);
  EXPECT_EQ(std::string(buf, n), "bad sample 0\nbad sample 1\n");
}

}  // namespace
}  // namespace reflex::bus
