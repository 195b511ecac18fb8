// reflex_vision_record: records a session folder (videos, timestamps, calibration, object map,
// mount) from live stereo cameras, or imports recorded video files offline as fast as the machine
// allows. Thin wrapper over reflex::vision::recordSession and reflex::vision::importVideoFiles.
#include "reflex/common/run_main.hpp"
#include "reflex/vision/error.hpp"
#include "reflex/vision/source.hpp"
#include "reflex/vision/video_files.hpp"

#include <CLI/CLI.hpp>

#include <filesystem>

#include <unistd.h>

#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <iostream>

namespace {
std::atomic<bool> g_stop{false};
void onSignal(int) { g_stop.store(true); }

/// Container for a FourCC: the lossless FFV1 and MJPEG go into AVI (exact frame counts), the rest into MP4.
std::string containerFor(const std::string& fourcc) { return fourcc == "MJPG" || fourcc == "FFV1" ? "avi" : "mp4"; }

/// What the videos were written with, in words (the codec chosen and its quality).
std::string describeCodec(const std::string& codec, int crf) {
  if (codec == reflex::vision::kX264Codec) return "x264 (H.264 by ffmpeg/libx264 at CRF " + std::to_string(crf) + ")";
  if (codec == "avc1") return "avc1 (H.264 by OpenCV at x264's default CRF 23)";
  if (codec == "FFV1") return "FFV1 (lossless)";
  return codec;
}

/// Says loudly when the H.264 writer at the chosen quality could not be used (no ffmpeg program).
void warnIfNotX264(const std::string& chosen, const std::string& asked, int crf) {
  if ((asked.empty() || asked == reflex::vision::kX264Codec) && chosen != reflex::vision::kX264Codec)
    std::cerr << "reflex_vision_record: warning: the videos are " << describeCodec(chosen, crf) << ", not x264 at CRF "
              << crf << ": no ffmpeg program on PATH (apt install ffmpeg)\n";
}

/// Offline import of video files (--from-files / --from-side-by-side); returns the exit code.
int importFiles(const reflex::vision::VideoFilesSpec& spec, const reflex::vision::StereoCalibration& calib,
                const reflex::vision::ObjectMap& objects, const std::optional<reflex::vision::CameraMount>& mount,
                reflex::vision::SessionWriterOptions wo, double fps_given, const std::string& out, bool show,
                const std::string& asked_codec) {
  using namespace reflex::vision;
  VideoFilesReader reader(spec, calib.left.image_size);  // every check before decoding: VisionError (exit 2)
  wo.fps = fps_given > 0.0 ? fps_given : reader.nominalFps();
  SessionWriter writer(out, calib, objects, mount, wo);
  std::signal(SIGINT, onSignal);
  std::signal(SIGTERM, onSignal);
  auto last_shown = std::chrono::steady_clock::now();
  const auto t0 = last_shown;
  ImportStats stats;
  try {
    stats = importVideoFiles(reader, writer, g_stop, [&](int done, int total) {
      const auto now = std::chrono::steady_clock::now();
      if (!show || now - last_shown < std::chrono::milliseconds(200)) return;
      last_shown = now;
      const double rate = done / std::max(1e-9, std::chrono::duration<double>(now - t0).count());
      if (total > 0)
        std::fprintf(stderr, "\rimported %d/%d pairs (%.0f pairs/s)   ", done, total, rate);
      else
        std::fprintf(stderr, "\rimported %d pairs (%.0f pairs/s)   ", done, rate);
    });
  } catch (const VisionError& e) {
    writer.abandon();  // no session.yaml: the half-written folder is not taken for a session
    if (show) std::fprintf(stderr, "\n");
    std::cerr << "reflex_vision_record: error: " << e.what() << " (nothing usable written to '" << out << "')\n";
    return 2;
  }
  if (show) std::fprintf(stderr, "\n");
  if (stats.frames == 0) {
    writer.abandon();
    std::cerr << "reflex_vision_record: error: no frame imported: the video" << (spec.side_by_side() ? "" : "s")
              << " hold no frame\n";
    return 3;
  }
  try {
    writer.finish();  // checks every file written and that the videos hold every pair
  } catch (const VisionError& e) {
    std::cerr << "reflex_vision_record: error: " << e.what() << "\n";
    return 4;
  }
  const double span = stats.last_stamp - stats.first_stamp;
  warnIfNotX264(writer.codec(), asked_codec, wo.crf);
  std::printf(
      "imported %d pairs%s into %s with codec %s: stamps %.6f .. %.6f s (span %.3f s, %.2f pairs/s of "
      "session time); %.1f pairs/s achieved (%.2f s)\n",
      stats.frames, stats.stopped ? " (interrupted)" : "", out.c_str(), describeCodec(writer.codec(), wo.crf).c_str(),
      stats.first_stamp, stats.last_stamp, span, stats.frames > 1 && span > 0.0 ? (stats.frames - 1) / span : 0.0,
      stats.frames / std::max(1e-9, stats.wall_seconds), stats.wall_seconds);
  return 0;
}
}  // namespace

