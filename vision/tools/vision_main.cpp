// reflex_vision: the stereo AprilTag vision process. Thin main: parse options, build the node
// (reflex::vision_node::VisionNode: source, pipeline, replay loop, DDS publisher or --dump CSV), install
// the process's signal handler, run, print the exit line.
#include "reflex/common/run_main.hpp"
#include "reflex/common/shipped.hpp"
#include "reflex/vision/error.hpp"
#include "reflex/vision_node/vision_node.hpp"

#ifdef REFLEX_VISION_WITH_BUS
#include <reflex/bus/bus.hpp>
#endif

#include <CLI/CLI.hpp>

#include <unistd.h>

#include <atomic>
#include <csignal>
#include <iostream>
#include <optional>
#include <string>

namespace {

// Offline (--dump, or a build without the bus) SIGINT / SIGTERM stop the node through this handler;
// on the bus, reflex::bus::StopOnSignal does (it also ignores SIGPIPE and SIGXFSZ).
std::atomic<reflex::vision_node::VisionNode*> g_node{nullptr};
void onSignal(int) {
  if (auto* node = g_node.load()) node->stop();  // offline, stop() only stores an atomic flag
}
class OfflineStopOnSignal {
 public:
  /// Installs the handler for `node` (nullptr: does nothing); the destructor detaches it from the node.
  explicit OfflineStopOnSignal(reflex::vision_node::VisionNode* node) {
    if (!node) return;
    g_node.store(node);
    std::signal(SIGINT, onSignal);
    std::signal(SIGTERM, onSignal);
  }
  ~OfflineStopOnSignal() { g_node.store(nullptr); }
  OfflineStopOnSignal(const OfflineStopOnSignal&) = delete;
  OfflineStopOnSignal& operator=(const OfflineStopOnSignal&) = delete;
};

}  // namespace

