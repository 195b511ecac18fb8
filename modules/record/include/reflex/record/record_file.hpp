// The Reflex recording file: an append-only log of length-prefixed, CRC-checked records, each one
// DDS sample as it was received (topic name, type name, receive time, source time, CDR payload).
//
// Layout (all integers little-endian):
//   file header (16 bytes): "RFXREC\r\n" | u32 format version (1) | u32 reserved (0)
//   record:                  u32 sync "RREC" | u32 body length L | u32 CRC-32 (IEEE) of the body | body
//   body:                    i64 receive time [ns, system clock, Unix epoch; >= 0]
//                            i64 source time [ns, the writer's DDS source timestamp]
//                            u16 topic length | topic bytes | u16 type length | type bytes
//                            u32 payload length | payload (XCDR1 with its 4-byte encapsulation)
//
// Why this survives a kill -9: the file is only ever appended to, each record is complete in itself
// and carries its own length and CRC, so whatever a crash leaves behind is a valid prefix plus at
// most one torn record at the end, which RecordReader detects and reports (TailState::kTorn) instead
// of returning it. A record that is corrupt in the middle (bad CRC, bad sync) is reported, and the
// reader can resynchronise on the next sync word whose CRC checks.
//
// Reading time is linear in the file size, whatever the bytes: a candidate
// record found while resynchronising is checked in O(1) reads plus O(kCrcMarkStride) bytes of CRC,
// not by reading its body (a crafted file with a sync word every 12 bytes, each claiming a body that
// runs to the end of the file, made the old reader quadratic: 2 MB took > 60 s). The CRC of a byte
// range comes from CRC-32 prefix values kept every kCrcMarkStride bytes (4 bytes per 256 of the file
// read that far, built once per reader) and the linearity of the CRC (crc32Combine). The record at the
// reading position is checked that way too before its body is read when the body it claims is above
// 1 KiB, so a damaged header costs at most 1 KiB of reading whatever it claims (at 64 KiB, a damaged
// header after every small record made reading 1,000 x slower than a valid file).
//
// Durability policy (RecordWriter): records are collected in a user-space buffer and handed to the
// kernel (write(2)) when the buffer holds flush_bytes or the oldest buffered record is older than
// flush_interval; fsync(2) runs every sync_interval and at close. A kill -9 loses at most the records
// of the last flush_interval (they were still in the process); data already written survives the
// process (page cache) and, after the next fsync, also a power loss or kernel crash.
#pragma once

#include "reflex/common/error.hpp"
#include "reflex/common/crc32.hpp"

#include <chrono>
#include <cstdint>
#include <cstdio>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

