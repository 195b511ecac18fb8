#include "reflex/common/files.hpp"

#include <atomic>
#include <cerrno>
#include <cstdlib>
#include <fcntl.h>
#include <cmath>
#include <exception>
#include <fstream>
#include <cstdio>
#include <cstring>
#include <iostream>
#include <sys/stat.h>
#include <unistd.h>

namespace reflex::common {

namespace {

/// The folder part of `path` ("." when there is none; "/" for "/x").
std::string parentOf(const std::string& path) {
  std::string p = path;
  while (p.size() > 1 && p.back() == '/') p.pop_back();  // "out/" names the folder "out"
  const auto slash = p.rfind('/');
  if (slash == std::string::npos) return ".";
  if (slash == 0) return "/";
  return p.substr(0, slash);
}

std::string quoted(const std::string& s) { return "'" + s + "'"; }

}  // namespace

const char* fileKind(mode_t mode) noexcept {
  if (S_ISREG(mode)) return "a regular file";
  if (S_ISDIR(mode)) return "a directory";
  if (S_ISFIFO(mode)) return "a FIFO (named pipe)";
  if (S_ISCHR(mode)) return "a character device";
  if (S_ISBLK(mode)) return "a block device";
  if (S_ISSOCK(mode)) return "a socket";
  if (S_ISLNK(mode)) return "a symbolic link";
  return "an unknown kind of file";
}

std::string inputFileProblem(const std::string& path) {
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0) return "";  // missing etc.: the caller's open says so
  if (S_ISREG(st.st_mode)) return "";
  return quoted(path) + " is " + fileKind(st.st_mode) + ", not a regular file";
}

std::string writeError(const std::string& path, int err) {
  return "cannot write " + quoted(path) + ": " + std::strerror(err);
}

namespace {

// "" when `path` is missing, a regular file or a link to one (then *target_out, if given, is the file
// the link resolves to); else "output file '<path>' [(a link to '<target>')] is <kind>: <rule>".
std::string nonRegularOutput(const std::string& path, std::string* target_out, const char* rule) {
  std::string target = path;
  struct stat st {};
  if (::lstat(path.c_str(), &st) == 0) {
    if (S_ISLNK(st.st_mode)) {
      char* resolved = ::realpath(path.c_str(), nullptr);
      if (resolved == nullptr) return writeError(path, errno);
      target = resolved;
      std::free(resolved);
      if (::stat(target.c_str(), &st) != 0) return writeError(path, errno);
    }
    if (!S_ISREG(st.st_mode))
      return "output file " + quoted(path) + (target == path ? "" : " (a link to " + quoted(target) + ")") + " is " +
             fileKind(st.st_mode) + ": " + rule;
  }
  if (target_out) *target_out = target;
  return "";
}

}  // namespace

std::string replaceableFileProblem(const std::string& path, std::string* target_out) {
  // Only a regular file is ever replaced: renaming over a device, a FIFO or a directory replaces the
  // node itself (`-o /dev/null` run as root deleted the machine's /dev/null). A symbolic link is
  // written through: its target is replaced, the link stays.
  return nonRegularOutput(path, target_out, "only a regular file is ever replaced");
}

std::string writeFileReplacing(const std::string& path, const std::string& text) {
  std::string target;
  if (std::string why = replaceableFileProblem(path, &target); !why.empty()) return why;
  // The temporary file: a fresh one beside the target (O_EXCL: never an existing node; mode 0666 less
  // the umask, as the file itself would get), removed on every failure.
  static std::atomic<unsigned> counter{0};
  std::string tmp;
  int fd = -1;
  for (int attempt = 0; attempt < 100 && fd < 0; ++attempt) {
    tmp = target + "." + std::to_string(::getpid()) + "." + std::to_string(counter++) + ".tmp";
    fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0666);
    if (fd < 0 && errno != EEXIST) return writeError(tmp, errno);
  }
  if (fd < 0) return writeError(tmp, EEXIST);
  ::close(fd);
  {
    std::ofstream out(tmp, std::ios::binary | std::ios::trunc);
    out << text;
    out.flush();
    if (!out) {
      const int err = errno;
      std::remove(tmp.c_str());
      return writeError(tmp, err);
    }
  }
  if (std::rename(tmp.c_str(), target.c_str()) != 0) {
    const int err = errno;
    std::remove(tmp.c_str());
    return writeError(target, err);
  }
  return {};
}

