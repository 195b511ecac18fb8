// The fit (issue 12, item 1): primitives enclosing every vertex and triangle of a link's meshes.
//
// One primitive for a point set P and a direction u (unit): the radius R is that of the minimal
// enclosing circle of P projected on the plane normal to u (Welzl); the core segment along u runs
// from s0 = min_i(t_i + h_i) to s1 = max_i(t_i - h_i), t_i = p_i.u, h_i = sqrt(R^2 - rho_i^2), rho_i
// the projected distance from the circle's centre: the shortest core with that radius enclosing
// every point. When s1 <= s0 it is a sphere. u is searched from the principal axes and the frame axes,
// refined by local rotation steps (0.2 rad halving to 0.003 rad), minimising the volume; the result
// is compared with an approximate minimal enclosing sphere. Only the convex-hull vertices take part
// (qhull), which encloses the same set.
//
// Several primitives (up to FitOptions::max_primitives): the triangles (subdivided until every edge
// is shorter than a tenth of the link's extent, so each piece stays inside the triangle it came from)
// are split into clusters greedily: the cluster and cut (by triangle centroid along each principal
// axis of the cluster and each frame axis, at the 10, 20, ... 90 % quantiles) that reduce the summed
// volume most, or a connected piece of the cluster (>= 5 % of its triangles) against the rest
// (ranked with a quick fit: principal axis only, coarse steps; the chosen one refitted), improved by moving triangles to the primitive they fit best (refineSplit); repeated
// while the summed volume / the link's hull volume is above split_ratio and a cut gains at least
// min_split_gain of the summed volume. Greedy, so not optimal (README, "Meshes", gives the numbers).
// Each cluster's primitive encloses every vertex of its triangles, so every triangle is inside one
// primitive. Finally end points are rounded to FitOptions::quantum and radii recomputed from the
// points and rounded UP, so the written numbers keep the guarantee.
#include "reflex/control/mesh_fit.hpp"
#include "reflex/control/urdf_loader.hpp"

#include <Eigen/Eigenvalues>
#include <libqhull_r/qhull_ra.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <map>
#include <numeric>
#include <random>

