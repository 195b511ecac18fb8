// Tests of control/include/reflex/control/convex.hpp: makeConvexPiece, supportVertex and
// computeConvexDistance (GJK). Checked against independent answers:
//   - hand-computed distances and witness points of cubes (face-face, edge-edge, vertex-vertex,
//     touching, overlapping, rotated), of a point, a segment and a flat square against a cube;
//   - a brute force on random convex pieces (hulls built here with qhull): the exact distance is the
//     minimum over all pairs of hull triangles of FCL's triangle-triangle distance (PQP's TriDist),
//     0 when the surfaces cross or one piece holds a vertex of the other; |GJK - brute| <= 1e-7,
//     the witness points inside their hulls (the hull's facet planes, 1e-7) and |p_a - p_b| = d;
//   - FCL's own convex-convex distance (fcl::Convex, fcl::distance, libccd GJK) on the same pieces,
//     a second library, within 1e-5 (libccd's GJK stops at a looser tolerance);
//   - supportVertex's hill-climbing against a linear scan of the vertices (same maximal dot product);
//     a warm start against a cold start; the distance's invariance under a rigid motion of both;
//   - no operator new over thousands of queries (support/count_allocations.hpp);
//   - degenerate pieces (flat, a segment, a point, collinear points, identical pieces, coordinates
//     from 1e-6 m to 1e6 m): finite answers, no NaN, and the hand-computed value where there is one.
#include "reflex/control/convex.hpp"

#include "support/count_allocations.hpp"

#include <fcl/geometry/shape/convex.h>
#include <fcl/narrowphase/detail/primitive_shape_algorithm/triangle_distance.h>
#include <fcl/narrowphase/distance.h>
#include <gtest/gtest.h>
#include <libqhull_r/qhull_ra.h>

#include <Eigen/Geometry>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <limits>
#include <memory>
#include <random>
#include <stdexcept>
#include <vector>

