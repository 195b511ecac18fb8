// The controller's --log file: the per-cycle time series in reflex_sim's
// CSV format, STREAMED to disk while the controller runs, so that output that cannot be written is
// never reported as success and the rows survive any stop but SIGKILL.
//
// Contract:
//  - open (constructor): the file is created and its header row written and flushed at once; a
//    missing folder, a path that is not writable or a full device is a LogError naming the file and
//    the system's reason, BEFORE the control loop starts.
//  - push (the 5 ms control thread): copies one row into a preallocated ring of `capacity` rows.
//    No allocation, no I/O, no lock, never throws. A full ring (the disk cannot keep up) drops the row
//    and counts it (droppedRows()); nothing is lost silently.
//  - a writer thread drains the ring every few milliseconds, formats the rows, writes and flushes
//    them, and checks every write; the first failure (errno) stops writing and is kept.
//  - close: drains what is left, flushes, closes and checks the close. Returns the outcome; error()
//    then names the file and the reason ("" when every row reached the file).
// Single producer (push), single consumer (the writer thread).
//
// Extending: another row format only needs another pair of header / row functions.
#pragma once

#include "reflex/common/error.hpp"
#include "reflex/control/model.hpp"
#include "reflex/control/scenarios.hpp"

#include <atomic>
#include <cstdint>
#include <cstdio>
#include <memory>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

namespace reflex::control_node {

class LogError : public reflex::Error {
 public:
  using reflex::Error::Error;
};

class TimeseriesLog {
 public:
  /// Opens `path` for writing (truncating) and writes the header row. `capacity` rows are
  /// preallocated (each with nq joint values). Throws LogError naming the file and the reason.
  TimeseriesLog(const control::Model& model, const std::string& path, std::size_t capacity = 4096);
  /// Closes the file if close() was not called (errors then go unreported: call close()).
  ~TimeseriesLog();
  TimeseriesLog(const TimeseriesLog&) = delete;
  TimeseriesLog& operator=(const TimeseriesLog&) = delete;

  /// Control thread: queues a copy of `row` (q and qdot of size nq). False if the ring was full (the
  /// row is dropped and counted). No allocation, no I/O, never throws.
  bool push(const control::SimSample& row) noexcept;

  /// Drains the ring, flushes and closes the file. True if every queued row was written and the
  /// close succeeded. Idempotent.
  bool close();

  const std::string& path() const { return path_; }
  std::uint64_t writtenRows() const { return written_.load(); }
  std::uint64_t droppedRows() const { return dropped_.load(); }
  /// Rows pushed and not yet taken by the writer thread.
  std::uint64_t queued() const { return head_.load() - tail_.load(); }
  /// "" or "cannot write the --log file '<path>': <reason> (after N rows)".
  std::string error() const;

 private:
  void writerLoop();
  bool drain();  // writer thread: formats and writes the queued rows; false on a write error
  void fail(int err);

  const control::Model& model_;
  std::string path_;
  std::FILE* file_ = nullptr;
  std::vector<control::SimSample> ring_;
  std::atomic<std::uint64_t> head_{0};  // next slot push writes (producer)
  std::atomic<std::uint64_t> tail_{0};  // next slot the writer reads (consumer)
  std::atomic<std::uint64_t> written_{0}, dropped_{0};
  std::atomic<bool> stop_{false};
  std::atomic<int> errno_{0};
  bool closed_ = false;
  bool close_ok_ = true;
  std::thread writer_;
};

}  // namespace reflex::control_node
