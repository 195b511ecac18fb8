// Closest points between sphere-swept lines (capsules; a sphere is a capsule of zero length).
// Header-only: these run for every checked primitive pair every 5 ms cycle.
// No allocation, no exceptions, no NaN for finite input.
#pragma once

#include <Eigen/Core>

#include <algorithm>

namespace reflex::control {

/// Core points below this separation count as coincident (the normal is then not defined by them).
inline constexpr double kCoincidentEps = 1e-12;

/// Closest points c1 on [a0, a1] and c2 on [b0, b1] (either segment may have zero length).
/// When the segments are parallel the closest pair is not unique; one valid pair is returned
/// (the one nearest the start of the first segment). s, t are the segment parameters in [0, 1].
inline void closestPointsSegmentSegment(const Eigen::Vector3d& a0, const Eigen::Vector3d& a1,
                                        const Eigen::Vector3d& b0, const Eigen::Vector3d& b1,
                                        Eigen::Vector3d& c1, Eigen::Vector3d& c2, double& s,
                                        double& t) {
  const Eigen::Vector3d d1 = a1 - a0;
  const Eigen::Vector3d d2 = b1 - b0;
  const Eigen::Vector3d r = a0 - b0;
  const double a = d1.squaredNorm();
  const double e = d2.squaredNorm();
  const double f = d2.dot(r);
  constexpr double kTiny = 1e-300;
  if (a <= kTiny && e <= kTiny) {
    s = 0.0;
    t = 0.0;
  } else if (a <= kTiny) {
    s = 0.0;
    t = std::clamp(f / e, 0.0, 1.0);
  } else {
    const double c = d1.dot(r);
    if (e <= kTiny) {
      t = 0.0;
      s = std::clamp(-c / a, 0.0, 1.0);
    } else {
      const double b = d1.dot(d2);
      const double denom = a * e - b * b;  // >= 0; ~0 when parallel
      s = denom > 1e-14 * a * e ? std::clamp((b * f - c * e) / denom, 0.0, 1.0) : 0.0;
      t = (b * s + f) / e;
      if (t < 0.0) {
        t = 0.0;
        s = std::clamp(-c / a, 0.0, 1.0);
      } else if (t > 1.0) {
        t = 1.0;
        s = std::clamp((b - c) / a, 0.0, 1.0);
      }
    }
  }
  c1 = a0 + s * d1;
  c2 = b0 + t * d2;
}

/// Surface-to-surface signed distance between capsule A (core [a0,a1], radius ra) and capsule B.
/// Outputs the witness points p_a (on A's surface), p_b (on B's surface) and the unit normal
/// nhat = (p_a - p_b) / d pointing from B towards A (d < 0 when they penetrate).
/// If the core points coincide, `fallback_n` (unit) is used as the normal and false is returned.
inline bool capsuleCapsuleDistance(const Eigen::Vector3d& a0, const Eigen::Vector3d& a1, double ra,
                                   const Eigen::Vector3d& b0, const Eigen::Vector3d& b1, double rb,
                                   const Eigen::Vector3d& fallback_n, double& d,
                                   Eigen::Vector3d& p_a, Eigen::Vector3d& p_b,
                                   Eigen::Vector3d& nhat) {
  Eigen::Vector3d c_a, c_b;
  double s, t;
  closestPointsSegmentSegment(a0, a1, b0, b1, c_a, c_b, s, t);
  const Eigen::Vector3d diff = c_a - c_b;
  const double core = diff.norm();
  const bool well_defined = core > kCoincidentEps;
  nhat = well_defined ? Eigen::Vector3d(diff / core) : fallback_n;
  d = core - ra - rb;
  p_a = c_a - ra * nhat;
  p_b = c_b + rb * nhat;
  return well_defined;
}

}  // namespace reflex::control
