#include "child_process.hpp"

#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <spawn.h>
#include <sys/stat.h>
#include <sys/sysmacros.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <iterator>
#include <thread>

extern char** environ;

namespace reflex::testing {

namespace {

std::string readWholeFile(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
}

}  // namespace

ChildProcess::ChildProcess(std::vector<std::string> argv, const std::string& log_path)
    : ChildProcess(std::move(argv), log_path.empty() ? ChildOutput::inherit() : ChildOutput::file(log_path)) {}

ChildProcess::ChildProcess(std::vector<std::string> argv, ChildOutput output) : out_(std::move(output)) {
  if (argv.empty()) {
    error_ = "empty argv";
    return;
  }
  std::vector<char*> args;
  for (auto& a : argv) args.push_back(a.data());
  args.push_back(nullptr);
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  int write_end = -1;
  if (out_.kind == ChildOutput::Kind::kFile) {
    posix_spawn_file_actions_addopen(&actions, STDOUT_FILENO, out_.path.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    posix_spawn_file_actions_adddup2(&actions, STDOUT_FILENO, STDERR_FILENO);
  } else if (out_.kind == ChildOutput::Kind::kPipe) {
    int fds[2];
    if (::pipe2(fds, O_CLOEXEC) != 0) {
      error_ = std::string("pipe2: ") + std::strerror(errno);
      posix_spawn_file_actions_destroy(&actions);
      return;
    }
    pipe_ = fds[0];
    write_end = fds[1];
    posix_spawn_file_actions_adddup2(&actions, write_end, STDOUT_FILENO);
  }
  const int rc = ::posix_spawn(&pid_, args[0], &actions, nullptr, args.data(), environ);
  posix_spawn_file_actions_destroy(&actions);
  if (write_end >= 0) ::close(write_end);  // the child holds its own copy; EOF once it exits
  if (rc != 0) {
    pid_ = -1;
    error_ = "cannot start '" + argv[0] + "': " + std::strerror(rc);
    return;
  }
  started_ = true;
}

ChildProcess::~ChildProcess() {
  terminate();
  if (pipe_ >= 0) ::close(pipe_);
}

void ChildProcess::signal(int sig) const {
  if (pid_ > 0) ::kill(pid_, sig);
}

bool ChildProcess::reap(bool block) {
  if (pid_ <= 0) return true;
  int status = 0;
  if (::waitpid(pid_, &status, block ? 0 : WNOHANG) != pid_) return false;
  pid_ = -1;
  code_ = WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
  signaled_ = WIFSIGNALED(status);
  drainPipe(0);
  return true;
}

int ChildProcess::wait(std::chrono::milliseconds timeout) {
  const auto end = std::chrono::steady_clock::now() + timeout;
  while (!reap(false)) {
    if (std::chrono::steady_clock::now() >= end) return kStillRunning;
    if (pipe_ >= 0)
      drainPipe(10);  // waits up to 10 ms for output
    else
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  return code_;
}

int ChildProcess::terminate(std::chrono::milliseconds grace) {
  if (pid_ <= 0) return code_;
  ::kill(pid_, SIGTERM);
  ::kill(pid_, SIGCONT);  // a stopped child (SIGSTOP) acts on the SIGTERM only once continued
  if (wait(grace) != kStillRunning) return code_;
  ::kill(pid_, SIGKILL);
  reap(true);
  return code_;
}

void ChildProcess::drainPipe(int timeout_ms) {
  if (pipe_ < 0) return;
  for (;;) {
    pollfd p{pipe_, POLLIN, 0};
    if (::poll(&p, 1, timeout_ms) <= 0) return;
    char buf[4096];
    const ssize_t n = ::read(pipe_, buf, sizeof buf);
    if (n <= 0) {  // EOF: the child (and every process it started) closed its stdout
      ::close(pipe_);
      pipe_ = -1;
      return;
    }
    read_.append(buf, static_cast<std::size_t>(n));
    timeout_ms = 0;  // after the first read, take only what is already there
  }
}

std::string ChildProcess::output() {
  switch (out_.kind) {
    case ChildOutput::Kind::kFile: return readWholeFile(out_.path);
    case ChildOutput::Kind::kPipe: drainPipe(0); return read_;
    case ChildOutput::Kind::kInherit: break;
  }
  return {};
}

std::string ChildProcess::readUntil(const std::string& token, std::chrono::milliseconds timeout) {
  const auto end = std::chrono::steady_clock::now() + timeout;
  for (;;) {
    std::string text = output();
    if (text.find(token) != std::string::npos || out_.kind == ChildOutput::Kind::kInherit) return text;
    const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(end - std::chrono::steady_clock::now());
    if (left.count() <= 0) return text;
    if (out_.kind == ChildOutput::Kind::kPipe) {
      if (pipe_ < 0) return read_;  // closed: nothing more will come
      drainPipe(static_cast<int>(std::min<long long>(left.count(), 100)));
    } else {
      if (pid_ <= 0) return text;  // exited: the file is complete
      reap(false);
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
  }
}

ProcessResult runShell(const std::string& command, const std::string& stderr_path, std::chrono::milliseconds timeout) {
  ProcessResult r;
  const std::string redirect = stderr_path.empty() ? std::string("2>&1") : "2>" + stderr_path;
  ChildProcess child({"/bin/sh", "-c", "{ " + command + "\n} " + redirect}, ChildOutput::pipe());
  if (!child.started()) return r;
  const int code = child.wait(timeout);
  r.out = child.output();
  if (!stderr_path.empty()) r.err = readWholeFile(stderr_path);
  r.exit_code = (code == ChildProcess::kStillRunning || child.signaled()) ? -1 : code;
  return r;
}

int runInChild(std::chrono::milliseconds timeout, const std::function<int()>& fn) {
  const pid_t pid = ::fork();
  if (pid < 0) return ChildProcess::kStillRunning;
  if (pid == 0) ::_exit(fn());
  const auto end = std::chrono::steady_clock::now() + timeout;
  int status = 0;
  while (::waitpid(pid, &status, WNOHANG) == 0) {
    if (std::chrono::steady_clock::now() > end) {
      ::kill(pid, SIGKILL);
      ::waitpid(pid, &status, 0);
      return ChildProcess::kStillRunning;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(2));
  }
  return WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
}

const std::string& fullDevice() {
  struct Node {
    std::string dir, path = "/dev/full";
    Node() {
      const char* tmp = std::getenv("TMPDIR");
      std::string templ = std::string(tmp != nullptr && *tmp != '\0' ? tmp : "/tmp") + "/reflex_full_device_XXXXXX";
      if (::mkdtemp(templ.data()) == nullptr) return;
      dir = templ;
      const std::string node = dir + "/full";
      if (::mknod(node.c_str(), S_IFCHR | 0666, makedev(1, 7)) == 0) path = node;
    }
    ~Node() {
      if (path != "/dev/full") ::unlink(path.c_str());
      if (!dir.empty()) ::rmdir(dir.c_str());
    }
  };
  static const Node node;
  return node.path;
}

}  // namespace reflex::testing
