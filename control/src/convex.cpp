// GJK distance between two convex polytopes (convex.hpp): the support queries, the signed-volume
// sub-distance (Montanari, Petrinic, Barbieri 2017, "Improving the GJK algorithm for faster and more
// reliable distance queries between convex objects", ACM TOG 36(3), Sec. 3 and Alg. 2-4) and the
// GJK loop (Gilbert, Johnson, Keerthi 1988; termination as in Montanari Alg. 1).
//
// Points w of the simplex are points of the Minkowski difference A - B in the base frame B. The
// sub-distance returns the simplex's smallest support set that holds its point closest to the origin,
// with that point's barycentric coordinates; everything lives on the stack (4 points at most).
#include "reflex/control/convex.hpp"

#include <Eigen/Eigenvalues>

#include <algorithm>
#include <cassert>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>
#include <utility>

namespace reflex::control {

Eigen::Matrix3d principalAxes(const std::vector<Eigen::Vector3d>& pts) {
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (const auto& p : pts) mean += p;
  mean /= static_cast<double>(pts.size());
  Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
  for (const auto& p : pts) cov += (p - mean) * (p - mean).transpose();
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(cov);
  Eigen::Matrix3d axes = es.eigenvectors();  // columns, ascending eigenvalues
  for (int k = 0; k < 3; ++k) {              // a fixed sign, for determinism across solvers
    int big = 0;
    axes.col(k).cwiseAbs().maxCoeff(&big);
    if (axes(big, k) < 0) axes.col(k) = -axes.col(k);
  }
  return axes;
}

namespace {

/// A flat set of points (every point within kFlatTolerance of one plane; a mesh's planar face, which a
/// hull program refuses as degenerate) as its polygon: the indices of the corners of its convex
/// hull in the plane, in order around it (inner points and points within kFlatTolerance of a side left
/// out: convex combinations of the corners to within it, so no support query can need them beyond
/// that). Empty when the points are not flat or fewer than 4.
std::vector<int> flatPolygon(const std::vector<Eigen::Vector3d>& v) {
  constexpr double kFlatTolerance = 1e-12;  // m: far below kConvexTolerance
  const std::size_t n = v.size();
  if (n < 4) return {};
  Eigen::Vector3d c = Eigen::Vector3d::Zero();
  for (const Eigen::Vector3d& p : v) c += p;
  c /= static_cast<double>(n);
  const Eigen::Matrix3d axes = principalAxes(v);
  const Eigen::Vector3d normal = axes.col(0), e1 = axes.col(2), e2 = axes.col(1);
  for (const Eigen::Vector3d& p : v)
    if (!(std::abs(normal.dot(p - c)) <= kFlatTolerance)) return {};
  // Andrew's monotone chain on the in-plane coordinates; strict turns only.
  std::vector<int> order(n);
  for (std::size_t i = 0; i < n; ++i) order[i] = static_cast<int>(i);
  auto uv = [&](int i) { return Eigen::Vector2d(e1.dot(v[i] - c), e2.dot(v[i] - c)); };
  std::sort(order.begin(), order.end(), [&](int a, int b) {
    const Eigen::Vector2d pa = uv(a), pb = uv(b);
    return pa.x() < pb.x() || (pa.x() == pb.x() && pa.y() < pb.y());
  });
  // Whether a turns left from o to b by more than the tolerance: a farther than kFlatTolerance from
  // the line o-b (|b - o| times that distance is the cross product), else a is left out.
  auto turns = [&](int o, int a, int b) {
    const Eigen::Vector2d po = uv(o), pa = uv(a) - po, pb = uv(b) - po;
    return pa.x() * pb.y() - pa.y() * pb.x() > kFlatTolerance * pb.norm();
  };
  std::vector<int> hull(2 * n);
  std::size_t k = 0;
  for (std::size_t i = 0; i < n; ++i) {  // lower chain
    while (k >= 2 && !turns(hull[k - 2], hull[k - 1], order[i])) --k;
    hull[k++] = order[i];
  }
  for (std::size_t i = n - 1, lower = k + 1; i-- > 0;) {  // upper chain
    while (k >= lower && !turns(hull[k - 2], hull[k - 1], order[i])) --k;
    hull[k++] = order[i];
  }
  hull.resize(k > 1 ? k - 1 : k);  // the first point closes the chain
  return hull;
}

}  // namespace

ConvexPiece makeConvexPiece(const std::vector<Eigen::Vector3d>& vertices,
                            const std::vector<std::array<int, 3>>& triangles) {
  if (vertices.empty()) throw std::invalid_argument("makeConvexPiece: no vertex");
  const int n = static_cast<int>(vertices.size());
  for (int i = 0; i < n; ++i)
    if (!vertices[i].allFinite())
      throw std::invalid_argument("makeConvexPiece: vertex " + std::to_string(i) + " is not finite (" +
                                  std::to_string(vertices[i].x()) + ", " + std::to_string(vertices[i].y()) + ", " +
                                  std::to_string(vertices[i].z()) + ")");
  for (std::size_t t = 0; t < triangles.size(); ++t)
    for (int k = 0; k < 3; ++k)
      if (triangles[t][k] < 0 || triangles[t][k] >= n)
        throw std::invalid_argument("makeConvexPiece: triangle " + std::to_string(t) + " has vertex index " +
                                    std::to_string(triangles[t][k]) + ", outside [0, " + std::to_string(n) + ")");

  // A flat piece without triangles: its polygon's corners, each joined to the next (hill-climbing
  // along a convex polygon's boundary finds its maximum like over a hull's edges).
  if (triangles.empty()) {
    const std::vector<int> polygon = flatPolygon(vertices);
    if (polygon.size() >= 3) {
      std::vector<Eigen::Vector3d> corners;
      std::vector<std::array<int, 3>> edges;  // {i, j, j}: the edge i-j alone (the graph takes triangles)
      for (const int i : polygon) corners.push_back(vertices[static_cast<std::size_t>(i)]);
      const int m = static_cast<int>(corners.size());
      for (int i = 0; i < m; ++i) edges.push_back({i, (i + 1) % m, (i + 1) % m});
      return makeConvexPiece(corners, edges);
    }
  }
  ConvexPiece piece;
  piece.vertices_L = vertices;
  Eigen::Vector3d lo = vertices[0], hi = vertices[0];
  for (const Eigen::Vector3d& v : vertices) {
    lo = lo.cwiseMin(v);
    hi = hi.cwiseMax(v);
  }
  piece.bound_center_L = 0.5 * (lo + hi);
  for (const Eigen::Vector3d& v : vertices)
    piece.bound_radius = std::max(piece.bound_radius, (v - piece.bound_center_L).norm());

  for (std::size_t k = 0; k < kStartDirections.size(); ++k) {
    const Eigen::Vector3d d(kStartDirections[k][0], kStartDirections[k][1], kStartDirections[k][2]);
    int best = 0;
    for (int i = 1; i < n; ++i)
      if (d.dot(vertices[i]) > d.dot(vertices[best])) best = i;
    piece.start_vertex[k] = best;
  }
  if (triangles.empty()) return piece;
  // Undirected edges of the triangles, both directions, sorted and unique: the CSR edge graph.
  std::vector<std::pair<int, int>> edges;
  edges.reserve(6 * triangles.size());
  for (const std::array<int, 3>& t : triangles)
    for (int k = 0; k < 3; ++k) {
      const int i = t[k], j = t[(k + 1) % 3];
      if (i == j) continue;
      edges.emplace_back(i, j);
      edges.emplace_back(j, i);
    }
  std::sort(edges.begin(), edges.end());
  edges.erase(std::unique(edges.begin(), edges.end()), edges.end());
  piece.neighbor_begin.assign(n + 1, 0);
  for (const std::pair<int, int>& e : edges) ++piece.neighbor_begin[e.first + 1];
  for (int i = 0; i < n; ++i) piece.neighbor_begin[i + 1] += piece.neighbor_begin[i];
  piece.neighbors.reserve(edges.size());
  for (const std::pair<int, int>& e : edges) piece.neighbors.push_back(e.second);
  // A vertex on no edge (a vertex the triangles leave out) could never be reached by hill-climbing
  // while it may be the support point: such a piece gets no graph and is scanned linearly. A single
  // vertex needs no graph either way.
  for (int i = 0; i < n; ++i)
    if (n > 1 && piece.neighbor_begin[i + 1] == piece.neighbor_begin[i]) {
      piece.neighbor_begin.clear();
      piece.neighbors.clear();
      break;
    }
  return piece;
}

int startVertex(const ConvexPiece& piece, const Eigen::Vector3d& d_L) noexcept {
  // The axes' cosines are |d_i| / |d|, the diagonals' (|d_x| + |d_y| + |d_z|) / (sqrt(3) |d|): the
  // largest component against the sum over sqrt(3) picks between the two kinds, the signs the one.
  const double ax = std::abs(d_L.x()), ay = std::abs(d_L.y()), az = std::abs(d_L.z());
  const int axis = ax >= ay ? (ax >= az ? 0 : 2) : (ay >= az ? 1 : 2);
  const double largest = std::max(ax, std::max(ay, az));
  const int on_axis = 2 * axis + (d_L[axis] < 0 ? 1 : 0);
  const int octant = 6 + (d_L.x() < 0 ? 4 : 0) + (d_L.y() < 0 ? 2 : 0) + (d_L.z() < 0 ? 1 : 0);
  const int k = largest * 1.7320508075688772 >= ax + ay + az ? on_axis : octant;
  return piece.start_vertex[static_cast<std::size_t>(k)];
}

namespace {

/// Whether the piece has its edge graph (else support queries scan every vertex).
inline bool hasGraph(const ConvexPiece& p) { return p.neighbor_begin.size() == p.vertices_L.size() + 1; }

/// Steepest ascent over a piece's edge graph towards direction d, a step at a time (supportVertex
/// climbs one piece, supportPair two side by side). On a convex polytope a vertex that no neighbour
/// beats is a global maximum; every step strictly increases the (computed) dot product, so no vertex
/// is visited twice and the climb ends after at most n steps even with rounding or a NaN direction.
struct Climb {
  const Eigen::Vector3d* v;
  const int* nb;
  const int* adj;
  double dx, dy, dz;
  int at;
  double at_dot;
  bool done;
  void init(const ConvexPiece& p, const Eigen::Vector3d& d, int start) {
    v = p.vertices_L.data();
    nb = p.neighbor_begin.data();
    adj = p.neighbors.data();
    dx = d.x(), dy = d.y(), dz = d.z();
    at = std::clamp(start, 0, static_cast<int>(p.vertices_L.size()) - 1);
    at_dot = dx * v[at].x() + dy * v[at].y() + dz * v[at].z();
    done = false;
  }
  [[gnu::always_inline]] inline void step() {
    int next = at;
    for (int k = nb[at]; k < nb[at + 1]; ++k) {
      const Eigen::Vector3d& w = v[adj[k]];
      const double dot = dx * w.x() + dy * w.y() + dz * w.z();
      if (dot > at_dot) {
        at_dot = dot;
        next = adj[k];
      }
    }
    done = next == at;
    at = next;
  }
};

}  // namespace

int supportVertex(const ConvexPiece& piece, const Eigen::Vector3d& d_L, int start) noexcept {
  const int n = static_cast<int>(piece.vertices_L.size());
  if (n <= 0) return 0;
  if (!hasGraph(piece)) {  // every vertex
    int best = std::clamp(start, 0, n - 1);
    double best_dot = d_L.dot(piece.vertices_L[best]);
    for (int i = 0; i < n; ++i) {
      const double dot = d_L.dot(piece.vertices_L[i]);
      if (dot > best_dot) {
        best_dot = dot;
        best = i;
      }
    }
    return best;
  }
  Climb c;
  c.init(piece, d_L, start);
  while (!c.done) c.step();
  return c.at;
}

namespace {

/// supportVertex of both pieces, the two climbs interleaved step by step (independent work for the
/// processor to overlap).
void supportPair(const ConvexPiece& a, const Eigen::Vector3d& da, int& ia, const ConvexPiece& b,
                 const Eigen::Vector3d& db, int& ib) {
  if (!hasGraph(a) || !hasGraph(b)) {
    ia = supportVertex(a, da, ia);
    ib = supportVertex(b, db, ib);
    return;
  }
  Climb A, B;
  A.init(a, da, ia);
  B.init(b, db, ib);
  while (!A.done && !B.done) {
    A.step();
    B.step();
  }
  while (!A.done) A.step();
  while (!B.done) B.step();
  ia = A.at;
  ib = B.at;
}

/// The GJK simplex: up to 4 points w = p_a - p_b of A - B (in A's link frame), with the vertex
/// indices they came from (the witness points are made from those at the end).
struct Simplex {
  Eigen::Vector3d w[4];
  int ia[4];
  int ib[4];
  int size = 0;
};

/// A sub-distance result: the support set (indices into the simplex, at most 4), the barycentric
/// coordinates of the closest point on it, that point v and |v|^2.
struct SubResult {
  int n = 0;
  int idx[4] = {0, 0, 0, 0};
  double lambda[4] = {0, 0, 0, 0};
  Eigen::Vector3d v = Eigen::Vector3d::Zero();
  double vv = 0.0;
};

/// True when a and b are both strictly positive or both strictly negative (Montanari's compareSigns).
inline bool sameSign(double a, double b) { return (a > 0 && b > 0) || (a < 0 && b < 0); }

void point(const Eigen::Vector3d* w, int i, SubResult& r) {
  r.n = 1;
  r.idx[0] = i;
  r.lambda[0] = 1.0;
  r.v = w[i];
  r.vv = r.v.squaredNorm();
}

/// Closest point to the origin on segment w[i] w[j] (Montanari S1D, written with the segment's own
/// parameter: relative coordinates keep the precision when the segment is far from the origin).
void s1d(const Eigen::Vector3d* w, int i, int j, SubResult& r) {
  const Eigen::Vector3d t = w[j] - w[i];
  const double tt = t.squaredNorm();
  const double u = tt > 0 ? -w[i].dot(t) / tt : 0.0;  // origin's projection: w[i] + u t
  if (!(u > 0)) return point(w, i, r);                // also a zero-length segment
  if (!(u < 1)) return point(w, j, r);
  r.n = 2;
  r.idx[0] = i;
  r.idx[1] = j;
  r.lambda[0] = 1.0 - u;
  r.lambda[1] = u;
  r.v = r.lambda[0] * w[i] + r.lambda[1] * w[j];
  r.vv = r.v.squaredNorm();
}

/// Keeps `cand` in `best` when it is closer to the origin.
inline void keepCloser(const SubResult& cand, SubResult& best) {
  if (cand.vv < best.vv) best = cand;
}

/// Closest point to the origin on triangle w[i] w[j] w[k] (Montanari S2D, Alg. 3): the origin's
/// projection on the plane, its signed areas in the axis plane where the triangle's projection is
/// largest; inside: barycentric coordinates; else the closest of the edges it lies beyond. A
/// (nearly) collinear triangle is taken as its three edges.
void s2d(const Eigen::Vector3d* w, int i, int j, int k, SubResult& r) {
  const Eigen::Vector3d e1 = w[j] - w[i];
  const Eigen::Vector3d e2 = w[k] - w[i];
  const Eigen::Vector3d n = e1.cross(e2);
  const double nn = n.squaredNorm();
  SubResult cand;
  r.vv = std::numeric_limits<double>::infinity();
  // sin^2 of the angle at w[i] below 1e-20: the triangle is within 1e-10 of its edges (relative).
  if (!(nn > 1e-20 * e1.squaredNorm() * e2.squaredNorm())) {
    s1d(w, i, j, cand);
    keepCloser(cand, r);
    s1d(w, j, k, cand);
    keepCloser(cand, r);
    s1d(w, k, i, cand);
    keepCloser(cand, r);
    return;
  }
  // q: the origin's projection on the plane, relative to w[i].
  const Eigen::Vector3d o = -w[i];
  const Eigen::Vector3d q = o - (o.dot(n) / nn) * n;
  int axis = 0;
  n.cwiseAbs().maxCoeff(&axis);
  const int a = (axis + 1) % 3, b = (axis + 2) % 3;  // n[axis] = e1[a] e2[b] - e1[b] e2[a]
  const double mu = n[axis];
  // Twice the signed areas of the sub-triangles with one vertex replaced by q (projected on a, b).
  const double cj = q[a] * e2[b] - q[b] * e2[a];  // (w_i, q, w_k)
  const double ck = e1[a] * q[b] - e1[b] * q[a];  // (w_i, w_j, q)
  const double ci = mu - cj - ck;                 // (q, w_j, w_k)
  if (sameSign(mu, ci) && sameSign(mu, cj) && sameSign(mu, ck)) {
    r.n = 3;
    r.idx[0] = i;
    r.idx[1] = j;
    r.idx[2] = k;
    r.lambda[1] = cj / mu;
    r.lambda[2] = ck / mu;
    r.lambda[0] = 1.0 - r.lambda[1] - r.lambda[2];
    r.v = r.lambda[0] * w[i] + r.lambda[1] * w[j] + r.lambda[2] * w[k];
    r.vv = r.v.squaredNorm();
    return;
  }
  // Outside (or on an edge): the edges opposite a vertex whose coordinate is not of mu's sign.
  if (!sameSign(mu, ci)) {
    s1d(w, j, k, cand);
    keepCloser(cand, r);
  }
  if (!sameSign(mu, cj)) {
    s1d(w, k, i, cand);
    keepCloser(cand, r);
  }
  if (!sameSign(mu, ck)) {
    s1d(w, i, j, cand);
    keepCloser(cand, r);
  }
}

/// Closest point to the origin on tetrahedron w[0..3] (Montanari S3D, Alg. 4): signed volumes of the
/// sub-tetrahedra with one vertex replaced by the origin, relative to w[0]; all of the sign of the
/// whole: the origin is inside (n = 4, v = 0); else the closest of the faces it lies beyond. A
/// (nearly) flat tetrahedron is taken as its four faces.
void s3d(const Eigen::Vector3d* w, SubResult& r) {
  const Eigen::Vector3d e1 = w[1] - w[0];
  const Eigen::Vector3d e2 = w[2] - w[0];
  const Eigen::Vector3d e3 = w[3] - w[0];
  const Eigen::Vector3d o = -w[0];
  const Eigen::Vector3d e2xe3 = e2.cross(e3);
  const double mu = e1.dot(e2xe3);  // 6 x signed volume
  const double scale = e1.norm() * e2.norm() * e3.norm();
  SubResult cand;
  r.vv = std::numeric_limits<double>::infinity();
  if (!(std::abs(mu) > 1e-12 * scale)) {
    s2d(w, 1, 2, 3, cand);
    keepCloser(cand, r);
    s2d(w, 0, 2, 3, cand);
    keepCloser(cand, r);
    s2d(w, 0, 1, 3, cand);
    keepCloser(cand, r);
    s2d(w, 0, 1, 2, cand);
    keepCloser(cand, r);
    return;
  }
  // Cramer on [e1 e2 e3] mu_123 = o: the origin's coordinates (times mu) on w1, w2, w3.
  const double c1 = o.dot(e2xe3);
  const double c2 = e1.dot(o.cross(e3));
  const double c3 = e1.dot(e2.cross(o));
  const double c0 = mu - c1 - c2 - c3;
  if (sameSign(mu, c0) && sameSign(mu, c1) && sameSign(mu, c2) && sameSign(mu, c3)) {
    r.n = 4;
    for (int m = 0; m < 4; ++m) r.idx[m] = m;
    r.lambda[1] = c1 / mu;
    r.lambda[2] = c2 / mu;
    r.lambda[3] = c3 / mu;
    r.lambda[0] = 1.0 - r.lambda[1] - r.lambda[2] - r.lambda[3];
    r.v.setZero();
    r.vv = 0.0;
    return;
  }
  if (!sameSign(mu, c0)) {
    s2d(w, 1, 2, 3, cand);
    keepCloser(cand, r);
  }
  if (!sameSign(mu, c1)) {
    s2d(w, 0, 2, 3, cand);
    keepCloser(cand, r);
  }
  if (!sameSign(mu, c2)) {
    s2d(w, 0, 1, 3, cand);
    keepCloser(cand, r);
  }
  if (!sameSign(mu, c3)) {
    s2d(w, 0, 1, 2, cand);
    keepCloser(cand, r);
  }
}

/// The sub-distance of the whole simplex (1 to 4 points).
void subDistance(const Simplex& s, SubResult& r) {
  switch (s.size) {
    case 1: point(s.w, 0, r); break;
    case 2: s1d(s.w, 0, 1, r); break;
    case 3: s2d(s.w, 0, 1, 2, r); break;
    default: s3d(s.w, r); break;
  }
}

/// The simplex reduced to the support set of r (r's indices become 0 .. n-1).
void reduce(Simplex& s, SubResult& r) {
  Simplex t;
  for (int m = 0; m < r.n; ++m) {
    const int k = r.idx[m];
    t.w[m] = s.w[k];
    t.ia[m] = s.ia[k];
    t.ib[m] = s.ib[k];
    r.idx[m] = m;
  }
  t.size = r.n;
  s = t;
}

/// The end of a search: witness points from the barycentric coordinates of the closest point on each
/// piece's support points (contact: their midpoint, distance 0), and the warm start for the next call
/// (the support pair of the heaviest weight).
[[gnu::always_inline]] inline void witnessPoints(const Simplex& s, const SubResult& sub, bool contact,
                                                 const ConvexPiece& a, const ConvexPiece& b, const Eigen::Matrix3d& R,
                                                 const Eigen::Vector3d& t, const Eigen::Isometry3d& X_B_A,
                                                 ConvexWarmStart* warm, ConvexDistance& out) {
  Eigen::Vector3d p_a = Eigen::Vector3d::Zero(), p_b = Eigen::Vector3d::Zero();
  int heaviest = 0;
  for (int m = 0; m < sub.n; ++m) {
    const int k = sub.idx[m];
    p_a += sub.lambda[m] * a.vertices_L[s.ia[k]];
    p_b += sub.lambda[m] * b.vertices_L[s.ib[k]];
    if (sub.lambda[m] > sub.lambda[heaviest]) heaviest = m;
  }
  p_b = R * p_b + t;  // the weights sum to 1
  const Eigen::Matrix3d& R_B_A = X_B_A.linear();
  const Eigen::Vector3d& p_B_A = X_B_A.translation();
  if (contact) {
    out.distance = 0.0;
    out.penetrating = true;
    out.p_B_a = out.p_B_b = R_B_A * (0.5 * (p_a + p_b)) + p_B_A;
  } else {
    out.p_B_a = R_B_A * p_a + p_B_A;
    out.p_B_b = R_B_A * p_b + p_B_A;
    out.distance = (out.p_B_a - out.p_B_b).norm();  // their distance, bit for bit, in B
  }
  if (warm != nullptr) {
    warm->vertex_a = s.ia[sub.idx[heaviest]];
    warm->vertex_b = s.ib[sub.idx[heaviest]];
  }
}

/// The search's tolerance for a problem of size sqrt(w2) (the largest |w| seen):
/// max(kConvexTolerance, 1e-9 |w|), without a square root below 1 m.
inline double searchTolerance(double w2) {
  static_assert(kConvexTolerance == 1e-9, "the 1 m threshold below assumes it");
  return w2 > 1.0 ? 1e-9 * std::sqrt(w2) : kConvexTolerance;
}

/// The gap between the extents of A and of B (placed in A's link frame by R, t) along e (from A
/// towards B), less the tolerance: a lower bound of their distance whatever e is.
double gapAlong(const ConvexPiece& a, const ConvexPiece& b, const Eigen::Matrix3d& R, const Eigen::Vector3d& t,
                const Eigen::Vector3d& e) noexcept {
  const Eigen::Vector3d e_b = -(R.transpose() * e);
  int ja = startVertex(a, e), jb = startVertex(b, e_b);
  supportPair(a, e, ja, b, e_b, jb);
  const Eigen::Vector3d w = a.vertices_L[ja] - (R * b.vertices_L[jb] + t);
  return -e.dot(w) / e.norm() - searchTolerance(w.squaredNorm());
}

/// A cold search's first support pair into the simplex's slot 0, towards B (`d`: the caller's
/// direction in A's frame, else B's bounding centre from A's), each climb from its piece's start
/// vertex for that direction, a proof's from the hint's vertices. True when that pair, or the hint's
/// axis, proves the distance above stop_above (`out` then holds the bound).
template <class Support>
[[gnu::always_inline]] inline bool coldStart(const ConvexPiece& a, const ConvexPiece& b, const Eigen::Matrix3d& R,
                                             const Eigen::Vector3d& t, Eigen::Vector3d d, double stop_above,
                                             ConvexHint* hint, int& ia, int& ib, Support&& support, const Simplex& s,
                                             ConvexDistance& out) {
  if (!(d.squaredNorm() > 0)) d = (R * b.bound_center_L + t) - a.bound_center_L;
  if (!(d.squaredNorm() > 0)) d = Eigen::Vector3d::UnitX();
  const bool proof = stop_above < std::numeric_limits<double>::infinity();
  // A proof climbs from where the last one ended (the same support pair unless vertices tie).
  const bool hinted = proof && hint != nullptr && hint->vertex_a >= 0 &&
                      hint->vertex_a < static_cast<int>(a.vertices_L.size()) && hint->vertex_b >= 0 &&
                      hint->vertex_b < static_cast<int>(b.vertices_L.size());
  auto fromStartVertices = [&] {
    ia = startVertex(a, d);
    ib = startVertex(b, -(R.transpose() * d));
  };
  if (hinted) {
    ia = hint->vertex_a;
    ib = hint->vertex_b;
  } else {
    fromStartVertices();
  }
  support(d, 0);
  if (hint != nullptr) {
    hint->vertex_a = ia;
    hint->vertex_b = ib;
  }
  // That support pair already bounds the distance: A's farthest point along d is A's support and
  // B's nearest is B's, so every point x of A - B has -d.x >= -d.w (the gap between the two
  // pieces' extents along d). A good guess of d (the caller's) often proves a far pair at once.
  if (proof) {
    const double lower = -d.dot(s.w[0]) / d.norm() - searchTolerance(s.w[0].squaredNorm());
    if (lower > stop_above) {
      out.above = true;
      out.distance = lower;
      if (hint != nullptr) hint->axis = d;
      return true;
    }
    // The direction that proved this pair far last time: its own support pair, the same bound.
    if (hint != nullptr && hint->axis.squaredNorm() > 0) {
      const double lower_e = gapAlong(a, b, R, t, hint->axis);
      if (lower_e > stop_above) {
        out.above = true;
        out.distance = lower_e;
        return true;
      }
    }
  }
  // The search goes on as without a hint: from the start vertices' climb.
  if (hinted) {
    fromStartVertices();
    support(d, 0);
  }
  return false;
}

}  // namespace

ConvexDistance computeConvexDistance(const ConvexPiece& a, const Eigen::Isometry3d& X_B_A, const ConvexPiece& b,
                                     const Eigen::Isometry3d& X_B_B, ConvexWarmStart* warm, double stop_above,
                                     const Eigen::Vector3d& towards_b, ConvexHint* hint) noexcept {
  constexpr int kMaxIterations = 64;
  ConvexDistance out;
  assert(!a.vertices_L.empty() && !b.vertices_L.empty());
  if (a.vertices_L.empty() || b.vertices_L.empty()) {  // broken invariant: the conservative answer
    out.penetrating = true;
    out.p_B_a = out.p_B_b = X_B_A.translation();
    return out;
  }
  // The search runs in A's link frame: B's vertices placed by X_A_B = X_B_A^-1 X_B_B (R, t), A's as
  // they are; only the witness points go back to B.
  const Eigen::Matrix3d R_B_A = X_B_A.linear();
  const Eigen::Matrix3d R = R_B_A.transpose() * X_B_B.linear();
  const Eigen::Vector3d t = R_B_A.transpose() * (X_B_B.translation() - X_B_A.translation());

  // Support point of A - B in direction d (frame A): s_A(d) - s_B(-d), B's direction taken into its
  // link frame (R^T d) so that only its chosen vertex is transformed.
  int ia = 0, ib = 0;
  Simplex s;
  auto support = [&](const Eigen::Vector3d& d, int m) {
    supportPair(a, d, ia, b, -(R.transpose() * d), ib);
    s.w[m] = a.vertices_L[ia] - (R * b.vertices_L[ib] + t);
    s.ia[m] = ia;
    s.ib[m] = ib;
  };

  if (warm != nullptr) {
    ia = std::clamp(warm->vertex_a, 0, static_cast<int>(a.vertices_L.size()) - 1);
    ib = std::clamp(warm->vertex_b, 0, static_cast<int>(b.vertices_L.size()) - 1);
    s.w[0] = a.vertices_L[ia] - (R * b.vertices_L[ib] + t);
    s.ia[0] = ia;
    s.ib[0] = ib;
  } else if (coldStart(a, b, R, t, R_B_A.transpose() * towards_b, stop_above, hint, ia, ib, support, s, out)) {
    return out;
  }
  if (hint != nullptr) hint->axis.setZero();  // set again below if the search proves the pair far
  s.size = 1;
  SubResult sub;
  point(s.w, 0, sub);
  double w2_max = s.w[0].squaredNorm();  // the largest |w|^2 seen: the problem's size for the tolerance

  bool contact = false;
  for (int it = 0; it < kMaxIterations; ++it) {
    // Tolerance on the distance: absolute, or relative to the size where rounding would dominate.
    const double tol = searchTolerance(w2_max);
    if (!(sub.vv > tol * tol)) {  // origin inside (v = 0) or within the tolerance of A - B
      contact = true;
      break;
    }
    const Eigen::Vector3d v = sub.v;
    const int m = s.size;  // the slot of the new point (a full simplex has v = 0: contact above)
    assert(m < 4);
    support(-v, m);
    ++out.iterations;
    w2_max = std::max(w2_max, s.w[m].squaredNorm());
    // Every point x of A - B has v.x >= v.w (w is the support in -v): the distance is at least
    // v.w / |v|; less the tolerance, at most the distance this search would report (within tol of
    // the exact one), so the bound is below the answer too. Above stop_above the caller needs no more.
    const double vw = v.dot(s.w[m]);
    if (stop_above < std::numeric_limits<double>::infinity()) {
      const double lower = vw / std::sqrt(sub.vv) - tol;
      if (lower > stop_above) {
        out.above = true;
        out.distance = lower;
        if (hint != nullptr) hint->axis = -v;  // v points from B towards A
        return out;
      }
    }
    // Montanari Alg. 1's relative test as a bound on the error: |v| - d <= (|v|^2 - v.w) / |v|.
    const double gap = sub.vv - vw;  // >= 0 in exact arithmetic
    if (!(gap > 0 && gap * gap > tol * tol * sub.vv)) break;
    bool repeated = false;  // a vertex pair already in the simplex: no progress possible
    for (int k = 0; k < m; ++k) repeated = repeated || (s.ia[k] == ia && s.ib[k] == ib);
    if (repeated) break;
    s.size = m + 1;
    SubResult next;
    subDistance(s, next);
    // GJK decreases |v| strictly in exact arithmetic; a step that does not (rounding, or a simplex
    // too flat to resolve) ends the search with the best point found so far.
    if (!(next.vv < sub.vv)) {
      s.size = m;
      break;
    }
    reduce(s, next);
    sub = next;
  }

  witnessPoints(s, sub, contact, a, b, R, t, X_B_A, warm, out);
  return out;
}

}  // namespace reflex::control
