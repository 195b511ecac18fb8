// reflex_controller as a real process over real DDS: it runs at 200 Hz, follows
// hand targets from another participant while keeping every pair above d_r, rejects NaN targets,
// and retracts both hands on its own when the target source goes silent.
#include "../bad_input/controller_run.hpp"
#include "support/child_process.hpp"

#include <reflex/bus/bus.hpp>

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <fstream>
#include <thread>

namespace reflex {
namespace {

constexpr int kDomain = 71;

/// reflex_sim's crossing_arms targets; nan_left: the left target's y is NaN.
msg::HandTargets crossing(bool nan_left = false) {
  msg::HandTargets t = bad_input::crossingTargets();
  if (nan_left) t.left().position_base().y(std::nan(""));
  return t;
}

TEST(ControllerNode, FollowsTargetsSafelyAndRetractsWhenTheSourceGoesSilent) {
  const std::string log = ::testing::TempDir() + "controller_node_test.log";
  testing::ChildProcess controller({std::string(REFLEX_BIN_DIR) + "/reflex_controller", "--domain",
                                    std::to_string(kDomain), "--duration", "11", "--input-timeout", "1.0"},
                                   log);
  ASSERT_TRUE(controller.started());

  bus::BusConfig config;
  config.module_name = "test_behavior";
  config.domain_id = kDomain;
  auto source = std::make_unique<bus::Participant>(config);
  auto* targets = &source->makeWriter<msg::HandTargets>();
  auto* heartbeat = &source->makeWriter<msg::Heartbeat>();
  bus::BusConfig watch_config = config;
  watch_config.module_name = "test_watch";
  bus::Participant watch(watch_config);
  // The recorder profile keeps a burst (keep last 256), so every 200 Hz sample can be counted.
  auto& status = watch.makeReader<msg::ControlStatus>("reflex/control_status", bus::kProfileRecord);
  auto& joints = watch.makeReader<msg::JointState>();
  ASSERT_TRUE(status.waitForWriters(1, std::chrono::seconds(10))) << "the controller publishes status";
  ASSERT_TRUE(targets->waitForReaders(1, std::chrono::seconds(10))) << "the controller subscribes hand targets";

  // Phase 1 (4 s): crossing targets and a heartbeat every 0.1 s (a stall of this test under 0.9 s
  // never looks like a silent source to --input-timeout 1.0: "stale events 1" below is the real one).
  std::vector<msg::ControlStatus> statuses;
  auto pump = [&](double seconds, bool send) {
    const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(seconds);
    int k = 0;
    while (std::chrono::steady_clock::now() < end) {
      if (send && k % 2 == 0) {
        msg::HandTargets t = crossing();
        targets->publish(t);
        msg::Heartbeat hb;
        hb.module_name("test_behavior");
        hb.state(msg::STATE_RUNNING);
        heartbeat->publish(hb);
      }
      ++k;
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
      status.takeAll(statuses);
    }
  };
  pump(4.0, true);
  const std::size_t phase1 = statuses.size();
  ASSERT_GT(phase1, 300U) << "status stream at 200 Hz";
  double dmin = 1.0;
  bool yellow = false;
  for (const auto& s : statuses) {
    dmin = std::min({dmin, s.left().distance(), s.right().distance()});
    yellow |= s.left().zone() != msg::ZONE_FREE || s.right().zone() != msg::ZONE_FREE;
    EXPECT_FALSE(s.left().estop_latched());
  }
  EXPECT_TRUE(yellow) << "the crossing targets bring the arms together";
  EXPECT_GE(dmin, 0.005) << "never below d_r";
  msg::JointState js;
  ASSERT_TRUE(joints.takeLatest(js));
  ASSERT_EQ(js.names().size(), js.positions().size());
  std::size_t r_elbow = 0;
  for (; r_elbow < js.names().size() && js.names()[r_elbow] != "r_elbow"; ++r_elbow) {
  }
  ASSERT_LT(r_elbow, js.names().size());
  const double elbow_reaching = js.positions()[r_elbow];
  EXPECT_LT(elbow_reaching, -0.6) << "the right elbow bent to reach the target";

  // A NaN target is rejected (counted), never followed: send one, then go silent.
  msg::HandTargets bad = crossing(true);
  targets->publish(bad);
  std::this_thread::sleep_for(std::chrono::milliseconds(1500));  // delivered (reliable) before the writer goes
  source.reset();  // the behavior process "dies": no more samples, no heartbeat
  pump(3.5, false);
  ASSERT_TRUE(joints.takeLatest(js));
  const double elbow_after = js.positions()[r_elbow];
  EXPECT_GT(elbow_after, elbow_reaching + 0.15) << "the right arm retracts";
  EXPECT_NEAR(elbow_after, -0.5, 0.1) << "towards its rest posture (elbow -0.5)";
  for (std::size_t k = phase1; k < statuses.size(); ++k)
    EXPECT_GE(std::min(statuses[k].left().distance(), statuses[k].right().distance()), 0.005);

  EXPECT_EQ(controller.wait(std::chrono::seconds(10)), 0);
  std::ifstream in(log);
  const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  EXPECT_NE(text.find("rejected 1"), std::string::npos) << text;
  EXPECT_NE(text.find("stale events 1"), std::string::npos) << text;
  EXPECT_NE(text.find("e-stops 0"), std::string::npos) << text;
}

TEST(ControllerNode, BadSetupIsAClearErrorAndNonZeroExit) {
  const std::string log = ::testing::TempDir() + "controller_node_bad.log";
  testing::ChildProcess bad({std::string(REFLEX_BIN_DIR) + "/reflex_controller", "--urdf", "/nonexistent/robot.urdf",
                             "--domain", std::to_string(kDomain + 1)},
                            log);
  EXPECT_EQ(bad.wait(std::chrono::seconds(10)), 2);
  std::ifstream in(log);
  const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  EXPECT_NE(text.find("/nonexistent/robot.urdf"), std::string::npos) << text;
}

// The robot's own controller configuration, <stem>.controller.yaml beside the URDF, is found
// by reflex_controller as by reflex_sim (control::loadControllerConfigFor). Independent answers: the
// banner names the file and its hand links; the joint state on the bus holds the small humanoid's
// joints at the rest posture written in that file (read here as text), not the built-in arms'.
constexpr int kOwnConfigDomain = 231;

TEST(ControllerNode, FindsTheRobotsControllerYamlBesideTheUrdf) {
  const std::string robots = std::string(REFLEX_SOURCE_DIR) + "/bringup/robots/";
  const std::string log = ::testing::TempDir() + "controller_node_own_config.log";
  testing::ChildProcess controller(
      {std::string(REFLEX_BIN_DIR) + "/reflex_controller", "--urdf", robots + "small_humanoid.urdf", "--domain",
       std::to_string(kOwnConfigDomain), "--duration", "3", "--peer-probe", "0"},
      log);
  ASSERT_TRUE(controller.started());
  bus::BusConfig config;
  config.module_name = "test_watch";
  config.domain_id = kOwnConfigDomain;
  bus::Participant watch(config);
  auto& joints = watch.makeReader<msg::JointState>();
  ASSERT_TRUE(joints.waitForWriters(1, std::chrono::seconds(10))) << "the controller publishes joint state";
  msg::JointState js;
  const auto end = std::chrono::steady_clock::now() + std::chrono::seconds(5);
  while (!joints.takeLatest(js) && std::chrono::steady_clock::now() < end)
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  // The rest posture of the left arm, as small_humanoid.controller.yaml writes it.
  std::ifstream yaml(robots + "small_humanoid.controller.yaml");
  std::string line, rest_line;
  while (std::getline(yaml, line))
    if (line.find("rest: [") != std::string::npos) {
      rest_line = line;
      break;
    }
  ASSERT_FALSE(rest_line.empty());
  double rest_roll = 0.0;  // the second value: l_shoulder_roll
  ASSERT_EQ(std::sscanf(rest_line.c_str() + rest_line.find('[') + 1, "%*f , %lf", &rest_roll), 1) << rest_line;
  ASSERT_EQ(js.names().size(), js.positions().size());
  std::size_t roll = 0;
  for (; roll < js.names().size() && js.names()[roll] != "l_shoulder_roll"; ++roll) {
  }
  ASSERT_LT(roll, js.names().size()) << "the small humanoid's joints";
  // (0.55 rad there; the built-in arms rest at 0.25. The avoidance may move it slightly at rest.)
  EXPECT_NEAR(js.positions()[roll], rest_roll, 0.05) << "at the rest posture of small_humanoid.controller.yaml";

  EXPECT_EQ(controller.wait(std::chrono::seconds(15)), 0);
  std::ifstream in(log);
  const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  EXPECT_NE(text.find("reflex_controller: controller configuration " + robots +
                      "small_humanoid.controller.yaml (beside the URDF): arm left to hand 'l_hand' (6 joints), "
                      "arm right to hand 'r_hand' (6 joints)"),
            std::string::npos)
      << text;
}

TEST(ControllerNode, ANamedControllerYamlThatDoesNotExistIsNamed) {
  const std::string log = ::testing::TempDir() + "controller_node_missing_config.log";
  testing::ChildProcess bad({std::string(REFLEX_BIN_DIR) + "/reflex_controller", "--controller",
                             "/nonexistent/ctl.yaml", "--domain", std::to_string(kOwnConfigDomain + 1)},
                            log);
  EXPECT_EQ(bad.wait(std::chrono::seconds(10)), 2);
  std::ifstream in(log);
  const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  EXPECT_NE(
      text.find("reflex_controller: error: --controller '/nonexistent/ctl.yaml': no such controller configuration "
                "file (No such file or directory)"),
      std::string::npos)
      << text;
}

}  // namespace
}  // namespace reflex
