// Shared helpers of the control/ tests: reproducible random configurations within the joint limits,
// random points and directions, and running a tool of build/bin. The shipped robots (robotPath,
// loadRobot, kAsimo, kSmall) are in tests/support/robot.hpp, included here.
#pragma once

#include "reflex/control/controller.hpp"
#include "reflex/control/kinematics.hpp"
#include "reflex/control/model.hpp"
#include "reflex/control/robot_setup.hpp"
#include "support/child_process.hpp"
#include "support/robot.hpp"

#include <Eigen/Core>
#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <sstream>
#include <random>
#include <string>
#include <vector>

namespace reflex::control::test {

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

/// At the rest posture `config` names (every other joint at neutralConfiguration), how far (m) the
/// right hand link's origin is from the mirror image of the left one's through the base's x-z plane.
inline double restHandsMirrorGap(const Model& model, const ControllerConfig& config) {
  Eigen::VectorXd q = neutralConfiguration(model);
  for (const auto& arm : config.arms)
    for (std::size_t i = 0; i < arm.joints.size(); ++i) q[model.qIndex(arm.joints[i])] = arm.rest[i];
  KinematicsData kin(model);
  computeForwardKinematics(model, kin, q);
  const Eigen::Vector3d l =
      kin.X_B_L[static_cast<std::size_t>(model.linkIndex(config.arms[kLeft].hand_link))].translation();
  const Eigen::Vector3d r =
      kin.X_B_L[static_cast<std::size_t>(model.linkIndex(config.arms[kRight].hand_link))].translation();
  return (r - Eigen::Vector3d(l.x(), -l.y(), l.z())).norm();
}

/// A whole file as text ("" if it cannot be read).
inline std::string slurp(const std::string& path) {
  std::ifstream in(path);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

using ProcessResult = reflex::testing::ProcessResult;

/// Runs build/bin/`tool` with `args` (already shell-quoted where needed) through the shell; its
/// stderr goes through <TempDir>/<tool>_stderr.txt.
inline ProcessResult runTool(const std::string& tool, const std::string& args) {
  return reflex::testing::runShell(reflex::testing::binPath(tool) + " " + args,
                                   ::testing::TempDir() + tool + "_stderr.txt");
}

inline Eigen::Vector3d randomUnit(std::mt19937_64& rng) {
  std::normal_distribution<double> n(0.0, 1.0);
  Eigen::Vector3d v(n(rng), n(rng), n(rng));
  while (v.norm() < 1e-6) v = Eigen::Vector3d(n(rng), n(rng), n(rng));
  return v.normalized();
}

}  // namespace reflex::control::test
