#include "process_guard.hpp"

#include "reflex/modules/module_call.hpp"

#include <poll.h>
#include <sys/syscall.h>
#include <unistd.h>

#include <algorithm>
#include <csignal>
#include <cstdio>
#include <cstring>

namespace reflex::modules {

namespace {

// The line of a crash, built in a fixed buffer: nothing in a signal handler may allocate or lock.
struct Line {
  char text[1024];
  std::size_t size = 0;
  void add(const char* s) {
    while (*s != '\0' && size + 1 < sizeof text) text[size++] = *s++;
  }
  void add(long v) {
    char digits[24];
    int n = 0;
    unsigned long u = v < 0 ? 0UL - static_cast<unsigned long>(v) : static_cast<unsigned long>(v);
    do {
      digits[n++] = static_cast<char>('0' + u % 10);
      u /= 10;
    } while (u != 0 && n < 23);
    if (v < 0) add("-");
    while (n > 0 && size + 1 < sizeof text) text[size++] = digits[--n];
  }
};

const char* signalName(int s) {
  switch (s) {
    case SIGSEGV: return "SIGSEGV";
    case SIGBUS: return "SIGBUS";
    case SIGFPE: return "SIGFPE";
    case SIGILL: return "SIGILL";
    case SIGABRT: return "SIGABRT";
    case SIGTRAP: return "SIGTRAP";
    case SIGSYS: return "SIGSYS";
    default: return "?";
  }
}

// Writes all of `text` to stderr unless stderr stays unwritable for 100 ms (a full pipe nobody
// reads): a process that must end is never held up by its own last line.
void writeStderr(const char* text, std::size_t size) {
  while (size > 0) {
    pollfd p{STDERR_FILENO, POLLOUT, 0};
    if (::poll(&p, 1, 100) <= 0 || (p.revents & POLLOUT) == 0) return;
    const ssize_t n = ::write(STDERR_FILENO, text, size);
    if (n <= 0) return;
    text += n;
    size -= static_cast<std::size_t>(n);
  }
}

extern "C" void onFatalSignal(int signal_number) {
  // SA_RESETHAND has restored the default action and SA_NODEFER leaves the signal unblocked: the
  // raise() below ends the process with this signal, as if no handler had been there.
  const ModuleCallInProgress call = moduleCallInProgress();
  Line line;
  line.add("reflex_behavior: fatal signal ");
  line.add(static_cast<long>(signal_number));
  line.add(" (");
  line.add(signalName(signal_number));
  line.add(") ");
  if (call.what == nullptr) {
    line.add("outside any module call");
  } else if (call.thread != static_cast<long>(::syscall(SYS_gettid))) {
    line.add("in a thread that is not the modules' one, while ");
    line.add(call.what);
    line.add(" was running");
  } else {
    line.add("in ");
    line.add(call.what);
  }
  line.add("\n");
  writeStderr(line.text, line.size);
  ::raise(signal_number);
}

}  // namespace

void installFatalSignalReport() {
  // A stack overflow leaves no stack for the handler: it runs on this one (the modules' thread).
  static char alt_stack[64 * 1024];
  stack_t ss{};
  ss.ss_sp = alt_stack;
  ss.ss_size = sizeof alt_stack;
  ::sigaltstack(&ss, nullptr);
  for (int s : {SIGSEGV, SIGBUS, SIGFPE, SIGILL, SIGABRT, SIGTRAP, SIGSYS}) {
    struct sigaction action {};
    action.sa_handler = onFatalSignal;
    sigemptyset(&action.sa_mask);
    action.sa_flags = SA_RESETHAND | SA_NODEFER | SA_ONSTACK;
    ::sigaction(s, &action, nullptr);
  }
}

StopWatchdog::StopWatchdog(StopBounds bounds, int exit_code)
    : bounds_(bounds), exit_code_(exit_code), thread_([this] { loop(); }) {}

StopWatchdog::~StopWatchdog() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    quit_ = true;
  }
  wake_.notify_all();
  thread_.join();
}

void StopWatchdog::watch(std::function<bool()> stop_requested) {
  std::lock_guard<std::mutex> lock(mutex_);
  stop_requested_ = std::move(stop_requested);
}

void StopWatchdog::unwatch() {
  std::lock_guard<std::mutex> lock(mutex_);
  stop_requested_ = nullptr;
}

void StopWatchdog::arm() {
  std::lock_guard<std::mutex> lock(mutex_);
  if (stop_ns_ == 0) stop_ns_ = steadyNowNs();
}

void StopWatchdog::loop() {
  const auto ns = [](std::chrono::milliseconds d) { return static_cast<std::int64_t>(d.count()) * 1000000; };
  std::unique_lock<std::mutex> lock(mutex_);
  while (!wake_.wait_for(lock, std::chrono::milliseconds(20), [this] { return quit_; })) {
    if (stop_ns_ == 0 && stop_requested_ && stop_requested_()) stop_ns_ = steadyNowNs();
    const std::int64_t now = steadyNowNs();
    const ModuleCallInProgress call = moduleCallInProgress();
    const double call_s = call.what ? 1e-9 * static_cast<double>(now - call.since_ns) : 0.0;
    // Lines are formatted here and written with write(2): the stuck thread may hold stdio's lock.
    char text[8192];
    if (stop_ns_ == 0) {
      if (call.what && now - call.since_ns >= ns(bounds_.overrun) && call.since_ns != reported_call_) {
        reported_call_ = call.since_ns;
        const int n = std::snprintf(text, sizeof text,
                                    "reflex_behavior: %s has not returned for %.1f s (the loop, the heartbeat and "
                                    "the outputs wait for it)\n",
                                    call.what, call_s);
        writeStderr(text, static_cast<std::size_t>(std::clamp<int>(n, 0, sizeof text - 1)));
      }
      continue;
    }
    const std::int64_t since_stop = now - stop_ns_;
    const bool module_stuck = call.what && since_stop >= ns(bounds_.module_bound);
    if (!module_stuck && since_stop < ns(bounds_.process_bound)) continue;
    const double bound_s =
        1e-3 * static_cast<double>(module_stuck ? bounds_.module_bound.count() : bounds_.process_bound.count());
    const int n = call.what
                      ? std::snprintf(text, sizeof text,
                                      "reflex_behavior: not stopped %.1f s after the stop request: %s has not returned "
                                      "(running for %.1f s); exit %d without clean-up\n",
                                      bound_s, call.what, call_s, exit_code_)
                      : std::snprintf(text, sizeof text,
                                      "reflex_behavior: not stopped %.1f s after the stop request, no module call "
                                      "running (the bus or its teardown); exit %d without clean-up\n",
                                      bound_s, exit_code_);
    writeStderr(text, static_cast<std::size_t>(std::clamp<int>(n, 0, sizeof text - 1)));
    ::_exit(exit_code_);
  }
}

}  // namespace reflex::modules
