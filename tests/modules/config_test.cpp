// Configuration errors name file, line, key and value; unknown module types and keys are errors at
// start; every shipped configuration in bringup/behavior/ loads and builds a host.
#include "modules_test_support.hpp"
#include "support/errors.hpp"

#include <reflex/modules/scripted.hpp>

#include <filesystem>
#include <fstream>

namespace reflex::modules {
namespace {

std::string errorOf(const std::string& yaml, const std::string& only = "") {
  return reflex::testing::messageOf<ConfigError>([&] { testing::TestHost h(yaml, builtinRegistry(), only); }, "");
}

void expectAll(const std::string& message, std::initializer_list<const char*> parts) {
  ASSERT_FALSE(message.empty()) << "expected a ConfigError";
  for (const char* p : parts) EXPECT_NE(message.find(p), std::string::npos) << "'" << p << "' not in: " << message;
}

TEST(ModulesConfig, UnknownModuleTypeNamesItAndTheKnownOnes) {
  expectAll(errorOf("modules:\n  - {name: p, type: pointng}\n"),
            {"test.yaml:2", "modules[0].type", "unknown module type", "'pointng'", "pointing, scripted"});
}

TEST(ModulesConfig, BadValueNamesFileLineKeyAndValue) {
  expectAll(errorOf("modules:\n  - name: p\n    type: pointing\n    config:\n      ray_distance: abc\n"),
            {"test.yaml:5:21: modules[0].config.ray_distance: not a finite number (value 'abc', expected a number in "
             "[0.05, "});
  expectAll(errorOf("modules:\n  - {name: p, type: pointing, config: {ray_distance: 0.9}}\n"),
            {"modules[0].config.ray_distance", "out of range", "'0.9'"});
  expectAll(errorOf("modules:\n  - {name: p, type: pointing, config: {ray_distance: .nan}}\n"),
            {"modules[0].config.ray_distance", "'.nan'"});
  expectAll(errorOf("modules:\n  - {name: p, type: pointing, config: {mode: laser}}\n"),
            {"modules[0].config.mode: unknown value (value 'laser', expected one of ray, object)"});
  expectAll(errorOf("modules:\n  - {name: p, type: pointing, config: {hands: [left, foot]}}\n"),
            {"modules[0].config.hands", "'[left, foot]'"});
  expectAll(errorOf("modules:\n  - {name: g, type: grasped_bar, config: {point_a: [0, 1]}}\n"),
            {"modules[0].config.point_a", "[x, y, z]", "'[0, 1]'"});
  expectAll(errorOf("inputs: {future_tolerance: -1}\nmodules:\n  - {name: p, type: pointing}\n"),
            {"test.yaml:1", "inputs.future_tolerance", "'-1'"});
}

TEST(ModulesConfig, UnknownKeysAreErrors) {
  expectAll(errorOf("modules:\n  - {name: p, type: pointing, config: {ray_distanse: 0.3}}\n"),
            {"modules[0].config.ray_distanse", "unknown key", "ray_distance"});
  expectAll(errorOf("modulez: []\n"), {"test.yaml:1:1: modulez: unknown key (expected one of "});
}

TEST(ModulesConfig, StructuralErrors) {
  expectAll(errorOf("process: behavior\n"), {"test.yaml:1:1: modules: missing (expected a list of modules)"});
  expectAll(errorOf("modules: []\n"), {"modules", "empty"});
  expectAll(
      errorOf("modules:\n  - {name: a, type: pointing}\n  - {name: a, type: walking, config: {goal: [1, 0, 0]}}\n"),
      {"modules[1].name", "duplicate", "'a'"});
  expectAll(errorOf("modules:\n  - {name: w, type: walking}\n"),
            {"modules[0].config.goal: missing (expected [x, y, yaw] in the world frame)"});
  expectAll(errorOf("modules:\n  - {name: o, type: occlusion}\n"), {"exactly one of 'object'"});
  expectAll(errorOf("modules:\n  - name\n"), {"modules[0]", "expected a map"});
  expectAll(errorOf("robot: {left_hand: paw}\nmodules:\n  - {name: p, type: pointing}\n"),
            {"robot.left_hand", "no link 'paw'"});
  expectAll(errorOf("robot: {urdf: /nonexistent/robot.urdf}\nmodules:\n  - {name: p, type: pointing}\n"),
            {"/nonexistent/robot.urdf"});
}

TEST(ModulesConfig, FileErrorsNameTheFile) {
  const ModuleRegistry r = builtinRegistry();
  try {
    loadHostConfig("/nonexistent/behavior.yaml", r);
    FAIL();
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("/nonexistent/behavior.yaml"), std::string::npos);
  }
  const std::string path = ::testing::TempDir() + "modules_config_syntax.yaml";
  std::ofstream(path) << "modules:\n  - {name: p, type: [pointing\n";
  try {
    loadHostConfig(path, r);
    FAIL();
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find(path), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("syntax"), std::string::npos) << e.what();
  }
}

