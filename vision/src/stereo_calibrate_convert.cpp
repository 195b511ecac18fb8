// reflex_calibrate convert: an OpenCV stereoCalibrate FileStorage file (or the intrinsics/extrinsics
// pair OpenCV's samples/cpp/stereo_calib.cpp writes) -> the ROS camera_info pair vision reads.
#include "reflex/vision/error.hpp"
#include "reflex/vision/stereo_calibrate.hpp"
#include "yaml_util.hpp"

#include <opencv2/calib3d.hpp>
#include <opencv2/core/persistence.hpp>

#include <memory>

namespace reflex::vision {
namespace {
using detail::fmt;

// One value of the calibration and the names it goes by in the wild.
struct Key {
  const char* label;
  std::vector<const char*> names;
};

std::string spellings(const Key& k) {
  std::string s;
  for (const char* n : k.names) s += (s.empty() ? "" : "|") + std::string(n);
  return s;
}

class Storages {
 public:
  explicit Storages(const std::vector<std::string>& files) {
    if (files.empty()) throw VisionError("convert: give the OpenCV calibration file(s)");
    for (const std::string& f : files) {
      (void)detail::readTextFile(f, "OpenCV calibration");  // a clear message for a missing or unreadable file
      auto fs = std::make_unique<cv::FileStorage>();
      try {
        if (!fs->open(f, cv::FileStorage::READ)) throw VisionError("");
      } catch (const cv::Exception& e) {
        throw VisionError(f +
                          ": not an OpenCV FileStorage file (YAML with %YAML:1.0, XML or JSON): " + std::string(e.err));
      } catch (const VisionError&) {
        throw VisionError(f + ": not an OpenCV FileStorage file (YAML with %YAML:1.0, XML or JSON)");
      }
      names_.push_back(f);
      fs_.push_back(std::move(fs));
    }
  }
  /// The node of the first spelling found in any file; `where` receives "file: name".
  cv::FileNode find(const Key& k, std::string& where) const {
    for (std::size_t i = 0; i < fs_.size(); ++i)
      for (const char* n : k.names) {
        const cv::FileNode node = (*fs_[i])[n];
        if (!node.empty() && !node.isNone()) {
          where = names_[i] + ": " + n;
          return node;
        }
      }
    return {};
  }
  std::string fileList() const {
    std::string s;
    for (const std::string& n : names_) s += (s.empty() ? "" : ", ") + n;
    return s;
  }

