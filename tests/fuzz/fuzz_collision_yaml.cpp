// libFuzzer target: collision configuration YAML (a file) -> loadCollisionConfig, then resolved
// against the shipped robot (unknown link names in exclude pairs). Documented error: ModelError.
#include "fuzz_util.hpp"

#include "reflex/control/urdf_loader.hpp"

#include <fstream>
#include <iterator>

namespace {
const std::string& shippedUrdf() {
  static const std::string text = [] {
    std::ifstream in(REFLEX_SOURCE_DIR "/bringup/robots/asimo_like.urdf");
    return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  }();
  return text;
}
}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace reflex::control;
  const std::string& path = reflex::fuzz::writeTemp(data, size, ".collision.yaml");
  reflex::fuzz::expectOnly<ModelError>("loadCollisionConfig", [&] {
    const CollisionConfig config = loadCollisionConfig(path);
    const Model model = loadModelFromString(shippedUrdf(), config, "asimo_like.urdf");
    (void)model;
  });
  return 0;
}