namespace reflex::control {
namespace {

constexpr double kPi = 3.14159265358979323846;

double primitiveVolume(const Primitive& p) {
  const double len = p.sphere ? 0.0 : (p.b_L - p.a_L).norm();
  return kPi * p.radius * p.radius * len + 4.0 / 3.0 * kPi * p.radius * p.radius * p.radius;
}

double distanceToSegment(const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& p) {
  const Eigen::Vector3d ab = b - a;
  const double l2 = ab.squaredNorm();
  double t = l2 > 0.0 ? (p - a).dot(ab) / l2 : 0.0;
  t = std::clamp(t, 0.0, 1.0);
  return (a + t * ab - p).norm();
}

/// Deterministic shuffle (std::shuffle's algorithm is implementation-defined; this one is not).
template <class T>
void shuffleFixed(std::vector<T>& v) {
  std::mt19937 rng(12345u);
  for (std::size_t i = v.size(); i > 1; --i) std::swap(v[i - 1], v[rng() % i]);
}

struct Circle {
  Eigen::Vector2d c = Eigen::Vector2d::Zero();
  double r = 0.0;
};

bool outside(const Circle& c, const Eigen::Vector2d& p) { return (p - c.c).norm() > c.r * (1.0 + 1e-12) + 1e-15; }

Circle circleFrom2(const Eigen::Vector2d& a, const Eigen::Vector2d& b) {
  return {0.5 * (a + b), 0.5 * (a - b).norm()};
}

Circle circleFrom3(const Eigen::Vector2d& a, const Eigen::Vector2d& b, const Eigen::Vector2d& c) {
  const Eigen::Vector2d ab = b - a, ac = c - a;
  const double d = 2.0 * (ab.x() * ac.y() - ab.y() * ac.x());
  if (std::abs(d) < 1e-18) {  // collinear: the circle on the farthest pair
    Circle best = circleFrom2(a, b);
    for (const Circle& cand : {circleFrom2(a, c), circleFrom2(b, c)})
      if (cand.r > best.r) best = cand;
    return best;
  }
  const double ab2 = ab.squaredNorm(), ac2 = ac.squaredNorm();
  const Eigen::Vector2d off((ac.y() * ab2 - ab.y() * ac2) / d, (ab.x() * ac2 - ac.x() * ab2) / d);
  return {a + off, off.norm()};
}

/// Minimal enclosing circle (Welzl, iterative, points in a fixed shuffled order); the radius is then
/// recomputed as the largest distance, so every point is inside whatever the rounding.
Circle minEnclosingCircle(std::vector<Eigen::Vector2d> pts) {
  shuffleFixed(pts);
  Circle c{pts[0], 0.0};
  for (std::size_t i = 1; i < pts.size(); ++i) {
    if (!outside(c, pts[i])) continue;
    c = {pts[i], 0.0};
    for (std::size_t j = 0; j < i; ++j) {
      if (!outside(c, pts[j])) continue;
      c = circleFrom2(pts[i], pts[j]);
      for (std::size_t k = 0; k < j; ++k)
        if (outside(c, pts[k])) c = circleFrom3(pts[i], pts[j], pts[k]);
    }
  }
  double r = 0.0;
  for (const auto& p : pts) r = std::max(r, (p - c.c).norm());
  c.r = r;
  return c;
}

/// The tightest capsule (or sphere) with core along u (see the opening block).
Primitive capsuleAlong(const std::vector<Eigen::Vector3d>& pts, const Eigen::Vector3d& u_in) {
  const Eigen::Vector3d u = u_in.normalized();
  const Eigen::Vector3d e1 = u.unitOrthogonal();
  const Eigen::Vector3d e2 = u.cross(e1);
  std::vector<Eigen::Vector2d> proj(pts.size());
  for (std::size_t i = 0; i < pts.size(); ++i) proj[i] = Eigen::Vector2d(pts[i].dot(e1), pts[i].dot(e2));
  const Circle c = minEnclosingCircle(proj);
  double s0 = std::numeric_limits<double>::infinity(), s1 = -s0;
  for (std::size_t i = 0; i < pts.size(); ++i) {
    const double t = pts[i].dot(u);
    const double rho2 = (proj[i] - c.c).squaredNorm();
    const double h = std::sqrt(std::max(0.0, c.r * c.r - rho2));
    s0 = std::min(s0, t + h);
    s1 = std::max(s1, t - h);
  }
  const Eigen::Vector3d centre = c.c.x() * e1 + c.c.y() * e2;
  Primitive p;
  if (s1 <= s0) {
    p.a_L = p.b_L = centre + 0.5 * (s0 + s1) * u;
    p.sphere = true;
  } else {
    p.a_L = centre + s0 * u;
    p.b_L = centre + s1 * u;
    p.sphere = false;
  }
  double r = 0.0;
  for (const auto& q : pts) r = std::max(r, distanceToSegment(p.a_L, p.b_L, q));
  p.radius = r;
  return p;
}

/// Approximate minimal enclosing sphere (Badoiu-Clarkson iterations), radius = largest distance.
Primitive enclosingSphere(const std::vector<Eigen::Vector3d>& pts) {
  Eigen::Vector3d c = pts[0];
  for (int k = 1; k <= 400; ++k) {
    std::size_t far = 0;
    double dmax = -1.0;
    for (std::size_t i = 0; i < pts.size(); ++i) {
      const double d = (pts[i] - c).squaredNorm();
      if (d > dmax) dmax = d, far = i;
    }
    c += (pts[far] - c) / (k + 1.0);
  }
  Primitive p;
  p.a_L = p.b_L = c;
  double r = 0.0;
  for (const auto& q : pts) r = std::max(r, (q - c).norm());
  p.radius = r;
  p.sphere = true;
  return p;
}

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

/// Convex hull of pts with qhull: its vertex indices and volume. A flat or tiny set (qhull refuses
/// it) gives all indices and volume 0.
struct Hull {
  std::vector<int> vertices;
  double volume = 0.0;
};

Hull convexHull(const std::vector<Eigen::Vector3d>& pts) {
  Hull hull;
  if (pts.size() >= 4) {
    std::vector<coordT> coords(3 * pts.size());
    for (std::size_t i = 0; i < pts.size(); ++i)
      for (int k = 0; k < 3; ++k) coords[3 * i + k] = pts[i][k];
    qhT qh_qh;
    qhT* qh = &qh_qh;
    FILE* devnull = std::fopen("/dev/null", "w");
    qh_zero(qh, devnull);
    char options[] = "qhull Qt";
    const int exitcode = qh_new_qhull(qh, 3, static_cast<int>(pts.size()), coords.data(), False, options, nullptr, devnull);
    if (!exitcode) {
      qh_getarea(qh, qh->facet_list);
      hull.volume = qh->totvol;
      vertexT* vertex;
      FORALLvertices hull.vertices.push_back(qh_pointid(qh, vertex->point));
    }
    qh_freeqhull(qh, !qh_ALL);
    int curlong = 0, totlong = 0;
    qh_memfreeshort(qh, &curlong, &totlong);
    if (devnull) std::fclose(devnull);
  }
  if (hull.vertices.empty()) {
    hull.vertices.resize(pts.size());
    std::iota(hull.vertices.begin(), hull.vertices.end(), 0);
    hull.volume = 0.0;
  }
  std::sort(hull.vertices.begin(), hull.vertices.end());
  return hull;
}

/// The smallest-volume single primitive enclosing pts (see the opening block).
Primitive fitOne(const std::vector<Eigen::Vector3d>& all, bool quick = false) {
  const Hull hull = convexHull(all);
  std::vector<Eigen::Vector3d> pts;
  pts.reserve(hull.vertices.size());
  for (int i : hull.vertices) pts.push_back(all[i]);
  Primitive best = enclosingSphere(pts);
  double best_volume = primitiveVolume(best);
  if (pts.size() < 2) return best;
  const Eigen::Matrix3d axes = principalAxes(pts);
  std::vector<Eigen::Vector3d> starts{axes.col(2), axes.col(1), axes.col(0), Eigen::Vector3d::UnitX(),
                                      Eigen::Vector3d::UnitY(), Eigen::Vector3d::UnitZ()};
  if (quick) starts.resize(1);  // the principal axis only, coarse steps: to rank candidate cuts
  for (const Eigen::Vector3d& start : starts) {
    Eigen::Vector3d u = start;
    Primitive cur = capsuleAlong(pts, u);
    double cur_volume = primitiveVolume(cur);
    for (double step = 0.2; step > (quick ? 0.04 : 0.003); step *= 0.5) {
      bool improved = true;
      for (int iter = 0; improved && iter < 20; ++iter) {
        improved = false;
        const Eigen::Vector3d e1 = u.unitOrthogonal();
        const Eigen::Vector3d e2 = u.cross(e1);
        const std::array<Eigen::Vector3d, 4> dirs{e1, Eigen::Vector3d(-e1), e2, Eigen::Vector3d(-e2)};
        for (const Eigen::Vector3d& dir : dirs) {
          const Eigen::Vector3d v = (std::cos(step) * u + std::sin(step) * dir).normalized();
          const Primitive cand = capsuleAlong(pts, v);
          const double vol = primitiveVolume(cand);
          if (vol < cur_volume * (1.0 - 1e-9)) {
            cur = cand, cur_volume = vol, u = v, improved = true;
            break;
          }
        }
      }
    }
    if (cur_volume < best_volume) best = cur, best_volume = cur_volume;
  }
  return best;
}

struct Cluster {
  std::vector<int> triangles;  ///< indices into the subdivided triangles
  Primitive prim;
  double volume = 0.0;
};

std::vector<Eigen::Vector3d> clusterPoints(const TriangleMesh& mesh, const std::vector<int>& tris) {
  std::vector<int> ids;
  ids.reserve(3 * tris.size());
  for (int t : tris)
    for (int k = 0; k < 3; ++k) ids.push_back(mesh.triangles[t][k]);
  std::sort(ids.begin(), ids.end());
  ids.erase(std::unique(ids.begin(), ids.end()), ids.end());
  std::vector<Eigen::Vector3d> pts;
  pts.reserve(ids.size());
  for (int i : ids) pts.push_back(mesh.vertices[i]);
  return pts;
}

Cluster makeCluster(const TriangleMesh& mesh, std::vector<int> tris, bool quick = false) {
  Cluster c;
  c.triangles = std::move(tris);
  c.prim = fitOne(clusterPoints(mesh, c.triangles), quick);
  c.volume = primitiveVolume(c.prim);
  return c;
}

/// Improves a cut (Lloyd-like): each triangle goes to the primitive its vertices stick out of least
/// (deepest inside), both are refitted; kept while the summed volume decreases (at most 4 rounds).
void refineSplit(const TriangleMesh& mesh, Cluster& a, Cluster& b) {
  for (int round = 0; round < 4; ++round) {
    std::vector<int> ta, tb;
    for (const std::vector<int>* from : {&a.triangles, &b.triangles})
      for (int t : *from) {
        double ca = -std::numeric_limits<double>::infinity(), cb = ca;
        for (int k = 0; k < 3; ++k) {
          const Eigen::Vector3d& v = mesh.vertices[mesh.triangles[t][k]];
          ca = std::max(ca, distanceToSegment(a.prim.a_L, a.prim.b_L, v) - a.prim.radius);
          cb = std::max(cb, distanceToSegment(b.prim.a_L, b.prim.b_L, v) - b.prim.radius);
        }
        (ca <= cb ? ta : tb).push_back(t);
      }
    if (ta.empty() || tb.empty()) return;
    std::sort(ta.begin(), ta.end());
    std::sort(tb.begin(), tb.end());
    if (ta == a.triangles && tb == b.triangles) return;
    Cluster na = makeCluster(mesh, std::move(ta)), nb = makeCluster(mesh, std::move(tb));
    if (!(na.volume + nb.volume < a.volume + b.volume)) return;
    a = std::move(na), b = std::move(nb);
  }
}

/// Triangles subdivided (midpoints) until every edge is at most max_edge (at most 6 levels).
TriangleMesh subdivide(const TriangleMesh& in, double max_edge) {
  TriangleMesh out;
  out.vertices = in.vertices;
  std::vector<std::array<int, 3>> todo = in.triangles;
  for (int level = 0; level < 6 && !todo.empty(); ++level) {
    std::vector<std::array<int, 3>> next;
    for (const auto& t : todo) {
      const auto& a = out.vertices[t[0]];
      const auto& b = out.vertices[t[1]];
      const auto& c = out.vertices[t[2]];
      const double longest = std::max({(a - b).norm(), (b - c).norm(), (c - a).norm()});
      if (!(longest > max_edge) || level == 5) {
        out.triangles.push_back(t);
        continue;
      }
      const int ab = static_cast<int>(out.vertices.size());
      out.vertices.push_back(0.5 * (a + b));
      out.vertices.push_back(0.5 * (out.vertices[t[1]] + out.vertices[t[2]]));
      out.vertices.push_back(0.5 * (out.vertices[t[2]] + out.vertices[t[0]]));
      const int bc = ab + 1, ca = ab + 2;
      next.push_back({t[0], ab, ca});
      next.push_back({ab, t[1], bc});
      next.push_back({ca, bc, t[2]});
      next.push_back({ab, bc, ca});
    }
    todo.swap(next);
  }
  for (const auto& t : todo) out.triangles.push_back(t);
  return out;
}

double pointTriangleDistance(const Eigen::Vector3d& p, const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                             const Eigen::Vector3d& c) {
  const Eigen::Vector3d n = (b - a).cross(c - a);
  const double n2 = n.squaredNorm();
  if (n2 > 1e-30) {  // the projection inside the triangle: the plane distance
    const Eigen::Vector3d q = p - n * ((p - a).dot(n) / n2);
    const double u = (b - q).cross(c - q).dot(n), v = (c - q).cross(a - q).dot(n), w = (a - q).cross(b - q).dot(n);
    if (u >= 0 && v >= 0 && w >= 0) return (p - q).norm();
  }
  return std::min({distanceToSegment(a, b, p), distanceToSegment(b, c, p), distanceToSegment(c, a, p)});
}

/// Points on the primitive's surface: a Fibonacci sphere split at the equator onto the two caps,
/// and rings on the cylinder, about `n` in all.
std::vector<Eigen::Vector3d> surfaceSamples(const Primitive& p, int n) {
  std::vector<Eigen::Vector3d> out;
  const Eigen::Vector3d axis = p.sphere ? Eigen::Vector3d::UnitZ() : Eigen::Vector3d((p.b_L - p.a_L).normalized());
  const Eigen::Vector3d e1 = axis.unitOrthogonal(), e2 = axis.cross(e1);
  const double len = p.sphere ? 0.0 : (p.b_L - p.a_L).norm();
  const double cap_area = 4.0 * kPi * p.radius * p.radius, side_area = 2.0 * kPi * p.radius * len;
  const int n_sphere = std::max(50, static_cast<int>(n * cap_area / (cap_area + side_area)));
  const double golden = kPi * (3.0 - std::sqrt(5.0));
  for (int i = 0; i < n_sphere; ++i) {
    const double z = 1.0 - 2.0 * (i + 0.5) / n_sphere;
    const double rr = std::sqrt(std::max(0.0, 1.0 - z * z));
    const Eigen::Vector3d d = rr * std::cos(golden * i) * e1 + rr * std::sin(golden * i) * e2 + z * axis;
    out.push_back((z >= 0 ? p.b_L : p.a_L) + p.radius * d);
  }
  if (len > 0) {
    const int rings = std::max(2, static_cast<int>(std::sqrt(std::max(1, n - n_sphere) * len / (2 * kPi * p.radius))));
    const int per_ring = std::max(8, (n - n_sphere) / rings);
    for (int r = 0; r < rings; ++r)
      for (int k = 0; k < per_ring; ++k) {
        const double ang = 2.0 * kPi * (k + 0.5 * (r % 2)) / per_ring;
        out.push_back(p.a_L + (r + 0.5) / rings * (p.b_L - p.a_L) +
                      p.radius * (std::cos(ang) * e1 + std::sin(ang) * e2));
      }
  }
  return out;
}

double roundTo(double v, double q) { return std::round(v / q) * q; }

}  // namespace

double signedDistanceToPrimitive(const Primitive& prim, const Eigen::Vector3d& p) {
  return distanceToSegment(prim.a_L, prim.b_L, p) - prim.radius;
}

std::vector<Primitive> fitPrimitives(const TriangleMesh& mesh, const FitOptions& options, FitStats* stats) {
  if (mesh.vertices.empty() || mesh.triangles.empty()) throw ModelError("fit: the mesh has no triangles");
  // Vertices that belong to no triangle still count (they are vertices of the link's meshes).
  TriangleMesh work = mesh;
  std::vector<char> used(mesh.vertices.size(), 0);
  for (const auto& t : mesh.triangles)
    for (int k = 0; k < 3; ++k) {
      if (t[k] < 0 || t[k] >= static_cast<int>(mesh.vertices.size())) throw ModelError("fit: triangle index out of range");
      used[t[k]] = 1;
    }
  for (std::size_t i = 0; i < mesh.vertices.size(); ++i)
    if (!used[i]) work.triangles.push_back({int(i), int(i), int(i)});
  const Hull hull = convexHull(mesh.vertices);
  Eigen::Vector3d lo = mesh.vertices[0], hi = mesh.vertices[0];
  for (const auto& v : mesh.vertices) lo = lo.cwiseMin(v), hi = hi.cwiseMax(v);
  const double extent = (hi - lo).norm();
  if (options.max_primitives > 1) work = subdivide(work, 0.1 * extent);

  // Connected pieces (shared vertices) of the triangles: a piece against the rest of its cluster is a
  // candidate cut too (a T-shaped torso of two shells, a box element beside a mesh, fingers).
  std::vector<int> parent(work.vertices.size());
  std::iota(parent.begin(), parent.end(), 0);
  auto root = [&](int v) {
    while (parent[v] != v) v = parent[v] = parent[parent[v]];
    return v;
  };
  for (const auto& t : work.triangles) parent[root(t[1])] = root(t[0]), parent[root(t[2])] = root(t[0]);
  std::vector<int> piece(work.triangles.size());
  for (std::size_t t = 0; t < work.triangles.size(); ++t) piece[t] = root(work.triangles[t][0]);

  std::vector<int> all(work.triangles.size());
  std::iota(all.begin(), all.end(), 0);
  std::vector<Cluster> clusters{makeCluster(work, all)};
  auto total = [&] {
    double sum = 0.0;
    for (const auto& c : clusters) sum += c.volume;
    return sum;
  };
  while (static_cast<int>(clusters.size()) < options.max_primitives && hull.volume > 0.0 &&
         total() / hull.volume > options.split_ratio) {
    double best_gain = 0.0;
    std::size_t best_cluster = 0;
    Cluster best_a, best_b;
    for (std::size_t ci = 0; ci < clusters.size(); ++ci) {
      const Cluster& c = clusters[ci];
      if (c.triangles.size() < 2) continue;
      std::vector<Eigen::Vector3d> centroids;
      for (int t : c.triangles)
        centroids.push_back((work.vertices[work.triangles[t][0]] + work.vertices[work.triangles[t][1]] +
                             work.vertices[work.triangles[t][2]]) / 3.0);
      auto consider = [&](std::vector<int> ta, std::vector<int> tb) {
        Cluster a = makeCluster(work, std::move(ta), true), b = makeCluster(work, std::move(tb), true);
        const double gain = c.volume - a.volume - b.volume;
        if (gain > best_gain) best_gain = gain, best_cluster = ci, best_a = std::move(a), best_b = std::move(b);
      };
      std::map<int, int> piece_size;
      for (int t : c.triangles) ++piece_size[piece[t]];
      if (piece_size.size() > 1) {
        std::vector<std::pair<int, int>> pieces;  // (-size, piece): the largest first, ties by id
        for (const auto& [id, n] : piece_size)
          if (20 * n >= static_cast<int>(c.triangles.size())) pieces.push_back({-n, id});
        std::sort(pieces.begin(), pieces.end());
        if (pieces.size() > 8) pieces.resize(8);
        for (const auto& pc : pieces) {
          std::vector<int> ta, tb;
          for (int t : c.triangles) (piece[t] == pc.second ? ta : tb).push_back(t);
          consider(std::move(ta), std::move(tb));
        }
      }
      const Eigen::Matrix3d pca = principalAxes(centroids);
      const std::array<Eigen::Vector3d, 6> axes{pca.col(2), pca.col(1), pca.col(0), Eigen::Vector3d::UnitX(),
                                                Eigen::Vector3d::UnitY(), Eigen::Vector3d::UnitZ()};
      for (const Eigen::Vector3d& axis : axes) {
        std::vector<std::pair<double, int>> order;
        for (std::size_t i = 0; i < c.triangles.size(); ++i) order.push_back({centroids[i].dot(axis), c.triangles[i]});
        std::sort(order.begin(), order.end());
        for (double q : {0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9}) {
          const std::size_t cut = static_cast<std::size_t>(q * order.size());
          if (cut == 0 || cut >= order.size()) continue;
          std::vector<int> ta, tb;
          for (std::size_t i = 0; i < order.size(); ++i) (i < cut ? ta : tb).push_back(order[i].second);
          std::sort(ta.begin(), ta.end());
          std::sort(tb.begin(), tb.end());
          consider(std::move(ta), std::move(tb));
        }
      }
    }
    if (!(best_gain > 0.0)) break;  // no cut helps (best_a, best_b are empty)
    best_a = makeCluster(work, std::move(best_a.triangles));  // the full fit of the chosen cut
    best_b = makeCluster(work, std::move(best_b.triangles));
    refineSplit(work, best_a, best_b);
    best_gain = clusters[best_cluster].volume - best_a.volume - best_b.volume;
    if (!(best_gain >= options.min_split_gain * total())) break;
    clusters[best_cluster] = std::move(best_a);
    clusters.insert(clusters.begin() + static_cast<long>(best_cluster) + 1, std::move(best_b));
  }

  // Round end points to the quantum, recompute each radius from its cluster's points, round it up.
  std::vector<Primitive> prims;
  for (const auto& c : clusters) {
    Primitive p = c.prim;
    for (int k = 0; k < 3; ++k) p.a_L[k] = roundTo(p.a_L[k], options.quantum), p.b_L[k] = roundTo(p.b_L[k], options.quantum);
    if (p.sphere || (p.b_L - p.a_L).norm() < options.quantum) p.b_L = p.a_L, p.sphere = true;
    double r = 0.0;
    for (const auto& q : clusterPoints(work, c.triangles)) r = std::max(r, distanceToSegment(p.a_L, p.b_L, q));
    p.radius = std::max(options.quantum, std::ceil(r / options.quantum + 1e-6) * options.quantum);
    prims.push_back(p);
  }

  if (stats) *stats = measureFit(mesh, prims, options, hull.volume);
  return prims;
}

FitStats measureFit(const TriangleMesh& mesh, const std::vector<Primitive>& prims, const FitOptions& options,
                    double hull_volume) {
  FitStats s;
  s.vertices = static_cast<int>(mesh.vertices.size());
  s.triangles = static_cast<int>(mesh.triangles.size());
  for (const auto& v : mesh.vertices) {
    bool inside = false;
    for (const auto& p : prims) inside = inside || signedDistanceToPrimitive(p, v) <= 0.0;
    s.vertices_enclosed += inside ? 1 : 0;
  }
  s.hull_volume = hull_volume >= 0.0 ? hull_volume : convexHull(mesh.vertices).volume;
  for (const auto& p : prims) s.fitted_volume += primitiveVolume(p);
  s.volume_ratio = s.hull_volume > 0 ? s.fitted_volume / s.hull_volume : 0.0;
  for (std::size_t i = 0; i < prims.size(); ++i)
    for (const auto& x : surfaceSamples(prims[i], options.gap_samples_per_primitive)) {
      bool covered = false;  // inside another primitive: not on the union's outer surface
      for (std::size_t j = 0; j < prims.size() && !covered; ++j)
        covered = j != i && signedDistanceToPrimitive(prims[j], x) < -1e-9;
      if (covered) continue;
      double d = std::numeric_limits<double>::infinity();
      for (const auto& t : mesh.triangles)
        d = std::min(d, pointTriangleDistance(x, mesh.vertices[t[0]], mesh.vertices[t[1]], mesh.vertices[t[2]]));
      s.worst_gap = std::max(s.worst_gap, d);
    }
  return s;
}

TriangleMesh boxMesh(const Eigen::Vector3d& size, const Eigen::Isometry3d& X_L_B) {
  TriangleMesh m;
  for (int i = 0; i < 8; ++i)
    m.vertices.push_back(X_L_B * Eigen::Vector3d((i & 1 ? 0.5 : -0.5) * size.x(), (i & 2 ? 0.5 : -0.5) * size.y(),
                                                 (i & 4 ? 0.5 : -0.5) * size.z()));
  m.triangles = {{0, 2, 1}, {1, 2, 3}, {4, 5, 6}, {5, 7, 6}, {0, 1, 4}, {1, 5, 4},
                 {2, 6, 3}, {3, 6, 7}, {0, 4, 2}, {2, 4, 6}, {1, 3, 5}, {3, 7, 5}};
  return m;
}

std::vector<Primitive> fitBox(const Eigen::Vector3d& size, const Eigen::Isometry3d& X_L_B, const FitOptions& options) {
  if (!(size.minCoeff() > 0.0) || !size.allFinite())
    throw ModelError("fit: box size " + std::to_string(size.x()) + " " + std::to_string(size.y()) + " " +
                     std::to_string(size.z()) + " must be positive");
  // A grid of n1 x n2 equal cells across the box, one primitive per cell along `axis`. A cell's
  // corners lie at radial distance rc (half its cross-section's diagonal) from its centre line, so a
  // capsule of radius r >= rc along it encloses the cell when its core reaches within
  // sqrt(r^2 - rc^2) of each end face: half-core h = max(0, L/2 - sqrt(r^2 - rc^2)) (a sphere at 0).
  // r is searched over [rc, sqrt(rc^2 + L^2/4)] for the least volume (sampled, then bracketed).
  struct Grid {
    int axis = 0, n1 = 1, n2 = 1;
    double r = 0.0, h = 0.0, volume = std::numeric_limits<double>::infinity();
  };
  const int max_prims = std::max(1, options.max_primitives);
  std::vector<Grid> best_of(static_cast<std::size_t>(max_prims) + 1);  // [k]: the least volume with k cells
  for (int axis = 0; axis < 3; ++axis) {
    const int i1 = (axis + 1) % 3, i2 = (axis + 2) % 3;
    const double L = size[axis];
    for (int n1 = 1; n1 <= max_prims; ++n1)
      for (int n2 = 1; n1 * n2 <= max_prims; ++n2) {
        const double rc = 0.5 * std::hypot(size[i1] / n1, size[i2] / n2);
        auto halfCore = [&](double r) { return std::max(0.0, 0.5 * L - std::sqrt(std::max(0.0, r * r - rc * rc))); };
        auto volume = [&](double r) { return n1 * n2 * (kPi * r * r * 2.0 * halfCore(r) + 4.0 / 3.0 * kPi * r * r * r); };
        const double r_hi = std::hypot(rc, 0.5 * L);
        constexpr int kSteps = 200;
        int best_step = 0;
        for (int k = 1; k <= kSteps; ++k)
          if (volume(rc + (r_hi - rc) * k / kSteps) < volume(rc + (r_hi - rc) * best_step / kSteps)) best_step = k;
        double lo = rc + (r_hi - rc) * std::max(0, best_step - 1) / kSteps;
        double hi = rc + (r_hi - rc) * std::min(kSteps, best_step + 1) / kSteps;
        for (int it = 0; it < 60; ++it) {  // golden-section search inside the bracket
          const double m1 = hi - 0.618033988749895 * (hi - lo), m2 = lo + 0.618033988749895 * (hi - lo);
          if (volume(m1) <= volume(m2))
            hi = m2;
          else
            lo = m1;
        }
        Grid g{axis, n1, n2, 0.5 * (lo + hi), halfCore(0.5 * (lo + hi)), volume(0.5 * (lo + hi))};
        if (volume(rc + (r_hi - rc) * best_step / kSteps) < g.volume)
          g.r = rc + (r_hi - rc) * best_step / kSteps, g.h = halfCore(g.r), g.volume = volume(g.r);
        Grid& slot = best_of[static_cast<std::size_t>(n1 * n2)];
        if (g.volume < slot.volume) slot = g;
      }
  }
  // From one cell up, as the mesh fit splits: the step to more cells with the largest saving per
  // added primitive, taken while it saves at least min_split_gain of the current volume, and none
  // once the volume is within split_ratio of the box's.
  const double box_volume = size.prod();
  std::size_t k = 1;
  for (;;) {
    if (best_of[k].volume <= options.split_ratio * box_volume) break;
    std::size_t next = 0;
    double best_rate = 0.0;
    for (std::size_t m = k + 1; m < best_of.size(); ++m) {
      const double rate = (best_of[k].volume - best_of[m].volume) / static_cast<double>(m - k);
      if (rate > best_rate) best_rate = rate, next = m;
    }
    if (next == 0 || !(best_of[k].volume - best_of[next].volume >= options.min_split_gain * best_of[k].volume)) break;
    k = next;
  }
  const Grid* chosen = &best_of[k];
  const int a = chosen->axis, i1 = (a + 1) % 3, i2 = (a + 2) % 3;
  std::vector<Primitive> prims;
  for (int c1 = 0; c1 < chosen->n1; ++c1)
    for (int c2 = 0; c2 < chosen->n2; ++c2) {
      // The cell (box frame): centre and half extents.
      Eigen::Vector3d centre = Eigen::Vector3d::Zero(), half = 0.5 * size;
      centre[i1] = -0.5 * size[i1] + (c1 + 0.5) * size[i1] / chosen->n1;
      centre[i2] = -0.5 * size[i2] + (c2 + 0.5) * size[i2] / chosen->n2;
      half[i1] = 0.5 * size[i1] / chosen->n1;
      half[i2] = 0.5 * size[i2] / chosen->n2;
      Eigen::Vector3d core = Eigen::Vector3d::Zero();
      core[a] = chosen->h;
      Primitive p;
      p.a_L = X_L_B * (centre - core);
      p.b_L = X_L_B * (centre + core);
      for (int k = 0; k < 3; ++k) p.a_L[k] = roundTo(p.a_L[k], options.quantum), p.b_L[k] = roundTo(p.b_L[k], options.quantum);
      p.sphere = !((p.b_L - p.a_L).norm() >= options.quantum);
      if (p.sphere) p.b_L = p.a_L;
      // The radius from the cell's 8 corners after rounding, rounded up: the cell (convex) is inside.
      double r = 0.0;
      for (int k = 0; k < 8; ++k) {
        const Eigen::Vector3d corner(k & 1 ? half.x() : -half.x(), k & 2 ? half.y() : -half.y(), k & 4 ? half.z() : -half.z());
        r = std::max(r, distanceToSegment(p.a_L, p.b_L, X_L_B * (centre + corner)));
      }
      p.radius = std::max(options.quantum, std::ceil(r / options.quantum + 1e-6) * options.quantum);
      prims.push_back(p);
    }
  return prims;
}

}  // namespace reflex::control
