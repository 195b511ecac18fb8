// Scene channels of MCAP recordings, real processes on domain 200:
// reflex_controller (joint state, status), reflex_fault_source (hand targets) and
// reflex_modules_object_publisher (objects) publish; reflex_record records them three times: MCAP
// (scene channels made live), .rfx (no scene channels; converted to MCAP afterwards, which adds them),
// and MCAP of reflex/control_status only (no joint state: no scene channels, said once). Independent
// answers, from the reference MCAP reader (@mcap/core) in scene_check.cjs:
//  - /tf and /reflex/scene exist with message encoding json, schema encoding jsonschema and the
//    foxglove schema names; every message validates against the schema in the file;
//  - every scene has the URDF's 17 capsules and 2 x 17 + 3 spheres, every /tf the URDF's links - 1
//    transforms parent -> child as the URDF's joints, counted from the URDF text;
//  - log times increase and lie within the recording; each /tf belongs to a recorded joint state (same
//    log time, timestamp = its header.stamp_ns), and for every 10th the transforms equal each joint's
//    origin and motion at the recorded position computed in JavaScript from the URDF (not by Reflex);
//  - at most 30 scenes per second of recording time (the default rate).
// And: converting the live MCAP file again makes byte-identical scene messages at the same log times
// (the channels depend on the recorded samples only); reflex_play and export --dir take a file with
// scene channels (they are not bus topics: not played, no CSV).
#include "mcap_check.hpp"

#include "reflex/record/mcap.hpp"
#include "reflex/record/recorder.hpp"
#include "reflex/record/recording.hpp"

#include <reflex/bus/bus.hpp>

#include <gtest/gtest.h>

#include <filesystem>
#include <thread>

