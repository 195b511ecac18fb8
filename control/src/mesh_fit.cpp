// The fit: primitives enclosing every vertex and triangle of a link's meshes.
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

Circle circleFrom2(const Eigen::Vector2d& a, const Eigen::Vector2d& b) { return {0.5 * (a + b), 0.5 * (a - b).norm()}; }

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

/// Convex hull of pts with qhull: its vertex indices and volume. A flat or tiny set (qhull refuses
/// it) gives all indices and volume 0.
struct Hull {
  std::vector<int> vertices;
  double volume = 0.0;
};

/// qhull ("Qt": triangulated facets) on pts: the hull's vertex ids (ascending), its facets (ids) and
/// volume; no vertex when qhull refuses the set (flat, tiny, fewer than 4 points).
struct QhullResult {
  std::vector<int> vertices;
  std::vector<std::array<int, 3>> facets;
  double volume = 0.0;
};

QhullResult runQhull(const std::vector<Eigen::Vector3d>& pts) {
  QhullResult r;
  if (pts.size() < 4) return r;
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
  if (!exitcode) {
    qh_getarea(qh, qh->facet_list);
    r.volume = qh->totvol;
    vertexT* vertex;
    FORALLvertices r.vertices.push_back(qh_pointid(qh, vertex->point));
    facetT* facet;
    FORALLfacets {
      std::array<int, 3> t{};
      int n = 0;
      vertexT** vertexp;
      FOREACHvertex_(facet->vertices) {
        if (n < 3) t[n] = qh_pointid(qh, vertex->point);
        ++n;
      }
      if (n == 3) r.facets.push_back(t);
    }
  }
  qh_freeqhull(qh, !qh_ALL);
  int curlong = 0, totlong = 0;
  qh_memfreeshort(qh, &curlong, &totlong);
  if (devnull) std::fclose(devnull);
  std::sort(r.vertices.begin(), r.vertices.end());
  return r;
}

