#include "reflex/vision/output_file.hpp"

#include "reflex/common/files.hpp"
#include "reflex/vision/error.hpp"

#include <fcntl.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <filesystem>

namespace reflex::vision {

void requireParentFolder(const std::string& path, const std::string& what) {
  const std::filesystem::path parent = std::filesystem::path(path).parent_path();
  if (parent.empty()) return;
  std::error_code ec;
  if (!std::filesystem::is_directory(parent, ec))
    throw VisionError("cannot write " + what + " '" + path + "': folder '" + parent.string() + "' does not exist");
}

OutputFile::OutputFile(const std::string& path, const std::string& what) : path_(path), what_(what) {
  requireParentFolder(path, what);
  // A directory or a block device in its place is refused; a device or a FIFO with a reader is
  // written through.
  if (const std::string why = common::outputFileProblem(path); !why.empty()) throw VisionError(what + ": " + why);
  fd_ = common::openOutputStream(path);
  if (fd_ < 0)
    throw VisionError("cannot write " + what + " '" + path + "': " +
                      (errno == ENXIO ? std::string("a FIFO with no reader") : std::string(std::strerror(errno))));
  buffer_.reserve(kBufferBytes);
}

OutputFile::~OutputFile() {
  if (fd_ >= 0) ::close(fd_);  // unchecked on purpose: close() is the checked path
}

void OutputFile::fail(int err) noexcept {
  if (error_.empty()) {
    try {
      error_ = "cannot write " + what_ + " '" + path_ + "': " + std::strerror(err);
    } catch (...) {
      error_ = "cannot write output file";  // out of memory while building the message
    }
  }
  buffer_.clear();
}

void OutputFile::flush() noexcept {
  std::size_t done = 0;
  while (fd_ >= 0 && !failed() && done < buffer_.size()) {
    const ssize_t n = ::write(fd_, buffer_.data() + done, buffer_.size() - done);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) {
      fail(n < 0 ? errno : EIO);
      break;
    }
    done += static_cast<std::size_t>(n);
  }
  buffer_.clear();
}

void OutputFile::write(std::string_view text) noexcept {
  if (failed() || fd_ < 0) return;
  try {
    buffer_.append(text);
  } catch (...) {
    fail(ENOMEM);
    return;
  }
  if (buffer_.size() >= kBufferBytes) flush();
}

void OutputFile::close() {
  if (fd_ < 0) {
    if (failed()) throw VisionError(error_);
    return;
  }
  flush();
  const int rc = ::close(fd_);
  const int err = errno;
  fd_ = -1;
  if (rc != 0 && err != EINTR) fail(err);  // EINTR: the descriptor is released on Linux, data handed over
  if (failed()) throw VisionError(error_);
}

void writeTextFile(const std::string& path, const std::string& text, const std::string& what) {
  OutputFile out(path, what);
  out.write(text);
  out.close();
}

}  // namespace reflex::vision
