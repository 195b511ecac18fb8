// Shared helpers of the control/ tests: where the shipped robots are, loading them, and
// reproducible random configurations within the joint limits.
#pragma once

#include "reflex/control/model.hpp"
#include "reflex/control/urdf_loader.hpp"

#include <Eigen/Core>
#include <gtest/gtest.h>

#include <sys/wait.h>

#include <cmath>
#include <cstdio>
#include <fstream>
#include <sstream>
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

/// A whole file as text ("" if it cannot be read).
inline std::string slurp(const std::string& path) {
  std::ifstream in(path);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

/// What a tool of build/bin printed and returned.
struct ProcessResult {
  int exit_code = -1;  ///< -1 if it could not be started or did not exit normally
  std::string out, err;
};

/// Runs build/bin/`tool` with `args` (already shell-quoted where needed) through the shell.
inline ProcessResult runTool(const std::string& tool, const std::string& args) {
  const std::string err_path = ::testing::TempDir() + tool + "_stderr.txt";
  const std::string cmd = std::string(REFLEX_BIN_DIR) + "/" + tool + " " + args + " 2>" + err_path;
  ProcessResult r;
  FILE* pipe = popen(cmd.c_str(), "r");
  if (!pipe) return r;
  char buf[4096];
  std::size_t n;
  while ((n = fread(buf, 1, sizeof buf, pipe)) > 0) r.out.append(buf, n);
  const int status = pclose(pipe);
  r.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  r.err = slurp(err_path);
  return r;
}

inline Eigen::Vector3d randomUnit(std::mt19937_64& rng) {
  std::normal_distribution<double> n(0.0, 1.0);
  Eigen::Vector3d v(n(rng), n(rng), n(rng));
  while (v.norm() < 1e-6) v = Eigen::Vector3d(n(rng), n(rng), n(rng));
  return v.normalized();
}

}  // namespace reflex::control::test
