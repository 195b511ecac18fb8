#include "reflex/record/record_file.hpp"

#include "reflex/common/files.hpp"

#include <algorithm>
#include <array>
#include <cerrno>
#include <cstring>
#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

namespace reflex::record {

namespace {

void putU16(std::vector<std::uint8_t>& b, std::uint16_t v) {
  for (int i = 0; i < 2; ++i) b.push_back(static_cast<std::uint8_t>(v >> (8 * i)));
}
void putU32(std::vector<std::uint8_t>& b, std::uint32_t v) {
  for (int i = 0; i < 4; ++i) b.push_back(static_cast<std::uint8_t>(v >> (8 * i)));
}
void putI64(std::vector<std::uint8_t>& b, std::int64_t v) {
  const auto u = static_cast<std::uint64_t>(v);
  for (int i = 0; i < 8; ++i) b.push_back(static_cast<std::uint8_t>(u >> (8 * i)));
}
std::uint32_t getU32(const std::uint8_t* p) {
  return static_cast<std::uint32_t>(p[0]) | (static_cast<std::uint32_t>(p[1]) << 8) |
         (static_cast<std::uint32_t>(p[2]) << 16) | (static_cast<std::uint32_t>(p[3]) << 24);
}
std::uint16_t getU16(const std::uint8_t* p) { return static_cast<std::uint16_t>(p[0] | (p[1] << 8)); }
std::int64_t getI64(const std::uint8_t* p) {
  std::uint64_t u = 0;
  for (int i = 7; i >= 0; --i) u = (u << 8) | p[i];
  return static_cast<std::int64_t>(u);
}

std::string sysError(const std::string& what, const std::string& path) {
  return what + " '" + path + "': " + std::strerror(errno);
}

}  // namespace

std::vector<std::uint8_t> encodeRecord(const RecordEntry& e) {
  if (e.receive_ns < 0)
    throw RecordError("sample of topic '" + e.topic + "' has a negative receive time " + std::to_string(e.receive_ns) +
                      " ns (ns since the Unix epoch expected)");
  if (e.topic.size() > 0xFFFF)
    throw RecordError("topic name longer than 65535 bytes: '" + e.topic.substr(0, 64) + "...'");
  if (e.type.size() > 0xFFFF) throw RecordError("type name longer than 65535 bytes: '" + e.type.substr(0, 64) + "...'");
  const std::size_t body_size = 8 + 8 + 2 + e.topic.size() + 2 + e.type.size() + 4 + e.payload.size();
  if (body_size > kMaxBodySize)
    throw RecordError("sample of topic '" + e.topic + "' is " + std::to_string(body_size) + " bytes, above the " +
                      std::to_string(kMaxBodySize) + "-byte record limit");
  std::vector<std::uint8_t> out;
  out.reserve(kRecordHeaderSize + body_size);
  putU32(out, kRecordSync);
  putU32(out, static_cast<std::uint32_t>(body_size));
  putU32(out, 0);  // CRC, filled below
  putI64(out, e.receive_ns);
  putI64(out, e.source_ns);
  putU16(out, static_cast<std::uint16_t>(e.topic.size()));
  out.insert(out.end(), e.topic.begin(), e.topic.end());
  putU16(out, static_cast<std::uint16_t>(e.type.size()));
  out.insert(out.end(), e.type.begin(), e.type.end());
  putU32(out, static_cast<std::uint32_t>(e.payload.size()));
  out.insert(out.end(), e.payload.begin(), e.payload.end());
  const std::uint32_t crc = crc32(out.data() + kRecordHeaderSize, body_size);
  for (int i = 0; i < 4; ++i) out[8 + i] = static_cast<std::uint8_t>(crc >> (8 * i));
  return out;
}

// ---------------------------------------------------------------------------------------------
// Output file helpers (RecordWriter, McapWriter)

int detail::openOutputFile(const std::string& path, bool truncate, bool& regular) {
  // O_NONBLOCK for the open only: a FIFO without a reader is an error at once (ENXIO), not a hang.
  const int flags = O_WRONLY | O_CREAT | O_CLOEXEC | O_NONBLOCK | (truncate ? O_TRUNC : 0);
  const int fd = ::open(path.c_str(), flags, 0644);
  if (fd < 0) throw RecordError(sysError("cannot open recording", path));
  struct stat st {};
  regular = ::fstat(fd, &st) == 0 && S_ISREG(st.st_mode);
  if (::fcntl(fd, F_SETFL, ::fcntl(fd, F_GETFL) & ~O_NONBLOCK) != 0) {
    const std::string msg = sysError("cannot set up recording", path);
    ::close(fd);
    throw RecordError(msg);
  }
  return fd;
}

void detail::writeAll(int fd, const std::uint8_t* data, std::size_t size, const std::string& path) {
  std::size_t done = 0;
  while (done < size) {
    const ssize_t n = ::write(fd, data + done, size - done);
    if (n < 0) {
      if (errno == EINTR) continue;
      throw RecordError(sysError("cannot write recording", path));
    }
    done += static_cast<std::size_t>(n);
  }
}

void detail::syncFile(int fd, bool regular, const std::string& path) {
  // A device or pipe (/dev/null, a FIFO) cannot be synchronised (EINVAL): nothing is lost there.
  if (::fsync(fd) != 0 && (regular || (errno != EINVAL && errno != EROFS)))
    throw RecordError(sysError("cannot fsync recording", path));
}

// ---------------------------------------------------------------------------------------------
// RecordWriter

RecordWriter::RecordWriter(const std::string& path, const WriterOptions& options) : path_(path), options_(options) {
  if (options.flush_interval.count() < 0 || options.sync_interval.count() < 0)
    throw RecordError("flush/sync intervals must not be negative (recording '" + path + "')");
  std::uint64_t keep = 0;
  bool existing = false;
  // At start, not at the end of a recording: a missing folder, a folder in the file's place, ...
  if (const std::string why = common::outputFileProblem(path); !why.empty()) throw RecordError("recording: " + why);
  if (options.append) {
    struct stat st {};
    if (::stat(path.c_str(), &st) == 0 && !S_ISREG(st.st_mode))
      throw RecordError("cannot append to recording '" + path + "': it is " + common::fileKind(st.st_mode) +
                        ", not a regular file");
    if (::stat(path.c_str(), &st) == 0 && st.st_size > 0) {
      RecordReader check(path);  // throws if it is not a recording
      check.setResync(false);
      RecordEntry scratch;
      while (check.next(scratch)) {
      }
      if (check.tailState() == TailState::kCorrupt)
        throw RecordError("cannot append to '" + path + "': corrupt record at byte " +
                          std::to_string(check.firstCorruptOffset()));
      keep = check.validEnd();  // a torn last record is cut off before appending
      existing = true;
    }
  }
  fd_ = detail::openOutputFile(path, !existing, regular_);
  if (existing) {
    if (::ftruncate(fd_, static_cast<off_t>(keep)) != 0 || ::lseek(fd_, static_cast<off_t>(keep), SEEK_SET) < 0) {
      const std::string msg = sysError("cannot position at the end of recording", path);
      ::close(fd_);
      fd_ = -1;
      throw RecordError(msg);
    }
  } else {
    std::vector<std::uint8_t> header(kFileMagic, kFileMagic + 8);
    putU32(header, kFormatVersion);
    putU32(header, 0);
    buffer_ = std::move(header);
    flush();
  }
  buffer_.reserve(options_.flush_bytes + 4096);
  last_sync_ = std::chrono::steady_clock::now();
}

RecordWriter::~RecordWriter() {
  try {
    close();
  } catch (const RecordError&) {
    // Destructors must not throw; close() reports errors to callers who want them.
  }
}

void RecordWriter::append(const RecordEntry& entry) {
  if (fd_ < 0) throw RecordError("recording '" + path_ + "' is closed");
  const std::vector<std::uint8_t> rec = encodeRecord(entry);
  if (buffer_.empty()) oldest_buffered_ = std::chrono::steady_clock::now();
  buffer_.insert(buffer_.end(), rec.begin(), rec.end());
  ++records_;
  if (buffer_.size() >= options_.flush_bytes) flush();
  poll();
}

void RecordWriter::poll() {
  if (fd_ < 0) return;
  const auto now = std::chrono::steady_clock::now();
  if (!buffer_.empty() && now - oldest_buffered_ >= options_.flush_interval) flush();
  if (now - last_sync_ >= options_.sync_interval) sync();
}

void RecordWriter::flush() {
  detail::writeAll(fd_, buffer_.data(), buffer_.size(), path_);
  bytes_ += buffer_.size();
  buffer_.clear();
}

void RecordWriter::sync() {
  if (fd_ < 0) return;
  flush();
  detail::syncFile(fd_, regular_, path_);
  last_sync_ = std::chrono::steady_clock::now();
}

void RecordWriter::close() {
  if (fd_ < 0) return;
  const int fd = fd_;
  try {
    sync();
  } catch (...) {
    ::close(fd);
    fd_ = -1;
    throw;
  }
  fd_ = -1;
  if (::close(fd) != 0) throw RecordError(sysError("cannot close recording", path_));
}

// ---------------------------------------------------------------------------------------------
// RecordReader

namespace {

using common::preadAll;

constexpr std::size_t kBlock = 4096;  // read cache: direct-mapped blocks of the file
constexpr std::size_t kCacheBlocks = 64;
constexpr std::size_t kDirectRead = 4 * kBlock;  // larger reads bypass the cache
/// A body longer than this is checked (checkAt: inner lengths, then the CRC from the marks, about
/// 2 x kCrcMarkStride bytes of work) before it is read, so that a damaged header costs at most this
/// many bytes of reading, whatever body it claims: at 64 KiB a damaged header after every 50-byte
/// record made reading 1,000 x slower than a valid file of the same size. Bodies up to 1 KiB (most
/// Reflex samples) are read at once, as checking first would cost about as much as reading.
constexpr std::uint32_t kCheckBeforeReading = 1024;

}  // namespace

RecordReader::RecordReader(const std::string& path) : path_(path) {
  // Before any open: a FIFO blocks open(2) and read(2) until a writer appears; a device never ends.
  if (const std::string why = common::inputFileProblem(path); !why.empty()) throw RecordError("recording " + why);
  fd_ = ::open(path.c_str(), O_RDONLY | O_CLOEXEC | O_NONBLOCK);
  if (fd_ < 0) throw RecordError(sysError("cannot open recording", path));
  struct stat st {};
  if (::fstat(fd_, &st) != 0) {
    const std::string msg = sysError("cannot stat recording", path);
    ::close(fd_);
    throw RecordError(msg);
  }
  if (!S_ISREG(st.st_mode)) {  // replaced between the check and the open
    ::close(fd_);
    throw RecordError("recording '" + path + "' is " + common::fileKind(st.st_mode) + ", not a regular file");
  }
  size_ = static_cast<std::uint64_t>(st.st_size);
  window_.reset(new std::uint8_t[kCacheBlocks * kBlock]);  // filled block by block before any use
  block_index_.assign(kCacheBlocks, ~std::uint64_t{0});
  crc_marks_.assign(1, 0u);  // the CRC of no bytes
  std::uint8_t header[kFileHeaderSize];
  if (size_ < kFileHeaderSize || !readAt(0, header, kFileHeaderSize) || std::memcmp(header, kFileMagic, 8) != 0) {
    ::close(fd_);
    throw RecordError("'" + path + "' is not a Reflex recording (neither an MCAP file nor an RFXREC log)");
  }
  const std::uint32_t version = getU32(header + 8);
  if (version != kFormatVersion) {
    ::close(fd_);
    throw RecordError("recording '" + path + "' has format version " + std::to_string(version) +
                      "; this tool reads version " + std::to_string(kFormatVersion));
  }
}

RecordReader::~RecordReader() {
  if (fd_ >= 0) ::close(fd_);
}

bool RecordReader::readAt(std::uint64_t offset, void* dst, std::size_t n) {
  if (offset > size_ || n > size_ - offset) return false;
  examined_ += n;
  if (n >= kDirectRead) return preadAll(fd_, offset, dst, n);
  auto* out = static_cast<std::uint8_t*>(dst);
  while (n > 0) {
    const std::uint64_t index = offset / kBlock;
    const std::size_t slot = static_cast<std::size_t>(index % kCacheBlocks);
    std::uint8_t* block = window_.get() + slot * kBlock;
    if (block_index_[slot] != index) {
      const std::uint64_t start = index * kBlock;
      const std::size_t len = static_cast<std::size_t>(std::min<std::uint64_t>(kBlock, size_ - start));
      block_index_[slot] = ~std::uint64_t{0};
      if (!preadAll(fd_, start, block, len)) return false;
      block_index_[slot] = index;
    }
    const std::size_t in_block = static_cast<std::size_t>(offset - index * kBlock);
    const std::size_t take = std::min(n, kBlock - in_block);
    std::memcpy(out, block + in_block, take);
    out += take;
    offset += take;
    n -= take;
  }
  return true;
}

bool RecordReader::prefixCrc(std::uint64_t x, std::uint32_t& crc) {
  if (x > size_) return false;
  const std::uint64_t mark = x / kCrcMarkStride;
  std::uint8_t buf[kCrcMarkStride];
  while (crc_marks_.size() <= mark) {  // extend the marks (each byte of the file is read once for them)
    const std::uint64_t j = crc_marks_.size() - 1;
    if (!readAt(j * kCrcMarkStride, buf, kCrcMarkStride)) return false;
    crc_marks_.push_back(crc32(buf, kCrcMarkStride, crc_marks_[j]));
  }
  const std::size_t rest = static_cast<std::size_t>(x - mark * kCrcMarkStride);
  if (!readAt(mark * kCrcMarkStride, buf, rest)) return false;
  crc = crc32(buf, rest, crc_marks_[mark]);
  return true;
}

RecordReader::Parse RecordReader::checkAt(std::uint64_t offset) {
  std::uint8_t head[kRecordHeaderSize];
  if (offset + kRecordHeaderSize > size_ || !readAt(offset, head, kRecordHeaderSize)) return Parse::kShort;
  if (getU32(head) != kRecordSync) return Parse::kBad;
  const std::uint32_t len = getU32(head + 4);
  if (len < 8 + 8 + 2 + 2 + 4 || len > kMaxBodySize) return Parse::kBad;
  if (offset + kRecordHeaderSize + len > size_) return Parse::kShort;
  const std::uint64_t body = offset + kRecordHeaderSize;
  // The inner fields, as parseAt checks them (O(1) reads).
  std::uint8_t b[8];
  if (!readAt(body, b, 8)) return Parse::kShort;
  if (getI64(b) < 0) return Parse::kBad;
  if (!readAt(body + 16, b, 2)) return Parse::kShort;
  const std::uint64_t topic_len = getU16(b);
  if (len - 18 < topic_len + 2) return Parse::kBad;
  if (!readAt(body + 18 + topic_len, b, 2)) return Parse::kShort;
  const std::uint64_t type_len = getU16(b);
  if (len - 20 - topic_len < type_len + 4) return Parse::kBad;
  if (!readAt(body + 20 + topic_len + type_len, b, 4)) return Parse::kShort;
  if (getU32(b) != len - 24 - topic_len - type_len) return Parse::kBad;
  // CRC of the body from two prefix CRCs: crc(body) = C(end) ^ (C(body) shifted by len bytes).
  std::uint32_t c_body = 0, c_end = 0;
  if (!prefixCrc(body, c_body) || !prefixCrc(body + len, c_end)) return Parse::kShort;
  if ((c_end ^ crc32Combine(c_body, 0, len)) != getU32(head + 8)) return Parse::kBad;
  return Parse::kOk;
}

RecordReader::Parse RecordReader::parseAt(std::uint64_t offset, RecordEntry& out, std::uint64_t& record_size) {
  std::uint8_t head[kRecordHeaderSize];
  if (offset + kRecordHeaderSize > size_) return Parse::kShort;
  if (!readAt(offset, head, kRecordHeaderSize)) return Parse::kShort;
  if (getU32(head) != kRecordSync) return Parse::kBad;
  const std::uint32_t len = getU32(head + 4);
  const std::uint32_t crc = getU32(head + 8);
  if (len < 8 + 8 + 2 + 2 + 4 || len > kMaxBodySize) return Parse::kBad;
  if (offset + kRecordHeaderSize + len > size_) return Parse::kShort;
  if (len > kCheckBeforeReading) {
    const Parse checked = checkAt(offset);
    if (checked != Parse::kOk) return checked;
  }
  body_.resize(len);
  if (!readAt(offset + kRecordHeaderSize, body_.data(), len)) return Parse::kShort;
  if (crc32(body_.data(), len) != crc) return Parse::kBad;
  // The CRC checks, so the inner lengths were written by encodeRecord; still verify them.
  const std::uint8_t* p = body_.data();
  const std::uint8_t* end = p + len;
  out.receive_ns = getI64(p);
  if (out.receive_ns < 0) return Parse::kBad;  // never written by encodeRecord (see RecordEntry)
  out.source_ns = getI64(p + 8);
  p += 16;
  const std::uint16_t topic_len = getU16(p);
  p += 2;
  if (end - p < topic_len + 2) return Parse::kBad;
  out.topic.assign(reinterpret_cast<const char*>(p), topic_len);
  p += topic_len;
  const std::uint16_t type_len = getU16(p);
  p += 2;
  if (end - p < type_len + 4) return Parse::kBad;
  out.type.assign(reinterpret_cast<const char*>(p), type_len);
  p += type_len;
  const std::uint32_t payload_len = getU32(p);
  p += 4;
  if (static_cast<std::uint64_t>(end - p) != payload_len) return Parse::kBad;
  out.payload.assign(p, end);
  record_size = kRecordHeaderSize + len;
  return Parse::kOk;
}

bool RecordReader::findValid(std::uint64_t from, std::uint64_t& at) {
  std::uint8_t b4[4];
  for (std::uint64_t scan = from; scan + kRecordHeaderSize <= size_; ++scan) {
    if (!readAt(scan, b4, 4) || getU32(b4) != kRecordSync) continue;
    if (checkAt(scan) == Parse::kOk) {
      at = scan;
      return true;
    }
  }
  return false;
}

bool RecordReader::next(RecordEntry& out) {
  while (pos_ < size_) {
    std::uint64_t record_size = 0;
    const Parse r = parseAt(pos_, out, record_size);
    if (r == Parse::kOk) {
      pos_ += record_size;
      valid_end_ = pos_;
      return true;
    }
    // A record that runs past the end of the file is a torn last write (kill -9, power loss) only
    // if no valid record follows it. If one does, its length field is damaged: corruption in the
    // middle, not the end (calling it torn would drop every later record, and --append would cut
    // them off).
    const bool maybe_torn = r == Parse::kShort && state_ != TailState::kCorrupt;
    std::uint64_t next_valid = size_;
    const bool later = (maybe_torn || resync_) && findValid(pos_ + 1, next_valid);
    if (maybe_torn && !later) {
      state_ = TailState::kTorn;
      return false;
    }
    if (state_ != TailState::kCorrupt) first_corrupt_ = pos_;
    state_ = TailState::kCorrupt;
    if (!resync_) return false;
    // Skip to the next sync word whose record checks (or to the end).
    skipped_ += next_valid - pos_;
    pos_ = next_valid;
  }
  return false;
}

void RecordReader::rewind() {
  pos_ = valid_end_ = kFileHeaderSize;
  skipped_ = first_corrupt_ = 0;
  state_ = TailState::kClean;
}

std::string RecordReader::problem() const {
  if (state_ == TailState::kCorrupt) return "corrupt record at byte " + std::to_string(first_corrupt_);
  if (state_ == TailState::kTorn) return "torn last record at byte " + std::to_string(valid_end_);
  return "";
}

const char* toString(TailState s) {
  switch (s) {
    case TailState::kClean: return "clean";
    case TailState::kTorn: return "torn last record (dropped)";
    case TailState::kCorrupt: return "corrupt records skipped";
  }
  return "?";
}

}  // namespace reflex::record
