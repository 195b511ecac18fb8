// bench_distance: the self-distance sweep of a robot, side by side with FCL and KDL, and the broad
// phase against the brute force. Not a CTest test; run by hand:
//   build-*/bin/bench_distance [--robot=NAME] --benchmark_repetitions=5 --benchmark_report_aggregates_only=true
// --robot: a robot of bringup/robots by name (asimo_like, the default; many_segment_humanoid, the
// >= 1,000-pair robot; small_humanoid; mesh_humanoid) or a URDF path; its collision configuration
// is the default one next to it. Every benchmark prints `pairs` (checked robot pairs).
//
// Every benchmark cycles through the same 256 random configurations (within the joint limits),
// precomputed outside the timed loop; one iteration = one configuration.
//   Reflex/*        reflex::control (FK = computeForwardKinematics of every link; sweep = FK +
//                   computeSegmentDistances over every checked pair)
//   FCL/*           the same checked pairs through FCL 0.7: fcl::distance on fcl::Sphered /
//                   fcl::Capsuled in B (dispatches to FCL's analytic sphere/capsule functions),
//                   minimum over each pair's primitive pairs, nearest points on
//   FCL_Analytic/*  the same, calling FCL's analytic functions (fcl::detail::sphereSphereDistance,
//                   sphereCapsuleDistance, capsuleCapsuleDistance) directly: FCL without its dispatch
//   Reflex_Broadphase/prune:1 vs prune:0   the control cycle's sweep (FK + every pair, rows below
//                   d_safe = 0.10 m) with the broad phase skipping pairs whose bounding spheres are more
//                   than 0.10 m apart, and the same without it (the brute force, the peer in the same
//                   process); ns_per_pair = sweep time / checked pairs, exact_share = share of the pairs
//                   computed exactly
//   KDL/*           kdl_parser tree, one KDL::Chain per tip: ChainFkSolverPos_recursive +
//                   ChainJntToJacSolver; tips: both hands, the 17 segment links, every link
//                   (Reflex: one computeForwardKinematics + computePointJacobian per tip)
//   ConvexDistance_Reflex/vertices:N/warm:W vs ConvexDistance_FCL/vertices:N   one convex-convex
//                   distance (the tight model's narrow phase, convex.hpp) per iteration, on the same
//                   16 pairs of random convex pieces of N = 40, 100, 300 hull vertices (qhull hulls of
//                   points on ellipsoids of 2-6 cm semi-axes), each pair moving slowly (256 poses per
//                   turn, ~1.4 degrees and a few mm a step) at distances of 0-100 mm; Reflex:
//                   computeConvexDistance with a warm start from the pair's previous pose (warm:1) or
//                   cold (warm:0); FCL: fcl::distance on fcl::Convexd (libccd GJK, nearest points on,
//                   default tolerance; FCL hill-climbs too above 32 vertices). Independent of --robot.
#include "reflex/control/convex.hpp"
#include "reflex/control/distance.hpp"
#include "reflex/control/kinematics.hpp"
#include "reflex/control/urdf_loader.hpp"
#include "bench_support.hpp"

#include <benchmark/benchmark.h>
#include <fcl/geometry/shape/convex.h>
#include <fcl/narrowphase/detail/primitive_shape_algorithm/capsule_capsule.h>
#include <fcl/narrowphase/detail/primitive_shape_algorithm/sphere_capsule.h>
#include <fcl/narrowphase/detail/primitive_shape_algorithm/sphere_sphere.h>
#include <fcl/narrowphase/distance.h>
#include <kdl/chainfksolverpos_recursive.hpp>
#include <kdl/chainjnttojacsolver.hpp>
#include <kdl/tree.hpp>
#include <kdl_parser/kdl_parser.hpp>

#include <Eigen/Geometry>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <limits>
#include <map>
#include <memory>
#include <random>
#include <stdexcept>
#include <string>
#include <vector>

#include <libqhull_r/qhull_ra.h>  // last: its macros (True, False, ...) stay out of the other headers

