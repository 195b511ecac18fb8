// reflex_controller --robot ros2 against a ros2_control robot of another DDS implementation:
// ros2_cyclone_robot (Cyclone DDS, C; ROS 2's types from idl/ros2.idl by Cyclone's idlc, ROS 2's topic
// names and default QoS), both real processes on domain 24. No ROS 2 is installed: the wire is the test.
//
// Checked against what the robot program saw and sent (independent of the controller's code):
//  - state in, commands out, for both command kinds: sensor_msgs/JointState on rt/joint_states drives
//    the controller; every std_msgs/Float64MultiArray on rt/forward_position_controller/commands (or
//    JointTrajectory on rt/<controller>/joint_trajectory) has one finite value per joint of the
//    controller's list, in its order (the trajectory: those names, one point, time_from_start set);
//    no commanded joint moves faster than its velocity limit between two commands;
//  - matching needs the same type names and compatible QoS: the robot uses ROS 2's default QoS
//    (reliable, keep last 10) on both sides, so a sample flowing at all checks both;
//  - the robot's bad states (a model joint missing: its name changed, one position too few, a name
//    twice, a NaN, a stamp 1 s ahead) are each rejected, counted by cause in the exit line exactly as
//    sent, and named on stderr; its states stamped 0 and its states without velocities are accepted;
//    a joint the model does not have (gripper_joint) is ignored;
//  - a joint the model does not have in --ros-joints, an unknown --ros-command and the ROS options
//    with another robot side are refused at start (exit 1), named.
#include "support/files.hpp"

#include "reflex/control/controller.hpp"
#include "reflex/control/scenarios.hpp"
#include "reflex/control/urdf_loader.hpp"
#include "support/child_process.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdio>
#include <sstream>
#include <string>
#include <vector>

