// MCAP recording of a live bus, real processes on domain 120: reflex_controller
// (joint state, status, heartbeat), reflex_fault_source (hand targets, heartbeat) and
// reflex_modules_object_publisher (object targets) publish; two reflex_record processes record them,
// one stopped with SIGINT (a finished file), one killed with SIGKILL (a torn file). Independent
// answers:
//  - the finished file in the reference reader (@mcap/core McapIndexedReader + Foxglove's OMG IDL CDR
//    decoder, mcap_check.cjs): the index is found and used, Statistics count the messages the
//    project's `info` counts, and every decoded message equals its row of the project's CSV export,
//    column by column, for every recorded topic;
//  - the killed file: Reflex's reader and the reference stream reader read the same messages (every
//    complete chunk), the tail is reported torn, not corrupt;
//  - reflex_play plays the MCAP file at twice the speed on domain 121: the status stream arrives.
#include "mcap_check.hpp"

#include "reflex/record/recorder.hpp"
#include "reflex/record/recording.hpp"
#include "../bus/bus_test_util.hpp"

#include <reflex/bus/bus.hpp>

#include <gtest/gtest.h>

#include <filesystem>
#include <thread>

namespace reflex::record {
namespace {

using mcap_check::json;
using mcap_check::slurp;
using namespace std::chrono_literals;

constexpr int kDomain = 120;

std::string bin(const std::string& name) { return std::string(REFLEX_BIN_DIR) + "/" + name; }
std::string tempPath(const std::string& name) { return ::testing::TempDir() + "record_mcap_process_test_" + name; }
int runTool(std::vector<std::string> argv, const std::string& log) {
  testing::ChildProcess p(std::move(argv), log);
  return p.wait(60s);
}

TEST(McapProcess, LiveBusRecordingReadsInTheReferenceReaderAsInTheCsvExport) {
  const std::string dom = std::to_string(kDomain);
  const std::string finished = tempPath("run.mcap"), killed = tempPath("killed.mcap");
  testing::ChildProcess controller({bin("reflex_controller"), "--domain", dom, "--duration", "12"},
                                   tempPath("controller.log"));
  testing::ChildProcess targets({bin("reflex_fault_source"), "--domain", dom, "--targets", "apart"},
                                tempPath("targets.log"));
  testing::ChildProcess objects({bin("reflex_modules_object_publisher"), "--domain", dom, "--object",
                                 "red_cup=0.4,0.1,0.2", "--object", "blue_box=0.5,-0.2,0.1", "--duration", "12"},
                                tempPath("objects.log"));
  testing::ChildProcess recorder({bin("reflex_record"), "record", "-o", finished, "--domain", dom, "--chunk-ms", "200"},
                                 tempPath("recorder.log"));
  testing::ChildProcess victim({bin("reflex_record"), "record", "-o", killed, "--domain", dom, "--chunk-ms", "200",
                                "--compression", "lz4", "--name", "victim"},
                               tempPath("victim.log"));
  ASSERT_TRUE(controller.started() && targets.started() && objects.started() && recorder.started() && victim.started());
  {
    bus::Participant watch(bus::test::testConfig("watch", kDomain));
    auto& status = watch.makeReader<msg::ControlStatus>("reflex/control_status", bus::kProfileRecord);
    auto& objs = watch.makeReader<msg::ObjectTargets>("reflex/object_targets", bus::kProfileRecord);
    ASSERT_TRUE(status.waitForWriters(1, 20s));
    ASSERT_TRUE(objs.waitForWriters(1, 20s));
  }
  std::this_thread::sleep_for(4s);
  victim.signal(SIGKILL);
  EXPECT_EQ(victim.wait(5s), 128 + SIGKILL);
  recorder.signal(SIGINT);
  ASSERT_EQ(recorder.wait(15s), 0) << slurp(tempPath("recorder.log"));

  // The finished file: what the project's reader, info and CSV export see ...
  const RecordingInfo info = scanRecording(finished);
  EXPECT_EQ(info.format, "mcap");
  EXPECT_EQ(info.tail, TailState::kClean) << info.problem;
  // (reflex/controller_protection is published once at the controller's start: a recorder started
  // at the same time may or may not see it.)
  for (const char* t : {"reflex/control_status", "reflex/joint_state", "reflex/hand_targets", "reflex/object_targets",
                        "reflex/heartbeat"})
    EXPECT_EQ(info.topics.count(t), 1u) << t << "\n" << slurp(tempPath("recorder.log"));
  ASSERT_GT(info.topics.count("reflex/control_status") ? info.topics.at("reflex/control_status").samples : 0, 400u);
  const std::string dir = tempPath("csv");
  std::filesystem::remove_all(dir);
  ASSERT_EQ(runTool({bin("reflex_record"), "export", finished, "--dir", dir}, tempPath("export.log")), 0)
      << slurp(tempPath("export.log"));

  // ... equals what the reference reader decodes, through the index.
  const json idx = mcap_check::runReference("indexed", finished, tempPath("run"));
  ASSERT_TRUE(idx.is_object());
  EXPECT_EQ(idx["statistics"]["message_count"], std::to_string(info.records));
  EXPECT_EQ(idx["messages"].size(), info.records);
  EXPECT_EQ(idx["statistics"]["chunk_count"].get<std::size_t>(), idx["chunk_indexes"].size());
  EXPECT_GE(idx["chunk_indexes"].size(), 10u) << "200 ms chunks over about 5 s";
  const std::uint64_t size = idx["file_size"];
  EXPECT_TRUE(mcap_check::readFooterFirst(idx)) << idx["reads_before_messages"].dump();
  std::uint64_t read_before = 0;
  for (const json& r : idx["reads_before_messages"]) read_before += std::stoull(r[1].get<std::string>());
  EXPECT_LT(read_before, size / 4) << "the summary, not a scan of the file";
  for (const auto& kv : info.topics) {
    SCOPED_TRACE(kv.first);
    if (!findCodecByType(kv.second.type)) continue;  // the scene channels (record_scene_process_test): no CSV
    EXPECT_EQ(mcap_check::expectCsvMatches(idx["messages"], kv.first, dir + "/" + csvFileNameForTopic(kv.first)),
              kv.second.samples);
  }
  // Publish time is the writer's DDS source time, log time the receive time (and never before it).
  for (const json& m : idx["messages"])
    ASSERT_LE(std::stoull(m["publish_time"].get<std::string>()),
              std::stoull(m["log_time"].get<std::string>()) + 5'000'000)
        << m.dump();

  // The killed file: every complete chunk, in both readers; a torn tail.
  const auto reader = openRecording(killed);
  RecordEntry e;
  std::uint64_t n = 0;
  while (reader->next(e)) ++n;
  EXPECT_EQ(reader->tailState(), TailState::kTorn) << reader->problem();
  EXPECT_GT(n, 200u) << "about 4 s recorded, 200 ms chunks";
  const json st = mcap_check::runReference("stream", killed, tempPath("killed"));
  ASSERT_TRUE(st.is_object());
  EXPECT_FALSE(st["done"].get<bool>());
  EXPECT_EQ(st["messages"].size(), n);

  EXPECT_EQ(controller.wait(20s), 0);

  // reflex_play plays MCAP: the status stream at twice the speed on another domain.
  bus::Participant sink(bus::test::testConfig("watch", kDomain + 1));
  auto& replayed = sink.makeReader<msg::ControlStatus>("reflex/control_status", bus::kProfileRecord);
  testing::ChildProcess player({bin("reflex_play"), finished, "--domain", std::to_string(kDomain + 1), "--rate", "2",
                                "--topic", "reflex/control_status", "--wait-readers", "1", "--delay", "0"},
                               tempPath("play.log"));
  std::uint64_t got = 0;
  const auto start = std::chrono::steady_clock::now();
  while (std::chrono::steady_clock::now() - start < 12s) {
    msg::ControlStatus s;
    if (!replayed.waitForData(50ms)) {
      if (got > 0 && std::chrono::steady_clock::now() - start > 8s) break;
      continue;
    }
    while (replayed.takeNext(s)) ++got;
  }
  EXPECT_EQ(player.wait(15s), 0) << slurp(tempPath("play.log"));
  EXPECT_GE(got, info.topics.at("reflex/control_status").samples * 90 / 100) << slurp(tempPath("play.log"));
}

}  // namespace
}  // namespace reflex::record
