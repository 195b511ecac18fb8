// libFuzzer target: controller configuration YAML (a file) -> loadControllerConfig, then resolved
// against the shipped robot with makeControllerModel. Documented error: ConfigError.
#include "fuzz_util.hpp"

#include "reflex/control/controller.hpp"
#include "reflex/control/urdf_loader.hpp"

namespace {
const reflex::control::Model& shippedModel() {
  using namespace reflex::control;
  static const Model model =
      loadModel(REFLEX_SOURCE_DIR "/bringup/robots/asimo_like.urdf",
                loadCollisionConfig(REFLEX_SOURCE_DIR "/bringup/robots/asimo_like.collision.yaml"));
  return model;
}
}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace reflex::control;
  const Model& model = shippedModel();
  const std::string& path = reflex::fuzz::writeTemp(data, size, ".controller.yaml");
  reflex::fuzz::expectOnly<ConfigError>("loadControllerConfig", [&] {
    const ControllerConfig config = loadControllerConfig(path);
    const ControllerModel cm = makeControllerModel(model, config);
    (void)cm;
  });
  return 0;
}
