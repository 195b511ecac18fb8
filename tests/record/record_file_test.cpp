// The recording file format (modules/record/include/reflex/record/record_file.hpp): records read back
// byte for byte; a file cut anywhere inside its last record reads as the records before it (torn
// tail), never as garbage; a corrupted record in the middle is reported and skipped; bad files and
// options are clear errors.
#include "reflex/record/record_file.hpp"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <random>
#include <thread>

namespace reflex::record {
namespace {

std::string tempPath(const std::string& name) { return ::testing::TempDir() + "record_file_test_" + name; }

RecordEntry makeEntry(int i, std::mt19937& rng) {
  RecordEntry e;
  e.receive_ns = 1'700'000'000'000'000'000LL + i * 5'000'000LL;
  e.source_ns = e.receive_ns - 1000 - i;
  e.topic = i % 2 ? "reflex/control_status" : "reflex/joint_state";
  e.type = i % 2 ? "reflex::msg::ControlStatus" : "reflex::msg::JointState";
  e.payload.resize(static_cast<std::size_t>(20 + rng() % 300));
  for (auto& b : e.payload) b = static_cast<std::uint8_t>(rng());
  return e;
}

void expectSame(const RecordEntry& a, const RecordEntry& b) {
  EXPECT_EQ(a.receive_ns, b.receive_ns);
  EXPECT_EQ(a.source_ns, b.source_ns);
  EXPECT_EQ(a.topic, b.topic);
  EXPECT_EQ(a.type, b.type);
  EXPECT_EQ(a.payload, b.payload);
}

std::vector<std::uint8_t> readBytes(const std::string& p) {
  std::ifstream in(p, std::ios::binary);
  return std::vector<std::uint8_t>((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
}
void writeBytes(const std::string& p, const std::vector<std::uint8_t>& b, std::size_t n) {
  std::ofstream out(p, std::ios::binary | std::ios::trunc);
  out.write(reinterpret_cast<const char*>(b.data()), static_cast<std::streamsize>(n));
}

TEST(Crc32, MatchesTheStandardCheckValue) {
  // The IEEE CRC-32 check value of "123456789" (e.g. zlib's crc32, Python's binascii.crc32).
  EXPECT_EQ(crc32("123456789", 9), 0xCBF43926u);
  EXPECT_EQ(crc32("", 0), 0u);
  // Incremental == one shot.
  EXPECT_EQ(crc32("6789", 4, crc32("12345", 5)), 0xCBF43926u);
}

TEST(RecordFile, RecordsReadBackExactly) {
  std::mt19937 rng(1);
  const std::string path = tempPath("roundtrip.rfx");
  std::vector<RecordEntry> written;
  {
    RecordWriter w(path);
    for (int i = 0; i < 200; ++i) {
      written.push_back(makeEntry(i, rng));
      w.append(written.back());
    }
    EXPECT_EQ(w.recordsWritten(), 200u);
  }
  RecordReader r(path);
  RecordEntry e;
  std::size_t n = 0;
  while (r.next(e)) {
    ASSERT_LT(n, written.size());
    expectSame(e, written[n++]);
  }
  EXPECT_EQ(n, written.size());
  EXPECT_EQ(r.tailState(), TailState::kClean);
  EXPECT_EQ(r.validEnd(), r.fileSize());
  r.rewind();
  ASSERT_TRUE(r.next(e));
  expectSame(e, written[0]);
}

TEST(RecordFile, ByteLayoutIsAsDocumented) {
  RecordEntry e;
  e.receive_ns = 0x0102030405060708LL;
  e.source_ns = 7;
  e.topic = "t";
  e.type = "ty";
  e.payload = {0xAA, 0xBB};
  const auto rec = encodeRecord(e);
  const std::size_t body = 8 + 8 + 2 + 1 + 2 + 2 + 4 + 2;
  ASSERT_EQ(rec.size(), kRecordHeaderSize + body);
  EXPECT_EQ(std::string(rec.begin(), rec.begin() + 4), "RREC");
  EXPECT_EQ(rec[4], body);
  EXPECT_EQ(rec[12], 0x08);  // receive time, little-endian
  EXPECT_EQ(rec[19], 0x01);
  const std::uint32_t crc = rec[8] | (rec[9] << 8) | (rec[10] << 16) | (static_cast<std::uint32_t>(rec[11]) << 24);
  EXPECT_EQ(crc, crc32(rec.data() + 12, body));
  EXPECT_EQ(rec.back(), 0xBB);
}

TEST(RecordFile, EveryCutInsideTheLastRecordIsATornTailWithAllEarlierRecords) {
  std::mt19937 rng(2);
  const std::string path = tempPath("torn_src.rfx");
  std::vector<RecordEntry> written;
  {
    RecordWriter w(path);
    for (int i = 0; i < 5; ++i) {
      written.push_back(makeEntry(i, rng));
      w.append(written.back());
    }
  }
  const auto bytes = readBytes(path);
  const std::size_t last_size = encodeRecord(written.back()).size();
  const std::size_t last_start = bytes.size() - last_size;
  const std::string cut = tempPath("torn_cut.rfx");
  for (std::size_t n = last_start; n <= bytes.size(); ++n) {
    writeBytes(cut, bytes, n);
    RecordReader r(cut);
    RecordEntry e;
    std::size_t count = 0;
    while (r.next(e)) expectSame(e, written[count++]);
    const bool complete = n == bytes.size();
    EXPECT_EQ(count, complete ? 5u : 4u) << "cut at " << n;
    EXPECT_EQ(r.tailState(), (complete || n == last_start) ? TailState::kClean : TailState::kTorn) << "cut at " << n;
    EXPECT_EQ(r.validEnd(), complete ? bytes.size() : last_start);
  }
}

TEST(RecordFile, ACorruptRecordInTheMiddleIsReportedAndSkipped) {
  std::mt19937 rng(3);
  const std::string path = tempPath("corrupt.rfx");
  std::vector<RecordEntry> written;
  std::vector<std::size_t> offsets;
  std::size_t off = kFileHeaderSize;
  {
    RecordWriter w(path);
    for (int i = 0; i < 10; ++i) {
      written.push_back(makeEntry(i, rng));
      offsets.push_back(off);
      off += encodeRecord(written.back()).size();
      w.append(written.back());
    }
  }
  auto bytes = readBytes(path);
  bytes[offsets[4] + kRecordHeaderSize + 30] ^= 0x5A;  // flip bits inside record 4's body
  writeBytes(path, bytes, bytes.size());
  {
    RecordReader r(path);
    RecordEntry e;
    std::vector<RecordEntry> got;
    while (r.next(e)) got.push_back(e);
    ASSERT_EQ(got.size(), 9u);
    for (std::size_t k = 0; k < got.size(); ++k) expectSame(got[k], written[k < 4 ? k : k + 1]);
    EXPECT_EQ(r.tailState(), TailState::kCorrupt);
    EXPECT_EQ(r.firstCorruptOffset(), offsets[4]);
    EXPECT_EQ(r.skippedBytes(), offsets[5] - offsets[4]);
  }
  {
    RecordReader r(path);
    r.setResync(false);
    RecordEntry e;
    std::size_t n = 0;
    while (r.next(e)) ++n;
    EXPECT_EQ(n, 4u);
    EXPECT_EQ(r.tailState(), TailState::kCorrupt);
  }
  // Appending to a file with a corrupt record is refused (it would hide the damage).
  WriterOptions append;
  append.append = true;
  EXPECT_THROW(RecordWriter(path, append), RecordError);
}

TEST(RecordFile, AppendCutsATornTailAndContinues) {
  std::mt19937 rng(4);
  const std::string path = tempPath("append.rfx");
  std::vector<RecordEntry> written;
  {
    RecordWriter w(path);
    for (int i = 0; i < 3; ++i) {
      written.push_back(makeEntry(i, rng));
      w.append(written.back());
    }
  }
  auto bytes = readBytes(path);
  writeBytes(path, bytes, bytes.size() - 7);  // tear the third record
  written.pop_back();
  {
    WriterOptions o;
    o.append = true;
    RecordWriter w(path, o);
    written.push_back(makeEntry(10, rng));
    w.append(written.back());
  }
  RecordReader r(path);
  RecordEntry e;
  std::size_t n = 0;
  while (r.next(e)) expectSame(e, written[n++]);
  EXPECT_EQ(n, 3u);
  EXPECT_EQ(r.tailState(), TailState::kClean);
}

TEST(RecordFile, WrittenRecordsReachTheFileWithinTheFlushInterval) {
  std::mt19937 rng(5);
  const std::string path = tempPath("flush.rfx");
  WriterOptions o;
  o.flush_interval = std::chrono::milliseconds(50);
  RecordWriter w(path, o);
  w.append(makeEntry(0, rng));
  EXPECT_EQ(std::filesystem::file_size(path), kFileHeaderSize) << "buffered, not yet written";
  std::this_thread::sleep_for(std::chrono::milliseconds(60));
  w.poll();
  // Visible to another reader while the writer is still open (what a kill -9 would leave).
  RecordReader r(path);
  RecordEntry e;
  EXPECT_TRUE(r.next(e));
  EXPECT_EQ(r.tailState(), TailState::kClean);
}

TEST(RecordFile, BadFilesAndValuesAreClearErrors) {
  const std::string missing = tempPath("does_not_exist.rfx");
  try {
    RecordReader r(missing);
    FAIL() << "no throw";
  } catch (const RecordError& e) {
    EXPECT_NE(std::string(e.what()).find(missing), std::string::npos) << e.what();
  }
  const std::string text = tempPath("text.rfx");
  { std::ofstream(text) << "hello, I am a CSV file\n"; }
  try {
    RecordReader r(text);
    FAIL() << "no throw";
  } catch (const RecordError& e) {
    EXPECT_NE(std::string(e.what()).find("not a Reflex recording"), std::string::npos) << e.what();
  }
  const std::string future = tempPath("future.rfx");
  {
    std::vector<std::uint8_t> h(kFileMagic, kFileMagic + 8);
    h.insert(h.end(), {9, 0, 0, 0, 0, 0, 0, 0});
    writeBytes(future, h, h.size());
  }
  try {
    RecordReader r(future);
    FAIL() << "no throw";
  } catch (const RecordError& e) {
    EXPECT_NE(std::string(e.what()).find("version 9"), std::string::npos) << e.what();
  }
  EXPECT_THROW(RecordWriter("/nonexistent_dir/x.rfx"), RecordError);
  RecordEntry huge;
  huge.topic = std::string(70000, 'a');
  EXPECT_THROW(encodeRecord(huge), RecordError);
  WriterOptions neg;
  neg.flush_interval = std::chrono::milliseconds(-1);
  EXPECT_THROW(RecordWriter(tempPath("neg.rfx"), neg), RecordError);
}

}  // namespace
}  // namespace reflex::record