namespace {

using namespace reflex::control;

constexpr int kConfigurations = 256;

std::string robotPath(const std::string& file) { return std::string(REFLEX_SOURCE_DIR) + "/bringup/robots/" + file; }

/// The URDF of --robot (bench_support.hpp).
std::string g_urdf = robotPath("asimo_like.urdf");

struct FclPrimitive {
  std::shared_ptr<fcl::CollisionGeometryd> geometry;
  Eigen::Isometry3d X_L_P;  // primitive frame in its link frame (capsule along local z)
  int link;
};

struct KdlTip {
  KDL::Chain chain;
  std::unique_ptr<KDL::ChainFkSolverPos_recursive> fk;
  std::unique_ptr<KDL::ChainJntToJacSolver> jac;
  std::vector<KDL::JntArray> q;  // per configuration
  KDL::Frame frame;
  KDL::Jacobian J;
  int link;
};

/// Everything shared by the benchmarks, built once.
struct Setup {
  Model model;
  std::vector<Eigen::VectorXd> qs;
  std::vector<KinematicsData> kin;  // FK of each configuration (for the distance-only benchmarks)
  std::vector<FclPrimitive> fcl_prims;
  std::vector<std::vector<fcl::Transform3d>> fcl_X;  // per configuration, per primitive, in B
  std::vector<std::pair<int, int>> robot_pairs;      // checked robot segment pairs
  KDL::Tree tree;

  Setup() : model(loadModel(g_urdf, loadCollisionConfig(bench::collisionPathFor(g_urdf)))) {
    std::mt19937_64 rng(42);
    for (int c = 0; c < kConfigurations; ++c) {
      Eigen::VectorXd q(model.nq);
      for (int i = 0; i < model.nq; ++i)
        q[i] = std::uniform_real_distribution<double>(model.q_lower[i], model.q_upper[i])(rng);
      qs.push_back(q);
      kin.emplace_back(model);
      computeForwardKinematics(model, kin.back(), q);
    }
    for (int s = 0; s < model.num_robot_segments; ++s) {
      const Segment& seg = model.segments[s];
      for (int p = seg.first_primitive; p < seg.first_primitive + seg.num_primitives; ++p) {
        const Primitive& prim = model.primitives[p];
        FclPrimitive f;
        f.link = seg.link;
        f.X_L_P.setIdentity();
        f.X_L_P.translation() = 0.5 * (prim.a_L + prim.b_L);
        if (prim.sphere) {
          f.geometry = std::make_shared<fcl::Sphered>(prim.radius);
        } else {
          f.X_L_P.linear() =
              Eigen::Quaterniond::FromTwoVectors(Eigen::Vector3d::UnitZ(), prim.b_L - prim.a_L).toRotationMatrix();
          f.geometry = std::make_shared<fcl::Capsuled>(prim.radius, (prim.b_L - prim.a_L).norm());
        }
        fcl_prims.push_back(f);
      }
    }
    for (int c = 0; c < kConfigurations; ++c) {
      std::vector<fcl::Transform3d> X;
      for (const FclPrimitive& f : fcl_prims) X.push_back(kin[c].X_B_L[f.link] * f.X_L_P);
      fcl_X.push_back(X);
    }
    for (const SegmentPair& p : model.pairs)
      if (!model.segments[p.b].body_schema_slot) robot_pairs.emplace_back(p.a, p.b);
    if (!kdl_parser::treeFromFile(g_urdf, tree)) throw std::runtime_error("kdl_parser failed on " + g_urdf);
  }