int main(int argc, char** argv) {
  using reflex::vision::VisionError;
  namespace vn = reflex::vision_node;
  CLI::App app{
      "reflex_vision: stereo AprilTag vision. Detects tags in both images, triangulates them and publishes\n"
      "ObjectTargets (robot frame, stamped with the capture time) at --publish-hz on the replay clock.\n"
      "Sources: a recorded session (--session) or live cameras (--camera-left/--camera-right or\n"
      "--side-by-side). --dump writes every detection to CSV and runs offline, without DDS.\n"
      "Exit: 0 done (also after SIGINT/SIGTERM), 2 bad option or input (named), 3 the video ended early,\n"
      "4 the --dump file could not be written (named, with the cause), 5 --wait-readers: the readers did\n"
      "not match within --wait-timeout (how many did is named)."};
  vn::NodeOptions o;
  bool quiet = false, progress_flag = false, no_refine = false;
  std::string domain_text;

  app.add_option("--session", o.session, "recorded session folder");
  app.add_option("--camera-left", o.camera_left, "left camera: device index or video file/URL");
  app.add_option("--camera-right", o.camera_right, "right camera: device index or video file/URL");
  app.add_option("--side-by-side", o.side_by_side, "one side-by-side stereo camera: device index or video file/URL");
  app.add_option("--calib-left", o.calib_left, "left camera_info YAML (cameras; overrides the session's)");
  app.add_option("--calib-right", o.calib_right, "right camera_info YAML (cameras; overrides the session's)");
  app.add_option("--objects", o.objects, "object map YAML (tag id -> name, size); default: the session's");
  app.add_option("--mount", o.mount,
                 "camera mount YAML (left camera in the robot base frame); default: the session's camera_mount.yaml. "
                 "Required otherwise (the shipped robot, head at zero: bringup/vision/camera_mount.yaml)");
  app.add_option("--dump", o.dump, "write every detection to this CSV and do not publish (offline, no DDS)");
  auto* rate_opt = app.add_option("--rate", o.replay.rate,
                                  "replay speed: 1 real time, 2 twice as fast, 0 as fast as possible "
                                  "(default 1, or 0 with --dump)");
  app.add_flag("--loop", o.replay.loop, "restart the session at the start offset when it ends");
  app.add_option("--max-lag", o.replay.max_lag,
                 "paced replay: a frame more than this many seconds behind the replay clock is dropped (counted in "
                 "the exit line); one less late is processed late, with its own capture stamp. (0, 10]")
      ->capture_default_str();
  app.add_option("--start", o.start, "start offset into the session, seconds");
  app.add_option("--duration", o.replay.duration, "stop after this many seconds of session time (0 = no limit)");
  app.add_option("--publish-hz", o.replay.publish_hz, "publication rate on the replay clock, Hz")
      ->capture_default_str();
  app.add_option("--family", o.family, "AprilTag family (default: the object map's)");
  app.add_option("--decimate", o.pipeline.detector.decimate, "AprilTag quad decimation (>= 1)")->capture_default_str();
  app.add_option("--threads", o.pipeline.detector.threads, "AprilTag threads per image")->capture_default_str();
  app.add_option("--rectify", o.rectify, "images (remap both images) or points (detect raw, rectify corners)")
      ->capture_default_str();
  app.add_flag("--no-refine", no_refine, "stereo-only triangulation (do not use the tag size)");
  app.add_flag("--progress", progress_flag,
               "show progress even if stderr is not a terminal: pass, frame i/N of the session (with --start too), "
               "session time, objects, lag");
  app.add_flag("--quiet", quiet, "no progress display");
  app.add_option("--domain", domain_text, "DDS domain id (default: $REFLEX_DOMAIN_ID, else 0)");
  app.add_option("--profiles", o.profiles_file,
                 "DDS QoS profiles XML (default: " + reflex::common::defaultProfilesFile() + ")");
  app.add_option("--frame-id", o.frame_id, "name of the robot base frame written into ObjectTargets")
      ->capture_default_str();
  app.add_option("--image-rate", o.image_hz,
                 "publish the left camera's image (JPEG) on reflex/camera_left this often per second of session "
                 "time, for viewers and recordings (0: never; at most 30)")
      ->capture_default_str();
  app.add_option("--image-width", o.image_width, "scale the published image down to at most this many pixels wide")
      ->capture_default_str();
  app.add_option(
      "--wait-readers", o.wait_readers,
      "hold the start until this many readers of reflex/object_targets have matched (e.g. 2: "
      "reflex_behavior and reflex_record), then 0.3 s for their side of the match, so the first frames reach "
      "them; under DDS-Security "
      "matching waits for authentication, seconds on a loaded machine (default 0: start at once)");
  app.add_option("--wait-timeout", o.wait_timeout, "seconds --wait-readers holds at most before exit 5")
      ->capture_default_str();
  if (const int code = reflex::parseCommandLine(app, argc, argv); code >= 0) return code;
  o.rate_given = rate_opt->count() > 0;
  o.pipeline.refine_with_tag_size = !no_refine;
  o.show_progress = !quiet && (progress_flag || isatty(STDERR_FILENO));

  try {
#ifdef REFLEX_VISION_WITH_BUS
    if (o.dump.empty() && !domain_text.empty()) o.domain_id = reflex::bus::parseDomainId(domain_text, "--domain");
#endif
    vn::VisionNode node(o);
    {
      // The process's signal handler (SIGINT / SIGTERM -> a clean stop, exit 0), installed here and not
      // in the node, so that nodes compose in one process.
#ifdef REFLEX_VISION_WITH_BUS
      std::optional<reflex::bus::StopOnSignal> stop_on_signal;
      if (node.bus()) stop_on_signal.emplace(*node.bus());
#endif
      OfflineStopOnSignal offline_stop(node.bus() ? nullptr : &node);
      node.run();
    }
    const reflex::vision::RunStats& stats = node.stats();
    std::cerr << "reflex_vision: " << stats.frames << " frames processed, " << stats.skipped << " skipped, "
              << stats.dropped << " dropped to keep up, " << stats.publications << " publications"
              << (o.dump.empty() ? "" : " (dump: " + o.dump + ")") << "\n";
    try {
      node.closeOutput();
    } catch (const VisionError& e) {
      std::cerr << "reflex_vision: error: " << e.what() << "\n";
      return 4;
    }
    if (!stats.end_message.empty()) {
      std::cerr << "reflex_vision: error: " << stats.end_message << "\n";
      return 3;
    }
  } catch (const vn::ReadersMissing& e) {
    std::cerr << "reflex_vision: error: " << e.what() << "\n";
    return 5;
  } catch (const std::exception& e) {
    std::cerr << "reflex_vision: error: " << e.what() << "\n";
    return 2;
  }
  return 0;
}
