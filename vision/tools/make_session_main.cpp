// reflex_make_session: renders a synthetic stereo session (videos, timestamps, calibration, object
// map, ground truth) from a scene script. Thin wrapper over reflex::vision::makeSession.
#include "reflex/common/run_main.hpp"
#include "reflex/vision/error.hpp"
#include "reflex/vision/session.hpp"
#include "reflex/vision/session_maker.hpp"

#include <CLI/CLI.hpp>

#include <cstdio>
#include <iostream>

int main(int argc, char** argv) {
  CLI::App app{
      "Render a synthetic stereo AprilTag session folder from a scene script (YAML).\n"
      "Exit: 0 written, 2 bad script or a file that could not be written (named, with the cause)."};
  std::string script_path, out_dir;
  bool quiet = false;
  app.add_option("--script", script_path, "scene script YAML (e.g. bringup/sessions/flagship/scene.yaml)")->required();
  app.add_option("--out", out_dir,
                 "session folder to write (created, its parent must exist; existing files are overwritten)")
      ->required();
  app.add_flag("--quiet", quiet, "no progress display");
  return reflex::runMain("reflex_make_session", app, argc, argv, [&]() -> int {
    if (const std::string why = reflex::vision::sessionFolderProblem(out_dir); !why.empty())
      throw reflex::vision::VisionError("--out: " + why);
    const reflex::vision::SceneScript script = reflex::vision::loadSceneScript(script_path);
    const auto summary = reflex::vision::makeSession(script, out_dir, [&](int k, int n) {
      if (!quiet && (k % 10 == 0 || k == n)) {
        std::fprintf(stderr, "\rrendering frame %d/%d", k, n);
        if (k == n) std::fprintf(stderr, "\n");
      }
    });
    std::cout << "wrote " << out_dir << ": " << summary.frames << " frames, codec " << summary.codec << ", "
              << summary.dropouts << " drop-out frames";
    for (std::size_t i = 0; i < script.objects.size(); ++i)
      std::cout << ", " << script.objects[i].name << " fully visible in " << summary.visible_frames[i];
    std::cout << "\n";
    return 0;
  });
}
