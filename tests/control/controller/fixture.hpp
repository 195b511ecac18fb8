// Shared set-up of the controller tests: the shipped robot and the default controller.
#pragma once

#include "reflex/control/controller.hpp"
#include "reflex/control/scenarios.hpp"
#include "reflex/control/urdf_loader.hpp"

#include <string>

namespace reflex::control::testing {

inline const std::string kUrdf = std::string(REFLEX_SOURCE_DIR) + "/bringup/robots/asimo_like.urdf";

inline const Model& shippedModel() {
  static const Model model = loadModel(kUrdf, loadCollisionConfig(defaultCollisionConfigPath(kUrdf)));
  return model;
}

inline const ControllerModel& defaultControllerModel() {
  static const ControllerModel cm = makeControllerModel(shippedModel(), defaultControllerConfig());
  return cm;
}

}  // namespace reflex::control::testing
