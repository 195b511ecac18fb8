// The real reflex_controller process in secure mode: started with the controller's
// generated profiles file (--profiles <dir>/profiles/controller.xml), it authenticates a secure
// behavior identity, follows its hand targets at 200 Hz with every pair above d_r, and publishes
// encrypted joint state / status that the recorder identity reads and an unauthenticated
// participant never sees. Domain 100. With a robot over DDS (--robot dds), domain 228: the controller
// commands a robot of the identity "robot" and takes no state from anyone else (an unauthenticated
// writer, a module without the grant).
#include "../bad_input/controller_run.hpp"
#include "support/child_process.hpp"
#include "security_support.hpp"

#include "reflex/control/controller.hpp"
#include "reflex/control/scenarios.hpp"
#include "reflex/control/urdf_loader.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <csignal>
#include <cstdio>
#include <numeric>
#include <regex>
#include <thread>
#include <vector>

namespace reflex::security_test {
namespace {

using namespace std::chrono_literals;
constexpr int kDomain = 100;

using bad_input::crossingTargets;  // reflex_sim's crossing_arms targets

TEST(SecureController, FollowsASecureSourceAt200HzAndHidesItsStateFromOutsiders) {
  const std::string dir = makeSecurityMaterial("proc");
  loadProfiles(dir);
  const std::string log = dir + "/controller.log";
  testing::ChildProcess controller(
      {std::string(REFLEX_BIN_DIR) + "/reflex_controller", "--domain", std::to_string(kDomain), "--duration", "12",
       "--input-timeout", "1.0", "--profiles", dir + "/profiles/controller.xml"},
      log);
  ASSERT_TRUE(controller.started());

  auto behavior = secureParticipant(dir, "behavior", kDomain);
  auto& targets = behavior->makeWriter<msg::HandTargets>();
  auto& heartbeat = behavior->makeWriter<msg::Heartbeat>();
  auto watch = secureParticipant(dir, "recorder", kDomain);
  auto& status = watch->makeReader<msg::ControlStatus>("reflex/control_status", bus::kProfileRecord);
  auto& joints = watch->makeReader<msg::JointState>("reflex/joint_state", bus::kProfileRecord);
  auto outsider = plainParticipant("outsider", kDomain);
  auto& outsider_status = outsider->makeReader<msg::ControlStatus>("reflex/control_status", bus::kProfileRecord);
  auto& outsider_targets = outsider->makeWriter<msg::HandTargets>();

  ASSERT_TRUE(status.waitForWriters(1, 20s)) << "the secure controller is authenticated by the recorder identity";
  ASSERT_TRUE(targets.waitForReaders(1, 20s)) << "the secure controller subscribes hand targets";

  std::vector<msg::ControlStatus> statuses, outsider_got;
  int k = 0;
  status.takeAll(statuses);
  statuses.clear();
  const auto t0 = std::chrono::steady_clock::now();
  repeatFor(4000ms, 50ms, [&] {
    if (k++ % 2 == 0) {
      msg::HandTargets t = crossingTargets();
      targets.publish(t);
      msg::Heartbeat hb;
      hb.module_name("behavior");
      hb.state(msg::STATE_RUNNING);
      heartbeat.publish(hb);
      msg::HandTargets forged = crossingTargets();
      forged.left().position_base().y(0.4);  // would pull the left hand far to its right
      outsider_targets.publish(forged);
    }
    status.takeAll(statuses);
    outsider_status.takeAll(outsider_got);
  });
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  // 200 Hz over DDS-Security: allow for best-effort losses on a loaded 2-core machine.
  EXPECT_GT(static_cast<double>(statuses.size()), 0.75 * 200.0 * seconds)
      << statuses.size() << " in " << seconds << " s";
  ASSERT_FALSE(statuses.empty());
  std::vector<double> periods;
  for (const auto& s : statuses) periods.push_back(s.cycle_period_us());
  std::sort(periods.begin(), periods.end());
  EXPECT_NEAR(periods[periods.size() / 2], 5000.0, 250.0) << "median cycle period";
  double dmin = 1.0;
  bool near = false;
  for (const auto& s : statuses) {
    dmin = std::min({dmin, s.left().distance(), s.right().distance()});
    near |= s.left().zone() != msg::ZONE_FREE || s.right().zone() != msg::ZONE_FREE;
  }
  std::printf("secure controller: %zu statuses in %.2f s (%.0f Hz), median cycle period %.0f us, closest %.1f mm\n",
              statuses.size(), seconds, static_cast<double>(statuses.size()) / seconds, periods[periods.size() / 2],
              dmin * 1000.0);
  EXPECT_TRUE(near) << "the crossing targets bring the arms together";
  EXPECT_GE(dmin, 0.005) << "never below d_r";
  msg::JointState js;
  ASSERT_TRUE(joints.takeLatest(js));
  const auto it = std::find(js.names().begin(), js.names().end(), "r_elbow");
  ASSERT_NE(it, js.names().end());
  EXPECT_LT(js.positions()[static_cast<std::size_t>(it - js.names().begin())], -0.6) << "the right arm reached";

  EXPECT_TRUE(outsider_got.empty()) << "an unauthenticated participant read " << outsider_got.size() << " statuses";
  EXPECT_EQ(outsider_status.stats().matched_writers, 0);
  EXPECT_EQ(outsider_targets.stats().matched_readers, 0) << "the controller never matched the forged source";

  EXPECT_EQ(controller.wait(15s), 0);
  const std::string text = readFile(log);
  EXPECT_NE(text.find("(rejected 0)"), std::string::npos) << text;
  EXPECT_NE(text.find("e-stops 0"), std::string::npos) << text;
}

TEST(SecureController, DrivesARobotOfTheRobotIdentityAndNoOtherWriter) {
  constexpr int kRobotDomain = 228;
  const std::string dir = makeSecurityMaterial("robot");
  loadProfiles(dir);
  const std::string log = dir + "/controller_robot.log";
  testing::ChildProcess controller(
      {std::string(REFLEX_BIN_DIR) + "/reflex_controller", "--domain", std::to_string(kRobotDomain), "--duration", "20",
       "--robot", "dds", "--peer-probe", "0", "--profiles", dir + "/profiles/controller.xml"},
      log);
  ASSERT_TRUE(controller.started());
  const std::string urdf = std::string(REFLEX_SOURCE_DIR) + "/bringup/robots/asimo_like.urdf";
  const control::Model model = control::loadModel(urdf, control::loadCollisionConfigFor(urdf, ""));
  const control::ControllerModel cm = control::makeControllerModel(model, control::defaultControllerConfig());
  const Eigen::VectorXd q0 = control::restConfiguration(model, cm);
  auto state = [&](double lift) {
    msg::RobotState s;
    s.names(model.q_names);
    s.positions().assign(q0.data(), q0.data() + model.nq);
    s.velocities().assign(static_cast<std::size_t>(model.nq), 0.0);
    for (const char* knee : {"l_knee", "r_knee"}) s.positions()[static_cast<std::size_t>(model.qIndex(knee))] += lift;
    return s;
  };

  auto robot = secureParticipant(dir, "robot", kRobotDomain);
  auto& states = robot->makeWriter<msg::RobotState>();
  auto& commands = robot->makeReader<msg::JointCommand>();
  ASSERT_TRUE(states.waitForReaders(1, 30s)) << readFile(log);
  ASSERT_TRUE(commands.waitForWriters(1, 30s)) << readFile(log);
  // A module without the grant cannot even make the writer; an outsider's states never arrive.
  auto behavior = secureParticipant(dir, "behavior", kRobotDomain);
  try {
    behavior->makeWriter<msg::RobotState>();
    ADD_FAILURE() << "behavior created a robot-state writer";
  } catch (const bus::BusError& e) {
    EXPECT_NE(std::string(e.what()).find("DDS-Security refused the DataWriter of topic 'reflex/robot_state'"),
              std::string::npos)
        << e.what();
  }
  auto outsider = plainParticipant("outsider", kRobotDomain);
  auto& forged = outsider->makeWriter<msg::RobotState>();
  std::vector<msg::JointCommand> got;
  std::uint64_t answered = 0, foreign = 0;
  std::vector<std::uint64_t> own;
  repeatFor(3000ms, 5ms, [&] {
    msg::RobotState s = state(0.0);
    states.publish(s);
    own.push_back(s.header().seq());
    msg::RobotState f = state(0.5);
    f.header().seq(1'000'000'000 + own.size());
    f.header().stamp_ns(bus::nowNs());
    forged.write(f);
    got.clear();
    commands.takeAll(got);
    for (const auto& c : got) {
      if (std::find(own.begin(), own.end(), c.state_seq()) != own.end()) ++answered;
      if (c.state_seq() >= 1'000'000'000) ++foreign;
    }
  });
  EXPECT_GT(answered, 100u) << "the controller commands the robot identity's states\n" << readFile(log);
  EXPECT_EQ(foreign, 0u) << "a command answered an unauthenticated state";
  controller.signal(SIGTERM);
  EXPECT_EQ(controller.wait(20s), 0);
  const std::string text = readFile(log);
  EXPECT_NE(text.find("(rejected 0)"), std::string::npos) << "nothing but the robot's states arrived: " << text;
  std::printf("secure robot: %llu commands answered the robot's states\n", static_cast<unsigned long long>(answered));
}

#ifdef REFLEX_SECURITY_CHAIN
// The whole chain in secure mode, every process with its own identity: reflex_vision (recorded
// flagship session) -> reflex_behavior (pointing) -> reflex_controller, all authenticated and
// encrypted; behavior also reads the controller's joint state. Same domain as above (the tests of
// this program run one after the other).
TEST(SecureController, VisionBehaviorControllerChainRunsSecurely) {
  const std::string dir = makeSecurityMaterial("chain");
  const std::string bin = REFLEX_BIN_DIR;
  const std::string d = std::to_string(kDomain);
  const std::string src = REFLEX_SOURCE_DIR;
  testing::ChildProcess controller(
      {bin + "/reflex_controller", "--domain", d, "--duration", "26", "--profiles", dir + "/profiles/controller.xml"},
      dir + "/controller.log");
  testing::ChildProcess behavior({bin + "/reflex_behavior", "--config", src + "/bringup/behavior/pointing.yaml",
                                  "--domain", d, "--duration", "23", "--profiles", dir + "/profiles/behavior.xml"},
                                 dir + "/behavior.log");
  // Vision holds its replay until behavior (the one reader it can authenticate with) has matched, so
  // the session is not spent on the handshake (a fixed 3 s wait was not always enough under load).
  testing::ChildProcess vision(
      {bin + "/reflex_vision", "--session", src + "/bringup/sessions/flagship", "--domain", d, "--duration", "18",
       "--quiet", "--wait-readers", "1", "--wait-timeout", "20", "--profiles", dir + "/profiles/vision.xml"},
      dir + "/vision.log");
  ASSERT_TRUE(controller.started() && behavior.started() && vision.started());
  auto outsider = plainParticipant("outsider", kDomain);
  auto& outsider_targets = outsider->makeReader<msg::HandTargets>("reflex/hand_targets", bus::kProfileRecord);
  auto& outsider_objects = outsider->makeReader<msg::ObjectTargets>("reflex/object_targets", bus::kProfileRecord);
  std::vector<msg::HandTargets> t;
  std::vector<msg::ObjectTargets> o;
  repeatFor(15000ms, 100ms, [&] {
    outsider_targets.takeAll(t);
    outsider_objects.takeAll(o);
  });
  EXPECT_TRUE(t.empty() && o.empty()) << "an unauthenticated participant read the chain's samples";

  EXPECT_EQ(vision.wait(30s), 0);
  EXPECT_EQ(behavior.wait(30s), 0);
  EXPECT_EQ(controller.wait(30s), 0);
  const std::string vis = readFile(dir + "/vision.log"), beh = readFile(dir + "/behavior.log"),
                    ctl = readFile(dir + "/controller.log");
  std::smatch m;
  ASSERT_TRUE(std::regex_search(vis, m, std::regex(R"((\d+) publications)"))) << vis;
  EXPECT_GT(std::stol(m[1]), 100) << vis;
  ASSERT_TRUE(std::regex_search(beh, m, std::regex(R"(objects_accepted=(\d+).*joint_states=(\d+))"))) << beh;
  EXPECT_GT(std::stol(m[1]), 100) << "behavior received vision's objects: " << beh;
  EXPECT_GT(std::stol(m[2]), 1000) << "behavior received the controller's joint states: " << beh;
  ASSERT_TRUE(std::regex_search(ctl, m, std::regex(R"(e-stops (\d+), targets (\d+) \(rejected (\d+)\))"))) << ctl;
  EXPECT_EQ(std::stol(m[1]), 0);
  EXPECT_GT(std::stol(m[2]), 50) << "the controller received behavior's hand targets: " << ctl;
  EXPECT_EQ(std::stol(m[3]), 0);
  std::printf("secure chain: %s\n", ctl.substr(ctl.rfind("reflex_controller:")).c_str());
}
#endif

}  // namespace
}  // namespace reflex::security_test