/// What the command line asks for.
struct RecordArgs {
  std::string cam_left, cam_right, sbs, calib_left, calib_right, objects_path, mount_path, out, name = "recording";
  std::string codec, from_sbs, timestamps;
  std::vector<std::string> from_files;
  reflex::vision::RecordOptions ro;
  double fps = 0.0;
  int crf = 18;
  bool quiet = false, progress = false;
  CLI::Option* fps_opt = nullptr;
};

void addOptions(CLI::App& app, RecordArgs& a) {
  app.add_option("--camera-left", a.cam_left, "left camera: device index or video file/URL");
  app.add_option("--camera-right", a.cam_right, "right camera: device index or video file/URL");
  app.add_option("--side-by-side", a.sbs, "one side-by-side stereo camera: device index or video file/URL");
  app.add_option("--from-files", a.from_files, "offline: import LEFT RIGHT video files (as fast as possible)")
      ->expected(2);
  app.add_option("--from-side-by-side", a.from_sbs, "offline: import one side-by-side video file (left half = left)");
  app.add_option("--timestamps", a.timestamps,
                 "offline: capture stamps, CSV 'frame,stamp' (seconds), one row per frame");
  app.add_option("--calib-left", a.calib_left, "left camera_info YAML")->required();
  app.add_option("--calib-right", a.calib_right, "right camera_info YAML")->required();
  app.add_option("--objects", a.objects_path, "object map YAML copied into the session")->required();
  app.add_option("--mount", a.mount_path, "camera mount YAML copied into the session (optional)");
  app.add_option("--out", a.out, "session folder to write")->required();
  app.add_option("--name", a.name, "session name")->capture_default_str();
  app.add_option("--frames", a.ro.max_frames, "stop after this many pairs (0 = no limit)");
  app.add_option("--duration", a.ro.duration, "stop after this many seconds (0 = no limit)");
  a.fps_opt = app.add_option("--fps", a.fps,
                             "cameras: nominal frame rate written to the videos (default: the camera's); "
                             "offline: stamp i = i / F (default: the video's rate)");
  app.add_option("--codec", a.codec,
                 "FourCC to use first (default x264/mp4: H.264 by ffmpeg at --crf; then avc1/mp4: H.264 by "
                 "OpenCV at x264's default CRF 23, mp4v/mp4, MJPG/avi; FFV1/avi is lossless, about 90x larger)");
  app.add_option("--crf", a.crf,
                 "x264's quality, the constant rate factor 0..51: lower is better and larger (18: visually "
                 "lossless; each +6 about halves the size)")
      ->capture_default_str();
  app.add_flag("--quiet", a.quiet, "no progress display");
  app.add_flag("--progress", a.progress, "show progress even if stderr is not a terminal");
}

