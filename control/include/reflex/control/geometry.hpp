// Closest points between sphere-swept lines (capsules; a sphere is a capsule of zero length).
// Header-only: these run for every checked primitive pair every 5 ms cycle.
// No allocation, no exceptions, no NaN for finite input.
#pragma once

#include <Eigen/Core>

#include <algorithm>

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

namespace reflex::control {

/// Core points below this separation count as coincident (the normal is then not defined by them).
inline constexpr double kCoincidentEps = 1e-12;

/// Below this squared length a segment counts as a point.
inline constexpr double kPointSegmentSq = 1e-300;

/// The per-segment quantities closestPointsSegmentSegment needs: direction d = end - start, its
/// squared length dd and 1/dd (0 for a point). Computed once per primitive per cycle when one
/// primitive takes part in several pairs.
struct SegmentB {
  Eigen::Vector3d start = Eigen::Vector3d::Zero();
  Eigen::Vector3d d = Eigen::Vector3d::Zero();
  double dd = 0.0;
  double inv_dd = 0.0;

  SegmentB() = default;
  SegmentB(const Eigen::Vector3d& p0, const Eigen::Vector3d& p1) { set(p0, p1); }
  void set(const Eigen::Vector3d& p0, const Eigen::Vector3d& p1) {
    start = p0;
    d = p1 - p0;
    dd = d.squaredNorm();
    inv_dd = dd > kPointSegmentSq ? 1.0 / dd : 0.0;
  }
};

/// x clamped to [0, 1], written so that it compiles to maxsd / minsd instead of branches (the
/// clamping outcome is data-dependent and mispredicts); NaN gives 0.
inline double clamp01(double x) {
#if defined(__SSE2__)
  // maxsd returns its second operand when either is NaN: max(x, 0) with x NaN gives 0.
  const __m128d v = _mm_min_sd(_mm_max_sd(_mm_set_sd(x), _mm_set_sd(0.0)), _mm_set_sd(1.0));
  return _mm_cvtsd_f64(v);
#else
  x = x > 0.0 ? x : 0.0;
  return x < 1.0 ? x : 1.0;
#endif
}

/// Segment parameters s, t in [0, 1] of the closest points A.start + s A.d and B.start + t B.d
/// (either segment may have zero length). When the segments are parallel the closest pair is not
/// unique; one valid pair is returned. At most one division and no data-dependent branch but the
/// parallel test: s on the line-line optimum (clamped), then t = the clamped foot of A(s) on B, then
/// s = the clamped foot of B(t) on A (Ericson, Real-Time Collision Detection, 5.1.9; the last step
/// is the identity when t was not clamped, so it is done unconditionally).
inline void closestParametersSegmentSegment(const SegmentB& A, const SegmentB& B, double& s, double& t) {
  // Written on scalars: Eigen's 2-wide SSE packets only add shuffles for 3-vectors here.
  const double rx = A.start.x() - B.start.x(), ry = A.start.y() - B.start.y(), rz = A.start.z() - B.start.z();
  const double f = B.d.x() * rx + B.d.y() * ry + B.d.z() * rz;
  const double c = A.d.x() * rx + A.d.y() * ry + A.d.z() * rz;
  const double b = A.d.x() * B.d.x() + A.d.y() * B.d.y() + A.d.z() * B.d.z();
  const double ae = A.dd * B.dd;
  const double denom = ae - b * b;  // >= 0; ~0 when parallel (or when either is a point)
  const double s_line = denom > 1e-14 * ae && denom > 0.0 ? (b * f - c * B.dd) / denom : 0.0;
  const double s0 = clamp01(s_line);
  const double t1 = clamp01((b * s0 + f) * B.inv_dd);
  t = t1;
  s = clamp01((b * t1 - c) * A.inv_dd);
}

/// Closest points c1 on [a0, a1] and c2 on [b0, b1] (either segment may have zero length).
/// When the segments are parallel the closest pair is not unique; one valid pair is returned
/// (see closestParametersSegmentSegment). s, t are the segment parameters in [0, 1].
inline void closestPointsSegmentSegment(const Eigen::Vector3d& a0, const Eigen::Vector3d& a1, const Eigen::Vector3d& b0,
                                        const Eigen::Vector3d& b1, Eigen::Vector3d& c1, Eigen::Vector3d& c2, double& s,
                                        double& t) {
  const SegmentB A(a0, a1), B(b0, b1);
  closestParametersSegmentSegment(A, B, s, t);
  c1 = A.start + s * A.d;
  c2 = B.start + t * B.d;
}

/// Surface-to-surface signed distance between capsule A (core [a0,a1], radius ra) and capsule B.
/// Outputs the witness points p_a (on A's surface), p_b (on B's surface) and the unit normal
/// nhat = (p_a - p_b) / d pointing from B towards A (d < 0 when they penetrate).
/// If the core points coincide, `fallback_n` (unit) is used as the normal and false is returned.
inline bool capsuleCapsuleDistance(const Eigen::Vector3d& a0, const Eigen::Vector3d& a1, double ra,
                                   const Eigen::Vector3d& b0, const Eigen::Vector3d& b1, double rb,
                                   const Eigen::Vector3d& fallback_n, double& d, Eigen::Vector3d& p_a,
                                   Eigen::Vector3d& p_b, Eigen::Vector3d& nhat) {
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
