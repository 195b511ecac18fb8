// Randomized safety: episodes with random targets for both hands changing every
// 100 ms — inside the body, crossing, behind, while walking — must never bring a pair below d_r,
// fire the e-stop, emit a non-finite value or exceed a joint velocity limit.
// REFLEX_SOAK_EPISODES=N runs a longer soak.
#include "support/robot.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <random>
#include <string>

namespace reflex::control {
namespace {

using testing::defaultControllerModel;
using testing::shippedModel;

Scenario randomEpisode(std::uint32_t seed, bool walk) {
  Scenario s;
  s.name = "random_" + std::to_string(seed);
  s.duration = 1.5;
  if (walk) {
    s.walk_distance = 0.3;
    s.walk_speed = 0.25;
  }
  auto rng = std::make_shared<std::mt19937>(seed);
  auto next_change = std::make_shared<double>(0.0);
  s.script = [rng, next_change](double t, ControlInput& in, ScenarioContext&) {
    if (t + 1e-9 < *next_change) return;
    *next_change = t + 0.1;
    std::uniform_real_distribution<double> x(-0.35, 0.65), y(-0.55, 0.55), z(0.35, 1.45), u(0.0, 1.0);
    for (int a = 0; a < 2; ++a) {
      if (u(*rng) < 0.1) {
        in.hands[a].status = HandStatus::kNoTarget;
        continue;
      }
      in.hands[a].status = HandStatus::kGiven;
      if (u(*rng) < 0.3) {  // deliberately inside the torso
        in.hands[a].target_B = Eigen::Vector3d(0.05 * (u(*rng) - 0.5), 0.12 * (u(*rng) - 0.5), 0.65 + 0.35 * u(*rng));
      } else if (u(*rng) < 0.4) {  // crossing: a target on the other side of the body
        const double side = a == kLeft ? -1.0 : 1.0;
        in.hands[a].target_B =
            Eigen::Vector3d(0.15 + 0.25 * u(*rng), side * (0.05 + 0.3 * u(*rng)), 0.7 + 0.4 * u(*rng));
      } else {
        in.hands[a].target_B = Eigen::Vector3d(x(*rng), y(*rng), z(*rng));
      }
    }
    const double p = u(*rng);
    in.priority =
        p < 0.6 ? MotionPriority::kEqual : (p < 0.8 ? MotionPriority::kLeftHigher : MotionPriority::kRightHigher);
  };
  return s;
}

TEST(RandomSafety, ThousandEpisodesNeverReachTheRedZone) {
  const Model& model = shippedModel();
  const ControllerModel& cm = defaultControllerModel();
  int episodes = 1000;
  if (const char* env = std::getenv("REFLEX_SOAK_EPISODES")) episodes = std::max(1, std::atoi(env));
  double worst = 1.0;
  std::uint32_t worst_seed = 0;
  std::uint64_t cycles = 0;
  SimOptions options;
  options.record = false;
  for (int e = 0; e < episodes; ++e) {
    const auto seed = static_cast<std::uint32_t>(e + 1);
    const SimResult r = runScenario(model, cm, randomEpisode(seed, e % 4 == 0), options);
    cycles += r.cycles;
    if (r.min_distance < worst) {
      worst = r.min_distance;
      worst_seed = seed;
    }
    ASSERT_GE(r.min_distance, cm.params.d_r)
        << "episode seed " << seed << " pair " << r.min_pair << " at t=" << r.min_time;
    ASSERT_FALSE(r.estop_fired) << "episode seed " << seed;
    ASSERT_FALSE(r.non_finite) << "episode seed " << seed;
    ASSERT_LE(r.max_joint_speed_ratio, 1.0 + 1e-9) << "episode seed " << seed;
  }
  std::printf("%d episodes, %llu cycles, closest approach %.2f mm (seed %u)\n", episodes,
              static_cast<unsigned long long>(cycles), worst * 1000.0, worst_seed);
}

// A randomized attack on "a configuration that validates can work" (controller.hpp): parameter sets
// drawn inside every range of controllerParamRanges (each key redrawn with probability 1/2, log-uniform
// over a wide range; keys whose range the others moved are redrawn until all validate), on every
// shipped robot with its own arms, each run through random episodes. A set is either refused at
// set-up (only for a rest posture inside the red zone, naming it) or keeps every pair at or above
// its d_r with no e-stop, no NaN and no joint above its limit.
ControllerParams randomValidParams(ControllerParams p, std::mt19937& rng) {
  std::uniform_real_distribution<double> u(0.0, 1.0);
  auto draw = [&](const ParamRange& r) {
    double v = r.lo > 0.0 && r.hi / r.lo > 20.0 ? r.lo * std::pow(r.hi / r.lo, u(rng)) : r.lo + (r.hi - r.lo) * u(rng);
    if (r.lo_open && v <= r.lo) v = std::nextafter(r.lo, r.hi);
    if (r.hi_open && v >= r.hi) v = std::nextafter(r.hi, r.lo);
    return v;
  };
  for (const ParamRange& r : controllerParamRanges(p)) {
    double* field = controllerParamField(p, r.key);
    if (field == nullptr)
      ADD_FAILURE() << "a range for an unknown key " << r.key;
    else if (u(rng) < 0.5 && r.hi > r.lo)
      *field = draw(r);
  }
  for (int pass = 0; pass < 4; ++pass)  // the ends that depend on other keys moved with them
    for (const ParamRange& r : controllerParamRanges(p))
      if (double* field = controllerParamField(p, r.key); field != nullptr && !r.contains(*field) && r.hi > r.lo)
        *field = draw(r);
  return p;
}

TEST(RandomSafety, EveryParameterSetThatValidatesKeepsEveryShippedRobotOutOfTheRedZone) {
  std::mt19937 rng(14);
  int refused = 0, runs = 0;
  for (const std::string robot : {"asimo_like", "small_humanoid", "mesh_humanoid", "many_segment_humanoid"}) {
    const Model model = testing::loadRobot(robot);
    const ControllerConfig base = loadControllerConfigFor(testing::robotPath(robot + ".urdf"), "");
    SimOptions options;
    options.record = false;
    for (int set = 0; set < 40; ++set) {
      ControllerConfig config = base;
      config.params = randomValidParams(base.params, rng);
      config.source = robot + " set " + std::to_string(set);
      ASSERT_NO_THROW(validateControllerParams(config.params, config.source)) << config.source;
      ControllerModel cm;
      try {
        cm = makeControllerModel(model, config);
      } catch (const ConfigError& e) {
        EXPECT_NE(std::string(e.what()).find("at the rest posture"), std::string::npos) << e.what();
        ++refused;
        continue;
      }
      for (int episode = 0; episode < 2; ++episode) {
        const auto seed = static_cast<std::uint32_t>(1000 * set + episode + 1);
        const SimResult r = runScenario(model, cm, randomEpisode(seed, episode == 0), options);
        ++runs;
        ASSERT_GE(r.min_distance, cm.params.d_r) << config.source << " episode " << seed << " pair " << r.min_pair;
        ASSERT_FALSE(r.estop_fired) << config.source << " episode " << seed;
        ASSERT_FALSE(r.non_finite) << config.source << " episode " << seed;
        ASSERT_LE(r.max_joint_speed_ratio, 1.0 + 1e-9) << config.source << " episode " << seed;
      }
    }
  }
  std::printf("%d episodes with random valid parameters, %d parameter sets refused (rest posture in the red zone)\n",
              runs, refused);
  EXPECT_GT(refused, 0) << "the draw must reach the refused case";
  EXPECT_GT(runs, 200);
}

}  // namespace
}  // namespace reflex::control
