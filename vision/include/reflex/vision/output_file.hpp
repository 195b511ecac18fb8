#pragma once
// Output files of the vision tools (the --dump CSV, session folders, calibration / object map /
// mount / ground truth files) with every write and the close checked: a file that could not be
// written completely is an error naming the file and the cause (the system's errno text), never a
// silent success (`--dump /dev/full` used to exit 0).
//
// Contract: the constructor opens (creates or truncates) the file; a missing parent folder is an
// error at that moment, before any work is done. write() never throws (it is called from the
// frame loop): it keeps the first error, and every later write is a no-op. close() flushes, closes
// and throws VisionError if any write or the close failed. Text is buffered in user space and
// handed to the kernel (write(2)) every kBufferBytes, so a full disk is seen during a long run,
// not only at its end (failed() tells the caller to stop early).
#include <string>
#include <string_view>

namespace reflex::vision {

class OutputFile {
 public:
  static constexpr std::size_t kBufferBytes = 64 * 1024;
  /// Opens `path` for writing; `what` names the file in messages ("dump file", "timestamps file").
  /// Throws VisionError "cannot write <what> '<path>': <cause>" (a missing folder says so).
  OutputFile(const std::string& path, const std::string& what);
  /// Closes the file if close() was not called; errors are dropped there (call close() to see them).
  ~OutputFile();
  OutputFile(const OutputFile&) = delete;
  OutputFile& operator=(const OutputFile&) = delete;

  /// Appends text. Never throws; after the first failure nothing more is written (see failed()).
  void write(std::string_view text) noexcept;
  /// True once a write failed (the message is error()).
  bool failed() const { return !error_.empty(); }
  /// "cannot write <what> '<path>': <cause>", or empty.
  const std::string& error() const { return error_; }
  /// Flushes and closes; throws VisionError with error() if anything failed. Later calls do nothing.
  void close();
  const std::string& path() const { return path_; }

 private:
  void flush() noexcept;
  void fail(int err) noexcept;
  std::string path_, what_, buffer_, error_;
  int fd_ = -1;
};

/// Writes `text` to `path` in one go (open, write, close, all checked). Throws VisionError naming
/// `what`, the path and the cause.
void writeTextFile(const std::string& path, const std::string& text, const std::string& what);

/// Throws VisionError naming `what` and the folder if the folder that would hold `path` does not
/// exist (or is not a folder). A path without a folder part refers to the current folder.
void requireParentFolder(const std::string& path, const std::string& what);

}  // namespace reflex::vision