Hull convexHull(const std::vector<Eigen::Vector3d>& pts) {
  const QhullResult q = runQhull(pts);
  Hull hull;
  hull.vertices = q.vertices;
  hull.volume = q.volume;
  if (hull.vertices.empty()) {
    hull.vertices.resize(pts.size());
    std::iota(hull.vertices.begin(), hull.vertices.end(), 0);
    hull.volume = 0.0;
  }
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
  std::vector<Eigen::Vector3d> starts{axes.col(2),
                                      axes.col(1),
                                      axes.col(0),
                                      Eigen::Vector3d::UnitX(),
                                      Eigen::Vector3d::UnitY(),
                                      Eigen::Vector3d::UnitZ()};
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

/// Calls consider(ta, tb) for every candidate cut of the triangles `tris` of `work` in two: each of the
/// (at most 8 largest) connected shells holding at least `min_shell_share` of them against the rest,
/// then, along each principal axis of their centroids and each frame axis, the cut at the 10, 20, ..
/// 90 % quantiles of the centroids (both sides sorted). Deterministic.
enum class Cuts { kBoth, kShells, kAxes };
template <class Consider>
void forEachCut(const TriangleMesh& work, const std::vector<int>& tris, const std::vector<int>& shell,
                double min_shell_share, Consider&& consider, Cuts which = Cuts::kBoth) {
  std::vector<Eigen::Vector3d> centroids;
  for (int t : tris)
    centroids.push_back((work.vertices[work.triangles[t][0]] + work.vertices[work.triangles[t][1]] +
                         work.vertices[work.triangles[t][2]]) /
                        3.0);
  std::map<int, int> shell_size;
  for (int t : tris) ++shell_size[shell[t]];
  if (which != Cuts::kAxes && shell_size.size() > 1) {
    std::vector<std::pair<int, int>> shells;  // (-size, id): the largest first, ties by id
    for (const auto& [id, n] : shell_size)
      if (n >= min_shell_share * static_cast<double>(tris.size())) shells.push_back({-n, id});
    std::sort(shells.begin(), shells.end());
    if (shells.size() > 8) shells.resize(8);
    for (const auto& sh : shells) {
      std::vector<int> ta, tb;
      for (int t : tris) (shell[t] == sh.second ? ta : tb).push_back(t);
      consider(std::move(ta), std::move(tb));
    }
  }
  if (which == Cuts::kShells) return;
  const Eigen::Matrix3d pca = principalAxes(centroids);
  const std::array<Eigen::Vector3d, 6> axes{
      pca.col(2), pca.col(1), pca.col(0), Eigen::Vector3d::UnitX(), Eigen::Vector3d::UnitY(), Eigen::Vector3d::UnitZ()};
  for (const Eigen::Vector3d& axis : axes) {
    std::vector<std::pair<double, int>> order;
    for (std::size_t i = 0; i < tris.size(); ++i) order.push_back({centroids[i].dot(axis), tris[i]});
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
      if (t[k] < 0 || t[k] >= static_cast<int>(mesh.vertices.size()))
        throw ModelError("fit: triangle index out of range");
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
      auto consider = [&](std::vector<int> ta, std::vector<int> tb) {
        Cluster a = makeCluster(work, std::move(ta), true), b = makeCluster(work, std::move(tb), true);
        const double gain = c.volume - a.volume - b.volume;
        if (gain > best_gain) best_gain = gain, best_cluster = ci, best_a = std::move(a), best_b = std::move(b);
      };
      forEachCut(work, c.triangles, piece, 0.05, consider);
    }
    if (!(best_gain > 0.0)) break;                            // no cut helps (best_a, best_b are empty)
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
    for (int k = 0; k < 3; ++k)
      p.a_L[k] = roundTo(p.a_L[k], options.quantum), p.b_L[k] = roundTo(p.b_L[k], options.quantum);
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
        auto volume = [&](double r) {
          return n1 * n2 * (kPi * r * r * 2.0 * halfCore(r) + 4.0 / 3.0 * kPi * r * r * r);
        };
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
      for (int k = 0; k < 3; ++k)
        p.a_L[k] = roundTo(p.a_L[k], options.quantum), p.b_L[k] = roundTo(p.b_L[k], options.quantum);
      p.sphere = !((p.b_L - p.a_L).norm() >= options.quantum);
      if (p.sphere) p.b_L = p.a_L;
      // The radius from the cell's 8 corners after rounding, rounded up: the cell (convex) is inside.
      double r = 0.0;
      for (int k = 0; k < 8; ++k) {
        const Eigen::Vector3d corner(k & 1 ? half.x() : -half.x(), k & 2 ? half.y() : -half.y(),
                                     k & 4 ? half.z() : -half.z());
        r = std::max(r, distanceToSegment(p.a_L, p.b_L, X_L_B * (centre + corner)));
      }
      p.radius = std::max(options.quantum, std::ceil(r / options.quantum + 1e-6) * options.quantum);
      prims.push_back(p);
    }
  return prims;
}

