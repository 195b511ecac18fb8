// The recording file format (modules/record/include/reflex/record/record_file.hpp): records read back
// byte for byte; a file cut anywhere inside its last record reads as the records before it (torn
// tail), never as garbage; a corrupted record in the middle is reported and skipped; bad files and
// options are clear errors. Reading is linear in the file size on crafted input (item 12:
// the work counter and the wall time of crafted files of 2 and 8 MB against each other and against a
// valid file of the same size; crc32Combine against the CRC of the concatenated bytes); a FIFO or a
// device named as a recording is refused at once, never read (item 11).
#include "reflex/record/record_file.hpp"
#include "support/child_process.hpp"

#include <gtest/gtest.h>

#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <ctime>
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

// ---------------------------------------------------------------- Linear time
TEST(Crc32, CombineEqualsTheCrcOfTheConcatenation) {
  std::mt19937 rng(7);
  for (int trial = 0; trial < 200; ++trial) {
    std::vector<std::uint8_t> a(rng() % 600), b(trial < 5 ? trial : rng() % 5000);
    for (auto& x : a) x = static_cast<std::uint8_t>(rng());
    for (auto& x : b) x = static_cast<std::uint8_t>(rng());
    std::vector<std::uint8_t> ab = a;
    ab.insert(ab.end(), b.begin(), b.end());
    EXPECT_EQ(crc32Combine(crc32(a.data(), a.size()), crc32(b.data(), b.size()), b.size()), crc32(ab.data(), ab.size()))
        << a.size() << " + " << b.size();
  }
}

void putU32(std::vector<std::uint8_t>& b, std::size_t at, std::uint32_t v) {
  for (int i = 0; i < 4; ++i) b[at + i] = static_cast<std::uint8_t>(v >> (8 * i));
}

/// `size` bytes: the file header, then a record header every 36 bytes whose body runs to the end of
/// the file, with consistent inner fields (receive time >= 0, empty topic and type, the payload
/// length that fills the body) and a wrong CRC; one valid record at the very end. The old reader
/// computed the CRC of every one of those bodies while resynchronising: quadratic.
std::vector<std::uint8_t> craftedRecording(std::size_t size) {
  const RecordEntry last{1, 2, "t", "T", {1, 2, 3}};
  const std::vector<std::uint8_t> tail = encodeRecord(last);
  std::vector<std::uint8_t> b(size, 0);
  std::copy(kFileMagic, kFileMagic + 8, b.begin());
  putU32(b, 8, kFormatVersion);
  const std::size_t end = size - tail.size();
  for (std::size_t at = kFileHeaderSize + 1; at + 36 <= end; at += 36) {
    const std::uint32_t len = static_cast<std::uint32_t>(end - at - kRecordHeaderSize);
    putU32(b, at, kRecordSync);
    putU32(b, at + 4, len);
    putU32(b, at + 8, 0xDEADBEEFu);  // wrong CRC
    // receive_ns, source_ns = 0; topic length 0, type length 0 (bytes at +28..+32 stay 0)
    putU32(b, at + 32, len - 24);  // payload length: the rest of the body
  }
  std::copy(tail.begin(), tail.end(), b.begin() + static_cast<std::ptrdiff_t>(end));
  return b;
}

/// A valid recording of about `size` bytes (records of 300-byte payloads).
std::vector<std::uint8_t> validRecording(const std::string& path, std::size_t size) {
  {
    RecordWriter w(path);
    RecordEntry e{1'000, 0, "reflex/joint_state", "reflex::msg::JointState", std::vector<std::uint8_t>(300, 7)};
    for (std::size_t n = kFileHeaderSize; n < size; n += kRecordHeaderSize + 8 + 8 + 2 + 18 + 2 + 23 + 4 + 300) {
      w.append(e);
      e.receive_ns += 5'000'000;
    }
    w.close();
  }
  return readBytes(path);
}

struct ReadStats {
  double seconds = 0.0;
  std::uint64_t records = 0, examined = 0;
  TailState tail = TailState::kClean;
};

/// CPU time of this thread (s): unlike wall time, hardly changed by other processes on the machine.
double threadCpuSeconds() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
}

