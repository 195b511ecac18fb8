// The robot over DDS with real processes: reflex_controller --robot dds against
// reflex_test_robot (test_robot_driver.cpp: a kinematic integrator of reflex/joint_command publishing
// reflex/robot_state at 1 kHz), a target source and a watcher in this process. Domains 140..142.
//
// Independent answers:
// - reaching: the same targets given to the in-process kinematic plant (OnboardController +
//   KinematicPort, the reflex_controller default) for the same time; the hands computed by forward
//   kinematics from the MEASURED robot state must agree with it within 1 cm (the reach tolerance of
//   SimResult::reach_time) and be within 1 cm of the targets;
// - the robot dies (kill -9): the controller's heartbeat says "robot state stale" and no new command
//   is published; a restarted robot gets commands again within 3 s (the bound), answering its
//   own states (state_seq of the new robot's counter);
// - bad states (a missing joint, NaN, lengths that differ, a stamp from the future) from a robot in
//   this test: never answered, named in the log and counted in the exit line; good states with the
//   names in another order: every command answers one of them, within v_max * period of it;
// - the controller dies (kill -9): the robot reports holding (RobotState.holding) within the command
//   deadline plus a margin, and its measured positions do not change for 1 s.
#include "support/files.hpp"
#include "support/child_process.hpp"

#include "reflex/control/onboard.hpp"
#include "reflex/control/scenarios.hpp"
#include "reflex/control/urdf_loader.hpp"

#include <reflex/bus/bus.hpp>

#include <gtest/gtest.h>

#include <algorithm>
#include <csignal>
#include <cmath>
#include <fstream>
#include <functional>
#include <map>
#include <sstream>
#include <thread>

namespace reflex {
namespace {

constexpr int kDomain = 140;
using Clock = std::chrono::steady_clock;

const Eigen::Vector3d kTargets[2] = {Eigen::Vector3d(0.30, 0.20, 0.85), Eigen::Vector3d(0.30, -0.20, 0.85)};

msg::HandTargets targetsMsg() {
  msg::HandTargets t;
  msg::HandTarget* h[2] = {&t.left(), &t.right()};
  for (int a = 0; a < 2; ++a) {
    h[a]->status(msg::TARGET_GIVEN);
    h[a]->position_base().x(kTargets[a].x());
    h[a]->position_base().y(kTargets[a].y());
    h[a]->position_base().z(kTargets[a].z());
  }
  return t;
}

using testing::readFile;

struct Fixture {
  std::string urdf = std::string(REFLEX_SOURCE_DIR) + "/bringup/robots/asimo_like.urdf";
  control::Model model = control::loadModel(urdf, control::loadCollisionConfigFor(urdf, ""));
  control::ControllerModel cm = control::makeControllerModel(model, control::defaultControllerConfig());

  /// Hands (W) from a measured RobotState, by name.
  std::array<Eigen::Vector3d, 2> hands(const msg::RobotState& s) const {
    Eigen::VectorXd q = control::restConfiguration(model, cm);
    for (std::size_t k = 0; k < s.names().size(); ++k) {
      const int i = model.qIndex(s.names()[k]);
      if (i >= 0) q[i] = s.positions()[k];
    }
    control::KinematicsData kin(model);
    EXPECT_TRUE(control::computeForwardKinematics(model, kin, q));
    std::array<Eigen::Vector3d, 2> h;
    for (int a = 0; a < 2; ++a) h[a] = kin.X_B_L[cm.arms[a].hand_link] * cm.arms[a].hand_point_L;
    return h;
  }