// ---- Convex pieces: the tight model ------------------------------------------------------------
//
// fitConvexPieces cuts a link's mesh into clusters of triangles and takes each cluster's convex hull
// (qhull) as a piece: every triangle lies in its cluster's hull, so the union of the pieces contains
// the mesh and a distance between pieces is never above the distance between the meshes. The cuts
// (greedy, deterministic) follow the worst GAP: the largest distance from a point of a piece's hull
// surface that lies outside the mesh's solid and outside every other piece to the mesh surface. That
// is how far the piece's surface can stand off the real surface, so how much shorter than the true
// distance a distance to it can be. While the worst gap is above options.piece_gap and the link has
// fewer than options.max_pieces pieces, the piece with the worst gap is cut in two: one connected
// shell against the rest (a mesh made of convex parts: a palm and its fingers) if any such cut makes
// progress, else a plane (by triangle centroid along its principal axes and the frame axes at the
// 10 .. 90 % quantiles); of those, the cut whose two hulls stand off the mesh least (their facets'
// centroids and edge midpoints), ties by the least summed volume; progress: smaller hulls or a
// smaller gap. "Outside the solid"
// is decided by the generalized winding number of the mesh (robust to small holes; a mesh with
// inconsistent winding only gets more cuts). Each piece then gets the capsule that encloses it (the
// broad phase's bound).
namespace {

/// An axis-aligned box tree over a mesh's triangles for point-to-surface distances (set-up only).
class TriangleTree {
 public:
  explicit TriangleTree(const TriangleMesh& mesh) : mesh_(mesh) {
    order_.resize(mesh.triangles.size());
    std::iota(order_.begin(), order_.end(), 0);
    if (!order_.empty()) build(0, static_cast<int>(order_.size()));
  }
  /// The distance from x to the mesh surface; as soon as it is known to be at most `enough`, some
  /// value <= `enough` is returned (the caller only needs to know that).
  double distance(const Eigen::Vector3d& x, double enough = -1.0) const {
    double best = std::numeric_limits<double>::infinity();
    if (nodes_.empty()) return best;
    int stack[128];
    int top = 0;
    stack[top++] = 0;
    while (top > 0) {
      const Node& n = nodes_[static_cast<std::size_t>(stack[--top])];
      if (n.box.exteriorDistance(x) >= best) continue;
      if (n.left < 0) {
        for (int k = n.begin; k < n.end; ++k) {
          const auto& t = mesh_.triangles[static_cast<std::size_t>(order_[static_cast<std::size_t>(k)])];
          best = std::min(best,
                          pointTriangleDistance(x, mesh_.vertices[t[0]], mesh_.vertices[t[1]], mesh_.vertices[t[2]]));
        }
        if (best <= enough) return best;
        continue;
      }
      const double dl = nodes_[static_cast<std::size_t>(n.left)].box.exteriorDistance(x);
      const double dr = nodes_[static_cast<std::size_t>(n.right)].box.exteriorDistance(x);
      if (top + 2 > 128) continue;  // depth bound (never reached: the tree is balanced)
      if (dl < dr) {
        stack[top++] = n.right;
        stack[top++] = n.left;
      } else {
        stack[top++] = n.left;
        stack[top++] = n.right;
      }
    }
    return best;
  }

