#pragma once
// Shared helpers of the vision tests: temporary folders, the scene scripts of the sessions that the
// tests generate at run time, and the evaluation of detections against a session's ground truth.
#include "reflex/vision/error.hpp"
#include "reflex/vision/runner.hpp"
#include "reflex/vision/session.hpp"
#include "reflex/vision/session_maker.hpp"
#include "../support/errors.hpp"

#include <atomic>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <random>
#include <sstream>
#include <string>
#include <vector>

namespace reflex::vision::test {

/// The message of the VisionError `f` throws, or "no error".
template <typename F>
std::string errorOf(F f) {
  return reflex::testing::messageOf<VisionError>(f);
}

/// A fresh folder under the system temp dir, removed when the object dies.
class TempDir {
 public:
  explicit TempDir(const std::string& tag) {
    std::random_device rd;
    path_ = (std::filesystem::temp_directory_path() / ("reflex_vision_" + tag + "_" + std::to_string(rd()))).string();
    std::filesystem::create_directories(path_);
  }
  ~TempDir() {
    std::error_code ec;
    std::filesystem::remove_all(path_, ec);
  }
  const std::string& path() const { return path_; }
  std::string operator/(const std::string& name) const { return path_ + "/" + name; }

 private:
  std::string path_;
};

#ifdef REFLEX_SOURCE_DIR
/// The shipped robot's camera mount (head joints at zero), from its configuration file: there is no
/// built-in default mount.
inline CameraMount shippedMount() {
  return loadCameraMount(std::string(REFLEX_SOURCE_DIR) + "/bringup/vision/camera_mount.yaml");
}
#endif

/// The rig shared by the generated sessions: 640x480, f ~ 500 px, plumb_bob distortion, 6 cm
/// baseline, right camera slightly rotated (so rectification matters).
inline std::string rigYaml() {
  return R"(rig:
  left: {fx: 500, fy: 500, cx: 319.5, cy: 239.5, distortion: [-0.04, 0.012, 0.0005, -0.0003, 0]}
  right: {fx: 503, fy: 502, cx: 322.0, cy: 241.0, distortion: [-0.038, 0.010, -0.0004, 0.0002, 0]}
  baseline: 0.06
  right_rpy_deg: [0.3, -0.5, 0.2]
  mount:   # the shipped robot, head joints at zero (bringup/vision/camera_mount.yaml)
    translation: [0.08, 0.03, 1.15]
    rotation_matrix: [0, 0, 1,  -1, 0, 0,  0, -1, 0]
)";
}

/// Near session: two held objects 0.5-0.9 m away, a passing occluder, one object hidden for a
/// while, drop-out frames, timestamp jitter, lighting changes, person in the background.
inline std::string nearScript(double duration = 6.0) {
  std::ostringstream os;
  os << "name: near_test\nduration: " << duration << "\nfps: 10\nseed: 7\n"
     << rigYaml() << R"(render:
  noise_sigma: 2.0
  dropout_probability: 0.03
  timestamp_jitter: 0.002
objects:
  - name: cup
    id: 0
    size: 0.06
    path:
      - {t: 0, p: [0.62, 0.10, 1.10]}
      - {t: 2, p: [0.80, 0.02, 1.04], rpy_deg: [10, 20, 5]}
      - {t: 4, p: [0.95, -0.10, 1.12], rpy_deg: [-10, -15, 0]}
      - {t: 6, p: [0.70, 0.08, 1.08]}
  - name: can
    id: 1
    size: 0.06
    hidden: [[2.5, 3.5]]
    path:
      - {t: 0, p: [0.75, -0.15, 1.02]}
      - {t: 3, p: [0.85, 0.12, 1.15], rpy_deg: [-15, -25, 0]}
      - {t: 6, p: [0.60, -0.08, 1.05]}
occluders:
  - name: sheet
    size: [0.07, 0.20]
    colour: [60, 160, 90]
    active: [[4.0, 5.5]]
    path:
      - {t: 4.0, p: [0.45, 0.20, 1.08]}
      - {t: 5.5, p: [0.45, -0.20, 1.08]}
)";
  return os.str();
}