namespace reflex::record {
namespace {

using mcap_check::json;
using mcap_check::slurp;
using namespace std::chrono_literals;

constexpr int kDomain = 200;  // 201: reflex_play, 202: a recorder alone

std::string bin(const std::string& name) { return std::string(REFLEX_BIN_DIR) + "/" + name; }
std::string tempPath(const std::string& name) { return ::testing::TempDir() + "record_scene_process_test_" + name; }
const std::string kUrdf = std::string(REFLEX_SOURCE_DIR) + "/bringup/robots/asimo_like.urdf";

int runTool(std::vector<std::string> argv, const std::string& log) {
  testing::ChildProcess p(std::move(argv), log);
  return p.wait(60s);
}

/// Runs scene_check.cjs on `file`; its JSON (null after a failure, reported).
json sceneCheck(const std::string& file, const std::string& name) {
  const std::string node = REFLEX_NODE;
  if (node.empty()) {
    ADD_FAILURE() << "node was not found at configure time: install Debian's nodejs (bringup/setup.sh)";
    return json();
  }
  const std::string out = tempPath(name + "_scene.json"), log = tempPath(name + "_scene.log");
  std::remove(out.c_str());
  testing::ChildProcess p(
      {node, std::string(REFLEX_SOURCE_DIR) + "/tests/record/scene_check.cjs", file, kUrdf, out, "10"}, log);
  const int rc = p.wait(std::chrono::minutes(2));
  if (rc != 0) {
    ADD_FAILURE() << "scene_check.cjs " << file << " exited " << rc << ":\n" << slurp(log);
    return json();
  }
  return json::parse(slurp(out));
}

/// The assertions every file with scene channels must pass (see the top of this file).
void expectSceneChannels(const json& r, const std::string& what) {
  SCOPED_TRACE(what);
  ASSERT_TRUE(r.is_object());
  ASSERT_EQ(r["channels"].size(), 2u) << r["channels"].dump();
  std::map<std::string, std::string> schema_of;
  for (const json& c : r["channels"]) {
    EXPECT_EQ(c["encoding"], "json");
    EXPECT_EQ(c["schema_encoding"], "jsonschema");
    schema_of[c["topic"]] = c["schema"];
  }
  EXPECT_EQ(schema_of["/tf"], "foxglove.FrameTransforms");
  EXPECT_EQ(schema_of["/reflex/scene"], "foxglove.SceneUpdate");
  const std::size_t scenes = r["counts"].value("/reflex/scene", 0), tfs = r["counts"].value("/tf", 0);
  EXPECT_GT(scenes, 30u) << "about 4 s at up to 30 per second";
  EXPECT_EQ(tfs, scenes);
  EXPECT_TRUE(r["schemaErrors"].empty()) << r["schemaErrors"].dump();
  // ... and against Foxglove's own published schemas (npm @foxglove/schemas, validated by ajv).
  EXPECT_EQ(r["officialChecked"].get<std::size_t>(), scenes + tfs) << "every scene and /tf message";
  EXPECT_EQ(r["expected"]["capsules"], 17) << "the shipped robot's URDF";
  for (const json& n : r["capsules"]) ASSERT_EQ(n, r["expected"]["capsules"]);
  for (const json& n : r["spheres"]) ASSERT_EQ(n, r["expected"]["spheres"]);
  for (const json& n : r["transforms"]) ASSERT_EQ(n, r["expected"]["transforms"]);
  EXPECT_TRUE(r["wrongFrames"].empty()) << r["wrongFrames"].dump();
  EXPECT_TRUE(r["monotonic"].get<bool>());
  EXPECT_TRUE(r["within"].get<bool>());
  EXPECT_EQ(r["tfWithoutJointState"], 0);
  EXPECT_EQ(r["tfStampMismatch"], 0);
  const json& fk = r["fk"];
  EXPECT_GE(fk["compared"].get<int>(), 3);
  EXPECT_EQ(fk["transforms"].get<int>(), fk["compared"].get<int>() * r["expected"]["transforms"].get<int>());
  EXPECT_LT(fk["maxTranslationError"].get<double>(), 1e-9) << fk.dump();
  EXPECT_LT(fk["maxRotationError"].get<double>(), 1e-6) << fk.dump();
  EXPECT_TRUE(fk["missingJoint"].empty()) << fk.dump();
  const double seconds = 1e-9 * static_cast<double>(std::stoll(r["scene_last_ns"].get<std::string>()) -
                                                    std::stoll(r["scene_first_ns"].get<std::string>()));
  ASSERT_GT(seconds, 2.0);
  const double rate = static_cast<double>(scenes - 1) / seconds;
  EXPECT_LE(rate, 30.0 + 1e-6) << "at most --scene-rate 30 per second of recording time";
  EXPECT_GE(rate, 15.0) << "joint states at 200 Hz give a scene about every 33-35 ms";
  std::printf("%s: %zu scenes, %.1f per second, FK compared on %d /tf (max %.2e m, %.2e rad)\n", what.c_str(), scenes,
              rate, fk["compared"].get<int>(), fk["maxTranslationError"].get<double>(),
              fk["maxRotationError"].get<double>());
}

/// (log time, payload) of the messages of `topic` in an MCAP file, by Reflex's reader.
std::vector<std::pair<std::int64_t, std::vector<std::uint8_t>>> messagesOf(const std::string& file,
                                                                           const std::string& topic) {
  std::vector<std::pair<std::int64_t, std::vector<std::uint8_t>>> out;
  McapSampleReader reader(file);
  RecordEntry e;
  while (reader.next(e))
    if (e.topic == topic) out.emplace_back(e.receive_ns, e.payload);
  return out;
}

int occurrences(const std::string& text, const std::string& what) {
  int n = 0;
  for (std::size_t at = text.find(what); at != std::string::npos; at = text.find(what, at + 1)) ++n;
  return n;
}

TEST(SceneChannels, RecordingsOfALiveBusCarryTheRobotForFoxglove) {
  const std::string dom = std::to_string(kDomain);
  const std::string live = tempPath("run.mcap"), rfx = tempPath("run.rfx"), status_only = tempPath("status.mcap");
  for (const auto& f : {live, rfx, status_only}) std::filesystem::remove(f);
  testing::ChildProcess controller({bin("reflex_controller"), "--domain", dom, "--duration", "14"},
                                   tempPath("controller.log"));
  testing::ChildProcess targets({bin("reflex_fault_source"), "--domain", dom, "--targets", "apart"},
                                tempPath("targets.log"));
  testing::ChildProcess objects(
      {bin("reflex_modules_object_publisher"), "--domain", dom, "--object", "red_cup=0.4,0.1,0.2", "--duration", "14"},
      tempPath("objects.log"));
  testing::ChildProcess rec_live({bin("reflex_record"), "record", "-o", live, "--domain", dom, "--chunk-ms", "200"},
                                 tempPath("live.log"));
  testing::ChildProcess rec_rfx({bin("reflex_record"), "record", "-o", rfx, "--domain", dom, "--name", "rfx"},
                                tempPath("rfx.log"));
  testing::ChildProcess rec_status({bin("reflex_record"), "record", "-o", status_only, "--domain", dom, "--name",
                                    "status", "-t", "reflex/control_status"},
                                   tempPath("status.log"));
  ASSERT_TRUE(controller.started() && targets.started() && objects.started() && rec_live.started() &&
              rec_rfx.started() && rec_status.started());
  bus::BusConfig cfg;
  cfg.module_name = "watch";
  cfg.domain_id = kDomain;
  {
    bus::Participant watch(cfg);
    auto& joints = watch.makeReader<msg::JointState>("reflex/joint_state", bus::kProfileRecord);
    auto& objs = watch.makeReader<msg::ObjectTargets>("reflex/object_targets", bus::kProfileRecord);
    ASSERT_TRUE(joints.waitForWriters(1, 20s));
    ASSERT_TRUE(objs.waitForWriters(1, 20s));
  }
  std::this_thread::sleep_for(4s);
  for (testing::ChildProcess* r : {&rec_live, &rec_rfx, &rec_status}) r->signal(SIGINT);
  ASSERT_EQ(rec_live.wait(15s), 0) << slurp(tempPath("live.log"));
  ASSERT_EQ(rec_rfx.wait(15s), 0) << slurp(tempPath("rfx.log"));
  ASSERT_EQ(rec_status.wait(15s), 0) << slurp(tempPath("status.log"));

  // The live MCAP recording, in the reference reader.
  const json live_check = sceneCheck(live, "live");
  expectSceneChannels(live_check, "live MCAP");
  const std::string live_log = slurp(tempPath("live.log"));
  EXPECT_NE(live_log.find("scene channels /tf and /reflex/scene: " +
                          std::to_string(live_check["counts"].value("/reflex/scene", 0)) + " scenes"),
            std::string::npos)
      << live_log;
  for (const json& c : live_check["channels"]) {
    if (c["topic"] == "/reflex/scene") {
      EXPECT_EQ(c["metadata"].value("robot", ""), "asimo_like") << c.dump();
    }
  }

  // Converting it again makes the same scene messages (from the recorded samples only).
  const std::string again = tempPath("again.mcap");
  ASSERT_EQ(runTool({bin("reflex_record"), "convert", live, again}, tempPath("again.log")), 0)
      << slurp(tempPath("again.log"));
  for (const char* topic : {"/tf", "/reflex/scene"}) {
    const auto a = messagesOf(live, topic), b = messagesOf(again, topic);
    EXPECT_EQ(a.size(), b.size()) << topic;
    EXPECT_TRUE(a == b) << topic << ": converted scene messages differ from the live ones";
  }

  // The .rfx recording has none; converted to MCAP it has them.
  EXPECT_NE(slurp(tempPath("rfx.log")).find("an .rfx recording has no scene channels"), std::string::npos);
  const std::string converted = tempPath("converted.mcap");
  ASSERT_EQ(runTool({bin("reflex_record"), "convert", rfx, converted, "--compression", "lz4"}, tempPath("convert.log")),
            0)
      << slurp(tempPath("convert.log"));
  EXPECT_NE(slurp(tempPath("convert.log")).find("scene channels /tf and /reflex/scene: "), std::string::npos)
      << slurp(tempPath("convert.log"));
  expectSceneChannels(sceneCheck(converted, "converted"), "converted .rfx");

  // Without the joint state: no scene channels, said once.
  const std::string status_log = slurp(tempPath("status.log"));
  EXPECT_EQ(occurrences(status_log, "no scene channels"), 1) << status_log;
  EXPECT_NE(status_log.find("reflex/joint_state is not recorded"), std::string::npos) << status_log;
  const RecordingInfo status_info = scanRecording(status_only);
  EXPECT_EQ(status_info.topics.size(), 1u);
  EXPECT_EQ(status_info.topics.count("/tf") + status_info.topics.count("/reflex/scene"), 0u);

  // Files with scene channels still play (every bus topic; the scene channels are not bus topics) and
  // export (one CSV per bus topic).
  const std::string dir = tempPath("csv");
  std::filesystem::remove_all(dir);
  ASSERT_EQ(runTool({bin("reflex_record"), "export", live, "--dir", dir}, tempPath("export.log")), 0)
      << slurp(tempPath("export.log"));
  EXPECT_TRUE(std::filesystem::exists(dir + "/reflex_joint_state.csv"));
  EXPECT_FALSE(std::filesystem::exists(dir + "/_tf.csv"));
  EXPECT_NE(
      slurp(tempPath("export.log")).find("/reflex/scene (foxglove.SceneUpdate) is not a Reflex topic type: no CSV"),
      std::string::npos);
  ASSERT_EQ(runTool({bin("reflex_play"), live, "--domain", std::to_string(kDomain + 1), "--rate", "8", "--delay", "0.2",
                     "--quiet"},
                    tempPath("play.log")),
            0)
      << slurp(tempPath("play.log"));
  EXPECT_NE(slurp(tempPath("play.log")).find("(0 failed)"), std::string::npos) << slurp(tempPath("play.log"));
  EXPECT_EQ(controller.wait(20s), 0);
}

TEST(SceneChannels, ARecordingWithoutJointStatesSaysSoOnce) {
  // Nobody publishes on domain 202: the joint state topic is recorded, but no sample comes.
  const std::string file = tempPath("empty.mcap"), log = tempPath("empty.log");
  ASSERT_EQ(
      runTool({bin("reflex_record"), "record", "-o", file, "--domain", std::to_string(kDomain + 2), "--duration", "1"},
              log),
      0)
      << slurp(log);
  EXPECT_EQ(occurrences(slurp(log), "no reflex/joint_state sample: no scene channels"), 1) << slurp(log);
  EXPECT_EQ(scanRecording(file).topics.count("/tf"), 0u);
  // A bad robot file is an error naming it, before any file is made.
  const std::string bad = tempPath("bad_urdf.mcap");
  std::filesystem::remove(bad);
  EXPECT_NE(runTool({bin("reflex_record"), "record", "-o", bad, "--domain", std::to_string(kDomain + 2), "--duration",
                     "1", "--urdf", "/nonexistent/robot.urdf"},
                    log),
            0);
  EXPECT_NE(slurp(log).find("/nonexistent/robot.urdf"), std::string::npos) << slurp(log);
  EXPECT_FALSE(std::filesystem::exists(bad));
  EXPECT_NE(runTool({bin("reflex_record"), "record", "-o", bad, "--domain", std::to_string(kDomain + 2), "--duration",
                     "1", "--scene-rate", "0"},
                    log),
            0);
  EXPECT_NE(slurp(log).find("--scene-rate 0 must be in (0, 200]"), std::string::npos) << slurp(log);
}

}  // namespace
}  // namespace reflex::record
