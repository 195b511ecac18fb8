// Which call into a module runs now, for the code that must name a module when it misbehaves without
// returning: a fatal-signal handler (a module that crashes) and a watchdog thread (a module that never
// returns). BehaviorHost marks every call it makes into a module (a ModuleCallMark around it); the
// reader takes a snapshot. Everything here is lock-free atomics on static storage, so
// moduleCallInProgress() is async-signal-safe and may run in any thread, even during static
// destruction.
//
// One mark at a time per process: the host runs its modules from one thread. A second host calling
// from another thread at the same moment would overwrite the mark (the reader then names the later
// call); reflex_behavior has one host.
#pragma once

#include <cstdint>

namespace reflex::modules {

/// A snapshot of the call in progress.
struct ModuleCallInProgress {
  /// "step() of module 'x' (type t, plugin /abs/libt.so)" or "... (type t, built in)"; nullptr when no
  /// module call runs. Points into the host's own strings: valid while the host lives.
  const char* what = nullptr;
  std::int64_t since_ns = 0;  ///< steady clock [ns] when the call began
  long thread = 0;            ///< kernel thread id (gettid) of the thread that made the call
};

/// The call in progress (async-signal-safe).
ModuleCallInProgress moduleCallInProgress() noexcept;

/// The steady clock in ns, the clock of ModuleCallInProgress::since_ns (async-signal-safe).
std::int64_t steadyNowNs() noexcept;

/// Marks `what` as the call in progress for its lifetime; the previous mark comes back after.
/// `what` must outlive the mark.
class ModuleCallMark {
 public:
  explicit ModuleCallMark(const char* what) noexcept;
  ~ModuleCallMark();
  ModuleCallMark(const ModuleCallMark&) = delete;
  ModuleCallMark& operator=(const ModuleCallMark&) = delete;

 private:
  ModuleCallInProgress previous_;
};

}  // namespace reflex::modules
