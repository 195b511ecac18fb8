#include "reflex/vision/calibration.hpp"

#include "reflex/vision/output_file.hpp"
#include "yaml_util.hpp"

#include <opencv2/calib3d.hpp>

#include <cmath>
#include <fstream>
#include <iomanip>
#include <sstream>

namespace reflex::vision {
namespace {
using namespace detail;

// A ROS matrix field: {rows, cols, data}; rows*cols must equal data length (and the expected shape,
// rows > 0). Returns the matrix node (for messages about its values) and fills `data`.
ConfigNode readRosMatrix(const ConfigNode& root, const std::string& key, int rows, int cols,
                         std::vector<double>& data) {
  const std::string shape =
      rows > 0 ? "a " + std::to_string(rows) + "x" + std::to_string(cols) + " matrix {rows, cols, data}"
               : "a matrix {rows, cols, data}";
  const ConfigNode m = root.at(key, shape);
  m.requireMap(shape);
  const int r = m.at("rows", "an integer").asInteger(0, 1000);
  const int c = m.at("cols", "an integer").asInteger(0, 1000);
  data = m.at("data", "a list of numbers").asNumbers();
  if (static_cast<std::size_t>(r) * static_cast<std::size_t>(c) != data.size())
    m.fail("data", "has " + std::to_string(data.size()) + " numbers",
           "rows*cols = " + std::to_string(r) + "*" + std::to_string(c) + " numbers");
  if (rows > 0 && (r != rows || c != cols))
    m.failHere("a " + std::to_string(r) + "x" + std::to_string(c) + " matrix", shape);
  return m;
}

std::size_t expectedDistortionLength(const ConfigNode& root) {
  const std::string model = root.requiredString("distortion_model", "plumb_bob, rational_polynomial or equidistant");
  if (model == "plumb_bob") return 5;
  if (model == "rational_polynomial") return 8;
  if (model == "equidistant") return 4;
  root.fail("distortion_model", "unknown distortion model", "one of plumb_bob, rational_polynomial, equidistant");
}

bool isRotation(const cv::Matx33d& R) {
  const cv::Matx33d E = R * R.t() - cv::Matx33d::eye();
  double err = 0.0;
  for (int i = 0; i < 9; ++i) err = std::max(err, std::abs(E.val[i]));
  return err < 1e-5 && cv::determinant(R) > 0.0;
}

// Focal lengths against the image width, pixel aspect, principal point inside the image
// (CalibrationLimits). `prime` is "'" for the rectified P, "" for K.
void checkIntrinsics(double fx, double fy, double cx, double cy, const cv::Size& size, const ConfigNode& matrix,
                     const std::string& prime) {
  using L = CalibrationLimits;
  const double w = size.width, h = size.height;
  if (fx < L::kMinFocalPerWidth * w || fx > L::kMaxFocalPerWidth * w)
    matrix.fail("data", "focal length fx" + prime + " = " + fmt(fx) + " px is out of range",
                "[" + fmt(L::kMinFocalPerWidth * w) + ", " + fmt(L::kMaxFocalPerWidth * w) + "] px for a " +
                    std::to_string(size.width) + " px wide image (a field of view between ~1 and ~169 deg)");
  if (fy < L::kMinAspect * fx || fy > L::kMaxAspect * fx)
    matrix.fail("data", "focal length fy" + prime + " = " + fmt(fy) + " px is out of range",
                "[" + fmt(L::kMinAspect * fx) + ", " + fmt(L::kMaxAspect * fx) + "] px (fx" + prime + " = " + fmt(fx) +
                    ": pixel aspect between " + fmt(L::kMinAspect) + " and " + fmt(L::kMaxAspect) + ")");
  if (!(cx >= 0.0 && cx <= w) || !(cy >= 0.0 && cy <= h))
    matrix.fail(
        "data",
        "principal point (cx" + prime + ", cy" + prime + ") = (" + fmt(cx) + ", " + fmt(cy) + ") is outside the image",
        "a point inside the " + std::to_string(size.width) + "x" + std::to_string(size.height) + " image");
}

// Fraction of the rectified image (a 32 x 24 grid of pixel centres) that sees the raw image: each
// rectified pixel is taken back to a raw camera ray (P^-1, R^T) and projected with K and D. A
// distortion or rectification no lens has (k1 = 1e6, say) leaves the rectified image black.
double rectifiedCoverage(const CameraInfo& c) {
  constexpr int kCols = 32, kRows = 24;
  const cv::Matx33d P3(c.P(0, 0), c.P(0, 1), c.P(0, 2), c.P(1, 0), c.P(1, 1), c.P(1, 2), c.P(2, 0), c.P(2, 1),
                       c.P(2, 2));
  const cv::Matx33d back = c.R.t() * P3.inv();
  std::vector<cv::Point3d> rays;
  for (int r = 0; r < kRows; ++r)
    for (int k = 0; k < kCols; ++k) {
      const cv::Vec3d ray =
          back * cv::Vec3d((k + 0.5) * c.image_size.width / kCols, (r + 0.5) * c.image_size.height / kRows, 1.0);
      if (ray[2] > 1e-9) rays.emplace_back(ray[0] / ray[2], ray[1] / ray[2], 1.0);  // behind the camera: unseen
    }
  if (rays.empty()) return 0.0;
  std::vector<cv::Point2d> raw;
  const cv::Vec3d no_rotation(0, 0, 0), no_translation(0, 0, 0);
  if (c.distortion_model == "equidistant")
    cv::fisheye::projectPoints(rays, raw, no_rotation, no_translation, c.K, c.D);
  else
    cv::projectPoints(rays, no_rotation, no_translation, c.K, c.D, raw);
  int inside = 0;
  for (const cv::Point2d& p : raw)
    if (p.x >= 0.0 && p.y >= 0.0 && p.x < c.image_size.width && p.y < c.image_size.height) ++inside;
  return static_cast<double>(inside) / (kCols * kRows);
}

void writeRosMatrix(std::ostream& os, const std::string& key, int rows, int cols, const double* data) {
  os << key << ":\n  rows: " << rows << "\n  cols: " << cols << "\n  data: [";
  for (int i = 0; i < rows * cols; ++i) os << (i ? ", " : "") << std::setprecision(12) << data[i];
  os << "]\n";
}

}  // namespace

CameraInfo parseCameraInfo(const std::string& yaml_text, const std::string& source) {
  // An OpenCV FileStorage calibration (stereoCalibrate's M1 D1 ..., "%YAML:1.0", !!opencv-matrix or
  // XML) is not camera_info: say how to turn it into one instead of naming the first missing field.
  const bool opencv_file = yaml_text.rfind("%YAML:1.0", 0) == 0 ||
                           yaml_text.find("!!opencv-matrix") != std::string::npos ||
                           yaml_text.find("<opencv_storage>") != std::string::npos;
  if (opencv_file && yaml_text.find("camera_matrix:") == std::string::npos)
    throw VisionError(source +
                      ": missing field 'camera_matrix': this is an OpenCV FileStorage calibration, not a ROS "
                      "camera_info file; convert it with `reflex_calibrate convert " +
                      source +
                      " [EXTRINSICS_FILE] --out DIR` (writes DIR/left.yaml and DIR/right.yaml, see vision/README.md)");
  const ConfigNode root = parseYaml(yaml_text, source);
  CameraInfo info;
  using L = CalibrationLimits;
  const int w = root.at("image_width", "an integer").asInteger(L::kMinImageSide, L::kMaxImageSide);
  const int h = root.at("image_height", "an integer").asInteger(L::kMinImageSide, L::kMaxImageSide);
  info.image_size = cv::Size(w, h);
  info.camera_name = root.string("camera_name", info.camera_name);

  std::vector<double> k;
  const ConfigNode km = readRosMatrix(root, "camera_matrix", 3, 3, k);
  for (int i = 0; i < 9; ++i) info.K.val[i] = k[static_cast<std::size_t>(i)];
  if (!(info.K(0, 0) > 0.0)) km.fail("data", "focal length fx = " + fmt(info.K(0, 0)) + " is not positive", "fx > 0");
  if (!(info.K(1, 1) > 0.0)) km.fail("data", "focal length fy = " + fmt(info.K(1, 1)) + " is not positive", "fy > 0");
  if (info.K(2, 0) != 0.0 || info.K(2, 1) != 0.0 || info.K(2, 2) != 1.0)
    km.fail("data", "last row is not [0, 0, 1]", "[fx, 0, cx, 0, fy, cy, 0, 0, 1]");
  checkIntrinsics(info.K(0, 0), info.K(1, 1), info.K(0, 2), info.K(1, 2), info.image_size, km, "");

  const std::size_t nd = expectedDistortionLength(root);
  info.distortion_model = root.requiredString("distortion_model");
  const ConfigNode dm = readRosMatrix(root, "distortion_coefficients", -1, -1, info.D);
  if (info.D.size() != nd)
    dm.fail("data", "has " + std::to_string(info.D.size()) + " coefficients",
            std::to_string(nd) + " for the distortion model '" + info.distortion_model + "'");

  std::vector<double> r;
  const ConfigNode rm = readRosMatrix(root, "rectification_matrix", 3, 3, r);
  for (int i = 0; i < 9; ++i) info.R.val[i] = r[static_cast<std::size_t>(i)];
  if (!isRotation(info.R)) rm.fail("data", "not a rotation", "R R^T = I and det > 0");

  std::vector<double> p;
  const ConfigNode pm = readRosMatrix(root, "projection_matrix", 3, 4, p);
  for (int i = 0; i < 12; ++i) info.P.val[i] = p[static_cast<std::size_t>(i)];
  if (!(info.P(0, 0) > 0.0)) pm.fail("data", "focal length fx' = " + fmt(info.P(0, 0)) + " is not positive", "fx' > 0");
  if (!(info.P(1, 1) > 0.0)) pm.fail("data", "focal length fy' = " + fmt(info.P(1, 1)) + " is not positive", "fy' > 0");
  if (info.P(2, 0) != 0.0 || info.P(2, 1) != 0.0 || info.P(2, 2) != 1.0 || info.P(2, 3) != 0.0)
    pm.fail("data", "last row is not [0, 0, 1, 0]", "[fx', 0, cx', Tx, 0, fy', cy', Ty, 0, 0, 1, 0]");
  checkIntrinsics(info.P(0, 0), info.P(1, 1), info.P(0, 2), info.P(1, 2), info.image_size, pm, "'");
  return info;
}

CameraInfo loadCameraInfo(const std::string& path) { return parseCameraInfo(readTextFile(path, "calibration"), path); }

void saveCameraInfo(const std::string& path, const CameraInfo& info) {
  std::ostringstream os;
  os << "image_width: " << info.image_size.width << "\n";
  os << "image_height: " << info.image_size.height << "\n";
  os << "camera_name: " << (info.camera_name.empty() ? "camera" : info.camera_name) << "\n";
  writeRosMatrix(os, "camera_matrix", 3, 3, info.K.val);
  os << "distortion_model: " << info.distortion_model << "\n";
  writeRosMatrix(os, "distortion_coefficients", 1, static_cast<int>(info.D.size()), info.D.data());
  writeRosMatrix(os, "rectification_matrix", 3, 3, info.R.val);
  writeRosMatrix(os, "projection_matrix", 3, 4, info.P.val);
  writeTextFile(path, os.str(), "calibration file");
}

void validateStereoCalibration(const StereoCalibration& calib, const std::string& left_source,
                               const std::string& right_source) {
  const CameraInfo& l = calib.left;
  const CameraInfo& r = calib.right;
  if (l.image_size != r.image_size)
    throw VisionError("image sizes differ: " + left_source + " has " + std::to_string(l.image_size.width) + "x" +
                      std::to_string(l.image_size.height) + " but " + right_source + " has " +
                      std::to_string(r.image_size.width) + "x" + std::to_string(r.image_size.height));
  // A rectified focal length that is not positive (a calibration that converged to a mirrored
  // solution, e.g. k3 running away) makes every check below meaningless: said first, as what it is.
  for (const auto& [camera, source] : {std::pair<const CameraInfo*, const std::string*>{&l, &left_source},
                                       std::pair<const CameraInfo*, const std::string*>{&r, &right_source}}) {
    if (!(camera->P(0, 0) > 0.0) || !(camera->P(1, 1) > 0.0))
      throw VisionError(*source + ": projection_matrix has the rectified focal lengths fx' = " + fmt(camera->P(0, 0)) +
                        ", fy' = " + fmt(camera->P(1, 1)) + "; both must be positive");
  }
  const double tol = 1e-6 * l.P(0, 0);
  if (std::abs(l.P(0, 3)) > tol)
    throw VisionError(left_source + ": projection_matrix P[0][3] = " + fmt(l.P(0, 3)) +
                      " must be 0 for the left camera (is left/right swapped?)");
  if (!(r.P(0, 3) < 0.0))
    throw VisionError(right_source + ": projection_matrix P[0][3] = " + fmt(r.P(0, 3)) +
                      " must be negative (-fx' * baseline) for the right camera (is left/right swapped?)");
  for (const auto& [camera, source] : {std::pair<const CameraInfo*, const std::string*>{&l, &left_source},
                                       std::pair<const CameraInfo*, const std::string*>{&r, &right_source}}) {
    const double coverage = rectifiedCoverage(*camera);
    if (coverage < CalibrationLimits::kMinRectifiedCoverage)
      throw VisionError(*source + ": only " + fmt(100.0 * coverage) +
                        " % of the rectified image sees the camera image (at least " +
                        fmt(100.0 * CalibrationLimits::kMinRectifiedCoverage) +
                        " % expected): distortion_coefficients, rectification_matrix or projection_matrix no lens has");
  }
  const double baseline = calib.baseline();
  if (baseline < CalibrationLimits::kMinBaseline || baseline > CalibrationLimits::kMaxBaseline)
    throw VisionError(right_source + ": projection_matrix P[0][3] = " + fmt(r.P(0, 3)) + " gives a baseline of " +
                      fmt(baseline) + " m, outside [" + fmt(CalibrationLimits::kMinBaseline) + ", " +
                      fmt(CalibrationLimits::kMaxBaseline) + "] m (P[0][3] = -fx' * baseline)");
  if (std::abs(l.P(1, 3)) > tol || std::abs(r.P(1, 3)) > tol)
    throw VisionError(right_source + ": projection_matrix P[1][3] must be 0 (only horizontal stereo is supported)");
  auto same = [&](double a, double b, const char* field) {
    if (std::abs(a - b) > 1e-6 * std::max(1.0, std::abs(a)))
      throw VisionError("rectified intrinsics differ: " + std::string(field) + " = " + fmt(a) + " in " + left_source +
                        " but " + fmt(b) + " in " + right_source);
  };
  same(l.P(0, 0), r.P(0, 0), "projection_matrix fx'");
  same(l.P(1, 1), r.P(1, 1), "projection_matrix fy'");
  same(l.P(1, 2), r.P(1, 2), "projection_matrix cy'");
}

StereoCalibration loadStereoCalibration(const std::string& left_path, const std::string& right_path) {
  StereoCalibration c;
  c.left = loadCameraInfo(left_path);
  c.right = loadCameraInfo(right_path);
  validateStereoCalibration(c, left_path, right_path);
  return c;
}

CameraMount parseCameraMount(const std::string& yaml_text, const std::string& source) {
  return detail::readCameraMount(parseYaml(yaml_text, source));
}

CameraMount detail::readCameraMount(const ConfigNode& root) {
  root.requireMap("{translation, rotation_matrix}");
  root.rejectUnknown({"translation", "rotation_matrix"});
  CameraMount m;
  const std::vector<double> t = root.at("translation", "[x, y, z] in m").asNumbers(3);
  m.p_B_C = cv::Vec3d(t[0], t[1], t[2]);
  const std::vector<double> r = root.at("rotation_matrix", "9 numbers, row-major").asNumbers(9);
  for (int i = 0; i < 9; ++i) m.R_B_C.val[i] = r[static_cast<std::size_t>(i)];
  for (int i = 0; i < 3; ++i)
    if (std::abs(t[static_cast<std::size_t>(i)]) > kMaxMountOffset)
      root.fail("translation",
                "translation[" + std::to_string(i) + "] = " + fmt(t[static_cast<std::size_t>(i)]) +
                    " m is too far from the robot base frame",
                "at most " + fmt(kMaxMountOffset) + " m on each axis");
  if (!isRotation(m.R_B_C)) root.fail("rotation_matrix", "not a rotation", "R R^T = I within 1e-5 and det > 0");
  return m;
}

CameraMount loadCameraMount(const std::string& path) {
  return parseCameraMount(readTextFile(path, "camera mount"), path);
}

void saveCameraMount(const std::string& path, const CameraMount& mount, const std::string& comment) {
  std::ostringstream os;
  os << "# Left camera optical frame C (z forward, x right, y down) in the robot base frame B\n"
        "# (x forward, y left, z up, metres): p_B = R_B_C p_C + p_B_C.\n";
  if (!comment.empty()) os << "# " << comment << "\n";
  os << std::setprecision(12) << "translation: [" << mount.p_B_C[0] << ", " << mount.p_B_C[1] << ", " << mount.p_B_C[2]
     << "]\nrotation_matrix: [";
  for (int i = 0; i < 9; ++i) os << (i ? ", " : "") << mount.R_B_C.val[i];
  os << "]  # row-major R_B_C\n";
  writeTextFile(path, os.str(), "camera mount file");
}

}  // namespace reflex::vision