namespace reflex::control {
namespace {

using Vec3 = Eigen::Vector3d;

// ------------------------------------------------------------------ test geometry

/// A convex hull: its vertices, outward triangles (indices into vertices) and facet planes
/// (unit normal n, offset c: n . x + c <= 0 inside).
struct Hull {
  std::vector<Vec3> vertices;
  std::vector<std::array<int, 3>> triangles;
  std::vector<Eigen::Vector4d> planes;
};

/// The convex hull of `pts` (at least 4 points, not coplanar) with qhull, triangulated ("Qt").
Hull qhullHull(const std::vector<Vec3>& pts) {
  std::vector<coordT> coords(3 * pts.size());
  for (std::size_t i = 0; i < pts.size(); ++i)
    for (int k = 0; k < 3; ++k) coords[3 * i + k] = pts[i][k];
  qhT qh_qh;
  qhT* qh = &qh_qh;
  FILE* devnull = std::fopen("/dev/null", "w");
  qh_zero(qh, devnull);
  char options[] = "qhull Qt";
  const int exitcode =
      qh_new_qhull(qh, 3, static_cast<int>(pts.size()), coords.data(), False, options, nullptr, devnull);
  Hull hull;
  if (!exitcode) {
    std::vector<int> index(pts.size(), -1);
    vertexT* vertex = nullptr;
    vertexT** vertexp = nullptr;
    facetT* facet = nullptr;
    FORALLvertices {
      const int id = qh_pointid(qh, vertex->point);
      index[id] = static_cast<int>(hull.vertices.size());
      hull.vertices.push_back(pts[id]);
    }
    FORALLfacets {
      std::array<int, 3> t{};
      int k = 0;
      FOREACHvertex_(facet->vertices) {
        if (k < 3) t[k] = index[qh_pointid(qh, vertex->point)];
        ++k;
      }
      const Vec3 n(facet->normal[0], facet->normal[1], facet->normal[2]);
      if (k == 3) {
        const Vec3& a = hull.vertices[t[0]];
        if ((hull.vertices[t[1]] - a).cross(hull.vertices[t[2]] - a).dot(n) < 0) std::swap(t[1], t[2]);
        hull.triangles.push_back(t);
      }
      hull.planes.emplace_back(n.x(), n.y(), n.z(), facet->offset);
    }
  }
  qh_freeqhull(qh, !qh_ALL);
  int curlong = 0, totlong = 0;
  qh_memfreeshort(qh, &curlong, &totlong);
  if (devnull) std::fclose(devnull);
  if (exitcode) throw std::runtime_error("qhull failed");
  return hull;
}

/// The cube [-h, h]^3 as a hull (12 triangles, 6 planes).
Hull cube(double h) {
  std::vector<Vec3> pts;
  for (int i = 0; i < 8; ++i) pts.emplace_back(i & 1 ? h : -h, i & 2 ? h : -h, i & 4 ? h : -h);
  return qhullHull(pts);
}

/// A flat convex polygon: n points on an ellipse in the plane z = 0 (angle order), fanned into
/// triangles; its planes are the polygon's edges plus z <= 0 and -z <= 0.
Hull flatPolygon(int n, double rx, double ry, std::mt19937_64& rng) {
  std::uniform_real_distribution<double> jitter(0.0, 1.0);
  std::vector<double> angles;
  for (int i = 0; i < n; ++i) angles.push_back(2 * M_PI * (i + 0.8 * jitter(rng)) / n);
  Hull hull;
  for (double t : angles) hull.vertices.emplace_back(rx * std::cos(t), ry * std::sin(t), 0.0);
  for (int i = 1; i + 1 < n; ++i) hull.triangles.push_back({0, i, i + 1});
  for (int i = 0; i < n; ++i) {
    const Vec3& p = hull.vertices[i];
    const Vec3& q = hull.vertices[(i + 1) % n];
    const Vec3 out = (q - p).cross(Vec3::UnitZ()).normalized();  // counter-clockwise polygon
    hull.planes.emplace_back(out.x(), out.y(), out.z(), -out.dot(p));
  }
  hull.planes.emplace_back(0, 0, 1, 0);
  hull.planes.emplace_back(0, 0, -1, 0);
  return hull;
}

ConvexPiece pieceOf(const Hull& hull) { return makeConvexPiece(hull.vertices, hull.triangles); }

/// Largest violation of the hull's planes by p (link frame): <= 0 inside.
double outside(const Hull& hull, const Vec3& p_L) {
  double worst = -std::numeric_limits<double>::infinity();
  for (const Eigen::Vector4d& pl : hull.planes) worst = std::max(worst, pl.head<3>().dot(p_L) + pl[3]);
  return worst;
}

Eigen::Quaterniond randomRotation(std::mt19937_64& rng) {
  std::normal_distribution<double> g;
  Eigen::Quaterniond q(g(rng), g(rng), g(rng), g(rng));
  q.normalize();
  return q;
}

Eigen::Isometry3d pose(const Eigen::Quaterniond& q, const Vec3& p) {
  Eigen::Isometry3d X = Eigen::Isometry3d::Identity();
  X.linear() = q.toRotationMatrix();
  X.translation() = p;
  return X;
}

Eigen::Isometry3d translation(double x, double y, double z) {
  return pose(Eigen::Quaterniond::Identity(), Vec3(x, y, z));
}

/// Random points in an ellipsoid of semi-axes `axes` around the origin.
std::vector<Vec3> randomPoints(int n, const Vec3& axes, std::mt19937_64& rng) {
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  std::vector<Vec3> pts;
  while (static_cast<int>(pts.size()) < n) {
    const Vec3 p(u(rng), u(rng), u(rng));
    if (p.squaredNorm() <= 1.0) pts.push_back(p.cwiseProduct(axes));
  }
  return pts;
}

/// A random piece: the hull of 4..60 random points in an ellipsoid of 2..6 cm semi-axes.
Hull randomHull(std::mt19937_64& rng) {
  std::uniform_int_distribution<int> count(4, 60);
  std::uniform_real_distribution<double> axis(0.02, 0.06);
  for (;;) {
    const std::vector<Vec3> pts = randomPoints(count(rng), Vec3(axis(rng), axis(rng), axis(rng)), rng);
    try {
      return qhullHull(pts);
    } catch (const std::runtime_error&) {  // (practically never) a flat draw: draw again
    }
  }
}

/// Two random hulls (randomHull), A turned at random with its origin `centre` away from B's in a
/// random direction, B turned at random at the origin.
struct RandomPair {
  Hull ha, hb;
  ConvexPiece a, b;
  Eigen::Isometry3d X_B_A, X_B_B;
};
RandomPair randomPair(std::mt19937_64& rng, std::uniform_real_distribution<double>& centre) {
  RandomPair p;
  p.ha = randomHull(rng);
  p.hb = randomHull(rng);
  p.a = pieceOf(p.ha);
  p.b = pieceOf(p.hb);
  p.X_B_A = pose(randomRotation(rng), centre(rng) * (randomRotation(rng) * Vec3::UnitX()));
  p.X_B_B = pose(randomRotation(rng), Vec3::Zero());
  return p;
}

/// Brute-force exact distance between two hulls placed in B: the minimum over all triangle pairs of
/// FCL's triangle-triangle distance, 0 when one holds a vertex of the other.
double bruteDistance(const Hull& a, const Eigen::Isometry3d& X_B_A, const Hull& b, const Eigen::Isometry3d& X_B_B) {
  if (outside(b, X_B_B.inverse() * (X_B_A * a.vertices[0])) <= 0) return 0.0;
  if (outside(a, X_B_A.inverse() * (X_B_B * b.vertices[0])) <= 0) return 0.0;
  std::vector<std::array<Vec3, 3>> ta, tb;
  for (const auto& t : a.triangles)
    ta.push_back({X_B_A * a.vertices[t[0]], X_B_A * a.vertices[t[1]], X_B_A * a.vertices[t[2]]});
  for (const auto& t : b.triangles)
    tb.push_back({X_B_B * b.vertices[t[0]], X_B_B * b.vertices[t[1]], X_B_B * b.vertices[t[2]]});
  double best = std::numeric_limits<double>::infinity();
  Vec3 P, Q;
  for (const auto& s : ta)
    for (const auto& t : tb)
      best = std::min(best, fcl::detail::TriangleDistance<double>::triDistance(s.data(), t.data(), P, Q));
  return best;
}

/// The same hull as an fcl::Convex.
std::shared_ptr<fcl::Convexd> fclConvex(const Hull& hull) {
  auto vertices = std::make_shared<std::vector<fcl::Vector3d>>(hull.vertices.begin(), hull.vertices.end());
  auto faces = std::make_shared<std::vector<int>>();
  for (const auto& t : hull.triangles) faces->insert(faces->end(), {3, t[0], t[1], t[2]});
  return std::make_shared<fcl::Convexd>(vertices, static_cast<int>(hull.triangles.size()), faces);
}

double fclDistance(const fcl::Convexd& a, const Eigen::Isometry3d& X_B_A, const fcl::Convexd& b,
                   const Eigen::Isometry3d& X_B_B) {
  fcl::DistanceRequestd request;
  request.gjk_solver_type = fcl::GST_LIBCCD;
  request.distance_tolerance = 1e-9;
  fcl::DistanceResultd result;
  fcl::distance(&a, X_B_A, &b, X_B_B, request, result);
  return result.min_distance;
}

/// The result's own invariants: finite, non-negative, |p_a - p_b| = distance, penetrating iff 0.
void expectConsistent(const ConvexDistance& r) {
  ASSERT_TRUE(std::isfinite(r.distance));
  ASSERT_TRUE(r.p_B_a.allFinite());
  ASSERT_TRUE(r.p_B_b.allFinite());
  EXPECT_GE(r.distance, 0.0);
  EXPECT_NEAR((r.p_B_a - r.p_B_b).norm(), r.distance, 1e-12 * (1.0 + r.p_B_a.norm()));
  if (r.penetrating) {
    EXPECT_EQ(r.distance, 0.0);
    EXPECT_EQ(r.p_B_a, r.p_B_b);
  }
  EXPECT_LE(r.iterations, 64);
}

// ------------------------------------------------------------------ makeConvexPiece

TEST(ConvexPiece, BuildsTheEdgeGraphAndTheBoundingSphere) {
  const Hull c = cube(1.0);
  const ConvexPiece p = pieceOf(c);
  ASSERT_EQ(p.vertices_L.size(), 8u);
  ASSERT_EQ(p.neighbor_begin.size(), 9u);
  EXPECT_EQ(p.neighbor_begin.back(), static_cast<int>(p.neighbors.size()));
  for (int i = 0; i < 8; ++i) {
    const int degree = p.neighbor_begin[i + 1] - p.neighbor_begin[i];
    EXPECT_GE(degree, 3);  // the cube's 3 edges, plus triangulation diagonals
    EXPECT_LE(degree, 6);
    for (int k = p.neighbor_begin[i]; k < p.neighbor_begin[i + 1]; ++k) {
      const int j = p.neighbors[k];
      EXPECT_NE(j, i);
      // Every graph edge joins two corners on a common face (a cube edge or a face diagonal).
      EXPECT_EQ(((p.vertices_L[i] - p.vertices_L[j]).array().abs() < 1e-12).count() >= 1, true);
      // Symmetric.
      const auto b = p.neighbors.begin() + p.neighbor_begin[j], e = p.neighbors.begin() + p.neighbor_begin[j + 1];
      EXPECT_NE(std::find(b, e, i), e);
    }
  }
  EXPECT_NEAR(p.bound_center_L.norm(), 0.0, 1e-15);
  EXPECT_NEAR(p.bound_radius, std::sqrt(3.0), 1e-15);
  // The start vertex of each of the 14 directions is a support vertex of that direction (a scan).
  for (std::size_t k = 0; k < kStartDirections.size(); ++k) {
    const Vec3 d(kStartDirections[k][0], kStartDirections[k][1], kStartDirections[k][2]);
    double most = -1e300;
    for (const Vec3& v : p.vertices_L) most = std::max(most, d.dot(v));
    EXPECT_EQ(d.dot(p.vertices_L[static_cast<std::size_t>(p.start_vertex[k])]), most) << "direction " << k;
  }
  // startVertex picks the nearest of the 14 directions: an axis, or a diagonal's octant.
  EXPECT_EQ(startVertex(p, Vec3(-2, 0.1, 0.3)), p.start_vertex[1]);
  EXPECT_EQ(startVertex(p, Vec3(0.1, 0.2, 5)), p.start_vertex[4]);
  EXPECT_EQ(startVertex(p, Vec3(1, -1, 1.1)), p.start_vertex[8]);
  EXPECT_EQ(startVertex(p, Vec3(-1, -0.9, -1)), p.start_vertex[13]);

  const ConvexPiece no_graph = makeConvexPiece(c.vertices, {});
  EXPECT_TRUE(no_graph.neighbor_begin.empty());
  EXPECT_TRUE(no_graph.neighbors.empty());
  // A vertex the triangles leave out cannot be reached by hill-climbing: no graph at all.
  std::vector<Vec3> extra = c.vertices;
  extra.emplace_back(5, 0, 0);
  EXPECT_TRUE(makeConvexPiece(extra, c.triangles).neighbor_begin.empty());
  const ConvexPiece single = makeConvexPiece({Vec3(1, 2, 3)}, {});
  EXPECT_EQ(single.bound_center_L, Vec3(1, 2, 3));
  EXPECT_EQ(single.bound_radius, 0.0);
}

// A flat piece (a mesh's planar face: qhull refuses it, the fit keeps its points without triangles)
// climbs along its polygon: the corners only, in a cycle; every support query and distance equal to a
// linear scan over all the points given (the independent answer), inner and edge points included.
TEST(ConvexPiece, AFlatPieceWithoutTrianglesClimbsAlongItsPolygon) {
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  const Eigen::Isometry3d X = Eigen::Translation3d(0.3, -0.2, 0.1) * Eigen::AngleAxisd(0.7, Vec3(1, 2, 3).normalized());
  std::vector<Vec3> disk;
  for (int k = 0; k < 12; ++k) {  // corners of a 12-gon, the midpoint of each side, and inner points
    const double a = 2.0 * M_PI * k / 12.0, b = 2.0 * M_PI * (k + 1) / 12.0;
    disk.push_back(Vec3(0.02 * std::cos(a), 0.02 * std::sin(a), 0.0));
    disk.push_back(Vec3(0.01 * (std::cos(a) + std::cos(b)), 0.01 * (std::sin(a) + std::sin(b)), 0.0));
  }
  for (int k = 0; k < 150; ++k) disk.push_back(Vec3(0.012 * u(rng), 0.012 * u(rng), 0.0));
  for (Vec3& p : disk) p = X * p;  // a plane in no axis direction
  const ConvexPiece flat = makeConvexPiece(disk, {});
  ASSERT_EQ(flat.vertices_L.size(), 12u) << "the 12 corners, not the side midpoints or the inner points";
  ASSERT_EQ(flat.neighbor_begin.size(), 13u);
  for (int i = 0; i < 12; ++i) EXPECT_EQ(flat.neighbor_begin[i + 1] - flat.neighbor_begin[i], 2) << "a cycle";
  const ConvexPiece scanned = makeConvexPiece(disk, {{0, 1, 2}, {0, 0, 0}}) /* a vertex on no edge: no graph */;
  ASSERT_TRUE(scanned.neighbor_begin.empty());
  std::normal_distribution<double> g;
  for (int k = 0; k < 2000; ++k) {
    const Vec3 d(g(rng), g(rng), g(rng));
    double most = -1e300;
    for (const Vec3& p : disk) most = std::max(most, d.dot(p));
    const int start = std::uniform_int_distribution<int>(0, 11)(rng);
    EXPECT_NEAR(d.dot(flat.vertices_L[static_cast<std::size_t>(supportVertex(flat, d, start))]), most, 1e-15);
  }
  const ConvexPiece box = pieceOf(
      qhullHull({Vec3(-0.01, -0.01, -0.01), Vec3(0.01, -0.01, -0.01), Vec3(-0.01, 0.01, -0.01), Vec3(0.01, 0.01, -0.01),
                 Vec3(-0.01, -0.01, 0.01), Vec3(0.01, -0.01, 0.01), Vec3(-0.01, 0.01, 0.01), Vec3(0.01, 0.01, 0.01)}));
  for (int k = 0; k < 300; ++k) {
    const Eigen::Isometry3d Y = Eigen::Translation3d(0.3 + 0.05 * u(rng), -0.2 + 0.05 * u(rng), 0.1 + 0.05 * u(rng)) *
                                Eigen::AngleAxisd(3.0 * u(rng), Vec3(g(rng), g(rng), g(rng)).normalized());
    const ConvexDistance a = computeConvexDistance(flat, Eigen::Isometry3d::Identity(), box, Y);
    const ConvexDistance b = computeConvexDistance(scanned, Eigen::Isometry3d::Identity(), box, Y);
    EXPECT_NEAR(a.distance, b.distance, 1e-9) << k;
  }
  // Points off the plane by more than the tolerance: not flat, no graph (scanned as before).
  std::vector<Vec3> bent = disk;
  bent.back() += 1e-9 * (X.linear() * Vec3::UnitZ());
  EXPECT_TRUE(makeConvexPiece(bent, {}).neighbor_begin.empty());
}

TEST(ConvexPiece, RejectsBadInput) {
  EXPECT_THROW(makeConvexPiece({}, {}), std::invalid_argument);
  EXPECT_THROW(makeConvexPiece({Vec3(0, 0, std::numeric_limits<double>::quiet_NaN())}, {}), std::invalid_argument);
  EXPECT_THROW(makeConvexPiece({Vec3(std::numeric_limits<double>::infinity(), 0, 0)}, {}), std::invalid_argument);
  EXPECT_THROW(makeConvexPiece({Vec3::Zero(), Vec3::UnitX(), Vec3::UnitY()}, {{0, 1, 3}}), std::invalid_argument);
  EXPECT_THROW(makeConvexPiece({Vec3::Zero(), Vec3::UnitX(), Vec3::UnitY()}, {{0, -1, 2}}), std::invalid_argument);
}

// ------------------------------------------------------------------ supportVertex

TEST(ConvexSupport, HillClimbingFindsTheLinearScansMaximum) {
  std::mt19937_64 rng(3);
  std::normal_distribution<double> g;
  int cases = 0;
  for (int p = 0; p < 50; ++p) {
    const Hull h = randomHull(rng);
    const ConvexPiece with = pieceOf(h);
    const ConvexPiece without = makeConvexPiece(h.vertices, {});
    ASSERT_FALSE(with.neighbor_begin.empty());
    const int n = static_cast<int>(h.vertices.size());
    for (int k = 0; k < 100; ++k, ++cases) {
      const Vec3 d(g(rng), g(rng), g(rng));
      const int start = std::uniform_int_distribution<int>(-2, n + 2)(rng);  // out of range: clamped
      const int i = supportVertex(with, d, start);
      const int j = supportVertex(without, d, start);
      ASSERT_GE(i, 0);
      ASSERT_LT(i, n);
      double scan = -std::numeric_limits<double>::infinity();
      for (const Vec3& v : h.vertices) scan = std::max(scan, d.dot(v));
      EXPECT_NEAR(d.dot(h.vertices[i]), scan, 1e-15);
      EXPECT_NEAR(d.dot(h.vertices[j]), scan, 1e-15);
    }
  }
  EXPECT_EQ(cases, 5000);
  // Degenerate directions: zero and NaN give a valid index.
  const ConvexPiece c = pieceOf(cube(1.0));
  EXPECT_EQ(supportVertex(c, Vec3::Zero(), 5), 5);
  const int nan_index = supportVertex(c, Vec3::Constant(std::numeric_limits<double>::quiet_NaN()), 3);
  EXPECT_GE(nan_index, 0);
  EXPECT_LT(nan_index, 8);
}

// ------------------------------------------------------------------ hand-computed cases

TEST(ConvexDistance, CubesApartAlongAnAxisADiagonalAndACorner) {
  const ConvexPiece c = pieceOf(cube(1.0));  // edge 2
  const Eigen::Isometry3d I = Eigen::Isometry3d::Identity();
  {  // face-face along x: A's face x = 2, B's face x = 1
    const ConvexDistance r = computeConvexDistance(c, translation(3, 0.4, -0.2), c, I);
    expectConsistent(r);
    EXPECT_NEAR(r.distance, 1.0, 1e-12);
    EXPECT_FALSE(r.penetrating);
    EXPECT_NEAR(r.p_B_a.x(), 2.0, 1e-12);
    EXPECT_NEAR(r.p_B_b.x(), 1.0, 1e-12);
    EXPECT_LE((r.p_B_a - r.p_B_b - Vec3(1, 0, 0)).norm(), 1e-12);  // points from B towards A
    EXPECT_GE(r.p_B_b.y(), -0.6 - 1e-12);                          // on the faces' common part
    EXPECT_LE(r.p_B_b.z(), 0.8 + 1e-12);
  }
  {  // edge-edge along the xy diagonal
    const ConvexDistance r = computeConvexDistance(c, translation(3, 3, 0.5), c, I);
    expectConsistent(r);
    EXPECT_NEAR(r.distance, std::sqrt(2.0), 1e-12);
    EXPECT_NEAR(r.p_B_a.x(), 2.0, 1e-12);
    EXPECT_NEAR(r.p_B_a.y(), 2.0, 1e-12);
    EXPECT_NEAR(r.p_B_b.x(), 1.0, 1e-12);
    EXPECT_NEAR(r.p_B_b.y(), 1.0, 1e-12);
    EXPECT_GE(r.p_B_b.z(), -0.5 - 1e-12);
  }
  {  // vertex-vertex along the space diagonal
    const ConvexDistance r = computeConvexDistance(c, translation(3, 3, 3), c, I);
    expectConsistent(r);
    EXPECT_NEAR(r.distance, std::sqrt(3.0), 1e-12);
    EXPECT_LE((r.p_B_a - Vec3(2, 2, 2)).norm(), 1e-12);
    EXPECT_LE((r.p_B_b - Vec3(1, 1, 1)).norm(), 1e-12);
  }
  {  // B moved instead of A: the same distance, the sign convention holds
    const ConvexDistance r = computeConvexDistance(c, I, c, translation(0, -5, 0));
    expectConsistent(r);
    EXPECT_NEAR(r.distance, 3.0, 1e-12);
    EXPECT_LE((r.p_B_a - r.p_B_b - Vec3(0, 3, 0)).norm(), 1e-12);
  }
}

TEST(ConvexDistance, PointAgainstCubeFaceEdgeAndVertex) {
  const ConvexPiece c = pieceOf(cube(1.0));
  const ConvexPiece dot = makeConvexPiece({Vec3::Zero()}, {});
  struct Case {
    Vec3 point, closest;
  };
  const Case cases[] = {
      {Vec3(3, 0.2, -0.3), Vec3(1, 0.2, -0.3)},    // face
      {Vec3(3, 3, 0.5), Vec3(1, 1, 0.5)},          // edge
      {Vec3(2, 3, 4), Vec3(1, 1, 1)},              // vertex
      {Vec3(-1.5, 0.9, -2.5), Vec3(-1, 0.9, -1)},  // another edge
  };
  for (const Case& k : cases) {
    const ConvexDistance r = computeConvexDistance(dot, translation(k.point.x(), k.point.y(), k.point.z()), c,
                                                   Eigen::Isometry3d::Identity());
    expectConsistent(r);
    EXPECT_NEAR(r.distance, (k.point - k.closest).norm(), 1e-12) << k.point.transpose();
    EXPECT_LE((r.p_B_a - k.point).norm(), 1e-15);
    EXPECT_LE((r.p_B_b - k.closest).norm(), 1e-12) << k.point.transpose();
    // Swapped: the witness points swap, the direction flips.
    const ConvexDistance s = computeConvexDistance(c, Eigen::Isometry3d::Identity(), dot,
                                                   translation(k.point.x(), k.point.y(), k.point.z()));
    EXPECT_NEAR(s.distance, r.distance, 1e-12);
    EXPECT_LE((s.p_B_a - k.closest).norm(), 1e-12);
  }
  // A point inside the cube, and on its surface.
  for (const Vec3& p : {Vec3(0.3, -0.2, 0.1), Vec3(1, 0.5, 0.5)}) {
    const ConvexDistance r =
        computeConvexDistance(dot, translation(p.x(), p.y(), p.z()), c, Eigen::Isometry3d::Identity());
    expectConsistent(r);
    EXPECT_TRUE(r.penetrating);
    EXPECT_EQ(r.distance, 0.0);
    EXPECT_LE((r.p_B_a - p).norm(), 1e-12);
  }
}

TEST(ConvexDistance, TouchingAndOverlappingCubesPenetrate) {
  const Hull h = cube(1.0);
  const ConvexPiece c = pieceOf(h);
  const Eigen::Isometry3d I = Eigen::Isometry3d::Identity();
  for (const Eigen::Isometry3d& X_B_A : {translation(2, 0, 0), translation(2, 2, 2), translation(2, 0.3, 1.1),
                                         translation(1.5, 0, 0), translation(0.1, -0.3, 0.2), I}) {
    const ConvexDistance r = computeConvexDistance(c, X_B_A, c, I);
    expectConsistent(r);
    EXPECT_TRUE(r.penetrating) << X_B_A.translation().transpose();
    EXPECT_EQ(r.distance, 0.0);
    // The common point is in both cubes.
    EXPECT_LE(outside(h, r.p_B_b), 1e-12);
    EXPECT_LE(outside(h, X_B_A.inverse() * r.p_B_a), 1e-12);
  }
}

TEST(ConvexDistance, RotatedPieces) {
  const ConvexPiece c = pieceOf(cube(1.0));
  // A turned 45 degrees about z: its vertical edge at x = cx - sqrt(2) faces B's face x = 1.
  const double cx = 1.0 + std::sqrt(2.0) + 0.5;
  const Eigen::Isometry3d X_B_A =
      pose(Eigen::Quaterniond(Eigen::AngleAxisd(M_PI / 4, Vec3::UnitZ())), Vec3(cx, 0.2, 0));
  const ConvexDistance r = computeConvexDistance(c, X_B_A, c, Eigen::Isometry3d::Identity());
  expectConsistent(r);
  EXPECT_NEAR(r.distance, 0.5, 1e-12);
  EXPECT_NEAR(r.p_B_a.x(), 1.5, 1e-12);
  EXPECT_NEAR(r.p_B_a.y(), 0.2, 1e-12);
  // A turned so a corner points at B's face: the corner (1,1,1) of A at distance 0.25 from x = 1.
  const Eigen::Quaterniond q = Eigen::Quaterniond::FromTwoVectors(Vec3(1, 1, 1).normalized(), -Vec3::UnitX());
  const Eigen::Isometry3d X_corner = pose(q, Vec3(1.25 + std::sqrt(3.0), 0.1, -0.1));
  const ConvexDistance s = computeConvexDistance(c, X_corner, c, Eigen::Isometry3d::Identity());
  expectConsistent(s);
  EXPECT_NEAR(s.distance, 0.25, 1e-12);
  EXPECT_LE((s.p_B_a - Vec3(1.25, 0.1, -0.1)).norm(), 1e-12);
  EXPECT_LE((s.p_B_b - Vec3(1.0, 0.1, -0.1)).norm(), 1e-12);
}

TEST(ConvexDistance, InvariantUnderARigidMotionOfBoth) {
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<double> u(-0.5, 0.5);
  for (int k = 0; k < 100; ++k) {
    const ConvexPiece a = pieceOf(randomHull(rng)), b = pieceOf(randomHull(rng));
    const Eigen::Isometry3d X_B_A = pose(randomRotation(rng), Vec3(u(rng), u(rng), u(rng)) * 0.5);
    const Eigen::Isometry3d X_B_B = pose(randomRotation(rng), Vec3::Zero());
    const Eigen::Isometry3d X = pose(randomRotation(rng), Vec3(u(rng), u(rng), u(rng)));
    const ConvexDistance r = computeConvexDistance(a, X_B_A, b, X_B_B);
    const ConvexDistance s = computeConvexDistance(a, X * X_B_A, b, X * X_B_B);
    EXPECT_EQ(r.penetrating, s.penetrating);
    EXPECT_NEAR(r.distance, s.distance, 1e-10);
    if (!r.penetrating) {
      EXPECT_LE((X * r.p_B_a - s.p_B_a).norm(), 1e-6);  // unique unless faces are parallel
      EXPECT_NEAR((r.p_B_a - r.p_B_b).normalized().dot((X.linear().transpose() * (s.p_B_a - s.p_B_b)).normalized()),
                  1.0, 1e-9);
    }
  }
}

// ------------------------------------------------------------------ brute force and FCL

TEST(ConvexDistance, MatchesBruteForceAndFclOnRandomPieces) {
  std::mt19937_64 rng(2024);
  std::uniform_real_distribution<double> centre(0.0, 0.25);
  constexpr int kCases = 600;
  int separated = 0, overlapping = 0, fcl_checked = 0, max_iterations = 0;
  double worst = 0.0, worst_inside = -1.0, worst_fcl = 0.0;
  for (int k = 0; k < kCases; ++k) {
    const Hull ha = randomHull(rng), hb = randomHull(rng);
    const ConvexPiece a = pieceOf(ha), b = pieceOf(hb);
    const Vec3 dir = randomRotation(rng) * Vec3::UnitX();
    const Eigen::Isometry3d X_B_A = pose(randomRotation(rng), centre(rng) * dir);
    const Eigen::Isometry3d X_B_B = pose(randomRotation(rng), Vec3(0.01, -0.02, 0.005));
    const ConvexDistance r = computeConvexDistance(a, X_B_A, b, X_B_B);
    expectConsistent(r);
    max_iterations = std::max(max_iterations, r.iterations);
    const double brute = bruteDistance(ha, X_B_A, hb, X_B_B);
    const double error = std::abs(r.distance - brute);
    worst = std::max(worst, error);
    EXPECT_LE(error, 1e-7) << "case " << k << ": GJK " << r.distance << ", brute " << brute;
    EXPECT_EQ(r.penetrating, brute == 0.0) << "case " << k << ": brute " << brute;
    // Witness points on their pieces.
    const double in_a = outside(ha, X_B_A.inverse() * r.p_B_a), in_b = outside(hb, X_B_B.inverse() * r.p_B_b);
    worst_inside = std::max({worst_inside, in_a, in_b});
    EXPECT_LE(in_a, 1e-7) << "case " << k;
    EXPECT_LE(in_b, 1e-7) << "case " << k;
    if (brute > 0) {
      ++separated;
      // The second library: FCL's libccd GJK on the same hulls.
      const double fcl_d = fclDistance(*fclConvex(ha), X_B_A, *fclConvex(hb), X_B_B);
      worst_fcl = std::max(worst_fcl, std::abs(fcl_d - r.distance));
      EXPECT_NEAR(fcl_d, r.distance, 1e-5) << "case " << k;
      ++fcl_checked;
    } else {
      ++overlapping;
      EXPECT_LE(fclDistance(*fclConvex(ha), X_B_A, *fclConvex(hb), X_B_B), 0.0) << "case " << k;  // FCL: -1
    }
  }
  std::printf(
      "[ convex ] %d random pairs (%d separated, %d overlapping): max |GJK - brute| = %.3g m, "
      "max witness outside its hull = %.3g m, max |GJK - FCL| = %.3g m over %d, max iterations %d\n",
      kCases, separated, overlapping, worst, worst_inside, worst_fcl, fcl_checked, max_iterations);
  EXPECT_GE(separated, kCases / 4);  // both kinds well represented
  EXPECT_GE(overlapping, kCases / 10);
}

/// stop_above: a pair farther than it is reported above with a lower bound of the brute-force
/// distance that is itself above stop_above; a pair not farther comes out exactly as without it (the
/// same bits). stop_above is set just below, just above and far from the brute-force distance.
TEST(ConvexDistance, StopAboveGivesALowerBoundOrTheSameAnswer) {
  std::mt19937_64 rng(77);
  std::uniform_real_distribution<double> centre(0.05, 0.3);
  int above = 0, same = 0;
  for (int k = 0; k < 300; ++k) {
    const auto [ha, hb, a, b, X_B_A, X_B_B] = randomPair(rng, centre);
    const ConvexDistance full = computeConvexDistance(a, X_B_A, b, X_B_B);
    const double brute = bruteDistance(ha, X_B_A, hb, X_B_B);
    for (const double stop : {brute * 0.5, brute - 1e-4, brute + 1e-4, brute * 2.0 + 0.01}) {
      const ConvexDistance r = computeConvexDistance(a, X_B_A, b, X_B_B, nullptr, stop);
      if (r.above) {
        ++above;
        EXPECT_GT(r.distance, stop) << "case " << k;
        EXPECT_LE(r.distance, brute + 1e-9) << "case " << k << ": the bound must be below the distance";
        EXPECT_LT(stop, brute) << "case " << k << ": stopped although the distance is not above " << stop;
      } else {
        ++same;
        EXPECT_EQ(r.distance, full.distance) << "case " << k;
        EXPECT_EQ(r.p_B_a, full.p_B_a) << "case " << k;
        EXPECT_EQ(r.p_B_b, full.p_B_b) << "case " << k;
        EXPECT_EQ(r.penetrating, full.penetrating) << "case " << k;
      }
    }
  }
  std::printf("[ convex ] stop_above: %d stopped early with a bound, %d computed in full\n", above, same);
  EXPECT_GT(above, 200);
  EXPECT_GT(same, 400);
}

/// The first support pair, in the caller's direction (towards_b), already bounds the distance: the gap
/// between the two pieces' extents along it. With the true direction between the closest points a pair
/// farther than stop_above is proven so before any GJK iteration; with a poor direction (random) the
/// bound may not prove it, and either way the answer is a lower bound or the full answer.
TEST(ConvexDistance, TheFirstDirectionAloneProvesAFarPair) {
  std::mt19937_64 rng(78);
  std::uniform_real_distribution<double> centre(0.05, 0.3);
  int at_once = 0, apart = 0;
  for (int k = 0; k < 300; ++k) {
    const auto [ha, hb, a, b, X_B_A, X_B_B] = randomPair(rng, centre);
    const ConvexDistance full = computeConvexDistance(a, X_B_A, b, X_B_B);
    if (full.penetrating) continue;
    ++apart;
    const double brute = bruteDistance(ha, X_B_A, hb, X_B_B);
    const Vec3 exact_direction = full.p_B_b - full.p_B_a;
    const Vec3 random_direction = randomRotation(rng) * Vec3::UnitX();
    for (int which = 0; which < 2; ++which) {
      const Vec3 towards_b = which == 0 ? exact_direction : random_direction;
      const ConvexDistance same_path =
          computeConvexDistance(a, X_B_A, b, X_B_B, nullptr, std::numeric_limits<double>::infinity(), towards_b);
      EXPECT_NEAR(same_path.distance, brute, 1e-9) << "case " << k;
      for (const double stop : {0.5 * brute, brute - 1e-4, brute + 1e-4}) {
        const ConvexDistance r = computeConvexDistance(a, X_B_A, b, X_B_B, nullptr, stop, towards_b);
        if (r.above) {
          EXPECT_GT(r.distance, stop) << "case " << k;
          EXPECT_LE(r.distance, brute + 1e-9) << "case " << k << ": the bound must be below the distance";
          if (r.iterations == 0) ++at_once;
        } else {
          EXPECT_EQ(r.distance, same_path.distance) << "case " << k;
          EXPECT_EQ(r.p_B_a, same_path.p_B_a) << "case " << k;
        }
      }
      // The true direction proves half the distance at once: the extents' gap along it is the distance.
      if (which == 0) {
        const ConvexDistance half = computeConvexDistance(a, X_B_A, b, X_B_B, nullptr, 0.5 * brute, towards_b);
        EXPECT_TRUE(half.above) << "case " << k;
        EXPECT_EQ(half.iterations, 0) << "case " << k;
      }
    }
  }
  std::printf("[ convex ] first direction: %d early stops before any iteration, %d pairs apart\n", at_once, apart);
  EXPECT_GT(apart, 200);
  EXPECT_GE(at_once, apart);
}

/// `axis`: a search that proves a pair far stores the direction that did it (A's link frame); given
/// back with the pair moved a little, that direction alone proves it far again (no GJK iteration),
/// from a poor first direction (random); a bound so proven is below the brute-force distance; a
/// distance computed with a stored direction is the same bits as without one, and clears it.
TEST(ConvexDistance, AnAxisThatProvedAPairFarProvesItAgainAndChangesNoComputedDistance) {
  std::mt19937_64 rng(79);
  std::uniform_real_distribution<double> centre(0.08, 0.3), nudge(-0.002, 0.002);
  int stored = 0, again_at_once = 0, computed = 0;
  for (int k = 0; k < 300; ++k) {
    const auto [ha, hb, a, b, X_B_A, X_B_B] = randomPair(rng, centre);
    const double brute = bruteDistance(ha, X_B_A, hb, X_B_B);
    if (!(brute > 0.01)) continue;
    const Vec3 poor = randomRotation(rng) * Vec3::UnitX();
    const double stop = 0.5 * brute;
    ConvexHint hint;
    const ConvexDistance first = computeConvexDistance(a, X_B_A, b, X_B_B, nullptr, stop, poor, &hint);
    ASSERT_TRUE(first.above) << "case " << k;
    EXPECT_LE(first.distance, brute + 1e-9) << "case " << k;
    ASSERT_GT(hint.axis.squaredNorm(), 0.0) << "case " << k << ": the proving direction is stored";
    ASSERT_GE(hint.vertex_a, 0) << "case " << k << ": the first support pair is stored";
    ASSERT_GE(hint.vertex_b, 0) << "case " << k;
    hint.vertex_a = hint.vertex_b = -1;  // the axis alone
    ++stored;
    // Moved by up to 2 mm: the same direction proves half the distance again, at once.
    Eigen::Isometry3d moved = X_B_A;
    moved.translation() += Vec3(nudge(rng), nudge(rng), nudge(rng));
    const double brute_moved = bruteDistance(ha, moved, hb, X_B_B);
    const Vec3 other_poor = randomRotation(rng) * Vec3::UnitX();
    const ConvexDistance again = computeConvexDistance(a, moved, b, X_B_B, nullptr, stop, other_poor, &hint);
    ASSERT_TRUE(again.above) << "case " << k;
    EXPECT_GT(again.distance, stop) << "case " << k;
    EXPECT_LE(again.distance, brute_moved + 1e-9) << "case " << k << ": the bound must be below the distance";
    if (again.iterations == 0) ++again_at_once;
    // Asked for more than the distance: computed in full, the same bits as without a direction.
    const double past = brute_moved + 0.01;
    const ConvexDistance plain = computeConvexDistance(a, moved, b, X_B_B, nullptr, past, other_poor);
    const ConvexDistance with_axis = computeConvexDistance(a, moved, b, X_B_B, nullptr, past, other_poor, &hint);
    ASSERT_FALSE(plain.above) << "case " << k;
    EXPECT_EQ(with_axis.above, plain.above) << "case " << k;
    EXPECT_EQ(with_axis.distance, plain.distance) << "case " << k;
    EXPECT_EQ(with_axis.p_B_a, plain.p_B_a) << "case " << k;
    EXPECT_EQ(with_axis.p_B_b, plain.p_B_b) << "case " << k;
    EXPECT_EQ(hint.axis, Vec3::Zero()) << "case " << k << ": a computed distance clears the direction";
    ++computed;
  }
  std::printf("[ convex ] axis: %d stored, %d proven again before any iteration, %d computed the same\n", stored,
              again_at_once, computed);
  EXPECT_GT(stored, 200);
  EXPECT_EQ(again_at_once, stored);
  EXPECT_EQ(computed, stored);
}

TEST(ConvexDistance, AHintOfAnyVerticesChangesNoComputedDistance) {
  // A hint's support pair only starts the first climbs: whatever vertices it names (ties on cubes'
  // faces included), a distance asked past is the same bits as without a hint, and a pair asked for
  // half its distance is proven above it with a bound below the brute force's distance. It fails
  // when a search goes on from the hinted climb (a tied vertex changes the simplex's path).
  std::mt19937_64 rng(83);
  std::uniform_real_distribution<double> centre(0.06, 0.3), unit(0.0, 1.0);
  int computed = 0, proven = 0, ties = 0;
  for (int k = 0; k < 600; ++k) {
    // Half random hulls, half axis-aligned cubes on axis-aligned offsets (support ties everywhere).
    RandomPair pair = randomPair(rng, centre);
    if (k % 2 == 1) {
      pair.ha = cube(0.02 + 0.03 * unit(rng));
      pair.hb = cube(0.02 + 0.03 * unit(rng));
      pair.a = pieceOf(pair.ha);
      pair.b = pieceOf(pair.hb);
      pair.X_B_A = translation(0.0, 0.0, 0.0);
      const int along = static_cast<int>(rng() % 3);
      Vec3 offset = Vec3::Zero();
      offset[along] = centre(rng);
      pair.X_B_B = translation(offset.x(), offset.y(), offset.z());
      ++ties;
    }
    const double brute = bruteDistance(pair.ha, pair.X_B_A, pair.hb, pair.X_B_B);
    if (!(brute > 0.005)) continue;
    const Vec3 towards = pair.X_B_B.translation() - pair.X_B_A.translation();
    for (int trial = 0; trial < 4; ++trial) {
      ConvexHint hint;
      hint.vertex_a = static_cast<int>(rng() % pair.a.vertices_L.size());
      hint.vertex_b = static_cast<int>(rng() % pair.b.vertices_L.size());
      ConvexHint proof_hint = hint;
      const double past = brute + 0.01;
      const ConvexDistance plain =
          computeConvexDistance(pair.a, pair.X_B_A, pair.b, pair.X_B_B, nullptr, past, towards);
      const ConvexDistance hinted =
          computeConvexDistance(pair.a, pair.X_B_A, pair.b, pair.X_B_B, nullptr, past, towards, &hint);
      ASSERT_FALSE(plain.above) << "case " << k;
      EXPECT_EQ(hinted.above, plain.above) << "case " << k;
      EXPECT_EQ(hinted.distance, plain.distance) << "case " << k << " trial " << trial;
      EXPECT_EQ(hinted.p_B_a, plain.p_B_a) << "case " << k << " trial " << trial;
      EXPECT_EQ(hinted.p_B_b, plain.p_B_b) << "case " << k << " trial " << trial;
      EXPECT_EQ(hinted.iterations, plain.iterations) << "case " << k << " trial " << trial;
      ++computed;
      const ConvexDistance half =
          computeConvexDistance(pair.a, pair.X_B_A, pair.b, pair.X_B_B, nullptr, 0.5 * brute, towards, &proof_hint);
      ASSERT_TRUE(half.above) << "case " << k;
      EXPECT_GT(half.distance, 0.5 * brute) << "case " << k;
      EXPECT_LE(half.distance, brute + 1e-9) << "case " << k << ": the bound must be below the distance";
      ++proven;
    }
  }
  std::printf("[ convex ] hint: %d computed the same bits, %d proven far (%d cube pairs)\n", computed, proven, ties);
  EXPECT_GT(computed, 1500);
  EXPECT_GT(ties, 250);
}

TEST(ConvexDistance, NearlyTouchingRandomPiecesMatchBruteForce) {
  // Pieces pushed apart along a random direction until they are 0.1 um to 1 mm apart: the regime
  // where the controller acts and where the sub-distance sees nearly flat simplices.
  std::mt19937_64 rng(77);
  std::uniform_real_distribution<double> exponent(-7.0, -3.0);
  double worst = 0.0;
  for (int k = 0; k < 200; ++k) {
    const Hull ha = randomHull(rng), hb = randomHull(rng);
    const ConvexPiece a = pieceOf(ha), b = pieceOf(hb);
    const Vec3 dir = randomRotation(rng) * Vec3::UnitX();
    const Eigen::Quaterniond qa = randomRotation(rng);
    const Eigen::Isometry3d X_B_B = pose(randomRotation(rng), Vec3::Zero());
    // Bisection on the offset for a brute-force gap near the target.
    const double target = std::pow(10.0, exponent(rng));
    double lo = 0.0, hi = 0.3;
    for (int i = 0; i < 45; ++i) {
      const double mid = 0.5 * (lo + hi);
      (bruteDistance(ha, pose(qa, mid * dir), hb, X_B_B) < target ? lo : hi) = mid;
    }
    const Eigen::Isometry3d X_B_A = pose(qa, hi * dir);
    const double brute = bruteDistance(ha, X_B_A, hb, X_B_B);
    const ConvexDistance r = computeConvexDistance(a, X_B_A, b, X_B_B);
    expectConsistent(r);
    worst = std::max(worst, std::abs(r.distance - brute));
    EXPECT_NEAR(r.distance, brute, 1e-7) << "case " << k;
    EXPECT_FALSE(r.penetrating) << "case " << k << ": brute " << brute;
    EXPECT_LE(outside(ha, X_B_A.inverse() * r.p_B_a), 1e-7);
    EXPECT_LE(outside(hb, X_B_B.inverse() * r.p_B_b), 1e-7);
  }
  std::printf("[ convex ] 200 nearly touching pairs (1e-7 .. 1e-3 m): max |GJK - brute| = %.3g m\n", worst);
}

TEST(ConvexDistance, ParallelFacesMatchBruteForce) {
  // Boxes turned by the same rotation (parallel faces: the Minkowski difference has large flat faces
  // with many coplanar points, GJK's hardest simplices), or by the same one plus a tilt of 1e-9 to
  // 1e-3 rad, at face-face, edge-face and overlapping offsets.
  std::mt19937_64 rng(41);
  std::uniform_real_distribution<double> size(0.01, 0.08), u(-1.0, 1.0), tilt(-9.0, -3.0);
  double worst = 0.0;
  for (int k = 0; k < 400; ++k) {
    std::vector<Vec3> ca, cb;
    const Vec3 sa(size(rng), size(rng), size(rng)), sb(size(rng), size(rng), size(rng));
    for (int i = 0; i < 8; ++i) {
      const Vec3 corner(i & 1 ? 1 : -1, i & 2 ? 1 : -1, i & 4 ? 1 : -1);
      ca.push_back(corner.cwiseProduct(sa));
      cb.push_back(corner.cwiseProduct(sb));
    }
    const Hull ha = qhullHull(ca), hb = qhullHull(cb);
    const ConvexPiece a = pieceOf(ha), b = pieceOf(hb);
    const Eigen::Quaterniond q = randomRotation(rng);
    Eigen::Quaterniond qa = q;
    if (k % 2)
      qa = q * Eigen::Quaterniond(Eigen::AngleAxisd(std::pow(10.0, tilt(rng)), randomRotation(rng) * Vec3::UnitX()));
    // Offset in the boxes' frame: apart along one axis by 0..2 cm, anywhere across the others.
    const int axis = k % 3;
    Vec3 offset_Q(u(rng), u(rng), u(rng));
    offset_Q = offset_Q.cwiseProduct(sa + sb);
    offset_Q[axis] = (sa[axis] + sb[axis] + 0.01 * (u(rng) + 1.0)) * (u(rng) < 0 ? -1 : 1);
    if (k % 5 == 0) offset_Q[axis] *= 0.9;  // overlapping
    const Eigen::Isometry3d X_B_A = pose(qa, q * offset_Q), X_B_B = pose(q, Vec3::Zero());
    const ConvexDistance r = computeConvexDistance(a, X_B_A, b, X_B_B);
    expectConsistent(r);
    const double brute = bruteDistance(ha, X_B_A, hb, X_B_B);
    worst = std::max(worst, std::abs(r.distance - brute));
    EXPECT_NEAR(r.distance, brute, 1e-7) << "case " << k;
    EXPECT_LE(outside(ha, X_B_A.inverse() * r.p_B_a), 1e-7) << "case " << k;
    EXPECT_LE(outside(hb, X_B_B.inverse() * r.p_B_b), 1e-7) << "case " << k;
  }
  std::printf("[ convex ] 400 box pairs with parallel or nearly parallel faces: max |GJK - brute| = %.3g m\n", worst);
}

TEST(ConvexDistance, LargeAndSliverPiecesMatchBruteForce) {
  // Pieces of 100 to 300 hull vertices (points on an ellipsoid's surface: every point a vertex, many
  // nearly coplanar neighbours) and slivers (a needle and a sheet, 0.1 mm thin) against the brute force.
  std::mt19937_64 rng(57);
  std::uniform_int_distribution<int> count(100, 300);
  std::uniform_real_distribution<double> axis(0.02, 0.06), centre(0.0, 0.2);
  auto surface = [&](int n, const Vec3& axes) {
    std::normal_distribution<double> g;
    std::vector<Vec3> pts;
    for (int i = 0; i < n; ++i) pts.push_back(Vec3(g(rng), g(rng), g(rng)).normalized().cwiseProduct(axes));
    return qhullHull(pts);
  };
  double worst = 0.0;
  for (int k = 0; k < 30; ++k) {
    Hull ha, hb;
    if (k % 3 == 0) {
      ha = surface(count(rng), Vec3(axis(rng), axis(rng), axis(rng)));
      hb = surface(count(rng), Vec3(axis(rng), axis(rng), axis(rng)));
    } else if (k % 3 == 1) {
      ha = qhullHull(randomPoints(20, Vec3(0.05, 1e-4, 1e-4), rng));  // a needle
      hb = surface(count(rng), Vec3(axis(rng), axis(rng), axis(rng)));
    } else {
      ha = qhullHull(randomPoints(30, Vec3(0.05, 0.04, 1e-4), rng));  // a sheet
      hb = qhullHull(randomPoints(20, Vec3(0.05, 1e-4, 1e-4), rng));  // a needle
    }
    const ConvexPiece a = pieceOf(ha), b = pieceOf(hb);
    const Eigen::Isometry3d X_B_A = pose(randomRotation(rng), centre(rng) * (randomRotation(rng) * Vec3::UnitX()));
    const Eigen::Isometry3d X_B_B = pose(randomRotation(rng), Vec3::Zero());
    const ConvexDistance r = computeConvexDistance(a, X_B_A, b, X_B_B);
    expectConsistent(r);
    const double brute = bruteDistance(ha, X_B_A, hb, X_B_B);
    worst = std::max(worst, std::abs(r.distance - brute));
    EXPECT_NEAR(r.distance, brute, 1e-7) << "case " << k;
    EXPECT_EQ(r.penetrating, brute == 0.0) << "case " << k;
    EXPECT_LE(outside(ha, X_B_A.inverse() * r.p_B_a), 1e-7) << "case " << k;
    EXPECT_LE(outside(hb, X_B_B.inverse() * r.p_B_b), 1e-7) << "case " << k;
  }
  std::printf("[ convex ] 30 pairs of large or sliver pieces: max |GJK - brute| = %.3g m\n", worst);
}

// ------------------------------------------------------------------ warm start

TEST(ConvexDistance, WarmStartGivesTheColdAnswer) {
  std::mt19937_64 rng(5);
  std::normal_distribution<double> g;
  long cold_iterations = 0, warm_iterations = 0;
  int queries = 0;
  for (int k = 0; k < 40; ++k) {
    const Hull ha = randomHull(rng), hb = randomHull(rng);
    const ConvexPiece a = pieceOf(ha), b = pieceOf(hb);
    Eigen::Quaterniond qa = randomRotation(rng);
    Vec3 pa = randomRotation(rng) * Vec3(0.12, 0, 0);
    const Eigen::Isometry3d X_B_B = Eigen::Isometry3d::Identity();
    ConvexWarmStart warm;
    for (int step = 0; step < 50; ++step, ++queries) {  // a slow motion: 2 mm and ~1 degree a step
      pa += 0.002 * Vec3(g(rng), g(rng), g(rng));
      qa = (qa * Eigen::Quaterniond(Eigen::AngleAxisd(0.02, Vec3(g(rng), g(rng), g(rng)).normalized()))).normalized();
      const Eigen::Isometry3d X_B_A = pose(qa, pa);
      const ConvexDistance cold = computeConvexDistance(a, X_B_A, b, X_B_B);
      const ConvexDistance hot = computeConvexDistance(a, X_B_A, b, X_B_B, &warm);
      expectConsistent(hot);
      EXPECT_NEAR(hot.distance, cold.distance, 2e-9) << "pair " << k << " step " << step;
      EXPECT_EQ(hot.penetrating, cold.penetrating);
      EXPECT_GE(warm.vertex_a, 0);
      EXPECT_LT(warm.vertex_a, static_cast<int>(a.vertices_L.size()));
      EXPECT_GE(warm.vertex_b, 0);
      EXPECT_LT(warm.vertex_b, static_cast<int>(b.vertices_L.size()));
      cold_iterations += cold.iterations;
      warm_iterations += hot.iterations;
    }
  }
  std::printf("[ convex ] %d queries on slowly moving pairs: %.2f iterations cold, %.2f warm\n", queries,
              double(cold_iterations) / queries, double(warm_iterations) / queries);
  EXPECT_LE(warm_iterations, cold_iterations);
  // A stale or out-of-range warm start (another pair's) is clamped and still gives the answer.
  const ConvexPiece c = pieceOf(cube(1.0));
  ConvexWarmStart stale{-7, 1000};
  const ConvexDistance r = computeConvexDistance(c, translation(3, 3, 3), c, Eigen::Isometry3d::Identity(), &stale);
  EXPECT_NEAR(r.distance, std::sqrt(3.0), 1e-12);
}

// ------------------------------------------------------------------ allocation

TEST(ConvexDistance, DoesNotAllocate) {
  std::mt19937_64 rng(9);
  std::vector<ConvexPiece> pieces;
  for (int k = 0; k < 10; ++k) pieces.push_back(pieceOf(randomHull(rng)));
  pieces.push_back(makeConvexPiece(randomPoints(30, Vec3(0.03, 0.02, 0.04), rng), {}));  // no graph
  pieces.push_back(makeConvexPiece({Vec3::Zero()}, {}));
  std::vector<Eigen::Isometry3d> poses;
  for (int k = 0; k < 64; ++k)
    poses.push_back(pose(randomRotation(rng), randomRotation(rng) * Vec3(0.1 * (k % 4), 0, 0)));
  std::vector<ConvexWarmStart> warm(pieces.size() * pieces.size());
  double sum = 0.0;
  int queries = 0;
  const long before = testing::allocations();
  for (std::size_t i = 0; i < pieces.size(); ++i)
    for (std::size_t j = 0; j < pieces.size(); ++j)
      for (std::size_t p = 0; p + 1 < poses.size(); ++p, ++queries) {
        sum += computeConvexDistance(pieces[i], poses[p], pieces[j], poses[p + 1]).distance;
        sum +=
            computeConvexDistance(pieces[i], poses[p], pieces[j], poses[p + 1], &warm[i * pieces.size() + j]).distance;
        sum += supportVertex(pieces[i], poses[p].translation(), static_cast<int>(p));
      }
  const long allocations = testing::allocations() - before;
  EXPECT_EQ(allocations, 0);
  EXPECT_TRUE(std::isfinite(sum));
  EXPECT_GT(queries, 5000);
  // The counter does see operator new (else the test would prove nothing).
  const long probe = testing::allocations();
  auto v = std::make_unique<std::vector<int>>(10);
  EXPECT_GE(testing::allocations() - probe, 2);
}

// ------------------------------------------------------------------ degenerate pieces

TEST(ConvexDistance, FlatPiecesSegmentsAndPoints) {
  const ConvexPiece c = pieceOf(cube(1.0));
  const Eigen::Isometry3d I = Eigen::Isometry3d::Identity();
  // A unit square in z = 0, fanned, with and without the graph.
  const std::vector<Vec3> square = {Vec3(-1, -1, 0), Vec3(1, -1, 0), Vec3(1, 1, 0), Vec3(-1, 1, 0)};
  for (const ConvexPiece& sq : {makeConvexPiece(square, {{0, 1, 2}, {0, 2, 3}}), makeConvexPiece(square, {})}) {
    ConvexDistance r = computeConvexDistance(sq, translation(0.5, 0.5, 3), c, I);  // face-face
    expectConsistent(r);
    EXPECT_NEAR(r.distance, 2.0, 1e-12);
    r = computeConvexDistance(sq, translation(3.5, 0, 0), c, I);  // square's edge to cube's face
    EXPECT_NEAR(r.distance, 1.5, 1e-12);
    r = computeConvexDistance(sq, translation(0.5, 0, 0), c, I);  // crossing the cube
    EXPECT_TRUE(r.penetrating);
    // Coplanar squares: apart and overlapping.
    r = computeConvexDistance(sq, translation(2.75, 0.5, 0), sq, I);
    expectConsistent(r);
    EXPECT_NEAR(r.distance, 0.75, 1e-12);
    r = computeConvexDistance(sq, translation(1.0, 0.5, 0), sq, I);
    expectConsistent(r);
    EXPECT_TRUE(r.penetrating);
    // Parallel squares above each other.
    r = computeConvexDistance(sq, translation(0.3, -0.2, 1e-3), sq, I);
    expectConsistent(r);
    EXPECT_NEAR(r.distance, 1e-3, 1e-12);
  }
  // Segments: skew, parallel, collinear, crossing.
  const ConvexPiece seg_x = makeConvexPiece({Vec3(-1, 0, 0), Vec3(1, 0, 0)}, {});
  const ConvexPiece seg_z = makeConvexPiece({Vec3(0, 0, -1), Vec3(0, 0, 1)}, {});
  ConvexDistance r = computeConvexDistance(seg_z, translation(0.25, 0.7, 0.3), seg_x, I);
  expectConsistent(r);
  EXPECT_NEAR(r.distance, 0.7, 1e-12);
  EXPECT_LE((r.p_B_a - Vec3(0.25, 0.7, 0)).norm(), 1e-12);
  EXPECT_LE((r.p_B_b - Vec3(0.25, 0, 0)).norm(), 1e-12);
  r = computeConvexDistance(seg_x, translation(0.5, 0.3, -0.4), seg_x, I);  // parallel, overlapping in x
  expectConsistent(r);
  EXPECT_NEAR(r.distance, 0.5, 1e-12);
  r = computeConvexDistance(seg_x, translation(3, 0, 0), seg_x, I);  // collinear, end to end
  EXPECT_NEAR(r.distance, 1.0, 1e-12);
  r = computeConvexDistance(seg_x, translation(1, 0, 0), seg_x, I);  // collinear, overlapping
  EXPECT_TRUE(r.penetrating);
  r = computeConvexDistance(seg_z, translation(0.2, 0, 0.1), seg_x, I);  // crossing
  EXPECT_TRUE(r.penetrating);
  EXPECT_LE((r.p_B_a - Vec3(0.2, 0, 0)).norm(), 1e-12);
  r = computeConvexDistance(seg_x, translation(2.5, 0.5, 0.5), c, I);  // segment end (1.5, .5, .5) to face x = 1
  EXPECT_NEAR(r.distance, 0.5, 1e-12);
  r = computeConvexDistance(seg_z, translation(2, 2, 0.5), c, I);  // parallel to the cube's edge x = y = 1
  EXPECT_NEAR(r.distance, std::sqrt(2.0), 1e-12);
  // Points.
  const ConvexPiece dot = makeConvexPiece({Vec3(0.1, 0.2, 0.3)}, {});
  r = computeConvexDistance(dot, I, dot, translation(0, 3, 4));
  expectConsistent(r);
  EXPECT_NEAR(r.distance, 5.0, 1e-12);
  r = computeConvexDistance(dot, I, dot, I);
  EXPECT_TRUE(r.penetrating);
  EXPECT_LE((r.p_B_a - Vec3(0.1, 0.2, 0.3)).norm(), 1e-15);
  // Collinear and repeated vertices (a degenerate "hull"): the segment they span.
  const ConvexPiece line =
      makeConvexPiece({Vec3(-1, 0, 0), Vec3(0, 0, 0), Vec3(0, 0, 0), Vec3(1, 0, 0)}, {{0, 1, 3}, {1, 2, 3}});
  r = computeConvexDistance(line, translation(0, 2, 0), c, I);
  expectConsistent(r);
  EXPECT_NEAR(r.distance, 1.0, 1e-12);
}

TEST(ConvexDistance, RandomFlatPiecesMatchBruteForce) {
  std::mt19937_64 rng(31);
  std::uniform_int_distribution<int> count(3, 24);
  std::uniform_real_distribution<double> radius(0.01, 0.06), centre(0.0, 0.15);
  double worst = 0.0;
  for (int k = 0; k < 300; ++k) {
    const Hull ha = flatPolygon(count(rng), radius(rng), radius(rng), rng);
    const Hull hb = k % 2 ? flatPolygon(count(rng), radius(rng), radius(rng), rng) : randomHull(rng);
    const ConvexPiece a = pieceOf(ha), b = pieceOf(hb);
    // Every third pair coplanar (the same plane z = 0 in B).
    const bool coplanar = k % 3 == 0 && k % 2 == 1;
    const Eigen::Quaterniond qa =
        coplanar ? Eigen::Quaterniond(Eigen::AngleAxisd(k, Vec3::UnitZ())) : randomRotation(rng);
    const Vec3 dir =
        coplanar ? Vec3(std::cos(k * 0.7), std::sin(k * 0.7), 0) : Vec3(randomRotation(rng) * Vec3::UnitX());
    const Eigen::Isometry3d X_B_A = pose(qa, centre(rng) * dir);
    const Eigen::Isometry3d X_B_B = coplanar ? Eigen::Isometry3d::Identity() : pose(randomRotation(rng), Vec3::Zero());
    const ConvexDistance r = computeConvexDistance(a, X_B_A, b, X_B_B);
    expectConsistent(r);
    const double brute = bruteDistance(ha, X_B_A, hb, X_B_B);
    worst = std::max(worst, std::abs(r.distance - brute));
    EXPECT_NEAR(r.distance, brute, 1e-7) << "case " << k;
    EXPECT_LE(outside(ha, X_B_A.inverse() * r.p_B_a), 1e-7) << "case " << k;
    EXPECT_LE(outside(hb, X_B_B.inverse() * r.p_B_b), 1e-7) << "case " << k;
  }
  std::printf("[ convex ] 300 pairs with flat pieces: max |GJK - brute| = %.3g m\n", worst);
}

TEST(ConvexDistance, IdenticalPiecesAndExtremeScales) {
  std::mt19937_64 rng(13);
  const Hull h = randomHull(rng);
  const ConvexPiece p = pieceOf(h);
  const Eigen::Isometry3d X = pose(randomRotation(rng), Vec3(0.3, -0.1, 0.7));
  ConvexDistance r = computeConvexDistance(p, X, p, X);
  expectConsistent(r);
  EXPECT_TRUE(r.penetrating);
  EXPECT_LE(outside(h, X.inverse() * r.p_B_a), 1e-12);

  // The cubes' face-face case at sizes from 1 um to 1 km, and far from the origin (1e6 m).
  for (double s : {1e-6, 1e-3, 1.0, 1e3}) {
    const ConvexPiece c = pieceOf(cube(s));
    for (double far : {0.0, 1e6}) {
      const Eigen::Isometry3d X_B_B = translation(far, -far, far);
      const Eigen::Isometry3d X_B_A = translation(far + 3 * s, -far + 0.3 * s, far);
      r = computeConvexDistance(c, X_B_A, c, X_B_B);
      expectConsistent(r);
      const double tol = std::max(kConvexTolerance, 1e-9 * (far + 4 * s));
      EXPECT_NEAR(r.distance, s, tol) << "size " << s << " at " << far;
      r = computeConvexDistance(c, translation(far + 1.5 * s, -far, far), c, X_B_B);
      EXPECT_TRUE(r.penetrating) << "size " << s << " at " << far;
      r = computeConvexDistance(c, translation(far + 3 * s, -far + 3 * s, far + 3 * s), c, X_B_B);
      EXPECT_NEAR(r.distance, std::sqrt(3.0) * s, tol) << "size " << s << " at " << far;
    }
  }
  // Random pieces scaled to 1e-6 .. 1e6 m at random poses: always finite.
  std::uniform_real_distribution<double> e(-6.0, 6.0), u(-1.0, 1.0);
  for (int k = 0; k < 300; ++k) {
    const double s = std::pow(10.0, e(rng));
    Hull ha = randomHull(rng), hb = randomHull(rng);
    for (Vec3& v : ha.vertices) v *= s / 0.05;
    for (Vec3& v : hb.vertices) v *= s / 0.05;
    const Eigen::Isometry3d X_B_A = pose(randomRotation(rng), std::pow(10.0, e(rng)) * Vec3(u(rng), u(rng), u(rng)));
    const Eigen::Isometry3d X_B_B = pose(randomRotation(rng), std::pow(10.0, e(rng)) * Vec3(u(rng), u(rng), u(rng)));
    r = computeConvexDistance(pieceOf(ha), X_B_A, pieceOf(hb), X_B_B);
    expectConsistent(r);
  }
}

}  // namespace
}  // namespace reflex::control
