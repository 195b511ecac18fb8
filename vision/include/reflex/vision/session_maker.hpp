#pragma once
// Synthetic session maker: renders tagged objects moving along scripted 3-D trajectories into both
// cameras of a calibrated stereo rig and writes a session folder with ground truth.
//
// Rendering (per frame, per camera): a static textured background (wall, floor, a person's torso
// and head) -> every planar quad (tag cards, hands, occluders) drawn far to near, each the card
// bitmap warped by the TRUE pinhole projection of its 3-D corners, anti-aliased by 4x4 supersampling
// -> lens distortion applied by remapping (the calibration's plumb_bob D) -> lighting gain -> Gaussian
// blur -> Gaussian noise -> drop-out (a black frame). Tag cards are the family bitmap (which has a
// one-cell white border) plus one more white cell all round. Every random choice comes from
// cv::RNG seeded by the script's seed, so ground truth regenerates identically; the videos are
// bit-identical as long as the encoder is deterministic (see vision/README.md).
//
// The script is YAML (see bringup/sessions/flagship/scene.yaml for a commented example).
// To extend: a new kind of moving thing is a quad with a texture (see ScriptedOccluder).
#include "reflex/vision/calibration.hpp"

#include <opencv2/core.hpp>

#include <cstdint>
#include <functional>
#include <string>
#include <utility>
#include <vector>

namespace reflex::vision {

/// A keyframe of a trajectory: time (s), position of the quad centre in the robot base frame (m),
/// and roll/pitch/yaw (deg) about the quad's own x, y, z axes relative to facing the robot.
struct Keyframe {
  double t = 0.0;
  cv::Vec3d p_B;
  cv::Vec3d rpy_deg{0, 0, 0};
};

/// A pose along a trajectory: R_B_Q columns are the quad's x (right as seen from the robot),
/// y (down) and z (away from the robot) axes in the base frame.
struct QuadPose {
  cv::Vec3d p_B;
  cv::Matx33d R_B_Q;
};

/// Cubic Hermite (Catmull-Rom tangents) through the keyframe positions, linear in rpy, clamped
/// outside the keyframe times. Precondition: at least one keyframe, strictly increasing times.
QuadPose evaluateTrajectory(const std::vector<Keyframe>& path, double t);

struct ScriptedObject {
  std::string name;
  int tag_id = 0;
  double tag_size = 0.06;  ///< black-square edge, m
  std::vector<Keyframe> path;
  std::vector<std::pair<double, double>> hidden;  ///< [t0, t1) intervals where it is out of sight
  bool hand = true;                               ///< draw a hand holding it (just behind, below)
};

struct ScriptedOccluder {
  std::string name;
  cv::Vec2d size{0.1, 0.1};  ///< width, height, m
  cv::Vec3d colour_bgr{90, 120, 170};
  std::vector<Keyframe> path;
  std::vector<std::pair<double, double>> active;  ///< intervals where it exists (empty = always)
};

struct RigSpec {
  cv::Size image_size{640, 480};
  cv::Matx33d K_left = cv::Matx33d(500, 0, 319.5, 0, 500, 239.5, 0, 0, 1);
  cv::Matx33d K_right = cv::Matx33d(500, 0, 319.5, 0, 500, 239.5, 0, 0, 1);
  std::vector<double> D_left = std::vector<double>(5, 0.0);  ///< plumb_bob
  std::vector<double> D_right = std::vector<double>(5, 0.0);
  double baseline = 0.06;            ///< m, right camera along +x of the left optical frame
  cv::Vec3d right_rpy_deg{0, 0, 0};  ///< right camera rotation relative to the left
  CameraMount mount;                 ///< required in a scene script (rig.mount), no default
};

struct RenderSpec {
  int supersample = 4;
  double noise_sigma = 2.0;            ///< grey levels
  cv::Vec2d blur_sigma{0.3, 0.7};      ///< per-frame Gaussian blur sigma range, px
  cv::Vec3d lighting{0.8, 1.1, 20.0};  ///< gain min, max, period (s)
  double dropout_probability = 0.0;    ///< per frame and camera: a black image
  double timestamp_jitter = 0.0;       ///< s, uniform +- on capture stamps
  bool person = true;                  ///< torso and head behind the objects
};

struct SceneScript {
  std::string name = "session";
  double duration = 10.0;
  double fps = 10.0;
  std::uint64_t seed = 1;
  std::string family = "tag36h11";
  std::vector<std::pair<std::string, std::string>> codecs = {{"avc1", "mp4"}, {"mp4v", "mp4"}, {"MJPG", "avi"}};
  RigSpec rig;
  RenderSpec render;
  std::vector<ScriptedObject> objects;
  std::vector<ScriptedOccluder> occluders;
};

/// Parses a scene script; throws VisionError naming the source and field for bad or missing values.
SceneScript parseSceneScript(const std::string& yaml_text, const std::string& source);
SceneScript loadSceneScript(const std::string& path);

/// The calibration the maker writes for a rig: K, D as given; R, P from cv::stereoRectify of the
/// rig's true extrinsics (zero disparity at infinity, alpha 0), like a ROS stereo calibration.
StereoCalibration rigCalibration(const RigSpec& rig);

struct MakeSummary {
  int frames = 0;
  int dropouts = 0;
  std::string codec;
  std::vector<int> visible_frames;  ///< per object, frames with the tag fully visible
};

/// Renders the scene into `out_dir` (created). progress(frame, frames) is called after each frame.
MakeSummary makeSession(const SceneScript& script, const std::string& out_dir,
                        const std::function<void(int, int)>& progress = {});

}  // namespace reflex::vision
