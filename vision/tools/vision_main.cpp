// reflex_vision: the stereo AprilTag vision process. Thin main: parse options, build the source and
// pipeline, run reflex::vision::runVision, hand publications to the DDS writer (if built with the
// bus) and/or every detection to a CSV (--dump, offline, no DDS).
#include "reflex/vision/error.hpp"
#include "reflex/vision/output_file.hpp"
#include "reflex/vision/runner.hpp"
#include "reflex/vision/source.hpp"
#include "reflex/vision/stereo_pipeline.hpp"

#ifdef REFLEX_VISION_WITH_BUS
#include <reflex/bus/log_limit.hpp>

#include "vision_publisher.hpp"
#endif

#include <CLI/CLI.hpp>

#include <unistd.h>

#include <atomic>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <memory>
#include <sstream>
#include <thread>

namespace {

std::atomic<bool> g_stop{false};
// No silent default mount (issue 15, item 2): what to pass instead.
const char* const kMountHelp =
    " (the left camera in the robot base frame; the shipped robot with its head at zero: "
    "bringup/vision/camera_mount.yaml; your own robot: see \"Measure the mount\" in vision/README.md)";
void onSignal(int) { g_stop.store(true); }

}  // namespace

int main(int argc, char** argv) {
  using namespace reflex::vision;
  CLI::App app{
      "reflex_vision: stereo AprilTag vision. Detects tags in both images, triangulates them and publishes\n"
      "ObjectTargets (robot frame, stamped with the capture time) at --publish-hz on the replay clock.\n"
      "Sources: a recorded session (--session) or live cameras (--camera-left/--camera-right or\n"
      "--side-by-side). --dump writes every detection to CSV and runs offline, without DDS.\n"
      "Exit: 0 done (also after SIGINT/SIGTERM), 2 bad option or input (named), 3 the video ended early,\n"
      "4 the --dump file could not be written (named, with the cause)."};
  std::string session, cam_left, cam_right, sbs, calib_left, calib_right, objects_path, mount_path, dump_path;
  std::string rectify = "images";
  ReplayOptions replay;
  double start = 0.0;
  bool rate_given = false, quiet = false, progress_flag = false, no_refine = false;
  PipelineOptions popt;
  std::string family;
  std::string domain_text, frame_id = "base_link";
  std::string profiles;

  app.add_option("--session", session, "recorded session folder");
  app.add_option("--camera-left", cam_left, "left camera: device index or video file/URL");
  app.add_option("--camera-right", cam_right, "right camera: device index or video file/URL");
  app.add_option("--side-by-side", sbs, "one side-by-side stereo camera: device index or video file/URL");
  app.add_option("--calib-left", calib_left, "left camera_info YAML (cameras; overrides the session's)");
  app.add_option("--calib-right", calib_right, "right camera_info YAML (cameras; overrides the session's)");
  app.add_option("--objects", objects_path, "object map YAML (tag id -> name, size); default: the session's");
  app.add_option("--mount", mount_path,
                 "camera mount YAML (left camera in the robot base frame); default: the session's camera_mount.yaml. "
                 "Required otherwise (the shipped robot, head at zero: bringup/vision/camera_mount.yaml)");
  app.add_option("--dump", dump_path, "write every detection to this CSV and do not publish (offline, no DDS)");
  auto* rate_opt = app.add_option("--rate", replay.rate,
                                  "replay speed: 1 real time, 2 twice as fast, 0 as fast as possible "
                                  "(default 1, or 0 with --dump)");
  app.add_flag("--loop", replay.loop, "restart the session at the start offset when it ends");
  app.add_option("--start", start, "start offset into the session, seconds");
  app.add_option("--duration", replay.duration, "stop after this many seconds of session time (0 = no limit)");
  app.add_option("--publish-hz", replay.publish_hz, "publication rate on the replay clock, Hz")
      ->capture_default_str();
  app.add_option("--family", family, "AprilTag family (default: the object map's)");
  app.add_option("--decimate", popt.detector.decimate, "AprilTag quad decimation (>= 1)")->capture_default_str();
  app.add_option("--threads", popt.detector.threads, "AprilTag threads per image")->capture_default_str();
  app.add_option("--rectify", rectify, "images (remap both images) or points (detect raw, rectify corners)")
      ->capture_default_str();
  app.add_flag("--no-refine", no_refine, "stereo-only triangulation (do not use the tag size)");
  app.add_flag("--progress", progress_flag,
               "show progress even if stderr is not a terminal: pass, frame i/N of the session (with --start too), "
               "session time, objects, lag");
  app.add_flag("--quiet", quiet, "no progress display");
  app.add_option("--domain", domain_text, "DDS domain id (default: $REFLEX_DOMAIN_ID, else 0)");
  app.add_option("--profiles", profiles, "DDS QoS profiles XML (default: bringup/dds/reflex_profiles.xml)");
  app.add_option("--frame-id", frame_id, "name of the robot base frame written into ObjectTargets")
      ->capture_default_str();
  CLI11_PARSE(app, argc, argv);
  rate_given = rate_opt->count() > 0;

  try {
    const int sources = (!session.empty()) + (!cam_left.empty() || !cam_right.empty()) + (!sbs.empty());
    if (sources != 1)
      throw VisionError("give exactly one source: --session DIR, --camera-left N --camera-right M, or --side-by-side N");
    if (!cam_left.empty() != !cam_right.empty())
      throw VisionError("--camera-left and --camera-right must be given together");
    if (rectify != "images" && rectify != "points")
      throw VisionError("--rectify '" + rectify + "' must be 'images' or 'points'");
    popt.rectify = rectify == "images" ? RectifyMode::kImages : RectifyMode::kPoints;
    popt.refine_with_tag_size = !no_refine;
    if (!dump_path.empty() && !rate_given) replay.rate = 0.0;
    validateReplayOptions(replay);

    std::unique_ptr<StereoSource> source;
    std::optional<CameraMount> mount;
    ObjectMap objects;
    if (!session.empty()) {
      auto s = std::make_unique<SessionSource>(session, start);
      objects = s->info().objects;
      mount = s->info().mount;
      source = std::move(s);
      if (!calib_left.empty() || !calib_right.empty())
        throw VisionError("--calib-left/--calib-right apply to cameras; a session carries its own calibration");
    } else {
      if (calib_left.empty() || calib_right.empty())
        throw VisionError("live cameras need --calib-left and --calib-right");
      if (objects_path.empty()) throw VisionError("live cameras need --objects");
      if (mount_path.empty()) throw VisionError(std::string("live cameras need --mount FILE") + kMountHelp);
      if (start != 0.0 || replay.loop) throw VisionError("--start and --loop apply to sessions only");
      const StereoCalibration calib = loadStereoCalibration(calib_left, calib_right);
      // A video file standing in for a camera is paced at its own frame rate.
      const std::string& first_spec = sbs.empty() ? cam_left : sbs;
      auto left = openCapture(first_spec);  // left first, so an error names the first bad device
      const double pace = isDeviceSpec(first_spec) ? 0.0 : left->get(cv::CAP_PROP_FPS);
      if (!sbs.empty())
        source = std::make_unique<CameraSource>(std::move(left), nullptr, calib, pace);
      else
        source = std::make_unique<CameraSource>(std::move(left), openCapture(cam_right), calib, pace);
      if (replay.rate != 1.0 && rate_given) throw VisionError("--rate applies to sessions only");
      replay.rate = 1.0;
    }
    if (!objects_path.empty()) objects = loadObjectMap(objects_path);
    if (!mount_path.empty()) mount = loadCameraMount(mount_path);
    if (!mount) throw VisionError("the session " + session + " has no camera_mount.yaml: pass --mount FILE" + kMountHelp);
    popt.detector.family = family.empty() ? objects.family() : family;
    StereoTagPipeline pipeline(source->calibration(), *mount, objects, popt);

    std::unique_ptr<OutputFile> dump;  // every write and the close checked (a full disk is an error, exit 4)
    if (!dump_path.empty()) {
      dump = std::make_unique<OutputFile>(dump_path, "dump file");
      dump->write("time,frame,object,tag_id,x,y,z,x_cam,y_cam,z_cam,confidence\n");
    }
#ifdef REFLEX_VISION_WITH_BUS
    std::unique_ptr<VisionPublisher> publisher;
    if (dump_path.empty()) {
      reflex::bus::BusConfig config;
      config.module_name = "vision";
      if (!domain_text.empty()) config.domain_id = reflex::bus::parseDomainId(domain_text, "--domain");
      config.profiles_file = profiles;
      publisher = std::make_unique<VisionPublisher>(config, frame_id);
    }
#else
    if (dump_path.empty())
      throw VisionError("this reflex_vision was built without the DDS bus (reflex::bus); use --dump FILE.csv");
    (void)frame_id;
#endif
    const bool show = !quiet && (progress_flag || isatty(STDERR_FILENO));
    auto last_shown = std::chrono::steady_clock::now() - std::chrono::seconds(1);
    RunCallbacks cb;
    std::ostringstream row;
    row << std::fixed;
    cb.on_frame = [&](const StereoFrame& f, double stamp, const StereoResult& r) {
      if (!dump) return;
      for (const ObjectObservation& o : r.objects) {
        row.str("");
        row << std::setprecision(6) << stamp << ',' << f.index << ',' << o.name << ',' << o.tag_id << ','
            << o.p_B[0] << ',' << o.p_B[1] << ',' << o.p_B[2] << ',' << o.p_C[0] << ',' << o.p_C[1] << ','
            << o.p_C[2] << ',' << std::setprecision(4) << o.confidence << '\n';
        dump->write(row.str());
      }
      if (dump->failed()) g_stop.store(true);  // no point in going on: reported after the run (exit 4)
    };
#ifdef REFLEX_VISION_WITH_BUS
    // One line per skipped frame, rate-limited (issue 16 item 8f): a long corrupt stretch of video
    // is counted (stats.skipped, exit line) but cannot flood stderr.
    reflex::bus::LogLimiter skip_log;
#endif
    cb.on_skip = [&](int frame, const std::string& why) {
      const std::string line = "\nreflex_vision: skipped frame " + std::to_string(frame) + ": " + why;
#ifdef REFLEX_VISION_WITH_BUS
      skip_log.print(stderr, line);
#else
      std::cerr << line << "\n";
#endif
    };
#ifdef REFLEX_VISION_WITH_BUS
    cb.on_publish = [&](const Publication& p) {
      if (publisher) publisher->publish(p);
    };
#endif
    cb.on_progress = [&](const RunProgress& p) {
      const auto now = std::chrono::steady_clock::now();
      if (!show || now - last_shown < std::chrono::milliseconds(200)) return;
      last_shown = now;
      if (p.frames > 0)
        std::fprintf(stderr, "\r[pass %d] frame %d/%d  t=%.1f s  objects=%d  lag=%.2f s   ", p.pass + 1, p.frame + 1,
                     p.frames, p.session_time, p.objects, p.lag);
      else
        std::fprintf(stderr, "\rframe %d  t=%.1f s  objects=%d   ", p.frame + 1, p.session_time, p.objects);
    };
    RunStats stats;
#ifdef REFLEX_VISION_WITH_BUS
    if (publisher) {
      // The bus loop (heartbeat timer, signal-driven stop) runs on this thread; vision on another.
      reflex::bus::StopOnSignal stop_on_signal(publisher->bus());
      std::string worker_error;
      std::thread worker([&] {
        try {
          stats = runVision(*source, pipeline, replay, cb, g_stop);
        } catch (const std::exception& e) {
          worker_error = e.what();
        }
        publisher->bus().stop();
      });
      publisher->heartbeat().setState(reflex::msg::STATE_RUNNING);
      publisher->bus().run();
      g_stop.store(true);
      worker.join();
      if (!worker_error.empty() || !stats.end_message.empty())
        publisher->heartbeat().setState(reflex::msg::STATE_ERROR,
                                        worker_error.empty() ? stats.end_message : worker_error);
      else
        publisher->heartbeat().setState(reflex::msg::STATE_STOPPING);
      if (!worker_error.empty()) throw VisionError(worker_error);
    } else
#endif
    {
      std::signal(SIGINT, onSignal);
      std::signal(SIGTERM, onSignal);
      stats = runVision(*source, pipeline, replay, cb, g_stop);
    }
    if (show) std::fprintf(stderr, "\n");
    std::cerr << "reflex_vision: " << stats.frames << " frames processed, " << stats.skipped << " skipped, "
              << stats.dropped << " dropped to keep up, "
              << stats.publications << " publications" << (dump_path.empty() ? "" : " (dump: " + dump_path + ")")
              << "\n";
    if (dump) {
      try {
        dump->close();
      } catch (const VisionError& e) {
        std::cerr << "reflex_vision: error: " << e.what() << "\n";
        return 4;
      }
    }
    if (!stats.end_message.empty()) {
      std::cerr << "reflex_vision: error: " << stats.end_message << "\n";
      return 3;
    }
  } catch (const VisionError& e) {
    std::cerr << "reflex_vision: error: " << e.what() << "\n";
    return 2;
  } catch (const std::exception& e) {
    std::cerr << "reflex_vision: error: " << e.what() << "\n";
    return 2;
  }
  return 0;
}
