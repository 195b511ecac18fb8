// libFuzzer target: recording files (.rfx, modules/record/record_file.hpp) -> RecordReader, as
// `reflex_record info --print` and `reflex_record export` read them: scanRecording, every record
// decoded by its type's codec (summary, CSV header and rows), then a second pass without resync.
// Documented error: reflex::record::RecordError.
//
// Every record carries a CRC-32, so random bytes almost never reach the record body. Each input is
// therefore read twice: as it is, and with the CRC of every framed record ("RREC" | length | CRC |
// body that fits) recomputed, so that the fuzzer also explores the body fields (inner lengths, the
// CDR payload of each type).
//
// Invariants checked beyond "no crash": every record the reader returns, re-encoded by
// encodeRecord, is byte for byte the bytes it was read from (the reader never returns a record that
// is not in the file); and a file the reader calls "torn" (cut inside its last record) holds no
// complete valid record after the point where reading stopped, i.e. a damaged length field in the
// middle of a file is not mistaken for the torn tail of a kill -9 (which would silently drop every
// later record).
// Time: the reader's work -- every byte it reads, CRCs included
// (RecordReader::bytesExamined) -- stays below kWorkPerByte times the file size plus a constant, on
// every input. The old resynchronisation was quadratic (a crafted 2 MB file: > 60 s); a regression
// to it breaks this bound on any input of more than a few kilobytes with many sync words. Work is
// counted, not timed, so the check is exact under sanitizers and on a loaded machine.
#include "fuzz_util.hpp"

#include "reflex/record/codecs.hpp"
#include "reflex/record/record_file.hpp"
#include "reflex/record/recorder.hpp"

#include <cstring>
#include <set>
#include <sstream>
#include <vector>

namespace {

using namespace reflex::record;

std::uint32_t readU32(const std::uint8_t* p) {
  return static_cast<std::uint32_t>(p[0]) | (static_cast<std::uint32_t>(p[1]) << 8) |
         (static_cast<std::uint32_t>(p[2]) << 16) | (static_cast<std::uint32_t>(p[3]) << 24);
}

/// The input with the CRC of every framed record recomputed (see the header comment).
std::vector<std::uint8_t> withFixedCrcs(const std::uint8_t* data, std::size_t size) {
  std::vector<std::uint8_t> out(data, data + size);
  std::size_t pos = kFileHeaderSize;
  while (pos + kRecordHeaderSize <= out.size()) {
    const std::uint32_t len = readU32(out.data() + pos + 4);
    if (readU32(out.data() + pos) != kRecordSync || len > out.size() - pos - kRecordHeaderSize) {
      ++pos;
      continue;
    }
    const std::uint32_t crc = crc32(out.data() + pos + kRecordHeaderSize, len);
    for (int i = 0; i < 4; ++i) out[pos + 8 + i] = static_cast<std::uint8_t>(crc >> (8 * i));
    pos += kRecordHeaderSize + len;
  }
  return out;
}

std::uint16_t readU16(const std::uint8_t* p) { return static_cast<std::uint16_t>(p[0] | (p[1] << 8)); }

/// Independent of RecordReader: is there a complete record with a good CRC and consistent inner
/// lengths at byte `pos` (record_file.hpp layout)?
bool validRecordAt(const std::vector<std::uint8_t>& b, std::size_t pos) {
  if (pos + kRecordHeaderSize > b.size() || readU32(b.data() + pos) != kRecordSync) return false;
  const std::uint64_t len = readU32(b.data() + pos + 4);
  if (len < 24 || len > kMaxBodySize || pos + kRecordHeaderSize + len > b.size()) return false;
  const std::uint8_t* body = b.data() + pos + kRecordHeaderSize;
  if (crc32(body, len) != readU32(b.data() + pos + 8)) return false;
  if (body[7] & 0x80) return false;  // a negative receive time (RecordEntry::receive_ns)
  std::uint64_t at = 16;
  const std::uint64_t topic = readU16(body + at);
  at += 2 + topic;
  if (at + 2 > len) return false;
  const std::uint64_t type = readU16(body + at);
  at += 2 + type;
  if (at + 4 > len) return false;
  return readU32(body + at) == len - at - 4;
}

constexpr std::uint64_t kWorkPerByte = 64;
constexpr std::uint64_t kWorkConstant = 1u << 20;

[[noreturn]] void invariantBroken(const char* what, std::uint64_t offset) {
  std::fprintf(stderr, "FUZZ FINDING: RecordReader %s (byte %llu)\n", what, static_cast<unsigned long long>(offset));
  std::abort();
}

void readRecording(const std::vector<std::uint8_t>& bytes) {
  const std::string& path = reflex::fuzz::writeTemp(bytes.data(), bytes.size(), ".rfx");
  reflex::fuzz::expectOnly<RecordError>("RecordReader", [&] {
    const RecordingInfo info = scanRecording(path);
    RecordReader reader(path);
    RecordEntry e;
    std::set<std::string> headed;
    std::uint64_t n = 0;
    while (reader.next(e)) {
      ++n;
      const std::vector<std::uint8_t> encoded = encodeRecord(e);
      const std::uint64_t end = reader.validEnd();
      if (end > bytes.size() || encoded.size() > end ||
          std::memcmp(bytes.data() + (end - encoded.size()), encoded.data(), encoded.size()) != 0) {
        invariantBroken("returned a record that is not the bytes it was read from", end);
      }
      const TopicCodec* codec = findCodecByType(e.type);
      if (!codec) continue;
      std::ostringstream csv;
      // A payload that does not decode is a RecordError naming the topic; go on with the next record.
      try {
        (void)codec->summary(e);
        if (headed.insert(e.topic).second) codec->writeCsvHeader(csv, e);
        codec->writeCsvRows(csv, e, CsvContext{info.first_ns});
      } catch (const RecordError&) {
      }
    }
    if (reader.bytesExamined() > kWorkPerByte * bytes.size() + kWorkConstant)
      invariantBroken("read more than 64 x the file size (not linear time)", reader.bytesExamined());
    if (n != info.records)
      invariantBroken("counted different records in two reads of the same file", reader.validEnd());
    if (reader.tailState() == TailState::kTorn) {
      for (std::size_t pos = reader.validEnd() + 1; pos < bytes.size(); ++pos) {
        if (validRecordAt(bytes, pos)) invariantBroken("called the tail torn but a valid record follows", pos);
      }
    }
    // Without resync reading stops at the first corrupt record.
    reader.rewind();
    reader.setResync(false);
    while (reader.next(e)) {
    }
    if (reader.validEnd() > reader.fileSize())
      invariantBroken("valid end beyond the end of the file", reader.validEnd());
  });
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  readRecording(std::vector<std::uint8_t>(data, data + size));
  const std::vector<std::uint8_t> fixed = withFixedCrcs(data, size);
  if (size > 0 && std::memcmp(fixed.data(), data, size) != 0) readRecording(fixed);
  return 0;
}
