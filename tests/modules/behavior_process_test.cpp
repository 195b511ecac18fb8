// reflex_behavior as a real process over real DDS (domain 61): one configuration (pointing), then
// another (scripted) with the same binary, fed by a separate synthetic object publisher; one module
// of a multi-module file as its own process; heartbeats; clean stop; start-up errors.
#include "support/child_process.hpp"

#include <reflex/bus/bus.hpp>
#include <reflex/control/kinematics.hpp>
#include <reflex/control/urdf_loader.hpp>

#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <fstream>
#include <memory>
#include <map>
#include <tuple>
#include <sstream>
#include <thread>

namespace reflex::modules {
namespace {

using namespace std::chrono_literals;
using Child = reflex::testing::ChildProcess;

/// The integer after "<key>=" in `text` (the last occurrence), or -1.
long statValue(const std::string& text, const std::string& key) {
  const auto pos = text.rfind(" " + key + "=");
  if (pos == std::string::npos) return -1;
  return std::stol(text.substr(pos + key.size() + 2));
}

constexpr int kDomain = 61;
const std::string kBin = REFLEX_BIN_DIR;
const std::string kBehaviorDir = std::string(REFLEX_SOURCE_DIR) + "/bringup/behavior";

// The test's own view of the bus.
struct Observer {
  bus::Participant participant;
  bus::Reader<msg::HandTargets>& all_hands;  // every sample (record profile, deep history)
  bus::Reader<msg::HandTargets>& hands;      // the current state (reliable, transient local)
  bus::Reader<msg::MotionPriority>& priority;
  bus::Reader<msg::BodySchemaChange>& schema;
  bus::Reader<msg::Heartbeat>& heartbeat;

  std::vector<msg::HandTargets> hand_log;
  std::vector<msg::BodySchemaChange> schema_log;
  std::vector<msg::MotionPriority> priority_log;
  std::vector<msg::Heartbeat> heartbeat_log;
  msg::HandTargets last_hands;
  bool have_hands = false;

  Observer()
      : participant(config()),
        all_hands(participant.makeReader<msg::HandTargets>("reflex/hand_targets", bus::kProfileRecord)),
        hands(participant.makeReader<msg::HandTargets>()),
        priority(participant.makeReader<msg::MotionPriority>()),
        schema(participant.makeReader<msg::BodySchemaChange>()),
        heartbeat(participant.makeReader<msg::Heartbeat>()) {}