 private:
  struct Node {
    Eigen::AlignedBox3d box;
    int left = -1, right = -1, begin = 0, end = 0;
  };
  int build(int begin, int end) {
    const int id = static_cast<int>(nodes_.size());
    nodes_.push_back(Node{});
    Eigen::AlignedBox3d box;
    Eigen::AlignedBox3d centres;
    for (int k = begin; k < end; ++k) {
      const auto& t = mesh_.triangles[static_cast<std::size_t>(order_[static_cast<std::size_t>(k)])];
      for (int j = 0; j < 3; ++j) box.extend(mesh_.vertices[t[j]]);
      centres.extend((mesh_.vertices[t[0]] + mesh_.vertices[t[1]] + mesh_.vertices[t[2]]) / 3.0);
    }
    nodes_[static_cast<std::size_t>(id)].box = box;
    nodes_[static_cast<std::size_t>(id)].begin = begin;
    nodes_[static_cast<std::size_t>(id)].end = end;
    if (end - begin <= 8) return id;
    int axis = 0;
    centres.sizes().maxCoeff(&axis);
    const int mid = (begin + end) / 2;
    auto centre = [&](int tri) {
      const auto& t = mesh_.triangles[static_cast<std::size_t>(tri)];
      return mesh_.vertices[t[0]][axis] + mesh_.vertices[t[1]][axis] + mesh_.vertices[t[2]][axis];
    };
    std::nth_element(order_.begin() + begin, order_.begin() + mid, order_.begin() + end,
                     [&](int a, int b) { return centre(a) < centre(b) || (centre(a) == centre(b) && a < b); });
    const int l = build(begin, mid);
    const int r = build(mid, end);
    nodes_[static_cast<std::size_t>(id)].left = l;
    nodes_[static_cast<std::size_t>(id)].right = r;
    return id;
  }
  const TriangleMesh& mesh_;
  std::vector<int> order_;
  std::vector<Node> nodes_;
};

struct PieceHull {
  std::vector<Eigen::Vector3d> points;        ///< hull vertices
  std::vector<std::array<int, 3>> triangles;  ///< indices into points (empty: flat or tiny)
  std::vector<Eigen::Vector4d> planes;        ///< outward unit normal (xyz) and offset: n.x <= w inside
  double volume = 0.0;
};

PieceHull pieceHull(const std::vector<Eigen::Vector3d>& pts) {
  PieceHull h;
  const QhullResult q = runQhull(pts);
  std::map<int, int> index;  // point id -> hull vertex index (ascending ids)
  for (const int id : q.vertices) {
    index[id] = static_cast<int>(h.points.size());
    h.points.push_back(pts[static_cast<std::size_t>(id)]);
  }
  for (const auto& f : q.facets) h.triangles.push_back({index[f[0]], index[f[1]], index[f[2]]});
  h.volume = q.volume;
  const bool ok = !h.triangles.empty();
  if (!ok) {  // flat, tiny or too few points: every distinct point, no facets (a support scan)
    h = PieceHull{};
    h.points = pts;
    std::sort(h.points.begin(), h.points.end(), [](const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
      return std::lexicographical_compare(a.data(), a.data() + 3, b.data(), b.data() + 3);
    });
    h.points.erase(std::unique(h.points.begin(), h.points.end()), h.points.end());
    return h;
  }
  Eigen::Vector3d centre = Eigen::Vector3d::Zero();
  for (const auto& p : h.points) centre += p;
  centre /= static_cast<double>(h.points.size());
  for (auto& t : h.triangles) {
    const Eigen::Vector3d& a = h.points[t[0]];
    Eigen::Vector3d n = (h.points[t[1]] - a).cross(h.points[t[2]] - a);
    const double len = n.norm();
    if (!(len > 0.0)) {
      h.planes.push_back(Eigen::Vector4d(0, 0, 0, 0));
      continue;
    }
    n /= len;
    if (n.dot(a - centre) < 0.0) {  // outward, and the triangle wound to match
      n = -n;
      std::swap(t[1], t[2]);
    }
    h.planes.push_back(Eigen::Vector4d(n.x(), n.y(), n.z(), n.dot(a)));
  }
  return h;
}

/// How far x lies outside the hull (max over its facet planes; < 0 inside). A hull without facets
/// contains nothing (+inf).
double outsideHull(const PieceHull& h, const Eigen::Vector3d& x) {
  if (h.planes.empty()) return std::numeric_limits<double>::infinity();
  double worst = -std::numeric_limits<double>::infinity();
  for (const auto& p : h.planes) worst = std::max(worst, p.head<3>().dot(x) - p[3]);
  return worst;
}

/// A point of a hull counts as inside the link's solid (never a gap) at this winding number or more.
/// Inside a closed mesh it is 1 (a cut's cap); across a hole of an open mesh (a head shell open at the
/// neck and the ears) it is fractional (about 0.5 in the hole's plane, 0.9-0.95 deep in the cavity):
/// such a point is empty space the hull closes over, a gap like any other (0.5 hid those gaps: a
/// shoulder in the cavity of iCub's head shell was reported touching, 45 mm from its triangles).
constexpr double kInsideWinding = 0.97;

/// The generalized winding number of the mesh at x (1 inside a closed outward-wound mesh, 0 outside).
double windingNumber(const TriangleMesh& mesh, const Eigen::Vector3d& x) {
  double sum = 0.0;
  for (const auto& t : mesh.triangles) {
    const Eigen::Vector3d a = mesh.vertices[t[0]] - x, b = mesh.vertices[t[1]] - x, c = mesh.vertices[t[2]] - x;
    const double la = a.norm(), lb = b.norm(), lc = c.norm();
    const double num = a.dot(b.cross(c));
    const double den = la * lb * lc + a.dot(b) * lc + a.dot(c) * lb + b.dot(c) * la;
    sum += 2.0 * std::atan2(num, den);
  }
  return sum / (4.0 * kPi);
}

/// Points on the hull's facets, about n in all, spread by area (a fixed pattern: deterministic).
std::vector<Eigen::Vector3d> hullSamples(const PieceHull& h, int n) {
  std::vector<Eigen::Vector3d> out;
  if (h.triangles.empty()) return out;
  double area = 0.0;
  std::vector<double> areas;
  for (const auto& t : h.triangles) {
    areas.push_back(0.5 * (h.points[t[1]] - h.points[t[0]]).cross(h.points[t[2]] - h.points[t[0]]).norm());
    area += areas.back();
  }
  if (!(area > 0.0)) return out;
  for (std::size_t f = 0; f < h.triangles.size(); ++f) {
    const auto& t = h.triangles[f];
    const int k = std::max(1, static_cast<int>(std::ceil(n * areas[f] / area)));
    const Eigen::Vector3d &a = h.points[t[0]], &b = h.points[t[1]], &c = h.points[t[2]];
    // A triangular grid of m(m+1)/2 >= k points strictly inside, plus the edge midpoints.
    int m = 1;
    while (m * (m + 1) / 2 < k) ++m;
    for (int i = 0; i < m; ++i)
      for (int j = 0; i + j < m; ++j) {
        const double u = (i + 1.0 / 3.0) / m, v = (j + 1.0 / 3.0) / m;
        out.push_back(a + u * (b - a) + v * (c - a));
      }
    out.push_back(0.5 * (a + b));
    out.push_back(0.5 * (b + c));
    out.push_back(0.5 * (c + a));
  }
  return out;
}

struct PieceCluster {
  std::vector<int> triangles;  ///< indices into the subdivided mesh
  PieceHull hull;
  double gap = -1.0;   ///< worst gap (m), -1: not measured since the last change
  bool final = false;  ///< no cut reduces it
};

/// A quick worst gap of one hull on its own (no other piece covers anything): its facets' centroids
/// and edge midpoints outside the mesh's solid, their largest distance to the mesh surface. Ranks the
/// candidate cuts.
double quickGap(const TriangleMesh& mesh, const TriangleTree& tree, const PieceHull& h) {
  std::vector<std::pair<double, Eigen::Vector3d>> far;  // (distance, point), then the largest first
  for (const auto& t : h.triangles) {
    const Eigen::Vector3d &a = h.points[t[0]], &b = h.points[t[1]], &c = h.points[t[2]];
    for (const Eigen::Vector3d& x : {Eigen::Vector3d((a + b + c) / 3.0), Eigen::Vector3d(0.5 * (a + b))})
      far.emplace_back(tree.distance(x), x);
  }
  std::sort(far.begin(), far.end(), [](const auto& u, const auto& v) { return u.first > v.first; });
  // The largest distance of a point outside the solid: the winding number only until one is found.
  for (const auto& [d, x] : far) {
    if (std::abs(windingNumber(mesh, x)) >= kInsideWinding) continue;  // inside the solid (a cut's cap)
    return d;
  }
  return 0.0;
}

PieceCluster makePieceCluster(const TriangleMesh& work, std::vector<int> tris) {
  PieceCluster c;
  c.triangles = std::move(tris);
  c.hull = pieceHull(clusterPoints(work, c.triangles));
  return c;
}

/// Piece i's worst gap (see the block above) against the link mesh `mesh`, `others` covering.
double pieceGap(const TriangleMesh& mesh, const TriangleTree& tree, const std::vector<PieceCluster>& pieces,
                std::size_t i, int samples) {
  std::vector<std::pair<double, Eigen::Vector3d>> far;  // uncovered samples, the largest distance first
  for (const Eigen::Vector3d& x : hullSamples(pieces[i].hull, samples)) {
    bool covered = false;
    for (std::size_t j = 0; j < pieces.size() && !covered; ++j)
      covered = j != i && outsideHull(pieces[j].hull, x) < -1e-9;
    if (!covered) far.emplace_back(tree.distance(x), x);
  }
  std::sort(far.begin(), far.end(), [](const auto& u, const auto& v) { return u.first > v.first; });
  for (const auto& [d, x] : far)
    if (std::abs(windingNumber(mesh, x)) < kInsideWinding) return d;  // inside the solid: never a surface point
  return 0.0;
}

}  // namespace