int main(int argc, char** argv) {
  using namespace reflex::vision;
  CLI::App app{
      "reflex_vision_record: record a stereo session folder from live cameras (two devices or one\n"
      "side-by-side device). A camera is a device index or a video file/URL (a file is read at its own\n"
      "frame rate, as a stand-in camera, and its end is a normal end). Stops at --frames/--duration, at the\n"
      "end of the source, or on Ctrl-C. Offline, --from-files LEFT RIGHT or --from-side-by-side FILE imports\n"
      "recorded videos as fast as the machine allows, stamped by --timestamps CSV (frame,stamp), --fps F\n"
      "(stamp i = i/F) or the video's own frame rate. Videos: H.264 at --crf 18 (visually lossless) by the\n"
      "ffmpeg program; --codec FFV1 keeps the images exactly (lossless, about 90x larger). The last line says\n"
      "which codec and quality were used.\n"
      "The --out folder is created; its parent must exist. Exit: 0 recorded, 2 bad option or input (named),\n"
      "3 nothing recorded, 4 the session could not be written (file and cause named)."};
  RecordArgs args;
  addOptions(app, args);
  if (const int code = reflex::parseCommandLine(app, argc, argv); code >= 0) return code;
  CLI::Option* fps_opt = args.fps_opt;
  try {
    if (const std::string why = sessionFolderProblem(args.out); !why.empty()) throw VisionError("--out: " + why);
    const bool offline = !args.from_files.empty() || !args.from_sbs.empty();
    const int sources = (!args.cam_left.empty() || !args.cam_right.empty()) + (!args.sbs.empty()) +
                        (!args.from_files.empty()) + (!args.from_sbs.empty());
    if (sources != 1)
      throw VisionError(
          "give one source: --camera-left N --camera-right M, --side-by-side N, --from-files LEFT RIGHT "
          "or --from-side-by-side FILE");
    if (fps_opt->count() > 0 && !(args.fps > 0.0 && args.fps <= kMaxSessionFps))
      throw VisionError("--fps " + std::to_string(args.fps) + " must be a number in (0, " +
                        std::to_string(kMaxSessionFps) + "]");
    if (!args.timestamps.empty() && !offline)
      throw VisionError("--timestamps applies to --from-files / --from-side-by-side (cameras are stamped live)");
    if (offline && (args.ro.max_frames != 0 || args.ro.duration != 0.0))
      throw VisionError("--frames and --duration apply to cameras; an import takes every frame of the videos");
    if (!args.cam_left.empty() != !args.cam_right.empty())
      throw VisionError("--camera-left and --camera-right must be given together");
    if (args.ro.max_frames < 0) throw VisionError("--frames " + std::to_string(args.ro.max_frames) + " must be >= 0");
    if (args.ro.duration < 0.0) throw VisionError("--duration " + std::to_string(args.ro.duration) + " must be >= 0");
    const StereoCalibration calib = loadStereoCalibration(args.calib_left, args.calib_right);
    const ObjectMap objects = loadObjectMap(args.objects_path);
    std::optional<CameraMount> mount;
    if (!args.mount_path.empty()) mount = loadCameraMount(args.mount_path);
    SessionWriterOptions wo;
    wo.name = args.name;
    if (!(args.crf >= 0 && args.crf <= 51))
      throw VisionError("--crf " + std::to_string(args.crf) + " must be an integer in 0..51");
    wo.crf = args.crf;
    wo.codecs.insert(wo.codecs.begin(), {kX264Codec, "mp4"});
    if (!args.codec.empty()) {
      if (args.codec.size() != 4) throw VisionError("--codec '" + args.codec + "' is not a FourCC");
      wo.codecs.insert(wo.codecs.begin(), {args.codec, containerFor(args.codec)});
    }
    const bool show = !args.quiet && (args.progress || isatty(STDERR_FILENO));
    if (offline) {
      // One video twice (a path typed twice, or a link to the other) gives a "stereo" session with no
      // disparity: every tag at infinity.
      std::error_code same_ec;
      if (!args.from_files.empty() && std::filesystem::equivalent(args.from_files[0], args.from_files[1], same_ec))
        throw VisionError("--from-files: the left and the right video are the same file ('" + args.from_files[0] +
                          "' and '" + args.from_files[1] + "'): a stereo session needs each camera's own video");
      VideoFilesSpec spec;
      spec.left = args.from_sbs.empty() ? args.from_files[0] : args.from_sbs;
      spec.right = args.from_sbs.empty() ? args.from_files[1] : std::string();
      spec.timestamps = args.timestamps;
      spec.fps = args.fps;
      return importFiles(spec, calib, objects, mount, wo, args.fps, args.out, show, args.codec);
    }
    const std::string& first_spec = args.sbs.empty() ? args.cam_left : args.sbs;
    auto left = openCapture(first_spec);
    const double cam_fps = left->get(cv::CAP_PROP_FPS);
    const double pace = isDeviceSpec(first_spec) ? 0.0 : cam_fps;
    std::unique_ptr<StereoSource> source;
    if (!args.sbs.empty())
      source = std::make_unique<CameraSource>(std::move(left), nullptr, calib, pace);
    else
      source = std::make_unique<CameraSource>(std::move(left), openCapture(args.cam_right), calib, pace);
    wo.fps = args.fps > 0.0 ? args.fps : (cam_fps > 0.0 && cam_fps < 500.0 ? cam_fps : 30.0);
    SessionWriter writer(args.out, calib, objects, mount, wo);
    std::signal(SIGINT, onSignal);
    std::signal(SIGTERM, onSignal);
    const RecordStats stats = recordSession(
        *source, writer, args.ro, g_stop,
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
    warnIfNotX264(writer.codec(), args.codec, wo.crf);
    std::cout << "recorded " << stats.recorded << " pairs (" << stats.skipped << " skipped) into " << args.out
              << " with codec " << describeCodec(writer.codec(), wo.crf) << "\n";
    if (stats.recorded > 0 && !stats.end_message.empty())
      std::cerr << "reflex_vision_record: the source stopped: " << stats.end_message << "\n";
    if (stats.recorded == 0) {
      std::cerr << "reflex_vision_record: error: no frame recorded"
                << (stats.end_message.empty() ? "" : ": " + stats.end_message) << "\n";
      return 3;
    }
  } catch (const std::exception& e) {
    return reflex::reportException("reflex_vision_record", e);
  }
  return 0;
}
