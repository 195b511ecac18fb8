// Robot fixtures of the tests: the shipped robots of bringup/robots/ by name, loaded with their
// collision configurations, and the shipped ASIMO-like robot with the default controller model,
// built once per test program. Header-only: a test that includes it links reflex::control.
#pragma once

#include "reflex/control/controller.hpp"
#include "reflex/control/model.hpp"
#include "reflex/control/scenarios.hpp"
#include "reflex/control/urdf_loader.hpp"

#include <string>
#include <vector>

namespace reflex::testing {

/// bringup/robots/`file` in the source tree.
inline std::string robotPath(const std::string& file) {
  return std::string(REFLEX_SOURCE_DIR) + "/bringup/robots/" + file;
}

/// The shipped ASIMO-like robot and the second humanoid (names of bringup/robots/<name>.urdf).
inline constexpr const char* kAsimo = "asimo_like";
inline constexpr const char* kSmall = "small_humanoid";

/// The shipped ASIMO-like robot's URDF.
inline const std::string kAsimoUrdf = robotPath("asimo_like.urdf");

/// bringup/robots/<name>.urdf with <name>.collision.yaml (a fresh model per call; setup errors
/// throw as loadModel's do). Loader warnings go to `warnings` if given.
inline control::Model loadRobot(const std::string& name, std::vector<std::string>* warnings = nullptr) {
  return control::loadModel(robotPath(name + ".urdf"),
                            control::loadCollisionConfig(robotPath(name + ".collision.yaml")), warnings);
}

/// The shipped ASIMO-like robot with its default collision configuration, loaded once.
inline const control::Model& shippedModel() {
  static const control::Model model =
      control::loadModel(kAsimoUrdf, control::loadCollisionConfig(control::defaultCollisionConfigPath(kAsimoUrdf)));
  return model;
}

/// shippedModel() under the default controller configuration, built once.
inline const control::ControllerModel& defaultControllerModel() {
  static const control::ControllerModel cm =
      control::makeControllerModel(shippedModel(), control::defaultControllerConfig());
  return cm;
}

}  // namespace reflex::testing
