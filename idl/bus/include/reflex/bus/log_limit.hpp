// reflex::bus::LogLimiter — a rate limit for log lines printed once per received sample.
//
// A line printed for every bad sample lets any permitted writer flood stderr (an authenticated
// flooder made the controller print 4.8 MB in 8 s). Every per-sample log line of
// the Reflex processes (controller, behavior, vision) goes through one LogLimiter per call site:
// at most `lines_per_second` lines are printed in each one-second window; the others are counted,
// and the next line printed says how many were suppressed since the previous one
// ("... [1234 similar lines suppressed]"). What the lines report is still counted by the caller
// (its rejection counters); the limiter only bounds the text.
//
//   bus::LogLimiter schema_log_;                                // a member, one per call site
//   schema_log_.print(stderr, "controller: segment 'x' rejected: ...");
//
// Bound: a call site writes at most lines_per_second lines per second, whatever the input rate.
// Threading: one LogLimiter is used from one thread (the thread that handles the samples).
// Allocation: print() writes the caller's line with one fprintf; it never throws.
#pragma once

#include <chrono>
#include <cstdint>
#include <cstdio>
#include <string>

namespace reflex::bus {

class LogLimiter {
 public:
  using Clock = std::chrono::steady_clock;
  static constexpr int kDefaultLinesPerSecond = 10;

  /// lines_per_second < 1 is taken as 1 (a limiter that prints nothing would hide a flood).
  explicit LogLimiter(int lines_per_second = kDefaultLinesPerSecond) noexcept
      : limit_(lines_per_second < 1 ? 1 : lines_per_second) {}

  /// Decides whether a line may be printed at `now`. On true, `suppressed` is the number of lines
  /// refused since the last admitted one (to be reported with this line), else it is left as is.
  bool admit(Clock::time_point now, std::uint64_t& suppressed) noexcept;

  /// Prints `line` (and the suppressed count, if any) with a newline to `out` when admit(now())
  /// allows it. Returns true if it printed. Never throws.
  bool print(std::FILE* out, const std::string& line) noexcept { return print(out, line.c_str()); }
  bool print(std::FILE* out, const char* line) noexcept;

  /// Lines refused since construction (for exit reports).
  std::uint64_t suppressedTotal() const noexcept { return suppressed_total_; }
  /// Lines printed (admitted) since construction.
  std::uint64_t admittedTotal() const noexcept { return admitted_total_; }

 private:
  int limit_;
  Clock::time_point window_start_{};
  bool started_ = false;
  int in_window_ = 0;
  std::uint64_t pending_ = 0;  // refused since the last admitted line
  std::uint64_t suppressed_total_ = 0;
  std::uint64_t admitted_total_ = 0;
};

}  // namespace reflex::bus
