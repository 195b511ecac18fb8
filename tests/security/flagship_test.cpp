// The flagship experiment in secure mode: the shipped 60 s session replayed through
// reflex_vision -> reflex_behavior (pointing) -> reflex_controller with avoidance, recorded by
// reflex_record, every process with its own DDS-Security identity (run_flagship.py --only on --secure).
// The outcome must be the one the plain run gives: the criteria are flagship_outcome.hpp's, shared with
// flagship_test. A participant without credentials on the same domain sees the secure participants
// (SPDP is plain) but receives none of their samples. A bad --secure folder is refused before anything
// starts, naming it. Domain 119.
#include "../system/flagship_outcome.hpp"
#include "security_support.hpp"

#include <fastdds/dds/domain/DomainParticipantListener.hpp>
#include <fastdds/rtps/participant/ParticipantDiscoveryInfo.h>

#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <mutex>
#include <regex>
#include <set>
#include <sstream>
#include <thread>
#include <vector>

namespace reflex::security_test {
namespace {

using namespace std::chrono_literals;
constexpr int kDomain = 119;

/// Names of the participants a (plain) participant discovers; called on Fast DDS threads.
class DiscoveredNames final : public eprosima::fastdds::dds::DomainParticipantListener {
 public:
  void on_participant_discovery(eprosima::fastdds::dds::DomainParticipant*,
                                eprosima::fastrtps::rtps::ParticipantDiscoveryInfo&& info) override {
    if (info.status != eprosima::fastrtps::rtps::ParticipantDiscoveryInfo::DISCOVERED_PARTICIPANT) return;
    std::ostringstream guid;
    guid << info.info.m_guid.guidPrefix;
    const std::lock_guard<std::mutex> lock(mutex_);
    guids_.insert(guid.str());
    names_.insert(info.info.m_participantName.to_string());
  }
  std::size_t count() const {
    const std::lock_guard<std::mutex> lock(mutex_);
    return guids_.size();
  }
  std::string names() const {
    const std::lock_guard<std::mutex> lock(mutex_);
    std::string s;
    for (const auto& n : names_) s += (s.empty() ? "" : ", ") + n;
    return s;
  }

