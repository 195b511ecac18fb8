#include "reflex/vision_node/vision_node.hpp"

#include "reflex/vision/error.hpp"
#include "reflex/vision/output_file.hpp"
#include "reflex/vision/source.hpp"

#ifdef REFLEX_VISION_WITH_BUS
#include <reflex/bus/log_limit.hpp>

#include "vision_publisher.hpp"

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#endif

#include <chrono>
#include <cmath>
#include <cstdio>
#include <iomanip>
#include <iostream>
#include <mutex>
#include <sstream>
#include <thread>

namespace reflex::vision_node {

using namespace reflex::vision;

namespace {

// No silent default mount: what to pass instead.
const char* const kMountHelp =
    " (the left camera in the robot base frame; the shipped robot with its head at zero: "
    "bringup/vision/camera_mount.yaml; your own robot: see \"Measure the mount\" in vision/README.md)";

#ifdef REFLEX_VISION_WITH_BUS
/// The left image as JPEG (quality 85), scaled down to at most max_width pixels wide. False for an
/// empty image or one the encoder refuses.
bool encodeLeftImage(const cv::Mat& left, int max_width, std::vector<std::uint8_t>& jpeg, int& width, int& height) {
  if (left.empty()) return false;
  cv::Mat scaled;
  if (left.cols > max_width) {
    const double s = static_cast<double>(max_width) / left.cols;
    cv::resize(left, scaled, cv::Size(max_width, std::max(1, static_cast<int>(std::lround(left.rows * s)))), 0, 0,
               cv::INTER_AREA);
  } else {
    scaled = left;
  }
  try {
    if (!cv::imencode(".jpg", scaled, jpeg, {cv::IMWRITE_JPEG_QUALITY, 85})) return false;
  } catch (const cv::Exception&) {
    return false;
  }
  width = scaled.cols;
  height = scaled.rows;
  return true;
}
#endif

}  // namespace

struct VisionNode::Impl {
  ReplayOptions replay;
  std::unique_ptr<StereoSource> source;
  std::unique_ptr<StereoTagPipeline> pipeline;
  std::unique_ptr<OutputFile> dump;  // every write and the close checked (a full disk is an error)
#ifdef REFLEX_VISION_WITH_BUS
  std::unique_ptr<VisionPublisher> publisher;
  // One line per skipped frame, rate-limited: a long corrupt stretch of video
  // is counted (stats.skipped, exit line) but cannot flood stderr.
  reflex::bus::LogLimiter skip_log;
  // The left image for reflex/camera_left: encoded on the replay thread (on_frame) at most image_hz per
  // second of session time, published on the publication thread with the publication of its frame
  // (the same capture stamp and index as its ObjectTargets).
  double image_period = 0.0;  // s of session time; 0: no images
  int image_width = 640;
  double next_image_stamp = -1e300;
  std::mutex image_mutex;
  int image_frame = -1;  // the frame `image` holds (-1: none waiting); guarded by image_mutex
  std::vector<std::uint8_t> image;
  int image_w = 0, image_h = 0;
#endif
  int wait_readers = 0;
  double wait_timeout = 0.0;
  bool show = false;
  std::chrono::steady_clock::time_point last_shown;
  std::ostringstream row;
  RunCallbacks callbacks;
};

namespace {

std::string seconds(double s) {
  char text[32];
  std::snprintf(text, sizeof text, "%g", s);
  return text;
}

#ifdef REFLEX_VISION_WITH_BUS
/// Holds until `readers` readers of reflex/object_targets matched: true. false when the node was
/// stopped (why stays empty) or `timeout` seconds passed (why says how many matched), then
/// bus::kReaderSideMatchGrace more. One line on stderr when holding starts and when it ends.
bool waitForReaders(const VisionPublisher& publisher, int readers, double timeout, const std::atomic<bool>& stop,
                    std::string& why) {
  const auto t0 = std::chrono::steady_clock::now();
  const auto deadline = t0 + std::chrono::duration<double>(timeout);
  std::fprintf(stderr,
               "reflex_vision: holding the start until %d reader(s) of reflex/object_targets matched "
               "(at most %.0f s)\n",
               readers, timeout);
  // In slices, so that a stop() (SIGTERM) while holding ends the wait at once.
  while (!publisher.waitForReaders(readers, std::chrono::milliseconds(100))) {
    if (stop.load()) return false;
    if (std::chrono::steady_clock::now() >= deadline) {
      why = "--wait-readers " + std::to_string(readers) + ": " + std::to_string(publisher.matchedReaders()) +
            " reader(s) of reflex/object_targets matched in " + seconds(timeout) +
            " s (--wait-timeout); is every consumer running on this domain (and, under DDS-Security, "
            "authenticated and allowed to read the topic)?";
      return false;
    }
  }
  const double matched_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  // Our writer has matched the readers; now their side of the match.
  const auto grace_end = std::chrono::steady_clock::now() + reflex::bus::kReaderSideMatchGrace;
  while (!stop.load() && std::chrono::steady_clock::now() < grace_end)
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  if (stop.load()) return false;
  std::fprintf(stderr, "reflex_vision: %d reader(s) matched after %.2f s, starting\n", publisher.matchedReaders(),
               matched_s);
  return true;
}
#endif

}  // namespace

VisionNode::VisionNode(const NodeOptions& o) : impl_(std::make_unique<Impl>()) {
  Impl& m = *impl_;
  m.replay = o.replay;
  PipelineOptions popt = o.pipeline;
  if (o.wait_readers < 0) throw VisionError("--wait-readers " + std::to_string(o.wait_readers) + " must be >= 0");
  if (!(o.wait_timeout > 0.0) || !std::isfinite(o.wait_timeout))
    throw VisionError("--wait-timeout " + seconds(o.wait_timeout) + " must be a positive, finite number of seconds");
  if (o.wait_readers > 0 && !o.dump.empty())
    throw VisionError("--wait-readers applies to publishing on the bus, not to --dump");
  if (!(o.image_hz >= 0.0 && o.image_hz <= 30.0))
    throw VisionError("--image-rate " + seconds(o.image_hz) + " must be in [0, 30] Hz (0: no camera image)");
  if (!(o.image_width >= 64 && o.image_width <= 4096))
    throw VisionError("--image-width " + std::to_string(o.image_width) + " must be in [64, 4096] pixels");
  m.wait_readers = o.wait_readers;
  m.wait_timeout = o.wait_timeout;
  const int sources =
      (!o.session.empty()) + (!o.camera_left.empty() || !o.camera_right.empty()) + (!o.side_by_side.empty());
  if (sources != 1)
    throw VisionError("give exactly one source: --session DIR, --camera-left N --camera-right M, or --side-by-side N");
  if (!o.camera_left.empty() != !o.camera_right.empty())
    throw VisionError("--camera-left and --camera-right must be given together");
  if (o.rectify != "images" && o.rectify != "points")
    throw VisionError("--rectify '" + o.rectify + "' must be 'images' or 'points'");
  popt.rectify = o.rectify == "images" ? RectifyMode::kImages : RectifyMode::kPoints;
  if (!o.dump.empty() && !o.rate_given) m.replay.rate = 0.0;
  validateReplayOptions(m.replay);

  std::optional<CameraMount> mount;
  ObjectMap objects;
  if (!o.session.empty()) {
    auto s = std::make_unique<SessionSource>(o.session, o.start);
    objects = s->info().objects;
    mount = s->info().mount;
    m.source = std::move(s);
    if (!o.calib_left.empty() || !o.calib_right.empty())
      throw VisionError("--calib-left/--calib-right apply to cameras; a session carries its own calibration");
  } else {
    if (o.calib_left.empty() || o.calib_right.empty())
      throw VisionError("live cameras need --calib-left and --calib-right");
    if (o.objects.empty()) throw VisionError("live cameras need --objects");
    if (o.mount.empty()) throw VisionError(std::string("live cameras need --mount FILE") + kMountHelp);
    if (o.start != 0.0 || m.replay.loop) throw VisionError("--start and --loop apply to sessions only");
    const StereoCalibration calib = loadStereoCalibration(o.calib_left, o.calib_right);
    // A video file standing in for a camera is paced at its own frame rate.
    const std::string& first_spec = o.side_by_side.empty() ? o.camera_left : o.side_by_side;
    auto left = openCapture(first_spec);  // left first, so an error names the first bad device
    const double pace = isDeviceSpec(first_spec) ? 0.0 : left->get(cv::CAP_PROP_FPS);
    if (!o.side_by_side.empty())
      m.source = std::make_unique<CameraSource>(std::move(left), nullptr, calib, pace);
    else
      m.source = std::make_unique<CameraSource>(std::move(left), openCapture(o.camera_right), calib, pace);
    if (m.replay.rate != 1.0 && o.rate_given) throw VisionError("--rate applies to sessions only");
    m.replay.rate = 1.0;
  }
  if (!o.objects.empty()) objects = loadObjectMap(o.objects);
  if (!o.mount.empty()) mount = loadCameraMount(o.mount);
  if (!mount)
    throw VisionError("the session " + o.session + " has no camera_mount.yaml: pass --mount FILE" + kMountHelp);
  popt.detector.family = o.family.empty() ? objects.family() : o.family;
  m.pipeline = std::make_unique<StereoTagPipeline>(m.source->calibration(), *mount, objects, popt);

  if (!o.dump.empty()) {
    m.dump = std::make_unique<OutputFile>(o.dump, "dump file");
    m.dump->write("time,frame,object,tag_id,x,y,z,x_cam,y_cam,z_cam,confidence\n");
  }
#ifdef REFLEX_VISION_WITH_BUS
  if (o.dump.empty()) {
    reflex::bus::BusConfig config;
    config.module_name = o.module_name;
    config.domain_id = o.domain_id;
    config.profiles_file = o.profiles_file;
    m.publisher = std::make_unique<VisionPublisher>(config, o.frame_id);
    m.image_period = o.image_hz > 0.0 ? 1.0 / o.image_hz : 0.0;
    m.image_width = o.image_width;
  }
#else
  if (o.dump.empty())
    throw VisionError("this reflex_vision was built without the DDS bus (reflex::bus); use --dump FILE.csv");
#endif

  m.show = o.show_progress;
  m.last_shown = std::chrono::steady_clock::now() - std::chrono::seconds(1);
  m.row << std::fixed;
  setUpCallbacks();
}

void VisionNode::setUpCallbacks() {
  RunCallbacks& cb = impl_->callbacks;
  cb.on_frame = [this](const StereoFrame& f, double stamp, const StereoResult& r) {
    Impl& n = *impl_;
#ifdef REFLEX_VISION_WITH_BUS
    if (n.publisher && n.image_period > 0.0 && (stamp >= n.next_image_stamp || stamp < n.next_image_stamp - 1.0)) {
      n.next_image_stamp = stamp + n.image_period;  // (a loop's restart, stamp going back: at once)
      std::vector<std::uint8_t> jpeg;
      int w = 0, h = 0;
      if (encodeLeftImage(f.left, n.image_width, jpeg, w, h)) {
        std::lock_guard<std::mutex> lock(n.image_mutex);
        n.image.swap(jpeg);
        n.image_w = w;
        n.image_h = h;
        n.image_frame = f.index;
      }
    }
#endif
    if (!n.dump) return;
    for (const ObjectObservation& ob : r.objects) {
      n.row.str("");
      n.row << std::setprecision(6) << stamp << ',' << f.index << ',' << ob.name << ',' << ob.tag_id << ',' << ob.p_B[0]
            << ',' << ob.p_B[1] << ',' << ob.p_B[2] << ',' << ob.p_C[0] << ',' << ob.p_C[1] << ',' << ob.p_C[2] << ','
            << std::setprecision(4) << ob.confidence << '\n';
      n.dump->write(n.row.str());
    }
    if (n.dump->failed()) stop_.store(true);  // no point in going on: closeOutput() reports it
  };
  cb.on_skip = [this](int frame, const std::string& why) {
    const std::string line = "\nreflex_vision: skipped frame " + std::to_string(frame) + ": " + why;
#ifdef REFLEX_VISION_WITH_BUS
    impl_->skip_log.print(stderr, line);
#else
    std::cerr << line << "\n";
#endif
  };
#ifdef REFLEX_VISION_WITH_BUS
  cb.on_publish = [this](const Publication& p) {
    Impl& n = *impl_;
    if (!n.publisher) return;
    n.publisher->publish(p);
    std::lock_guard<std::mutex> lock(n.image_mutex);
    if (n.image_frame >= 0 && n.image_frame == p.frame) {
      n.publisher->publishImage(p, n.image, n.image_w, n.image_h);
      n.image_frame = -1;
    }
  };
#endif
  cb.on_progress = [this](const RunProgress& p) {
    Impl& n = *impl_;
    const auto now = std::chrono::steady_clock::now();
    if (!n.show || now - n.last_shown < std::chrono::milliseconds(200)) return;
    n.last_shown = now;
    if (p.frames > 0)
      std::fprintf(stderr, "\r[pass %d] frame %d/%d  t=%.1f s  objects=%d  lag=%.2f s   ", p.pass + 1, p.frame + 1,
                   p.frames, p.session_time, p.objects, p.lag);
    else
      std::fprintf(stderr, "\rframe %d  t=%.1f s  objects=%d   ", p.frame + 1, p.session_time, p.objects);
  };
}

VisionNode::~VisionNode() = default;

const RunStats& VisionNode::run() {
  Impl& m = *impl_;
#ifdef REFLEX_VISION_WITH_BUS
  if (m.publisher) {
    // The bus loop (heartbeat timer, stop) runs on this thread; vision on a worker.
    std::string worker_error, readers_missing;
    std::thread worker([&] {
      try {
        if (m.wait_readers > 0 &&
            !waitForReaders(*m.publisher, m.wait_readers, m.wait_timeout, stop_, readers_missing)) {
          m.publisher->bus().stop();
          return;
        }
        stats_ = runVision(*m.source, *m.pipeline, m.replay, m.callbacks, stop_);
      } catch (const std::exception& e) {
        worker_error = e.what();
      }
      m.publisher->bus().stop();
    });
    m.publisher->heartbeat().setState(reflex::msg::STATE_RUNNING);
    try {
      m.publisher->bus().run();
    } catch (...) {  // the security material expired: end the worker before the error leaves
      stop_.store(true);
      worker.join();
      throw;
    }
    stop_.store(true);
    worker.join();
    const std::string& error = !worker_error.empty()      ? worker_error
                               : !readers_missing.empty() ? readers_missing
                                                          : stats_.end_message;
    if (!error.empty())
      m.publisher->heartbeat().setState(reflex::msg::STATE_ERROR, error);
    else
      m.publisher->heartbeat().setState(reflex::msg::STATE_STOPPING);
    if (!worker_error.empty()) throw VisionError(worker_error);
    if (!readers_missing.empty()) throw ReadersMissing(readers_missing);
  } else
#endif
  {
    stats_ = runVision(*m.source, *m.pipeline, m.replay, m.callbacks, stop_);
  }
  if (m.show) std::fprintf(stderr, "\n");
  return stats_;
}

void VisionNode::stop() noexcept {
  stop_.store(true);
#ifdef REFLEX_VISION_WITH_BUS
  if (impl_->publisher) impl_->publisher->bus().stop();
#endif
}

reflex::bus::Participant* VisionNode::bus() noexcept {
#ifdef REFLEX_VISION_WITH_BUS
  if (impl_->publisher) return &impl_->publisher->bus();
#endif
  return nullptr;
}

void VisionNode::closeOutput() {
  if (impl_->dump) impl_->dump->close();
}

}  // namespace reflex::vision_node