std::vector<PieceFit> fitConvexPieces(const TriangleMesh& mesh, const FitOptions& options, double* worst_gap) {
  if (mesh.vertices.empty() || mesh.triangles.empty()) throw ModelError("fit: the mesh has no triangles");
  for (const auto& t : mesh.triangles)
    for (int k = 0; k < 3; ++k)
      if (t[k] < 0 || t[k] >= static_cast<int>(mesh.vertices.size()))
        throw ModelError("fit: triangle index out of range");
  for (const auto& v : mesh.vertices)
    if (!v.allFinite()) throw ModelError("fit: a mesh vertex is not finite");
  TriangleMesh work = mesh;
  std::vector<char> used(mesh.vertices.size(), 0);
  for (const auto& t : mesh.triangles)
    for (int k = 0; k < 3; ++k) used[t[k]] = 1;
  for (std::size_t i = 0; i < mesh.vertices.size(); ++i)
    if (!used[i]) work.triangles.push_back({int(i), int(i), int(i)});
  Eigen::Vector3d lo = mesh.vertices[0], hi = mesh.vertices[0];
  for (const auto& v : mesh.vertices) lo = lo.cwiseMin(v), hi = hi.cwiseMax(v);
  const double extent = (hi - lo).norm();
  if (options.max_pieces > 1) work = subdivide(work, 0.1 * extent);
  // Connected shells (shared vertices), for the shell-against-the-rest cuts.
  std::vector<int> parent(work.vertices.size());
  std::iota(parent.begin(), parent.end(), 0);
  auto root = [&](int v) {
    while (parent[v] != v) v = parent[v] = parent[parent[v]];
    return v;
  };
  for (const auto& t : work.triangles) parent[root(t[1])] = root(t[0]), parent[root(t[2])] = root(t[0]);
  std::vector<int> shell(work.triangles.size());
  for (std::size_t t = 0; t < work.triangles.size(); ++t) shell[t] = root(work.triangles[t][0]);

  std::vector<int> all(work.triangles.size());
  std::iota(all.begin(), all.end(), 0);
  std::vector<PieceCluster> pieces{makePieceCluster(work, all)};
  const int samples = options.gap_samples_per_primitive;
  const TriangleTree tree(mesh);
  for (;;) {
    for (std::size_t i = 0; i < pieces.size(); ++i)
      if (pieces[i].gap < 0.0) pieces[i].gap = pieceGap(mesh, tree, pieces, i, samples);
    // Up to max_pieces, any gap above piece_gap is cut; beyond, only one above large_gap.
    const bool beyond = static_cast<int>(pieces.size()) >= options.max_pieces;
    const double cut_above = beyond ? std::max(options.piece_gap, options.large_gap) : options.piece_gap;
    std::size_t worst = pieces.size();
    for (std::size_t i = 0; i < pieces.size(); ++i)
      if (!pieces[i].final && pieces[i].triangles.size() >= 2 && pieces[i].gap > cut_above &&
          (worst == pieces.size() || pieces[i].gap > pieces[worst].gap))
        worst = i;
    if (worst == pieces.size() ||
        static_cast<int>(pieces.size()) >= std::max(options.max_pieces, options.max_pieces_large_gap))
      break;
    const PieceCluster& c = pieces[worst];
    // The cut whose two hulls stand off the mesh least (quickGap, the larger of the two), ties within
    // 0.1 mm by the least summed volume; a cut must make the hulls smaller or the gap smaller.
    double best_gap = std::numeric_limits<double>::infinity(), best_volume = c.hull.volume * (1.0 - 1e-6);
    std::vector<int> best_a, best_b;
    auto consider = [&](std::vector<int> ta, std::vector<int> tb) {
      if (ta.empty() || tb.empty()) return;
      const PieceHull ha = pieceHull(clusterPoints(work, ta));
      const double ga = quickGap(mesh, tree, ha);
      if (ga > best_gap + 1e-4) return;  // the larger of the two gaps cannot beat the best cut any more
      const PieceHull hb = pieceHull(clusterPoints(work, tb));
      const double v = ha.volume + hb.volume;
      const double g = std::max(ga, quickGap(mesh, tree, hb));
      // Progress: smaller hulls, or (a flat piece: an L-shaped face bridged across its notch, volume
      // 0 either way) a smaller gap.
      if (!(v < c.hull.volume * (1.0 - 1e-6)) && !(g < 0.99 * c.gap)) return;
      if (g < best_gap - 1e-4 || (g < best_gap + 1e-4 && v < best_volume)) {
        best_gap = std::min(best_gap, g), best_volume = v, best_a = std::move(ta), best_b = std::move(tb);
      }
    };
    // Separate shells first (the convex parts a mesh is often made of: a palm and its fingers), then
    // planes.
    forEachCut(work, c.triangles, shell, 0.0, consider, Cuts::kShells);
    if (best_a.empty()) forEachCut(work, c.triangles, shell, 0.0, consider, Cuts::kAxes);
    if (best_a.empty()) {  // no cut makes the hulls or the gap smaller: this piece stays as it is
      pieces[worst].final = true;
      continue;
    }
    Eigen::AlignedBox3d changed;  // where coverage changed: the split piece's hull
    for (const auto& x : pieces[worst].hull.points) changed.extend(x);
    pieces[worst] = makePieceCluster(work, std::move(best_a));
    pieces.insert(pieces.begin() + static_cast<long>(worst) + 1, makePieceCluster(work, std::move(best_b)));
    for (auto& p : pieces) {  // a piece whose hull meets that box is measured again
      Eigen::AlignedBox3d box;
      for (const auto& x : p.hull.points) box.extend(x);
      if (changed.intersects(box)) p.gap = -1.0;
    }
  }
  double link_gap = 0.0;
  std::vector<PieceFit> out;
  for (const auto& p : pieces) {
    link_gap = std::max(link_gap, p.gap);
    PieceFit f;
    f.vertices = p.hull.points;
    f.triangles = p.hull.triangles;
    f.capsule = enclosingCapsule(f.vertices, options);
    out.push_back(std::move(f));
  }
  if (worst_gap) *worst_gap = link_gap;
  return out;
}

