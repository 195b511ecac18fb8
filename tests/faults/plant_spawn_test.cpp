// The bus plant reflex_sim --robot mujoco uses (BusScenarioPlant, control/node/bus_plant.hpp), with a
// spawned robot that exits at once (as reflex_mujoco does when MuJoCo refuses a model): the plant says
// so as soon as the process has exited, with its exit status and the end of its output, instead of
// waiting the whole first-state timeout (30 s) and saying only that no state came. DDS domain 226.
#include "reflex/control/urdf_loader.hpp"
#include "reflex/control_node/bus_plant.hpp"

#include "../control/test_support.hpp"

#include <gtest/gtest.h>

#include <chrono>
#include <fstream>
#include <string>
#include <sys/stat.h>

namespace reflex {
namespace {

TEST(BusPlant, ARobotThatExitsAtOnceIsReportedAtOnceWithItsLastWords) {
  const control::Model model = testing::loadRobot("asimo_like");
  const std::string dir = ::testing::TempDir();
  const std::string script = dir + "plant_spawn_dies.sh";
  {
    std::ofstream out(script);
    out << "#!/bin/sh\necho 'robot: starting'\necho 'MuJoCo could not compile the generated MJCF: mass and inertia "
           "of moving bodies must be larger than mjMINVAL' >&2\nexit 3\n";
  }
  ASSERT_EQ(::chmod(script.c_str(), 0755), 0);
  control_node::BusPlantOptions o;
  o.domain = 226;
  o.robot_binary = script;
  o.robot_log = dir + "plant_spawn_dies.log";
  o.q_start = Eigen::VectorXd::Zero(model.nq);
  o.first_state_timeout = 30.0;
  const auto t0 = std::chrono::steady_clock::now();
  try {
    control_node::BusScenarioPlant plant(model, {}, o);
    FAIL() << "a plant without a robot started";
  } catch (const std::runtime_error& e) {
    const double waited = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    const std::string what = e.what();
    EXPECT_LT(waited, 5.0) << "said after " << waited << " s: " << what;
    EXPECT_NE(what.find("robot plant: the spawned robot (" + script +
                        ") exited with status 3 before its first state; "
                        "the end of its output (" +
                        o.robot_log +
                        "): robot: starting | MuJoCo could not compile the "
                        "generated MJCF: mass and inertia of moving bodies must be larger than mjMINVAL"),
              std::string::npos)
        << what;
  }
}

}  // namespace
}  // namespace reflex