/// Range session: a 10 cm and a 6 cm tag sweeping 0.5 m <-> 1.5 m from the camera, tilted.
inline std::string rangeScript(double duration = 6.0) {
  std::ostringstream os;
  os << "name: range_test\nduration: " << duration << "\nfps: 10\nseed: 11\n"
     << rigYaml() << R"(render:
  noise_sigma: 2.0
  dropout_probability: 0.02
  timestamp_jitter: 0.002
  person: false
objects:
  - name: box
    id: 5
    size: 0.10
    path:
      - {t: 0, p: [0.58, 0.12, 1.12]}
      - {t: 3, p: [1.05, 0.05, 1.05], rpy_deg: [15, -20, 0]}
      - {t: 6, p: [1.58, -0.15, 1.18], rpy_deg: [0, 10, 0]}
  - name: ball
    id: 7
    size: 0.06
    path:
      - {t: 0, p: [1.55, -0.2, 1.0]}
      - {t: 3, p: [1.0, -0.05, 1.1], rpy_deg: [-20, 15, 10]}
      - {t: 6, p: [0.6, 0.0, 1.05]}
)";
  return os.str();
}

/// One detection as written by --dump / seen in on_frame.
struct Detection {
  int frame = 0;
  std::string object;
  cv::Vec3d p_B;
};

struct Evaluation {
  int visible = 0;           ///< (frame, object) pairs with the tag fully visible
  int detected_visible = 0;  ///< of those, detected
  int rms_samples = 0;
  double rms_mm = 0.0;  ///< over detected visible pairs with camera distance in [lo, hi]
  double max_visible_error_mm = 0.0;
  int invented = 0;  ///< detections of absent objects, or farther than 30 mm from the truth
  double detection_rate() const { return visible ? double(detected_visible) / visible : 0.0; }
};

inline Evaluation evaluate(const std::vector<GroundTruthRow>& truth, const std::vector<Detection>& dets,
                           double lo = 0.5, double hi = 1.5) {
  std::map<std::pair<int, std::string>, const GroundTruthRow*> gt;
  for (const GroundTruthRow& r : truth) gt[{r.frame, r.object}] = &r;
  std::map<std::pair<int, std::string>, const Detection*> seen;
  Evaluation e;
  double ss = 0.0;
  for (const Detection& d : dets) {
    seen[{d.frame, d.object}] = &d;
    const auto it = gt.find({d.frame, d.object});
    if (it == gt.end() || !it->second->present) {
      ++e.invented;
      continue;
    }
    const double err = cv::norm(d.p_B - it->second->p_B);
    if (err > 0.030) ++e.invented;
    if (!it->second->visible) continue;
    e.max_visible_error_mm = std::max(e.max_visible_error_mm, 1000.0 * err);
    const double dist = cv::norm(it->second->p_C);
    if (dist >= lo && dist <= hi) {
      ss += err * err;
      ++e.rms_samples;
    }
  }
  for (const GroundTruthRow& r : truth) {
    if (!r.visible) continue;
    ++e.visible;
    if (seen.count({r.frame, r.object})) ++e.detected_visible;
  }
  e.rms_mm = e.rms_samples ? 1000.0 * std::sqrt(ss / e.rms_samples) : 0.0;
  return e;
}

/// Runs the same path as `reflex_vision --dump` (as fast as possible) and collects detections.
inline std::vector<Detection> detectSession(const std::string& dir, PipelineOptions options = {}) {
  SessionSource source(dir, 0.0);
  options.detector.family = source.info().objects.family();
  StereoTagPipeline pipeline(source.calibration(), source.info().mount.value(), source.info().objects, options);
  std::vector<Detection> out;
  RunCallbacks cb;
  cb.on_frame = [&](const StereoFrame& f, double, const StereoResult& r) {
    for (const ObjectObservation& o : r.objects) out.push_back({f.index, o.name, o.p_B});
  };
  ReplayOptions ro;
  ro.rate = 0.0;
  std::atomic<bool> stop{false};
  runVision(source, pipeline, ro, cb, stop);
  return out;
}

inline void writeText(const std::string& path, const std::string& text) {
  std::ofstream os(path);
  os << text;
}

inline std::string readText(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream os;
  os << in.rdbuf();
  return os.str();
}

}  // namespace reflex::vision::test