  static bus::BusConfig config() {
    bus::BusConfig c;
    c.module_name = "modules_test";
    c.domain_id = kDomain;
    return c;
  }
  void collect(std::chrono::milliseconds d) {
    const auto end = std::chrono::steady_clock::now() + d;
    while (std::chrono::steady_clock::now() < end) {
      msg::HandTargets h;
      while (all_hands.takeNext(h)) hand_log.push_back(h);
      while (hands.takeNext(h)) {
        last_hands = h;
        have_hands = true;
      }
      msg::BodySchemaChange s;
      while (schema.takeNext(s)) schema_log.push_back(s);
      msg::MotionPriority p;
      while (priority.takeNext(p)) priority_log.push_back(p);
      msg::Heartbeat b;
      while (heartbeat.takeNext(b)) heartbeat_log.push_back(b);
      std::this_thread::sleep_for(5ms);
    }
  }
  /// Collects until `done()` holds (checked every 100 ms) or `limit` has passed; what done() said.
  /// For what a process publishes once: on a loaded two-core machine discovery alone can take
  /// seconds (a fixed 2 s window once missed the grasped bar in CI).
  template <class Pred>
  bool collectUntil(Pred done, std::chrono::milliseconds limit) {
    const auto end = std::chrono::steady_clock::now() + limit;
    do {
      collect(100ms);
      if (done()) return true;
    } while (std::chrono::steady_clock::now() < end);
    return false;
  }
  void clear() {
    collect(200ms);
    hand_log.clear();
    schema_log.clear();
    priority_log.clear();
    heartbeat_log.clear();
    have_hands = false;
  }
};

Eigen::Vector3d vec(const msg::Vector3& v) { return {v.x(), v.y(), v.z()}; }

// Shoulder of the robot at rest, from the URDF through reflex::control (not through the modules).
Eigen::Vector3d restShoulder(const std::string& link) {
  const std::string urdf = std::string(REFLEX_SOURCE_DIR) + "/bringup/robots/asimo_like.urdf";
  const control::Model model =
      control::loadModel(urdf, control::loadCollisionConfig(control::defaultCollisionConfigPath(urdf)));
  control::KinematicsData data(model);
  Eigen::VectorXd q = Eigen::VectorXd::Zero(model.nq);
  for (int i = 0; i < model.nq; ++i) q[i] = std::clamp(0.0, model.q_lower[i], model.q_upper[i]);
  control::computeForwardKinematics(model, data, q);
  return data.X_B_L[static_cast<std::size_t>(model.linkIndex(link))].translation();
}

struct CsvTarget {
  std::string hand;
  Eigen::Vector3d p;
};

// The first target of each hand in a t,hand,x,y,z timeline, read here independently of the module.
std::vector<CsvTarget> firstTargets(const std::string& path) {
  std::ifstream in(path);
  std::string line;
  std::vector<CsvTarget> out;
  bool seen_left = false, seen_right = false;
  while (std::getline(in, line)) {
    if (line.empty() || line[0] == '#' || line.rfind("t,", 0) == 0) continue;
    std::stringstream ss(line);
    std::string t, hand, x, y, z;
    std::getline(ss, t, ',');
    std::getline(ss, hand, ',');
    std::getline(ss, x, ',');
    std::getline(ss, y, ',');
    std::getline(ss, z, ',');
    if (hand != "left" && hand != "right") continue;
    bool& seen = hand == "left" ? seen_left : seen_right;
    if (seen || x == "none") continue;
    seen = true;
    out.push_back({hand, Eigen::Vector3d(std::stod(x), std::stod(y), std::stod(z))});
  }
  return out;
}

std::vector<std::string> behavior(const std::string& config, std::vector<std::string> extra = {}) {
  std::vector<std::string> a{kBin + "/reflex_behavior", "--config",   config, "--domain",
                             std::to_string(kDomain),   "--progress", "0"};
  a.insert(a.end(), extra.begin(), extra.end());
  return a;
}

TEST(BehaviorProcess, PointingThenScriptedConfigurationSameBinary) {
  Observer bus;
  const Eigen::Vector3d cup(0.46, -0.13, 0.95), can(0.46, 0.13, 0.96);
  std::unique_ptr<Child> publisher;

  // ---- 1. pointing.yaml
  {
    Child proc(behavior(kBehaviorDir + "/pointing.yaml"), ::testing::TempDir() + "modules_behavior_pointing.log");
    ASSERT_TRUE(proc.started());
    // Objects start once the behavior's hand-target writer is matched, so that the deep-history
    // reader (volatile) sees every sample from the first assignment on.
    ASSERT_TRUE(bus.all_hands.waitForWriters(1, 10s)) << proc.output();
    publisher = std::make_unique<Child>(
        std::vector<std::string>{kBin + "/reflex_modules_object_publisher", "--domain", std::to_string(kDomain),
                                 "--duration", "14", "--object", "cup=0.46,-0.13,0.95", "--object",
                                 "can=0.46,0.13,0.96", "--inject-bad"},
        ::testing::TempDir() + "modules_publisher.log");
    ASSERT_TRUE(publisher->started());
    const auto t0 = std::chrono::steady_clock::now();
    bus.collect(4000ms);
    const double window = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    ASSERT_TRUE(bus.have_hands) << proc.output();
    const msg::HandTargets& h = bus.last_hands;
    EXPECT_EQ(h.header().source(), "behavior");
    ASSERT_EQ(h.right().status(), msg::TARGET_GIVEN) << proc.output();
    ASSERT_EQ(h.left().status(), msg::TARGET_GIVEN) << proc.output();
    EXPECT_EQ(h.right().object_name(), "cup");
    EXPECT_EQ(h.left().object_name(), "can");
    // pointing.yaml: mode ray, ray_distance 0.40, from each shoulder towards its object.
    for (auto [target, shoulder, obj] : {std::tuple{vec(h.right().position_base()), restShoulder("r_shoulder"), cup},
                                         std::tuple{vec(h.left().position_base()), restShoulder("l_shoulder"), can}}) {
      EXPECT_NEAR((target - shoulder).norm(), 0.40, 1e-9);
      EXPECT_NEAR((target - shoulder).normalized().dot((obj - shoulder).normalized()), 1.0, 1e-9);
    }
    // Bad samples (NaN cup, "ghost", cup from the future at (0.3, 0.3, 0.5), cup in frame "odom" at
    // (0.35, -0.3, 0.6)) never got through.
    ASSERT_FALSE(bus.hand_log.empty());
    for (const auto& s : bus.hand_log) {
      for (const msg::HandTarget* t : {&s.left(), &s.right()}) {
        EXPECT_TRUE(vec(t->position_base()).allFinite());
        EXPECT_NE(t->object_name(), "ghost");
        // The cup stands still: every target for it is the same point (a future or "odom" sample
        // would move it).
        if (t->status() == msg::TARGET_GIVEN && t->object_name() == "cup") {
          EXPECT_NEAR((vec(t->position_base()) - vec(h.right().position_base())).norm(), 0.0, 1e-9);
        }
      }
    }
    // A priority was decided (first_assigned; both assigned in one frame -> priority_tie right).
    ASSERT_FALSE(bus.priority_log.empty());
    EXPECT_EQ(bus.priority_log.back().priority(), msg::PRIORITY_RIGHT_HIGHER);
    // Heartbeat at 2 Hz.
    int beats = 0;
    for (const auto& b : bus.heartbeat_log) beats += b.module_name() == "behavior" && b.state() == msg::STATE_RUNNING;
    EXPECT_GE(beats, static_cast<int>(window * 2.0) - 2);
    EXPECT_LE(beats, static_cast<int>(window * 2.0) + 2);
    std::printf("pointing: %zu hand-target samples, %d heartbeats in %.2f s\n", bus.hand_log.size(), beats, window);

    EXPECT_EQ(proc.terminate(), 0) << proc.output();
    bus.collectUntil(
        [&] {
          return bus.last_hands.left().status() == msg::TARGET_NONE &&
                 bus.last_hands.right().status() == msg::TARGET_NONE &&
                 bus.priority_log.back().priority() == msg::PRIORITY_EQUAL;
        },
        5000ms);
    EXPECT_EQ(bus.last_hands.left().status(), msg::TARGET_NONE);
    EXPECT_EQ(bus.last_hands.right().status(), msg::TARGET_NONE);
    EXPECT_EQ(bus.priority_log.back().priority(), msg::PRIORITY_EQUAL);
    const std::string log = proc.output();
    std::printf("%s", log.substr(log.rfind("reflex_behavior: stats")).c_str());
    EXPECT_GT(statValue(log, "rejected_future"), 0) << log;
    EXPECT_GT(statValue(log, "rejected_frame"), 0) << log;
    EXPECT_GT(statValue(log, "rejected_invalid"), 0) << log;
    EXPECT_GT(statValue(log, "rejected_unknown"), 0) << log;
    EXPECT_GT(statValue(log, "objects_accepted"), 0) << log;
    EXPECT_EQ(statValue(log, "forced_cleanups"), 0) << log;
  }
  bus.clear();

  // ---- 2. scripted.yaml: same binary, another file; the objects are still being published.
  {
    Child proc(behavior(kBehaviorDir + "/scripted.yaml"), ::testing::TempDir() + "modules_behavior_scripted.log");
    ASSERT_TRUE(proc.started());
    bus.collectUntil(
        [&] {
          return bus.have_hands && bus.last_hands.left().status() == msg::TARGET_GIVEN &&
                 bus.last_hands.right().status() == msg::TARGET_GIVEN;
        },
        15000ms);
    ASSERT_TRUE(bus.have_hands) << proc.output();
    const auto expected = firstTargets(kBehaviorDir + "/scripted_timeline.csv");
    ASSERT_EQ(expected.size(), 2u);
    const msg::HandTargets& h = bus.last_hands;
    for (const auto& e : expected) {
      const msg::HandTarget& t = e.hand == "left" ? h.left() : h.right();
      ASSERT_EQ(t.status(), msg::TARGET_GIVEN) << e.hand;
      EXPECT_NEAR((vec(t.position_base()) - e.p).norm(), 0.0, 1e-12) << e.hand;
      EXPECT_EQ(t.object_name(), "");  // scripted: nothing to do with the objects
    }
    EXPECT_EQ(proc.terminate(), 0) << proc.output();
    bus.collectUntil(
        [&] {
          return bus.last_hands.left().status() == msg::TARGET_NONE &&
                 bus.last_hands.right().status() == msg::TARGET_NONE;
        },
        5000ms);
    EXPECT_EQ(bus.last_hands.left().status(), msg::TARGET_NONE);
    EXPECT_EQ(bus.last_hands.right().status(), msg::TARGET_NONE);
  }
}

TEST(BehaviorProcess, OneModuleOfAFileRunsAsItsOwnProcess) {
  Observer bus;
  Child proc(behavior(kBehaviorDir + "/bar_occlusion.yaml", {"--module", "occlusion"}),
             ::testing::TempDir() + "modules_behavior_occlusion.log");
  ASSERT_TRUE(proc.started());
  // Until the attach and a heartbeat have arrived (process start and discovery can take seconds).
  bus.collectUntil(
      [&] {
        bool a = false, b = false;
        for (const auto& s : bus.schema_log) a |= s.operation() == msg::SCHEMA_ATTACH;
        for (const auto& h : bus.heartbeat_log) b |= h.module_name() == "occlusion";
        return a && b;
      },
      15000ms);
  bool attached = false;
  for (const auto& s : bus.schema_log) {
    EXPECT_EQ(s.header().source(), "occlusion");
    EXPECT_EQ(s.segment_name(), "gaze_line");  // only this module: no grasped bar
    attached |= s.operation() == msg::SCHEMA_ATTACH && s.virtual_segment() && s.parent_link() == "head";
  }
  EXPECT_TRUE(attached) << proc.output();
  for (const auto& h : bus.hand_log) EXPECT_NE(h.header().source(), "occlusion");  // no hands claimed
  bool beat = false;
  for (const auto& b : bus.heartbeat_log) beat |= b.module_name() == "occlusion";
  EXPECT_TRUE(beat);
  EXPECT_EQ(proc.terminate(), 0) << proc.output();
  bus.collectUntil([&] { return !bus.schema_log.empty() && bus.schema_log.back().operation() == msg::SCHEMA_DETACH; },
                   5000ms);
  ASSERT_FALSE(bus.schema_log.empty());
  EXPECT_EQ(bus.schema_log.back().operation(), msg::SCHEMA_DETACH);
  EXPECT_EQ(bus.schema_log.back().segment_name(), "gaze_line");
}

TEST(BehaviorProcess, BarAndOcclusionTogetherAttachBothAndRemoveBothAtStop) {
  Observer bus;
  Child proc(behavior(kBehaviorDir + "/bar_occlusion.yaml"), ::testing::TempDir() + "modules_behavior_bar.log");
  ASSERT_TRUE(proc.started());
  std::map<std::string, msg::BodySchemaChange> last;
  bus.collectUntil(
      [&] {
        for (const auto& s : bus.schema_log) last[s.segment_name()] = s;
        return last.count("grasped_bar") == 1 && last.count("gaze_line") == 1 && bus.have_hands &&
               bus.last_hands.left().status() == msg::TARGET_GIVEN;
      },
      10000ms);
  ASSERT_EQ(last.count("grasped_bar"), 1u) << proc.output();
  ASSERT_EQ(last.count("gaze_line"), 1u) << proc.output();
  EXPECT_EQ(last["grasped_bar"].parent_link(), "l_hand");
  EXPECT_EQ(last["grasped_bar"].motion_priority(), 1);
  EXPECT_FALSE(last["grasped_bar"].virtual_segment());
  EXPECT_TRUE(last["gaze_line"].virtual_segment());
  ASSERT_TRUE(bus.have_hands);
  EXPECT_EQ(bus.last_hands.left().status(), msg::TARGET_GIVEN);
  EXPECT_EQ(proc.terminate(), 0) << proc.output();
  bus.collectUntil(
      [&] {
        for (const auto& s : bus.schema_log) last[s.segment_name()] = s;
        return last["grasped_bar"].operation() == msg::SCHEMA_DETACH &&
               last["gaze_line"].operation() == msg::SCHEMA_DETACH;
      },
      5000ms);
  EXPECT_EQ(last["grasped_bar"].operation(), msg::SCHEMA_DETACH);
  EXPECT_EQ(last["gaze_line"].operation(), msg::SCHEMA_DETACH);
}

int runToExit(const std::vector<std::string>& argv, const std::string& name, std::string& log) {
  Child c(argv, ::testing::TempDir() + name);
  const int rc = c.wait(20000ms);
  log = c.output();
  return rc;
}

TEST(BehaviorProcess, StartUpErrorsNameTheBadValue) {
  std::string log;
  EXPECT_EQ(runToExit({kBin + "/reflex_behavior", "--help"}, "help.log", log), 0);
  EXPECT_NE(log.find("--config"), std::string::npos);

  const std::string unknown = ::testing::TempDir() + "modules_unknown_type.yaml";
  std::ofstream(unknown) << "modules:\n  - {name: p, type: pointng}\n";
  EXPECT_EQ(runToExit(behavior(unknown), "unknown.log", log), 2);
  EXPECT_NE(log.find(unknown + ":2"), std::string::npos) << log;
  EXPECT_NE(log.find("'pointng'"), std::string::npos) << log;

  const std::string bad = ::testing::TempDir() + "modules_bad_value.yaml";
  std::ofstream(bad) << "modules:\n  - name: p\n    type: pointing\n    config: {lost_timeout: soon}\n";
  EXPECT_EQ(runToExit(behavior(bad), "bad.log", log), 2);
  EXPECT_NE(log.find("modules[0].config.lost_timeout"), std::string::npos) << log;
  EXPECT_NE(log.find("'soon'"), std::string::npos) << log;

  EXPECT_EQ(runToExit(behavior(kBehaviorDir + "/pointing.yaml", {"--module", "nosuch"}), "nosuch.log", log), 2);
  EXPECT_NE(log.find("no module named 'nosuch'"), std::string::npos) << log;

  EXPECT_EQ(runToExit({kBin + "/reflex_behavior", "--config", kBehaviorDir + "/pointing.yaml", "--domain", "999"},
                      "domain.log", log),
            2);
  EXPECT_NE(log.find("999"), std::string::npos) << log;

  EXPECT_EQ(runToExit({kBin + "/reflex_behavior"}, "noconfig.log", log), 2);
  EXPECT_NE(log.find("--config"), std::string::npos) << log;

  // The process name and a body-schema segment name are DDS keys (heartbeat,
  // body schema): above 255 bytes a clear error at start, not an abort in the first publish.
  const std::string urdf = std::string(REFLEX_SOURCE_DIR) + "/bringup/robots/asimo_like.urdf";
  const std::string long_name(256, 'p');
  const std::string long_process = ::testing::TempDir() + "modules_long_process.yaml";
  std::ofstream(long_process) << "process: " << long_name << "\nrobot:\n  urdf: " << urdf
                              << "\nmodules:\n  - name: s\n    type: scripted\n    config:\n      timeline:\n"
                                 "        - {t: 0.0, right: [0.35, -0.18, 0.95]}\n";
  EXPECT_EQ(runToExit(behavior(long_process), "long_process.log", log), 2) << log;
  EXPECT_NE(log.find("'" + long_name + "' is 256 bytes long; at most 255 bytes"), std::string::npos) << log;
  const std::string long_segment = ::testing::TempDir() + "modules_long_segment.yaml";
  std::ofstream(long_segment) << "process: behavior\nrobot:\n  urdf: " << urdf
                              << "\nmodules:\n  - name: bar\n    type: grasped_bar\n    config:\n      hand: left\n"
                                 "      segment: "
                              << std::string(300, 's') << "\n";
  EXPECT_EQ(runToExit(behavior(long_segment), "long_segment.log", log), 2) << log;
  EXPECT_NE(log.find("body-schema segment name '" + std::string(300, 's') + "' is 300 bytes long; at most 255 bytes"),
            std::string::npos)
      << log;
}

// Two writers of reflex/joint_state (two controllers) — the behavior process
// follows the one it heard first, ignores the other (counted, said on stderr), and takes the second
// one only after the first has been silent for 0.5 s (a restarted controller).
TEST(BehaviorProcess, JointStatesFromASecondWriterAreIgnoredAndCounted) {
  const std::string urdf = std::string(REFLEX_SOURCE_DIR) + "/bringup/robots/asimo_like.urdf";
  const control::Model model =
      control::loadModel(urdf, control::loadCollisionConfig(control::defaultCollisionConfigPath(urdf)));
  Child proc(behavior(kBehaviorDir + "/scripted.yaml", {"--duration", "6"}),
             ::testing::TempDir() + "modules_behavior_two_writers.log");
  ASSERT_TRUE(proc.started());
  bus::BusConfig config;
  config.domain_id = kDomain;
  // Both named "controller": the identity inputs.joint_state_sources accepts, as two real
  // controllers would be (a writer of any other name is rejected before this check).
  config.module_name = "controller";
  auto a = std::make_unique<bus::Participant>(config);
  bus::Participant b(config);
  auto& writer_a = a->makeWriter<msg::JointState>();
  auto& writer_b = b.makeWriter<msg::JointState>();
  ASSERT_TRUE(writer_a.waitForReaders(1, 15s) && writer_b.waitForReaders(1, 15s));
  msg::JointState js;
  js.names(model.q_names);
  js.positions().assign(static_cast<std::size_t>(model.nq), 0.0);
  js.velocities().assign(static_cast<std::size_t>(model.nq), 0.0);
  int sent_b_while_a = 0;
  for (int k = 0; k < 200; ++k) {  // 2 s: a from the start, b from 0.5 s on
    writer_a.publish(js);
    if (k >= 50) {
      writer_b.publish(js);
      ++sent_b_while_a;
    }
    std::this_thread::sleep_for(10ms);
  }
  a.reset();  // a stops (and leaves): after 0.5 s of silence b is followed
  for (int k = 0; k < 150; ++k) {
    writer_b.publish(js);
    std::this_thread::sleep_for(10ms);
  }
  ASSERT_EQ(proc.wait(15000ms), 0) << proc.output();
  const std::string log = proc.output();
  const long ignored = statValue(log, "joint_states_other_writer");
  EXPECT_GE(ignored, sent_b_while_a * 6 / 10) << log;  // best effort: most of b's samples arrive
  EXPECT_LE(ignored, sent_b_while_a + 50) << "only b's samples while a lived, plus a's last 0.5 s of silence" << log;
  EXPECT_EQ(statValue(log, "joint_writer_changes"), 1) << log;
  EXPECT_NE(log.find("joint states from a second writer ('controller') ignored"), std::string::npos) << log;
}

}  // namespace
}  // namespace reflex::modules
