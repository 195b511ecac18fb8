// The camera in the head frame from tag points seen by the camera and known from the kinematics
// (reflex_calibrate mount). See stereo_calibrate.hpp.
#include "reflex/vision/error.hpp"
#include "reflex/vision/stereo_calibrate.hpp"
#include "yaml_util.hpp"

#include <algorithm>
#include <cmath>

namespace reflex::vision {
namespace {
using detail::fmt;

struct RigidFit {
  cv::Matx33d R;
  cv::Vec3d t;
  double spread = 0.0;  ///< RMS spread of the camera points along their second principal direction
};

// Least-squares rigid transform with R a rotation: p_H ~ R p_C + t (Kabsch: SVD of the cross covariance).
RigidFit fitRigid(const std::vector<MountObservation>& obs, const std::vector<std::size_t>& use) {
  cv::Vec3d c_C(0, 0, 0), c_H(0, 0, 0);
  for (std::size_t i : use) {
    c_C += obs[i].p_C;
    c_H += obs[i].p_H;
  }
  const double n = static_cast<double>(use.size());
  c_C *= 1.0 / n;
  c_H *= 1.0 / n;
  cv::Matx33d cross = cv::Matx33d::zeros(), cov = cv::Matx33d::zeros();
  for (std::size_t i : use) {
    const cv::Vec3d a = obs[i].p_C - c_C, b = obs[i].p_H - c_H;
    cross += a * b.t();
    cov += a * a.t();
  }
  RigidFit f;
  cv::Matx31d spread_w;
  cv::Matx33d spread_u, spread_vt;
  cv::SVD::compute(cov * (1.0 / n), spread_w, spread_u, spread_vt);
  f.spread = std::sqrt(std::max(0.0, spread_w(1)));  // singular values descending
  cv::Matx31d w;
  cv::Matx33d u, vt;
  cv::SVD::compute(cross, w, u, vt);
  const cv::Matx33d v = vt.t();
  const double d = cv::determinant(v * u.t()) < 0.0 ? -1.0 : 1.0;
  f.R = v * cv::Matx33d(1, 0, 0, 0, 1, 0, 0, 0, d) * u.t();
  f.t = c_H - f.R * c_C;
  return f;
}

double median(std::vector<double> v) {
  const std::size_t mid = v.size() / 2;
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(mid), v.end());
  return v[mid];
}

}  // namespace

MountResult estimateCameraInHead(const std::vector<MountObservation>& obs, const MountOptions& o,
                                 const CalibrateLog& log) {
  if (!(o.outlier_factor > 1.0))
    throw VisionError("outlier factor = " + fmt(o.outlier_factor) + " must be greater than 1");
  if (o.min_views < 3) throw VisionError("min views = " + std::to_string(o.min_views) + " must be at least 3");
  MountResult res;
  std::vector<std::size_t> kept;
  for (std::size_t i = 0; i < obs.size(); ++i) {
    for (int k = 0; k < 3; ++k)
      if (!std::isfinite(obs[i].p_C[k]) || !std::isfinite(obs[i].p_H[k]))
        throw VisionError("view " + obs[i].name + ": a coordinate is not finite");
    MountViewReport v;
    v.name = obs[i].name;
    if (!(obs[i].p_C[2] > 0.0)) {
      v.dropped = true;
      v.why = "z_cam = " + fmt(obs[i].p_C[2]) + " m: not in front of the camera";
    } else {
      kept.push_back(i);
    }
    res.views.push_back(v);
  }
  for (;;) {
    if (static_cast<int>(kept.size()) < o.min_views)
      throw VisionError("too few usable views: " + std::to_string(kept.size()) + " of " + std::to_string(obs.size()) +
                        " (at least " + std::to_string(o.min_views) + ")");
    ++res.rounds;
    const RigidFit f = fitRigid(obs, kept);
    if (f.spread < o.min_spread_m)
      throw VisionError("the tag points spread only " + fmt(1000.0 * f.spread) +
                        " mm across their main line (at least " + fmt(1000.0 * o.min_spread_m) +
                        " mm): move the hand to places that are not on one line (up/down and left/right)");
    res.R_H_C = f.R;
    res.p_H_C = f.t;
    std::vector<double> r(kept.size());
    for (std::size_t j = 0; j < kept.size(); ++j) {
      const MountObservation& m = obs[kept[j]];
      r[j] = cv::norm(f.R * m.p_C + f.t - m.p_H);
      res.views[kept[j]].residual = r[j];
    }
    const double med = median(r);
    const double limit = std::max(o.outlier_factor * med, o.min_outlier_m);
    if (log)
      log("round " + std::to_string(res.rounds) + ": " + std::to_string(kept.size()) + " views, median residual " +
          cv::format("%.2f", 1000.0 * med) + " mm, outlier above " + cv::format("%.2f", 1000.0 * limit) + " mm");
    std::vector<std::size_t> next;
    for (std::size_t j = 0; j < kept.size(); ++j) {
      if (r[j] > limit) {
        MountViewReport& v = res.views[kept[j]];
        v.dropped = true;
        v.why = "outlier in round " + std::to_string(res.rounds) + ": residual " + cv::format("%.2f", 1000.0 * r[j]) +
                " mm > " + fmt(o.outlier_factor) + " x median " + cv::format("%.2f", 1000.0 * med) + " mm";
        if (log) log("dropped " + v.name + ": " + v.why);
      } else {
        next.push_back(kept[j]);
      }
    }
    if (next.size() == kept.size()) break;
    kept = next;
  }
  double ss = 0.0;
  for (std::size_t k : kept) {
    ss += res.views[k].residual * res.views[k].residual;
    res.max = std::max(res.max, res.views[k].residual);
  }
  res.rms = std::sqrt(ss / static_cast<double>(kept.size()));
  return res;
}

}  // namespace reflex::vision
