#include "reflex/modules/module_call.hpp"

#include <sys/syscall.h>
#include <time.h>
#include <unistd.h>

#include <atomic>

namespace reflex::modules {

namespace {

// A sequence lock: the writer bumps `g_seq` to odd, stores the fields, bumps it to even; a reader
// retries while the sequence is odd or changed under it. No lock, so a signal handler can read it.
std::atomic<std::uint64_t> g_seq{0};
std::atomic<const char*> g_what{nullptr};
std::atomic<std::int64_t> g_since_ns{0};
std::atomic<long> g_thread{0};

static_assert(std::atomic<const char*>::is_always_lock_free && std::atomic<std::int64_t>::is_always_lock_free &&
                  std::atomic<std::uint64_t>::is_always_lock_free && std::atomic<long>::is_always_lock_free,
              "the call mark is read from a signal handler: its atomics must be lock-free");

void store(const ModuleCallInProgress& c) noexcept {
  g_seq.fetch_add(1, std::memory_order_acq_rel);
  g_what.store(c.what, std::memory_order_relaxed);
  g_since_ns.store(c.since_ns, std::memory_order_relaxed);
  g_thread.store(c.thread, std::memory_order_relaxed);
  g_seq.fetch_add(1, std::memory_order_release);
}

}  // namespace

std::int64_t steadyNowNs() noexcept {
  timespec ts{};
  ::clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * 1000000000 + ts.tv_nsec;
}

ModuleCallInProgress moduleCallInProgress() noexcept {
  ModuleCallInProgress c;
  // A handler that interrupted the writer in its own thread would spin forever on an odd sequence:
  // a bounded number of tries, then the fields as they are (at worst from two neighbouring calls).
  for (int attempt = 0; attempt < 100; ++attempt) {
    const std::uint64_t before = g_seq.load(std::memory_order_acquire);
    c.what = g_what.load(std::memory_order_relaxed);
    c.since_ns = g_since_ns.load(std::memory_order_relaxed);
    c.thread = g_thread.load(std::memory_order_relaxed);
    std::atomic_thread_fence(std::memory_order_acquire);
    if (before % 2 == 0 && g_seq.load(std::memory_order_relaxed) == before) break;
  }
  return c;
}

ModuleCallMark::ModuleCallMark(const char* what) noexcept : previous_(moduleCallInProgress()) {
  store({what, steadyNowNs(), static_cast<long>(::syscall(SYS_gettid))});
}

ModuleCallMark::~ModuleCallMark() { store(previous_); }

}  // namespace reflex::modules
