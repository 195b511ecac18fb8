#include "reflex/control_node/timeseries_log.hpp"

#include "reflex/common/files.hpp"

#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cstring>
#include <sstream>

namespace reflex::control_node {

namespace {
std::string reasonOf(int err) { return std::strerror(err); }
}  // namespace

TimeseriesLog::TimeseriesLog(const control::Model& model, const std::string& path, std::size_t capacity)
    : model_(model), path_(path) {
  if (capacity == 0) throw LogError("--log ring capacity must be positive");
  // A directory or a block device in its place is refused; a device or a FIFO with a reader is
  // written through (--log /dev/null, a pipe into a plotter).
  if (const std::string why = reflex::common::outputFileProblem(path); !why.empty()) throw LogError("--log: " + why);
  const int fd = reflex::common::openOutputStream(path);
  file_ = fd < 0 ? nullptr : ::fdopen(fd, "w");
  if (file_ == nullptr) {
    const int err = errno;
    if (fd >= 0) ::close(fd);
    throw LogError("cannot open the --log file '" + path +
                   "' for writing: " + (err == ENXIO ? std::string("a FIFO with no reader") : reasonOf(err)));
  }
  std::ostringstream header;
  control::writeTimeseriesCsvHeader(model, header);
  const std::string text = header.str();
  errno = 0;
  if (std::fwrite(text.data(), 1, text.size(), file_) != text.size() || std::fflush(file_) != 0) {
    const int err = errno != 0 ? errno : EIO;
    std::fclose(file_);
    file_ = nullptr;
    throw LogError("cannot write the --log file '" + path + "': " + reasonOf(err));
  }
  ring_.resize(capacity);
  for (auto& row : ring_) {
    row.q.setZero(model.nq);
    row.qdot.setZero(model.nq);
  }
  writer_ = std::thread([this] { writerLoop(); });
}

TimeseriesLog::~TimeseriesLog() {
  if (!closed_) close();
}

bool TimeseriesLog::push(const control::SimSample& row) noexcept {
  const std::uint64_t head = head_.load(std::memory_order_relaxed);
  if (head - tail_.load(std::memory_order_acquire) >= ring_.size()) {
    dropped_.fetch_add(1, std::memory_order_relaxed);
    return false;
  }
  // Same-size Eigen vectors and fixed-size members: the copy does not allocate.
  ring_[head % ring_.size()] = row;
  head_.store(head + 1, std::memory_order_release);
  return true;
}

void TimeseriesLog::fail(int err) {
  int expected = 0;
  errno_.compare_exchange_strong(expected, err != 0 ? err : EIO);
}

bool TimeseriesLog::drain() {
  const std::uint64_t head = head_.load(std::memory_order_acquire);
  std::uint64_t tail = tail_.load(std::memory_order_relaxed);
  if (tail == head) return true;
  std::ostringstream text;
  std::uint64_t n = 0;
  for (; tail != head; ++tail, ++n) control::writeTimeseriesCsvRow(model_, ring_[tail % ring_.size()], text);
  tail_.store(tail, std::memory_order_release);  // the slots are free again once formatted
  if (errno_.load() != 0) return false;          // after a failure rows are consumed, not written
  const std::string s = text.str();
  errno = 0;
  if (std::fwrite(s.data(), 1, s.size(), file_) != s.size() || std::fflush(file_) != 0) {
    fail(errno);
    return false;
  }
  written_.fetch_add(n);
  return true;
}

void TimeseriesLog::writerLoop() {
  while (!stop_.load()) {
    drain();
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
}

bool TimeseriesLog::close() {
  if (closed_) return close_ok_;
  closed_ = true;
  stop_.store(true);
  if (writer_.joinable()) writer_.join();
  drain();  // what the producer queued after the thread's last pass
  errno = 0;
  if (std::fclose(file_) != 0) fail(errno);
  file_ = nullptr;
  close_ok_ = errno_.load() == 0 && dropped_.load() == 0;
  return close_ok_;
}

std::string TimeseriesLog::error() const {
  std::string e;
  if (const int err = errno_.load(); err != 0) {
    e = "cannot write the --log file '" + path_ + "': " + reasonOf(err) + " (" + std::to_string(written_.load()) +
        " rows written before the error)";
  }
  if (const std::uint64_t d = dropped_.load(); d > 0) {
    e += std::string(e.empty() ? "" : "; ") + "--log file '" + path_ + "': " + std::to_string(d) +
         " rows dropped (the writer could not keep up)";
  }
  return e;
}

}  // namespace reflex::control_node
