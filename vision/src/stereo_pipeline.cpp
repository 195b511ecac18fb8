#include "reflex/vision/stereo_pipeline.hpp"

#include "reflex/vision/error.hpp"

#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <future>
#include <map>

namespace reflex::vision {
namespace {

const CameraInfo& cam(const StereoCalibration& c, bool right) { return right ? c.right : c.left; }

// Keeps only ids seen exactly once in an image; duplicates (two tags with one id) are ambiguous.
std::map<int, const TagDetection*> uniqueById(const std::vector<TagDetection>& dets, int& duplicates) {
  std::map<int, const TagDetection*> out;
  std::map<int, int> count;
  for (const TagDetection& d : dets) ++count[d.id];
  for (const TagDetection& d : dets) {
    if (count[d.id] == 1)
      out[d.id] = &d;
    else
      ++duplicates;
  }
  return out;
}

}  // namespace

StereoRectifier::StereoRectifier(const StereoCalibration& calib) : calib_(calib) {
  for (int i = 0; i < 2; ++i) {
    const CameraInfo& c = cam(calib_, i == 1);
    const cv::Mat P(c.P);
    if (c.distortion_model == "equidistant")
      cv::fisheye::initUndistortRectifyMap(c.K, c.D, c.R, P.colRange(0, 3), c.image_size, CV_16SC2, map1_[i], map2_[i]);
    else
      cv::initUndistortRectifyMap(c.K, c.D, c.R, P.colRange(0, 3), c.image_size, CV_16SC2, map1_[i], map2_[i]);
  }
}

void StereoRectifier::rectifyImage(const cv::Mat& raw, cv::Mat& rect, bool right) const {
  const int i = right ? 1 : 0;
  cv::remap(raw, rect, map1_[i], map2_[i], cv::INTER_LINEAR, cv::BORDER_CONSTANT, cv::Scalar(0));
}

void StereoRectifier::rectifyPoints(const std::vector<cv::Point2d>& raw, std::vector<cv::Point2d>& rect,
                                    bool right) const {
  rect.clear();
  if (raw.empty()) return;
  const CameraInfo& c = cam(calib_, right);
  const cv::Mat P = cv::Mat(c.P).colRange(0, 3);
  if (c.distortion_model == "equidistant")
    cv::fisheye::undistortPoints(raw, rect, c.K, c.D, c.R, P);
  else
    cv::undistortPoints(raw, rect, c.K, c.D, c.R, P);
}

bool StereoRectifier::triangulate(const cv::Point2d& l, const cv::Point2d& r, cv::Vec3d& p_rect,
                                  double min_disparity_px) const {
  const cv::Matx34d& PL = calib_.left.P;
  const cv::Matx34d& PR = calib_.right.P;
  const double fx = PL(0, 0), fy = PL(1, 1), cy = PL(1, 2);
  const double xl = l.x - PL(0, 2);
  const double d = xl - (r.x - PR(0, 2));
  if (!(d >= min_disparity_px)) return false;
  const double Z = -PR(0, 3) / d;  // = fx' B / d
  p_rect = cv::Vec3d(xl * Z / fx, (0.5 * (l.y + r.y) - cy) * Z / fy, Z);
  return true;
}

cv::Point2d StereoRectifier::projectRect(const cv::Vec3d& p, bool right) const {
  const cv::Matx34d& P = right ? calib_.right.P : calib_.left.P;
  const cv::Vec3d h = P * cv::Vec4d(p[0], p[1], p[2], 1.0);
  return cv::Point2d(h[0] / h[2], h[1] / h[2]);
}

namespace {

// 16 residuals (u, v of 4 corners in the left then the right rectified image) of the square posed
// by (R, t) in the rectified left frame, its model corners scaled by `scale`.
void tagResiduals(const StereoRectifier& rect, const cv::Vec3d model[4], double scale, const cv::Matx33d& R,
                  const cv::Vec3d& t, const std::array<cv::Point2d, 4>& l, const std::array<cv::Point2d, 4>& r,
                  double res[16], bool& in_front) {
  in_front = true;
  for (int k = 0; k < 4; ++k) {
    const cv::Vec3d p = R * (scale * model[k]) + t;
    in_front = in_front && p[2] > 1e-3;
    const cv::Point2d pl = rect.projectRect(p, false);
    const cv::Point2d pr = rect.projectRect(p, true);
    const auto ku = static_cast<std::size_t>(k);
    res[2 * k] = pl.x - l[ku].x;
    res[2 * k + 1] = pl.y - l[ku].y;
    res[8 + 2 * k] = pr.x - r[ku].x;
    res[8 + 2 * k + 1] = pr.y - r[ku].y;
  }
}

cv::Matx33d expRotation(const cv::Vec3d& w) {
  cv::Matx33d R;
  cv::Rodrigues(w, R);
  return R;
}

}  // namespace

bool fitTagPoseStereo(const StereoRectifier& rectifier, const std::array<cv::Point2d, 4>& left_rect,
                      const std::array<cv::Point2d, 4>& right_rect, const std::array<cv::Vec3d, 4>& seed_rect,
                      double tag_size, cv::Vec3d& centre_rect, cv::Vec3d& zhat_rect, double& rms_px,
                      const TagFitWeights& weights) {
  const double h = 0.5 * tag_size;
  const cv::Vec3d model[4] = {{-h, h, 0.0}, {h, h, 0.0}, {h, -h, 0.0}, {-h, -h, 0.0}};
  // Seed: Kabsch fit of the model square to the triangulated corners.
  cv::Vec3d cbar(0, 0, 0);
  for (const cv::Vec3d& c : seed_rect) cbar += 0.25 * c;
  cv::Matx33d H = cv::Matx33d::zeros();
  for (std::size_t k = 0; k < 4; ++k) H += model[k] * (seed_rect[k] - cbar).t();
  cv::Mat w, U, Vt;
  cv::SVD::compute(cv::Mat(H), w, U, Vt);
  const cv::Matx33d Um(U), V(cv::Mat(Vt.t()));
  const double d = cv::determinant(V * Um.t()) < 0.0 ? -1.0 : 1.0;
  cv::Matx33d R = V * cv::Matx33d(1, 0, 0, 0, 1, 0, 0, 0, d) * Um.t();
  cv::Vec3d t = cbar;

  // Residuals in units of their standard deviation: 16 pixel residuals / corner_sigma_px, then the
  // size prior (scale - 1) / size_sigma. size_sigma <= 0 holds the scale at 1 (the known size, exactly).
  const bool free_scale = weights.size_sigma > 0.0;
  const double wp = 1.0 / std::max(weights.corner_sigma_px, 1e-6);
  const double ws = free_scale ? 1.0 / weights.size_sigma : 0.0;
  double scale = 1.0;
  double res[16], res2[16];
  bool in_front = true;
  for (int iter = 0; iter < 15; ++iter) {
    tagResiduals(rectifier, model, scale, R, t, left_rect, right_rect, res, in_front);
    if (!in_front) return false;
    cv::Matx<double, 17, 7> J = cv::Matx<double, 17, 7>::zeros();
    cv::Matx<double, 17, 1> r;
    for (int i = 0; i < 16; ++i) r(i) = wp * res[i];
    r(16) = ws * (scale - 1.0);
    for (int j = 0; j < 7; ++j) {
      if (j == 6 && !free_scale) break;
      cv::Vec3d dw(0, 0, 0), dt(0, 0, 0);
      double ds = 0.0;
      const double eps = j < 3 ? 1e-6 : (j < 6 ? 1e-7 : 1e-6);
      if (j < 3)
        dw[j] = eps;
      else if (j < 6)
        dt[j - 3] = eps;
      else
        ds = eps;
      tagResiduals(rectifier, model, scale + ds, expRotation(dw) * R, t + dt, left_rect, right_rect, res2, in_front);
      for (int i = 0; i < 16; ++i) J(i, j) = wp * (res2[i] - res[i]) / eps;
    }
    J(16, 6) = ws;
    cv::Matx<double, 7, 7> A = J.t() * J;
    for (int j = 0; j < 7; ++j) A(j, j) += 1e-9 + 1e-6 * A(j, j);
    if (!free_scale) A(6, 6) = 1.0;  // column 6 is zero: the scale stays at 1
    const cv::Matx<double, 7, 1> b = -(J.t() * r);
    cv::Matx<double, 7, 1> delta;
    if (!cv::solve(A, b, delta, cv::DECOMP_CHOLESKY)) return false;
    R = expRotation(cv::Vec3d(delta(0), delta(1), delta(2))) * R;
    t += cv::Vec3d(delta(3), delta(4), delta(5));
    scale += delta(6);
    if (!(scale > 0.5 && scale < 2.0)) return false;
    if (cv::norm(cv::Vec3d(delta(3), delta(4), delta(5))) < 1e-9 &&
        cv::norm(cv::Vec3d(delta(0), delta(1), delta(2))) < 1e-9 && std::abs(delta(6)) < 1e-9)
      break;
  }
  tagResiduals(rectifier, model, scale, R, t, left_rect, right_rect, res, in_front);
  double ss = 0.0;
  for (double v : res) ss += v * v;
  rms_px = std::sqrt(ss / 8.0);  // per corner observation (u and v together)
  if (!in_front || !std::isfinite(rms_px)) return false;
  centre_rect = t;
  zhat_rect = R * cv::Vec3d(0, 0, 1);
  return true;
}

double apparentSizeSigma(double edge_px) {
  const double L = std::max(edge_px, 1.0);
  return kApparentSizeBiasPx3 / (L * L * L);
}

double stereoSizeSigma(double edge_px, double disparity_px) {
  const double m = std::max(std::min(edge_px, disparity_px), 1.0);
  return kStereoSizeNoisePx2 / (m * m);
}

double computeConfidence(double decision_margin, double epipolar_px, double size_ratio, double edge_px,
                         double disparity_px) {
  const double m = std::clamp(decision_margin / kFullMargin, 0.0, 1.0);
  const double e = std::exp(-0.5 * epipolar_px * epipolar_px);
  const double tol = std::max(kMinSizeTolerance, kSizeToleranceSigmas * stereoSizeSigma(edge_px, disparity_px));
  const double s = std::exp(-0.5 * std::pow((size_ratio - 1.0) / tol, 2));
  return std::clamp(m * e * s, 0.0, 1.0);
}

StereoTagPipeline::StereoTagPipeline(const StereoCalibration& calib, const CameraMount& mount, const ObjectMap& objects,
                                     const PipelineOptions& options)
    : rectifier_(calib), mount_(mount), objects_(objects), options_(options) {
  if (objects_.family() != options_.detector.family)
    throw VisionError("object map family '" + objects_.family() + "' differs from the detector family '" +
                      options_.detector.family + "'");
  if (!(options_.max_epipolar_px > 0.0))
    throw VisionError("pipeline option max_epipolar_px = " + std::to_string(options_.max_epipolar_px) +
                      " must be positive");
  if (!(options_.max_size_deviation > 0.0))
    throw VisionError("pipeline option max_size_deviation = " + std::to_string(options_.max_size_deviation) +
                      " must be positive");
  for (auto& d : detector_) d = std::make_unique<TagDetector>(options_.detector);
  for (const ObjectSpec& o : objects_.objects())
    if (o.tag_id >= detector_[0]->family().codeCount())
      throw VisionError("object '" + o.name + "': tag id " + std::to_string(o.tag_id) + " is out of range for " +
                        options_.detector.family + " (0.." + std::to_string(detector_[0]->family().codeCount() - 1) +
                        ")");
}

StereoTagPipeline::~StereoTagPipeline() = default;

bool StereoTagPipeline::grayImages(const cv::Mat& left, const cv::Mat& right, StereoResult& out) {
  const cv::Size expected = rectifier_.calibration().left.image_size;
  const cv::Mat* in[2] = {&left, &right};
  for (int i = 0; i < 2; ++i) {
    const char* side = i == 0 ? "left" : "right";
    const cv::Mat& m = *in[i];
    if (m.empty()) {
      out.status = FrameStatus::kSkipped;
      out.message = std::string(side) + " image is empty";
      return false;
    }
    if (m.size() != expected) {
      out.status = FrameStatus::kSkipped;
      out.message = std::string(side) + " image is " + std::to_string(m.cols) + "x" + std::to_string(m.rows) +
                    " but the calibration says " + std::to_string(expected.width) + "x" +
                    std::to_string(expected.height);
      return false;
    }
    if (m.depth() != CV_8U || (m.channels() != 1 && m.channels() != 3 && m.channels() != 4)) {
      out.status = FrameStatus::kSkipped;
      out.message = std::string(side) + " image has unsupported type " + std::to_string(m.type());
      return false;
    }
    if (m.channels() == 1)
      gray_[i] = m;
    else
      cv::cvtColor(m, gray_[i], m.channels() == 3 ? cv::COLOR_BGR2GRAY : cv::COLOR_BGRA2GRAY);
  }

  return true;
}

void StereoTagPipeline::detectSide(int i, std::vector<TagDetection>& dets) {
  const bool right_side = i == 1;
  if (options_.rectify == RectifyMode::kImages) {
    rectifier_.rectifyImage(gray_[i], rect_[i], right_side);
    dets = detector_[i]->detect(rect_[i]);
    return;
  }
  dets = detector_[i]->detect(gray_[i]);
  std::vector<cv::Point2d> raw, rect;
  for (const TagDetection& d : dets) {
    raw.push_back(d.center);
    raw.insert(raw.end(), d.corners.begin(), d.corners.end());
  }
  rectifier_.rectifyPoints(raw, rect, right_side);
  for (std::size_t k = 0; k < dets.size(); ++k) {
    dets[k].center = rect[5 * k];
    for (std::size_t c = 0; c < 4; ++c) dets[k].corners[c] = rect[5 * k + 1 + c];
  }
}

bool StereoTagPipeline::observe(int id, const TagDetection& dl_ref, const TagDetection& dr, const ObjectSpec& spec_ref,
                                ObjectObservation& o) {
  const TagDetection* dl = &dl_ref;
  const ObjectSpec* spec = &spec_ref;
  const cv::Matx33d R_C_rect = rectifier_.calibration().left.R.t();
  std::array<cv::Vec3d, 4> c_rect;
  bool ok = true;
  double epi = 0.0, disparity = 0.0;
  for (std::size_t k = 0; k < 4; ++k) {
    ok = ok && rectifier_.triangulate(dl->corners[k], dr.corners[k], c_rect[k]);
    epi += std::abs(dl->corners[k].y - dr.corners[k].y) / 4.0;
    disparity += ((dl->corners[k].x - rectifier_.calibration().left.P(0, 2)) -
                  (dr.corners[k].x - rectifier_.calibration().right.P(0, 2))) /
                 4.0;
  }
  if (!ok || epi > options_.max_epipolar_px) {
    return false;
  }
  cv::Vec3d centre = 0.25 * (c_rect[0] + c_rect[1] + c_rect[2] + c_rect[3]);
  double edge = 0.0;
  for (std::size_t k = 0; k < 4; ++k) edge += cv::norm(c_rect[(k + 1) % 4] - c_rect[k]) / 4.0;
  const double ratio = edge / spec->tag_size;
  if (std::abs(ratio - 1.0) > options_.max_size_deviation) {
    return false;
  }
  cv::Vec3d n = (c_rect[2] - c_rect[0]).cross(c_rect[3] - c_rect[1]);
  n = n / std::max(cv::norm(n), 1e-12);
  double edge_px = 0.0;  // mean edge length over both rectified images
  for (std::size_t k = 0; k < 4; ++k)
    edge_px +=
        (cv::norm(dl->corners[(k + 1) % 4] - dl->corners[k]) + cv::norm(dr.corners[(k + 1) % 4] - dr.corners[k])) / 8.0;
  double rms = 0.0;
  if (options_.refine_with_tag_size) {
    cv::Vec3d fit_centre, fit_z;
    TagFitWeights weights;
    weights.size_sigma = apparentSizeSigma(edge_px);
    if (fitTagPoseStereo(rectifier_, dl->corners, dr.corners, c_rect, spec->tag_size, fit_centre, fit_z, rms,
                         weights)) {
      centre = fit_centre;
      n = fit_z;
    } else {
      rms = -1.0;
    }
  }
  if (rms <= 0.0) {  // stereo-only estimate: reprojection of the triangulated corners
    double ss = 0.0;
    for (std::size_t k = 0; k < 4; ++k) {
      const cv::Point2d el = rectifier_.projectRect(c_rect[k], false) - dl->corners[k];
      const cv::Point2d er = rectifier_.projectRect(c_rect[k], true) - dr.corners[k];
      ss += el.dot(el) + er.dot(er);
    }
    rms = std::sqrt(ss / 8.0);
  }
  if (n.dot(centre) > 0.0) n = -n;  // towards the camera

  o.tag_id = id;
  o.name = spec->name;
  o.p_C = R_C_rect * centre;
  o.p_B = mount_.toBase(o.p_C);
  o.nhat_C = R_C_rect * n;
  o.decision_margin = std::min(dl->decision_margin, dr.decision_margin);
  o.epipolar_px = epi;
  o.disparity_px = disparity;
  o.size_ratio = ratio;
  o.reprojection_px = rms;
  o.edge_px = edge_px;
  o.confidence = computeConfidence(o.decision_margin, epi, ratio, edge_px, disparity);
  return true;
}

void StereoTagPipeline::process(const cv::Mat& left, const cv::Mat& right, StereoResult& out) {
  out.status = FrameStatus::kOk;
  out.message.clear();
  out.objects.clear();
  out.left.clear();
  out.right.clear();
  out.unknown_tags = 0;
  out.rejected = 0;

  if (!grayImages(left, right, out)) return;

  if (options_.parallel) {
    auto right_job = std::async(std::launch::async, [&] { detectSide(1, out.right); });
    detectSide(0, out.left);
    right_job.get();
  } else {
    detectSide(0, out.left);
    detectSide(1, out.right);
  }

  int duplicates = 0;
  const std::map<int, const TagDetection*> L = uniqueById(out.left, duplicates);
  const std::map<int, const TagDetection*> R = uniqueById(out.right, duplicates);
  out.rejected += duplicates;

  for (const auto& [id, dl] : L) {
    const auto it = R.find(id);
    if (it == R.end()) continue;
    const TagDetection& dr = *it->second;
    const ObjectSpec* spec = objects_.find(id);
    if (spec == nullptr) {
      ++out.unknown_tags;
      continue;
    }
    ObjectObservation o;
    if (observe(id, *dl, dr, *spec, o))
      out.objects.push_back(o);
    else
      ++out.rejected;
  }
}

}  // namespace reflex::vision
