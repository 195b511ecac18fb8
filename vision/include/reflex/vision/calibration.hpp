#pragma once
// Camera calibration in the ROS camera_info YAML format (one file per camera, as written by
// ROS camera_calibration / camera_calibration_parsers), the stereo pair built from two such files,
// and the camera mount (left optical frame in the robot base frame).
//
// Conventions (those of ROS sensor_msgs/CameraInfo and OpenCV):
//  - K (camera_matrix) and D (distortion_coefficients) describe the raw image;
//  - R (rectification_matrix) rotates raw camera rays into the rectified frame: x_rect = R x_cam;
//  - P (projection_matrix) projects rectified-frame points to rectified pixels. For the right
//    camera of a horizontal pair, P(0,3) = -fx' * B with B > 0 the baseline in metres; the left
//    camera has P(0,3) = 0. Both P share fx', fy', cy' (cx' may differ).
// Frames: optical frames are z forward, x right, y down (metres). The mount gives the LEFT optical
// frame C in the robot base frame B (x forward, y left, z up, origin on the floor between the feet):
// p_B = R_B_C p_C + p_B_C.
#include <opencv2/core.hpp>

#include <string>
#include <vector>

namespace reflex::vision {

/// Physically possible ranges, checked at load (VisionError naming the file, field and value and
/// the range); a calibration outside them cannot produce any detection.
struct CalibrationLimits {
  static constexpr int kMinImageSide = 16;     ///< pixels, width and height
  static constexpr int kMaxImageSide = 16384;  ///< pixels (beyond: the rectification maps alone take GBs)
  /// Focal length per image width, fx / width, for K and P: 0.05 is a ~169 deg horizontal field of
  /// view (beyond a fisheye's), 50 a ~1.1 deg telephoto.
  static constexpr double kMinFocalPerWidth = 0.05;
  static constexpr double kMaxFocalPerWidth = 50.0;
  /// Pixel aspect fy / fx (K and P).
  static constexpr double kMinAspect = 0.25;
  static constexpr double kMaxAspect = 4.0;
  /// Stereo baseline B = -P_R[0][3] / fx', metres.
  static constexpr double kMinBaseline = 0.001;
  static constexpr double kMaxBaseline = 10.0;
  /// Least fraction of the rectified image that must see the raw image (rectified pixels taken back
  /// through P, R, K and D); below it the distortion or rectification is no lens's.
  static constexpr double kMinRectifiedCoverage = 0.25;
};

/// One camera's calibration (a ROS camera_info YAML file).
/// Invariants after load: image sides in [kMinImageSide, kMaxImageSide]; fx in [kMinFocalPerWidth,
/// kMaxFocalPerWidth] * width and fy / fx in [kMinAspect, kMaxAspect], for K and for P; principal
/// points (K and P) inside the image, [0, width] x [0, height]; K's last row [0 0 1] and P's
/// [0 0 1 0]; D.size() matches distortion_model (plumb_bob 5, rational_polynomial 8, equidistant 4);
/// R a rotation.
struct CameraInfo {
  std::string camera_name;
  cv::Size image_size;
  cv::Matx33d K = cv::Matx33d::eye();
  std::string distortion_model = "plumb_bob";
  std::vector<double> D = std::vector<double>(5, 0.0);
  cv::Matx33d R = cv::Matx33d::eye();
  cv::Matx34d P = cv::Matx34d::zeros();
};

/// Parses camera_info YAML text. `source` names the file in error messages.
/// Throws VisionError naming the file and field for a missing/mistyped/inconsistent field
/// (rows*cols != data length, non-positive focal length, unknown distortion model, ...).
CameraInfo parseCameraInfo(const std::string& yaml_text, const std::string& source);
/// Loads a camera_info YAML file; throws VisionError if it cannot be read or is invalid.
CameraInfo loadCameraInfo(const std::string& path);
/// Writes `info` as camera_info YAML (the layout ROS tools write). Throws on I/O failure.
void saveCameraInfo(const std::string& path, const CameraInfo& info);

/// A calibrated horizontal stereo pair.
struct StereoCalibration {
  CameraInfo left;
  CameraInfo right;
  /// Baseline B in metres, from the right projection matrix: B = -P_R(0,3) / P_R(0,0).
  double baseline() const { return -right.P(0, 3) / right.P(0, 0); }
};

/// Checks the pair is consistent: equal image sizes, left P(0,3) = 0, right P(0,3) < 0 (the right
/// camera lies to the right of the left one; else "left/right swapped?"), the baseline in
/// [kMinBaseline, kMaxBaseline], P(1,3) = 0 (horizontal pair), the rectified intrinsics fx',
/// fy', cy' equal in both P, and at least kMinRectifiedCoverage of each rectified image seeing its
/// raw image. Throws VisionError naming the file and field.
void validateStereoCalibration(const StereoCalibration& calib, const std::string& left_source,
                               const std::string& right_source);
/// Loads and validates a stereo pair from two camera_info files.
StereoCalibration loadStereoCalibration(const std::string& left_path, const std::string& right_path);

/// Largest |coordinate| of the camera in the robot base frame, metres (a head is not 10 m away).
inline constexpr double kMaxMountOffset = 10.0;

/// Left optical frame C in robot base frame B. Invariants: R_B_C is a rotation (orthonormal, det +1);
/// each coordinate of p_B_C within kMaxMountOffset of the base frame origin.
struct CameraMount {
  cv::Matx33d R_B_C;
  cv::Vec3d p_B_C;
  cv::Vec3d toBase(const cv::Vec3d& p_C) const { return R_B_C * p_C + p_B_C; }
};

// There is deliberately no built-in mount: a mount is always a file the user
// names (the shipped robot's, head joints at zero: bringup/vision/camera_mount.yaml), so a missing
// one is an error, never the shipped robot's head taken silently for another rig.
/// Parses a mount YAML node text:  translation: [x, y, z]  (metres) and
/// rotation_matrix: [9 numbers, row-major R_B_C]. Throws VisionError naming source and field.
CameraMount parseCameraMount(const std::string& yaml_text, const std::string& source);
CameraMount loadCameraMount(const std::string& path);
void saveCameraMount(const std::string& path, const CameraMount& mount, const std::string& comment);

}  // namespace reflex::vision