  std::unique_ptr<KdlTip> kdlTip(const std::string& tip) const {
    auto t = std::make_unique<KdlTip>();
    if (!tree.getChain(model.links[0].name, tip, t->chain)) throw std::runtime_error("no KDL chain to " + tip);
    t->fk = std::make_unique<KDL::ChainFkSolverPos_recursive>(t->chain);
    t->jac = std::make_unique<KDL::ChainJntToJacSolver>(t->chain);
    t->J.resize(t->chain.getNrOfJoints());
    t->link = model.linkIndex(tip);
    for (const Eigen::VectorXd& q : qs) {
      KDL::JntArray kq(t->chain.getNrOfJoints());
      unsigned k = 0;
      for (const KDL::Segment& s : t->chain.segments)
        if (s.getJoint().getType() != KDL::Joint::None) kq(k++) = q[model.qIndex(s.getJoint().getName())];
      t->q.push_back(kq);
    }
    return t;
  }
};

const Setup& setup() {
  static const Setup s;
  return s;
}

// ---------------------------------------------------------------- Reflex
void Reflex_FK(benchmark::State& state) {
  const Setup& s = setup();
  KinematicsData kin(s.model);
  int c = 0;
  for (auto _ : state) {
    computeForwardKinematics(s.model, kin, s.qs[c]);
    benchmark::DoNotOptimize(kin.X_B_L.data());
    c = (c + 1) % kConfigurations;
  }
}

void sweep(benchmark::State& state, double row_threshold, bool with_fk) {
  const Setup& s = setup();
  KinematicsData kin(s.model);
  DistanceData dist(s.model);
  const DistanceOptions options{row_threshold};
  int c = 0;
  for (auto _ : state) {
    if (with_fk) {
      computeForwardKinematics(s.model, kin, s.qs[c]);
      computeSegmentDistances(s.model, kin, dist, options);
    } else {
      computeSegmentDistances(s.model, s.kin[c], dist, options);
    }
    benchmark::DoNotOptimize(dist.pairs.data());
    benchmark::ClobberMemory();
    c = (c + 1) % kConfigurations;
  }
  state.counters["pairs"] = static_cast<double>(s.robot_pairs.size());
}

void Reflex_Sweep_RowsOff(benchmark::State& state) { sweep(state, -std::numeric_limits<double>::infinity(), true); }
void Reflex_Sweep_RowsBelow40mm(benchmark::State& state) { sweep(state, 0.04, true); }
void Reflex_Sweep_RowsAll(benchmark::State& state) { sweep(state, std::numeric_limits<double>::infinity(), true); }
void Reflex_DistancesOnly_RowsOff(benchmark::State& state) {
  sweep(state, -std::numeric_limits<double>::infinity(), false);
}

/// The control cycle's sweep with (range 0 = 1) or without the broad phase.
void Reflex_Broadphase(benchmark::State& state) {
  const Setup& s = setup();
  KinematicsData kin(s.model);
  DistanceData dist(s.model);
  DistanceOptions options;
  options.row_threshold = 0.10;
  if (state.range(0) != 0) options.prune_distance = 0.10;
  int c = 0;
  double exact = 0.0;
  for (auto _ : state) {
    computeForwardKinematics(s.model, kin, s.qs[c]);
    computeSegmentDistances(s.model, kin, dist, options);
    benchmark::DoNotOptimize(dist.pairs.data());
    benchmark::ClobberMemory();
    exact += dist.num_exact_pairs;
    c = (c + 1) % kConfigurations;
  }
  const double pairs = static_cast<double>(s.robot_pairs.size());
  state.counters["pairs"] = pairs;
  state.counters["exact_share"] = exact / (pairs * static_cast<double>(state.iterations()));
  // Seconds per checked pair, printed in ns: sweep time / (iterations * pairs).
  state.counters["ns_per_pair"] = benchmark::Counter(pairs * static_cast<double>(state.iterations()) * 1e-9,
                                                     benchmark::Counter::kIsRate | benchmark::Counter::kInvert);
}

// ---------------------------------------------------------------- FCL
double fclPairs(const Setup& s, const std::vector<fcl::Transform3d>& X, const fcl::DistanceRequestd& request) {
  double sum = 0.0;
  for (const auto& [a, b] : s.robot_pairs) {
    const Segment& A = s.model.segments[a];
    const Segment& B = s.model.segments[b];
    double best = std::numeric_limits<double>::infinity();
    for (int pa = A.first_primitive; pa < A.first_primitive + A.num_primitives; ++pa) {
      for (int pb = B.first_primitive; pb < B.first_primitive + B.num_primitives; ++pb) {
        fcl::DistanceResultd result;
        fcl::distance(s.fcl_prims[pa].geometry.get(), X[pa], s.fcl_prims[pb].geometry.get(), X[pb], request, result);
        if (result.min_distance < best) best = result.min_distance;
      }
    }
    sum += best;
  }
  return sum;
}

void FCL_DistancesOnly(benchmark::State& state) {
  const Setup& s = setup();
  fcl::DistanceRequestd request;
  request.enable_nearest_points = true;
  int c = 0;
  for (auto _ : state) {
    benchmark::DoNotOptimize(fclPairs(s, s.fcl_X[c], request));
    c = (c + 1) % kConfigurations;
  }
  state.counters["pairs"] = static_cast<double>(s.robot_pairs.size());
}

double fclAnalyticPairs(const Setup& s, const std::vector<fcl::Transform3d>& X) {
  double sum = 0.0;
  for (const auto& [a, b] : s.robot_pairs) {
    const Segment& A = s.model.segments[a];
    const Segment& B = s.model.segments[b];
    double best = std::numeric_limits<double>::infinity();
    for (int pa = A.first_primitive; pa < A.first_primitive + A.num_primitives; ++pa) {
      for (int pb = B.first_primitive; pb < B.first_primitive + B.num_primitives; ++pb) {
        const bool sa = s.model.primitives[pa].sphere, sb = s.model.primitives[pb].sphere;
        const auto* ga = s.fcl_prims[pa].geometry.get();
        const auto* gb = s.fcl_prims[pb].geometry.get();
        double d = 0.0;
        Eigen::Vector3d p1, p2;
        if (sa && sb) {
          fcl::detail::sphereSphereDistance(*static_cast<const fcl::Sphered*>(ga), X[pa],
                                            *static_cast<const fcl::Sphered*>(gb), X[pb], &d, &p1, &p2);
        } else if (sa) {
          fcl::detail::sphereCapsuleDistance(*static_cast<const fcl::Sphered*>(ga), X[pa],
                                             *static_cast<const fcl::Capsuled*>(gb), X[pb], &d, &p1, &p2);
        } else if (sb) {
          fcl::detail::sphereCapsuleDistance(*static_cast<const fcl::Sphered*>(gb), X[pb],
                                             *static_cast<const fcl::Capsuled*>(ga), X[pa], &d, &p2, &p1);
        } else {
          fcl::detail::capsuleCapsuleDistance(*static_cast<const fcl::Capsuled*>(ga), X[pa],
                                              *static_cast<const fcl::Capsuled*>(gb), X[pb], &d, &p1, &p2);
        }
        if (d < best) best = d;
      }
    }
    sum += best;
  }
  return sum;
}

void FCL_Analytic_DistancesOnly(benchmark::State& state) {
  const Setup& s = setup();
  int c = 0;
  for (auto _ : state) {
    benchmark::DoNotOptimize(fclAnalyticPairs(s, s.fcl_X[c]));
    c = (c + 1) % kConfigurations;
  }
  state.counters["pairs"] = static_cast<double>(s.robot_pairs.size());
}

void FCL_Sweep_ReflexFK(benchmark::State& state) {
  // The FCL counterpart of Reflex_Sweep_RowsOff: Reflex FK, primitive poses into B, FCL pairs.
  const Setup& s = setup();
  KinematicsData kin(s.model);
  std::vector<fcl::Transform3d> X(s.fcl_prims.size());
  fcl::DistanceRequestd request;
  request.enable_nearest_points = true;
  int c = 0;
  for (auto _ : state) {
    computeForwardKinematics(s.model, kin, s.qs[c]);
    for (std::size_t p = 0; p < X.size(); ++p) X[p] = kin.X_B_L[s.fcl_prims[p].link] * s.fcl_prims[p].X_L_P;
    benchmark::DoNotOptimize(fclPairs(s, X, request));
    c = (c + 1) % kConfigurations;
  }
  state.counters["pairs"] = static_cast<double>(s.robot_pairs.size());
}

// ---------------------------------------------------------------- FK + Jacobians: KDL vs Reflex
const std::vector<std::string>& handTips() {
  static const std::vector<std::string> t = {"l_hand", "r_hand"};
  return t;
}

std::vector<std::string> segmentLinks(const Model& m) {
  std::vector<std::string> t;
  for (int s = 0; s < m.num_robot_segments; ++s) t.push_back(m.links[m.segments[s].link].name);
  return t;
}

void kdlFkJac(benchmark::State& state, const std::vector<std::string>& tips) {
  const Setup& s = setup();
  std::vector<std::unique_ptr<KdlTip>> kt;
  for (const auto& t : tips) kt.push_back(s.kdlTip(t));
  int c = 0;
  for (auto _ : state) {
    for (auto& t : kt) {
      t->fk->JntToCart(t->q[c], t->frame);
      t->jac->JntToJac(t->q[c], t->J);
      benchmark::DoNotOptimize(t->J.data.data());
    }
    c = (c + 1) % kConfigurations;
  }
  state.counters["tips"] = static_cast<double>(tips.size());
}

void reflexFkJac(benchmark::State& state, const std::vector<std::string>& tips) {
  const Setup& s = setup();
  KinematicsData kin(s.model);
  std::vector<int> links;
  for (const auto& t : tips) links.push_back(s.model.linkIndex(t));
  std::vector<Eigen::MatrixXd> J(links.size(), Eigen::MatrixXd(3, s.model.nq));
  int c = 0;
  for (auto _ : state) {
    computeForwardKinematics(s.model, kin, s.qs[c]);
    for (std::size_t i = 0; i < links.size(); ++i) {
      computePointJacobian(s.model, kin, links[i], kin.X_B_L[links[i]].translation(), J[i]);
      benchmark::DoNotOptimize(J[i].data());
    }
    c = (c + 1) % kConfigurations;
  }
  state.counters["tips"] = static_cast<double>(tips.size());
}

std::vector<std::string> allLinks(const Model& m) {
  std::vector<std::string> t;
  for (std::size_t l = 1; l < m.links.size(); ++l) t.push_back(m.links[l].name);  // every link but the root
  return t;
}

void KDL_FK_Jac_Hands(benchmark::State& state) { kdlFkJac(state, handTips()); }
void Reflex_FK_Jac_Hands(benchmark::State& state) { reflexFkJac(state, handTips()); }
void KDL_FK_Jac_SegmentLinks(benchmark::State& state) { kdlFkJac(state, segmentLinks(setup().model)); }
void Reflex_FK_Jac_SegmentLinks(benchmark::State& state) { reflexFkJac(state, segmentLinks(setup().model)); }
void KDL_FK_Jac_AllLinks(benchmark::State& state) { kdlFkJac(state, allLinks(setup().model)); }
void Reflex_FK_Jac_AllLinks(benchmark::State& state) { reflexFkJac(state, allLinks(setup().model)); }

// ---------------------------------------------------------------- convex pieces: Reflex GJK vs FCL
constexpr int kConvexPairs = 16;
constexpr int kConvexPoses = 256;  // per pair: one slow turn

/// A convex hull with qhull ("Qt": triangulated): vertices and triangles (indices into vertices).
struct ConvexHull {
  std::vector<Eigen::Vector3d> vertices;
  std::vector<std::array<int, 3>> triangles;
};

ConvexHull qhullHull(const std::vector<Eigen::Vector3d>& pts) {
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
  ConvexHull hull;
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
      const Eigen::Vector3d n(facet->normal[0], facet->normal[1], facet->normal[2]);
      const Eigen::Vector3d& a = hull.vertices[t[0]];
      if ((hull.vertices[t[1]] - a).cross(hull.vertices[t[2]] - a).dot(n) < 0) std::swap(t[1], t[2]);
      if (k == 3) hull.triangles.push_back(t);
    }
  }
  qh_freeqhull(qh, !qh_ALL);
  int curlong = 0, totlong = 0;
  qh_memfreeshort(qh, &curlong, &totlong);
  if (devnull) std::fclose(devnull);
  if (exitcode) throw std::runtime_error("bench_distance: qhull failed on a random piece");
  return hull;
}

