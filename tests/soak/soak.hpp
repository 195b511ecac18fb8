// Soak of the reactive controller: many random reactive episodes run back to back
// in simulation (reflex::control::runScenario), each one a fresh robot at rest whose hand targets
// jump every 50 ms .. 1 s to random places — reachable, inside the torso, across the body, behind,
// out of reach, or none — with random motion priority, some of them while walking. Every episode
// must keep every physical pair above d_r, never fire the e-stop, never produce a non-finite value,
// and never exceed a joint velocity limit.
#pragma once

#include "reflex/control/controller.hpp"
#include "reflex/control/scenarios.hpp"

#include <cstdint>
#include <string>

namespace reflex::soak {

/// The random episode of `seed` (deterministic): `duration` simulated seconds.
reflex::control::Scenario randomReactiveEpisode(std::uint64_t seed, double duration);

struct EpisodeOutcome {
  std::uint64_t seed = 0;
  std::uint64_t cycles = 0;
  double min_distance = 0.0;  ///< closest physical pair (m)
  int min_pair = -1;
  double min_time = 0.0;
  bool violation = false;  ///< below d_r, e-stop, non-finite or over a velocity limit
  std::string why;         ///< what was violated ("" if none)
};

/// Runs episode `seed` and checks it.
EpisodeOutcome runEpisode(const reflex::control::Model& model, const reflex::control::ControllerModel& cm,
                          std::uint64_t seed, double duration);

}  // namespace reflex::soak
