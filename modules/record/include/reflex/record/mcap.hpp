// MCAP recordings: a writer and a reader of the MCAP container format (the
// recording format of ROS 2 and Foxglove), written from its specification (mcap.dev/spec, major
// version 0); no third-party MCAP library.
//
// File written by McapWriter (all integers little-endian, as the specification says):
//   magic "\x89MCAP0\r\n" | Header (profile "", library "reflex")
//   data section:   [Schema Channel ...] Chunk | MessageIndex per channel of the chunk | ... | DataEnd
//                   The Schema and Channel records of a channel stand outside the chunks, just before
//                   the chunk of its first message (so a damaged chunk loses its own messages only,
//                   not the channels of the later ones). A chunk holds Message records, optionally
//                   compressed (zstd frame, lz4 frame), with the CRC-32 of their uncompressed bytes.
//                   DataEnd carries the CRC-32 of every byte before it (magic included).
//   summary:        Schema* | Channel* | Statistics | ChunkIndex* (grouped by opcode)
//   summary offset: SummaryOffset per group
//   Footer (summary start, summary offset start, CRC-32 of the summary through the footer's offsets)
//   | magic
// CRC-32 is the IEEE one of record_file.hpp (crc32).
//
// Durability: messages are collected in the open chunk (in the process); the chunk is closed and
// handed to the kernel (write(2)) with its message indexes when its records reach chunk_bytes or its
// first message is chunk_interval old (poll()), and fsync(2) runs every sync_interval and at close.
// A crash (kill -9) therefore loses the messages of the open chunk -- at most chunk_interval of
// recording or chunk_bytes of data -- and leaves a file without summary and footer, which McapReader
// and the reference readers (streamed) read up to the last complete chunk (TailState::kTorn).
//
// To add a channel of another encoding (e.g. JSON scene channels with a JSON schema), call
// McapWriter::addChannel with its topic, message encoding, schema name, schema encoding and data.
#pragma once

#include "reflex/record/record_file.hpp"

#include <chrono>
#include <cstdint>
#include <map>
#include <memory>
#include <string>
#include <vector>

namespace reflex::record {

inline constexpr std::uint8_t kMcapMagic[8] = {0x89, 'M', 'C', 'A', 'P', '0', '\r', '\n'};

/// Chunk compression of an MCAP file.
enum class McapCompression { kNone, kZstd, kLz4 };
/// "none" / "zstd" / "lz4" -> the value; throws RecordError quoting any other text.
McapCompression parseMcapCompression(const std::string& text);
/// The Chunk record's compression string: "" (none), "zstd", "lz4".
const char* mcapCompressionName(McapCompression c);

struct McapWriterOptions {
  McapCompression compression = McapCompression::kZstd;
  std::uint64_t chunk_bytes = 1u << 20;           ///< close a chunk when its records reach this size (> 0)
  std::chrono::milliseconds chunk_interval{500};  ///< ... or when its first message is this old (> 0)
  std::chrono::milliseconds sync_interval{1000};  ///< fsync(2) period (0: after every chunk)
  std::string profile;                            ///< Header.profile ("": none of the well-known ones)
  std::string library = "reflex";                 ///< Header.library
};

/// What a channel is: one topic with one message encoding and schema.
struct McapChannelSpec {
  std::string topic;             ///< e.g. "reflex/joint_state"
  std::string message_encoding;  ///< e.g. "cdr", "json"
  std::string schema_name;       ///< e.g. "reflex::msg::JointState"; a schema is shared by channels with equal
                                 ///< name, encoding and data
  std::string schema_encoding;   ///< e.g. "omgidl", "jsonschema"; "" for no schema (then schema_data is empty)
  std::string schema_data;       ///< the schema text
  std::map<std::string, std::string> metadata;  ///< Channel.metadata
};

/// Writes an MCAP file (see the top of this header). Not thread-safe (one writer thread). The
/// destructor finishes the file (errors swallowed; call close() to see them).
class McapWriter {
 public:
  /// Creates (truncates) `path` and writes magic and Header. Throws RecordError naming the path or the
  /// bad option (chunk_bytes 0, negative intervals) before anything is written.
  McapWriter(const std::string& path, const McapWriterOptions& options = {});
  ~McapWriter();
  McapWriter(const McapWriter&) = delete;
  McapWriter& operator=(const McapWriter&) = delete;