/// The pieces and poses of one size (see the opening block), built on first use.
struct ConvexSet {
  std::vector<ConvexPiece> pieces;                        // 2 per pair: a, b
  std::vector<std::shared_ptr<fcl::Convexd>> fcl_pieces;  // the same hulls
  std::vector<Eigen::Isometry3d> X_B_A;                   // [pair * kConvexPoses + pose]; B at identity
  double hull_vertices = 0.0;                             // mean over the pieces
  double mean_distance = 0.0;                             // mean over every pose (m)
};

const ConvexSet& convexSet(int vertices) {
  static std::map<int, ConvexSet> sets;
  auto found = sets.find(vertices);
  if (found != sets.end()) return found->second;
  ConvexSet& set = sets[vertices];
  std::mt19937_64 rng(1000 + vertices);
  std::normal_distribution<double> g;
  std::uniform_real_distribution<double> axis(0.02, 0.06), phase(0.0, 2 * M_PI);
  auto unit = [&] { return Eigen::Vector3d(g(rng), g(rng), g(rng)).normalized(); };
  for (int i = 0; i < 2 * kConvexPairs; ++i) {
    // Points on an ellipsoid's surface: (nearly) every point is a hull vertex.
    const Eigen::Vector3d axes(axis(rng), axis(rng), axis(rng));
    std::vector<Eigen::Vector3d> pts;
    for (int k = 0; k < vertices; ++k) pts.push_back(unit().cwiseProduct(axes));
    const ConvexHull hull = qhullHull(pts);
    set.pieces.push_back(makeConvexPiece(hull.vertices, hull.triangles));
    auto v = std::make_shared<std::vector<fcl::Vector3d>>(hull.vertices.begin(), hull.vertices.end());
    auto f = std::make_shared<std::vector<int>>();
    for (const auto& t : hull.triangles) f->insert(f->end(), {3, t[0], t[1], t[2]});
    set.fcl_pieces.push_back(std::make_shared<fcl::Convexd>(v, static_cast<int>(hull.triangles.size()), f));
    set.hull_vertices += static_cast<double>(hull.vertices.size()) / (2 * kConvexPairs);
  }
  const Eigen::Isometry3d I = Eigen::Isometry3d::Identity();
  for (int p = 0; p < kConvexPairs; ++p) {
    // A slow periodic motion: A turns once about one axis while its direction from B turns once about
    // another; the gap follows 50 + 50 sin (mm), so it spans 0-100 mm.
    const Eigen::Quaterniond q0(Eigen::AngleAxisd(phase(rng), unit()));
    const Eigen::Vector3d spin = unit(), orbit = unit(), dir0 = orbit.cross(unit()).normalized();
    const double ph = phase(rng);
    for (int c = 0; c < kConvexPoses; ++c) {
      const double t = 2 * M_PI * c / kConvexPoses;
      const Eigen::Quaterniond q = q0 * Eigen::Quaterniond(Eigen::AngleAxisd(t, spin));
      const Eigen::Vector3d dir = Eigen::AngleAxisd(t, orbit) * dir0;
      const double gap = 0.05 + 0.05 * std::sin(t + ph);
      // The offset along dir where the distance is `gap` (bisection; distance grows with the offset).
      double lo = 0.0, hi = 0.5;
      for (int i = 0; i < 50; ++i) {
        const double mid = 0.5 * (lo + hi);
        Eigen::Isometry3d X = I;
        X.linear() = q.toRotationMatrix();
        X.translation() = mid * dir;
        (computeConvexDistance(set.pieces[2 * p], X, set.pieces[2 * p + 1], I).distance < gap ? lo : hi) = mid;
      }
      Eigen::Isometry3d X = I;
      X.linear() = q.toRotationMatrix();
      X.translation() = hi * dir;
      set.X_B_A.push_back(X);
      set.mean_distance += computeConvexDistance(set.pieces[2 * p], X, set.pieces[2 * p + 1], I).distance /
                           (kConvexPairs * kConvexPoses);
    }
  }
  return set;
}