namespace reflex::record {

/// Set-up and I/O errors of recording files (message names the file and the bad value).
class RecordError : public reflex::Error {
 public:
  using reflex::Error::Error;
};

inline constexpr char kFileMagic[8] = {'R', 'F', 'X', 'R', 'E', 'C', '\r', '\n'};
inline constexpr std::uint32_t kFormatVersion = 1;
inline constexpr std::uint32_t kRecordSync = 0x43455252u;  // "RREC" read as little-endian u32
inline constexpr std::size_t kFileHeaderSize = 16;
inline constexpr std::size_t kRecordHeaderSize = 12;  // sync + length + CRC
/// Upper bound on one record's body; a length above it is treated as corruption, not allocated.
inline constexpr std::uint32_t kMaxBodySize = 64u << 20;

/// One recorded sample.
struct RecordEntry {
  /// When the recorder received it (system clock, ns since epoch). Never negative: a record with a
  /// negative receive time is invalid (corrupt), so the difference of any two receive times of a
  /// file fits an int64 (players and exporters subtract them).
  std::int64_t receive_ns = 0;
  std::int64_t source_ns = 0;         ///< DDS source timestamp of the writer (ns since epoch), 0 if unknown
  std::string topic;                  ///< DDS topic name, e.g. "reflex/control_status"
  std::string type;                   ///< DDS type name, e.g. "reflex::msg::ControlStatus"
  std::vector<std::uint8_t> payload;  ///< serialized sample: encapsulation header + XCDR1 body
};

/// CRC-32 and its combination: the project's one implementation (reflex/common/crc32.hpp).
using common::crc32;
using common::crc32Combine;

/// How the reader's scan of a file ended.
enum class TailState {
  kClean,    ///< the last record ended exactly at the end of the file (MCAP: footer and closing magic read)
  kTorn,     ///< the file ends inside a record (e.g. killed while writing) and no valid record
             ///< follows its start; that record was dropped (MCAP: the file has no footer, i.e. the
             ///< writer did not finish; every complete chunk before the cut was read)
  kCorrupt,  ///< a record with a bad sync word, length or CRC that is NOT at the end (see skipped);
             ///< also one whose length runs past the end of the file while a valid record follows
             ///< (MCAP: a chunk, data section or summary whose CRC does not check)
};

/// A recording being written, whatever its format (.rfx: RecordWriter; .mcap: McapSampleWriter in
/// mcap.hpp; made by createRecording in recording.hpp). Not thread-safe (one writer thread).
class SampleWriter {
 public:
  virtual ~SampleWriter() = default;
  /// Stores one sample. Throws RecordError on I/O failure or a sample the format cannot hold.
  virtual void append(const RecordEntry& entry) = 0;
  /// Applies the time-based part of the durability policy (call it periodically).
  virtual void poll() = 0;
  /// Finishes the file (MCAP: last chunk, summary, footer), fsyncs and closes; later calls do nothing.
  virtual void close() = 0;
  virtual const std::string& path() const = 0;
  /// Bytes handed to the kernel so far.
  virtual std::uint64_t bytesWritten() const = 0;
};

/// A recording being read in file order, whatever its format (openRecording in recording.hpp).
/// Never returns a sample whose CRC does not check.
class SampleReader {
 public:
  virtual ~SampleReader() = default;
  /// Reads the next valid sample into `out`; false at the end (or where reading had to stop).
  virtual bool next(RecordEntry& out) = 0;
  /// Goes back to the first sample (counters reset).
  virtual void rewind() = 0;
  virtual TailState tailState() const = 0;
  /// Byte offset just after the last valid record read.
  virtual std::uint64_t validEnd() const = 0;
  virtual std::uint64_t fileSize() const = 0;
  /// Bytes skipped as corrupt.
  virtual std::uint64_t skippedBytes() const = 0;
  /// The first problem met, with its byte offset ("" if none): "corrupt record at byte 1234".
  virtual std::string problem() const = 0;
  /// "rfx" or "mcap".
  virtual const char* formatName() const = 0;
};

/// Spacing of the CRC prefix values RecordReader keeps while resynchronising (bytes).
inline constexpr std::size_t kCrcMarkStride = 256;

/// Encodes a record (header + body) as it is stored in the file. Throws RecordError if the receive
/// time is negative, the topic or type name is longer than 65535 bytes or the body exceeds
/// kMaxBodySize.
std::vector<std::uint8_t> encodeRecord(const RecordEntry& entry);

struct WriterOptions {
  std::chrono::milliseconds flush_interval{100};  ///< max age of a buffered record before write(2)
  std::size_t flush_bytes = 256 * 1024;           ///< buffer size that triggers write(2)
  std::chrono::milliseconds sync_interval{1000};  ///< fsync(2) period (0: after every flush)
  bool append = false;  ///< false: create/truncate; true: append to an existing valid recording
};

/// Appends records to a recording file. Not thread-safe (one writer thread). The destructor flushes
/// and fsyncs (errors there are swallowed; call close() to see them).
class RecordWriter final : public SampleWriter {
 public:
  /// Creates (or, with options.append, opens and checks the header of) `path`. Throws RecordError
  /// naming the path and the cause: a missing folder or a directory in the file's place (before
  /// anything is written), a FIFO without a reader (never blocks), appending to something that is
  /// not a regular file, the failing system call. Devices (/dev/null) are valid outputs; a write
  /// that fails (/dev/full: ENOSPC) throws from append / flush / close, naming the file.
  RecordWriter(const std::string& path, const WriterOptions& options = {});
  ~RecordWriter();
  RecordWriter(const RecordWriter&) = delete;
  RecordWriter& operator=(const RecordWriter&) = delete;

  /// Buffers one record, then flushes / syncs as the policy says. Throws RecordError on I/O failure.
  void append(const RecordEntry& entry) override;
  /// Applies the time-based part of the policy (call it periodically when no records arrive).
  void poll() override;
  /// Hands the buffer to the kernel (write(2)).
  void flush();
  /// flush() + fsync(2).
  void sync();
  /// sync() and close the file; later calls do nothing.
  void close() override;

  const std::string& path() const override { return path_; }
  std::uint64_t recordsWritten() const { return records_; }
  std::uint64_t bytesWritten() const override { return bytes_; }

