#include "reflex/bus/signals.hpp"

#include <fcntl.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <string>
#include <utility>

#include "reflex/bus/error.hpp"
#include "reflex/bus/participant.hpp"

namespace reflex::bus {

namespace {

// Process-wide state the handler may touch: a write end of a pipe (written with write(2), which is
// async-signal-safe) and whether a StopOnSignal exists.
int g_pipe_write = -1;
std::atomic<bool> g_installed{false};

extern "C" void onStopSignal(int signal_number) {
  const int saved_errno = errno;
  const unsigned char byte = static_cast<unsigned char>(signal_number);
  if (g_pipe_write >= 0) {
    [[maybe_unused]] const ssize_t n = ::write(g_pipe_write, &byte, 1);
  }
  errno = saved_errno;
}

}  // namespace

std::vector<int> stopSignals() {
  std::vector<int> s = {SIGINT,    SIGTERM, SIGHUP,  SIGQUIT, SIGUSR1,   SIGUSR2, SIGALRM,
                        SIGVTALRM, SIGPROF, SIGPOLL, SIGPWR,  SIGSTKFLT, SIGXCPU};
  for (int r = SIGRTMIN; r <= SIGRTMAX; ++r) s.push_back(r);
  return s;
}

StopOnSignal::StopOnSignal(Participant& participant, std::vector<int> signals) : signals_(std::move(signals)) {
  if (g_installed.exchange(true)) {
    throw BusError("a StopOnSignal already exists in this process; only one may be installed");
  }
  int fds[2];
  if (::pipe2(fds, O_CLOEXEC) != 0) {
    g_installed.store(false);
    throw BusError(std::string("StopOnSignal: pipe2 failed: ") + std::strerror(errno));
  }
  pipe_read_ = fds[0];
  ::fcntl(fds[1], F_SETFL, O_NONBLOCK);  // the handler must never block
  g_pipe_write = fds[1];

  for (int s : signals_) {
    struct sigaction action {};
    action.sa_handler = onStopSignal;
    sigemptyset(&action.sa_mask);
    action.sa_flags = SA_RESTART;
    struct sigaction old {};
    if (::sigaction(s, &action, &old) != 0) {
      const std::string reason = std::strerror(errno);
      for (std::size_t i = 0; i < previous_.size(); ++i) ::sigaction(signals_[i], &previous_[i], nullptr);
      ::close(g_pipe_write);
      ::close(pipe_read_);
      g_pipe_write = -1;
      g_installed.store(false);
      throw BusError("StopOnSignal: cannot install a handler for signal " + std::to_string(s) + ": " + reason);
    }
    previous_.push_back(old);
  }
  // A write to a pipe without a reader or past the file size limit fails with EPIPE / EFBIG where it
  // happens instead of killing the process (the old dispositions come back with the destructor).
  struct sigaction ignore {};
  ignore.sa_handler = SIG_IGN;
  sigemptyset(&ignore.sa_mask);
  ::sigaction(SIGPIPE, &ignore, &previous_pipe_);
  ::sigaction(SIGXFSZ, &ignore, &previous_xfsz_);
  watcher_ = std::thread([this, &participant] { watch(participant); });
}

StopOnSignal::~StopOnSignal() {
  for (std::size_t i = 0; i < previous_.size(); ++i) ::sigaction(signals_[i], &previous_[i], nullptr);
  ::sigaction(SIGPIPE, &previous_pipe_, nullptr);
  ::sigaction(SIGXFSZ, &previous_xfsz_, nullptr);
  const unsigned char quit = 0;  // byte 0 is no signal number: it tells the watcher to leave
  [[maybe_unused]] const ssize_t n = ::write(g_pipe_write, &quit, 1);
  if (watcher_.joinable()) watcher_.join();
  ::close(g_pipe_write);
  g_pipe_write = -1;
  ::close(pipe_read_);
  g_installed.store(false);
}

void StopOnSignal::watch(Participant& participant) {
  for (;;) {
    unsigned char byte = 0;
    const ssize_t n = ::read(pipe_read_, &byte, 1);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0 || byte == 0) return;
    last_signal_.store(byte);
    participant.stop();
  }
}

}  // namespace reflex::bus
