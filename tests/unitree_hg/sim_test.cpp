// The whole chain on Unitree's hg interface with the physics robot as the judge: reflex_sim
// crossing_arms --robot unitree_hg spawns reflex_mujoco --interface unitree_hg (the asimo_like robot
// behind bringup/robots/asimo_like.hg.yaml) on domain 14 and drives it through UnitreeHgPort: states
// from rt/lowstate, commands on rt/arm_sdk blended by the weight, which ramps in from 0 and, after
// the scenario, out to 0 (--ramp-time 0.25: fast, so that the weight's own limit — half of v_max dt
// per joint over the distance between Reflex's arms and the robot's own targets — is what keeps
// the ramp out smooth; with 0.25 s and no such limit a joint moved 1.23 v_max dt between two states).
//
// Judged against MuJoCo (its own collision detection at margin d_r) and the robot's measured states:
// no pair closer than d_r (0 contact samples, 0 contact steps), none below d_r by our distances on
// the measured joints, every joint's step between consecutive states at most v_max * dt (dt from
// the ticks) over the whole run, the ramp out included; the weight never moves more than
// dt / ramp time per command; the robot accepted the commands (crc, weight) and rejected none.
#include "support/files.hpp"
#include "support/child_process.hpp"

#include <gtest/gtest.h>

#include <cstdlib>
#include <fstream>
#include <string>

namespace {

using namespace reflex::testing;

using reflex::testing::numberAfter;
using reflex::testing::readFile;

TEST(UnitreeHgSim, CrossingArmsOnThePhysicsRobotRampsInAndOutWithoutContact) {
  const std::string out = testing::TempDir() + "/hg_sim";
  const ProcessResult r = runShell("'" + binPath("reflex_sim") + "' crossing_arms --robot unitree_hg --domain 14 " +
                                       "--ramp-time 0.25 --no-plots --out '" + out + "'",
                                   "", std::chrono::seconds(80));
  ASSERT_EQ(r.exit_code, 0) << r.out;
  const std::string summary = readFile(out + "/summary.txt");
  ASSERT_NE(summary.find("plant                 unitree_hg over DDS"), std::string::npos) << summary;
  EXPECT_EQ(numberAfter(summary, "MuJoCo contacts       "), 0) << summary;
  EXPECT_EQ(numberAfter(summary, "robot's contact steps "), 0) << summary;
  EXPECT_EQ(numberAfter(summary, "measured below d_r    "), 0) << summary;
  const double steps = numberAfter(summary, "measured joint steps  max |dq|/(v_max dt) ");
  EXPECT_GT(steps, 0.0) << "the arms moved\n" << summary;
  EXPECT_LE(steps, 1.0) << summary;
  const double ramp_out = numberAfter(summary, "max |qdot|/v_max while ramping out ");
  EXPECT_GE(ramp_out, 0.0) << summary;
  EXPECT_LE(ramp_out, 1.0) << summary;
  const double weight_step = numberAfter(summary, "largest step ");
  EXPECT_GT(weight_step, 0.0) << summary;
  EXPECT_LE(weight_step, 0.005 / 0.25 + 1e-9) << summary;
  const std::string robot = readFile(out + "/reflex_mujoco.log");
  EXPECT_GT(numberAfter(robot, "arm_sdk commands accepted "), 500) << robot;
  EXPECT_NE(robot.find(" rejected 0 (bad crc 0, weight 0, not finite 0, size 0), weight at exit 0,"), std::string::npos)
      << robot;
}

}  // namespace
