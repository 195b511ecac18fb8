// Tests of control/include/reflex/control/geometry.hpp: closest points and surface distances of
// sphere-swept lines. Hand-computed cases for every primitive pair and every special case, then a
// randomized cross-check against FCL 0.7's analytic primitive algorithms.
#include "reflex/control/geometry.hpp"

#include "test_support.hpp"

#include <fcl/narrowphase/collision.h>
#include <fcl/narrowphase/distance.h>
#include <fcl/narrowphase/detail/primitive_shape_algorithm/capsule_capsule.h>
#include <gtest/gtest.h>

#include <Eigen/Geometry>

#include <cmath>
#include <memory>
#include <random>

namespace reflex::control {
namespace {

using Eigen::Vector3d;

struct Result {
  double d = 0.0;
  Vector3d p_a, p_b, n;
  bool well_defined = false;
};

Result query(const Vector3d& a0, const Vector3d& a1, double ra, const Vector3d& b0, const Vector3d& b1, double rb,
             const Vector3d& fallback = Vector3d::UnitZ()) {
  Result r;
  r.well_defined = capsuleCapsuleDistance(a0, a1, ra, b0, b1, rb, fallback, r.d, r.p_a, r.p_b, r.n);
  return r;
}

// The PairDistance invariants of distance.hpp, which hold for every result of capsuleCapsuleDistance:
// finite, |n| = 1, p_a - p_b = d n (also when penetrating and when the normal is the fallback).
void expectInvariants(const Result& r) {
  ASSERT_TRUE(std::isfinite(r.d));
  ASSERT_TRUE(r.p_a.allFinite() && r.p_b.allFinite() && r.n.allFinite());
  EXPECT_NEAR(r.n.norm(), 1.0, 1e-12);
  EXPECT_LT((r.p_a - r.p_b - r.d * r.n).norm(), 1e-12);
}

void expectVec(const Vector3d& actual, const Vector3d& expected, double tol = 1e-12) {
  EXPECT_LT((actual - expected).norm(), tol)
      << "actual " << actual.transpose() << ", expected " << expected.transpose();
}

// ---------------------------------------------------------------- sphere - sphere
TEST(GeometrySphereSphere, AxisAlignedSeparated) {
  const Result r = query({0, 0, 0}, {0, 0, 0}, 0.1, {1, 0, 0}, {1, 0, 0}, 0.2);
  expectInvariants(r);
  EXPECT_TRUE(r.well_defined);
  EXPECT_NEAR(r.d, 0.7, 1e-15);
  expectVec(r.p_a, {0.1, 0, 0});
  expectVec(r.p_b, {0.8, 0, 0});
  expectVec(r.n, {-1, 0, 0});  // from b towards a
}

TEST(GeometrySphereSphere, GeneralPosition345) {
  // Centres 5 apart along (3, 4, 0).
  const Result r = query({1, 2, 3}, {1, 2, 3}, 0.5, {4, 6, 3}, {4, 6, 3}, 1.0);
  expectInvariants(r);
  EXPECT_NEAR(r.d, 3.5, 1e-14);
  expectVec(r.p_a, {1.3, 2.4, 3});
  expectVec(r.p_b, {3.4, 5.2, 3});
  expectVec(r.n, {-0.6, -0.8, 0});
}

TEST(GeometrySphereSphere, Penetrating) {
  const Result r = query({0, 0, 0}, {0, 0, 0}, 0.5, {0.6, 0, 0}, {0.6, 0, 0}, 0.3);
  expectInvariants(r);
  EXPECT_TRUE(r.well_defined);
  EXPECT_NEAR(r.d, -0.2, 1e-15);
  expectVec(r.n, {-1, 0, 0});
  expectVec(r.p_a, {0.5, 0, 0});  // deepest point of a inside b
  expectVec(r.p_b, {0.3, 0, 0});
}

TEST(GeometrySphereSphere, ConcentricUsesFallbackAndFlag) {
  const Vector3d fallback = Vector3d(1, 1, 0).normalized();
  const Result r = query({1, 1, 1}, {1, 1, 1}, 0.2, {1, 1, 1}, {1, 1, 1}, 0.3, fallback);
  expectInvariants(r);
  EXPECT_FALSE(r.well_defined);
  EXPECT_NEAR(r.d, -0.5, 1e-15);
  expectVec(r.n, fallback);
  expectVec(r.p_a, Vector3d(1, 1, 1) - 0.2 * fallback);
  expectVec(r.p_b, Vector3d(1, 1, 1) + 0.3 * fallback);
}

// ---------------------------------------------------------------- sphere - capsule
TEST(GeometrySphereCapsule, BesideTheCore) {
  // Sphere above the middle of a capsule along x: closest core point (0.5, 0, 0).
  const Result r = query({0.5, 1, 0}, {0.5, 1, 0}, 0.1, {0, 0, 0}, {1, 0, 0}, 0.2);
  expectInvariants(r);
  EXPECT_NEAR(r.d, 0.7, 1e-15);
  expectVec(r.n, {0, 1, 0});
  expectVec(r.p_a, {0.5, 0.9, 0});
  expectVec(r.p_b, {0.5, 0.2, 0});
}

TEST(GeometrySphereCapsule, CapsuleFirstGivesMirroredResult) {
  const Result r = query({0, 0, 0}, {1, 0, 0}, 0.2, {0.5, 1, 0}, {0.5, 1, 0}, 0.1);
  expectInvariants(r);
  EXPECT_NEAR(r.d, 0.7, 1e-15);
  expectVec(r.n, {0, -1, 0});
  expectVec(r.p_a, {0.5, 0.2, 0});
  expectVec(r.p_b, {0.5, 0.9, 0});
}

TEST(GeometrySphereCapsule, BeyondTheEndCap) {
  // Closest core point is the end (1, 0, 0); the centre is sqrt(2) away diagonally.
  const Result r = query({2, 1, 0}, {2, 1, 0}, 0.1, {0, 0, 0}, {1, 0, 0}, 0.2);
  expectInvariants(r);
  const Vector3d u = Vector3d(1, 1, 0).normalized();
  EXPECT_NEAR(r.d, std::sqrt(2.0) - 0.3, 1e-15);
  expectVec(r.n, u);
  expectVec(r.p_a, Vector3d(2, 1, 0) - 0.1 * u);
  expectVec(r.p_b, Vector3d(1, 0, 0) + 0.2 * u);
}

TEST(GeometrySphereCapsule, BeforeTheStartCapOnTheAxis) {
  const Result r = query({-1, 0, 0}, {-1, 0, 0}, 0.25, {0, 0, 0}, {1, 0, 0}, 0.25);
  expectInvariants(r);
  EXPECT_NEAR(r.d, 0.5, 1e-15);
  expectVec(r.p_a, {-0.75, 0, 0});
  expectVec(r.p_b, {-0.25, 0, 0});
}

TEST(GeometrySphereCapsule, Penetrating) {
  const Result r = query({0.3, 0.1, 0}, {0.3, 0.1, 0}, 0.1, {0, 0, 0}, {1, 0, 0}, 0.2);
  expectInvariants(r);
  EXPECT_TRUE(r.well_defined);
  EXPECT_NEAR(r.d, -0.2, 1e-15);
  expectVec(r.n, {0, 1, 0});
  expectVec(r.p_a, {0.3, 0.0, 0});
  expectVec(r.p_b, {0.3, 0.2, 0});
}

TEST(GeometrySphereCapsule, CentreOnTheCoreIsCoincident) {
  const Result r = query({0.4, 0, 0}, {0.4, 0, 0}, 0.1, {0, 0, 0}, {1, 0, 0}, 0.2, {0, 0, -1});
  expectInvariants(r);
  EXPECT_FALSE(r.well_defined);
  EXPECT_NEAR(r.d, -0.3, 1e-15);
  expectVec(r.n, {0, 0, -1});
}

// ---------------------------------------------------------------- capsule - capsule
TEST(GeometryCapsuleCapsule, CrossingAtRightAngles) {
  const Result r = query({-1, 0, 0}, {1, 0, 0}, 0.1, {0, -1, 1}, {0, 1, 1}, 0.2);
  expectInvariants(r);
  EXPECT_NEAR(r.d, 0.7, 1e-15);
  expectVec(r.n, {0, 0, -1});
  expectVec(r.p_a, {0, 0, 0.1});
  expectVec(r.p_b, {0, 0, 0.8});
}

TEST(GeometryCapsuleCapsule, CrossingDiagonals) {
  // Diagonals of the unit square at heights 0 and 1 cross over (1, 1).
  const Result r = query({0, 0, 0}, {2, 2, 0}, 0.25, {2, 0, 1}, {0, 2, 1}, 0.25);
  expectInvariants(r);
  EXPECT_NEAR(r.d, 0.5, 1e-15);
  expectVec(r.p_a, {1, 1, 0.25});
  expectVec(r.p_b, {1, 1, 0.75});
}

TEST(GeometryCapsuleCapsule, SegmentParameters) {
  Vector3d c1, c2;
  double s = -1, t = -1;
  closestPointsSegmentSegment({0, 0, 0}, {4, 0, 0}, {1, -1, 2}, {1, 3, 2}, c1, c2, s, t);
  EXPECT_NEAR(s, 0.25, 1e-15);
  EXPECT_NEAR(t, 0.25, 1e-15);
  expectVec(c1, {1, 0, 0});
  expectVec(c2, {1, 0, 2});
}

TEST(GeometryCapsuleCapsule, LinesCrossOutsideOneSegment) {
  // The lines meet at (2, 0, 0), beyond a's end: a's end is closest, and b's foot of it.
  const Result r = query({0, 0, 0}, {1, 0, 0}, 0.1, {2, -1, 0}, {2, 1, 0}, 0.1);
  expectInvariants(r);
  EXPECT_NEAR(r.d, 0.8, 1e-15);
  expectVec(r.p_a, {1.1, 0, 0});
  expectVec(r.p_b, {1.9, 0, 0});
}

TEST(GeometryCapsuleCapsule, EndToEndSkew) {
  const Result r = query({0, 0, 0}, {1, 0, 0}, 0.1, {2, 1, 0}, {2, 3, 0}, 0.1);
  expectInvariants(r);
  const Vector3d u = Vector3d(-1, -1, 0).normalized();  // from b's start towards a's end
  EXPECT_NEAR(r.d, std::sqrt(2.0) - 0.2, 1e-15);
  expectVec(r.n, u);
  expectVec(r.p_a, Vector3d(1, 0, 0) - 0.1 * u);
  expectVec(r.p_b, Vector3d(2, 1, 0) + 0.1 * u);
}

TEST(GeometryCapsuleCapsule, CollinearEndToEnd) {
  // Same line, gap of 1 between a's end and b's (reversed) end.
  const Result r = query({0, 0, 0}, {1, 0, 0}, 0.2, {3, 0, 0}, {2, 0, 0}, 0.3);
  expectInvariants(r);
  EXPECT_TRUE(r.well_defined);
  EXPECT_NEAR(r.d, 0.5, 1e-15);
  expectVec(r.n, {-1, 0, 0});
  expectVec(r.p_a, {1.2, 0, 0});
  expectVec(r.p_b, {1.7, 0, 0});
}

TEST(GeometryCapsuleCapsule, CollinearOverlappingIsCoincident) {
  const Vector3d fallback(0, 1, 0);
  const Result r = query({0, 0, 0}, {2, 0, 0}, 0.2, {1, 0, 0}, {3, 0, 0}, 0.3, fallback);
  expectInvariants(r);
  EXPECT_FALSE(r.well_defined);
  EXPECT_NEAR(r.d, -0.5, 1e-15);
  expectVec(r.n, fallback);
}

TEST(GeometryCapsuleCapsule, ParallelOverlapping) {
  // Not unique: any x in [1, 2] is a closest pair; the distance and the normal are unique.
  const Result r = query({0, 0, 0}, {2, 0, 0}, 0.1, {1, 1, 0}, {3, 1, 0}, 0.2);
  expectInvariants(r);
  EXPECT_NEAR(r.d, 0.7, 1e-15);
  expectVec(r.n, {0, -1, 0});
  EXPECT_GE(r.p_a.x(), 1.0 - 1e-15);
  EXPECT_LE(r.p_a.x(), 2.0 + 1e-15);
  EXPECT_NEAR(r.p_b.x(), r.p_a.x(), 1e-15);
  EXPECT_NEAR(r.p_a.y(), 0.1, 1e-15);
  EXPECT_NEAR(r.p_b.y(), 0.8, 1e-15);
}

TEST(GeometryCapsuleCapsule, AntiParallelOverlapping) {
  const Result r = query({0, 0, 0}, {2, 0, 0}, 0.1, {3, 0, 1}, {1, 0, 1}, 0.1);
  expectInvariants(r);
  EXPECT_NEAR(r.d, 0.8, 1e-15);
  expectVec(r.n, {0, 0, -1});
  EXPECT_GE(r.p_a.x(), 1.0 - 1e-15);
  EXPECT_LE(r.p_a.x(), 2.0 + 1e-15);
  EXPECT_NEAR(r.p_b.x(), r.p_a.x(), 1e-15);
}

TEST(GeometryCapsuleCapsule, ParallelDisjoint) {
  // Parallel but not overlapping along the axis: the closest pair is unique (ends).
  for (const bool reversed : {false, true}) {
    const Vector3d b0 = reversed ? Vector3d(3, 1, 0) : Vector3d(2, 1, 0);
    const Vector3d b1 = reversed ? Vector3d(2, 1, 0) : Vector3d(3, 1, 0);
    const Result r = query({0, 0, 0}, {1, 0, 0}, 0.1, b0, b1, 0.1);
    expectInvariants(r);
    const Vector3d u = Vector3d(-1, -1, 0).normalized();
    EXPECT_NEAR(r.d, std::sqrt(2.0) - 0.2, 1e-15);
    expectVec(r.p_a, Vector3d(1, 0, 0) - 0.1 * u);
    expectVec(r.p_b, Vector3d(2, 1, 0) + 0.1 * u);
  }
}

TEST(GeometryCapsuleCapsule, PenetratingCrossing) {
  const Result r = query({-1, 0, 0}, {1, 0, 0}, 0.3, {0, -1, 0.2}, {0, 1, 0.2}, 0.3);
  expectInvariants(r);
  EXPECT_TRUE(r.well_defined);
  EXPECT_NEAR(r.d, -0.4, 1e-15);
  expectVec(r.n, {0, 0, -1});
  expectVec(r.p_a, {0, 0, 0.3});
  expectVec(r.p_b, {0, 0, -0.1});
}

TEST(GeometryCapsuleCapsule, IntersectingCoresAreCoincident) {
  const Vector3d fallback = Vector3d(1, 2, 2) / 3.0;
  const Result r = query({-1, 0, 0}, {1, 0, 0}, 0.1, {0, -1, 0}, {0, 1, 0}, 0.2, fallback);
  expectInvariants(r);
  EXPECT_FALSE(r.well_defined);
  EXPECT_NEAR(r.d, -0.3, 1e-15);
  expectVec(r.n, fallback);
  expectVec(r.p_a, -0.1 * fallback);
  expectVec(r.p_b, 0.2 * fallback);
}

TEST(GeometryCapsuleCapsule, DegenerateZeroLengthIsASphere) {
  // A zero-length capsule against a capsule equals the sphere case; both zero equals sphere-sphere.
  const Result a = query({0.5, 1, 0}, {0.5, 1, 0}, 0.1, {0, 0, 0}, {1, 0, 0}, 0.2);
  EXPECT_NEAR(a.d, 0.7, 1e-15);
  const Result b = query({0, 0, 0}, {1, 0, 0}, 0.2, {1, 0, 0}, {1, 0, 0}, 0.1);  // on the end
  expectInvariants(b);
  EXPECT_FALSE(b.well_defined);
  // Nearly zero length (1e-200): finite and equal to the sphere answer.
  const Result c = query({0.5, 1, 0}, {0.5, 1, 1e-200}, 0.1, {0, 0, 0}, {1, 0, 0}, 0.2);
  expectInvariants(c);
  EXPECT_NEAR(c.d, 0.7, 1e-15);
  expectVec(c.p_b, {0.5, 0.2, 0});
}

TEST(GeometryCapsuleCapsule, NearlyParallelStaysFinite) {
  // Parallel up to 1e-17 rad: the parallel branch; distance still right and everything finite.
  const Result r = query({0, 0, 0}, {2, 0, 0}, 0.1, {1, 1, 0}, {3, 1 + 2e-17, 0}, 0.1);
  expectInvariants(r);
  EXPECT_NEAR(r.d, 0.8, 1e-12);
}

// ---------------------------------------------------------------- FCL 0.7 cross-check
//
// FCL facts this relies on, checked here or in the FCL 0.7 sources (fcl/narrowphase/detail/
// gjk_solver_libccd-inl.h): with the default solver (GST_LIBCCD) fcl::distance dispatches
// sphere-sphere, sphere-capsule and capsule-capsule to the analytic functions in
// primitive_shape_algorithm/ (sphereSphereDistance, sphereCapsuleDistance, capsuleCapsuleDistance),
// not to GJK; the sphere functions report -1 (no points) for touching or penetrating shapes, so
// penetration of those is checked through fcl::collide's analytic contact depth instead. The
// GST_INDEP solver has the same analytic specializations (gjk_solver_indep-inl.h); both are used.
// A Capsule is centred on its frame origin, along its local z, with lz = core length.

std::shared_ptr<fcl::CollisionGeometryd> fclShape(const Vector3d& a, const Vector3d& b, double r,
                                                  fcl::Transform3d& X_B_S) {
  X_B_S.setIdentity();
  X_B_S.translation() = 0.5 * (a + b);
  const double length = (b - a).norm();
  if (length == 0.0) return std::make_shared<fcl::Sphered>(r);
  X_B_S.linear() = Eigen::Quaterniond::FromTwoVectors(Vector3d::UnitZ(), b - a).toRotationMatrix();
  return std::make_shared<fcl::Capsuled>(r, length);
}

TEST(GeometryFcl, NearestPointsAreInTheWorldFrame) {
  // FCL 0.6 returned GJK nearest points in object frames; 0.7 returns them in the world frame.
  // Checked on a case with rotated, translated frames so that the conventions differ.
  fcl::Transform3d X1, X2;
  const auto s = fclShape({5, 5, 5}, {5, 5, 5}, 0.5, X1);
  const auto c = fclShape({5, 7, 4}, {5, 7, 6}, 0.5, X2);  // vertical capsule, 2 m away in y
  X1.linear() = Eigen::AngleAxisd(1.0, Vector3d(1, 2, 3).normalized()).toRotationMatrix();
  for (const fcl::GJKSolverType solver : {fcl::GST_LIBCCD, fcl::GST_INDEP}) {
    fcl::DistanceRequestd request;
    request.enable_nearest_points = true;
    request.gjk_solver_type = solver;
    fcl::DistanceResultd result;
    fcl::distance(s.get(), X1, c.get(), X2, request, result);
    EXPECT_NEAR(result.min_distance, 1.0, 1e-12);
    expectVec(result.nearest_points[0], {5, 5.5, 5});
    expectVec(result.nearest_points[1], {5, 6.5, 5});
  }
}

struct Counts {
  int distance_compared = 0;
  int points_compared = 0;
  int penetrating_compared = 0;
};

TEST(GeometryFcl, RandomPairsAgreeWithFcl) {
  std::mt19937_64 rng(20240611);
  std::uniform_real_distribution<double> uniform(0.0, 1.0);
  double max_d_err = 0.0, max_p_err = 0.0, max_pen_err = 0.0;
  Counts n;
  constexpr int kPairs = 14000;
  for (int i = 0; i < kPairs; ++i) {
    // Kinds: 0 sphere-sphere, 1 sphere-capsule, 2 capsule-sphere, 3..5 capsule-capsule,
    // 6 (near-)parallel capsules, 7 collinear capsules.
    const int kind = static_cast<int>(uniform(rng) * 8.0);
    const bool a_sphere = kind == 0 || kind == 1;
    const bool b_sphere = kind == 0 || kind == 2;
    const Vector3d ca = test::randomPoint(rng, 0.5);
    const Vector3d cb = test::randomPoint(rng, 0.5);
    Vector3d ua = test::randomUnit(rng);
    Vector3d ub = test::randomUnit(rng);
    if (kind == 6) {
      const double tilt = uniform(rng) < 0.5 ? 0.0 : 1e-9 * uniform(rng);
      ub = (ua + tilt * test::randomUnit(rng)).normalized();
      if (uniform(rng) < 0.5) ub = -ub;
    }
    const double la = a_sphere ? 0.0 : 0.01 + 0.5 * uniform(rng);
    const double lb = b_sphere ? 0.0 : 0.01 + 0.5 * uniform(rng);
    const double ra = 0.01 + 0.14 * uniform(rng);
    const double rb = 0.01 + 0.14 * uniform(rng);
    const Vector3d a0 = ca - 0.5 * la * ua, a1 = ca + 0.5 * la * ua;
    Vector3d b0 = cb - 0.5 * lb * ub, b1 = cb + 0.5 * lb * ub;
    if (kind == 7) {  // on a's line, somewhere along it
      const double shift = -1.0 + 2.0 * uniform(rng);
      b0 = ca + (shift - 0.5 * lb) * ua;
      b1 = ca + (shift + 0.5 * lb) * ua;
      ub = ua;
    }
    const Result r = query(a0, a1, ra, b0, b1, rb);
    expectInvariants(r);

    fcl::Transform3d Xa, Xb;
    const auto ga = fclShape(a0, a1, ra, Xa);
    const auto gb = fclShape(b0, b1, rb, Xb);
    const double core = r.d + ra + rb;
    if (core < 1e-9) continue;  // coincident cores: FCL and Reflex pick different arbitrary normals
    // Unique closest points unless both are capsules whose axes are (nearly) parallel.
    const bool unique = a_sphere || b_sphere || ua.cross(ub).norm() > 1e-3;

    if (r.d > 1e-12) {
      fcl::DistanceRequestd request;
      request.enable_nearest_points = true;
      // Both narrow-phase solvers dispatch these shapes to the same analytic functions; use both.
      request.gjk_solver_type = (i % 2) ? fcl::GST_INDEP : fcl::GST_LIBCCD;
      fcl::DistanceResultd result;
      fcl::distance(ga.get(), Xa, gb.get(), Xb, request, result);
      const double e = std::abs(result.min_distance - r.d);
      max_d_err = std::max(max_d_err, e);
      ASSERT_LT(e, 1e-9) << "pair " << i << " kind " << kind;
      ++n.distance_compared;
      if (unique) {
        const double ep =
            std::max((result.nearest_points[0] - r.p_a).norm(), (result.nearest_points[1] - r.p_b).norm());
        max_p_err = std::max(max_p_err, ep);
        ASSERT_LT(ep, 1e-9) << "pair " << i << " kind " << kind;
        ++n.points_compared;
      }
    } else if (r.d < -1e-12) {
      if (!a_sphere && !b_sphere) {
        // capsuleCapsuleDistance is signed and returns witness points when penetrating too.
        double d = 0.0;
        Vector3d pa, pb;
        fcl::detail::capsuleCapsuleDistance(static_cast<const fcl::Capsuled&>(*ga), Xa,
                                            static_cast<const fcl::Capsuled&>(*gb), Xb, &d, &pa, &pb);
        const double e = std::abs(d - r.d);
        max_pen_err = std::max(max_pen_err, e);
        ASSERT_LT(e, 1e-9) << "pair " << i;
        if (unique) {
          const double ep = std::max((pa - r.p_a).norm(), (pb - r.p_b).norm());
          max_p_err = std::max(max_p_err, ep);
          ASSERT_LT(ep, 1e-9) << "pair " << i;
        }
      } else {
        // Analytic sphere contacts: penetration depth = -d.
        fcl::CollisionRequestd request(1, true);
        fcl::CollisionResultd result;
        fcl::collide(ga.get(), Xa, gb.get(), Xb, request, result);
        ASSERT_TRUE(result.isCollision()) << "pair " << i;
        const double e = std::abs(result.getContact(0).penetration_depth + r.d);
        max_pen_err = std::max(max_pen_err, e);
        ASSERT_LT(e, 1e-9) << "pair " << i;
      }
      ++n.penetrating_compared;
    }
  }
  EXPECT_GE(n.distance_compared, 10000);
  EXPECT_GE(n.points_compared, 8000);
  EXPECT_GE(n.penetrating_compared, 100);
  std::printf(
      "FCL cross-check: %d distances (max error %.3g m), %d witness pairs (max error %.3g m), "
      "%d penetrating (max error %.3g m)\n",
      n.distance_compared, max_d_err, n.points_compared, max_p_err, n.penetrating_compared, max_pen_err);
}

}  // namespace
}  // namespace reflex::control
