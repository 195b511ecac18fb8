// reflex_vision_record: records a session folder (videos, timestamps, calibration, object map,
// mount) from live stereo cameras. Thin wrapper over reflex::vision::recordSession.
#include "reflex/vision/error.hpp"
#include "reflex/vision/source.hpp"

#include <CLI/CLI.hpp>

#include <unistd.h>

#include <csignal>
#include <cstdio>
#include <iostream>

namespace {
std::atomic<bool> g_stop{false};
void onSignal(int) { g_stop.store(true); }
}  // namespace

int main(int argc, char** argv) {
  using namespace reflex::vision;
  CLI::App app{
      "reflex_vision_record: record a stereo session folder from live cameras (two devices or one\n"
      "side-by-side device). A camera is a device index or a video file/URL (a file is read at its own\n"
      "frame rate, as a stand-in camera). Stops at --frames/--duration, at the end of the source, or on Ctrl-C.\n"
      "The --out folder is created; its parent must exist. Exit: 0 recorded, 2 bad option or input (named),\n"
      "3 nothing recorded, 4 the session could not be written (file and cause named)."};
  std::string cam_left, cam_right, sbs, calib_left, calib_right, objects_path, mount_path, out, name = "recording";
  std::string codec;
  RecordOptions ro;
  double fps = 0.0;
  bool quiet = false;
  app.add_option("--camera-left", cam_left, "left camera: device index or video file/URL");
  app.add_option("--camera-right", cam_right, "right camera: device index or video file/URL");
  app.add_option("--side-by-side", sbs, "one side-by-side stereo camera: device index or video file/URL");
  app.add_option("--calib-left", calib_left, "left camera_info YAML")->required();
  app.add_option("--calib-right", calib_right, "right camera_info YAML")->required();
  app.add_option("--objects", objects_path, "object map YAML copied into the session")->required();
  app.add_option("--mount", mount_path, "camera mount YAML copied into the session (optional)");
  app.add_option("--out", out, "session folder to write")->required();
  app.add_option("--name", name, "session name")->capture_default_str();
  app.add_option("--frames", ro.max_frames, "stop after this many pairs (0 = no limit)");
  app.add_option("--duration", ro.duration, "stop after this many seconds (0 = no limit)");
  app.add_option("--fps", fps, "nominal frame rate written to the videos (default: the camera's)");
  app.add_option("--codec", codec, "FourCC to use first (default avc1/mp4, then mp4v/mp4, MJPG/avi)");
  app.add_flag("--quiet", quiet, "no progress display");
  CLI11_PARSE(app, argc, argv);
  try {
    const int sources = (!cam_left.empty() || !cam_right.empty()) + (!sbs.empty());
    if (sources != 1) throw VisionError("give --camera-left N --camera-right M, or --side-by-side N");
    if (!cam_left.empty() != !cam_right.empty())
      throw VisionError("--camera-left and --camera-right must be given together");
    if (ro.max_frames < 0) throw VisionError("--frames " + std::to_string(ro.max_frames) + " must be >= 0");
    if (ro.duration < 0.0) throw VisionError("--duration " + std::to_string(ro.duration) + " must be >= 0");
    if (fps < 0.0) throw VisionError("--fps " + std::to_string(fps) + " must be > 0");
    const StereoCalibration calib = loadStereoCalibration(calib_left, calib_right);
    const ObjectMap objects = loadObjectMap(objects_path);
    std::optional<CameraMount> mount;
    if (!mount_path.empty()) mount = loadCameraMount(mount_path);
    const std::string& first_spec = sbs.empty() ? cam_left : sbs;
    auto left = openCapture(first_spec);
    const double cam_fps = left->get(cv::CAP_PROP_FPS);
    const double pace = isDeviceSpec(first_spec) ? 0.0 : cam_fps;
    std::unique_ptr<StereoSource> source;
    if (!sbs.empty())
      source = std::make_unique<CameraSource>(std::move(left), nullptr, calib, pace);
    else
      source = std::make_unique<CameraSource>(std::move(left), openCapture(cam_right), calib, pace);
    SessionWriterOptions wo;
    wo.name = name;
    wo.fps = fps > 0.0 ? fps : (cam_fps > 0.0 && cam_fps < 500.0 ? cam_fps : 30.0);
    if (!codec.empty()) {
      if (codec.size() != 4) throw VisionError("--codec '" + codec + "' is not a FourCC");
      wo.codecs.insert(wo.codecs.begin(), {codec, codec == "MJPG" ? "avi" : "mp4"});
    }
    SessionWriter writer(out, calib, objects, mount, wo);
    std::signal(SIGINT, onSignal);
    std::signal(SIGTERM, onSignal);
    const bool show = !quiet && isatty(STDERR_FILENO);
    const RecordStats stats = recordSession(
        *source, writer, ro, g_stop,
        [](int frame, const std::string& why) {
          std::cerr << "\nreflex_vision_record: skipped frame " << frame << ": " << why << "\n";
        },
        [&](int n, double s) {
          if (show && n % 10 == 0) std::fprintf(stderr, "\rrecorded %d pairs, %.1f s", n, s);
        });
    if (show) std::fprintf(stderr, "\n");
    try {
      writer.finish();  // checks every file written and that the videos hold every pair
    } catch (const VisionError& e) {
      std::cerr << "reflex_vision_record: error: " << e.what() << "\n";
      return 4;
    }
    std::cout << "recorded " << stats.recorded << " pairs (" << stats.skipped << " skipped) into " << out
              << " with codec " << writer.codec() << "\n";
    if (stats.recorded > 0 && !stats.end_message.empty())
      std::cerr << "reflex_vision_record: the source stopped: " << stats.end_message << "\n";
    if (stats.recorded == 0) {
      std::cerr << "reflex_vision_record: error: no frame recorded"
                << (stats.end_message.empty() ? "" : ": " + stats.end_message) << "\n";
      return 3;
    }
  } catch (const VisionError& e) {
    std::cerr << "reflex_vision_record: error: " << e.what() << "\n";
    return 2;
  }
  return 0;
}