  /// Adds a channel (and its schema, unless an equal one exists) and returns its id (1, 2, ...).
  /// Throws RecordError after 65535 channels or schemas, or if the file is closed.
  std::uint16_t addChannel(const McapChannelSpec& spec);
  /// Appends one message to the open chunk. log_time / publish_time: ns (since the Unix epoch for
  /// Reflex). `channel` must come from addChannel (else RecordError naming it). Closes the chunk when
  /// it is full. Throws RecordError on I/O failure.
  void write(std::uint16_t channel, std::uint32_t sequence, std::uint64_t log_time, std::uint64_t publish_time,
             const std::uint8_t* data, std::size_t size);
  /// Closes the open chunk if it is chunk_interval old; fsyncs every sync_interval.
  void poll();
  /// Closes the open chunk now (write(2)).
  void flushChunk();
  /// Last chunk, DataEnd, summary, summary offsets, footer, magic; fsync and close. Later calls do nothing.
  void close();

  const std::string& path() const { return path_; }
  std::uint64_t bytesWritten() const { return offset_; }
  std::uint64_t messagesWritten() const { return message_count_; }
  std::uint64_t chunksWritten() const { return chunk_indexes_.size(); }

 private:
  struct Schema {
    std::uint16_t id;
    std::string name, encoding, data;
    bool in_file = false;  ///< its record is written or waits in definitions_
  };
  struct Channel {
    std::uint16_t id, schema_id;
    McapChannelSpec spec;
    bool in_file = false;  ///< its Channel record is written or waits in definitions_
    std::uint64_t messages = 0;
  };
  struct ChunkIndex {
    std::uint64_t start_time, end_time, offset, length, index_length, compressed, uncompressed;
    std::map<std::uint16_t, std::uint64_t> index_offsets;
  };
  void emit(const std::vector<std::uint8_t>& bytes);  ///< write(2) + data CRC + offset
  void sync();

  std::string path_;
  McapWriterOptions options_;
  int fd_ = -1;
  bool regular_ = true;
  std::uint64_t offset_ = 0;
  std::uint32_t data_crc_ = 0;
  std::vector<Schema> schemas_;
  std::vector<Channel> channels_;
  std::vector<ChunkIndex> chunk_indexes_;
  std::uint64_t message_count_ = 0, start_time_ = 0, end_time_ = 0;
  // the open chunk, and the Schema / Channel records of its new channels (written just before it)
  std::vector<std::uint8_t> definitions_;
  std::vector<std::uint8_t> chunk_;
  std::map<std::uint16_t, std::vector<std::uint8_t>> chunk_message_index_;  ///< channel -> (time, offset) pairs
  std::uint64_t chunk_start_ = 0, chunk_end_ = 0;
  bool chunk_has_messages_ = false;
  std::chrono::steady_clock::time_point chunk_opened_{}, last_sync_{};
};

struct McapSchemaRecord {
  std::uint16_t id = 0;
  std::string name, encoding;
  std::string data;
};
struct McapChannelRecord {
  std::uint16_t id = 0, schema_id = 0;
  std::string topic, message_encoding;
  std::map<std::string, std::string> metadata;
};
struct McapMessageRecord {
  std::uint16_t channel_id = 0;
  std::uint32_t sequence = 0;
  std::uint64_t log_time = 0, publish_time = 0;
  std::vector<std::uint8_t> data;
};

/// Reads an MCAP file in file order, record by record (it does not need the summary, so a file cut
/// anywhere reads up to its last complete chunk). Checks every CRC the file carries (chunk, data
/// section, summary); a chunk whose CRC or decompression fails is skipped and reported with its byte
/// offset (TailState::kCorrupt), the following chunks are still read. Memory: one chunk, budgeted
/// against the bytes in the file: a record must fit in the file and be <= 1 GiB; an uncompressed chunk
/// must hold exactly its declared size; a compressed one may declare <= 1 GiB and <= 1000 x its
/// compressed bytes, and is decoded into a buffer that grows with the output and stops at the first
/// byte beyond the declared size (a zstd bomb is refused before it is expanded).
class McapReader {
 public:
  /// Opens `path`. Throws RecordError naming the path: missing, not a regular file, shorter than the
  /// magic ("cut inside the MCAP magic"), no MCAP magic.
  explicit McapReader(const std::string& path);
  ~McapReader();
  McapReader(const McapReader&) = delete;
  McapReader& operator=(const McapReader&) = delete;

