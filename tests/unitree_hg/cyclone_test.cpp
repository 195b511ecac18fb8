// reflex_controller --robot unitree_hg against a robot of another DDS implementation: hg_cyclone_robot
// (Cyclone DDS, C; types from idl/unitree_hg.idl by Cyclone's idlc, its own Crc32Core over its own C
// structs), both real processes on domain 13.
//
// Checked against what the robot program saw and sent (independent of the controller's code):
//  - state in, commands out: the controller accepts the robot's states and answers on rt/arm_sdk;
//    every command's crc is right by the robot's own computation; the weight motor_cmd[29].q rises
//    to 1 and is 0 at the end, never jumping (the controller's own largest step is dt / ramp time);
//    the arm_sdk slots of the joint map carry the map's kp / kd and mode 1, the legs nothing;
//  - the robot's 3 states with a wrong crc, 2 of 30 motors (another payload size under the same type
//    name), 3 + S with a tick that does not advance, a NaN and an absurd position of one motor and 4
//    valid ones from a second DataWriter are each
//    rejected, counted by cause in the exit line (exactly as many as sent) and named on stderr; while the tick stands still the
//    controller goes stale and sends nothing (the robot sees the gap);
//  - a joint map naming a joint the model does not have, or a motor the message lacks (35), no map,
//    or a map with --robot dds is refused at start (exit 1) naming the joint / the key / the option.
#include "support/files.hpp"
#include "reflex/control_node/unitree_hg.hpp"

#include "reflex/control/controller.hpp"
#include "reflex/control/scenarios.hpp"
#include "reflex/control/urdf_loader.hpp"
#include "support/child_process.hpp"

#include <gtest/gtest.h>

#include <cstdio>
#include <fstream>
#include <map>
#include <regex>
#include <string>

