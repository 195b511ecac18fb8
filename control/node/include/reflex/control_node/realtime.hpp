// Real-time hardening of a control process: reflex_controller --realtime PRIORITY[,CPU].
//
// applyRealtime() makes the calling process a real-time one, in this order, each step checked:
//   1. CPU affinity (if a CPU is given): the process runs on that CPU only (sched_setaffinity);
//   2. SCHED_FIFO at PRIORITY (1..99, sched_setscheduler on the process);
//   3. memory locked, now and in the future (mlockall(MCL_CURRENT | MCL_FUTURE)): no page fault
//      reaches the disk, and no page of the loop is ever paged out;
//   4. the stack pre-faulted (kPrefaultStackBytes touched once, locked by 3.), so the loop's first
//      deep call does not fault either.
// Call it before the threads it should cover are created: every thread made afterwards (the DDS
// receive threads that deliver the robot state, the outbox's writer, the --log writer) inherits the
// affinity and the policy. A step that is not permitted or not possible throws RealtimeError naming
// the option's value, the step, the system call's reason and what would permit it; nothing continues
// without what was asked (a run that believes it is real-time but is not would report numbers it
// cannot keep). Steps done before a failing one are not undone: the caller exits.
//
// What permits it on Linux: root, or the capabilities CAP_SYS_NICE (affinity, SCHED_FIFO) and
// CAP_IPC_LOCK (mlockall), or for an ordinary user an RLIMIT_RTPRIO of at least PRIORITY and an
// RLIMIT_MEMLOCK of unlimited (/etc/security/limits.conf: `user - rtprio 90`, `user - memlock unlimited`).
#pragma once

#include "reflex/common/error.hpp"
#include <cstddef>
#include <stdexcept>
#include <string>

namespace reflex::control_node {

class RealtimeError : public reflex::Error {
 public:
  using reflex::Error::Error;
};

struct RealtimeRequest {
  int priority = 0;  ///< SCHED_FIFO priority, 1..99
  int cpu = -1;      ///< the one CPU to run on (0-based), -1: any
};

/// Bytes of stack touched once by applyRealtime (step 4).
inline constexpr std::size_t kPrefaultStackBytes = 512 * 1024;

/// "80" or "80,1" (priority, then CPU). Throws RealtimeError quoting `text` for anything else: not
/// integers, a priority outside 1..99, a negative CPU, a trailing character.
RealtimeRequest parseRealtime(const std::string& text);

/// Applies `request` to the calling process (see the header). Throws RealtimeError naming `option_text`
/// (the value as the user gave it), the step and the reason. On success returns a one-line summary,
/// e.g. "SCHED_FIFO priority 80, CPU 1 only, memory locked (VmLck 123456 kB), 512 KiB of stack pre-faulted".
std::string applyRealtime(const RealtimeRequest& request, const std::string& option_text);

}  // namespace reflex::control_node
