// reflex_scene: the live view's scenes from a recorded controller time series, for drawing the robot
// afterwards with the SAME renderer as the live view.
//
//   reflex_scene --log controller.csv --at 5.4,17.3 --out render.js [--tile 360x420]
//                [--camera AZ,EL,RADIUS,TX,TY,TZ] [--urdf F] [--collision F] [--controller F]
//
// Writes one ES module (`export default {...};`) that the page of reflex_view draws without a server or
// a WebSocket: modules/view/web/index.html?render=render.js (view.js, static mode; README.md of
// modules/view). It holds the tile size [CSS px], the camera of every tile (orbit around the target:
// azimuth and elevation [rad], radius [m], target [m] in the robot's base frame B) and, per requested
// time, the foxglove.SceneUpdate that reflex::scene builds for the nearest row (as reflex_view does from
// the bus). modules/view/tools/render_scenes.py runs this, then Chromium headless, and keeps the PNG.
//
// Bad input: exit 2 with one line naming the value (no --log / --at / --out, a bad --tile or --camera,
// the robot files' and the time series' errors as reflex::view::readLogScenes names them).
#include "reflex/common/run_main.hpp"
#include "reflex/common/shipped.hpp"
#include <reflex/common/files.hpp>
#include <reflex/view/log_scene.hpp>
#include <reflex/view/scene.hpp>

#include <CLI/CLI.hpp>

#include <cerrno>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

namespace {

/// "WxH" with 16 <= W, H <= 4096 [CSS px]; throws naming the text.
void parseTile(const std::string& text, int& width, int& height) {
  const std::size_t x = text.find('x');
  double w = 0, h = 0;
  if (x == std::string::npos || !reflex::common::parseFiniteNumber(text.substr(0, x), w) ||
      !reflex::common::parseFiniteNumber(text.substr(x + 1), h) || w != std::floor(w) || h != std::floor(h) || w < 16 ||
      h < 16 || w > 4096 || h > 4096)
    throw reflex::Error("--tile '" + text + "' is not WIDTHxHEIGHT with whole numbers in 16..4096");
  width = static_cast<int>(w);
  height = static_cast<int>(h);
}

/// "AZ,EL,RADIUS,TX,TY,TZ": six finite numbers, |EL| < pi/2, RADIUS > 0; throws naming the text.
std::vector<double> parseCamera(const std::string& text) {
  std::vector<double> v;
  std::stringstream ss(text);
  std::string field;
  while (std::getline(ss, field, ',')) {
    double value = 0;
    if (!reflex::common::parseFiniteNumber(field, value))
      throw reflex::Error("--camera '" + text + "': '" + field + "' is not a finite number");
    v.push_back(value);
  }
  if (v.size() != 6) throw reflex::Error("--camera '" + text + "' needs six numbers AZ,EL,RADIUS,TX,TY,TZ");
  if (!(std::abs(v[1]) < 1.5) || !(v[2] > 0.05))
    throw reflex::Error("--camera '" + text + "': elevation must be in (-1.5, 1.5) rad and radius > 0.05 m");
  return v;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{
      "reflex_scene: the live view's foxglove.SceneUpdate at chosen rows of a controller time series "
      "(reflex_controller --log), as a module the view's page draws headless (static mode)"};
  std::string log, out, tile = "360x420", camera_text = "0.5,0.45,1.7,0.1,0,0.9";
  std::string urdf = reflex::common::defaultUrdf(), collision, controller;
  std::vector<double> at;
  app.add_option("--log", log, "time series CSV (reflex_controller --log, or reflex_sim's timeseries.csv)")->required();
  app.add_option("--at", at, "times [s] of the rows to draw (the nearest row each), comma-separated")
      ->delimiter(',')
      ->required();
  app.add_option("--out", out, "output module (.js), read by index.html?render=FILE")->required();
  app.add_option("--tile", tile, "size of each scene's picture, WIDTHxHEIGHT [CSS px]")->capture_default_str();
  app.add_option("--camera", camera_text,
                 "the camera of every tile: AZ,EL,RADIUS,TX,TY,TZ (orbit azimuth and elevation [rad] about the "
                 "target TX,TY,TZ [m] in the root frame, at RADIUS [m]; azimuth 0 looks from +x)")
      ->capture_default_str();
  app.add_option("--urdf", urdf, "robot URDF")->capture_default_str();
  app.add_option("--collision", collision, "collision YAML (default: next to the URDF)");
  app.add_option("--controller", controller,
                 "controller YAML (zone thresholds; default: <URDF stem>.controller.yaml beside the URDF if it exists, "
                 "else built-in)");
  return reflex::runMain("reflex_scene", app, argc, argv, [&]() -> int {
    int width = 0, height = 0;
    parseTile(tile, width, height);
    const std::vector<double> cam = parseCamera(camera_text);
    if (const std::string why = reflex::common::regularOutputProblem(out); !why.empty()) throw reflex::Error(why);
    const reflex::view::SceneModel scene = reflex::view::loadSceneModel(urdf, collision, controller);
    const std::vector<reflex::view::LogScene> rows = reflex::view::readLogScenes(scene, log, at);

    nlohmann::json doc;
    doc["tile"] = {{"width", width}, {"height", height}};
    doc["camera"] = {
        {"azimuth", cam[0]}, {"elevation", cam[1]}, {"radius", cam[2]}, {"target", {cam[3], cam[4], cam[5]}}};
    doc["robot"] = scene.model.name;
    doc["scenes"] = nlohmann::json::array();
    reflex::view::SceneData data(scene);
    for (const reflex::view::LogScene& row : rows) {
      if (!reflex::view::updateScene(scene, data, row.input))
        throw reflex::Error(log + " row " + std::to_string(row.row) + ": the joint positions cannot be drawn");
      doc["scenes"].push_back(
          {{"time", row.t}, {"row", row.row}, {"update", reflex::view::buildSceneUpdate(scene, data, row.input)}});
    }
    errno = 0;
    std::ofstream file(out);
    file << "// Made by reflex_scene from " << log << " (" << rows.size()
         << " scenes); drawn by view.js (static mode).\n"
         << "export default " << doc.dump() << ";\n";
    file.close();
    if (!file) throw reflex::Error(reflex::common::writeError(out, errno ? errno : EIO));
    std::printf("reflex_scene: wrote %zu scenes to %s (%s)\n", rows.size(), out.c_str(), scene.controller_note.c_str());
    if (const std::string why = reflex::common::flushStandardOutput(); !why.empty()) {
      std::fprintf(stderr, "reflex_scene: error: %s\n", why.c_str());
      return 1;
    }
    return 0;
  });
}
