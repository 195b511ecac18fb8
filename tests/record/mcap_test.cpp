// MCAP recordings, checked against the reference implementation: @mcap/core
// (McapIndexedReader: footer, summary, chunk index, statistics; McapStreamReader) and Foxglove's OMG
// IDL CDR decoder, run by node (mcap_check.cjs). No DDS here (record_mcap_process_test records a live
// bus). Independent answers:
//  - every message of the fuzz seed (one sample of every topic type, twice), converted from .rfx with
//    `reflex_record convert` in none / zstd / lz4, decodes in the reference reader to the values of
//    the project's CSV export, column by column; the three files decode identically; the CSV of the
//    MCAP equals the CSV of the .rfx byte for byte (the conversion loses nothing);
//  - the indexed reader finds the index: its first read is the footer at the end of the file, it reads
//    less than the file before the messages, its chunk count and message count (Statistics) are the
//    writer's;
//  - a file cut at EVERY byte offset: Reflex's reader yields exactly the messages of the chunks that
//    end before the cut (chunk offsets from the reference reader's chunk index, message counts per
//    chunk from its stream reader), reports a torn tail, never corrupt, never crashes; the reference
//    stream reader reads the same count at every cut;
//  - the robot boundary (RobotState, JointCommand, RobotContacts; samples.hpp's distinctive values):
//    written to MCAP, they decode in the reference reader with the schemas made from robot.idl to the
//    values of the CSV export, column by column (per-joint columns, a short efforts list, one row per
//    contact pair);
//  - bad inputs: not an MCAP file, cut inside the magic, a damaged chunk (named with its byte offset;
//    the reference reader rejects its CRC too), a damaged message index (data section CRC), unknown
//    --compression / --format values, --append on MCAP: errors naming the value.
#include "mcap_check.hpp"

#include "reflex/record/recorder.hpp"
#include "reflex/record/recording.hpp"

#include <reflex/bus/bus.hpp>

#include "samples.hpp"
#include "record_support.hpp"

#include <gtest/gtest.h>

#include <filesystem>
#include <unistd.h>