/// One query per iteration: pair by pair, each pair through its poses in order (so a warm start
/// comes from the pair's previous pose).
void ConvexDistance_Reflex(benchmark::State& state) {
  const ConvexSet& set = convexSet(static_cast<int>(state.range(0)));
  const bool use_warm = state.range(1) != 0;
  std::vector<ConvexWarmStart> warm(kConvexPairs);
  const Eigen::Isometry3d I = Eigen::Isometry3d::Identity();
  int k = 0;
  double iterations = 0.0;
  for (auto _ : state) {
    const int p = k / kConvexPoses;
    const ConvexDistance r =
        computeConvexDistance(set.pieces[2 * p], set.X_B_A[k], set.pieces[2 * p + 1], I, use_warm ? &warm[p] : nullptr);
    benchmark::DoNotOptimize(r);
    iterations += r.iterations;
    k = (k + 1) % (kConvexPairs * kConvexPoses);
  }
  state.counters["hull_vertices"] = set.hull_vertices;
  state.counters["mean_distance_mm"] = 1e3 * set.mean_distance;
  state.counters["gjk_iterations"] = iterations / static_cast<double>(state.iterations());
}

void ConvexDistance_FCL(benchmark::State& state) {
  const ConvexSet& set = convexSet(static_cast<int>(state.range(0)));
  fcl::DistanceRequestd request;
  request.enable_nearest_points = true;
  const Eigen::Isometry3d I = Eigen::Isometry3d::Identity();
  int k = 0;
  for (auto _ : state) {
    const int p = k / kConvexPoses;
    fcl::DistanceResultd result;
    fcl::distance(set.fcl_pieces[2 * p].get(), set.X_B_A[k], set.fcl_pieces[2 * p + 1].get(), I, request, result);
    benchmark::DoNotOptimize(result.min_distance);
    k = (k + 1) % (kConvexPairs * kConvexPoses);
  }
  state.counters["hull_vertices"] = set.hull_vertices;
  state.counters["mean_distance_mm"] = 1e3 * set.mean_distance;
}

