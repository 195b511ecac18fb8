// A child process for the modules' integration tests: started with posix_spawn (stdout and stderr
// to a log file), stopped with SIGTERM then SIGKILL in the destructor, so a failing test leaves no
// process behind.
#pragma once

#include <fcntl.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <fstream>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

extern char** environ;

namespace reflex::modules::testing {

class Child {
 public:
  Child(std::vector<std::string> argv, std::string log_path) : log_(std::move(log_path)) {
    std::vector<char*> args;
    for (auto& a : argv) args.push_back(a.data());
    args.push_back(nullptr);
    posix_spawn_file_actions_t fa;
    posix_spawn_file_actions_init(&fa);
    posix_spawn_file_actions_addopen(&fa, 1, log_.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    posix_spawn_file_actions_adddup2(&fa, 1, 2);
    if (posix_spawn(&pid_, args[0], &fa, nullptr, args.data(), environ) != 0) pid_ = -1;
    posix_spawn_file_actions_destroy(&fa);
  }
  ~Child() { terminate(); }
  Child(const Child&) = delete;
  Child& operator=(const Child&) = delete;

  bool started() const { return pid_ > 0; }
  /// Waits up to `timeout` for the exit; the exit code, 128 + signal, or -1 if still running.
  int wait(std::chrono::milliseconds timeout) {
    const auto end = std::chrono::steady_clock::now() + timeout;
    while (pid_ > 0) {
      int status = 0;
      if (waitpid(pid_, &status, WNOHANG) == pid_) {
        pid_ = -1;
        code_ = WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
        return code_;
      }
      if (std::chrono::steady_clock::now() >= end) return -1;
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    return code_;
  }
  /// SIGTERM, then SIGKILL after 5 s; the exit code.
  int terminate() {
    if (pid_ <= 0) return code_;
    kill(pid_, SIGTERM);
    int rc = wait(std::chrono::milliseconds(5000));
    if (rc == -1) {
      kill(pid_, SIGKILL);
      rc = wait(std::chrono::milliseconds(2000));
    }
    return rc;
  }
  std::string log() const {
    std::ifstream in(log_);
    std::stringstream ss;
    ss << in.rdbuf();
    return ss.str();
  }

 private:
  pid_t pid_ = -1;
  int code_ = -1;
  std::string log_;
};

/// The integer after "<key>=" in `text` (the last occurrence), or -1.
inline long statValue(const std::string& text, const std::string& key) {
  const auto pos = text.rfind(" " + key + "=");
  if (pos == std::string::npos) return -1;
  return std::stol(text.substr(pos + key.size() + 2));
}

}  // namespace reflex::modules::testing