  /// The next message in file order; false at the end of the data (or where reading had to stop).
  bool next(McapMessageRecord& out);
  void rewind();

  /// Channels and schemas seen so far (by id).
  const McapChannelRecord* channel(std::uint16_t id) const;
  const McapSchemaRecord* schema(std::uint16_t id) const;

  TailState tailState() const { return state_; }
  /// First problem with its byte offset ("" if none).
  const std::string& problem() const { return problem_; }
  std::uint64_t validEnd() const { return valid_end_; }
  std::uint64_t fileSize() const { return size_; }
  std::uint64_t skippedBytes() const { return skipped_; }
  std::uint64_t chunksRead() const { return chunks_; }
  const std::string& path() const { return path_; }
  const std::string& headerLibrary() const { return library_; }

 private:
  bool readAt(std::uint64_t offset, void* dst, std::size_t n);
  void fail(TailState state, const std::string& what);
  bool nextTopLevel();  ///< reads one top-level record; false when reading ends
  bool parseInner(const std::uint8_t* p, std::uint64_t len, std::uint8_t op, std::uint64_t at, McapMessageRecord* out);
  void finishFile(std::uint64_t data_end);

  std::string path_;
  int fd_ = -1;
  std::uint64_t size_ = 0, pos_ = 0, valid_end_ = 0, skipped_ = 0, chunks_ = 0;
  std::uint32_t data_crc_ = 0;
  bool ended_ = false;
  TailState state_ = TailState::kClean;
  std::string problem_, library_;
  std::map<std::uint16_t, McapSchemaRecord> schemas_;
  std::map<std::uint16_t, McapChannelRecord> channels_;
  std::vector<std::uint8_t> record_, chunk_;
  std::size_t chunk_pos_ = 0;
  std::uint64_t chunk_at_ = 0;
  std::vector<McapMessageRecord> loose_;  ///< a message found outside chunks, handed out next
};

/// SampleWriter over McapWriter for Reflex samples: one channel per topic, message encoding "cdr"
/// (the XCDR1 bytes Fast DDS serialises, 4-byte encapsulation header included), schema encoding
/// "omgidl" with the type's self-contained IDL text from idl/ (schema name = DDS type name,
/// "reflex::msg::JointState"). log_time = receive time; publish_time = the writer's DDS source
/// timestamp (log_time when unknown, i.e. 0 or negative); sequence = per-channel count from 1.
/// A type that is not in idl/ gets a schema with its name and no encoding (so it reads back).
class McapSampleWriter final : public SampleWriter {
 public:
  McapSampleWriter(const std::string& path, const McapWriterOptions& options);
  void append(const RecordEntry& entry) override;
  void poll() override { writer_.poll(); }
  void close() override { writer_.close(); }
  const std::string& path() const override { return writer_.path(); }
  std::uint64_t bytesWritten() const override { return writer_.bytesWritten(); }
  /// The MCAP writer itself (to add channels of other encodings).
  McapWriter& mcap() { return writer_; }

 private:
  McapWriter writer_;
  std::map<std::string, std::pair<std::uint16_t, std::uint32_t>> channels_;  ///< topic -> id, count
};

/// SampleReader over McapReader: topic = channel topic, type = schema name, receive_ns = log_time,
/// source_ns = publish_time, payload = message data. A message on an unknown channel is skipped.
class McapSampleReader final : public SampleReader {
 public:
  explicit McapSampleReader(const std::string& path) : reader_(path) {}
  bool next(RecordEntry& out) override;
  void rewind() override { reader_.rewind(); }
  TailState tailState() const override { return reader_.tailState(); }
  std::uint64_t validEnd() const override { return reader_.validEnd(); }
  std::uint64_t fileSize() const override { return reader_.fileSize(); }
  std::uint64_t skippedBytes() const override { return reader_.skippedBytes(); }
  std::string problem() const override { return reader_.problem(); }
  const char* formatName() const override { return "mcap"; }
  McapReader& mcap() { return reader_; }

 private:
  McapReader reader_;
  McapMessageRecord message_;
};

/// The self-contained OMG IDL schema text of a Reflex type ("reflex::msg::JointState"), made at build
/// time from idl/*.idl (includes inlined, preprocessor lines removed); "" if the type is not in idl/.
const std::string& omgidlSchemaFor(const std::string& type_name);

}  // namespace reflex::record