namespace reflex::record {
namespace {

using mcap_check::json;
using mcap_check::slurp;
using namespace std::chrono_literals;

std::string bin(const std::string& name) { return std::string(REFLEX_BIN_DIR) + "/" + name; }
std::string tempPath(const std::string& name) { return ::testing::TempDir() + "record_mcap_test_" + name; }
std::string seedPath() { return std::string(REFLEX_SOURCE_DIR) + "/tests/fuzz/seeds/recording.rfx"; }

int runTool(std::vector<std::string> argv, const std::string& log) {
  testing::ChildProcess p(std::move(argv), log);
  return p.wait(60s);
}

std::vector<RecordEntry> readAll(const std::string& path) {
  std::vector<RecordEntry> out;
  const auto reader = openRecording(path);
  RecordEntry e;
  while (reader->next(e)) out.push_back(e);
  return out;
}

void flipByte(const std::string& path, std::uint64_t offset) {
  std::fstream f(path, std::ios::in | std::ios::out | std::ios::binary);
  f.seekg(static_cast<std::streamoff>(offset));
  char c = 0;
  f.get(c);
  f.seekp(static_cast<std::streamoff>(offset));
  f.put(static_cast<char>(c ^ 0x5A));
}

TEST(Mcap, ConvertedRecordingDecodesInTheReferenceReaderAsInTheCsvExport) {
  const std::string seed = seedPath();
  const RecordingInfo seed_info = scanRecording(seed);
  ASSERT_EQ(seed_info.records, 16u);
  const std::string rfx_csv = tempPath("csv_rfx");
  std::filesystem::remove_all(rfx_csv);
  ASSERT_EQ(runTool({bin("reflex_record"), "export", seed, "--dir", rfx_csv}, tempPath("export_rfx.log")), 0);

  json first_messages;
  for (const std::string comp : {"none", "zstd", "lz4"}) {
    SCOPED_TRACE(comp);
    const std::string file = tempPath(comp + ".mcap");
    // --no-scene: the copy alone (the scene channels convert adds: record_scene_process_test).
    ASSERT_EQ(runTool({bin("reflex_record"), "convert", seed, file, "--compression", comp, "--chunk-size", "300",
                       "--no-scene"},
                      tempPath("convert.log")),
              0)
        << slurp(tempPath("convert.log"));
    // Reflex's own reader: clean, every sample, the same bytes as the .rfx.
    McapReader own(file);
    McapMessageRecord m;
    std::uint64_t n = 0;
    while (own.next(m)) ++n;
    EXPECT_EQ(own.tailState(), TailState::kClean) << own.problem();
    EXPECT_EQ(n, 16u);
    const auto from_rfx = readAll(seed), from_mcap = readAll(file);
    ASSERT_EQ(from_rfx.size(), from_mcap.size());
    for (std::size_t i = 0; i < from_rfx.size(); ++i) {
      EXPECT_EQ(from_rfx[i].payload, from_mcap[i].payload) << i;
      EXPECT_EQ(from_rfx[i].topic, from_mcap[i].topic) << i;
      EXPECT_EQ(from_rfx[i].type, from_mcap[i].type) << i;
      EXPECT_EQ(from_rfx[i].receive_ns, from_mcap[i].receive_ns) << i;
      EXPECT_EQ(from_rfx[i].source_ns, from_mcap[i].source_ns) << i;
    }

    // The reference indexed reader: index found and used, statistics as written.
    const json idx = mcap_check::runReference("indexed", file, tempPath(comp));
    ASSERT_TRUE(idx.is_object());
    EXPECT_EQ(idx["library"], "reflex");
    EXPECT_EQ(idx["statistics"]["message_count"], "16");
    EXPECT_EQ(idx["statistics"]["chunk_count"].get<std::uint64_t>(), own.chunksRead());
    EXPECT_EQ(idx["chunk_indexes"].size(), own.chunksRead());
    EXPECT_GE(own.chunksRead(), 5u) << "300-byte chunks: several";
    EXPECT_EQ(idx["statistics"]["channel_count"], seed_info.topics.size());
    for (const json& c : idx["chunk_indexes"]) EXPECT_EQ(c["compression"], comp == "none" ? "" : comp);
    for (const json& c : idx["channels"]) {
      EXPECT_EQ(c["encoding"], "cdr");
      EXPECT_EQ(c["schema_encoding"], "omgidl");
      EXPECT_EQ(c["schema"], seed_info.topics.at(c["topic"].get<std::string>()).type);
    }
    const std::uint64_t size = idx["file_size"];
    std::uint64_t read_before = 0;
    for (const json& r : idx["reads_before_messages"]) read_before += std::stoull(r[1].get<std::string>());
    EXPECT_TRUE(mcap_check::readFooterFirst(idx)) << idx["reads_before_messages"].dump();
    EXPECT_LT(read_before, size) << "the summary, not a scan of the file";
    ASSERT_EQ(idx["messages"].size(), 16u);
    if (first_messages.is_null()) first_messages = idx["messages"];
    EXPECT_EQ(idx["messages"], first_messages) << "none / zstd / lz4 decode identically";

    // The reference stream reader agrees.
    const json st = mcap_check::runReference("stream", file, tempPath(comp));
    EXPECT_TRUE(st["done"].get<bool>());
    EXPECT_EQ(st["messages"], idx["messages"]);

    // Every column of the CSV export of the MCAP file equals the decoded value; the CSV equals the .rfx one.
    const std::string dir = tempPath("csv_" + comp);
    std::filesystem::remove_all(dir);
    ASSERT_EQ(runTool({bin("reflex_record"), "export", file, "--dir", dir}, tempPath("export.log")), 0)
        << slurp(tempPath("export.log"));
    for (const auto& kv : seed_info.topics) {
      const std::string csv = dir + "/" + csvFileNameForTopic(kv.first);
      EXPECT_EQ(mcap_check::expectCsvMatches(idx["messages"], kv.first, csv), kv.second.samples) << kv.first;
      EXPECT_EQ(slurp(csv), slurp(rfx_csv + "/" + csvFileNameForTopic(kv.first))) << kv.first;
    }
  }
}

/// A small uncompressed file of many chunks for the cut tests (the seed's samples, 4 passes).
std::string writeSmallFile(const std::string& name, McapCompression comp = McapCompression::kNone) {
  const std::string file = tempPath(name);
  McapWriterOptions o;
  o.compression = comp;
  o.chunk_bytes = 400;
  McapSampleWriter w(file, o);
  const auto seed = readAll(seedPath());
  for (int pass = 0; pass < 4; ++pass)
    for (RecordEntry e : seed) {
      if (e.topic != "reflex/joint_state" && e.topic != "reflex/control_status" && e.topic != "reflex/hand_targets")
        continue;
      e.receive_ns += pass * 1'000'000'000LL;
      w.append(e);
    }
  w.close();
  return file;
}

TEST(Mcap, FileCutAtEveryByteYieldsEveryCompleteChunk) {
  const std::string file = writeSmallFile("torn_source.mcap");
  const json idx = mcap_check::runReference("indexed", file, tempPath("torn"));
  const json st = mcap_check::runReference("stream", file, tempPath("torn"));
  ASSERT_TRUE(idx.is_object() && st.is_object());
  ASSERT_EQ(idx["chunk_indexes"].size(), st["chunks"].size());
  ASSERT_GE(st["chunks"].size(), 6u);
  const std::vector<RecordEntry> all = readAll(file);
  ASSERT_EQ(all.size(), 24u);
  // Messages a reader must yield from the first `cut` bytes: those of every chunk that ends by then.
  std::vector<std::pair<std::uint64_t, std::uint64_t>> chunk_end_count;
  for (std::size_t i = 0; i < st["chunks"].size(); ++i)
    chunk_end_count.emplace_back(std::stoull(idx["chunk_indexes"][i]["offset"].get<std::string>()) +
                                     std::stoull(idx["chunk_indexes"][i]["length"].get<std::string>()),
                                 st["chunks"][i]["messages"].get<std::uint64_t>());
  const auto expected = [&](std::uint64_t cut) {
    std::uint64_t n = 0;
    for (const auto& [end, count] : chunk_end_count)
      if (end <= cut) n += count;
    return n;
  };

  // Reflex's reader at every byte offset (the file truncated in place, from the end down).
  const std::string torn = tempPath("torn.mcap");
  std::filesystem::copy_file(file, torn, std::filesystem::copy_options::overwrite_existing);
  const auto size = std::filesystem::file_size(file);
  int failures = 0;
  for (std::uint64_t cut = size; cut + 1 > 0; --cut) {
    ASSERT_EQ(::truncate(torn.c_str(), static_cast<off_t>(cut)), 0);
    if (cut < 8) {
      try {
        McapReader r(torn);
        ADD_FAILURE() << "a file of " << cut << " bytes opened";
      } catch (const RecordError& e) {
        EXPECT_NE(std::string(e.what()).find("cut inside its magic (" + std::to_string(cut) + " of 8 bytes)"),
                  std::string::npos)
            << e.what();
      }
      continue;
    }
    McapSampleReader r(torn);
    RecordEntry e;
    std::uint64_t n = 0;
    bool same = true;
    while (r.next(e)) same = same && n < all.size() && e.payload == all[n].payload && e.topic == all[n].topic, ++n;
    const TailState want = cut == size ? TailState::kClean : TailState::kTorn;
    if ((n != expected(cut) || !same || r.tailState() != want) && ++failures <= 10)
      ADD_FAILURE() << "cut at " << cut << " of " << size << ": " << n << " messages (want " << expected(cut)
                    << "), same " << same << ", tail " << toString(r.tailState()) << " " << r.problem();
  }
  EXPECT_EQ(failures, 0);

  // The reference stream reader on every prefix agrees.
  const json cuts = mcap_check::runReference("torn", file, tempPath("torn"), "1");
  ASSERT_TRUE(cuts.is_object());
  ASSERT_EQ(cuts["counts"].size(), size + 1) << "every byte offset";
  failures = 0;
  for (const json& c : cuts["counts"]) {
    const std::uint64_t cut = c[0];
    if (c[1].get<long long>() != static_cast<long long>(expected(cut)) && ++failures <= 10)
      ADD_FAILURE() << "reference reader, cut at " << cut << ": " << c.dump() << " (want " << expected(cut) << ")";
  }
  EXPECT_EQ(failures, 0);
}

TEST(Mcap, DamagedBytesNeverYieldAForeignPayload) {
  // 1500 copies of a small file, each with one byte changed at a random offset: Reflex's reader
  // never crashes, never loops, and every payload it returns is one the writer wrote (chunks are
  // CRC-checked), in order.
  const std::string file = writeSmallFile("flip_source.mcap", McapCompression::kZstd);
  const std::vector<RecordEntry> all = readAll(file);
  const auto size = std::filesystem::file_size(file);
  const std::string damaged = tempPath("flip.mcap");
  std::uint64_t state = 12345;
  int corrupt = 0;
  for (int i = 0; i < 1500; ++i) {
    std::filesystem::copy_file(file, damaged, std::filesystem::copy_options::overwrite_existing);
    state = state * 6364136223846793005ULL + 1442695040888963407ULL;
    flipByte(damaged, 8 + (state >> 33) % (size - 8));
    McapSampleReader r(damaged);
    RecordEntry e;
    std::size_t next = 0;
    while (r.next(e)) {
      while (next < all.size() && all[next].payload != e.payload) ++next;
      ASSERT_LT(next, all.size()) << "a payload the writer never wrote, flip " << i;
      ++next;
    }
    corrupt += r.tailState() == TailState::kCorrupt;
  }
  EXPECT_GT(corrupt, 500) << "most flips are found by a CRC";
}

TEST(Mcap, BadInputsAreNamed) {
  // Not an MCAP file (nor .rfx).
  const std::string text = tempPath("text.mcap");
  std::ofstream(text) << "hello, this is not a recording\n";
  const auto message = [](const std::function<void()>& f) {
    try {
      f();
    } catch (const RecordError& e) {
      return std::string(e.what());
    }
    return std::string("(no error)");
  };
  EXPECT_NE(message([&] { openRecording(text); }).find("is not a Reflex recording"), std::string::npos);
  EXPECT_NE(message([&] { McapReader r(text); }).find("is not an MCAP file"), std::string::npos);
  // Cut inside the magic: named as such, not "not a recording".
  const std::string stub = tempPath("stub.mcap");
  std::ofstream(stub, std::ios::binary).write(reinterpret_cast<const char*>(kMcapMagic), 5);
  EXPECT_NE(message([&] { openRecording(stub); }).find("cut inside its magic (5 of 8 bytes)"), std::string::npos)
      << message([&] { openRecording(stub); });

  // A damaged chunk: skipped and named with its offset; the other chunks still read; the reference
  // reader rejects the same chunk's CRC.
  const std::string good = writeSmallFile("good.mcap");
  const json idx = mcap_check::runReference("indexed", good, tempPath("bad"));
  const json st = mcap_check::runReference("stream", good, tempPath("bad"));
  ASSERT_TRUE(idx.is_object() && st.is_object());
  const std::uint64_t chunk2 = std::stoull(idx["chunk_indexes"][2]["offset"].get<std::string>());
  const std::uint64_t chunk2_len = std::stoull(idx["chunk_indexes"][2]["length"].get<std::string>());
  const std::string bad = tempPath("bad_chunk.mcap");
  std::filesystem::copy_file(good, bad, std::filesystem::copy_options::overwrite_existing);
  flipByte(bad, chunk2 + chunk2_len - 3);  // inside the chunk's last message
  {
    McapSampleReader r(bad);
    RecordEntry e;
    std::uint64_t n = 0;
    while (r.next(e)) ++n;
    EXPECT_EQ(r.tailState(), TailState::kCorrupt);
    EXPECT_EQ(n, 24u - st["chunks"][2]["messages"].get<std::uint64_t>());
    EXPECT_NE(r.problem().find("chunk at byte " + std::to_string(chunk2) + ": CRC mismatch"), std::string::npos)
        << r.problem();
  }
  ASSERT_EQ(runTool({bin("reflex_record"), "info", bad}, tempPath("info_bad.log")), 0);
  EXPECT_NE(slurp(tempPath("info_bad.log")).find("chunk at byte " + std::to_string(chunk2)), std::string::npos)
      << slurp(tempPath("info_bad.log"));
  {
    const std::string log = tempPath("ref_bad.log");
    testing::ChildProcess p({REFLEX_NODE, std::string(REFLEX_SOURCE_DIR) + "/tests/record/mcap_check.cjs", "stream",
                             bad, tempPath("ref_bad.json")},
                            log);
    EXPECT_EQ(p.wait(60s), 1);
    EXPECT_NE(slurp(log).find("Incorrect chunk CRC"), std::string::npos) << slurp(log);
  }
  // A damaged message index (outside every chunk): the data section CRC names the DataEnd record.
  const std::string bad_index = tempPath("bad_index.mcap");
  std::filesystem::copy_file(good, bad_index, std::filesystem::copy_options::overwrite_existing);
  flipByte(bad_index, chunk2 + chunk2_len + 9 + 2 + 4 + 3);  // a log time in the first message index
  {
    McapSampleReader r(bad_index);
    RecordEntry e;
    std::uint64_t n = 0;
    while (r.next(e)) ++n;
    EXPECT_EQ(n, 24u) << "the messages themselves are intact";
    EXPECT_EQ(r.tailState(), TailState::kCorrupt);
    EXPECT_NE(r.problem().find("data section CRC mismatch (DataEnd at byte "), std::string::npos) << r.problem();
  }

  // Command-line values.
  struct Case {
    std::vector<std::string> args;
    std::string needle;
  };
  const std::vector<Case> cases = {
      {{bin("reflex_record"), "convert", seedPath(), tempPath("x.mcap"), "--compression", "brotli"}, "'brotli'"},
      {{bin("reflex_record"), "convert", seedPath(), tempPath("x.mcap"), "--format", "bag"}, "'bag'"},
      {{bin("reflex_record"), "convert", text, tempPath("x.mcap")}, "not a Reflex recording"},
      {{bin("reflex_record"), "info", stub}, "cut inside its magic"},
      {{bin("reflex_record"), "convert", good, good}, "is the input recording"},
      {{bin("reflex_record"), "record", "-o", tempPath("x.mcap"), "--append", "--domain", "129"}, "--append"},
      {{bin("reflex_record"), "record", "-o", tempPath("x.mcap"), "--compression", "gzip", "--domain", "129"},
       "'gzip'"},
  };
  for (const Case& c : cases) {
    const std::string log = tempPath("cli.log");
    EXPECT_NE(runTool(c.args, log), 0) << c.args[1] << " " << c.needle;
    EXPECT_NE(slurp(log).find(c.needle), std::string::npos) << c.needle << ": " << slurp(log);
  }
}

TEST(Mcap, WriterTakesChannelsOfAnyEncoding) {
  // A JSON channel with a JSON schema beside a CDR one (the scene channels of the live view), and a
  // file without messages: both read back, in Reflex's reader and the reference indexed reader.
  const std::string file = tempPath("json.mcap");
  {
    McapWriter w(file, {});
    const std::uint16_t scene = w.addChannel(
        {"scene", "json", "foxglove.SceneUpdate", "jsonschema", R"({"type":"object"})", {{"origin", "test"}}});
    const std::string msg = R"({"entities":[]})";
    w.write(scene, 1, 5, 5, reinterpret_cast<const std::uint8_t*>(msg.data()), msg.size());
    w.close();
  }
  McapReader r(file);
  McapMessageRecord m;
  ASSERT_TRUE(r.next(m));
  EXPECT_EQ(std::string(m.data.begin(), m.data.end()), R"({"entities":[]})");
  ASSERT_NE(r.channel(m.channel_id), nullptr);
  EXPECT_EQ(r.channel(m.channel_id)->message_encoding, "json");
  EXPECT_EQ(r.channel(m.channel_id)->metadata.at("origin"), "test");
  EXPECT_EQ(r.schema(r.channel(m.channel_id)->schema_id)->encoding, "jsonschema");
  EXPECT_FALSE(r.next(m));
  EXPECT_EQ(r.tailState(), TailState::kClean) << r.problem();

  const std::string empty = tempPath("empty.mcap");
  McapWriter(empty, {}).close();
  const json idx = mcap_check::runReference("indexed", empty, tempPath("empty"));
  ASSERT_TRUE(idx.is_object());
  EXPECT_EQ(idx["statistics"]["message_count"], "0");
  EXPECT_EQ(idx["statistics"]["chunk_count"], 0);
  EXPECT_TRUE(idx["messages"].empty());
  EXPECT_EQ(readAll(empty).size(), 0u);
}

// The robot types: their MCAP schemas (from robot.idl) decode in Foxglove's OMG IDL reader
// to the values of the project's CSV export.
TEST(Mcap, RobotTypesDecodeInTheReferenceReaderAsInTheCsvExport) {
  const std::string file = tempPath("robot.mcap");
  {
    McapSampleWriter w(file, {});
    for (int k = 0; k < 3; ++k) {
      const std::int64_t t = 1'700'000'000'000'000'000LL + k * 1'000'000LL;
      msg::RobotContacts contacts = bus::test::robotContacts(k);
      if (k == 1) contacts.contacts().clear();  // a sample without pairs: one row of empty cells
      w.append(test::encodeEntry(bus::test::robotState(k), t));
      w.append(test::encodeEntry(bus::test::jointCommand(k), t + 1));
      w.append(test::encodeEntry(contacts, t + 2));
    }
    w.close();
  }
  const json idx = mcap_check::runReference("indexed", file, tempPath("robot"));
  ASSERT_TRUE(idx.is_object());
  ASSERT_EQ(idx["messages"].size(), 9u);
  for (const json& c : idx["channels"]) EXPECT_EQ(c["schema_encoding"], "omgidl");
  const std::string dir = tempPath("csv_robot");
  std::filesystem::remove_all(dir);
  ASSERT_EQ(runTool({bin("reflex_record"), "export", file, "--dir", dir}, tempPath("export_robot.log")), 0)
      << slurp(tempPath("export_robot.log"));
  for (const std::string topic : {"reflex/robot_state", "reflex/joint_command", "reflex/robot_contacts"})
    EXPECT_EQ(mcap_check::expectCsvMatches(idx["messages"], topic, dir + "/" + csvFileNameForTopic(topic)), 3u)
        << topic;
}

}  // namespace
}  // namespace reflex::record
