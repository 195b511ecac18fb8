#pragma once
// One calibrated camera, one image (reflex_detect): the pose of a square tag of known size from its
// four detected corners, and an annotated copy of the image.
//
// Frames: the camera's optical frame C (z forward, x right, y down, metres; the raw image described
// by camera_info K and D, pixel centres at integers as in TagDetection). The tag frame T has its
// origin at the tag centre, x right and y down as the tag is printed upright, z into the tag (away
// from a viewer facing it) -- libapriltag's and OpenCV's IPPE_SQUARE convention; the corners of
// TagDetection are then at T = (-s/2, +s/2, 0), (+s/2, +s/2, 0), (+s/2, -s/2, 0), (-s/2, -s/2, 0)
// for a black square of edge s. p_C = R_C_T p_T + t_C.
//
// Method: the corners are undistorted with the camera's own model (plumb_bob, rational_polynomial
// or equidistant) to normalised coordinates and posed by cv::solvePnP(SOLVEPNP_IPPE_SQUARE), which
// picks the better of the two planar solutions by reprojection error.
#include "reflex/vision/calibration.hpp"
#include "reflex/vision/tag_detector.hpp"

#include <opencv2/core.hpp>

#include <optional>
#include <vector>

namespace reflex::vision {

/// Pose of one tag. Invariants: R_C_T a rotation, rvec its axis-angle form, t_C(2) > 0 (in front).
struct TagPose {
  cv::Vec3d t_C;               ///< tag centre in the camera's optical frame, metres
  cv::Matx33d R_C_T;           ///< tag frame in the camera frame
  cv::Vec3d rvec;              ///< R_C_T as axis * angle, radians (cv::Rodrigues)
  double distance = 0.0;       ///< |t_C|, metres
  double tilt_deg = 0.0;       ///< angle between the tag's normal and the line of sight to it, degrees
  double reprojection_px = 0;  ///< RMS distance of the four reprojected corners to the detected ones, pixels
};

/// Pose of `tag` (corners in `camera`'s raw image) for a black square of edge `tag_size` metres.
/// Throws VisionError if tag_size is not in (0, 5] m or not finite. Returns nullopt if no pose puts
/// the tag in front of the camera (degenerate corners).
std::optional<TagPose> estimateTagPose(const CameraInfo& camera, const TagDetection& tag, double tag_size);

/// Draws on a BGR image: each tag's outline (green), its first corner (red dot), its id and, for a
/// tag with a pose, its x (red), y (green) and z (blue) axes of half the tag size. `poses` is empty
/// or one entry per tag; `camera` is needed only for the axes.
void drawTags(cv::Mat& bgr, const std::vector<TagDetection>& tags, const std::vector<std::optional<TagPose>>& poses,
              const CameraInfo* camera, double tag_size);

}  // namespace reflex::vision
