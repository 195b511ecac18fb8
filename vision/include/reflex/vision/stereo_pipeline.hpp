#pragma once
// Stereo AprilTag pipeline: rectify both images with the calibration's own R/P (as ROS image_proc
// does), detect tags in both, match them by id, triangulate the four corners, and report each
// mapped object's centre in the left optical frame C and, through the camera mount, in the robot
// base frame B, with a confidence.
//
// Triangulation in the rectified left frame (x right, y down, z forward; rectified pixels u, v):
//   d = (u_L - c'_xL) - (u_R - c'_xR)        disparity, pixels (> 0 in front of the rig)
//   Z = f'_x B / d,  X = (u_L - c'_xL) Z / f'_x,  Y = (v - c'_y) Z / f'_y   (v = mean of v_L, v_R)
// then p_C = R_L^T p_rect (R_L = left rectification_matrix) and p_B = R_B_C p_C + p_B_C.
// The tag centre is the mean of its four triangulated corners (exact for a planar square).
// With refine_with_tag_size (default), that stereo-only estimate seeds a stereo pose fit: the tag's
// square is posed (6 DOF) to minimise the reprojection error of its four corners in BOTH rectified
// images (Gauss-Newton, 16 residuals), its size free within its expected error (a 7th parameter with a
// prior, apparentSizeSigma). The tag size is then a second depth cue (apparent size) beside the
// disparity, weighted by what it is worth: strong on large tags, fading out below ~30-40 px, where
// libapriltag's corners bias the apparent size by 1-3 % and stereo alone is the better range.
// size_ratio always reports the stereo-only edge length over the nominal size, so a wrong size in
// the object map shows up (and beyond max_size_deviation the tag is rejected).
//
// To extend: a new cue for the confidence goes into computeConfidence(); a new rejection rule into
// StereoTagPipeline::process(), counted in StereoResult::rejected.
#include "reflex/vision/calibration.hpp"
#include "reflex/vision/object_map.hpp"
#include "reflex/vision/tag_detector.hpp"

#include <opencv2/core.hpp>

#include <array>
#include <memory>
#include <string>
#include <vector>

namespace reflex::vision {

/// Rectification model of a stereo pair: undistort+rectify maps for both cameras, built once.
class StereoRectifier {
 public:
  explicit StereoRectifier(const StereoCalibration& calib);

  const StereoCalibration& calibration() const { return calib_; }
  /// Remaps a raw 8-bit image of camera `right` (false = left) to the rectified image (same size).
  void rectifyImage(const cv::Mat& raw, cv::Mat& rect, bool right) const;
  /// Maps raw pixel coordinates to rectified pixel coordinates (undistort + R + P).
  void rectifyPoints(const std::vector<cv::Point2d>& raw, std::vector<cv::Point2d>& rect, bool right) const;
  /// Triangulates one rectified correspondence into the rectified left frame. Returns false if the
  /// disparity is below min_disparity_px (point at or behind infinity).
  bool triangulate(const cv::Point2d& left_rect, const cv::Point2d& right_rect, cv::Vec3d& p_rect,
                   double min_disparity_px = 0.5) const;
  /// Rectified left frame -> left optical frame: p_C = R_L^T p_rect.
  cv::Vec3d rectToCamera(const cv::Vec3d& p_rect) const { return calib_.left.R.t() * p_rect; }
  /// Projects a rectified-left-frame point into the rectified left/right images with P_L / P_R.
  cv::Point2d projectRect(const cv::Vec3d& p_rect, bool right) const;