Primitive enclosingCapsule(const std::vector<Eigen::Vector3d>& points, const FitOptions& options) {
  if (points.empty()) throw ModelError("fit: no point to enclose");
  Primitive p = fitOne(points);
  for (int k = 0; k < 3; ++k)
    p.a_L[k] = roundTo(p.a_L[k], options.quantum), p.b_L[k] = roundTo(p.b_L[k], options.quantum);
  if (p.sphere || (p.b_L - p.a_L).norm() < options.quantum) p.b_L = p.a_L, p.sphere = true;
  double r = 0.0;
  for (const auto& q : points) r = std::max(r, distanceToSegment(p.a_L, p.b_L, q));
  p.radius = std::max(options.quantum, std::ceil(r / options.quantum + 1e-6) * options.quantum);
  return p;
}

FitStats measurePieces(const TriangleMesh& mesh, const std::vector<PieceFit>& pieces, double worst_gap) {
  FitStats s;
  s.vertices = static_cast<int>(mesh.vertices.size());
  s.triangles = static_cast<int>(mesh.triangles.size());
  std::vector<PieceHull> hulls;
  for (const PieceFit& p : pieces) {
    hulls.push_back(pieceHull(p.vertices));
    s.fitted_volume += hulls.back().volume;
  }
  for (const auto& v : mesh.vertices) {
    bool inside = false;
    for (std::size_t i = 0; i < pieces.size() && !inside; ++i) {
      inside = outsideHull(hulls[i], v) <= 1e-9;
      for (const auto& x : pieces[i].vertices) inside = inside || x == v;  // a flat piece's own points
    }
    s.vertices_enclosed += inside ? 1 : 0;
  }
  s.hull_volume = mesh.vertices.empty() ? 0.0 : convexHull(mesh.vertices).volume;
  s.volume_ratio = s.hull_volume > 0 ? s.fitted_volume / s.hull_volume : 0.0;
  s.worst_gap = worst_gap;
  return s;
}

