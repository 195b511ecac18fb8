#include "reflex/vision/calibration.hpp"

#include "yaml_util.hpp"

#include <cmath>
#include <fstream>
#include <iomanip>

namespace reflex::vision {
namespace {
using namespace detail;

// A ROS matrix field: {rows, cols, data}; rows*cols must equal data length (and the expected shape).
std::vector<double> readRosMatrix(const YAML::Node& root, const std::string& key, int rows, int cols,
                                  const std::string& source) {
  const std::string where = source + ": " + key;
  const YAML::Node m = require(root, key, source);
  if (!m.IsMap()) throw VisionError(where + ": expected a mapping with rows, cols, data");
  const int r = asInt(require(m, "rows", where), where + ".rows");
  const int c = asInt(require(m, "cols", where), where + ".cols");
  const std::vector<double> data = asDoubles(require(m, "data", where), where + ".data");
  if (r < 0 || c < 0 || static_cast<std::size_t>(r) * static_cast<std::size_t>(c) != data.size())
    throw VisionError(where + ": rows*cols = " + std::to_string(r) + "*" + std::to_string(c) +
                      " does not match data length " + std::to_string(data.size()));
  if (rows > 0 && (r != rows || c != cols))
    throw VisionError(where + ": expected a " + std::to_string(rows) + "x" + std::to_string(cols) +
                      " matrix, got " + std::to_string(r) + "x" + std::to_string(c));
  return data;
}

std::size_t expectedDistortionLength(const std::string& model, const std::string& where) {
  if (model == "plumb_bob") return 5;
  if (model == "rational_polynomial") return 8;
  if (model == "equidistant") return 4;
  throw VisionError(where + ": unknown distortion_model '" + model +
                    "' (known: plumb_bob, rational_polynomial, equidistant)");
}

bool isRotation(const cv::Matx33d& R) {
  const cv::Matx33d E = R * R.t() - cv::Matx33d::eye();
  double err = 0.0;
  for (int i = 0; i < 9; ++i) err = std::max(err, std::abs(E.val[i]));
  return err < 1e-5 && cv::determinant(R) > 0.0;
}

void writeRosMatrix(std::ostream& os, const std::string& key, int rows, int cols, const double* data) {
  os << key << ":\n  rows: " << rows << "\n  cols: " << cols << "\n  data: [";
  for (int i = 0; i < rows * cols; ++i) os << (i ? ", " : "") << std::setprecision(12) << data[i];
  os << "]\n";
}

}  // namespace

CameraInfo parseCameraInfo(const std::string& yaml_text, const std::string& source) {
  const YAML::Node root = parseYaml(yaml_text, source);
  CameraInfo info;
  const int w = asInt(require(root, "image_width", source), source + ": image_width");
  const int h = asInt(require(root, "image_height", source), source + ": image_height");
  if (w <= 0) throw VisionError(source + ": image_width = " + std::to_string(w) + " must be positive");
  if (h <= 0) throw VisionError(source + ": image_height = " + std::to_string(h) + " must be positive");
  info.image_size = cv::Size(w, h);
  if (root["camera_name"]) info.camera_name = asString(root["camera_name"], source + ": camera_name");

  const std::vector<double> k = readRosMatrix(root, "camera_matrix", 3, 3, source);
  for (int i = 0; i < 9; ++i) info.K.val[i] = k[static_cast<std::size_t>(i)];
  if (!(info.K(0, 0) > 0.0))
    throw VisionError(source + ": camera_matrix: focal length fx = " + fmt(info.K(0, 0)) + " must be positive");
  if (!(info.K(1, 1) > 0.0))
    throw VisionError(source + ": camera_matrix: focal length fy = " + fmt(info.K(1, 1)) + " must be positive");
  if (info.K(2, 0) != 0.0 || info.K(2, 1) != 0.0 || info.K(2, 2) != 1.0)
    throw VisionError(source + ": camera_matrix: last row must be [0, 0, 1]");

  info.distortion_model =
      asString(require(root, "distortion_model", source), source + ": distortion_model");
  const std::size_t nd = expectedDistortionLength(info.distortion_model, source + ": distortion_model");
  info.D = readRosMatrix(root, "distortion_coefficients", -1, -1, source);
  if (info.D.size() != nd)
    throw VisionError(source + ": distortion_coefficients: model '" + info.distortion_model + "' needs " +
                      std::to_string(nd) + " coefficients, got " + std::to_string(info.D.size()));

  const std::vector<double> r = readRosMatrix(root, "rectification_matrix", 3, 3, source);
  for (int i = 0; i < 9; ++i) info.R.val[i] = r[static_cast<std::size_t>(i)];
  if (!isRotation(info.R))
    throw VisionError(source + ": rectification_matrix is not a rotation (R R^T != I or det <= 0)");

  const std::vector<double> p = readRosMatrix(root, "projection_matrix", 3, 4, source);
  for (int i = 0; i < 12; ++i) info.P.val[i] = p[static_cast<std::size_t>(i)];
  if (!(info.P(0, 0) > 0.0))
    throw VisionError(source + ": projection_matrix: focal length fx' = " + fmt(info.P(0, 0)) + " must be positive");
  if (!(info.P(1, 1) > 0.0))
    throw VisionError(source + ": projection_matrix: focal length fy' = " + fmt(info.P(1, 1)) + " must be positive");
  return info;
}

CameraInfo loadCameraInfo(const std::string& path) {
  return parseCameraInfo(readTextFile(path, "calibration"), path);
}

void saveCameraInfo(const std::string& path, const CameraInfo& info) {
  std::ofstream os(path);
  if (!os) throw VisionError("cannot write calibration file '" + path + "'");
  os << "image_width: " << info.image_size.width << "\n";
  os << "image_height: " << info.image_size.height << "\n";
  os << "camera_name: " << (info.camera_name.empty() ? "camera" : info.camera_name) << "\n";
  writeRosMatrix(os, "camera_matrix", 3, 3, info.K.val);
  os << "distortion_model: " << info.distortion_model << "\n";
  writeRosMatrix(os, "distortion_coefficients", 1, static_cast<int>(info.D.size()), info.D.data());
  writeRosMatrix(os, "rectification_matrix", 3, 3, info.R.val);
  writeRosMatrix(os, "projection_matrix", 3, 4, info.P.val);
  if (!os) throw VisionError("failed writing calibration file '" + path + "'");
}

void validateStereoCalibration(const StereoCalibration& calib, const std::string& left_source,
                               const std::string& right_source) {
  const CameraInfo& l = calib.left;
  const CameraInfo& r = calib.right;
  if (l.image_size != r.image_size)
    throw VisionError("image sizes differ: " + left_source + " has " + std::to_string(l.image_size.width) + "x" +
                      std::to_string(l.image_size.height) + " but " + right_source + " has " +
                      std::to_string(r.image_size.width) + "x" + std::to_string(r.image_size.height));
  const double tol = 1e-6 * l.P(0, 0);
  if (std::abs(l.P(0, 3)) > tol)
    throw VisionError(left_source + ": projection_matrix P[0][3] = " + fmt(l.P(0, 3)) +
                      " must be 0 for the left camera (is left/right swapped?)");
  if (!(r.P(0, 3) < 0.0))
    throw VisionError(right_source + ": projection_matrix P[0][3] = " + fmt(r.P(0, 3)) +
                      " must be negative (-fx' * baseline) for the right camera (is left/right swapped?)");
  if (std::abs(l.P(1, 3)) > tol || std::abs(r.P(1, 3)) > tol)
    throw VisionError(right_source + ": projection_matrix P[1][3] must be 0 (only horizontal stereo is supported)");
  auto same = [&](double a, double b, const char* field) {
    if (std::abs(a - b) > 1e-6 * std::max(1.0, std::abs(a)))
      throw VisionError("rectified intrinsics differ: " + std::string(field) + " = " + fmt(a) + " in " +
                        left_source + " but " + fmt(b) + " in " + right_source);
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

CameraMount defaultCameraMount() {
  CameraMount m;
  // Columns are the optical axes in base coordinates: x_C = -y_B, y_C = -z_B, z_C = +x_B.
  m.R_B_C = cv::Matx33d(0, 0, 1,
                        -1, 0, 0,
                        0, -1, 0);
  m.p_B_C = cv::Vec3d(0.08, 0.03, 1.15);
  return m;
}

CameraMount parseCameraMount(const std::string& yaml_text, const std::string& source) {
  const YAML::Node root = parseYaml(yaml_text, source);
  CameraMount m;
  const std::vector<double> t = asDoublesN(require(root, "translation", source), 3, source + ": translation");
  m.p_B_C = cv::Vec3d(t[0], t[1], t[2]);
  const std::vector<double> r =
      asDoublesN(require(root, "rotation_matrix", source), 9, source + ": rotation_matrix");
  for (int i = 0; i < 9; ++i) m.R_B_C.val[i] = r[static_cast<std::size_t>(i)];
  if (!isRotation(m.R_B_C))
    throw VisionError(source + ": rotation_matrix is not a rotation (R R^T != I within 1e-5, or det <= 0)");
  return m;
}

CameraMount loadCameraMount(const std::string& path) {
  return parseCameraMount(readTextFile(path, "camera mount"), path);
}

void saveCameraMount(const std::string& path, const CameraMount& mount, const std::string& comment) {
  std::ofstream os(path);
  if (!os) throw VisionError("cannot write camera mount file '" + path + "'");
  os << "# Left camera optical frame C (z forward, x right, y down) in the robot base frame B\n"
        "# (x forward, y left, z up, metres): p_B = R_B_C p_C + p_B_C.\n";
  if (!comment.empty()) os << "# " << comment << "\n";
  os << std::setprecision(12) << "translation: [" << mount.p_B_C[0] << ", " << mount.p_B_C[1] << ", "
     << mount.p_B_C[2] << "]\nrotation_matrix: [";
  for (int i = 0; i < 9; ++i) os << (i ? ", " : "") << mount.R_B_C.val[i];
  os << "]  # row-major R_B_C\n";
  if (!os) throw VisionError("failed writing camera mount file '" + path + "'");
}

}  // namespace reflex::vision