 private:
  StereoCalibration calib_;
  cv::Mat map1_[2], map2_[2];
};

enum class RectifyMode {
  kImages,  ///< remap both images, detect on rectified images (default; straight tag edges)
  kPoints,  ///< detect on raw images, rectify only the detected points (faster, small distortion only)
};

struct PipelineOptions {
  DetectorOptions detector;
  RectifyMode rectify = RectifyMode::kImages;
  bool parallel = true;              ///< detect left and right on two threads
  double max_epipolar_px = 2.0;      ///< max mean |v_L - v_R| of the corners, rectified pixels
  double max_size_deviation = 0.3;   ///< reject if |measured edge / tag size - 1| exceeds this
  bool refine_with_tag_size = true;  ///< stereo pose fit of the known square (see header comment)
};

/// One object seen in both images. Invariants: confidence in [0, 1]; p_C(2) > 0; p_B = mount(p_C).
struct ObjectObservation {
  int tag_id = -1;
  std::string name;
  cv::Vec3d p_C;                 ///< tag centre, left optical frame, metres
  cv::Vec3d p_B;                 ///< tag centre, robot base frame, metres
  cv::Vec3d nhat_C;              ///< unit normal of the tag plane, pointing from the tag towards the camera
  double confidence = 0.0;       ///< product of the margin, epipolar and size cues (see computeConfidence)
  double decision_margin = 0.0;  ///< smaller of the two images' AprilTag decision margins
  double epipolar_px = 0.0;      ///< mean |v_L - v_R| over the four corners
  double disparity_px = 0.0;     ///< mean disparity of the four corners
  double size_ratio = 0.0;       ///< triangulated mean edge length / nominal tag size
  double reprojection_px = 0.0;  ///< RMS corner reprojection error of the final estimate, both images
  double edge_px = 0.0;          ///< mean edge length of the tag's square in both rectified images, px
};

/// Weights of the stereo pose fit: its residuals are divided by their expected standard deviation.
struct TagFitWeights {
  double corner_sigma_px = 0.1;  ///< noise of a detected corner, rectified px (each of u, v)
  /// Expected relative error of the tag's apparent size (edge in the images / true edge). The fit's
  /// square may scale by a factor s with the prior (s - 1) / size_sigma; 0 holds s = 1 (the size
  /// exactly known: the apparent size is a depth cue as strong as the corners allow).
  double size_sigma = 0.0;
};

/// Stereo pose fit of a square tag of edge `tag_size` (corners in libapriltag order, i.e. tag-frame
/// (-1,+1), (+1,+1), (+1,-1), (-1,-1) times size/2, x right, y down). Inputs: rectified corners in
/// the left and right images and the stereo-only corner points (rectified left frame) as the seed.
/// Gauss-Newton over the pose (6) and the square's scale (weighted by `weights`, see TagFitWeights).
/// Outputs the tag centre and unit normal (+z of the tag frame, pointing away from the viewer) in the
/// rectified left frame and the RMS reprojection error in pixels. Returns false if it diverges.
bool fitTagPoseStereo(const StereoRectifier& rectifier, const std::array<cv::Point2d, 4>& left_rect,
                      const std::array<cv::Point2d, 4>& right_rect, const std::array<cv::Vec3d, 4>& seed_rect,
                      double tag_size, cv::Vec3d& centre_rect, cv::Vec3d& zhat_rect, double& rms_px,
                      const TagFitWeights& weights = {});

/// The apparent-size cue's error model, measured on generated sessions (docs/vision_accuracy.md):
/// libapriltag's corners make a small tag's square systematically too large or too small (the sign
/// depends on blur, rendering and lens; here +2.5 % at 19 px, +1 % at 23 px, +0.3 % at 33 px, < 0.05 %
/// beyond 40 px; an outside evaluation measured -1.31 % at 16 px, -0.25 % at 35 px).
/// apparentSizeSigma(L) = kApparentSizeBiasPx3 / L^3, L the mean edge in rectified px (2.2 % at 19 px,
/// 0.35 % at 35 px, 0.16 % at 45 px, 0.03 % at 75 px): an upper bound of that bias, so the size cue fades
/// out below ~30-40 px (stereo alone decides the range there) and keeps its weight on large tags.
inline constexpr double kApparentSizeBiasPx3 = 150.0;
double apparentSizeSigma(double edge_px);

/// Expected relative error of the stereo-only size_ratio (edge length triangulated from both images):
/// stereoSizeSigma(L, d) = kStereoSizeNoisePx2 / min(L, d)^2 (L edge, d disparity, rectified px).
/// Measured: the RMS of size_ratio - 1 on generated sessions stays below it at every L (3.4 % at
/// 19 px, 0.9 % at 27 px, 0.3 % at 45 px; the model gives 3.3, 1.6, 0.6 %).
inline constexpr double kStereoSizeNoisePx2 = 12.0;
double stereoSizeSigma(double edge_px, double disparity_px);

/// Confidence factors (see computeConfidence).
inline constexpr double kFullMargin = 50.0;          ///< decision margin that counts as fully decoded
inline constexpr double kMinSizeTolerance = 0.05;    ///< size tolerance of a large, near tag (5 %)
inline constexpr double kSizeToleranceSigmas = 2.5;  ///< tolerance in stereoSizeSigma units

/// Confidence in [0, 1], the product of three factors, each 1 for a perfect measurement:
///   margin   min(1, margin / 50)                 (libapriltag's decision margin; tags below 20 are dropped)
///   epipolar exp(-epi^2 / 2)                     (epi: mean |v_L - v_R| of the corners, px)
///   size     exp(-((ratio - 1) / tol)^2 / 2),  tol = max(0.05, 2.5 * stereoSizeSigma(edge_px, disparity_px))
/// On a well calibrated rig each factor stays above 0.5 unless its cue is ~3 expected standard
/// deviations off: margin below 25 (barely decoded), epipolar error above 1.18 px (calibration), stereo
/// size off by more than 1.18 tol (calibration or a wrong size in the object map).
double computeConfidence(double decision_margin, double epipolar_px, double size_ratio, double edge_px,
                         double disparity_px);

enum class FrameStatus { kOk, kSkipped };

struct StereoResult {
  FrameStatus status = FrameStatus::kOk;
  std::string message;                     ///< why a frame was skipped
  std::vector<ObjectObservation> objects;  ///< sorted by tag id
  std::vector<TagDetection> left, right;   ///< all accepted detections, rectified pixel coordinates
  int unknown_tags = 0;                    ///< matched ids absent from the object map (not reported)
  int rejected = 0;                        ///< mapped tags rejected (epipolar, disparity, size, duplicate)
};

class StereoTagPipeline {
 public:
  /// Throws VisionError if the object map's family differs from the detector's, an id is out of
  /// the family's range, or an option is out of range.
  StereoTagPipeline(const StereoCalibration& calib, const CameraMount& mount, const ObjectMap& objects,
                    const PipelineOptions& options);
  ~StereoTagPipeline();
  StereoTagPipeline(const StereoTagPipeline&) = delete;
  StereoTagPipeline& operator=(const StereoTagPipeline&) = delete;