  /// The in-process kinematic plant given the same targets for `seconds`.
  std::array<Eigen::Vector3d, 2> kinematicHands(double seconds) const {
    const Eigen::VectorXd q0 = control::restConfiguration(model, cm);
    control::KinematicPort port(q0);
    control::OnboardController ctl(model, cm, port, q0);
    std::array<control::HandCommand, 2> cmd;
    for (int a = 0; a < 2; ++a) cmd[a] = {control::HandStatus::kGiven, kTargets[a]};
    const double dt = cm.params.period;
    for (int k = 0; k * dt < seconds; ++k) {
      if (k % 100 == 0) ctl.setHandTargets(cmd, k * dt);
      ctl.step(k * dt);
    }
    std::array<Eigen::Vector3d, 2> h;
    for (int a = 0; a < 2; ++a) h[a] = ctl.data().arms[a].hand_B;
    return h;
  }
};

TEST(RobotPort, TheControllerDrivesADdsRobotLikeTheKinematicPlantFreezesWithoutItAndTheRobotHoldsWithoutTheController) {
  Fixture fx;
  const std::string bin = REFLEX_BIN_DIR;
  const std::string robot_log = ::testing::TempDir() + "robot_port_test.robot.log";
  const std::string robot_log2 = ::testing::TempDir() + "robot_port_test.robot2.log";
  const std::string ctl_log = ::testing::TempDir() + "robot_port_test.controller.log";
  auto robot = std::make_unique<testing::ChildProcess>(
      std::vector<std::string>{bin + "/reflex_test_robot", "--domain", std::to_string(kDomain)}, robot_log);
  ASSERT_TRUE(robot->started());
  testing::ChildProcess controller({bin + "/reflex_controller", "--domain", std::to_string(kDomain), "--robot", "dds",
                                    "--peer-probe", "0", "--input-timeout", "5", "--duration", "60"},
                                   ctl_log);
  ASSERT_TRUE(controller.started());

  bus::BusConfig config;
  config.module_name = "test_source";
  config.domain_id = kDomain;
  bus::Participant source(config);
  auto& targets = source.makeWriter<msg::HandTargets>();
  auto& source_heartbeat = source.makeWriter<msg::Heartbeat>();
  bus::BusConfig watch_config = config;
  watch_config.module_name = "test_watch";
  bus::Participant watch(watch_config);
  auto& states = watch.makeReader<msg::RobotState>();
  auto& commands = watch.makeReader<msg::JointCommand>("reflex/joint_command", bus::kProfileRecord);
  auto& heartbeats = watch.makeReader<msg::Heartbeat>();
  ASSERT_TRUE(targets.waitForReaders(1, std::chrono::seconds(15))) << readFile(ctl_log);
  ASSERT_TRUE(commands.waitForWriters(1, std::chrono::seconds(15))) << readFile(ctl_log);
  ASSERT_TRUE(states.waitForWriters(1, std::chrono::seconds(15))) << readFile(robot_log);

  msg::RobotState last_state;
  bool have_state = false;
  std::string ctl_detail = "(no heartbeat)";
  std::vector<msg::JointCommand> cmds;
  auto pump = [&](double seconds, bool send) {
    const auto end = Clock::now() + std::chrono::duration<double>(seconds);
    int k = 0;
    while (Clock::now() < end) {
      if (send && k % 10 == 0) {
        msg::HandTargets t = targetsMsg();
        targets.publish(t);
        msg::Heartbeat hb;
        hb.module_name("test_source");
        hb.state(msg::STATE_RUNNING);
        source_heartbeat.publish(hb);
      }
      ++k;
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
      msg::RobotState s;
      while (states.takeNext(s)) {
        last_state = s;
        have_state = true;
      }
      msg::Heartbeat hb;
      while (heartbeats.takeNext(hb))
        if (hb.module_name() == "controller") ctl_detail = hb.detail();
      commands.takeAll(cmds);
    }
  };

  // 1. Reaching: 4 s of targets. The robot's MEASURED hands against the kinematic plant's.
  const double reach_time = 4.0;
  pump(reach_time, true);
  ASSERT_TRUE(have_state);
  ASSERT_GT(cmds.size(), 300U) << "commands at 200 Hz";
  const auto dds_hands = fx.hands(last_state);
  const auto kin_hands = fx.kinematicHands(reach_time);
  for (int a = 0; a < 2; ++a) {
    std::printf(
        "arm %d: measured hand %.4f %.4f %.4f, kinematic plant %.4f %.4f %.4f, |diff| %.2f mm, to target %.2f mm\n", a,
        dds_hands[a].x(), dds_hands[a].y(), dds_hands[a].z(), kin_hands[a].x(), kin_hands[a].y(), kin_hands[a].z(),
        (dds_hands[a] - kin_hands[a]).norm() * 1e3, (dds_hands[a] - kTargets[a]).norm() * 1e3);
    EXPECT_LT((dds_hands[a] - kin_hands[a]).norm(), 0.01) << "arm " << a << " as with the kinematic plant";
    EXPECT_LT((dds_hands[a] - kTargets[a]).norm(), 0.01) << "arm " << a << " reached its target";
  }
  EXPECT_EQ(ctl_detail, "") << "the controller reports nothing wrong while the robot is fresh";
  EXPECT_FALSE(last_state.holding()) << "the robot applies commands";
  // Every command answers a state of this robot, with its stamp; deadline ahead of its own stamp.
  const msg::JointCommand& c = cmds.back();
  EXPECT_GT(c.state_seq(), 0U);
  EXPECT_LE(c.state_seq(), last_state.header().seq());
  EXPECT_GT(c.valid_until_ns(), c.header().stamp_ns());
  EXPECT_LE(c.valid_until_ns() - c.header().stamp_ns(), 16'000'000) << "three 5 ms periods";
  EXPECT_EQ(c.names().size(), control::drivenJoints(fx.model, fx.cm).size());
  // Latency from the robot's measurement to the command answering it (one host, one clock): never
  // above --robot-timeout (50 ms by default: an older state is not answered).
  std::vector<double> latency_ms;
  for (const auto& cmd : cmds)
    latency_ms.push_back(static_cast<double>(cmd.header().stamp_ns() - cmd.state_stamp_ns()) * 1e-6);
  std::sort(latency_ms.begin(), latency_ms.end());
  std::printf("state -> command latency over %zu commands: p50 %.2f ms, p99 %.2f ms, max %.2f ms\n", latency_ms.size(),
              latency_ms[latency_ms.size() / 2], latency_ms[latency_ms.size() * 99 / 100], latency_ms.back());
  EXPECT_GE(latency_ms.front(), 0.0);
  EXPECT_LE(latency_ms.back(), 50.0 + 1e-6);

  // 2. The robot dies: the controller says so and stops commanding.
  robot->signal(SIGKILL);
  robot->wait(std::chrono::seconds(5));
  const auto killed = Clock::now();
  pump(1.0, true);
  EXPECT_NE(ctl_detail.find("robot state stale"), std::string::npos) << "heartbeat detail: " << ctl_detail;
  cmds.clear();
  pump(1.0, true);
  EXPECT_EQ(cmds.size(), 0U) << "no command while the robot state is stale";
  EXPECT_GT(std::chrono::duration<double>(Clock::now() - killed).count(), 1.9);

  // 3. A new robot: commands again within 3 s, answering the new robot's states.
  have_state = false;
  robot = std::make_unique<testing::ChildProcess>(
      std::vector<std::string>{bin + "/reflex_test_robot", "--domain", std::to_string(kDomain)}, robot_log2);
  ASSERT_TRUE(robot->started());
  const auto restarted = Clock::now();
  // The controller's recovery: commands again (they stopped while the state was stale, so any
  // command now answers the new robot) and its heartbeat's detail is empty again. Whether this
  // watcher has discovered the new robot yet is a separate matter (DDS discovery of a third
  // participant, measured up to 3.2 s under load), so the robot's applying is checked after.
  double recovered_after = -1.0, state_after = -1.0, applied_after = -1.0;
  while (Clock::now() - restarted < std::chrono::seconds(10) && (recovered_after < 0.0 || applied_after < 0.0)) {
    pump(0.02, true);
    const double since = std::chrono::duration<double>(Clock::now() - restarted).count();
    if (have_state && state_after < 0.0) state_after = since;
    if (recovered_after < 0.0 && !cmds.empty() && ctl_detail.empty()) recovered_after = since;
    if (applied_after < 0.0 && have_state && last_state.applied_command_seq() > 0) applied_after = since;
  }
  std::printf(
      "restart: the controller commanded again %.2f s after the robot restarted; the new robot's state first "
      "seen here after %.2f s, applying commands after %.2f s\n",
      recovered_after, state_after, applied_after);
  ASSERT_GE(recovered_after, 0.0) << readFile(ctl_log);
  EXPECT_LT(recovered_after, 3.0);
  ASSERT_GE(applied_after, 0.0) << "the restarted robot applies the controller's commands";
  EXPECT_LT(cmds.back().state_seq(), 20000U) << "answers the new robot's counter (it restarted at 1)";
  pump(4.0, true);
  const auto again = fx.hands(last_state);
  for (int a = 0; a < 2; ++a) EXPECT_LT((again[a] - kTargets[a]).norm(), 0.01) << "arm " << a << " after the restart";

  // 4. The controller dies: the robot holds.
  controller.signal(SIGKILL);
  controller.wait(std::chrono::seconds(5));
  const auto ctl_killed = Clock::now();
  bool holding = false;
  double hold_after = -1.0;
  while (Clock::now() - ctl_killed < std::chrono::seconds(2) && !holding) {
    pump(0.005, false);
    if (last_state.holding()) {
      holding = true;
      hold_after = std::chrono::duration<double>(Clock::now() - ctl_killed).count();
    }
  }
  ASSERT_TRUE(holding) << "the robot holds without commands";
  std::printf("the robot reported holding %.0f ms after the controller was killed\n", hold_after * 1e3);
  EXPECT_LT(hold_after, 0.5);
  const msg::RobotState held = last_state;
  pump(1.0, false);
  ASSERT_TRUE(last_state.holding());
  EXPECT_GT(last_state.header().seq(), held.header().seq() + 500) << "the robot kept publishing";
  for (std::size_t k = 0; k < held.positions().size(); ++k)
    EXPECT_EQ(last_state.positions()[k], held.positions()[k]) << held.names()[k] << " moved while holding";

  robot->signal(SIGTERM);
  EXPECT_EQ(robot->wait(std::chrono::seconds(10)), 0);
  const std::string text = readFile(ctl_log);
  EXPECT_NE(text.find("robot state stale"), std::string::npos) << text;
  EXPECT_NE(text.find("robot state fresh"), std::string::npos) << text;
}

TEST(RobotPort, BadRobotStatesAreRejectedNamedAndCountedAndNeverAnswered) {
  // This test is the robot: it publishes states that lack a joint, carry a NaN, have lengths that
  // differ, or are stamped 1 s in the future (each kind for 0.5 s at 200 Hz). None may be answered
  // by a command. Then good states with the names in reverse order (the name map): every command
  // answers one of them and moves no driven joint more than v_max * period from the state it answers.
  Fixture fx;
  const std::string bin = REFLEX_BIN_DIR;
  const std::string ctl_log = ::testing::TempDir() + "robot_port_test.bad_states.log";
  testing::ChildProcess controller({bin + "/reflex_controller", "--domain", std::to_string(kDomain + 2), "--robot",
                                    "dds", "--peer-probe", "0", "--duration", "30"},
                                   ctl_log);
  ASSERT_TRUE(controller.started());
  bus::BusConfig config;
  config.module_name = "test_robot_in_test";
  config.domain_id = kDomain + 2;
  bus::Participant robot(config);
  auto& states = robot.makeWriter<msg::RobotState>();
  auto& commands = robot.makeReader<msg::JointCommand>("reflex/joint_command", bus::kProfileRecord);
  ASSERT_TRUE(states.waitForReaders(1, std::chrono::seconds(15))) << readFile(ctl_log);
  ASSERT_TRUE(commands.waitForWriters(1, std::chrono::seconds(15))) << readFile(ctl_log);
  const Eigen::VectorXd q0 = control::restConfiguration(fx.model, fx.cm);
  auto good = [&](bool reversed) {
    msg::RobotState st;
    for (int k = 0; k < fx.model.nq; ++k) {
      const int i = reversed ? fx.model.nq - 1 - k : k;
      st.names().push_back(fx.model.q_names[i]);
      st.positions().push_back(q0[i]);
      st.velocities().push_back(0.0);
    }
    return st;
  };
  std::vector<msg::JointCommand> got;
  auto send = [&](const char* what, const std::function<void(msg::RobotState&)>& spoil, bool future) {
    for (int k = 0; k < 100; ++k) {
      msg::RobotState st = good(false);
      spoil(st);
      if (future) {
        st.header().stamp_ns(bus::nowNs() + 1'000'000'000);
        st.header().seq(static_cast<std::uint64_t>(k + 1));
        states.write(st);
      } else {
        states.publish(st);
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
    }
    commands.takeAll(got);
    EXPECT_EQ(got.size(), 0U) << "a command answered a state that " << what;
  };
  const std::string elbow = "l_elbow";
  ASSERT_GE(fx.model.qIndex(elbow), 0);
  send(
      "lacks l_elbow",
      [&](msg::RobotState& st) {
        for (std::size_t k = 0; k < st.names().size(); ++k)
          if (st.names()[k] == elbow) {
            st.names().erase(st.names().begin() + static_cast<long>(k));
            st.positions().erase(st.positions().begin() + static_cast<long>(k));
            st.velocities().erase(st.velocities().begin() + static_cast<long>(k));
            break;
          }
      },
      false);
  send(
      "has a NaN", [](msg::RobotState& st) { st.positions()[3] = std::nan(""); }, false);
  send(
      "has lengths that differ", [](msg::RobotState& st) { st.velocities().pop_back(); }, false);
  send(
      "is stamped 1 s in the future", [](msg::RobotState&) {}, true);

  // Good states, names reversed.
  std::map<std::uint64_t, msg::RobotState> sent;
  for (int k = 0; k < 200; ++k) {
    msg::RobotState st = good(true);
    states.publish(st);
    sent[st.header().seq()] = st;
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
    commands.takeAll(got);
  }
  ASSERT_GT(got.size(), 50U) << "good states are answered";
  const double period = fx.cm.params.period;
  for (const auto& c : got) {
    ASSERT_TRUE(sent.count(c.state_seq())) << "answers a state that was sent: seq " << c.state_seq();
    const msg::RobotState& st = sent[c.state_seq()];
    EXPECT_EQ(c.state_stamp_ns(), st.header().stamp_ns());
    for (std::size_t k = 0; k < c.names().size(); ++k) {
      const int i = fx.model.qIndex(c.names()[k]);
      ASSERT_GE(i, 0);
      const double measured = st.positions()[static_cast<std::size_t>(fx.model.nq - 1 - i)];  // reversed
      EXPECT_LE(std::abs(c.positions()[k] - measured), fx.model.v_max[i] * period * (1 + 1e-9)) << c.names()[k];
      EXPECT_NEAR(c.velocities()[k], (c.positions()[k] - measured) / period, 1e-9) << c.names()[k];
    }
  }
  controller.signal(SIGTERM);
  EXPECT_EQ(controller.wait(std::chrono::seconds(10)), 0);
  const std::string text = readFile(ctl_log);
  EXPECT_NE(text.find("joint 'l_elbow' is missing"), std::string::npos) << text;
  EXPECT_NE(text.find("position nan"), std::string::npos) << text;
  EXPECT_NE(text.find("names but"), std::string::npos) << text;
  EXPECT_NE(text.find("in the future"), std::string::npos) << text;
  const std::size_t at = text.find("robot dds: states ");
  ASSERT_NE(at, std::string::npos) << text;
  unsigned long long accepted = 0, rejected = 0;
  ASSERT_EQ(std::sscanf(text.c_str() + at, "robot dds: states %llu (rejected %llu)", &accepted, &rejected), 2) << text;
  std::printf("controller exit: %llu states accepted, %llu rejected (400 bad sent, best effort)\n", accepted, rejected);
  EXPECT_GT(rejected, 300U);
  EXPECT_LE(rejected, 400U);
  EXPECT_GT(accepted, 100U);
}

TEST(RobotPort, BadRobotOptionsAreRefusedNamingTheValue) {
  const std::string bin = REFLEX_BIN_DIR;
  struct Case {
    std::vector<std::string> args;
    std::string expect;
  } cases[] = {
      {{"--robot", "mujoco"}, "--robot 'mujoco' is not a robot side"},
      {{"--robot", "dds", "--robot-timeout", "0"}, "--robot-timeout 0"},
      {{"--robot", "dds", "--command-deadline", "0.001"}, "--command-deadline 0.001"},
      {{"--robot", "dds", "--robot-state", "/tmp/x.state"}, "--robot-state '/tmp/x.state'"},
  };
  int n = 0;
  for (const auto& c : cases) {
    const std::string log = ::testing::TempDir() + "robot_port_test.bad" + std::to_string(n++) + ".log";
    std::vector<std::string> argv = {bin + "/reflex_controller", "--domain", std::to_string(kDomain + 1),
                                     "--peer-probe", "0"};
    argv.insert(argv.end(), c.args.begin(), c.args.end());
    testing::ChildProcess p(argv, log);
    ASSERT_TRUE(p.started());
    EXPECT_EQ(p.wait(std::chrono::seconds(20)), 2) << c.expect;
    const std::string text = readFile(log);
    EXPECT_NE(text.find(c.expect), std::string::npos) << text;
  }
}

}  // namespace
}  // namespace reflex
