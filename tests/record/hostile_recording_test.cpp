// Hostile recordings against the reading side of reflex_record (mcap.cpp, cdr_check.cpp, export.cpp,
// cli.cpp), each file built here byte by byte. What is checked, against what:
//  - memory: `reflex_record info` / `export` run as a child process; its peak RSS (wait4's
//    ru_maxrss) stays < 200 MB where a length in the file claims 1 GiB (an MCAP chunk declaring
//    1 GiB uncompressed, plain or zstd, a zstd bomb that really expands to 1 GiB) or 16 M strings
//    (a JointState name count); and the tool says what it refused;
//  - time: `export --dir` of 3,000 one-message topics against the same 3,000 messages on one topic,
//    as a ratio in the same run (two passes whatever the number of topics);
//  - CSV file names: "reflex/heartbeat", "reflex_heartbeat", "reflex:heartbeat" are refused, named,
//    never written into one file; the other topics are exported;
//  - one undecodable sample: skipped, counted, named; every other sample written; exit 1;
//  - control bytes in topic names: printed as \xNN by info and export, never raw.
#include "cdr_check.hpp"
#include "reflex/record/mcap.hpp"
#include "reflex/record/recorder.hpp"
#include "record_support.hpp"
#include "samples.hpp"
#include "support/child_process.hpp"

#include <gtest/gtest.h>
#include <zstd.h>

#include <fcntl.h>
#include <spawn.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>

extern char** environ;

