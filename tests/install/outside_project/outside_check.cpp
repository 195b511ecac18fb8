// outside_check URDF LEFT_YAML RIGHT_YAML: uses the installed reflex::control (robot model and its
// checked pairs) and reflex::vision (a stereo calibration), and prints what the in-tree tools print, for
// install_test.sh to compare: "robot NAME: S segments, P checked pairs" and "baseline B".
#include <reflex/control/urdf_loader.hpp>
#include <reflex/vision/calibration.hpp>

#include <cstdio>
#include <exception>

int main(int argc, char** argv) {
  if (argc != 4) {
    std::fprintf(stderr, "usage: outside_check URDF LEFT_YAML RIGHT_YAML\n");
    return 2;
  }
  try {
    const reflex::control::Model model =
        reflex::control::loadModel(argv[1], reflex::control::loadCollisionConfigFor(argv[1], ""));
    int robot_pairs = 0;
    for (const auto& p : model.pairs)
      if (p.a < model.num_robot_segments && p.b < model.num_robot_segments) ++robot_pairs;
    std::printf("robot %s: %d segments, %d checked pairs\n", model.name.c_str(), model.num_robot_segments, robot_pairs);
    const reflex::vision::StereoCalibration calib = reflex::vision::loadStereoCalibration(argv[2], argv[3]);
    std::printf("baseline %.6f\n", calib.baseline());
    return 0;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "outside_check: error: %s\n", e.what());
    return 1;
  }
}
