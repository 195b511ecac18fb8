// libFuzzer target: URDF text -> reflex::control::loadModelFromString (urdfdom + primitive checks).
// Documented reaction to bad input: reflex::control::ModelError.
#include "fuzz_util.hpp"

#include "reflex/control/urdf_loader.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace reflex::control;
  reflex::fuzz::expectOnly<ModelError>("loadModelFromString", [&] {
    std::vector<std::string> warnings;
    const Model model = loadModelFromString(reflex::fuzz::asText(data, size), CollisionConfig{}, "fuzz", &warnings);
    (void)model;
  });
  return 0;
}