TEST(ModulesConfig, RegistryRefusesDuplicatesAndUnknownTypes) {
  ModuleRegistry r = builtinRegistry();
  EXPECT_THROW(r.add("pointing", "again", [](const std::string& n) { return std::make_unique<ScriptedModule>(n); }),
               ConfigError);
  EXPECT_THROW(r.create("nosuch", "x"), ConfigError);
  EXPECT_EQ(r.types(), (std::vector<std::string>{"grasped_bar", "occlusion", "pointing", "scripted", "walking"}));
}

TEST(ModulesConfig, TimelineCsvErrorsNameFileLineAndColumn) {
  const std::string dir = ::testing::TempDir();
  auto write = [&](const std::string& name, const std::string& text) {
    std::ofstream(dir + name) << text;
    return dir + name;
  };
  auto err = [](const std::string& path) {
    try {
      readTimelineCsv(path);
    } catch (const ConfigError& e) {
      return std::string(e.what());
    }
    return std::string();
  };
  const std::string bad_number = write("tl_bad.csv", "t,hand,x,y,z\n0,right,0.3,abc,1.0\n");
  expectAll(err(bad_number), {"tl_bad.csv:2", "column 'y'", "'abc'"});
  expectAll(err(write("tl_hand.csv", "t,hand,x,y,z\n# comment\n0,foot,0.3,0,1.0\n")),
            {"tl_hand.csv:3", "column 'hand'", "'foot'"});
  expectAll(err(write("tl_order.csv", "t,hand,x,y,z\n2,right,none,,\n1,right,none,,\n")),
            {"tl_order.csv:3", "out of time order"});
  expectAll(err(write("tl_header.csv", "time,hand,x,y,z\n")), {"tl_header.csv:1", "header"});
  expectAll(err(write("tl_far.csv", "t,hand,x,y,z\n0,left,3,0,0\n")), {"tl_far.csv:2", "farther than 2 m"});
  expectAll(err(write("tl_prio.csv", "t,hand,x,y,z\n0,priority,up,,\n")), {"tl_prio.csv:2", "'up'"});
  expectAll(err(dir + "tl_missing.csv"), {"tl_missing.csv", "cannot be opened"});
  expectAll(
      errorOf(
          "modules:\n  - {name: s, type: scripted, config: {timeline: [{t: 1, left: none}, {t: 0.5, left: none}]}}\n"),
      {"modules[0].config.timeline[1].t", "out of time order"});
  expectAll(errorOf("modules:\n  - {name: s, type: scripted, config: {}}\n"), {"exactly one of 'timeline'"});
}

TEST(ModulesConfig, EveryShippedConfigurationLoadsAndStarts) {
  const ModuleRegistry registry = builtinRegistry();
  int n = 0;
  for (const auto& entry : std::filesystem::directory_iterator(std::string(REFLEX_SOURCE_DIR) + "/bringup/behavior")) {
    if (entry.path().extension() != ".yaml") continue;
    SCOPED_TRACE(entry.path().string());
    const HostConfig config = loadHostConfig(entry.path().string(), registry);
    testing::RecordingSink sink;
    BehaviorHost host(config, registry, sink, [](const std::string&) {});
    host.start(testing::at(0.0));
    for (double t = 0.02; t < 2.0; t += 0.02) host.tick(testing::at(t));
    host.stop(testing::at(2.0));
    EXPECT_EQ(host.stats().forced_cleanups, 0u);
    EXPECT_EQ(host.stats().outputs_rejected, 0u);
    EXPECT_TRUE(!host.hand(Hand::kLeft).given && !host.hand(Hand::kRight).given);
    EXPECT_TRUE(host.segments().empty());
    ++n;
  }
  EXPECT_GE(n, 3);
}

}  // namespace
}  // namespace reflex::modules
