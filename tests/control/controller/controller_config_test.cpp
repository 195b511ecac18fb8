// Controller configuration: defaults are the paper's, YAML overrides them, every bad value is a
// ConfigError that names the file, the key and the value.
#include "fixture.hpp"

#include <gtest/gtest.h>

#include <cstdio>
#include <fstream>
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

TEST(ControllerConfig, DefaultsAreThePapers) {
  const ControllerParams p;
  EXPECT_DOUBLE_EQ(p.d_a, 0.040);
  EXPECT_DOUBLE_EQ(p.d_b, 0.010);
  EXPECT_DOUBLE_EQ(p.d_r, 0.005);
  EXPECT_DOUBLE_EQ(p.period, 0.005);
  EXPECT_EQ(p.mode, AvoidanceMode::kOneDof);
}

TEST(ControllerConfig, YamlOverridesDefaults) {
  const std::string path = writeTemp("d_a: 0.05\nd_b: 0.012\navoidance: three_dof\narms:\n  left:\n    rest: [0.1, 0.2, 0.0, -0.4, 0.0]\n");
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
  expectError("d_b: -0.01\n", "d_b = -0.01");
  expectError("k_virtual: 0\n", "k_virtual = 0");
  expectError("period: 1.5\n", "period = 1.5");
  expectError("damping: .nan\n", "damping");
  expectError("d_safe: 0.01\n", "d_safe = 0.01");
  expectError("avoidance: sideways\n", "sideways");
  expectError("alpha_t: fast\n", "fast");
  expectError("no_such_key: 1\n", "no_such_key");
  expectError("guard_rate: 500\n", "guard_rate");
  expectError("arms:\n  left:\n    joints: [l_shoulder_pitch, no_such_joint]\n    rest: [0, 0]\n", "no_such_joint");
  expectError("arms:\n  left:\n    rest: [0, 0]\n", "rest has 2 values");
  expectError("arms:\n  left:\n    rest: [0, 9, 0, 0, 0]\n", "outside its limits");
  expectError("arms:\n  middle:\n    rest: [0]\n", "middle");
  expectError("arms:\n  left:\n    hand_link: nowhere\n", "nowhere");
  expectError("arms:\n  right:\n    joints: [l_shoulder_pitch, r_shoulder_roll, r_shoulder_yaw, r_elbow, r_wrist]\n",
              "used twice");
  expectError("d_a: [1, 2\n", "malformed YAML");
  EXPECT_THROW(loadControllerConfig("/nonexistent/controller.yaml"), ConfigError);
}

}  // namespace
}  // namespace reflex::control
