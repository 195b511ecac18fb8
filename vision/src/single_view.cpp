#include "reflex/vision/single_view.hpp"

#include "reflex/vision/error.hpp"

#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

#include <cmath>

namespace reflex::vision {
namespace {

std::vector<cv::Point3d> tagCorners(double s) {
  return {{-s / 2, s / 2, 0}, {s / 2, s / 2, 0}, {s / 2, -s / 2, 0}, {-s / 2, -s / 2, 0}};
}

/// Camera points -> raw pixels with the camera's own distortion model.
std::vector<cv::Point2d> projectRaw(const CameraInfo& camera, const std::vector<cv::Point3d>& p_T,
                                    const cv::Vec3d& rvec, const cv::Vec3d& tvec) {
  std::vector<cv::Point2d> px;
  const cv::Mat K(camera.K), D(camera.D);
  if (camera.distortion_model == "equidistant")
    cv::fisheye::projectPoints(p_T, px, rvec, tvec, K, D);
  else
    cv::projectPoints(p_T, rvec, tvec, K, D, px);
  return px;
}

}  // namespace

std::optional<TagPose> estimateTagPose(const CameraInfo& camera, const TagDetection& tag, double tag_size) {
  if (!(tag_size > 0.0 && tag_size <= 5.0))
    throw VisionError("tag size " + std::to_string(tag_size) + " m must be in (0, 5]");
  const std::vector<cv::Point2d> raw(tag.corners.begin(), tag.corners.end());
  std::vector<cv::Point2d> normalised;
  const cv::Mat K(camera.K), D(camera.D);
  if (camera.distortion_model == "equidistant")
    cv::fisheye::undistortPoints(raw, normalised, K, D);
  else
    cv::undistortPoints(raw, normalised, K, D);
  const std::vector<cv::Point3d> object = tagCorners(tag_size);
  cv::Vec3d rvec, tvec;
  if (!cv::solvePnP(object, normalised, cv::Mat::eye(3, 3, CV_64F), cv::noArray(), rvec, tvec, false,
                    cv::SOLVEPNP_IPPE_SQUARE) ||
      !(tvec[2] > 0.0))
    return std::nullopt;
  TagPose pose;
  pose.t_C = tvec;
  pose.rvec = rvec;
  cv::Rodrigues(rvec, pose.R_C_T);
  pose.distance = cv::norm(tvec);
  const cv::Vec3d z_T(pose.R_C_T(0, 2), pose.R_C_T(1, 2), pose.R_C_T(2, 2));
  pose.tilt_deg = std::acos(std::min(1.0, std::abs(z_T.dot(tvec)) / pose.distance)) * 180.0 / CV_PI;
  const std::vector<cv::Point2d> back = projectRaw(camera, object, rvec, tvec);
  double ss = 0.0;
  for (std::size_t k = 0; k < 4; ++k) ss += (back[k] - raw[k]).dot(back[k] - raw[k]);
  pose.reprojection_px = std::sqrt(ss / 4.0);
  return pose;
}

void drawTags(cv::Mat& bgr, const std::vector<TagDetection>& tags, const std::vector<std::optional<TagPose>>& poses,
              const CameraInfo* camera, double tag_size) {
  const int line = std::max(1, bgr.cols / 640);
  auto pt = [](const cv::Point2d& p) { return cv::Point(cvRound(p.x), cvRound(p.y)); };
  for (std::size_t i = 0; i < tags.size(); ++i) {
    const TagDetection& t = tags[i];
    for (std::size_t k = 0; k < 4; ++k)
      cv::line(bgr, pt(t.corners[k]), pt(t.corners[(k + 1) % 4]), cv::Scalar(0, 255, 0), line, cv::LINE_AA);
    cv::circle(bgr, pt(t.corners[0]), 3 * line, cv::Scalar(0, 0, 255), cv::FILLED, cv::LINE_AA);
    cv::putText(bgr, std::to_string(t.id), pt(t.center), cv::FONT_HERSHEY_SIMPLEX, 0.6 * line, cv::Scalar(255, 0, 255),
                line + 1, cv::LINE_AA);
    if (camera == nullptr || i >= poses.size() || !poses[i]) continue;
    const double a = tag_size / 2;
    const std::vector<cv::Point2d> axes =
        projectRaw(*camera, {{0, 0, 0}, {a, 0, 0}, {0, a, 0}, {0, 0, a}}, poses[i]->rvec, poses[i]->t_C);
    const cv::Scalar colours[3] = {{0, 0, 255}, {0, 255, 0}, {255, 0, 0}};
    for (int k = 0; k < 3; ++k) cv::line(bgr, pt(axes[0]), pt(axes[k + 1]), colours[k], line + 1, cv::LINE_AA);
  }
}

}  // namespace reflex::vision
