#include "soak.hpp"

#include <memory>
#include <random>

namespace reflex::soak {

using namespace reflex::control;

Scenario randomReactiveEpisode(std::uint64_t seed, double duration) {
  Scenario s;
  s.name = "soak_" + std::to_string(seed);
  s.duration = duration;
  std::mt19937_64 setup(seed);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  if (u(setup) < 0.2) {  // one episode in five walks forward
    s.walk_distance = 0.2 + 0.4 * u(setup);
    s.walk_speed = 0.1 + 0.2 * u(setup);
    s.walk_start = duration * 0.5 * u(setup);
  }
  struct State {
    std::mt19937_64 rng;
    double next_change = 0.0;
  };
  auto state = std::make_shared<State>();
  state->rng.seed(seed * 0x9E3779B97F4A7C15ULL + 1);
  s.script = [state](double t, ControlInput& in, ScenarioContext&) {
    if (t + 1e-9 < state->next_change) return;
    std::uniform_real_distribution<double> u(0.0, 1.0);
    auto& rng = state->rng;
    state->next_change = t + 0.05 + 0.95 * u(rng) * u(rng);  // 50 ms .. 1 s, short ones more often
    for (int a = 0; a < 2; ++a) {
      const double side = a == kLeft ? 1.0 : -1.0;  // +y is the robot's left
      const double kind = u(rng);
      HandCommand& h = in.hands[a];
      h.status = HandStatus::kGiven;
      if (kind < 0.1) {
        h.status = HandStatus::kNoTarget;
      } else if (kind < 0.35) {  // inside the torso / head: unreachable without a collision
        h.target_B = Eigen::Vector3d(0.08 * (u(rng) - 0.5), 0.16 * (u(rng) - 0.5), 0.6 + 0.6 * u(rng));
      } else if (kind < 0.6) {  // across the body: the arms meet
        h.target_B = Eigen::Vector3d(0.1 + 0.35 * u(rng), -side * (0.02 + 0.35 * u(rng)), 0.6 + 0.5 * u(rng));
      } else if (kind < 0.7) {  // behind the back
        h.target_B = Eigen::Vector3d(-0.1 - 0.3 * u(rng), 0.6 * (u(rng) - 0.5), 0.5 + 0.7 * u(rng));
      } else if (kind < 0.8) {  // out of reach (but inside the 2 m the node accepts)
        h.target_B = Eigen::Vector3d(0.8 + 0.6 * u(rng), side * u(rng), 0.3 + 1.4 * u(rng));
      } else {  // ordinary reachable workspace on its own side
        h.target_B = Eigen::Vector3d(0.15 + 0.4 * u(rng), side * (0.05 + 0.45 * u(rng)), 0.5 + 0.8 * u(rng));
      }
    }
    const double p = u(rng);
    in.priority =
        p < 0.5 ? MotionPriority::kEqual : (p < 0.75 ? MotionPriority::kLeftHigher : MotionPriority::kRightHigher);
  };
  return s;
}

EpisodeOutcome runEpisode(const Model& model, const ControllerModel& cm, std::uint64_t seed, double duration) {
  SimOptions options;
  options.record = false;
  const SimResult r = runScenario(model, cm, randomReactiveEpisode(seed, duration), options);
  EpisodeOutcome o;
  o.seed = seed;
  o.cycles = r.cycles;
  o.min_distance = r.min_distance;
  o.min_pair = r.min_pair;
  o.min_time = r.min_time;
  if (!(r.min_distance >= cm.params.d_r)) o.why += "pair below d_r; ";
  if (r.estop_fired) o.why += "e-stop fired; ";
  if (r.non_finite) o.why += "non-finite value; ";
  if (r.max_joint_speed_ratio > 1.0 + 1e-9) o.why += "joint velocity limit exceeded; ";
  o.violation = !o.why.empty();
  return o;
}

}  // namespace reflex::soak