/// Reads `path` to the end: CPU time of the fastest of `runs` runs (robust against a loaded machine).
ReadStats readAll(const std::string& path, int runs = 3) {
  ReadStats best;
  best.seconds = 1e9;
  for (int run = 0; run < runs; ++run) {
    const double t0 = threadCpuSeconds();
    RecordReader r(path);
    RecordEntry e;
    std::uint64_t n = 0;
    while (r.next(e)) ++n;
    const double s = threadCpuSeconds() - t0;
    if (s < best.seconds) best = {s, n, r.bytesExamined(), r.tailState()};
  }
  return best;
}

TEST(RecordFileLinearTime, CraftedResyncInputReadsInLinearTime) {
  const std::size_t mb = 1u << 20;
  const std::string p2 = tempPath("crafted2.rfx"), p8 = tempPath("crafted8.rfx"), pv = tempPath("valid2.rfx");
  const auto c2 = craftedRecording(2 * mb), c8 = craftedRecording(8 * mb);
  writeBytes(p2, c2, c2.size());
  writeBytes(p8, c8, c8.size());
  const auto v2 = validRecording(pv, 2 * mb);
  const ReadStats s2 = readAll(p2), s8 = readAll(p8), sv = readAll(pv);
  std::printf(
      "crafted 2 MB: %.4f s, %llu bytes examined; crafted 8 MB: %.4f s, %llu bytes; valid %.1f MB: %.4f s, "
      "%llu bytes\n",
      s2.seconds, static_cast<unsigned long long>(s2.examined), s8.seconds,
      static_cast<unsigned long long>(s8.examined), v2.size() / 1048576.0, sv.seconds,
      static_cast<unsigned long long>(sv.examined));
  // The crafted files hold exactly one valid record (the last), after corrupt bytes.
  EXPECT_EQ(s2.records, 1u);
  EXPECT_EQ(s8.records, 1u);
  EXPECT_EQ(s2.tail, TailState::kCorrupt);
  // Work: a fixed multiple of the size (deterministic). Quadratic would be ~ size / 72 per byte.
  EXPECT_LT(s2.examined, 64u * c2.size());
  EXPECT_LT(s8.examined, 64u * c8.size());
  EXPECT_LT(static_cast<double>(s8.examined) / static_cast<double>(s2.examined), 4.5);
  // CPU time: 4 x the bytes, about 4 x the time (quadratic: 16 x); against a valid file of the same size.
  EXPECT_LT(s8.seconds / s2.seconds, 8.0) << "2 MB " << s2.seconds << " s, 8 MB " << s8.seconds << " s";
  EXPECT_LT(s2.seconds / sv.seconds, 100.0) << "crafted " << s2.seconds << " s, valid " << sv.seconds << " s";
}

/// A file of `records` valid records, each followed by a damaged header (sync word, a claimed body of
/// at most `claim` bytes reaching at most the end of the file, a CRC of 0).
std::vector<std::uint8_t> validRecordsWithDamagedHeaders(std::size_t records, std::size_t claim) {
  std::vector<std::uint8_t> b(kFileMagic, kFileMagic + 8);
  b.insert(b.end(), {1, 0, 0, 0, 0, 0, 0, 0});
  const std::vector<std::uint8_t> rec = encodeRecord(RecordEntry{5, 6, "a", "B", {9, 9}});
  const std::size_t total = b.size() + records * (rec.size() + 12);
  for (std::size_t i = 0; i < records; ++i) {
    b.insert(b.end(), rec.begin(), rec.end());
    const std::size_t at = b.size();
    b.resize(at + 12);
    putU32(b, at, kRecordSync);
    putU32(b, at + 4, static_cast<std::uint32_t>(std::min(claim, total - at - 12)));
    putU32(b, at + 8, 0);
  }
  return b;
}

