// Controller configuration: defaults are the paper's, YAML overrides them, every bad value is a
// ConfigError that names the file, the key and the value. Every numeric key's documented range
// (control/README.md; written out again here) is tested at both ends: at the end (accepted unless
// the end is open), just beyond it (refused, naming file, key, value and range) and just inside.
#include "support/robot.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdio>
#include <fstream>
#include <iomanip>
#include <sstream>
#include <vector>
#include <unistd.h>

namespace reflex::control {
namespace {

std::string writeTemp(const std::string& text) {
  char name[] = "/tmp/reflex_controller_XXXXXX.yaml";
  const int fd = mkstemps(name, 5);
  EXPECT_GE(fd, 0);
  close(fd);
  std::ofstream(name) << text;
  return name;
}

void expectError(const std::string& yaml, const std::string& needle) {
  const std::string path = writeTemp(yaml);
  try {
    const ControllerConfig c = loadControllerConfig(path);
    makeControllerModel(testing::shippedModel(), c);
    ADD_FAILURE() << "no error for:\n" << yaml;
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find(needle), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find(path), std::string::npos) << e.what();
  }
  std::remove(path.c_str());
}

/// A segment of several links moves as one body for the controller (its row is taken on its link):
/// an arm joint between its links is refused, naming the segment, the link and the joint; a segment
/// whose links no arm joint moves apart (the head with the torso: neck joints) is taken.
TEST(ControllerConfig, ASegmentThatAnArmJointBendsIsRefused) {
  CollisionConfig c = loadCollisionConfig(testing::robotPath("mesh_humanoid.collision.yaml"));
  c.segments = {{"l_forearm", {"l_hand"}}};
  const Model bent = loadModel(testing::robotPath("mesh_humanoid.urdf"), c);
  const ControllerConfig config = loadControllerConfig(testing::robotPath("mesh_humanoid.controller.yaml"));
  try {
    makeControllerModel(bent, config);
    ADD_FAILURE() << "a segment bent by l_wrist_pitch was taken";
  } catch (const ConfigError& e) {
    const std::string what = e.what();
    for (const char* part :
         {"mesh_humanoid.controller.yaml", "segment 'l_forearm' takes in link 'l_hand'", "arm joint 'l_wrist_pitch'"})
      EXPECT_NE(what.find(part), std::string::npos) << what;
  }
  c.segments = {{"torso", {"head"}}};
  const Model head = loadModel(testing::robotPath("mesh_humanoid.urdf"), c);
  const ControllerModel cm = makeControllerModel(head, config);
  EXPECT_EQ(cm.arms[kLeft].n, 5);
}

TEST(ControllerConfig, DefaultsAreThePapers) {
  const ControllerParams p;
  EXPECT_DOUBLE_EQ(p.d_a, 0.040);
  EXPECT_DOUBLE_EQ(p.d_b, 0.010);
  EXPECT_DOUBLE_EQ(p.d_r, 0.005);
  EXPECT_DOUBLE_EQ(p.period, 0.005);
  EXPECT_EQ(p.mode, AvoidanceMode::kOneDof);
}

TEST(ControllerConfig, YamlOverridesDefaults) {
  const std::string path =
      writeTemp("d_a: 0.05\nd_b: 0.012\navoidance: three_dof\narms:\n  left:\n    rest: [0.1, 0.2, 0.0, -0.4, 0.0]\n");
  const ControllerConfig c = loadControllerConfig(path);
  EXPECT_DOUBLE_EQ(c.params.d_a, 0.05);
  EXPECT_DOUBLE_EQ(c.params.d_b, 0.012);
  EXPECT_DOUBLE_EQ(c.params.d_r, 0.005);
  EXPECT_EQ(c.params.mode, AvoidanceMode::kThreeDof);
  const ControllerModel cm = makeControllerModel(testing::shippedModel(), c);
  EXPECT_DOUBLE_EQ(cm.arms[kLeft].rest[3], -0.4);
  std::remove(path.c_str());
}

TEST(ControllerConfig, BadValuesAreClearErrors) {
  expectError("d_a: 0.005\n", "d_r < d_b < d_a");
  expectError("d_b: -0.01\n", "d_b: outside its range (value '-0.01'");
  expectError("k_virtual: 0\n", "k_virtual: outside its range (value '0'");
  expectError("period: 1.5\n", "period: outside its range (value '1.5'");
  expectError("damping: .nan\n", "damping: not a finite number (value '.nan'");
  expectError("d_safe: 0.01\n", "d_safe: outside its range (value '0.01'");
  expectError("avoidance: sideways\n",
              "avoidance: unknown value (value 'sideways', expected one of one_dof, three_dof, off)");
  expectError("alpha_t: fast\n", "alpha_t: not a finite number (value 'fast'");
  expectError("no_such_key: 1\n", ":1:1: no_such_key: unknown key (expected one of avoidance, camera_link, arms, d_a");
  expectError("guard_rate: 500\n", "guard_rate");
  expectError("arms:\n  left:\n    joints: [l_shoulder_pitch, no_such_joint]\n    rest: [0, 0]\n", "no_such_joint");
  expectError("arms:\n  left:\n    rest: [0, 0]\n", "rest has 2 values");
  expectError("arms:\n  left:\n    rest: [0, 9, 0, 0, 0]\n", "outside its limits");
  expectError("arms:\n  middle:\n    rest: [0]\n", ":2:3: arms.middle: unknown key (expected one of left, right)");
  expectError("arms:\n  left:\n    hand_link: nowhere\n", "nowhere");
  expectError("arms:\n  right:\n    joints: [l_shoulder_pitch, r_shoulder_roll, r_shoulder_yaw, r_elbow, r_wrist]\n",
              "used twice");
  expectError("d_a: [1, 2\n", "YAML syntax error");
  EXPECT_THROW(loadControllerConfig("/nonexistent/controller.yaml"), ConfigError);
}

/// One end of a parameter's documented range (control/README.md, "Controller parameters"), written
/// here independently of controllerParamRanges. `context` sets other keys so that only this one
/// can be out of range (e.g. a large d_r needs larger d_b, d_a).
struct Bound {
  const char* key;
  double value;         // the end
  bool upper;           // true: the upper end
  bool open;            // true: the end itself is outside
  const char* context;  // other keys, YAML
};

const std::vector<Bound>& documentedBounds() {
  static const std::vector<Bound> bounds = {
      {"d_r", 0.0, false, true, ""},
      {"d_r", 0.05, true, false, "d_b: 0.06\nd_a: 0.1\n"},
      {"d_b", 0.005, false, true, "guard_margin: 0\npredict_margin: 0\nestop_release_margin: 0\n"},
      {"d_b", 0.1, true, false, "d_a: 0.15\nd_safe: 0.2\n"},
      {"d_a", 0.01, false, true, ""},
      {"d_a", 0.2, true, false, "d_safe: 0.3\n"},
      {"d_safe", 0.04, false, false, ""},
      {"d_safe", 0.5, true, false, ""},
      {"period", 0.001, false, false, ""},
      {"period", 0.1, true, false, "alpha_t: 5\nreach_gain: 5\nguard_rate: 2\n"},
      {"k_virtual", 0.5, false, false, ""},
      {"k_virtual", 100.0, true, false, ""},  // 0.5 / period
      {"alpha_ca", 0.0, false, false, ""},
      {"alpha_ca", 100.0, true, false, ""},
      {"alpha_t", 1.0, false, false, ""},
      {"alpha_t", 200.0, true, false, ""},  // 1 / period
      {"alpha_jla", 0.0, false, false, ""},
      {"alpha_jla", 10.0, true, false, ""},
      {"alpha_rest", 0.0, false, false, ""},
      {"alpha_rest", 200.0, true, false, ""},  // 1 / period
      {"damping", 0.001, false, false, ""},
      {"damping", 0.2, true, false, ""},
      {"reach_gain", 1.0, false, false, ""},
      {"reach_gain", 200.0, true, false, ""},  // 1 / period
      {"max_task_speed", 0.05, false, false, "trajectory_speed: 0.05\n"},
      {"max_task_speed", 2.0, true, false, ""},
      {"trajectory_speed", 0.01, false, false, ""},
      {"trajectory_speed", 0.6, true, false, ""},  // max_task_speed
      {"guard_rate", 1.0, false, false, ""},
      {"guard_rate", 100.0, true, false, ""},  // 0.5 / period
      {"guard_margin", 0.0, false, false, ""},
      {"guard_margin", 0.005, true, true, ""},  // d_b - d_r
      {"predict_margin", 0.0, false, false, ""},
      {"predict_margin", 0.005, true, true, ""},  // d_b - d_r
      {"estop_release_margin", 0.0, false, false, ""},
      {"estop_release_margin", 0.005, true, false, ""},  // d_b - d_r
  };
  return bounds;
}

std::string text(double v) {
  std::ostringstream os;
  os << std::setprecision(15) << v;
  return os.str();
}

/// Loads `yaml`; "" if accepted (library load and model), else the ConfigError's message.
std::string tryLoad(const std::string& yaml, std::string& path) {
  path = writeTemp(yaml);
  std::string error;
  try {
    makeControllerModel(testing::shippedModel(), loadControllerConfig(path));
  } catch (const ConfigError& e) {
    error = e.what();
  }
  std::remove(path.c_str());
  return error;
}

TEST(ControllerConfig, EveryBoundHoldsAtItsEndAndFailsJustBeyondNamingKeyValueRangeAndFile) {
  int accepted = 0, refused = 0;
  for (const Bound& b : documentedBounds()) {
    // Just beyond: a relative step of 1e-6 (absolute 1e-6 at an end of 0).
    const double step = b.value == 0.0 ? 1e-6 : 1e-6 * std::abs(b.value);
    const double beyond = b.upper ? b.value + step : b.value - step;
    const double inside = b.upper ? b.value - step : b.value + step;
    for (const double v : {b.value, beyond, inside}) {
      const bool should_fail = v == beyond || (v == b.value && b.open);
      std::string path;
      const std::string value = text(v);
      const std::string error = tryLoad(std::string(b.context) + b.key + ": " + value + "\n", path);
      if (!should_fail) {
        EXPECT_EQ(error, "") << b.key << " = " << value << " must be accepted";
        ++accepted;
        continue;
      }
      ++refused;
      ASSERT_NE(error, "") << b.key << " = " << value << " must be refused";
      EXPECT_NE(error.find(path), std::string::npos) << error;  // the file
      EXPECT_NE(error.find(std::string(b.key) + ": outside its range (value '" + value + "'"), std::string::npos)
          << error;  // key and value as written
      EXPECT_NE(error.find(", expected "), std::string::npos) << error;
      EXPECT_NE(error.find(text(b.value)), std::string::npos) << error;  // the range's end
    }
  }
  EXPECT_EQ(accepted + refused, 3 * static_cast<int>(documentedBounds().size()));
}

TEST(ControllerConfig, TheLibrarysRangeTableIsTheDocumentedOne) {
  // Every numeric key has both ends documented, and the library's table agrees on each end.
  const ControllerParams defaults;
  const std::vector<ParamRange> ranges = controllerParamRanges(defaults);
  EXPECT_EQ(ranges.size(), 18U);
  for (const ParamRange& r : ranges) {
    int ends = 0;
    for (const Bound& b : documentedBounds()) {
      if (std::string(b.key) != r.key) continue;
      ++ends;
      if (b.upper) {
        EXPECT_NEAR(r.hi, b.value, 1e-12) << r.key;
        EXPECT_EQ(r.hi_open, b.open) << r.key;
      } else {
        EXPECT_NEAR(r.lo, b.value, 1e-12) << r.key;
        EXPECT_EQ(r.lo_open, b.open) << r.key;
      }
    }
    EXPECT_EQ(ends, 2) << r.key;
    EXPECT_TRUE(r.contains(r.value)) << r.key << ": the defaults lie inside every range";
  }
}

TEST(ControllerConfig, ErrorsHaveTheOneFormatFileLineColumnKeyValueExpected) {
  // control/docs/configuration.md, "Error messages": the whole message, position counted by hand
  // (line 2, column 6 is the value's first character).
  const std::string path = writeTemp("d_r: 0.005\nd_b: -0.01\n");
  std::string error;
  try {
    loadControllerConfig(path);
  } catch (const ConfigError& e) {
    error = e.what();
  }
  EXPECT_EQ(error, path +
                       ":2:6: d_b: outside its range (value '-0.01', expected (d_r = 0.005, 0.1] m: zones "
                       "ordered d_r < d_b < d_a (Eq. 13))");
  std::remove(path.c_str());
  // A nested key: its full path, at its value's position.
  const std::string nested = writeTemp("arms:\n  left:\n    hand_point: [0, 0]\n");
  error.clear();
  try {
    loadControllerConfig(nested);
  } catch (const ConfigError& e) {
    error = e.what();
  }
  EXPECT_EQ(
      error,
      nested + ":3:17: arms.left.hand_point: has 2 numbers (value '[0, 0]', expected [x, y, z] of finite numbers)");
  std::remove(nested.c_str());
}

TEST(ControllerConfig, ConfigurationsThatValidateButCannotWorkAreRefused) {
  // Each validated before and gave a robot that cannot work.
  expectError("estop_release_margin: 100\n",
              "estop_release_margin: outside its range (value '100', expected [0, d_b - d_r = 0.005] m");
  expectError("alpha_t: 0\n", "alpha_t: outside its range (value '0', expected [1, 1 / period = 200] 1/s");
  expectError("reach_gain: 0\n", "reach_gain: outside its range (value '0'");
  expectError("period: 1e-9\n", "period: outside its range (value '1e-9', expected [0.001, 0.1] s");
  expectError("trajectory_speed: 1.0\n",
              "trajectory_speed: outside its range (value '1.0', expected [0.01, max_task_speed = 0.6] m/s");
  expectError("damping: 0\n", "damping: outside its range (value '0'");
  expectError("k_virtual: 1000\n", "k_virtual: outside its range (value '1000'");
}

// A randomized attack (random parameters inside every range, 300 trials on each shipped robot): the
// only configurations that validated and could not work put the rest posture inside the red zone.
// small_humanoid's feet are 11.63 mm apart at rest: with d_r 20 mm the e-stop latched at the first
// cycle and no arm could release it. Such a configuration is refused at set-up, naming the pair.
std::string restPostureError(const std::string& robot, ControllerConfig config) {
  const Model model = testing::loadRobot(robot);
  try {
    makeControllerModel(model, config);
  } catch (const ConfigError& e) {
    return e.what();
  }
  return "";
}

ControllerConfig robotConfig(const std::string& robot, double d_r, double d_b, double release) {
  ControllerConfig config = loadControllerConfigFor(testing::robotPath(robot + ".urdf"), "");
  config.source = robot + ".yaml";
  config.params.d_r = d_r;
  config.params.d_b = d_b;
  config.params.estop_release_margin = release;
  config.params.guard_margin = config.params.predict_margin = 0.0;
  config.params.d_a = std::max(config.params.d_a, d_b + 0.02);
  config.params.d_safe = std::max(config.params.d_safe, config.params.d_a);
  return config;
}

TEST(ControllerConfig, ARestPostureInsideTheRedZoneIsRefusedNamingThePairItsDistanceAndTheLimit) {
  // A pair no arm moves: the e-stop would never release.
  EXPECT_EQ(restPostureError(testing::kSmall, robotConfig(testing::kSmall, 0.020, 0.030, 0.001)),
            "small_humanoid.yaml: d_r 20.00 mm + estop_release_margin 1.00 mm = 21.00 mm is above the distance of "
            "'l_foot' and 'r_foot' at the rest posture, 11.63 mm: the red-zone e-stop would latch there and never "
            "release (no arm moves either segment); make d_r + estop_release_margin at most 11.63 mm or, if the two "
            "can never come closer, exclude the pair (collision configuration)");
  // A pair an arm moves (the 1,343-pair robot's left forearm and finger at rest, 38.00 mm).
  EXPECT_EQ(restPostureError("many_segment_humanoid", robotConfig("many_segment_humanoid", 0.040, 0.050, 0.0)),
            "many_segment_humanoid.yaml: d_r 40.00 mm + estop_release_margin 0.00 mm = 40.00 mm is above the distance "
            "of 'l_forearm' and 'l_finger2_0' at the rest posture, 38.00 mm: the red-zone e-stop would latch there "
            "whenever the arms rest; make d_r + estop_release_margin at most 38.00 mm or move the arms' rest posture");
  // The limit itself: d_r + estop_release_margin 0.1 um below and above the feet's distance at rest
  // (the sweep's value, the message's 11.63 mm).
  const Model small = testing::loadRobot(testing::kSmall);
  const ControllerModel cm = makeControllerModel(small, robotConfig(testing::kSmall, 0.005, 0.010, 0.001));
  KinematicsData kin(small);
  DistanceData dist(small);
  ASSERT_TRUE(computeForwardKinematics(small, kin, restConfiguration(small, cm)));
  computeSegmentDistances(small, kin, dist);
  const double feet = dist.pairs[static_cast<std::size_t>(dist.closest)].distance;
  EXPECT_NEAR(feet, 0.01163, 0.000005);
  EXPECT_EQ(restPostureError(testing::kSmall, robotConfig(testing::kSmall, feet - 0.001 - 1e-7, 0.02, 0.001)), "");
  EXPECT_NE(restPostureError(testing::kSmall, robotConfig(testing::kSmall, feet - 0.001 + 1e-7, 0.02, 0.001)), "");
  // Without the e-stop (reflex_sim --no-avoidance's comparison runs) there is nothing to latch.
  ControllerConfig no_estop = robotConfig(testing::kSmall, 0.020, 0.030, 0.001);
  no_estop.params.estop = false;
  EXPECT_EQ(restPostureError(testing::kSmall, no_estop), "");
  // The shipped configurations all pass (their rest postures are 11.6-57.8 mm clear).
  for (const std::string robot : {"asimo_like", "small_humanoid", "mesh_humanoid", "many_segment_humanoid"})
    EXPECT_EQ(restPostureError(robot, loadControllerConfigFor(testing::robotPath(robot + ".urdf"), "")), "") << robot;
}

TEST(ControllerConfig, AModelWithMoreSegmentsThanTheMasksHoldIsRefusedNamingCountAndLimit) {
  // Segment sets are 64-bit masks (kMaxSegments): a model built by hand past the loader's check is
  // refused at set-up, never truncated. 64 passes, 65 fails.
  Model model = testing::shippedModel();
  ASSERT_LE(model.segments.size(), static_cast<std::size_t>(kMaxSegments));
  while (model.segments.size() < static_cast<std::size_t>(kMaxSegments))
    model.segments.push_back(model.segments.back());
  // The copies are of a body-schema slot past the model's slots: a model no distance sweep can run
  // on, so the set-up's rest-posture check (which needs the e-stop) is off for the passing case.
  ControllerConfig no_estop = defaultControllerConfig();
  no_estop.params.estop = false;
  EXPECT_NO_THROW(makeControllerModel(model, no_estop));
  model.segments.push_back(model.segments.back());
  try {
    makeControllerModel(model, defaultControllerConfig());
    FAIL() << "65 segments accepted";
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find(
                  "has 65 segments (collision segments and body-schema slots); at most 64 are supported"),
              std::string::npos)
        << e.what();
  }
}

}  // namespace
}  // namespace reflex::control