// The machine is shared: besides mean / median / stddev, report the minimum over repetitions (the
// run least disturbed by other processes).
double minimum(const std::vector<double>& v) { return *std::min_element(v.begin(), v.end()); }
#define REFLEX_BENCH(fn) BENCHMARK(fn)->ComputeStatistics("min", minimum)

REFLEX_BENCH(Reflex_FK);
REFLEX_BENCH(Reflex_Sweep_RowsOff);
REFLEX_BENCH(Reflex_Sweep_RowsBelow40mm);
REFLEX_BENCH(Reflex_Sweep_RowsAll);
REFLEX_BENCH(Reflex_DistancesOnly_RowsOff);
REFLEX_BENCH(Reflex_Broadphase)->ArgName("prune")->Arg(1)->Arg(0);
REFLEX_BENCH(FCL_DistancesOnly);
REFLEX_BENCH(FCL_Analytic_DistancesOnly);
REFLEX_BENCH(FCL_Sweep_ReflexFK);
REFLEX_BENCH(Reflex_FK_Jac_Hands);
REFLEX_BENCH(KDL_FK_Jac_Hands);
REFLEX_BENCH(Reflex_FK_Jac_SegmentLinks);
REFLEX_BENCH(KDL_FK_Jac_SegmentLinks);
REFLEX_BENCH(Reflex_FK_Jac_AllLinks);
REFLEX_BENCH(KDL_FK_Jac_AllLinks);
REFLEX_BENCH(ConvexDistance_Reflex)->ArgNames({"vertices", "warm"})->ArgsProduct({{40, 100, 300}, {1, 0}});
REFLEX_BENCH(ConvexDistance_FCL)->ArgName("vertices")->Arg(40)->Arg(100)->Arg(300);

}  // namespace

int main(int argc, char** argv) {
  return reflex::control::bench::benchMain(
      argc, argv, "bench_distance",
      "bench_distance [--robot=NAME|PATH.urdf] [benchmark options]\n"
      "  --robot  a robot of bringup/robots by name (default asimo_like; many_segment_humanoid:\n"
      "           the >= 1,000-pair robot) or a URDF path; collision configuration next to it\n",
      &g_urdf, nullptr, [] {
        std::printf("robot: %s, %zu checked robot pairs, %s sweep kernel\n", g_urdf.c_str(), setup().robot_pairs.size(),
                    fastestSweepKernel() == SweepKernel::kAvx2 ? "AVX2" : "scalar");
      });
}