namespace reflex::record {
namespace {

std::string tempPath(const std::string& name) { return ::testing::TempDir() + "hostile_recording_test_" + name; }

std::string slurp(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

struct ToolRun {
  int exit_code = -1;
  long max_rss_kb = 0;
  double seconds = 0.0;
  std::string out, err;
};

/// Runs reflex_record with `args` (no shell), stdout and stderr into files. Its peak RSS from wait4 is
/// an upper bound: Linux carries the spawning process's RSS high-water mark across the exec, so the
/// test's own (up to ~80 MB after building the 20 MB sample) is included.
ToolRun runRecordTool(const std::vector<std::string>& args) {
  const std::string out = tempPath("tool.out"), err = tempPath("tool.err");
  std::vector<std::string> argv_s = {reflex::testing::binPath("reflex_record")};
  argv_s.insert(argv_s.end(), args.begin(), args.end());
  std::vector<char*> argv;
  for (std::string& a : argv_s) argv.push_back(a.data());
  argv.push_back(nullptr);
  posix_spawn_file_actions_t fa;
  posix_spawn_file_actions_init(&fa);
  posix_spawn_file_actions_addopen(&fa, 1, out.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0600);
  posix_spawn_file_actions_addopen(&fa, 2, err.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0600);
  ToolRun r;
  pid_t pid = -1;
  const auto t0 = std::chrono::steady_clock::now();
  const int rc = posix_spawn(&pid, argv[0], &fa, nullptr, argv.data(), environ);
  posix_spawn_file_actions_destroy(&fa);
  if (rc != 0) return r;
  int status = 0;
  rusage ru{};
  if (wait4(pid, &status, 0, &ru) != pid) return r;
  r.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  r.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
  r.max_rss_kb = ru.ru_maxrss;
  r.out = slurp(out);
  r.err = slurp(err);
  return r;
}

// ---- MCAP bytes --------------------------------------------------------------------------------------

void le(std::vector<std::uint8_t>& b, std::uint64_t v, int n) {
  for (int i = 0; i < n; ++i) b.push_back(static_cast<std::uint8_t>(v >> (8 * i)));
}
void str(std::vector<std::uint8_t>& b, const std::string& s) {
  le(b, s.size(), 4);
  b.insert(b.end(), s.begin(), s.end());
}

/// An MCAP file: magic, Header, one Chunk declaring `uncompressed` bytes with `records` as its
/// (compressed) content, and no summary (a file cut after the chunk reads as such).
std::vector<std::uint8_t> mcapWithChunk(std::uint64_t uncompressed, const std::string& compression,
                                        const std::vector<std::uint8_t>& records) {
  std::vector<std::uint8_t> b(kMcapMagic, kMcapMagic + 8);
  std::vector<std::uint8_t> header;
  str(header, "");
  str(header, "hostile");
  b.push_back(0x01);
  le(b, header.size(), 8);
  b.insert(b.end(), header.begin(), header.end());
  std::vector<std::uint8_t> chunk;
  le(chunk, 1, 8);  // start time
  le(chunk, 2, 8);  // end time
  le(chunk, uncompressed, 8);
  le(chunk, 0, 4);  // CRC 0: not checked
  str(chunk, compression);
  le(chunk, records.size(), 8);
  chunk.insert(chunk.end(), records.begin(), records.end());
  b.push_back(0x06);
  le(b, chunk.size(), 8);
  b.insert(b.end(), chunk.begin(), chunk.end());
  return b;
}

void writeFile(const std::string& path, const std::vector<std::uint8_t>& b) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(reinterpret_cast<const char*>(b.data()), static_cast<std::streamsize>(b.size()));
}

/// `total` zero bytes compressed by zstd, streamed (the test never holds them).
std::vector<std::uint8_t> zstdZeros(std::uint64_t total) {
  ZSTD_CCtx* c = ZSTD_createCCtx();
  ZSTD_CCtx_setParameter(c, ZSTD_c_compressionLevel, 1);
  ZSTD_CCtx_setPledgedSrcSize(c, total);
  const std::vector<std::uint8_t> zeros(1 << 20, 0);
  std::vector<std::uint8_t> out, buf(ZSTD_CStreamOutSize());
  for (std::uint64_t done = 0; done < total;) {
    const std::size_t n = static_cast<std::size_t>(std::min<std::uint64_t>(zeros.size(), total - done));
    done += n;
    ZSTD_inBuffer in{zeros.data(), n, 0};
    const ZSTD_EndDirective mode = done == total ? ZSTD_e_end : ZSTD_e_continue;
    for (;;) {
      ZSTD_outBuffer o{buf.data(), buf.size(), 0};
      const std::size_t left = ZSTD_compressStream2(c, &o, &in, mode);
      EXPECT_FALSE(ZSTD_isError(left));
      out.insert(out.end(), buf.begin(), buf.begin() + static_cast<std::ptrdiff_t>(o.pos));
      if (ZSTD_isError(left) || (mode == ZSTD_e_end ? left == 0 : in.pos == in.size)) break;
    }
  }
  ZSTD_freeCCtx(c);
  return out;
}

constexpr long kRssLimitKb = 200 * 1024;
constexpr std::uint64_t kGiB = 1ull << 30;

TEST(HostileMcap, AChunkDeclaringOneGibibyteIsRefusedBeforeAnyLargeAllocation) {
  struct Case {
    std::string name;
    std::vector<std::uint8_t> file;
    std::string expected;  // in the problem line
  };
  std::vector<Case> cases;
  // 1. ~600 bytes, uncompressed, declaring 1 GiB (before: 1,041 MB RSS).
  cases.push_back({"plain", mcapWithChunk(kGiB, "", std::vector<std::uint8_t>(540, 0)), "claims 1073741824"});
  // 2. A zstd bomb: a real frame of 1 GiB of zeros (a few tens of KB), declaring 1 GiB (before: ~1 GB, 11 s).
  const std::vector<std::uint8_t> bomb = zstdZeros(kGiB);
  cases.push_back({"zstd bomb", mcapWithChunk(kGiB, "zstd", bomb), "more than 1000 x"});
  // 3. The same bomb declaring what the ratio cap allows: decoding stops at the declared size.
  cases.push_back(
      {"zstd bomb within the ratio", mcapWithChunk(1000 * bomb.size(), "zstd", bomb), "more than the declared"});
  for (const Case& c : cases) {
    const std::string path = tempPath("chunk.mcap");
    writeFile(path, c.file);
    const ToolRun r = runRecordTool({"info", path});
    std::printf("%s: %zu-byte file, info exit %d, peak RSS %ld MB, %.2f s\n", c.name.c_str(), c.file.size(),
                r.exit_code, r.max_rss_kb / 1024, r.seconds);
    EXPECT_EQ(r.exit_code, 0) << c.name << ": " << r.err;  // a damaged chunk is reported, not fatal
    EXPECT_LT(r.max_rss_kb, kRssLimitKb) << c.name;
    EXPECT_NE(r.out.find("problem:"), std::string::npos) << c.name << ": " << r.out;
    EXPECT_NE(r.out.find(c.expected), std::string::npos) << c.name << ": " << r.out;
  }
}

TEST(HostileMcap, ValidCompressedChunksStillRead) {
  for (const std::string comp : {"zstd", "lz4", "none"}) {
    const std::string path = tempPath("valid_" + comp + ".mcap");
    {
      McapWriterOptions o;
      o.compression = parseMcapCompression(comp);
      o.chunk_bytes = 4096;
      McapSampleWriter w(path, o);
      for (int k = 1; k <= 200; ++k) w.append(test::encodeEntry(bus::test::jointState(k), 1'000'000'000LL * k));
      w.close();
    }
    const RecordingInfo info = scanRecording(path);
    EXPECT_EQ(info.records, 200u) << comp;
    EXPECT_EQ(info.tail, TailState::kClean) << comp << ": " << info.problem;
  }
}

// ---- samples ----------------------------------------------------------------------------------------

/// A JointState payload: header (stamp, seq, source "x"), then `names` as the name count followed by
/// `zeros` zero bytes (each 4 of them an empty string to fastcdr).
std::vector<std::uint8_t> jointStateClaiming(std::uint32_t names, std::size_t zeros) {
  std::vector<std::uint8_t> p = {0, 1, 0, 0};  // CDR little-endian
  le(p, 7, 8);                                 // stamp_ns
  le(p, 1, 8);                                 // seq
  le(p, 2, 4);                                 // source: 2 bytes with its terminator
  p.push_back('x');
  p.push_back(0);
  p.resize(4 + 24, 0);  // align 4
  le(p, names, 4);
  p.resize(p.size() + zeros, 0);
  return p;
}

TEST(HostileSamples, AJointStateClaimingSixteenMillionNamesIsRefusedWithoutAllocatingThem) {
  const std::string path = tempPath("names.rfx"), csv = tempPath("names.csv");
  {
    RecordWriter w(path);
    RecordEntry e = test::encodeEntry(bus::test::jointState(1), 1'000'000'000);
    w.append(e);
    e.receive_ns += 1'000'000;
    e.payload = jointStateClaiming(16u << 20, 20u << 20);  // fastcdr wants 1 byte per element: 20 MB given
    w.append(e);
    e.receive_ns += 1'000'000;
    e.payload = test::encodeEntry(bus::test::jointState(3), 0).payload;
    w.append(e);
    w.close();
  }
  const ToolRun r = runRecordTool({"export", path, "-t", "reflex/joint_state", "--csv", csv});
  std::printf("16 M names: export exit %d, peak RSS %ld MB, %.2f s\n%s", r.exit_code, r.max_rss_kb / 1024, r.seconds,
              r.err.c_str());
  EXPECT_LT(r.max_rss_kb, kRssLimitKb);
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("1 sample could not be decoded, first at sample 2 of the file"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("names: 16777216 elements claimed"), std::string::npos) << r.err;
  // The two good samples are written.
  const std::string text = slurp(csv);
  EXPECT_EQ(std::count(text.begin(), text.end(), '\n'), 3) << text;
}

TEST(HostileSamples, SequenceCountsAreBudgetedAgainstTheBytesLeftWithinTheBound) {
  // 60 names (within the bound of 64) but 20 bytes after the count: at least 4 bytes per string.
  const auto p = jointStateClaiming(60, 20);
  const std::string path = tempPath("short.rfx");
  {
    RecordWriter w(path);
    w.append(RecordEntry{1'000, 0, "reflex/joint_state", "reflex::msg::JointState", p});
    w.close();
  }
  const ToolRun r = runRecordTool({"export", path, "-t", "reflex/joint_state", "--csv", tempPath("short.csv")});
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("names: 60 elements claimed at byte 28 (at least 4 bytes each), 20 bytes left"),
            std::string::npos)
      << r.err;
}

TEST(HostileSamples, EveryTopicTypeIsCheckedAndItsValidSamplesPass) {
  // The check reads the types from the IDL text: a type it could not parse would silently go
  // unchecked. Every codec's type: a valid sample passes, the same cut after its encapsulation does not.
  const std::vector<RecordEntry> valid = {
      test::encodeEntry(bus::test::objectTargets(3), 1),        test::encodeEntry(bus::test::handTargets(3), 1),
      test::encodeEntry(bus::test::motionPriority(3), 1),       test::encodeEntry(bus::test::bodySchemaChange(3), 1),
      test::encodeEntry(bus::test::walkCommand(3), 1),          test::encodeEntry(bus::test::jointState(3), 1),
      test::encodeEntry(bus::test::controlStatus(3), 1),        test::encodeEntry(bus::test::heartbeat(3), 1),
      test::encodeEntry(bus::test::controllerProtection(3), 1), test::encodeEntry(bus::test::robotState(3), 1),
      test::encodeEntry(bus::test::jointCommand(3), 1),         test::encodeEntry(bus::test::robotContacts(3), 1),
      test::encodeEntry(bus::test::cameraImage(3), 1)};
  ASSERT_EQ(valid.size(), allCodecs().size());
  for (const RecordEntry& e : valid) {
    EXPECT_EQ(cdrLengthProblem(e.type, e.payload.data(), e.payload.size()), "") << e.type;
    EXPECT_NE(cdrLengthProblem(e.type, e.payload.data(), 4), "") << e.type;
  }
}

TEST(HostileSamples, OneUndecodableSampleIsSkippedCountedAndNamedAndTheRestWritten) {
  const std::string path = tempPath("one_bad.rfx"), dir = tempPath("one_bad_csv");
  std::filesystem::remove_all(dir);
  {
    RecordWriter w(path);
    for (int k = 1; k <= 5; ++k) {
      RecordEntry e = test::encodeEntry(bus::test::jointState(k), 1'000'000'000LL + k * 1'000'000LL);
      if (k == 3) e.payload = {0, 1, 0, 0, 9};  // cut inside the header
      w.append(e);
      w.append(test::encodeEntry(bus::test::heartbeat(k), 1'000'000'000LL + k * 1'000'000LL + 1));
    }
    w.close();
  }
  const ToolRun r = runRecordTool({"export", path, "--dir", dir});
  EXPECT_EQ(r.exit_code, 1) << r.err;
  EXPECT_NE(r.err.find("1 sample could not be decoded, first at sample 5 of the file (t = 0.002000 s)"),
            std::string::npos)
      << r.err;
  EXPECT_NE(r.err.find("reflex/joint_state"), std::string::npos) << r.err;
  const std::string js = slurp(dir + "/reflex_joint_state.csv"), hb = slurp(dir + "/reflex_heartbeat.csv");
  EXPECT_EQ(std::count(js.begin(), js.end(), '\n'), 5) << js;  // header + 4 samples
  EXPECT_EQ(std::count(hb.begin(), hb.end(), '\n'), 6) << hb;  // header + 5 samples
}

// ---- topic names ------------------------------------------------------------------------------------

TEST(HostileTopics, TopicsThatWouldShareACsvFileAreRefusedNamingThemAndTheOthersExported) {
  const std::string path = tempPath("collide.rfx"), dir = tempPath("collide_csv");
  std::filesystem::remove_all(dir);
  const std::vector<std::string> colliding = {"reflex/heartbeat", "reflex_heartbeat", "reflex:heartbeat"};
  {
    RecordWriter w(path);
    std::int64_t t = 1'000'000'000;
    for (const std::string& topic : colliding) {
      RecordEntry e = test::encodeEntry(bus::test::heartbeat(1), t += 1000);
      e.topic = topic;
      w.append(e);
    }
    w.append(test::encodeEntry(bus::test::jointState(1), t += 1000));
    w.close();
  }
  const ToolRun r = runRecordTool({"export", path, "--dir", dir});
  EXPECT_EQ(r.exit_code, 1) << r.err;
  for (const std::string& topic : colliding) EXPECT_NE(r.err.find("'" + topic + "'"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("would all be written to reflex_heartbeat.csv"), std::string::npos) << r.err;
  EXPECT_FALSE(std::filesystem::exists(dir + "/reflex_heartbeat.csv"));
  EXPECT_TRUE(std::filesystem::exists(dir + "/reflex_joint_state.csv"));
  // The names of other bytes are escaped, so they cannot meet: '%' itself too.
  EXPECT_EQ(csvFileNameForTopic("reflex/a\nb%c.d-e_f"), "reflex_a%0Ab%25c.d-e_f.csv");
  EXPECT_EQ(csvFileNameForTopic("../x"), ".._x.csv");
  EXPECT_TRUE(csvFileNameCollisions({"a/b", "a%2Fb", "a\\b"}).empty());
}

TEST(HostileTopics, ControlBytesInTopicNamesArePrintedEscaped) {
  const std::string path = tempPath("ctrl.rfx"), dir = tempPath("ctrl_csv");
  std::filesystem::remove_all(dir);
  const std::string evil = "reflex/evil\x1b[2J\rOK\n";
  {
    RecordWriter w(path);
    RecordEntry e = test::encodeEntry(bus::test::heartbeat(1), 1'000'000'000);
    e.topic = evil;
    w.append(e);
    w.close();
  }
  const ToolRun info = runRecordTool({"info", path, "--print", "1"});
  EXPECT_EQ(info.exit_code, 0) << info.err;
  const ToolRun exp = runRecordTool({"export", path, "--dir", dir});
  EXPECT_EQ(exp.exit_code, 0) << exp.err;
  for (const std::string& text : {info.out, exp.err}) {
    EXPECT_EQ(text.find('\x1b'), std::string::npos) << text;
    EXPECT_EQ(text.find('\r'), std::string::npos) << text;
    EXPECT_NE(text.find("reflex/evil\\x1B[2J\\x0DOK\\x0A"), std::string::npos) << text;
  }
  EXPECT_TRUE(std::filesystem::exists(dir + "/reflex_evil%1B%5B2J%0DOK%0A.csv"));
  EXPECT_EQ(printableName("a\\b\x7f"), "a\\x5Cb\\x7F");
}

// ---- export time -------------------------------------------------------------------------------------

TEST(HostileTopics, ExportDirOfThreeThousandTopicsTakesAboutAsLongAsThreeThousandSamplesOfOne) {
  const int n = 3000;
  const std::string many = tempPath("many.rfx"), one = tempPath("one.rfx");
  {
    RecordWriter wm(many), wo(one);
    for (int k = 0; k < n; ++k) {
      RecordEntry e = test::encodeEntry(bus::test::heartbeat(k), 1'000'000'000LL + k * 1000LL);
      char topic[32];
      std::snprintf(topic, sizeof(topic), "t/%04d", k);
      e.topic = topic;  // the same length as "t/one_": the two files have the same size
      wm.append(e);
      e.topic = "t/one_";
      wo.append(e);
    }
    wm.close();
    wo.close();
  }
  ASSERT_EQ(std::filesystem::file_size(many), std::filesystem::file_size(one));
  const std::string dm = tempPath("many_csv"), d1 = tempPath("one_csv");
  std::filesystem::remove_all(dm);
  std::filesystem::remove_all(d1);
  const ToolRun rm = runRecordTool({"export", many, "--dir", dm});
  const ToolRun r1 = runRecordTool({"export", one, "--dir", d1});
  std::printf("export --dir: %d topics of one sample %.3f s, one topic of %d samples %.3f s (ratio %.1f)\n", n,
              rm.seconds, n, r1.seconds, rm.seconds / r1.seconds);
  ASSERT_EQ(rm.exit_code, 0) << rm.err.substr(0, 2000);
  ASSERT_EQ(r1.exit_code, 0) << r1.err;
  EXPECT_EQ(std::distance(std::filesystem::directory_iterator(dm), std::filesystem::directory_iterator()), n);
  const std::string last = slurp(dm + "/t_2999.csv");
  EXPECT_EQ(std::count(last.begin(), last.end(), '\n'), 2) << last;
  // Two passes whatever the number of topics; the 3,000 files themselves cost some (before: 2 passes
  // per topic, 44 s).
  EXPECT_LT(rm.seconds / r1.seconds, 20.0);
}

}  // namespace
}  // namespace reflex::record
