// control_only URDF: the installed reflex::control alone (no DDS, no OpenCV): loads the robot with its
// collision configuration and prints "robot NAME: S segments, P checked pairs", as reflex_inspect does.
#include <reflex/control/urdf_loader.hpp>

#include <cstdio>
#include <exception>

int main(int argc, char** argv) {
  if (argc != 2) {
    std::fprintf(stderr, "usage: control_only URDF\n");
    return 2;
  }
  try {
    const reflex::control::Model model =
        reflex::control::loadModel(argv[1], reflex::control::loadCollisionConfigFor(argv[1], ""));
    int robot_pairs = 0;
    for (const auto& p : model.pairs)
      if (p.a < model.num_robot_segments && p.b < model.num_robot_segments) ++robot_pairs;
    std::printf("robot %s: %d segments, %d checked pairs\n", model.name.c_str(), model.num_robot_segments, robot_pairs);
    return 0;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "control_only: error: %s\n", e.what());
    return 1;
  }
}
