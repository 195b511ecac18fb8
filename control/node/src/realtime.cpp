#include "reflex/control_node/realtime.hpp"

#include <alloca.h>
#include <sched.h>
#include <sys/mman.h>
#include <sys/resource.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>

namespace reflex::control_node {

namespace {

std::string errnoText(int e) { return std::strerror(e); }

/// "0-1" or "0,2-3": the CPUs in `set`.
std::string describeCpus(const cpu_set_t& set) {
  std::string out;
  for (int c = 0; c < CPU_SETSIZE; ++c) {
    if (!CPU_ISSET(c, &set)) continue;
    int last = c;
    while (last + 1 < CPU_SETSIZE && CPU_ISSET(last + 1, &set)) ++last;
    out += (out.empty() ? "" : ",") + std::to_string(c) + (last > c ? "-" + std::to_string(last) : "");
    c = last;
  }
  return out.empty() ? "none" : out;
}

std::string limitText(int resource) {
  rlimit lim{};
  if (getrlimit(resource, &lim) != 0) return "unknown";
  return lim.rlim_cur == RLIM_INFINITY ? "unlimited" : std::to_string(static_cast<unsigned long long>(lim.rlim_cur));
}

/// VmLck of this process in kB (/proc/self/status), -1 if unknown.
long lockedKb() {
  std::ifstream in("/proc/self/status");
  std::string line;
  while (std::getline(in, line))
    if (line.rfind("VmLck:", 0) == 0) return std::strtol(line.c_str() + 6, nullptr, 10);
  return -1;
}

/// Touches `bytes` of stack below the caller's frame, so that (with MCL_FUTURE) they are resident.
__attribute__((noinline)) void prefaultStack(std::size_t bytes) {
  volatile unsigned char* stack = static_cast<volatile unsigned char*>(alloca(bytes));
  const long page = sysconf(_SC_PAGESIZE) > 0 ? sysconf(_SC_PAGESIZE) : 4096;
  for (std::size_t i = 0; i < bytes; i += static_cast<std::size_t>(page)) stack[i] = 0;
}

}  // namespace

RealtimeRequest parseRealtime(const std::string& text) {
  const std::string why = "--realtime '" + text +
                          "' is not PRIORITY[,CPU]: a SCHED_FIFO priority 1..99, optionally a comma and the "
                          "CPU to run on (0-based), e.g. 80 or 80,1";
  RealtimeRequest r;
  const std::size_t comma = text.find(',');
  auto toInt = [&](const std::string& part, int& out) {
    if (part.empty() || part.size() > 6) throw RealtimeError(why);
    for (const char c : part)
      if (c < '0' || c > '9') throw RealtimeError(why);
    out = std::stoi(part);
  };
  toInt(text.substr(0, comma), r.priority);
  if (comma != std::string::npos) toInt(text.substr(comma + 1), r.cpu);
  if (r.priority < 1 || r.priority > 99)
    throw RealtimeError("--realtime '" + text + "': SCHED_FIFO priority " + std::to_string(r.priority) +
                        " is outside 1..99");
  return r;
}

std::string applyRealtime(const RealtimeRequest& request, const std::string& option_text) {
  const std::string head = "--realtime '" + option_text + "': ";
  const std::string permit =
      "run as root, give the binary the capabilities (setcap cap_sys_nice,cap_ipc_lock+ep reflex_controller), or "
      "give the user an rtprio limit >= the priority and an unlimited memlock limit (/etc/security/limits.conf)";
  std::string summary = "SCHED_FIFO priority " + std::to_string(request.priority);
  // 1. CPU affinity, against the CPUs this process may use at all (a cgroup or taskset may allow fewer).
  if (request.cpu >= 0) {
    cpu_set_t allowed;
    CPU_ZERO(&allowed);
    if (sched_getaffinity(0, sizeof(allowed), &allowed) != 0)
      throw RealtimeError(head + "cannot read this process's CPUs (sched_getaffinity: " + errnoText(errno) + ")");
    if (request.cpu >= CPU_SETSIZE || !CPU_ISSET(request.cpu, &allowed))
      throw RealtimeError(head + "CPU " + std::to_string(request.cpu) +
                          " is not one this process may run on (allowed: " + describeCpus(allowed) + "; " +
                          std::to_string(sysconf(_SC_NPROCESSORS_ONLN)) + " online)");
    cpu_set_t one;
    CPU_ZERO(&one);
    CPU_SET(request.cpu, &one);
    if (sched_setaffinity(0, sizeof(one), &one) != 0)
      throw RealtimeError(head + "cannot pin the process to CPU " + std::to_string(request.cpu) +
                          " (sched_setaffinity: " + errnoText(errno) + ")");
    summary += ", CPU " + std::to_string(request.cpu) + " only";
  }
  // 2. SCHED_FIFO.
  sched_param param{};
  param.sched_priority = request.priority;
  if (sched_setscheduler(0, SCHED_FIFO, &param) != 0) {
    const int e = errno;
    std::string reason = head + "SCHED_FIFO priority " + std::to_string(request.priority) +
                         " refused (sched_setscheduler: " + errnoText(e) + ")";
    if (e == EPERM)
      reason += ": this process has neither CAP_SYS_NICE nor an rtprio limit of at least " +
                std::to_string(request.priority) + " (ulimit -r is " + limitText(RLIMIT_RTPRIO) + "); " + permit;
    throw RealtimeError(reason);
  }
  // 3. Memory locked (now and every later allocation).
  if (mlockall(MCL_CURRENT | MCL_FUTURE) != 0) {
    const int e = errno;
    std::string reason = head + "memory cannot be locked (mlockall: " + errnoText(e) + ")";
    if (e == EPERM || e == ENOMEM)
      reason += ": this process has neither CAP_IPC_LOCK nor a memlock limit large enough (ulimit -l is " +
                limitText(RLIMIT_MEMLOCK) + " bytes); " + permit;
    throw RealtimeError(reason);
  }
  // 4. The stack, pre-faulted (and so locked).
  prefaultStack(kPrefaultStackBytes);
  summary += ", memory locked (VmLck " + std::to_string(lockedKb()) + " kB), " +
             std::to_string(kPrefaultStackBytes / 1024) + " KiB of stack pre-faulted";
  return summary;
}

}  // namespace reflex::control_node
