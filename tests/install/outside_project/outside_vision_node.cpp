// outside_vision_node SESSION OUT.csv: builds the installed reflex::vision_node (the vision process as a
// library) offline on a recorded session, 2 s of session time, every detection into OUT.csv; prints the
// node's frame count. install_test.sh compares OUT.csv byte for byte with the in-tree reflex_vision --dump.
#include <reflex/vision_node/vision_node.hpp>

#include <cstdio>
#include <exception>

int main(int argc, char** argv) {
  if (argc != 3) {
    std::fprintf(stderr, "usage: outside_vision_node SESSION OUT.csv\n");
    return 2;
  }
  try {
    reflex::vision_node::NodeOptions options;
    options.session = argv[1];
    options.dump = argv[2];
    options.replay.duration = 2.0;
    reflex::vision_node::VisionNode node(options);
    const reflex::vision::RunStats& stats = node.run();
    node.closeOutput();
    std::printf("vision node: %d frames\n", stats.frames);
    return stats.end_message.empty() ? 0 : 1;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "outside_vision_node: error: %s\n", e.what());
    return 1;
  }
}
