// Clean shutdown on any catchable terminating signal for a Reflex DDS process.
//
//   reflex::bus::Participant bus(config);
//   reflex::bus::StopOnSignal stop_on_signal(bus);   // installs the handlers
//   bus.run();                                       // returns after Ctrl-C, `kill <pid>`, a hang-up, ...
//
// The contract: a process that holds a StopOnSignal never dies of a signal it can handle. Every
// signal whose default action ends the process and that may be caught (stopSignals(): SIGINT,
// SIGTERM, SIGHUP, SIGQUIT, SIGUSR1, SIGUSR2, SIGALRM, SIGVTALRM, SIGPROF, SIGPOLL, SIGPWR,
// SIGSTKFLT, SIGXCPU and every real-time signal) stops the participant, so the process leaves its
// loop and finishes as after SIGTERM (summary, files closed). SIGPIPE and SIGXFSZ are IGNORED while
// it exists: a write to a pipe without a reader (e.g. stderr of a closed terminal) or beyond the file
// size limit then fails with EPIPE / EFBIG where it happens, and the writer reports it. Program-error
// signals (SIGSEGV, SIGBUS, SIGFPE, SIGILL, SIGABRT, SIGTRAP, SIGSYS) and SIGKILL / SIGSTOP are not
// caught. A process that uses a signal itself (reflex_controller: SIGUSR1 leaves a latched e-stop)
// passes stopSignals() without it and installs its own handler.
//
// The signal handler is async-signal-safe: it only writes the signal number to a self-pipe. A
// watcher thread reads the pipe and calls Participant::stop() (which takes locks, so it must not run
// inside the handler). The destructor restores the previous handlers and joins the thread.
// At most one StopOnSignal may exist at a time (the handler state is process-wide).
#pragma once

#include <atomic>
#include <csignal>
#include <thread>
#include <vector>

namespace reflex::bus {

class Participant;

/// The catchable signals whose default action ends the process (see the opening comment).
std::vector<int> stopSignals();

class StopOnSignal {
 public:
  /// Installs handlers for `signals` that stop `participant`, and ignores SIGPIPE and SIGXFSZ.
  /// Throws BusError if another StopOnSignal exists or the pipe / handlers cannot be set up.
  explicit StopOnSignal(Participant& participant, std::vector<int> signals = stopSignals());
  ~StopOnSignal();
  StopOnSignal(const StopOnSignal&) = delete;
  StopOnSignal& operator=(const StopOnSignal&) = delete;

  /// The last signal received (0 if none yet).
  int lastSignal() const noexcept { return last_signal_.load(); }

 private:
  void watch(Participant& participant);

  std::vector<int> signals_;
  std::vector<struct sigaction> previous_;
  struct sigaction previous_pipe_ {
  }, previous_xfsz_{};
  int pipe_read_ = -1;
  std::atomic<int> last_signal_{0};
  std::thread watcher_;
};

}  // namespace reflex::bus
