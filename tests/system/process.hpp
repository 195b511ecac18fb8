// A child process for integration tests: started with posix_spawn, stopped with SIGTERM (then
// SIGKILL) in the destructor, so a failing test never leaves processes behind.
#pragma once

#include <csignal>
#include <fcntl.h>
#include <chrono>
#include <spawn.h>
#include <string>
#include <sys/wait.h>
#include <thread>
#include <unistd.h>
#include <vector>

extern char** environ;

namespace reflex::testing {

class ChildProcess {
 public:
  explicit ChildProcess(std::vector<std::string> argv, const std::string& log_path = "") {
    std::vector<char*> args;
    for (auto& a : argv) args.push_back(a.data());
    args.push_back(nullptr);
    posix_spawn_file_actions_t fa;
    posix_spawn_file_actions_init(&fa);
    if (!log_path.empty()) {
      posix_spawn_file_actions_addopen(&fa, 1, log_path.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
      posix_spawn_file_actions_adddup2(&fa, 1, 2);
    }
    if (posix_spawn(&pid_, args[0], &fa, nullptr, args.data(), environ) != 0) pid_ = -1;
    posix_spawn_file_actions_destroy(&fa);
  }
  ~ChildProcess() { terminate(); }
  ChildProcess(const ChildProcess&) = delete;
  ChildProcess& operator=(const ChildProcess&) = delete;

  bool started() const { return pid_ > 0; }
  pid_t pid() const { return pid_; }

  /// Waits for the exit (up to timeout); returns the exit code, or -1 if it did not exit.
  int wait(std::chrono::milliseconds timeout) {
    const auto end = std::chrono::steady_clock::now() + timeout;
    while (pid_ > 0 && std::chrono::steady_clock::now() < end) {
      int status = 0;
      const pid_t r = waitpid(pid_, &status, WNOHANG);
      if (r == pid_) {
        pid_ = -1;
        return WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
    return -1;
  }
  void signal(int sig) {
    if (pid_ > 0) kill(pid_, sig);
  }
  /// SIGTERM, then SIGKILL after 3 s; returns the exit code.
  int terminate() {
    if (pid_ <= 0) return -1;
    kill(pid_, SIGTERM);
    int rc = wait(std::chrono::milliseconds(3000));
    if (rc < 0 && pid_ > 0) {
      kill(pid_, SIGKILL);
      rc = wait(std::chrono::milliseconds(3000));
    }
    return rc;
  }

 private:
  pid_t pid_ = -1;
};

}  // namespace reflex::testing
