#include "reflex/bus/log_limit.hpp"

namespace reflex::bus {

bool LogLimiter::admit(Clock::time_point now, std::uint64_t& suppressed) noexcept {
  // Fixed one-second windows: the window restarts at the first call that falls outside it, so a
  // quiet call site prints its next line at once.
  if (!started_ || now - window_start_ >= std::chrono::seconds(1) || now < window_start_) {
    started_ = true;
    window_start_ = now;
    in_window_ = 0;
  }
  if (in_window_ >= limit_) {
    ++pending_;
    ++suppressed_total_;
    return false;
  }
  ++in_window_;
  ++admitted_total_;
  suppressed = pending_;
  pending_ = 0;
  return true;
}

bool LogLimiter::print(std::FILE* out, const char* line) noexcept {
  std::uint64_t suppressed = 0;
  if (!admit(Clock::now(), suppressed)) return false;
  if (suppressed > 0) {
    std::fprintf(out, "%s [%llu similar lines suppressed]\n", line, static_cast<unsigned long long>(suppressed));
  } else {
    std::fprintf(out, "%s\n", line);
  }
  return true;
}

}  // namespace reflex::bus
