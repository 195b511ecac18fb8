// reflex_behavior's answer to a module it cannot unwind. The host catches whatever a module throws
// (host.hpp); this covers the two failures no catch reaches, and names the module in both:
//   - a crash (SIGSEGV, SIGBUS, SIGFPE, SIGILL, SIGABRT, SIGTRAP, SIGSYS): one line on stderr naming
//     the module call in progress (module_call.hpp), then the process dies of the same signal, so
//     its exit status still says what happened (139 for SIGSEGV). No recovery is tried: the module's
//     memory, and the host's, can no longer be trusted.
//   - a call that does not return: a watchdog thread names a module call running longer than
//     `overrun` while the process runs; after a stop request (SIGINT, SIGTERM, ... through
//     bus::StopOnSignal, or the end of --duration) it ends the process with `exit_code` once a module
//     call is still running `module_bound` later, or once `process_bound` has passed whatever runs
//     (the removals' acknowledgments take up to 2 s). The line names the call; nothing is cleaned up
//     (the stuck call may hold any lock), the controller sees the heartbeat end.
// Process-wide by nature (signal dispositions, _exit), hence part of the executable, not of a library.
#pragma once

#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <functional>
#include <mutex>
#include <thread>

namespace reflex::modules {

/// Installs the crash report for the rest of the process, with an alternate signal stack for the
/// calling thread (the one that runs the modules), so a module's runaway recursion is named too.
void installFatalSignalReport();

struct StopBounds {
  std::chrono::milliseconds overrun{1000};       ///< a call longer than this is named (once) while running
  std::chrono::milliseconds module_bound{2000};  ///< after the stop request: a module call still running ends it
  /// After the stop request: the process ends, whatever runs. Above the normal stop's worst case (up to
  /// 2 s for the removals' acknowledgments, then the DDS teardown) with room for a loaded machine.
  std::chrono::milliseconds process_bound{6000};
};

class StopWatchdog {
 public:
  StopWatchdog(StopBounds bounds, int exit_code);
  /// Joins the thread (the bound no longer applies after that).
  ~StopWatchdog();
  StopWatchdog(const StopWatchdog&) = delete;
  StopWatchdog& operator=(const StopWatchdog&) = delete;

  /// Polls `stop_requested` (from the watchdog thread) until unwatch(); its first true starts the stop
  /// clock. `stop_requested` must stay callable until unwatch() returns.
  void watch(std::function<bool()> stop_requested);
  void unwatch();
  /// Starts the stop clock now, unless it runs already.
  void arm();

 private:
  void loop();

  const StopBounds bounds_;
  const int exit_code_;
  std::mutex mutex_;
  std::condition_variable wake_;
  bool quit_ = false;
  std::function<bool()> stop_requested_;
  std::int64_t stop_ns_ = 0;        // steadyNowNs() of the stop request (0: not yet)
  std::int64_t reported_call_ = 0;  // since_ns of the call last named as overrunning
  std::thread thread_;
};

}  // namespace reflex::modules