namespace {

using namespace reflex::testing;
namespace hg = reflex::unitree_hg;

const std::string kUrdf = std::string(REFLEX_SOURCE_DIR) + "/bringup/robots/asimo_like.urdf";
const std::string kMap = std::string(REFLEX_SOURCE_DIR) + "/bringup/robots/asimo_like.hg.yaml";

using reflex::testing::numberAfter;
using reflex::testing::readFile;

TEST(UnitreeHgCyclone, StateInCommandsOutAndBadStatesRejectedCountedNamed) {
  const auto model = reflex::control::loadModel(kUrdf, reflex::control::loadCollisionConfigFor(kUrdf, ""));
  const auto cm = reflex::control::makeControllerModel(model, reflex::control::loadControllerConfigFor(kUrdf, ""));
  const Eigen::VectorXd rest = reflex::control::restConfiguration(model, cm);
  const hg::HgJointMap map = hg::loadHgJointMap(kMap);
  const std::string log = testing::TempDir() + "/hg_controller.log";
  ChildProcess controller({binPath("reflex_controller"), "--robot", "unitree_hg", "--joint-map", kMap, "--domain", "13",
                           "--duration", "5", "--ramp-time", "1", "--peer-probe", "0"},
                          log);
  ASSERT_TRUE(controller.started()) << controller.error();
  // The robot starts once the controller runs (its schedule is in seconds from its own start).
  ASSERT_NE(controller.readUntil("reflex_controller: running at", std::chrono::seconds(30)).find("running at"),
            std::string::npos)
      << readFile(log);
  std::vector<std::string> robot_args = {binPath("hg_cyclone_robot"),
                                         "--domain",
                                         "13",
                                         "--bad-at",
                                         "2.5",
                                         "--stall-ms",
                                         "300",
                                         "--stop-at",
                                         "6.5",
                                         "--listen-until",
                                         "8.5"};
  for (const auto& m : map.motors) {
    robot_args.push_back("--q");
    robot_args.push_back(std::to_string(m.motor) + "=" + std::to_string(rest[model.qIndex(m.joint)]));
  }
  ChildProcess robot(robot_args, ChildOutput::pipe());
  ASSERT_TRUE(robot.started()) << robot.error();
  ASSERT_EQ(robot.wait(std::chrono::seconds(30)), 0) << robot.output();
  ASSERT_EQ(controller.wait(std::chrono::seconds(30)), 0) << readFile(log);
  const std::string out = robot.output();
  const std::string ctl = readFile(log);
  std::printf("[ robot ] %s\n[ controller ] %s\n", out.substr(0, out.find("slot 0 ")).c_str(),
              ctl.substr(ctl.rfind("reflex_controller: ")).c_str());

  // What the robot sent.
  const double stall = numberAfter(out, " stall ");
  ASSERT_EQ(numberAfter(out, "bad_crc "), 3) << out;
  ASSERT_EQ(numberAfter(out, "repeat_tick "), 3) << out;
  ASSERT_EQ(numberAfter(out, " short "), 2) << out;
  ASSERT_EQ(numberAfter(out, "other_writer "), 4) << out;
  ASSERT_EQ(numberAfter(out, " nan "), 1) << out;
  ASSERT_EQ(numberAfter(out, " far "), 1) << out;
  ASSERT_EQ(stall, 150) << out;

  // Counted by cause, exactly as many as sent, and named.
  EXPECT_EQ(numberAfter(ctl, "robot_state_bad_crc "), 3) << ctl;
  EXPECT_EQ(numberAfter(ctl, "robot_state_motor_count "), 2) << ctl;
  EXPECT_EQ(numberAfter(ctl, "robot_state_old_tick "), 3 + stall) << ctl;
  const std::size_t states_at = ctl.find("robot unitree_hg: states ");
  ASSERT_NE(states_at, std::string::npos) << ctl;
  unsigned long long accepted = 0, rejected = 0;
  ASSERT_EQ(std::sscanf(ctl.c_str() + states_at, "robot unitree_hg: states %llu (rejected %llu)", &accepted, &rejected),
            2);
  EXPECT_EQ(static_cast<double>(rejected), 3 + 2 + 3 + stall + 4 + 2) << ctl;
  // Motor 18 is l_elbow in the map: a NaN and a position 50 rad out.
  EXPECT_EQ(numberAfter(ctl, "robot_state_not_finite "), 1) << ctl;
  EXPECT_EQ(numberAfter(ctl, "robot_state_outside_limits "), 1) << ctl;
  EXPECT_NE(ctl.find("motor 18 (joint 'l_elbow') q nan"), std::string::npos) << ctl;
  EXPECT_NE(ctl.find("motor 18 (joint 'l_elbow') q 50 outside its limits"), std::string::npos) << ctl;
  // A second writer of valid states while the robot's is alive: ignored, counted, named.
  EXPECT_EQ(numberAfter(ctl, "robot_state_other_writer "), 4) << ctl;
  EXPECT_NE(ctl.find("SECOND ROBOT WRITER ignored (4 samples)"), std::string::npos) << ctl;
  EXPECT_NE(ctl.find("ignored: written by "), std::string::npos) << ctl;
  EXPECT_GT(accepted, 1000u) << ctl;  // 500 Hz for ~5 s, the bad ones excepted
  EXPECT_NE(ctl.find("rejected: crc 0x"), std::string::npos) << ctl;
  EXPECT_NE(ctl.find("not the size of a LowState_ with 35 motors"), std::string::npos) << ctl;
  EXPECT_NE(ctl.find("does not advance over the held tick"), std::string::npos) << ctl;
  // The stall: fresh -> stale once, said on stderr, and cycles without state counted.
  EXPECT_GE(numberAfter(ctl, "robot stale events "), 1) << ctl;  // 2 when the first cycle ran before the first state
  EXPECT_NE(ctl.find("robot state stale: no fresh state on rt/lowstate"), std::string::npos) << ctl;
  EXPECT_NE(ctl.find("arm_sdk weight at exit 0.000 (largest step 0.00500)"), std::string::npos) << ctl;

  // Commands out, checked by the robot.
  const double commands = numberAfter(out, "commands ");
  EXPECT_GT(commands, 500) << out;  // 200 Hz for ~4.5 s and the ramp out
  EXPECT_EQ(numberAfter(out, "crc_ok "), commands) << out;
  EXPECT_EQ(numberAfter(out, "crc_bad "), 0) << out;
  EXPECT_EQ(numberAfter(out, "non_finite "), 0) << out;
  EXPECT_EQ(numberAfter(out, "out_of_range "), 0) << out;
  EXPECT_NEAR(numberAfter(out, "weight_max "), 1.0, 1e-6) << out;
  EXPECT_EQ(numberAfter(out, "weight_last "), 0.0) << out;
  // Never a jump: the controller's step is 0.005 (dt / ramp time); the robot may miss a best-effort
  // sample now and then, which doubles what it sees.
  EXPECT_LE(numberAfter(out, "max_up_step "), 0.0151) << out;
  EXPECT_LE(numberAfter(out, "max_down_step "), 0.0151) << out;
  // While the tick stood still (150 states, 300 ms from 2.5 s) nothing was commanded after the 50 ms timeout.
  EXPECT_GE(numberAfter(out, "longest_gap_ms "), 200) << out;
  const double gap_start = numberAfter(out, "gap_start_s ");
  EXPECT_GE(gap_start, 2.4) << out;
  EXPECT_LE(gap_start, 2.7) << out;
  // The slots: the map's arm_sdk motors with its gains, the rest (legs, 29's mode, unused) off.
  std::map<int, const hg::HgMotor*> by_slot;
  for (const auto& m : map.motors) by_slot[m.motor] = &m;
  for (int slot = 0; slot < hg::kMotors; ++slot) {
    char key[32];
    std::snprintf(key, sizeof(key), "slot %d mode ", slot);
    const double mode = numberAfter(out, key);
    const auto it = by_slot.find(slot);
    const bool commanded = it != by_slot.end() && slot >= hg::kArmSdkFirst && slot <= hg::kArmSdkLast;
    EXPECT_EQ(mode, commanded ? 1 : 0) << "slot " << slot;
    const std::string line = out.substr(out.find(key));
    float kp = -1, kd = -1;
    ASSERT_EQ(std::sscanf(line.c_str(), "slot %*d mode %*d kp %f kd %f", &kp, &kd), 2) << line;
    EXPECT_FLOAT_EQ(kp, commanded ? static_cast<float>(it->second->kp) : 0.0f) << "slot " << slot;
    EXPECT_FLOAT_EQ(kd, commanded ? static_cast<float>(it->second->kd) : 0.0f) << "slot " << slot;
  }
}

std::string writeMap(const std::string& name, const std::string& text) {
  const std::string path = testing::TempDir() + "/" + name;
  std::ofstream(path) << text;
  return path;
}

TEST(UnitreeHgCyclone, AMapTheRobotCannotServeIsRefusedAtStart) {
  std::string base = readFile(kMap);
  // A joint the model does not have (a G1 name on the asimo_like robot).
  std::string unknown = base;
  unknown.replace(unknown.find("joint: l_elbow,"), std::string("joint: l_elbow,").size(), "joint: left_elbow_joint,");
  const std::string unknown_path = writeMap("unknown.hg.yaml", unknown);
  ChildProcess c1({binPath("reflex_controller"), "--robot", "unitree_hg", "--joint-map", unknown_path, "--domain", "13",
                   "--duration", "1", "--peer-probe", "0"},
                  testing::TempDir() + "/unknown.log");
  EXPECT_EQ(c1.wait(std::chrono::seconds(20)), 2);
  const std::string e1 = readFile(testing::TempDir() + "/unknown.log");
  EXPECT_NE(e1.find("joint 'left_elbow_joint' is not a joint of the robot model 'asimo_like'"), std::string::npos)
      << e1;
  // A motor the message does not have (35 slots: 0..34).
  std::string beyond = base;
  beyond.replace(beyond.find("motor: 31,"), std::string("motor: 31,").size(), "motor: 35,");
  const std::string beyond_path = writeMap("beyond.hg.yaml", beyond);
  ChildProcess c2({binPath("reflex_controller"), "--robot", "unitree_hg", "--joint-map", beyond_path, "--domain", "13",
                   "--duration", "1", "--peer-probe", "0"},
                  testing::TempDir() + "/beyond.log");
  EXPECT_EQ(c2.wait(std::chrono::seconds(20)), 2);
  const std::string e2 = readFile(testing::TempDir() + "/beyond.log");
  EXPECT_NE(e2.find("motor"), std::string::npos) << e2;
  EXPECT_NE(e2.find("value '35'"), std::string::npos) << e2;
  // No map given and none beside the URDF, and a map for another robot side.
  const std::string small = std::string(REFLEX_SOURCE_DIR) + "/bringup/robots/small_humanoid.urdf";
  ChildProcess c3(
      {binPath("reflex_controller"), "--robot", "unitree_hg", "--urdf", small, "--domain", "13", "--peer-probe", "0"},
      testing::TempDir() + "/nomap.log");
  EXPECT_EQ(c3.wait(std::chrono::seconds(20)), 2);
  const std::string e3 = readFile(testing::TempDir() + "/nomap.log");
  EXPECT_NE(e3.find("no joint map: --joint-map not given and no '" + std::string(REFLEX_SOURCE_DIR) +
                    "/bringup/robots/small_humanoid.hg.yaml' beside the URDF"),
            std::string::npos)
      << e3;
  ChildProcess c4(
      {binPath("reflex_controller"), "--robot", "dds", "--joint-map", kMap, "--domain", "13", "--peer-probe", "0"},
      testing::TempDir() + "/ddsmap.log");
  EXPECT_EQ(c4.wait(std::chrono::seconds(20)), 2);
  const std::string e4 = readFile(testing::TempDir() + "/ddsmap.log");
  EXPECT_NE(e4.find("is for --robot unitree_hg, not 'dds'"), std::string::npos) << e4;
}

}  // namespace
