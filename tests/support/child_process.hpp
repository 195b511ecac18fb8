// ChildProcess: one real executable started from a test (posix_spawn, the argv as given, no shell),
// with its stdout and stderr inherited, written to a log file, or read through a pipe. The
// destructor stops a child that still runs (SIGTERM, then SIGKILL after the grace period) and reaps
// it, so a failing test never leaves a process behind. Not thread-safe: one test thread owns it.
//
// Exit codes everywhere: the process's exit status, 128 + N if signal N ended it, kStillRunning
// (-1) if it has not exited (wait timed out) or never started.
#pragma once

#include <sys/types.h>

#include <chrono>
#include <functional>
#include <string>
#include <vector>

namespace reflex::testing {

/// Where a child's output goes.
struct ChildOutput {
  enum class Kind {
    kInherit,  ///< the test's own stdout/stderr (ctest shows it)
    kFile,     ///< stdout and stderr both to `path` (created or truncated)
    kPipe,     ///< stdout through a pipe (read with readUntil()/output()); stderr inherited
  };
  Kind kind = Kind::kInherit;
  std::string path;

  static ChildOutput inherit() { return {}; }
  static ChildOutput file(std::string path) { return {Kind::kFile, std::move(path)}; }
  static ChildOutput pipe() { return {Kind::kPipe, {}}; }
};

class ChildProcess {
 public:
  static constexpr int kStillRunning = -1;

  /// Starts argv[0] (a path, not searched in PATH) with `argv`. A start failure is not thrown:
  /// started() is false and error() says why (the test asserts on it).
  ChildProcess(std::vector<std::string> argv, ChildOutput output);
  /// The same with output to `log_path` (stdout + stderr), or inherited if `log_path` is empty.
  explicit ChildProcess(std::vector<std::string> argv, const std::string& log_path = "");
  ~ChildProcess();
  ChildProcess(const ChildProcess&) = delete;
  ChildProcess& operator=(const ChildProcess&) = delete;

  bool started() const { return started_; }
  /// Why the start failed ("" if it started).
  const std::string& error() const { return error_; }
  /// The process id (-1 if it never started or has been reaped).
  pid_t pid() const { return pid_; }
  /// True once the child has been reaped and a signal ended it (its code is then 128 + signal).
  bool signaled() const { return signaled_; }

  /// Sends signal `sig` if the child still runs.
  void signal(int sig) const;
  /// Waits up to `timeout` for the exit (reading the pipe meanwhile, so a chatty child never blocks
  /// on a full pipe); the exit code, or kStillRunning. After the exit, returns the same code again.
  int wait(std::chrono::milliseconds timeout);
  /// SIGTERM, up to `grace` for the exit, then SIGKILL; the exit code (the stored one if the
  /// child had already exited).
  int terminate(std::chrono::milliseconds grace = std::chrono::milliseconds(5000));

  /// Reads the output until `token` appears, the child closes it (exited), or `timeout` passes;
  /// returns everything read so far (pipe or log file; "" for inherited output).
  std::string readUntil(const std::string& token, std::chrono::milliseconds timeout);
  /// Everything the child has written so far (pipe: what can be read without waiting; log file:
  /// the file; inherited: "").
  std::string output();

 private:
  void drainPipe(int timeout_ms);
  bool reap(bool block);

  ChildOutput out_;
  pid_t pid_ = -1;
  bool started_ = false;
  int code_ = kStillRunning;
  bool signaled_ = false;
  int pipe_ = -1;
  std::string read_;
  std::string error_;
};

/// Path of an executable built into the project's bin folder (build/bin/`name`).
inline std::string binPath(const std::string& name) { return std::string(REFLEX_BIN_DIR) + "/" + name; }

/// A "full" character device of this test program's own (1, 7: every write fails with ENOSPC), in a
/// private folder made at the first call and removed at exit: a test that needs a full device never
/// depends on the machine's /dev/full being intact after other tests ran. Without the right to make
/// device nodes (not root): "/dev/full".
const std::string& fullDevice();

/// What a command printed and returned (run to completion).
struct ProcessResult {
  int exit_code = -1;  ///< -1 if it could not be started or did not exit normally
  std::string out, err;
};

/// Runs `command` through /bin/sh -c (so `command` may hold quoting and redirections) to completion:
/// stdout read through a pipe into out; the whole command line's stderr to `stderr_path` (then read
/// back into err), or, if `stderr_path` is empty, into out as well (2>&1). Waits up to `timeout`,
/// then kills it (exit_code -1).
ProcessResult runShell(const std::string& command, const std::string& stderr_path = "",
                       std::chrono::milliseconds timeout = std::chrono::minutes(5));

/// Runs `fn` in a forked copy of the test program (for code that may block or crash: a read of a
/// FIFO, a loader fed a device) and returns its result as the exit code (0..255), 128 + N if signal
/// N ended it, or ChildProcess::kStillRunning if it did not finish within `timeout` (it is then
/// killed and reaped). The child leaves with _exit: no gtest output, no static destructors.
int runInChild(std::chrono::milliseconds timeout, const std::function<int()>& fn);

}  // namespace reflex::testing