PieceFit boxPiece(const Eigen::Vector3d& size, const Eigen::Isometry3d& X_L_B, const FitOptions& options) {
  if (!(size.minCoeff() > 0.0) || !size.allFinite())
    throw ModelError("fit: box size " + std::to_string(size.x()) + " " + std::to_string(size.y()) + " " +
                     std::to_string(size.z()) + " must be positive");
  const TriangleMesh m = boxMesh(size, X_L_B);
  PieceFit f;
  f.vertices = m.vertices;
  f.triangles = m.triangles;
  f.capsule = enclosingCapsule(f.vertices, options);
  return f;
}

namespace {

/// Whether segment p-q crosses triangle (a, b, c) (Moller-Trumbore; a segment in the triangle's plane
/// is not seen).
bool segmentCrossesTriangle(const Eigen::Vector3d& p, const Eigen::Vector3d& q, const Eigen::Vector3d& a,
                            const Eigen::Vector3d& b, const Eigen::Vector3d& c) {
  const Eigen::Vector3d d = q - p, e1 = b - a, e2 = c - a;
  const Eigen::Vector3d h = d.cross(e2);
  const double det = e1.dot(h);
  if (std::abs(det) < 1e-18) return false;
  const double inv = 1.0 / det;
  const Eigen::Vector3d s = p - a;
  const double u = inv * s.dot(h);
  if (u < 0.0 || u > 1.0) return false;
  const Eigen::Vector3d qv = s.cross(e1);
  const double v = inv * d.dot(qv);
  if (v < 0.0 || u + v > 1.0) return false;
  const double t = inv * e2.dot(qv);
  return t >= 0.0 && t <= 1.0;
}

/// An edge of one triangle crosses the other.
bool trianglesCross(const std::array<Eigen::Vector3d, 3>& t, const std::array<Eigen::Vector3d, 3>& u) {
  for (int k = 0; k < 3; ++k) {
    if (segmentCrossesTriangle(t[k], t[(k + 1) % 3], u[0], u[1], u[2])) return true;
    if (segmentCrossesTriangle(u[k], u[(k + 1) % 3], t[0], t[1], t[2])) return true;
  }
  return false;
}

}  // namespace

