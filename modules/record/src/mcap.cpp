#include "reflex/record/mcap.hpp"

#include "idl_schemas.hpp"
#include "reflex/common/files.hpp"

#include <lz4frame.h>
#include <zstd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <functional>
#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

namespace reflex::record {

namespace {

enum Op : std::uint8_t {
  kHeader = 0x01,
  kFooter = 0x02,
  kSchema = 0x03,
  kChannel = 0x04,
  kMessage = 0x05,
  kChunk = 0x06,
  kMessageIndex = 0x07,
  kChunkIndex = 0x08,
  kStatistics = 0x0B,
  kSummaryOffset = 0x0E,
  kDataEnd = 0x0F,
};
constexpr std::size_t kRecordPrefix = 1 + 8;             // opcode + content length
constexpr std::size_t kFooterSize = kRecordPrefix + 20;  // summary_start, summary_offset_start, crc
/// Largest record or uncompressed chunk the reader accepts: a bigger length is corruption, not allocated.
/// (The writer's --chunk-size goes up to 1 GiB too.)
constexpr std::uint64_t kMaxRecord = 1ull << 30;
/// Largest uncompressed / compressed size ratio a compressed chunk may declare. Reflex chunks compress
/// 3-20 x (timestamps and doubles); zstd reaches ~30,000 x on zeros only, which is what a bomb holds.
constexpr std::uint64_t kMaxChunkRatio = 1000;

// ---- little-endian serialisation -----------------------------------------------------------------

class Out {
 public:
  explicit Out(std::vector<std::uint8_t>& b) : b_(b) {}
  void u8(std::uint8_t v) { b_.push_back(v); }
  void u16(std::uint16_t v) { le(v, 2); }
  void u32(std::uint32_t v) { le(v, 4); }
  void u64(std::uint64_t v) { le(v, 8); }
  void str(const std::string& s) {
    u32(static_cast<std::uint32_t>(s.size()));
    b_.insert(b_.end(), s.begin(), s.end());
  }
  void bytes(const void* p, std::size_t n) {
    const auto* c = static_cast<const std::uint8_t*>(p);
    b_.insert(b_.end(), c, c + n);
  }
  /// Starts a record: opcode and a length placeholder; end(at) fills the length in.
  std::size_t begin(std::uint8_t op) {
    u8(op);
    const std::size_t at = b_.size();
    u64(0);
    return at;
  }
  void end(std::size_t at) {
    const std::uint64_t len = b_.size() - at - 8;
    for (int i = 0; i < 8; ++i) b_[at + i] = static_cast<std::uint8_t>(len >> (8 * i));
  }
  std::size_t size() const { return b_.size(); }

 private:
  void le(std::uint64_t v, int n) {
    for (int i = 0; i < n; ++i) b_.push_back(static_cast<std::uint8_t>(v >> (8 * i)));
  }
  std::vector<std::uint8_t>& b_;
};

/// Bounds-checked little-endian reading of one record's content; ok() turns false on any overrun.
class In {
 public:
  In(const std::uint8_t* p, std::uint64_t n) : p_(p), n_(n) {}
  std::uint64_t uint(int bytes) {
    if (!take(static_cast<std::uint64_t>(bytes))) return 0;
    std::uint64_t v = 0;
    for (int i = bytes - 1; i >= 0; --i)
      v = (v << 8) | p_[at_ - static_cast<std::uint64_t>(bytes) + static_cast<std::uint64_t>(i)];
    return v;
  }
  std::string str() {
    const std::uint64_t len = uint(4);
    if (!take(len)) return {};
    return std::string(reinterpret_cast<const char*>(p_ + at_ - len), len);
  }
  std::map<std::string, std::string> strMap() {
    std::map<std::string, std::string> m;
    const std::uint64_t len = uint(4);
    const std::uint64_t end = at_ + len;
    if (len > n_ - std::min(n_, at_)) {
      ok_ = false;
      return m;
    }
    while (ok_ && at_ < end) {
      std::string k = str();
      m[k] = str();
    }
    if (at_ != end) ok_ = false;
    return m;
  }
  const std::uint8_t* here() const { return p_ + at_; }
  std::uint64_t left() const { return n_ - at_; }
  bool take(std::uint64_t len) {
    if (!ok_ || len > n_ - at_) return ok_ = false;
    at_ += len;
    return true;
  }
  bool ok() const { return ok_; }

