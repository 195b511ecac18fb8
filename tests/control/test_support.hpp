// Shared helpers of the control/ tests: where the shipped robots are, loading them, and
// reproducible random configurations within the joint limits.
#pragma once

#include "reflex/control/model.hpp"
#include "reflex/control/urdf_loader.hpp"

#include <Eigen/Core>

#include <cmath>
#include <random>
#include <string>
#include <vector>

namespace reflex::control::test {

inline std::string robotPath(const std::string& file) {
  return std::string(REFLEX_SOURCE_DIR) + "/bringup/robots/" + file;
}

/// The shipped ASIMO-like robot and the second humanoid, with their collision configurations.
inline constexpr const char* kAsimo = "asimo_like";
inline constexpr const char* kSmall = "small_humanoid";

inline Model loadRobot(const std::string& name, std::vector<std::string>* warnings = nullptr) {
  return loadModel(robotPath(name + ".urdf"), loadCollisionConfig(robotPath(name + ".collision.yaml")),
                   warnings);
}

/// Uniform within the position limits; joints without limits (continuous) in [-pi, pi].
inline Eigen::VectorXd randomConfiguration(const Model& model, std::mt19937_64& rng) {
  Eigen::VectorXd q(model.nq);
  for (int i = 0; i < model.nq; ++i) {
    const double lo = std::isfinite(model.q_lower[i]) ? model.q_lower[i] : -M_PI;
    const double hi = std::isfinite(model.q_upper[i]) ? model.q_upper[i] : M_PI;
    q[i] = std::uniform_real_distribution<double>(lo, hi)(rng);
  }
  return q;
}

inline Eigen::Vector3d randomPoint(std::mt19937_64& rng, double half_width) {
  std::uniform_real_distribution<double> u(-half_width, half_width);
  return {u(rng), u(rng), u(rng)};
}

inline Eigen::Vector3d randomUnit(std::mt19937_64& rng) {
  std::normal_distribution<double> n(0.0, 1.0);
  Eigen::Vector3d v(n(rng), n(rng), n(rng));
  while (v.norm() < 1e-6) v = Eigen::Vector3d(n(rng), n(rng), n(rng));
  return v.normalized();
}

}  // namespace reflex::control::test