bool meshesIntersect(const TriangleMesh& a, const Eigen::Isometry3d& X_B_A, const TriangleMesh& b,
                     const Eigen::Isometry3d& X_B_B) {
  if (a.triangles.empty() || b.triangles.empty()) return false;
  // b in a's frame; only the triangles inside the other mesh's box can cross.
  const Eigen::Isometry3d X_A_B = X_B_A.inverse() * X_B_B;
  std::vector<Eigen::Vector3d> vb(b.vertices.size());
  for (std::size_t i = 0; i < vb.size(); ++i) vb[i] = X_A_B * b.vertices[i];
  Eigen::AlignedBox3d box_a, box_b;
  for (const auto& v : a.vertices) box_a.extend(v);
  for (const auto& v : vb) box_b.extend(v);
  if (!box_a.intersects(box_b)) return false;
  auto corners = [](const std::vector<Eigen::Vector3d>& v, const std::array<int, 3>& t) {
    return std::array<Eigen::Vector3d, 3>{v[t[0]], v[t[1]], v[t[2]]};
  };
  auto boxOf = [](const std::array<Eigen::Vector3d, 3>& t) {
    Eigen::AlignedBox3d x;
    for (const auto& p : t) x.extend(p);
    return x;
  };
  std::vector<std::pair<std::array<Eigen::Vector3d, 3>, Eigen::AlignedBox3d>> ta, tb;
  for (const auto& t : a.triangles) {
    const auto c = corners(a.vertices, t);
    const auto x = boxOf(c);
    if (x.intersects(box_b)) ta.emplace_back(c, x);
  }
  for (const auto& t : b.triangles) {
    const auto c = corners(vb, t);
    const auto x = boxOf(c);
    if (x.intersects(box_a)) tb.emplace_back(c, x);
  }
  for (const auto& [t, x] : ta)
    for (const auto& [u, y] : tb)
      if (x.intersects(y) && trianglesCross(t, u)) return true;
  // No surfaces crossing: one inside the other?
  TriangleMesh b_in_a{vb, b.triangles};
  return std::abs(windingNumber(b_in_a, a.vertices[a.triangles[0][0]])) >= 0.95 ||
         std::abs(windingNumber(a, vb[b.triangles[0][0]])) >= 0.95;
}

}  // namespace reflex::control