 private:
  const std::uint8_t* p_;
  std::uint64_t n_, at_ = 0;
  bool ok_ = true;
};

std::string hex(std::uint32_t v) {
  char buf[16];
  std::snprintf(buf, sizeof(buf), "0x%08x", v);
  return buf;
}

std::vector<std::uint8_t> compress(McapCompression c, const std::vector<std::uint8_t>& in) {
  std::vector<std::uint8_t> out;
  if (c == McapCompression::kZstd) {
    out.resize(ZSTD_compressBound(in.size()));
    const std::size_t n = ZSTD_compress(out.data(), out.size(), in.data(), in.size(), 3);
    if (ZSTD_isError(n)) throw RecordError(std::string("zstd compression failed: ") + ZSTD_getErrorName(n));
    out.resize(n);
  } else if (c == McapCompression::kLz4) {
    LZ4F_preferences_t prefs{};
    prefs.frameInfo.contentSize = in.size();
    out.resize(LZ4F_compressFrameBound(in.size(), &prefs));
    const std::size_t n = LZ4F_compressFrame(out.data(), out.size(), in.data(), in.size(), &prefs);
    if (LZ4F_isError(n)) throw RecordError(std::string("lz4 compression failed: ") + LZ4F_getErrorName(n));
    out.resize(n);
  }
  return out;
}

/// Decompresses a chunk's records into `out` (exactly `size` bytes); "" on success, else the reason.
/// Memory is budgeted against the bytes present, never taken from the declared size alone: an
/// uncompressed chunk must hold exactly `size` bytes; a compressed one may declare at most
/// kMaxChunkRatio times its compressed bytes (and kMaxRecord), and `out` grows only as the decoder
/// actually produces bytes, stopping with an error at the first byte beyond the declared size. A
/// 600-byte file declaring a 1 GiB chunk, or a 265 KB zstd bomb that really expands to 1 GiB, is
/// refused before any large allocation.
std::string decompress(const std::string& compression, const std::uint8_t* in, std::size_t n, std::uint64_t size,
                       std::vector<std::uint8_t>& out) {
  out.clear();
  if (compression.empty()) {
    if (n != size) return "uncompressed chunk of " + std::to_string(n) + " bytes claims " + std::to_string(size);
    out.assign(in, in + n);
    return "";
  }
  if (compression != "zstd" && compression != "lz4") return "unknown compression '" + compression + "'";
  if (size > kMaxRecord)
    return "uncompressed size " + std::to_string(size) + " is above the " + std::to_string(kMaxRecord) + "-byte cap";
  if (size > kMaxChunkRatio * n)
    return "uncompressed size " + std::to_string(size) + " claimed for " + std::to_string(n) +
           " compressed bytes (more than " + std::to_string(kMaxChunkRatio) + " x)";
  // One decoder step: reads from src (advancing src_pos), writes into dst (advancing dst_pos);
  // returns false with `why` set on a decoder error; `ended` turns true when the last frame is complete.
  std::string why;
  bool ended = false;
  std::function<bool(std::uint8_t*, std::size_t, std::size_t&, std::size_t&)> step;
  ZSTD_DCtx* zctx = nullptr;
  LZ4F_dctx* lctx = nullptr;
  if (compression == "zstd") {
    zctx = ZSTD_createDCtx();
    if (!zctx) return "zstd: no decompression context";
    step = [&](std::uint8_t* dst, std::size_t cap, std::size_t& dst_pos, std::size_t& src_pos) {
      ZSTD_outBuffer o{dst, cap, dst_pos};
      ZSTD_inBuffer i{in, n, src_pos};
      const std::size_t r = ZSTD_decompressStream(zctx, &o, &i);
      if (ZSTD_isError(r)) {
        why = std::string("zstd: ") + ZSTD_getErrorName(r);
        return false;
      }
      dst_pos = o.pos;
      src_pos = i.pos;
      ended = r == 0;  // a frame completely decoded and flushed (another may follow in the input)
      return true;
    };
  } else {
    if (LZ4F_isError(LZ4F_createDecompressionContext(&lctx, LZ4F_VERSION))) return "lz4: no decompression context";
    step = [&](std::uint8_t* dst, std::size_t cap, std::size_t& dst_pos, std::size_t& src_pos) {
      std::size_t d = cap - dst_pos, s = n - src_pos;
      const std::size_t r = LZ4F_decompress(lctx, dst + dst_pos, &d, in + src_pos, &s, nullptr);
      if (LZ4F_isError(r)) {
        why = std::string("lz4: ") + LZ4F_getErrorName(r);
        return false;
      }
      dst_pos += d;
      src_pos += s;
      ended = r == 0;
      return true;
    };
  }
  constexpr std::size_t kFirstGrowth = 1u << 20;
  std::size_t done = 0, src_pos = 0;
  while (why.empty() && (src_pos < n || !ended)) {
    const std::size_t before_src = src_pos, before_dst = done;
    if (done == out.size() && out.size() < size)  // grow with what was produced: at most twice it
      out.resize(static_cast<std::size_t>(std::min<std::uint64_t>(size, std::max(kFirstGrowth, 2 * out.size()))));
    if (done < out.size()) {
      if (!step(out.data(), out.size(), done, src_pos)) break;
    } else {  // the declared size is reached: the frame must end without another byte
      std::uint8_t extra = 0;
      std::size_t probe = 0;
      if (!step(&extra, 1, probe, src_pos)) break;
      if (probe != 0) why = compression + " chunk gives more than the declared " + std::to_string(size) + " bytes";
    }
    if (why.empty() && src_pos == before_src && done == before_dst)
      why = compression + ": the compressed data ends inside a frame";
  }
  if (zctx) ZSTD_freeDCtx(zctx);
  if (lctx) LZ4F_freeDecompressionContext(lctx);
  if (why.empty() && done != size)
    why = compression + " chunk gave " + std::to_string(done) + " bytes, not " + std::to_string(size);
  return why;
}

}  // namespace

McapCompression parseMcapCompression(const std::string& text) {
  if (text == "none") return McapCompression::kNone;
  if (text == "zstd") return McapCompression::kZstd;
  if (text == "lz4") return McapCompression::kLz4;
  throw RecordError("unknown MCAP compression '" + text + "' (none, zstd or lz4)");
}

const char* mcapCompressionName(McapCompression c) {
  switch (c) {
    case McapCompression::kNone: return "";
    case McapCompression::kZstd: return "zstd";
    case McapCompression::kLz4: return "lz4";
  }
  return "";
}

// ---------------------------------------------------------------------------------------------
// McapWriter

McapWriter::McapWriter(const std::string& path, const McapWriterOptions& options) : path_(path), options_(options) {
  if (options.chunk_bytes == 0) throw RecordError("MCAP chunk size must be > 0 bytes (recording '" + path + "')");
  if (options.chunk_interval.count() <= 0 || options.sync_interval.count() < 0)
    throw RecordError("MCAP chunk interval must be > 0 and sync interval >= 0 ms (recording '" + path + "')");
  if (const std::string why = common::outputFileProblem(path); !why.empty()) throw RecordError("recording: " + why);
  fd_ = detail::openOutputFile(path, true, regular_);
  std::vector<std::uint8_t> head(kMcapMagic, kMcapMagic + 8);
  Out o(head);
  const std::size_t at = o.begin(kHeader);
  o.str(options.profile);
  o.str(options.library);
  o.end(at);
  try {
    emit(head);
  } catch (...) {
    ::close(fd_);
    fd_ = -1;
    throw;
  }
  last_sync_ = std::chrono::steady_clock::now();
}

McapWriter::~McapWriter() {
  try {
    close();
  } catch (const RecordError&) {
    // Destructors must not throw; close() reports errors to callers who want them.
  }
}

void McapWriter::emit(const std::vector<std::uint8_t>& bytes) {
  detail::writeAll(fd_, bytes.data(), bytes.size(), path_);
  data_crc_ = crc32(bytes.data(), bytes.size(), data_crc_);
  offset_ += bytes.size();
}

std::uint16_t McapWriter::addChannel(const McapChannelSpec& spec) {
  if (fd_ < 0) throw RecordError("MCAP recording '" + path_ + "' is closed");
  if (channels_.size() >= 0xFFFF) throw RecordError("MCAP recording '" + path_ + "': more than 65535 channels");
  std::uint16_t schema_id = 0;
  for (const Schema& s : schemas_)
    if (s.name == spec.schema_name && s.encoding == spec.schema_encoding && s.data == spec.schema_data)
      schema_id = s.id;
  if (schema_id == 0 && !(spec.schema_name.empty() && spec.schema_encoding.empty() && spec.schema_data.empty())) {
    if (schemas_.size() >= 0xFFFE) throw RecordError("MCAP recording '" + path_ + "': more than 65534 schemas");
    schema_id = static_cast<std::uint16_t>(schemas_.size() + 1);
    schemas_.push_back({schema_id, spec.schema_name, spec.schema_encoding, spec.schema_data});
  }
  const auto id = static_cast<std::uint16_t>(channels_.size() + 1);
  channels_.push_back({id, schema_id, spec, false, 0});
  return id;
}

namespace {
void putSchema(Out& o, std::uint16_t id, const std::string& name, const std::string& encoding,
               const std::string& data) {
  const std::size_t at = o.begin(kSchema);
  o.u16(id);
  o.str(name);
  o.str(encoding);
  o.str(data);
  o.end(at);
}
void putChannel(Out& o, std::uint16_t id, std::uint16_t schema_id, const McapChannelSpec& spec) {
  const std::size_t at = o.begin(kChannel);
  o.u16(id);
  o.u16(schema_id);
  o.str(spec.topic);
  o.str(spec.message_encoding);
  std::vector<std::uint8_t> map;
  Out m(map);
  for (const auto& kv : spec.metadata) {
    m.str(kv.first);
    m.str(kv.second);
  }
  o.u32(static_cast<std::uint32_t>(map.size()));
  o.bytes(map.data(), map.size());
  o.end(at);
}
}  // namespace

void McapWriter::write(std::uint16_t channel, std::uint32_t sequence, std::uint64_t log_time,
                       std::uint64_t publish_time, const std::uint8_t* data, std::size_t size) {
  if (fd_ < 0) throw RecordError("MCAP recording '" + path_ + "' is closed");
  if (channel == 0 || channel > channels_.size())
    throw RecordError("MCAP recording '" + path_ + "': no channel " + std::to_string(channel));
  Channel& ch = channels_[channel - 1];
  if (chunk_.empty()) chunk_opened_ = std::chrono::steady_clock::now();
  if (!ch.in_file) {  // its schema and channel go into the data section just before this chunk
    Out defs(definitions_);
    if (ch.schema_id != 0 && !schemas_[ch.schema_id - 1].in_file) {
      const Schema& s = schemas_[ch.schema_id - 1];
      putSchema(defs, s.id, s.name, s.encoding, s.data);
      schemas_[ch.schema_id - 1].in_file = true;
    }
    putChannel(defs, ch.id, ch.schema_id, ch.spec);
    ch.in_file = true;
  }
  Out o(chunk_);
  Out index(chunk_message_index_[channel]);
  index.u64(log_time);
  index.u64(chunk_.size());
  const std::size_t at = o.begin(kMessage);
  o.u16(channel);
  o.u32(sequence);
  o.u64(log_time);
  o.u64(publish_time);
  o.bytes(data, size);
  o.end(at);
  if (!chunk_has_messages_ || log_time < chunk_start_) chunk_start_ = log_time;
  if (!chunk_has_messages_ || log_time > chunk_end_) chunk_end_ = log_time;
  if (message_count_ == 0 || log_time < start_time_) start_time_ = log_time;
  if (message_count_ == 0 || log_time > end_time_) end_time_ = log_time;
  chunk_has_messages_ = true;
  ++message_count_;
  ++ch.messages;
  if (chunk_.size() >= options_.chunk_bytes) flushChunk();
}

void McapWriter::poll() {
  if (fd_ < 0) return;
  const auto now = std::chrono::steady_clock::now();
  if (!chunk_.empty() && now - chunk_opened_ >= options_.chunk_interval) flushChunk();
  if (now - last_sync_ >= options_.sync_interval) sync();
}

void McapWriter::sync() {
  detail::syncFile(fd_, regular_, path_);
  last_sync_ = std::chrono::steady_clock::now();
}

void McapWriter::flushChunk() {
  if (fd_ < 0 || chunk_.empty()) return;
  const std::vector<std::uint8_t> packed = compress(options_.compression, chunk_);
  const std::vector<std::uint8_t>& records = options_.compression == McapCompression::kNone ? chunk_ : packed;
  std::vector<std::uint8_t> out = std::move(definitions_);  // Schema and Channel records first
  definitions_.clear();
  out.reserve(out.size() + records.size() + 128 + 32 * chunk_message_index_.size());
  Out o(out);
  ChunkIndex ci{};
  ci.start_time = chunk_has_messages_ ? chunk_start_ : 0;
  ci.end_time = chunk_has_messages_ ? chunk_end_ : 0;
  ci.offset = offset_ + out.size();
  ci.compressed = records.size();
  ci.uncompressed = chunk_.size();
  const std::size_t at = o.begin(kChunk);
  o.u64(ci.start_time);
  o.u64(ci.end_time);
  o.u64(chunk_.size());
  o.u32(crc32(chunk_.data(), chunk_.size()));
  o.str(mcapCompressionName(options_.compression));
  o.u64(records.size());
  o.bytes(records.data(), records.size());
  o.end(at);
  ci.length = offset_ + out.size() - ci.offset;
  for (const auto& kv : chunk_message_index_) {  // one MessageIndex per channel of the chunk
    ci.index_offsets[kv.first] = offset_ + out.size();
    const std::size_t mi = o.begin(kMessageIndex);
    o.u16(kv.first);
    o.u32(static_cast<std::uint32_t>(kv.second.size()));
    o.bytes(kv.second.data(), kv.second.size());
    o.end(mi);
  }
  ci.index_length = offset_ + out.size() - ci.offset - ci.length;
  emit(out);
  chunk_indexes_.push_back(std::move(ci));
  chunk_.clear();
  chunk_message_index_.clear();
  chunk_has_messages_ = false;
  if (options_.sync_interval.count() == 0) sync();
}

void McapWriter::close() {
  if (fd_ < 0) return;
  const int fd = fd_;
  try {
    flushChunk();
    std::vector<std::uint8_t> out;
    Out o(out);
    std::size_t at = o.begin(kDataEnd);
    o.u32(data_crc_);
    o.end(at);
    const std::uint64_t summary_start = offset_ + out.size();
    struct Group {
      std::uint8_t op;
      std::uint64_t start, length;
    };
    std::vector<Group> groups;
    const auto group = [&](std::uint8_t op, std::size_t begin) {
      if (o.size() > begin) groups.push_back({op, offset_ + begin, o.size() - begin});
    };
    std::size_t begin = o.size();
    for (const Schema& s : schemas_) putSchema(o, s.id, s.name, s.encoding, s.data);
    group(kSchema, begin);
    begin = o.size();
    for (const Channel& c : channels_) putChannel(o, c.id, c.schema_id, c.spec);
    group(kChannel, begin);
    begin = o.size();
    at = o.begin(kStatistics);
    o.u64(message_count_);
    o.u16(static_cast<std::uint16_t>(schemas_.size()));
    o.u32(static_cast<std::uint32_t>(channels_.size()));
    o.u32(0);  // attachments
    o.u32(0);  // metadata
    o.u32(static_cast<std::uint32_t>(chunk_indexes_.size()));
    o.u64(message_count_ ? start_time_ : 0);
    o.u64(message_count_ ? end_time_ : 0);
    std::vector<std::uint8_t> counts;
    Out c(counts);
    for (const Channel& ch : channels_) {
      c.u16(ch.id);
      c.u64(ch.messages);
    }
    o.u32(static_cast<std::uint32_t>(counts.size()));
    o.bytes(counts.data(), counts.size());
    o.end(at);
    group(kStatistics, begin);
    begin = o.size();
    for (const ChunkIndex& ci : chunk_indexes_) {
      at = o.begin(kChunkIndex);
      o.u64(ci.start_time);
      o.u64(ci.end_time);
      o.u64(ci.offset);
      o.u64(ci.length);
      o.u32(static_cast<std::uint32_t>(ci.index_offsets.size() * 10));
      for (const auto& kv : ci.index_offsets) {
        o.u16(kv.first);
        o.u64(kv.second);
      }
      o.u64(ci.index_length);
      o.str(mcapCompressionName(options_.compression));
      o.u64(ci.compressed);
      o.u64(ci.uncompressed);
      o.end(at);
    }
    group(kChunkIndex, begin);
    const std::uint64_t summary_offset_start = offset_ + o.size();
    for (const Group& g : groups) {
      at = o.begin(kSummaryOffset);
      o.u8(g.op);
      o.u64(g.start);
      o.u64(g.length);
      o.end(at);
    }
    const std::size_t summary_begin = static_cast<std::size_t>(summary_start - offset_);
    o.u8(kFooter);
    o.u64(kFooterSize - kRecordPrefix);  // its length is in the CRC below: written, not filled in later
    o.u64(summary_start);
    o.u64(summary_offset_start);
    // CRC of the summary and summary offset sections and of the footer up to this field.
    o.u32(crc32(out.data() + summary_begin, out.size() - summary_begin));
    o.bytes(kMcapMagic, 8);
    emit(out);
    sync();
  } catch (...) {
    ::close(fd);
    fd_ = -1;
    throw;
  }
  fd_ = -1;
  if (::close(fd) != 0) throw RecordError("cannot close recording '" + path_ + "': " + std::strerror(errno));
}

// ---------------------------------------------------------------------------------------------
// McapReader

McapReader::McapReader(const std::string& path) : path_(path) {
  if (const std::string why = common::inputFileProblem(path); !why.empty()) throw RecordError("recording " + why);
  fd_ = ::open(path.c_str(), O_RDONLY | O_CLOEXEC | O_NONBLOCK);
  if (fd_ < 0) throw RecordError("cannot open recording '" + path + "': " + std::strerror(errno));
  struct stat st {};
  if (::fstat(fd_, &st) != 0 || !S_ISREG(st.st_mode)) {
    ::close(fd_);
    throw RecordError("recording '" + path + "' is not a regular file");
  }
  size_ = static_cast<std::uint64_t>(st.st_size);
  std::uint8_t magic[8] = {};
  const std::size_t have = static_cast<std::size_t>(std::min<std::uint64_t>(size_, 8));
  const bool read_ok = have == 0 || readAt(0, magic, have);
  if (!read_ok || std::memcmp(magic, kMcapMagic, have) != 0) {
    ::close(fd_);
    throw RecordError("'" + path + "' is not an MCAP file (no MCAP magic)");
  }
  if (have < 8) {
    ::close(fd_);
    throw RecordError("MCAP file '" + path + "' is cut inside its magic (" + std::to_string(have) + " of 8 bytes)");
  }
  rewind();
}

McapReader::~McapReader() {
  if (fd_ >= 0) ::close(fd_);
}

bool McapReader::readAt(std::uint64_t offset, void* dst, std::size_t n) {
  return common::preadAll(fd_, offset, dst, n);
}

void McapReader::rewind() {
  pos_ = valid_end_ = 8;
  data_crc_ = crc32(kMcapMagic, 8);
  skipped_ = chunks_ = 0;
  ended_ = false;
  state_ = TailState::kClean;
  problem_.clear();
  schemas_.clear();
  channels_.clear();
  chunk_.clear();
  chunk_pos_ = 0;
  loose_.clear();
}

void McapReader::fail(TailState state, const std::string& what) {
  if (problem_.empty()) problem_ = what;
  if (state_ != TailState::kCorrupt) state_ = state;
}

const McapChannelRecord* McapReader::channel(std::uint16_t id) const {
  const auto it = channels_.find(id);
  return it == channels_.end() ? nullptr : &it->second;
}
const McapSchemaRecord* McapReader::schema(std::uint16_t id) const {
  const auto it = schemas_.find(id);
  return it == schemas_.end() ? nullptr : &it->second;
}

bool McapReader::parseInner(const std::uint8_t* p, std::uint64_t len, std::uint8_t op, std::uint64_t at,
                            McapMessageRecord* out) {
  In in(p, len);
  if (op == kSchema) {
    McapSchemaRecord s;
    s.id = static_cast<std::uint16_t>(in.uint(2));
    s.name = in.str();
    s.encoding = in.str();
    s.data = in.str();
    if (!in.ok())
      fail(TailState::kCorrupt, "malformed Schema record at byte " + std::to_string(at));
    else if (s.id != 0)
      schemas_[s.id] = std::move(s);  // id 0 is invalid: ignored, as the spec says
  } else if (op == kChannel) {
    McapChannelRecord c;
    c.id = static_cast<std::uint16_t>(in.uint(2));
    c.schema_id = static_cast<std::uint16_t>(in.uint(2));
    c.topic = in.str();
    c.message_encoding = in.str();
    c.metadata = in.strMap();
    if (!in.ok())
      fail(TailState::kCorrupt, "malformed Channel record at byte " + std::to_string(at));
    else
      channels_[c.id] = std::move(c);
  } else if (op == kMessage && out) {
    out->channel_id = static_cast<std::uint16_t>(in.uint(2));
    out->sequence = static_cast<std::uint32_t>(in.uint(4));
    out->log_time = in.uint(8);
    out->publish_time = in.uint(8);
    if (!in.ok()) {
      fail(TailState::kCorrupt, "malformed Message record at byte " + std::to_string(at));
      return false;
    }
    out->data.assign(in.here(), in.here() + in.left());
    return true;
  }
  return false;
}

void McapReader::finishFile(std::uint64_t data_end) {
  ended_ = true;
  // Footer and closing magic at the very end; the summary CRC covers [summary_start, footer + 25).
  std::uint8_t tail[kFooterSize + 8];
  if (size_ < data_end + sizeof(tail) || !readAt(size_ - sizeof(tail), tail, sizeof(tail)) || tail[0] != kFooter ||
      std::memcmp(tail + kFooterSize, kMcapMagic, 8) != 0) {
    fail(TailState::kTorn, "no footer after the data section (file cut after byte " + std::to_string(data_end) + ")");
    return;
  }
  In f(tail + kRecordPrefix, 20);
  const std::uint64_t summary_start = f.uint(8);
  (void)f.uint(8);
  const auto stored = static_cast<std::uint32_t>(f.uint(4));
  const std::uint64_t footer_at = size_ - sizeof(tail);
  const std::uint64_t from = summary_start != 0 ? summary_start : footer_at;
  if (stored == 0) return;
  if (from < data_end || from > footer_at) {
    fail(TailState::kCorrupt, "footer at byte " + std::to_string(footer_at) + " names summary start " +
                                  std::to_string(summary_start) + ", outside the file's summary");
    return;
  }
  std::uint32_t crc = 0;
  std::vector<std::uint8_t> buf(64 * 1024);
  for (std::uint64_t x = from; x < footer_at + kRecordPrefix + 16;) {
    const std::size_t n =
        static_cast<std::size_t>(std::min<std::uint64_t>(buf.size(), footer_at + kRecordPrefix + 16 - x));
    if (!readAt(x, buf.data(), n)) return;
    crc = crc32(buf.data(), n, crc);
    x += n;
  }
  if (crc != stored)
    fail(TailState::kCorrupt, "summary CRC mismatch (footer at byte " + std::to_string(footer_at) + " stores " +
                                  hex(stored) + ", the bytes give " + hex(crc) + ")");
}

bool McapReader::nextTopLevel() {
  if (ended_) return false;
  std::uint8_t prefix[kRecordPrefix];
  if (pos_ + kRecordPrefix > size_ || !readAt(pos_, prefix, kRecordPrefix)) {
    fail(TailState::kTorn, pos_ == size_
                               ? "file ends after byte " + std::to_string(pos_) + " without DataEnd and footer"
                               : "file cut inside the record at byte " + std::to_string(pos_));
    ended_ = true;
    return false;
  }
  const std::uint8_t op = prefix[0];
  std::uint64_t len = 0;
  for (int i = 7; i >= 0; --i) len = (len << 8) | prefix[1 + i];
  const std::uint64_t at = pos_;
  if (len > size_ - pos_ - kRecordPrefix) {
    // Running past the end: the torn last record of a crash (or a damaged length, which ends reading too).
    fail(TailState::kTorn, "file cut inside the record at byte " + std::to_string(at) + " (opcode " +
                               std::to_string(op) + ", " + std::to_string(len) + " bytes)");
    ended_ = true;
    return false;
  }
  if (op == kDataEnd) {
    std::uint8_t b[4] = {};
    if (len >= 4) readAt(pos_ + kRecordPrefix, b, 4);
    const std::uint32_t stored = static_cast<std::uint32_t>(b[0]) | (static_cast<std::uint32_t>(b[1]) << 8) |
                                 (static_cast<std::uint32_t>(b[2]) << 16) | (static_cast<std::uint32_t>(b[3]) << 24);
    if (len < 4)
      fail(TailState::kCorrupt, "malformed DataEnd record at byte " + std::to_string(at));
    else if (stored != 0 && stored != data_crc_)
      fail(TailState::kCorrupt, "data section CRC mismatch (DataEnd at byte " + std::to_string(at) + " stores " +
                                    hex(stored) + ", the bytes give " + hex(data_crc_) + ")");
    pos_ += kRecordPrefix + len;
    valid_end_ = pos_;
    finishFile(pos_);
    return false;
  }
  if (op == kFooter) {  // a file without DataEnd (allowed by the specification)
    valid_end_ = pos_;
    finishFile(pos_);
    return false;
  }
  if (len > kMaxRecord) {
    fail(TailState::kCorrupt, "record at byte " + std::to_string(at) + " claims " + std::to_string(len) + " bytes");
    ended_ = true;
    return false;
  }
  record_.resize(static_cast<std::size_t>(len));
  if (!readAt(pos_ + kRecordPrefix, record_.data(), record_.size())) {
    fail(TailState::kTorn, "cannot read the record at byte " + std::to_string(at));
    ended_ = true;
    return false;
  }
  data_crc_ = crc32(prefix, kRecordPrefix, data_crc_);
  data_crc_ = crc32(record_.data(), record_.size(), data_crc_);
  pos_ += kRecordPrefix + len;
  valid_end_ = pos_;
  if (op == kHeader) {
    In in(record_.data(), len);
    (void)in.str();
    library_ = in.str();
  } else if (op == kChunk) {
    In in(record_.data(), len);
    (void)in.uint(8);
    (void)in.uint(8);
    const std::uint64_t uncompressed = in.uint(8);
    const auto crc = static_cast<std::uint32_t>(in.uint(4));
    const std::string compression = in.str();
    const std::uint64_t n = in.uint(8);
    std::string why;
    if (!in.ok() || n > in.left()) why = "malformed Chunk record";
    if (why.empty()) why = decompress(compression, in.here(), static_cast<std::size_t>(n), uncompressed, chunk_);
    if (why.empty() && crc != 0 && crc32(chunk_.data(), chunk_.size()) != crc)
      why = "CRC mismatch (stores " + hex(crc) + ", the records give " + hex(crc32(chunk_.data(), chunk_.size())) + ")";
    if (!why.empty()) {
      fail(TailState::kCorrupt, "chunk at byte " + std::to_string(at) + ": " + why + "; skipped");
      skipped_ += kRecordPrefix + len;
      chunk_.clear();
    } else {
      ++chunks_;
      chunk_pos_ = 0;
      chunk_at_ = at;
    }
  } else if (op == kMessage) {
    McapMessageRecord m;
    if (parseInner(record_.data(), len, op, at, &m)) loose_.push_back(std::move(m));
  } else {
    parseInner(record_.data(), len, op, at, nullptr);  // Schema, Channel; other records are skipped
  }
  return true;
}

bool McapReader::next(McapMessageRecord& out) {
  for (;;) {
    if (!loose_.empty()) {
      out = std::move(loose_.back());
      loose_.clear();
      return true;
    }
    while (chunk_pos_ < chunk_.size()) {
      const std::uint64_t left = chunk_.size() - chunk_pos_;
      const std::uint64_t at = chunk_pos_;
      std::uint64_t len = 0;
      if (left >= kRecordPrefix)
        for (int i = 7; i >= 0; --i) len = (len << 8) | chunk_[chunk_pos_ + 1 + static_cast<std::size_t>(i)];
      if (left < kRecordPrefix || len > left - kRecordPrefix) {
        fail(TailState::kCorrupt, "record at offset " + std::to_string(at) + " of the chunk at byte " +
                                      std::to_string(chunk_at_) + " runs past the chunk");
        chunk_pos_ = chunk_.size();
        break;
      }
      const std::uint8_t op = chunk_[chunk_pos_];
      chunk_pos_ += kRecordPrefix + static_cast<std::size_t>(len);
      if (parseInner(chunk_.data() + at + kRecordPrefix, len, op, chunk_at_, &out)) return true;
    }
    chunk_.clear();
    chunk_pos_ = 0;
    if (!nextTopLevel()) return false;
  }
}

// ---------------------------------------------------------------------------------------------
// Reflex samples <-> MCAP

const std::string& omgidlSchemaFor(const std::string& type_name) {
  static const std::map<std::string, std::string> by_type = [] {
    std::map<std::string, std::string> m;
    for (const IdlSchemaFile& f : idlSchemaFiles())
      for (const char* t : f.types) m[t] = f.text;
    return m;
  }();
  static const std::string none;
  const auto it = by_type.find(type_name);
  return it == by_type.end() ? none : it->second;
}

McapSampleWriter::McapSampleWriter(const std::string& path, const McapWriterOptions& options)
    : writer_(path, options) {}

void McapSampleWriter::append(const RecordEntry& e) {
  if (e.receive_ns < 0)
    throw RecordError("sample of topic '" + e.topic + "' has a negative receive time " + std::to_string(e.receive_ns) +
                      " ns (ns since the Unix epoch expected)");
  auto it = channels_.find(e.topic);
  if (it == channels_.end()) {
    McapChannelSpec spec;
    spec.topic = e.topic;
    spec.message_encoding = "cdr";
    spec.schema_name = e.type;
    spec.schema_data = omgidlSchemaFor(e.type);
    spec.schema_encoding = spec.schema_data.empty() ? "" : "omgidl";
    it = channels_.emplace(e.topic, std::make_pair(writer_.addChannel(spec), 0u)).first;
  }
  const auto log_time = static_cast<std::uint64_t>(e.receive_ns);
  const std::uint64_t publish_time = e.source_ns > 0 ? static_cast<std::uint64_t>(e.source_ns) : log_time;
  writer_.write(it->second.first, ++it->second.second, log_time, publish_time, e.payload.data(), e.payload.size());
}

bool McapSampleReader::next(RecordEntry& out) {
  while (reader_.next(message_)) {
    const McapChannelRecord* ch = reader_.channel(message_.channel_id);
    if (!ch) continue;
    const McapSchemaRecord* schema = reader_.schema(ch->schema_id);
    // Timestamps above int64 (not written by Reflex) saturate instead of turning negative.
    const auto clamp = [](std::uint64_t t) {
      return static_cast<std::int64_t>(std::min<std::uint64_t>(t, static_cast<std::uint64_t>(INT64_MAX)));
    };
    out.receive_ns = clamp(message_.log_time);
    out.source_ns = clamp(message_.publish_time);
    out.topic = ch->topic;
    out.type = schema ? schema->name : std::string();
    out.payload = std::move(message_.data);
    return true;
  }
  return false;
}

}  // namespace reflex::record