 private:
  std::vector<std::string> names_;
  std::vector<std::unique_ptr<cv::FileStorage>> fs_;
};

cv::Mat readMat(const cv::FileNode& node, const std::string& where) {
  cv::Mat m;
  try {
    if (node.isSeq()) {
      std::vector<double> v;
      node >> v;
      m = cv::Mat(v, true).reshape(1, 1);
    } else {
      node >> m;
    }
  } catch (const cv::Exception& e) {
    throw VisionError(where + ": not a matrix: " + std::string(e.err));
  }
  if (m.empty()) throw VisionError(where + ": not a matrix (expected !!opencv-matrix or a list of numbers)");
  m.convertTo(m, CV_64F);
  for (auto it = m.begin<double>(); it != m.end<double>(); ++it)
    if (!std::isfinite(*it)) throw VisionError(where + ": holds a value that is not finite");
  return m;
}

cv::Mat readShaped(const Storages& s, const Key& k, int rows, int cols, std::string& where) {
  const cv::Mat m = readMat(s.find(k, where), where);
  if (static_cast<int>(m.total()) != rows * cols)
    throw VisionError(where + ": expected " + std::to_string(rows) + "x" + std::to_string(cols) + " (" + k.label +
                      "), got " + std::to_string(m.rows) + "x" + std::to_string(m.cols));
  return m.reshape(1, rows).clone();
}

// Distortion as ROS models it: 4 (k1 k2 p1 p2, k3 = 0 added) or 5 -> plumb_bob, 8 -> rational_polynomial.
cv::Mat readDistortion(const Storages& s, const Key& k, std::string& model) {
  std::string where;
  cv::Mat d = readMat(s.find(k, where), where).reshape(1, 1);
  const int n = static_cast<int>(d.total());
  if (n == 4) {
    cv::hconcat(d, cv::Mat::zeros(1, 1, CV_64F), d);
  } else if (n != 5 && n != 8) {
    throw VisionError(where + ": " + std::to_string(n) +
                      " distortion coefficients; ROS camera_info takes 4 or 5 (plumb_bob) or 8 (rational_polynomial)");
  }
  model = d.total() == 8 ? "rational_polynomial" : "plumb_bob";
  return d;
}

const Key kK1{"left camera matrix", {"M1", "K1", "cameraMatrix1", "camera_matrix_left", "cameraMatrixL"}};
const Key kK2{"right camera matrix", {"M2", "K2", "cameraMatrix2", "camera_matrix_right", "cameraMatrixR"}};
const Key kD1{"left distortion", {"D1", "distCoeffs1", "dist_coeffs_left", "distortion_left", "distCoeffsL"}};
const Key kD2{"right distortion", {"D2", "distCoeffs2", "dist_coeffs_right", "distortion_right", "distCoeffsR"}};
const Key kR{"rotation left -> right", {"R", "rotation"}};
const Key kT{"translation left -> right", {"T", "translation"}};
const Key kR1{"left rectification", {"R1"}};
const Key kR2{"right rectification", {"R2"}};
const Key kP1{"left projection", {"P1"}};
const Key kP2{"right projection", {"P2"}};
const Key kWidth{"image width", {"image_width", "imageWidth", "width"}};
const Key kHeight{"image height", {"image_height", "imageHeight", "height"}};
const Key kSize{"image size", {"image_size", "imageSize", "size"}};

cv::Size readSize(const Storages& s, const ConvertOptions& o, std::string& notes) {
  std::string where;
  const cv::FileNode w = s.find(kWidth, where), h = s.find(kHeight, where);
  if (!w.empty() && !h.empty() && w.isInt() && h.isInt()) return cv::Size(static_cast<int>(w), static_cast<int>(h));
  const cv::FileNode both = s.find(kSize, where);
  if (!both.empty()) {
    const cv::Mat m = readMat(both, where);
    if (m.total() != 2) throw VisionError(where + ": expected [width, height]");
    return cv::Size(static_cast<int>(std::lround(m.at<double>(0))), static_cast<int>(std::lround(m.at<double>(1))));
  }
  if (o.size.area() > 0) {
    notes += "image size " + std::to_string(o.size.width) + "x" + std::to_string(o.size.height) + " from --size\n";
    return o.size;
  }
  throw VisionError(s.fileList() +
                    ": no image size (image_width + image_height, or image_size: [w, h]); OpenCV's "
                    "stereo_calib sample does not store it: pass --size WIDTHxHEIGHT");
}

}  // namespace

StereoCalibration convertOpenCvStereo(const std::vector<std::string>& files, const ConvertOptions& o,
                                      std::string& notes) {
  const Storages s(files);
  std::string missing, where;
  for (const Key* k : {&kK1, &kD1, &kK2, &kD2, &kR, &kT})
    if (s.find(*k, where).empty()) missing += std::string(missing.empty() ? "" : ", ") + spellings(*k);
  if (!missing.empty())
    throw VisionError(s.fileList() + ": not an OpenCV stereo calibration: missing " + missing +
                      " (the left/right camera matrices, distortions and R, T of stereoCalibrate)");
  if (!(o.translation_scale > 0.0))
    throw VisionError("translation scale = " + fmt(o.translation_scale) + " must be positive");
  const cv::Size size = readSize(s, o, notes);
  using L = CalibrationLimits;
  if (size.width < L::kMinImageSide || size.height < L::kMinImageSide || size.width > L::kMaxImageSide ||
      size.height > L::kMaxImageSide)
    throw VisionError("image size " + std::to_string(size.width) + "x" + std::to_string(size.height) + " is outside [" +
                      std::to_string(L::kMinImageSide) + ", " + std::to_string(L::kMaxImageSide) + "] pixels");

  StereoCalibration c;
  CameraInfo* cams[2] = {&c.left, &c.right};
  const Key* kk[2] = {&kK1, &kK2};
  const Key* kd[2] = {&kD1, &kD2};
  cv::Mat K[2], D[2];
  for (int i = 0; i < 2; ++i) {
    K[i] = readShaped(s, *kk[i], 3, 3, where);
    D[i] = readDistortion(s, *kd[i], cams[i]->distortion_model);
    cams[i]->camera_name = i == 0 ? "left" : "right";
    cams[i]->image_size = size;
  }
  cv::Mat R = readMat(s.find(kR, where), where);
  if (R.total() == 3) cv::Rodrigues(R.reshape(1, 3), R);  // a rotation vector
  if (R.total() != 9) throw VisionError(where + ": expected a 3x3 rotation or a rotation vector");
  R = R.reshape(1, 3);
  cv::Mat T = readShaped(s, kT, 3, 1, where) * o.translation_scale;
  const double baseline = cv::norm(T);
  if (baseline > L::kMaxBaseline)
    throw VisionError(where + ": |T| = " + fmt(baseline) + " is more than " + fmt(L::kMaxBaseline) +
                      " m: is the calibration in millimetres? pass --scale 0.001");

  cv::Mat R1, R2, P1, P2;
  const bool have_rect = !s.find(kR1, where).empty() && !s.find(kR2, where).empty() && !s.find(kP1, where).empty() &&
                         !s.find(kP2, where).empty();
  if (have_rect) {
    R1 = readShaped(s, kR1, 3, 3, where);
    R2 = readShaped(s, kR2, 3, 3, where);
    P1 = readShaped(s, kP1, 3, 4, where);
    P2 = readShaped(s, kP2, 3, 4, where);
    P1.col(3) *= o.translation_scale;
    P2.col(3) *= o.translation_scale;
    notes += "rectification (R1 R2 P1 P2) taken from the file\n";
  } else {
    cv::Mat Q;
    cv::stereoRectify(K[0], D[0], K[1], D[1], size, R, T, R1, R2, P1, P2, Q, cv::CALIB_ZERO_DISPARITY, o.alpha);
    notes += "rectification computed with stereoRectify (alpha " + fmt(o.alpha) + "): the file has no R1 R2 P1 P2\n";
  }
  const cv::Mat* rr[2] = {&R1, &R2};
  const cv::Mat* pp[2] = {&P1, &P2};
  for (int i = 0; i < 2; ++i) {
    for (int j = 0; j < 9; ++j) cams[i]->K.val[j] = K[i].at<double>(j / 3, j % 3);
    for (int j = 0; j < 9; ++j) cams[i]->R.val[j] = rr[i]->at<double>(j / 3, j % 3);
    for (int j = 0; j < 12; ++j) cams[i]->P.val[j] = pp[i]->at<double>(j / 4, j % 4);
    cams[i]->D.assign(D[i].begin<double>(), D[i].end<double>());
  }
  validateStereoCalibration(c, s.fileList() + " (left camera)", s.fileList() + " (right camera)");
  notes += "baseline " + fmt(c.baseline()) + " m\n";
  return c;
}

}  // namespace reflex::vision