std::string flushStandardOutput() {
  errno = 0;
  std::cout.flush();
  const bool cout_ok = static_cast<bool>(std::cout);
  const int cout_errno = errno;
  errno = 0;
  const bool stdout_ok = std::fflush(stdout) == 0 && !std::ferror(stdout);
  if (cout_ok && stdout_ok) return "";
  const int err = !stdout_ok && errno != 0 ? errno : (cout_errno != 0 ? cout_errno : EIO);
  return std::string("cannot write the standard output: ") + std::strerror(err);
}

std::string outputFileProblem(const std::string& path) {
  if (path.empty()) return "empty output file name";
  struct stat st {};
  if (::stat(path.c_str(), &st) == 0) {
    if (S_ISDIR(st.st_mode)) return "output file " + quoted(path) + " is a directory";
    if (!S_ISREG(st.st_mode) && !S_ISCHR(st.st_mode) && !S_ISFIFO(st.st_mode))
      return "output file " + quoted(path) + " is " + fileKind(st.st_mode);
    if (::access(path.c_str(), W_OK) != 0) return writeError(path, errno);
    return "";
  }
  if (errno != ENOENT) return writeError(path, errno);
  const std::string dir = parentOf(path);
  if (::stat(dir.c_str(), &st) != 0) {
    if (errno == ENOENT) return "folder " + quoted(dir) + " of output file " + quoted(path) + " does not exist";
    return "cannot write " + quoted(path) + ": folder " + quoted(dir) + ": " + std::strerror(errno);
  }
  if (!S_ISDIR(st.st_mode))
    return "folder " + quoted(dir) + " of output file " + quoted(path) + " is " + fileKind(st.st_mode);
  if (::access(dir.c_str(), W_OK | X_OK) != 0)
    return "cannot create " + quoted(path) + " in folder " + quoted(dir) + ": " + std::strerror(errno);
  return "";
}

int openOutputStream(const std::string& path) noexcept {
  const int fd = ::open(path.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC | O_NONBLOCK, 0644);
  if (fd < 0) return -1;
  if (::fcntl(fd, F_SETFL, ::fcntl(fd, F_GETFL) & ~O_NONBLOCK) != 0) {
    const int err = errno;
    ::close(fd);
    errno = err;
    return -1;
  }
  return fd;
}

std::string regularOutputProblem(const std::string& path) {
  struct stat st {};
  if (::stat(path.c_str(), &st) == 0 && !S_ISREG(st.st_mode))
    return nonRegularOutput(path, nullptr, "only a regular file is written");
  return outputFileProblem(path);
}

std::string outputFolderProblem(const std::string& dir) {
  if (dir.empty()) return "empty output folder name";
  std::string probe = dir;
  for (;;) {
    struct stat st {};
    if (::stat(probe.c_str(), &st) == 0) {
      if (!S_ISDIR(st.st_mode)) {
        if (probe == dir) return "output folder " + quoted(dir) + " is " + fileKind(st.st_mode);
        return "output folder " + quoted(dir) + " cannot be created: " + quoted(probe) + " is " + fileKind(st.st_mode);
      }
      if (::access(probe.c_str(), W_OK | X_OK) != 0) {
        if (probe == dir) return "cannot write into output folder " + quoted(dir) + ": " + std::strerror(errno);
        return "output folder " + quoted(dir) + " cannot be created in " + quoted(probe) + ": " + std::strerror(errno);
      }
      return "";
    }
    // ENOTDIR: a file on the way ("/dev/null/x"); the walk up names it.
    if (errno != ENOENT && errno != ENOTDIR)
      return "output folder " + quoted(dir) + " cannot be used: " + quoted(probe) + ": " + std::strerror(errno);
    const std::string up = parentOf(probe);
    if (up == probe) return "output folder " + quoted(dir) + ": no existing ancestor folder";
    probe = up;
  }
}

bool parseFiniteNumber(const std::string& text, double& out) noexcept {
  std::size_t used = 0;
  double v = 0.0;
  try {
    v = std::stod(text, &used);
  } catch (const std::exception&) {
    return false;
  }
  if (used == 0 || used != text.size() || !std::isfinite(v)) return false;
  out = v;
  return true;
}

bool preadAll(int fd, std::uint64_t offset, void* dst, std::size_t n) noexcept {
  auto* out = static_cast<std::uint8_t*>(dst);
  while (n > 0) {
    const ssize_t got = ::pread(fd, out, n, static_cast<off_t>(offset));
    if (got < 0 && errno == EINTR) continue;
    if (got <= 0) return false;
    out += got;
    offset += static_cast<std::uint64_t>(got);
    n -= static_cast<std::size_t>(got);
  }
  return true;
}

}  // namespace reflex::common