 private:
  mutable std::mutex mutex_;
  std::set<std::string> guids_, names_;
};

/// The sample count of `topic` in `reflex_record info` output, or -1.
long recordedCount(const std::string& info, const std::string& topic) {
  std::smatch m;
  if (!std::regex_search(info, m, std::regex(topic + R"(\s+\S+\s+(\d+))"))) return -1;
  return std::stol(m[1]);
}

std::string commandOutput(const std::string& cmd) { return reflex::testing::runShell(cmd).out; }

TEST(SecureFlagship, AvoidanceRunGivesThePlainOutcomeAndAnOutsiderReceivesNothing) {
  // The material is made by run_flagship.py itself (the folder does not exist yet): its --secure path.
  // One fixed folder, emptied first (a run leaves ~20 MB: recording, plots).
  const std::string base = ::testing::TempDir() + "reflex_security_flagship_test";
  std::filesystem::remove_all(base);
  ASSERT_TRUE(std::filesystem::create_directories(base));
  const std::string dir = base + "/security", out = base + "/out";

  // The outsider: plain participant on the run's domain, reading every topic the chain publishes.
  auto outsider = plainParticipant("outsider", kDomain);
  DiscoveredNames discovered;
  ASSERT_EQ(outsider->native().set_listener(&discovered, eprosima::fastdds::dds::StatusMask::none()),
            eprosima::fastrtps::types::ReturnCode_t::RETCODE_OK);
  auto& objects = outsider->makeReader<msg::ObjectTargets>("reflex/object_targets", bus::kProfileRecord);
  auto& targets = outsider->makeReader<msg::HandTargets>("reflex/hand_targets", bus::kProfileRecord);
  auto& priority = outsider->makeReader<msg::MotionPriority>("reflex/motion_priority", bus::kProfileRecord);
  auto& joints = outsider->makeReader<msg::JointState>("reflex/joint_state", bus::kProfileRecord);
  auto& status = outsider->makeReader<msg::ControlStatus>("reflex/control_status", bus::kProfileRecord);
  auto& heartbeats = outsider->makeReader<msg::Heartbeat>("reflex/heartbeat", bus::kProfileRecord);
  std::atomic<bool> done{false};
  std::atomic<std::size_t> received{0};
  std::atomic<int> matched{0};
  std::thread listen([&] {
    std::vector<msg::ObjectTargets> o;
    std::vector<msg::HandTargets> t;
    std::vector<msg::MotionPriority> p;
    std::vector<msg::JointState> j;
    std::vector<msg::ControlStatus> s;
    std::vector<msg::Heartbeat> h;
    while (!done) {
      received += objects.takeAll(o) + targets.takeAll(t) + priority.takeAll(p) + joints.takeAll(j) +
                  status.takeAll(s) + heartbeats.takeAll(h);
      matched = std::max<int>(matched, objects.stats().matched_writers + targets.stats().matched_writers +
                                           priority.stats().matched_writers + joints.stats().matched_writers +
                                           status.stats().matched_writers + heartbeats.stats().matched_writers);
      std::this_thread::sleep_for(100ms);
    }
  });

  const auto t0 = std::chrono::steady_clock::now();
  const flagship::Run run =
      flagship::runFlagship(out, "--only on --domain " + std::to_string(kDomain) + " --secure " + dir);
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  done = true;
  listen.join();
  ASSERT_EQ(run.exit_code, 0) << run.log;
  ASSERT_FALSE(run.summary.empty()) << run.log;

  // It ran secure: the material was made in dir, every process got its identity's profiles file.
  EXPECT_NE(run.log.find("DDS-Security, identities from " + dir), std::string::npos) << run.log;
  EXPECT_TRUE(std::filesystem::exists(dir + "/profiles/recorder.xml")) << run.log;
  EXPECT_EQ(flagship::flag(run.summary, "avoidance", "secure"), 1) << run.summary;
  const std::string report = readFile(out + "/report.md");
  EXPECT_NE(report.find("| DDS | secure (DDS-Security, identities from `" + dir + "`)"), std::string::npos) << report;

  // The same outcome as the plain run with avoidance.
  flagship::expectAvoidanceOutcome(run.summary, out + "/avoidance");

  // The recorder (its own identity) recorded the chain: vision's objects (10 Hz for 60 s), behavior's
  // hand targets, the controller's status (200 Hz); best effort on a loaded machine, hence the margins.
  const std::string info =
      commandOutput(std::string(REFLEX_BIN_DIR) + "/reflex_record info " + out + "/avoidance/bus.mcap");
  EXPECT_GT(recordedCount(info, "reflex/object_targets"), 400) << info;
  EXPECT_GT(recordedCount(info, "reflex/hand_targets"), 100) << info;
  EXPECT_GT(recordedCount(info, "reflex/control_status"), 6000) << info;

  // The outsider was on the domain the whole run (it discovered controller, behavior, recorder and
  // vision) and received nothing, matched nothing.
  EXPECT_GE(discovered.count(), 4u) << "discovered: " << discovered.names();
  EXPECT_EQ(received.load(), 0u) << "an unauthenticated participant read samples of the secure run";
  EXPECT_EQ(matched.load(), 0) << "an unauthenticated participant matched a secure writer";
  std::printf(
      "secure flagship: %.0f s, closest arms %.1f mm, closest pair %.1f mm, max f %.2f; outsider discovered "
      "%zu participants (%s), received %zu samples\n",
      seconds, 1000.0 * flagship::field(run.summary, "avoidance", "min_arm_distance_m"),
      1000.0 * flagship::field(run.summary, "avoidance", "min_distance_all_pairs_m"),
      flagship::field(run.summary, "avoidance", "max_f"), discovered.count(), discovered.names().c_str(),
      received.load());
}

TEST(SecureFlagship, ABadSecureFolderIsRefusedBeforeAnythingStartsNamingIt) {
  const std::string base = ::testing::TempDir() + "reflex_security_flagship_bad_test";
  std::filesystem::remove_all(base);
  ASSERT_TRUE(std::filesystem::create_directories(base));
  const std::string out = base + "/out";
  auto expectRefused = [&](const std::string& secure, const std::string& what) {
    SCOPED_TRACE("--secure " + secure);
    const flagship::Run run = flagship::runFlagship(
        out, "--only on --domain " + std::to_string(kDomain) + " --secure " + secure + " --no-report");
    EXPECT_EQ(run.exit_code, 2) << run.log;
    EXPECT_NE(run.log.find("--secure " + secure), std::string::npos) << run.log;
    EXPECT_NE(run.log.find(what), std::string::npos) << run.log;
    EXPECT_FALSE(std::filesystem::exists(out + "/avoidance")) << "nothing was started";
  };
  // A file, not a folder.
  writeFile(base + "/file", "not a folder\n");
  expectRefused(base + "/file", "not a folder");
  // A folder with something else in it (not made by make_security.sh, and not made over it).
  std::filesystem::create_directory(base + "/other");
  writeFile(base + "/other/notes.txt", "x\n");
  expectRefused(base + "/other", "no profiles/behavior.xml");
  EXPECT_FALSE(std::filesystem::exists(base + "/other/ca")) << "an existing folder is never written";
  // Material moved after it was made: its profiles name files of the old place.
  const std::string made = makeSecurityMaterial("flagship_moved");
  std::filesystem::rename(made, base + "/moved");
  expectRefused(base + "/moved", "which is missing or unreadable");
  // A profiles file without security properties (a plain profiles file in place of the identity's).
  std::filesystem::copy_file(kBaseProfiles, base + "/moved/profiles/behavior.xml",
                             std::filesystem::copy_options::overwrite_existing);
  expectRefused(base + "/moved", "profiles/behavior.xml holds no security properties");
}

}  // namespace
}  // namespace reflex::security_test