 private:
  std::string path_;
  WriterOptions options_;
  int fd_ = -1;
  bool regular_ = true;  ///< false for a device or FIFO output (/dev/null): no fsync there
  std::vector<std::uint8_t> buffer_;
  std::chrono::steady_clock::time_point oldest_buffered_{};
  std::chrono::steady_clock::time_point last_sync_{};
  std::uint64_t records_ = 0, bytes_ = 0;
};

/// Reads a recording sequentially. Never returns a record whose CRC does not check.
class RecordReader final : public SampleReader {
 public:
  /// Opens `path` and checks the file header. Throws RecordError naming the path and what is wrong
  /// (missing, not a regular file -- a FIFO or device is refused before it is opened --, not a
  /// recording, unsupported version).
  explicit RecordReader(const std::string& path);
  ~RecordReader();
  RecordReader(const RecordReader&) = delete;
  RecordReader& operator=(const RecordReader&) = delete;

  /// Reads the next valid record into `out`; false at the end. With resync (the default) a corrupt
  /// record in the middle is skipped by scanning for the next sync word whose record checks
  /// (counted in skippedBytes(), state kCorrupt); without it reading stops there.
  bool next(RecordEntry& out) override;
  /// Goes back to the first record (counters reset).
  void rewind() override;
  void setResync(bool on) { resync_ = on; }

  TailState tailState() const override { return state_; }
  /// Byte offset just after the last valid record read.
  std::uint64_t validEnd() const override { return valid_end_; }
  std::uint64_t fileSize() const override { return size_; }
  std::uint64_t skippedBytes() const override { return skipped_; }
  std::string problem() const override;
  const char* formatName() const override { return "rfx"; }
  /// Offset of the first corrupt record seen (meaningful if tailState() == kCorrupt).
  std::uint64_t firstCorruptOffset() const { return first_corrupt_; }
  const std::string& path() const { return path_; }
  /// Bytes this reader has read from the file so far (every byte it looks at, CRCs included): a
  /// measure of its work that tests and the fuzz target bound by a multiple of the file size.
  std::uint64_t bytesExamined() const { return examined_; }

 private:
  enum class Parse { kOk, kShort, kBad };
  Parse parseAt(std::uint64_t offset, RecordEntry& out, std::uint64_t& record_size);
  bool readAt(std::uint64_t offset, void* dst, std::size_t n);
  /// Is there a complete record at `offset` with a good CRC and consistent inner fields? Reads only
  /// the header, three inner fields and at most 2 * kCrcMarkStride bytes (plus, once per reader, the
  /// file up to the record's end for the CRC marks). kShort: it would run past the end of the file.
  Parse checkAt(std::uint64_t offset);
  /// CRC-32 of the file's bytes [0, x), from the marks.
  bool prefixCrc(std::uint64_t x, std::uint32_t& crc);
  /// The first offset >= `from` holding a valid record (into `at`). Linear in the bytes scanned.
  bool findValid(std::uint64_t from, std::uint64_t& at);

  std::string path_;
  int fd_ = -1;
  std::unique_ptr<std::uint8_t[]> window_;  ///< read cache: direct-mapped 4 KiB blocks (not zeroed)
  std::vector<std::uint64_t> block_index_;  ///< which block each cache slot holds (~0: none)
  std::vector<std::uint32_t> crc_marks_;    ///< crc_marks_[i] = CRC-32 of the file's bytes [0, i * stride)
  std::uint64_t size_ = 0, pos_ = kFileHeaderSize, valid_end_ = kFileHeaderSize;
  std::uint64_t skipped_ = 0, first_corrupt_ = 0, examined_ = 0;
  TailState state_ = TailState::kClean;
  bool resync_ = true;
  std::vector<std::uint8_t> body_;
};

namespace detail {
/// Opens `path` for writing (created with mode 0644, truncated if `truncate`), after
/// common::outputFileProblem; a FIFO without a reader fails at once (ENXIO) instead of blocking.
/// `regular` tells whether it is a regular file (fsync possible). Throws RecordError naming the path.
int openOutputFile(const std::string& path, bool truncate, bool& regular);
/// write(2) of all `size` bytes (EINTR retried). Throws RecordError naming `path` on failure.
void writeAll(int fd, const std::uint8_t* data, std::size_t size, const std::string& path);
/// fsync(2); a device or pipe (EINVAL/EROFS when not `regular`) is not an error. Throws RecordError.
void syncFile(int fd, bool regular, const std::string& path);
}  // namespace detail

/// Human-readable name of a tail state ("clean", "torn last record", "corrupt records skipped").
const char* toString(TailState s);

}  // namespace reflex::record