  /// Processes one raw stereo pair (8-bit gray or BGR). Never throws for bad frames: an empty image,
  /// a size differing from the calibration, or a type that is not 8-bit gives status kSkipped.
  void process(const cv::Mat& left, const cv::Mat& right, StereoResult& out);

  const StereoRectifier& rectifier() const { return rectifier_; }
  const CameraMount& mount() const { return mount_; }
  const ObjectMap& objects() const { return objects_; }
  const PipelineOptions& options() const { return options_; }

 private:
  StereoRectifier rectifier_;
  CameraMount mount_;
  ObjectMap objects_;
  PipelineOptions options_;
  /// process()'s steps: both images checked (size, type) into gray_ (false: out says why, skipped);
  /// one side's tags, in rectified coordinates; one tag seen in both images as an observation (false:
  /// rejected by a plausibility check).
  bool grayImages(const cv::Mat& left, const cv::Mat& right, StereoResult& out);
  void detectSide(int i, std::vector<TagDetection>& dets);
  bool observe(int id, const TagDetection& dl, const TagDetection& dr, const ObjectSpec& spec, ObjectObservation& o);

  std::unique_ptr<TagDetector> detector_[2];
  cv::Mat gray_[2], rect_[2];
  std::vector<cv::Point2d> raw_pts_, rect_pts_;
};

}  // namespace reflex::vision
