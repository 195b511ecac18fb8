// reflex::view::readLogScenes (include/reflex/view/log_scene.hpp): the rows of a controller time series
// as scene inputs, for the report's 3D strip. Checked against hand-written CSV files: the nearest row
// to each time (ties to the earlier row), the joint values by name (columns in another order than the
// model's), each arm's zone / f / distance / closest pair, the e-stop, the targets only when "given",
// and every bad input named (missing column, short row, NaN joint, unknown zone, non-finite time).
#include <reflex/control/controller.hpp>
#include <reflex/view/log_scene.hpp>

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <string>

namespace {

using namespace reflex::view;

SceneModel asimo() {
  return loadSceneModel(std::string(REFLEX_SOURCE_DIR) + "/bringup/robots/asimo_like.urdf", "", "");
}

/// A CSV with the model's joints in reverse order (all 0 except l_elbow = row index / 10) and `extra`
/// columns; `rows` gives time and the extra values of each row.
std::string writeLog(const SceneModel& scene, const std::string& name, const std::string& extra_header,
                     const std::vector<std::pair<std::string, std::string>>& rows) {
  const std::string path = ::testing::TempDir() + name;
  std::ofstream f(path);
  f << "time";
  for (int i = scene.model.nq - 1; i >= 0; --i) f << ",q_" << scene.model.q_names[static_cast<std::size_t>(i)];
  f << extra_header << "\n";
  int k = 0;
  for (const auto& [time, extra] : rows) {
    f << time;
    for (int i = scene.model.nq - 1; i >= 0; --i)
      f << "," << (scene.model.q_names[static_cast<std::size_t>(i)] == "l_elbow" ? std::to_string(-0.1 * k) : "0");
    f << extra << "\n";
    ++k;
  }
  return path;
}

const std::string kArms =
    ",left_f,left_distance,left_pair,left_zone,left_status,left_target_x,left_target_y,left_target_z,"
    "right_f,right_distance,right_pair,right_zone,right_status,right_target_x,right_target_y,right_target_z,estop";

TEST(LogScene, NearestRowsWithTheirJointsZonesAndTargets) {
  const SceneModel scene = asimo();
  const std::string path = writeLog(
      scene, "log_ok.csv", kArms,
      {{"0.0", ",0,0.2,,free,no_target,nan,nan,nan,0,0.3,,free,no_target,nan,nan,nan,0"},
       {"1.0", ",0.5,0.012,chest|l_hand,yellow,given,0.3,0.2,1.0,0,0.3,,free,no_target,nan,nan,nan,0"},
       {"2.0", ",1,0.004,r_forearm|l_hand,red,given,0.3,0.2,1.0,1,0.004,r_forearm|l_hand,red,given,0.3,-0.1,0.9,2"}});
  // 0.5 is a tie between rows 1 and 2: the earlier row.
  const std::vector<LogScene> s = readLogScenes(scene, path, {1.6, 0.5, -3.0, 99.0});
  ASSERT_EQ(s.size(), 4u);
  EXPECT_EQ(s[0].row, 3u);
  EXPECT_DOUBLE_EQ(s[0].t, 2.0);
  EXPECT_EQ(s[1].row, 1u);
  EXPECT_EQ(s[2].row, 1u);
  EXPECT_EQ(s[3].row, 3u);
  const int elbow = scene.model.qIndex("l_elbow");
  EXPECT_DOUBLE_EQ(s[0].input.q[elbow], -0.2);
  EXPECT_DOUBLE_EQ(s[0].input.q.cwiseAbs().sum(), 0.2) << "every other joint 0";
  const ArmState& left = s[0].input.arms[0];
  EXPECT_TRUE(left.valid);
  EXPECT_EQ(left.zone, Zone::kRed);
  EXPECT_DOUBLE_EQ(left.blend_f, 1.0);
  EXPECT_DOUBLE_EQ(left.distance, 0.004);
  EXPECT_EQ(left.closest_a, "r_forearm");
  EXPECT_EQ(left.closest_b, "l_hand");
  EXPECT_TRUE(left.estop_latched);
  EXPECT_TRUE(s[0].input.targets[1].given);
  EXPECT_DOUBLE_EQ(s[0].input.targets[1].p_B.y(), -0.1);
  EXPECT_EQ(s[1].input.arms[0].zone, Zone::kFree);
  EXPECT_FALSE(s[1].input.targets[0].given) << "no_target: not drawn";
  EXPECT_TRUE(s[1].input.arms[0].closest_a.empty());
  // The scene builder takes it: the left arm's segments red.
  SceneData data(scene);
  ASSERT_TRUE(updateScene(scene, data, s[0].input));
  EXPECT_EQ(data.segment_zone[static_cast<std::size_t>(scene.model.segmentIndex("l_hand"))], Zone::kRed);
}

TEST(LogScene, WithoutArmColumnsTheArmsAreNeutral) {
  const SceneModel scene = asimo();
  const std::vector<LogScene> s = readLogScenes(scene, writeLog(scene, "log_bare.csv", "", {{"0.5", ""}}), {0.0});
  ASSERT_EQ(s.size(), 1u);
  EXPECT_FALSE(s[0].input.arms[0].valid);
  EXPECT_FALSE(s[0].input.targets[0].given);
}

void expectError(const SceneModel& scene, const std::string& path, const std::vector<double>& at,
                 const std::string& text) {
  try {
    readLogScenes(scene, path, at);
    ADD_FAILURE() << "no error, expected: " << text;
  } catch (const reflex::control::ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find(text), std::string::npos) << e.what();
  }
}

TEST(LogScene, BadInputIsNamed) {
  const SceneModel scene = asimo();
  const std::string dir = ::testing::TempDir();
  std::ofstream(dir + "log_no_joint.csv") << "time,q_l_elbow\n0,0\n";
  expectError(scene, dir + "log_no_joint.csv", {0.0}, "no column q_");
  std::ofstream(dir + "log_no_time.csv") << "t,q_l_elbow\n0,0\n";
  expectError(scene, dir + "log_no_time.csv", {0.0}, "no 'time' column");
  expectError(scene, writeLog(scene, "log_zone.csv", ",left_zone", {{"0", ",purple"}}), {0.0},
              "row 1 column left_zone: zone 'purple' is none of free, yellow, orange, red");
  expectError(scene, writeLog(scene, "log_short.csv", ",left_zone", {{"0", ""}}), {0.0}, "row 1: ");
  expectError(scene, writeLog(scene, "log_time.csv", "", {{"0", ""}, {"nan", ""}}), {0.0},
              "row 2 column time: 'nan' is not finite");
  expectError(scene, writeLog(scene, "log_f.csv", ",left_zone,left_f", {{"0", ",free,x1"}}), {0.0},
              "column left_f: 'x1' is not a number");
  {
    std::ofstream f(dir + "log_nan_q.csv");
    f << "time";
    for (const std::string& n : scene.model.q_names) f << ",q_" << n;
    f << "\n0";
    for (int i = 0; i < scene.model.nq; ++i) f << (i == 3 ? ",nan" : ",0");
    f << "\n";
  }
  expectError(scene, dir + "log_nan_q.csv", {0.0},
              "column q_" + scene.model.q_names[3] + ": 'nan' is not a finite joint position");
  expectError(scene, writeLog(scene, "log_at.csv", "", {{"0", ""}}), {NAN}, "a requested time is not finite");
  std::ofstream(dir + "log_empty.csv") << "";
  expectError(scene, dir + "log_empty.csv", {0.0}, "empty time series");
  expectError(scene, dir, {0.0}, "is a directory");
}

}  // namespace
