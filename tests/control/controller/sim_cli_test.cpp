// reflex_sim as a real process: --list, a scenario run writing the documented CSV, the comparison
// run, and clear errors for bad arguments.
#include "support/child_process.hpp"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

namespace {

struct ProcessResult {
  int status;
  std::string out;
};

ProcessResult sh(const std::string& args) {
  const reflex::testing::ProcessResult r =
      reflex::testing::runShell(reflex::testing::binPath("reflex_sim") + " " + args);
  return {r.exit_code, r.out};
}

TEST(SimCli, ListsTheScenarios) {
  const ProcessResult r = sh("--list");
  EXPECT_EQ(r.status, 0);
  for (const char* name : {"target_inside_body", "through_body", "one_vs_three_dof", "crossing_arms",
                           "walking_target_behind", "grasped_bar", "occlusion"})
    EXPECT_NE(r.out.find(name), std::string::npos) << name;
}

TEST(SimCli, WritesTheTimeSeriesCsv) {
  const auto dir = std::filesystem::temp_directory_path() / "reflex_sim_cli_test";
  std::filesystem::remove_all(dir);
  const ProcessResult r = sh("crossing_arms --no-plots --out " + dir.string());
  ASSERT_EQ(r.status, 0) << r.out;
  std::ifstream in(dir / "timeseries.csv");
  std::string header, line;
  ASSERT_TRUE(std::getline(in, header));
  for (const char* col : {"time", "left_f", "right_distance", "right_pair", "left_zone", "estop", "right_hand_x",
                          "left_target_z", "q_r_elbow"})
    EXPECT_NE(header.find(col), std::string::npos) << col;
  int rows = 0;
  while (std::getline(in, line)) ++rows;
  EXPECT_EQ(rows, 1001);  // 5 s at 5 ms, both ends
  EXPECT_TRUE(std::filesystem::exists(dir / "summary.txt"));
  EXPECT_TRUE(std::filesystem::exists(dir / "postures.csv"));
  const ProcessResult off = sh("crossing_arms --no-avoidance --no-plots --out " + dir.string());
  EXPECT_EQ(off.status, 0);
  EXPECT_NE(off.out.find("avoidance off"), std::string::npos);
  std::filesystem::remove_all(dir);
}

TEST(SimCli, BadArgumentsAreClearErrors) {
  ProcessResult r = sh("no_such_scenario --out /tmp/x");
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.out.find("no_such_scenario"), std::string::npos);
  r = sh("crossing_arms --mode sideways");
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.out.find("sideways"), std::string::npos);
  r = sh("crossing_arms --urdf /nonexistent.urdf --no-plots --out /tmp/reflex_bad");
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.out.find("/nonexistent.urdf"), std::string::npos);
  r = sh("--help");
  EXPECT_EQ(r.status, 0);
  EXPECT_NE(r.out.find("--no-avoidance"), std::string::npos);
}

}  // namespace