TEST(RecordFileLinearTime, LongCorruptHeadersBetweenValidRecordsCostNoMoreThanTheirHeader) {
  // A valid record, then a header claiming a body to the end of the file with a wrong CRC, and so
  // on: each damaged header was read and CRC-checked to the end of the file (quadratic).
  const std::string path = tempPath("longheaders.rfx");
  const std::size_t records = 20000;
  const std::vector<std::uint8_t> b = validRecordsWithDamagedHeaders(records, ~std::size_t{0});
  writeBytes(path, b, b.size());
  const ReadStats s = readAll(path, 1);
  EXPECT_EQ(s.records, records);
  EXPECT_EQ(s.tail, TailState::kCorrupt);
  EXPECT_LT(s.examined, 64u * b.size()) << s.examined << " bytes examined for a " << b.size() << "-byte file";
}

TEST(RecordFileLinearTime, DamagedHeadersClaimingMidSizeBodiesCostNoMoreThanAValidFileTimesTheBound) {
  // As above, but each damaged header claims a 64 KiB body (or the rest of the file): below the size
  // that was checked before reading, so each was read and CRC-checked in full (1,000 x its own bytes).
  const std::string path = tempPath("midheaders.rfx"), valid = tempPath("midheaders_valid.rfx");
  const std::size_t records = 20000;
  const std::vector<std::uint8_t> b = validRecordsWithDamagedHeaders(records, 64 * 1024);
  writeBytes(path, b, b.size());
  validRecording(valid, b.size());
  const ReadStats s = readAll(path), v = readAll(valid);
  std::printf(
      "damaged 64 KiB headers, %zu bytes: %.4f s, %llu bytes examined; valid %llu bytes examined: %.4f s "
      "(ratio %.1f)\n",
      b.size(), s.seconds, static_cast<unsigned long long>(s.examined), static_cast<unsigned long long>(v.examined),
      v.seconds, s.seconds / v.seconds);
  EXPECT_EQ(s.records, records);
  EXPECT_EQ(s.tail, TailState::kCorrupt);
  // Work: at most kCheckBeforeReading (1 KiB) or one check per damaged header; 64 KiB each was ~1,000 x.
  EXPECT_LT(s.examined, 64u * b.size()) << s.examined << " bytes examined for a " << b.size() << "-byte file";
  // The documented bound (record_file.hpp, bad_input 16.12a): within 100 x a valid file of the same size.
  EXPECT_LT(s.seconds / v.seconds, 100.0) << "damaged " << s.seconds << " s, valid " << v.seconds << " s";
}

// ---------------------------------------------------------------- Not a regular file
/// Runs `fn` in a child process; true if it finished within `seconds` (a blocked child is killed).
template <class Fn>
bool finishesWithin(double seconds, Fn fn) {
  const auto timeout = std::chrono::duration_cast<std::chrono::milliseconds>(std::chrono::duration<double>(seconds));
  return reflex::testing::runInChild(timeout, [&] {
           fn();
           return 0;
         }) == 0;
}

TEST(RecordFile, AFifoOrADeviceIsRefusedAtOnceNeverRead) {
  const std::string fifo = tempPath("recording.fifo");
  std::filesystem::remove(fifo);
  ASSERT_EQ(mkfifo(fifo.c_str(), 0600), 0);
  const std::string dir = tempPath("a_folder.rfx");
  std::filesystem::create_directories(dir);
  const std::vector<std::pair<std::string, std::string>> cases = {
      {fifo, "is a FIFO (named pipe)"}, {"/dev/zero", "is a character device"}, {dir, "is a directory"}};
  for (const auto& [path, kind] : cases) {
    // In a child process with a deadline: the old reader blocked forever on the FIFO.
    EXPECT_TRUE(finishesWithin(1.0, [&, p = path, k = kind] {
      try {
        RecordReader r(p);
        _exit(2);
      } catch (const RecordError& e) {
        const std::string what = e.what();
        _exit(what.find(p) != std::string::npos && what.find(k) != std::string::npos ? 0 : 3);
      }
    })) << path;
    // Appending to one is refused the same way (it reads the file first).
    EXPECT_TRUE(finishesWithin(1.0, [&, p = path] {
      try {
        WriterOptions o;
        o.append = true;
        RecordWriter w(p, o);
        _exit(p == "/dev/zero" ? 0 : 2);  // /dev/zero is empty for stat: nothing to read
      } catch (const RecordError&) {
        _exit(0);
      }
    })) << path;
  }
  std::filesystem::remove(fifo);
}

}  // namespace
}  // namespace reflex::record
