// Clean shutdown on SIGINT / SIGTERM for a Reflex DDS process.
//
//   reflex::bus::Participant bus(config);
//   reflex::bus::StopOnSignal stop_on_signal(bus);   // installs the handlers
//   bus.run();                                       // returns after Ctrl-C or `kill <pid>`
//
// The signal handler is async-signal-safe: it only writes the signal number to a self-pipe. A
// watcher thread reads the pipe and calls Participant::stop() (which takes locks, so it must not run
// inside the handler). The destructor restores the previous handlers and joins the thread.
// At most one StopOnSignal may exist at a time (the handler state is process-wide).
#pragma once

#include <atomic>
#include <csignal>
#include <initializer_list>
#include <thread>
#include <vector>

namespace reflex::bus {

class Participant;

class StopOnSignal {
 public:
  /// Installs handlers for `signals` that stop `participant`. Throws BusError if another
  /// StopOnSignal exists or the pipe / handlers cannot be set up.
  explicit StopOnSignal(Participant& participant, std::initializer_list<int> signals = {SIGINT, SIGTERM});
  ~StopOnSignal();
  StopOnSignal(const StopOnSignal&) = delete;
  StopOnSignal& operator=(const StopOnSignal&) = delete;

  /// The last signal received (0 if none yet).
  int lastSignal() const noexcept { return last_signal_.load(); }

 private:
  void watch(Participant& participant);

  std::vector<int> signals_;
  std::vector<struct sigaction> previous_;
  int pipe_read_ = -1;
  std::atomic<int> last_signal_{0};
  std::thread watcher_;
};

}  // namespace reflex::bus