namespace {

using namespace reflex::testing;
using reflex::testing::numberAfter;
using reflex::testing::readFile;

const std::string kUrdf = std::string(REFLEX_SOURCE_DIR) + "/bringup/robots/asimo_like.urdf";

struct PairRun {
  std::string robot_out, controller_log;
  std::vector<std::string> joints;  ///< the controller's commanded joints, as it announced them
};

/// The controller (extra arguments) and the robot (--command kind, --controller name) on domain 24.
PairRun runPair(const std::vector<std::string>& controller_extra, const std::string& kind,
                const std::string& controller_name, double bad_at, const std::string& tag) {
  const auto model = reflex::control::loadModel(kUrdf, reflex::control::loadCollisionConfigFor(kUrdf, ""));
  const auto cm = reflex::control::makeControllerModel(model, reflex::control::loadControllerConfigFor(kUrdf, ""));
  const Eigen::VectorXd rest = reflex::control::restConfiguration(model, cm);
  PairRun run;
  const std::string log = testing::TempDir() + "/ros2_controller_" + tag + ".log";
  std::vector<std::string> args = {
      binPath("reflex_controller"), "--robot", "ros2", "--domain", "24", "--duration", "6.5", "--peer-probe", "0"};
  args.insert(args.end(), controller_extra.begin(), controller_extra.end());
  ChildProcess controller(args, log);
  EXPECT_TRUE(controller.started()) << controller.error();
  const std::string start = controller.readUntil("reflex_controller: running at", std::chrono::seconds(30));
  EXPECT_NE(start.find("running at"), std::string::npos) << readFile(log);
  // The joints the controller commands, in its order: what a user puts in the ros2_control controller.
  const std::size_t at = start.find("for the joints [");
  EXPECT_NE(at, std::string::npos) << start;
  if (at == std::string::npos) return run;
  std::stringstream list(start.substr(at + 16, start.find(']', at) - at - 16));
  for (std::string name; std::getline(list, name, ',');) {
    name.erase(0, name.find_first_not_of(' '));
    run.joints.push_back(name);
  }
  std::string joined;
  for (const auto& j : run.joints) joined += (joined.empty() ? "" : ",") + j;
  std::vector<std::string> robot_args = {binPath("ros2_cyclone_robot"),
                                         "--domain",
                                         "24",
                                         "--joints",
                                         joined,
                                         "--command",
                                         kind,
                                         "--rename",
                                         "l_elbow",
                                         "--bad-at",
                                         std::to_string(bad_at),
                                         "--stop-at",
                                         "5.5",
                                         "--listen-until",
                                         "6.5"};
  if (!controller_name.empty()) robot_args.insert(robot_args.end(), {"--controller", controller_name});
  for (int i = 0; i < model.nq; ++i) {
    robot_args.push_back("--q");
    robot_args.push_back(model.q_names[static_cast<std::size_t>(i)] + "=" + std::to_string(rest[i]));
  }
  ChildProcess robot(robot_args, ChildOutput::pipe());
  EXPECT_TRUE(robot.started()) << robot.error();
  EXPECT_EQ(robot.wait(std::chrono::seconds(30)), 0) << robot.output();
  EXPECT_EQ(controller.wait(std::chrono::seconds(30)), 0) << readFile(log);
  run.robot_out = robot.output();
  run.controller_log = readFile(log);
  std::printf("[ robot ] %s[ controller ] %s\n", run.robot_out.c_str(),
              run.controller_log.substr(run.controller_log.rfind("reflex_controller: ")).c_str());
  return run;
}

/// The largest velocity limit of the joints named (rad/s).
double fastestLimit(const std::vector<std::string>& joints) {
  const auto model = reflex::control::loadModel(kUrdf, reflex::control::loadCollisionConfigFor(kUrdf, ""));
  double v = 0.0;
  for (const auto& j : joints) v = std::max(v, model.v_max[static_cast<std::size_t>(model.qIndex(j))]);
  return v;
}

TEST(Ros2Wire, ForwardControllerStateInCommandsOutBadStatesRejectedCountedNamed) {
  const PairRun r = runPair({}, "forward", "", 2.0, "forward");
  const std::string& out = r.robot_out;
  const std::string& ctl = r.controller_log;
  ASSERT_GE(r.joints.size(), 10u) << ctl;  // both arms of asimo_like
  EXPECT_NE(ctl.find("ROS 2 on the wire: state rt/joint_states (sensor_msgs::msg::dds_::JointState_), commands "
                     "rt/forward_position_controller/commands (std_msgs::msg::dds_::Float64MultiArray_)"),
            std::string::npos)
      << ctl;
  // What the robot sent.
  ASSERT_EQ(numberAfter(out, "missing "), 2) << out;
  ASSERT_EQ(numberAfter(out, "length "), 1) << out;
  ASSERT_EQ(numberAfter(out, "duplicate "), 1) << out;
  ASSERT_EQ(numberAfter(out, " nan "), 1) << out;
  ASSERT_EQ(numberAfter(out, "future "), 1) << out;
  ASSERT_EQ(numberAfter(out, "unstamped "), 40) << out;
  ASSERT_EQ(numberAfter(out, "no_velocity "), 40) << out;
  // Counted by cause, exactly as sent, and named.
  EXPECT_EQ(numberAfter(ctl, "robot_state_missing_joint "), 2) << ctl;
  EXPECT_EQ(numberAfter(ctl, "robot_state_length "), 1) << ctl;
  EXPECT_EQ(numberAfter(ctl, "robot_state_duplicate_name "), 1) << ctl;
  EXPECT_EQ(numberAfter(ctl, "robot_state_not_finite "), 1) << ctl;
  EXPECT_EQ(numberAfter(ctl, "robot_state_future_stamp "), 1) << ctl;
  const std::size_t states_at = ctl.find("robot ros2: states ");
  ASSERT_NE(states_at, std::string::npos) << ctl;
  unsigned long long accepted = 0, rejected = 0;
  ASSERT_EQ(std::sscanf(ctl.c_str() + states_at, "robot ros2: states %llu (rejected %llu)", &accepted, &rejected), 2);
  EXPECT_EQ(rejected, 6u)
      << "the unstamped states, those without velocities and the unknown gripper joint are accepted\n"
      << ctl;
  // 200 Hz from when the robot's reader matched (about 1.3 s after the robot started, here) until the
  // controller stops (6.5 s after it started).
  EXPECT_GT(accepted, 600u) << ctl;
  EXPECT_NE(ctl.find("rt/joint_states sample"), std::string::npos) << ctl;
  EXPECT_NE(ctl.find("rejected: joint 'l_elbow' is missing"), std::string::npos) << ctl;
  EXPECT_NE(ctl.find("is listed twice"), std::string::npos) << ctl;
  EXPECT_NE(ctl.find("ms in the future"), std::string::npos) << ctl;
  // Commands out, checked by the robot: one finite value per controller joint, no joint faster than
  // its limit (5 ms a cycle; a skipped cycle would double the step, not more than that).
  const double commands = numberAfter(out, "commands ");
  EXPECT_GT(commands, 500) << out;
  EXPECT_EQ(numberAfter(out, "wrong_size "), 0) << out;
  EXPECT_EQ(numberAfter(out, "non_finite "), 0) << out;
  EXPECT_LE(numberAfter(out, "max_step_rad "), 2 * fastestLimit(r.joints) * 0.005 * (1 + 1e-9)) << out;
  EXPECT_EQ(numberAfter(ctl.substr(states_at), "commands "), commands)
      << "every command the controller sent arrived (reliable)\n"
      << ctl;
}

TEST(Ros2Wire, TrajectoryControllerGetsOnePointPerCycleWithItsJointNames) {
  const PairRun r = runPair({"--ros-command", "trajectory", "--ros-controller", "arms_controller"}, "trajectory",
                            "arms_controller", 99.0, "trajectory");
  const std::string& out = r.robot_out;
  const std::string& ctl = r.controller_log;
  EXPECT_NE(ctl.find("commands rt/arms_controller/joint_trajectory (trajectory_msgs::msg::dds_::JointTrajectory_)"),
            std::string::npos)
      << ctl;
  EXPECT_GT(numberAfter(out, "commands "), 500) << out;
  EXPECT_EQ(numberAfter(out, "wrong_names "), 0) << out;
  EXPECT_EQ(numberAfter(out, "wrong_points "), 0) << out;
  EXPECT_EQ(numberAfter(out, "wrong_size "), 0) << out;
  EXPECT_EQ(numberAfter(out, "non_finite "), 0) << out;
  EXPECT_NE(ctl.find("robot ros2: states "), std::string::npos) << ctl;
  EXPECT_EQ(ctl.find("robot_state_"), std::string::npos) << "no bad state was sent\n" << ctl;
}

TEST(Ros2Wire, OptionsTheRobotCannotServeAreRefusedAtStart) {
  struct Case {
    std::vector<std::string> args;
    std::string want;
  };
  const std::vector<Case> cases = {
      {{"--robot", "ros2", "--ros-joints", "l_shoulder_pitch,left_elbow_joint"},
       "--ros-joints: joint 'left_elbow_joint' is not a joint of the robot 'asimo_like'"},
      {{"--robot", "ros2", "--ros-command", "effort"}, "--ros-command: unknown kind 'effort'"},
      {{"--robot", "dds", "--ros-controller", "arms"}, "are for --robot ros2, not 'dds'"},
  };
  int k = 0;
  for (const Case& c : cases) {
    const std::string log = testing::TempDir() + "/ros2_refused_" + std::to_string(k++) + ".log";
    std::vector<std::string> args = {
        binPath("reflex_controller"), "--domain", "24", "--duration", "1", "--peer-probe", "0"};
    args.insert(args.end(), c.args.begin(), c.args.end());
    ChildProcess p(args, log);
    EXPECT_EQ(p.wait(std::chrono::seconds(20)), 2) << readFile(log);
    EXPECT_NE(readFile(log).find(c.want), std::string::npos) << readFile(log);
  }
}

}  // namespace
