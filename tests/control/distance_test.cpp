// Tests of control/include/reflex/control/distance.hpp on whole robots: the checked pair list, the
// PairDistance invariants, distances and witness points against FCL at random configurations, the
// avoidance rows against the Jacobians and against finite differences of the pair distance,
// body-schema slots, the coincident-core fallback, NaN joint values, the broad phase against the
// brute force, and the AVX2 sweep kernels against the scalar ones (the same bits).
#include "reflex/control/distance.hpp"

#include "reflex/control/kinematics.hpp"
#include "segment_kernels.hpp"  // control/src: the sweep's kernels, tested directly below
#include "test_support.hpp"

#include <fcl/narrowphase/distance.h>
#include <gtest/gtest.h>

#include <Eigen/Geometry>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <limits>
#include <memory>
#include <random>
#include <set>
#include <string>

namespace reflex::control {
namespace {

using Eigen::Vector3d;

std::pair<std::string, std::string> pairNames(const Model& m, const SegmentPair& p) {
  return {m.segments[p.a].name, m.segments[p.b].name};
}

bool hasPair(const Model& m, const std::string& a, const std::string& b) {
  for (const SegmentPair& p : m.pairs) {
    const auto [na, nb] = pairNames(m, p);
    if ((na == a && nb == b) || (na == b && nb == a)) return true;
  }
  return false;
}

int robotPairCount(const Model& m) {
  return static_cast<int>(std::count_if(m.pairs.begin(), m.pairs.end(),
                                        [&](const SegmentPair& p) { return !m.segments[p.b].body_schema_slot; }));
}

int yamlExcludeEntries(const std::string& path) {
  std::ifstream in(path);
  std::string line;
  int n = 0;
  while (std::getline(in, line))
    if (line.rfind("  - [", 0) == 0) ++n;
  return n;
}

// ---------------------------------------------------------------- pair list
TEST(DistancePairs, ShippedRobotChecksEveryPairButNeighboursAndExclusions) {
  const Model m = testing::loadRobot(testing::kAsimo);
  ASSERT_EQ(m.num_robot_segments, 17);
  // 17 segments: 136 pairs. Neighbours in the segment tree (hand-listed from Fig. 1): body-chest,
  // chest-head, chest-shoulders (2), shoulder-upper arm, upper arm-forearm, forearm-hand (2 x 3),
  // body-thighs (2), thigh-shank, shank-foot (2 x 2) = 16.
  const int excluded = yamlExcludeEntries(testing::robotPath("asimo_like.collision.yaml"));
  EXPECT_EQ(excluded, 45);
  EXPECT_EQ(robotPairCount(m), 136 - 16 - excluded);
  for (const auto& [a, b] : {std::pair{"body", "chest"},
                             {"chest", "head"},
                             {"chest", "l_shoulder"},
                             {"l_shoulder", "l_upper_arm"},
                             {"l_upper_arm", "l_forearm"},
                             {"r_forearm", "r_hand"},
                             {"body", "l_thigh"},
                             {"l_shank", "l_foot"},
                             {"l_thigh", "r_thigh"},
                             {"head", "body"}})
    EXPECT_FALSE(hasPair(m, a, b)) << a << "-" << b;
  for (const auto& [a, b] : {std::pair{"l_hand", "r_hand"},
                             {"l_hand", "head"},
                             {"l_forearm", "body"},
                             {"r_upper_arm", "chest"},
                             {"l_hand", "l_thigh"},
                             {"l_shoulder", "l_hand"},
                             {"l_upper_arm", "l_hand"}})
    EXPECT_TRUE(hasPair(m, a, b)) << a << "-" << b;
  // Every robot segment against each body-schema slot; never slot against slot; a < b always.
  EXPECT_EQ(static_cast<int>(m.pairs.size()) - robotPairCount(m), 17 * kBodySchemaSlots);
  std::set<std::pair<int, int>> seen;
  for (const SegmentPair& p : m.pairs) {
    EXPECT_LT(p.a, p.b);
    EXPECT_FALSE(m.segments[p.a].body_schema_slot);
    EXPECT_TRUE(seen.insert({p.a, p.b}).second) << "duplicate pair";
  }
}

TEST(DistancePairs, AdjacencyExclusionCanBeTurnedOff) {
  CollisionConfig config = loadCollisionConfig(testing::robotPath("asimo_like.collision.yaml"));
  config.exclude_adjacent = false;
  const Model m = loadModel(testing::robotPath("asimo_like.urdf"), config);
  // Without the adjacency rule every pair but the 45 listed ones is checked, except chest-body: the
  // chest is fixed to the body (one rigid body, never checked whatever the configuration says).
  EXPECT_EQ(robotPairCount(m), 136 - 45 - 1);
  EXPECT_FALSE(hasPair(m, "body", "chest"));
  EXPECT_TRUE(hasPair(m, "l_forearm", "l_hand"));
  CollisionConfig none;
  const Model all = loadModel(testing::robotPath("asimo_like.urdf"), none);
  EXPECT_EQ(robotPairCount(all), 136 - 16);
}

// ---------------------------------------------------------------- against FCL on the robot
std::shared_ptr<fcl::CollisionGeometryd> fclShape(const Vector3d& a, const Vector3d& b, double r,
                                                  fcl::Transform3d& X_B_S) {
  X_B_S.setIdentity();
  X_B_S.translation() = 0.5 * (a + b);
  const double length = (b - a).norm();
  if (length == 0.0) return std::make_shared<fcl::Sphered>(r);
  X_B_S.linear() = Eigen::Quaterniond::FromTwoVectors(Vector3d::UnitZ(), b - a).toRotationMatrix();
  return std::make_shared<fcl::Capsuled>(r, length);
}

struct FclPair {
  double d = std::numeric_limits<double>::infinity();
  double second = std::numeric_limits<double>::infinity();  // next best primitive pair
  Vector3d p_a, p_b;
  bool parallel = false;
};

// The segment distance from FCL: the minimum over the segments' primitive pairs, each primitive
// placed in B with the link pose from FK and the local endpoints from the model.
FclPair fclSegmentDistance(const Model& m, const KinematicsData& kin, int sa, int sb) {
  FclPair out;
  const Segment& A = m.segments[sa];
  const Segment& B = m.segments[sb];
  for (int pa = A.first_primitive; pa < A.first_primitive + A.num_primitives; ++pa) {
    for (int pb = B.first_primitive; pb < B.first_primitive + B.num_primitives; ++pb) {
      const Primitive& P = m.primitives[pa];
      const Primitive& Q = m.primitives[pb];
      const Eigen::Isometry3d& XA = kin.X_B_L[A.link];
      const Eigen::Isometry3d& XB = kin.X_B_L[B.link];
      fcl::Transform3d Xa, Xb;
      const auto ga = fclShape(XA * P.a_L, P.sphere ? Vector3d(XA * P.a_L) : Vector3d(XA * P.b_L), P.radius, Xa);
      const auto gb = fclShape(XB * Q.a_L, Q.sphere ? Vector3d(XB * Q.a_L) : Vector3d(XB * Q.b_L), Q.radius, Xb);
      fcl::DistanceRequestd request;
      request.enable_nearest_points = true;
      fcl::DistanceResultd result;
      fcl::distance(ga.get(), Xa, gb.get(), Xb, request, result);
      const double d = result.min_distance;
      if (d < out.d) {
        out.second = out.d;
        out.d = d;
        out.p_a = result.nearest_points[0];
        out.p_b = result.nearest_points[1];
        out.parallel =
            !P.sphere && !Q.sphere &&
            (XA.linear() * (P.b_L - P.a_L)).normalized().cross((XB.linear() * (Q.b_L - Q.a_L)).normalized()).norm() <
                1e-3;
      } else {
        out.second = std::min(out.second, d);
      }
    }
  }
  return out;
}

void checkRobotAgainstFcl(const Model& m, int configurations, std::uint64_t seed) {
  KinematicsData kin(m);
  DistanceData dist(m);
  std::mt19937_64 rng(seed);
  double max_d = 0.0, max_p = 0.0;
  int compared = 0, points = 0;
  for (int c = 0; c < configurations; ++c) {
    ASSERT_TRUE(computeForwardKinematics(m, kin, test::randomConfiguration(m, rng)));
    computeSegmentDistances(m, kin, dist);
    int closest = -1;
    for (std::size_t i = 0; i < dist.pairs.size(); ++i) {
      const PairDistance& pd = dist.pairs[i];
      if (m.segments[pd.seg_b].body_schema_slot) {
        EXPECT_FALSE(pd.active);  // no slot enabled
        EXPECT_EQ(pd.distance, std::numeric_limits<double>::infinity());
        continue;
      }
      ASSERT_TRUE(pd.active);
      // Invariants.
      ASSERT_TRUE(std::isfinite(pd.distance));
      EXPECT_NEAR(pd.nhat_B.norm(), 1.0, 1e-12);
      EXPECT_LT((pd.p_B_a - pd.p_B_b - pd.distance * pd.nhat_B).norm(), 1e-12);
      if (closest < 0 || pd.distance < dist.pairs[closest].distance) closest = static_cast<int>(i);
      const FclPair f = fclSegmentDistance(m, kin, pd.seg_a, pd.seg_b);
      if (!(f.d > 1e-9)) continue;  // FCL reports no points for touching/penetrating spheres
      const double e = std::abs(f.d - pd.distance);
      max_d = std::max(max_d, e);
      ASSERT_LT(e, 1e-9) << m.segments[pd.seg_a].name << "-" << m.segments[pd.seg_b].name;
      ++compared;
      // Witness points are unique unless the best primitive pair is (nearly) parallel or two
      // primitive pairs tie.
      if (!f.parallel && f.second - f.d > 1e-9) {
        const double ep = std::max((f.p_a - pd.p_B_a).norm(), (f.p_b - pd.p_B_b).norm());
        max_p = std::max(max_p, ep);
        ASSERT_LT(ep, 1e-9) << m.segments[pd.seg_a].name << "-" << m.segments[pd.seg_b].name;
        ++points;
      }
    }
    EXPECT_EQ(dist.closest, closest);
  }
  EXPECT_GT(compared, configurations * robotPairCount(m) * 9 / 10);
  EXPECT_GT(points, compared / 2);
  std::printf("%s vs FCL: %d pair distances (max error %.3g m), %d witness pairs (max error %.3g m)\n", m.name.c_str(),
              compared, max_d, points, max_p);
}

TEST(DistanceFcl, ShippedRobotAgreesWithFcl) { checkRobotAgainstFcl(testing::loadRobot(testing::kAsimo), 60, 7); }

TEST(DistanceFcl, SecondHumanoidAgreesWithFcl) { checkRobotAgainstFcl(testing::loadRobot(testing::kSmall), 60, 8); }

// ---------------------------------------------------------------- avoidance rows
double pairDistanceAt(const Model& m, KinematicsData& kin, DistanceData& dist, const Eigen::VectorXd& q, int i) {
  EXPECT_TRUE(computeForwardKinematics(m, kin, q));
  computeSegmentDistances(m, kin, dist, DistanceOptions{-std::numeric_limits<double>::infinity()});
  return dist.pairs[i].distance;
}

void checkRowsAgainstFiniteDifferences(const Model& m, int configurations, std::uint64_t seed) {
  KinematicsData kin(m), kin_fd(m);
  DistanceData dist(m), dist_fd(m);
  std::mt19937_64 rng(seed);
  const double h = 1e-6;
  double max_err = 0.0;
  int rows_checked = 0, rows_nonzero = 0, active_pairs = 0;
  for (int c = 0; c < configurations; ++c) {
    const Eigen::VectorXd q = test::randomConfiguration(m, rng);
    ASSERT_TRUE(computeForwardKinematics(m, kin, q));
    computeSegmentDistances(m, kin, dist);  // default threshold +inf: every active pair has a row
    for (std::size_t i = 0; i < dist.pairs.size(); ++i) {
      const PairDistance& pd = dist.pairs[i];
      if (!pd.active) {
        EXPECT_FALSE(pd.has_row);
        continue;
      }
      ASSERT_TRUE(pd.has_row);
      ++active_pairs;
      // The row is n^T (J_pa - J_pb) with the Jacobians of the witness points on their links.
      const int la = m.segments[pd.seg_a].link, lb = m.segments[pd.seg_b].link;
      Eigen::MatrixXd Ja(3, m.nq), Jb(3, m.nq);
      computePointJacobian(m, kin, la, pd.p_B_a, Ja);
      computePointJacobian(m, kin, lb, pd.p_B_b, Jb);
      const Eigen::RowVectorXd expected = pd.nhat_B.transpose() * (Ja - Jb);
      EXPECT_LT((dist.rows.row(static_cast<Eigen::Index>(i)) - expected).cwiseAbs().maxCoeff(), 1e-12);
      // ... and it is the gradient of the pair distance (closest points unique at random configs).
      if (!pd.well_defined) continue;
      for (int j = 0; j < m.nq; ++j) {
        Eigen::VectorXd qp = q, qm = q;
        qp[j] += h;
        qm[j] -= h;
        const double fd = (pairDistanceAt(m, kin_fd, dist_fd, qp, static_cast<int>(i)) -
                           pairDistanceAt(m, kin_fd, dist_fd, qm, static_cast<int>(i))) /
                          (2 * h);
        const double e = std::abs(fd - dist.rows(static_cast<Eigen::Index>(i), j));
        max_err = std::max(max_err, e);
        ASSERT_LT(e, 1e-6) << m.segments[pd.seg_a].name << "-" << m.segments[pd.seg_b].name << " joint "
                           << m.q_names[j];
      }
      ++rows_checked;
      rows_nonzero += dist.rows.row(static_cast<Eigen::Index>(i)).cwiseAbs().maxCoeff() > 1e-6 ? 1 : 0;
    }
  }
  std::printf(
      "%s: %d avoidance rows vs central differences (h = 1e-6; %d of them non-zero, of %d active "
      "pairs): max error %.3g\n",
      m.name.c_str(), rows_checked, rows_nonzero, active_pairs, max_err);
  // A check of no rows, or of zero rows only, would pass whatever the rows were:
  // nearly every active pair is well defined at random configurations, and every checked pair has a
  // segment that some joint moves (pairs no joint moves are excluded in the shipped configurations).
  EXPECT_GE(rows_checked, active_pairs * 9 / 10);
  EXPECT_GT(active_pairs, 0);
  EXPECT_EQ(rows_nonzero, rows_checked);
}

TEST(DistanceRows, ShippedRobotRowsAreDistanceGradients) {
  checkRowsAgainstFiniteDifferences(testing::loadRobot(testing::kAsimo), 4, 11);
}

TEST(DistanceRows, SecondHumanoidRowsAreDistanceGradients) {
  checkRowsAgainstFiniteDifferences(testing::loadRobot(testing::kSmall), 3, 12);
}

TEST(DistanceRows, ThresholdSelectsRows) {
  const Model m = testing::loadRobot(testing::kAsimo);
  KinematicsData kin(m);
  DistanceData dist(m);
  std::mt19937_64 rng(3);
  ASSERT_TRUE(computeForwardKinematics(m, kin, test::randomConfiguration(m, rng)));
  computeSegmentDistances(m, kin, dist, DistanceOptions{0.15});
  int with = 0;
  for (const PairDistance& pd : dist.pairs) {
    EXPECT_EQ(pd.has_row, pd.active && pd.distance < 0.15);
    with += pd.has_row;
  }
  EXPECT_GT(with, 0);
  computeSegmentDistances(m, kin, dist, DistanceOptions{-std::numeric_limits<double>::infinity()});
  for (const PairDistance& pd : dist.pairs) EXPECT_FALSE(pd.has_row);
}

// ---------------------------------------------------------------- broad phase
// The pruned sweep against the brute force (the unpruned sweep, itself checked against FCL above):
// over random configurations, every pair whose true distance is within the prune distance is
// identical bit for bit (distance, witness points, normal, row), every skipped pair reports a lower
// bound above the prune distance and at most its true distance, the closest pair and its distance
// are identical, and refinePairDistance turns a skipped pair into the brute-force result.
/// Pair i of y is pair i of x bit for bit: witness points, normal, flag, row (both computed exactly).
void expectSamePair(const DistanceData& x, const DistanceData& y, std::size_t i, const std::string& name) {
  const PairDistance& a = x.pairs[i];
  const PairDistance& b = y.pairs[i];
  EXPECT_EQ(b.p_B_a, a.p_B_a) << name;
  EXPECT_EQ(b.p_B_b, a.p_B_b) << name;
  EXPECT_EQ(b.nhat_B, a.nhat_B) << name;
  EXPECT_EQ(b.well_defined, a.well_defined) << name;
  ASSERT_EQ(b.has_row, a.has_row) << name;
  if (a.has_row) {
    EXPECT_EQ(y.rows.row(static_cast<Eigen::Index>(i)), x.rows.row(static_cast<Eigen::Index>(i))) << name;
  }
}

void checkBroadPhase(const Model& m, double prune_distance, int configurations, unsigned seed) {
  KinematicsData kin(m);
  DistanceData brute(m), pruned(m);
  DistanceOptions exact_options;
  exact_options.row_threshold = prune_distance;
  DistanceOptions prune_options = exact_options;
  prune_options.prune_distance = prune_distance;
  std::mt19937_64 rng(seed);
  // A stick in the left hand: slot pairs take part too (always exact).
  ASSERT_TRUE(attachBodySchemaSegment(m, brute, 0, m.linkIndex("l_hand"), Vector3d(0, 0, -0.08),
                                      Vector3d(0.2, 0, -0.08), 0.02));
  pruned.slots = brute.slots;
  long within = 0, skipped = 0, refined = 0;
  for (int c = 0; c < configurations; ++c) {
    ASSERT_TRUE(computeForwardKinematics(m, kin, test::randomConfiguration(m, rng)));
    computeSegmentDistances(m, kin, brute, exact_options);
    computeSegmentDistances(m, kin, pruned, prune_options);
    ASSERT_EQ(pruned.closest, brute.closest) << "configuration " << c;
    ASSERT_EQ(pruned.pairs[pruned.closest].distance, brute.pairs[brute.closest].distance);
    ASSERT_TRUE(pruned.pairs[pruned.closest].exact);
    for (std::size_t i = 0; i < m.pairs.size(); ++i) {
      const PairDistance& b = brute.pairs[i];
      const PairDistance& p = pruned.pairs[i];
      ASSERT_TRUE(b.exact);
      ASSERT_EQ(p.active, b.active);
      if (!b.active) continue;
      const std::string name = m.segments[b.seg_a].name + "-" + m.segments[b.seg_b].name;
      if (!p.exact) {
        ++skipped;
        EXPECT_GT(p.distance, prune_distance) << name;
        EXPECT_LE(p.distance, b.distance) << name << ": the broad phase's bound must be a lower bound";
        EXPECT_FALSE(p.has_row);
        if (skipped % 7 == 0) {  // refined: the brute-force result exactly
          refinePairDistance(m, kin, pruned, static_cast<int>(i), prune_options);
          EXPECT_TRUE(p.exact);
          EXPECT_EQ(p.distance, b.distance) << name;
          EXPECT_EQ(p.p_B_a, b.p_B_a) << name;
          EXPECT_EQ(p.nhat_B, b.nhat_B) << name;
          ++refined;
        }
        continue;
      }
      if (b.distance <= prune_distance) ++within;
      EXPECT_EQ(p.distance, b.distance) << name;
      expectSamePair(brute, pruned, i, name);
    }
  }
  // Not vacuous: pairs inside the distance were compared, and pairs were skipped and refined.
  std::printf(
      "%s, prune distance %.3f m, %d configurations: %ld pairs within it identical, %ld skipped "
      "(lower bounds), %ld of them refined\n",
      m.name.c_str(), prune_distance, configurations, within, skipped, refined);
  EXPECT_GT(within, configurations / 2);
  EXPECT_GT(skipped, configurations);
  EXPECT_GT(refined, 0);
}

TEST(DistanceBroadPhase, PrunedSweepEqualsBruteForceOnTheShippedRobot) {
  const Model m = testing::loadRobot(testing::kAsimo);
  checkBroadPhase(m, 0.10, 400, 21);
  checkBroadPhase(m, 0.01, 200, 22);
}

TEST(DistanceBroadPhase, PrunedSweepEqualsBruteForceOnTheSecondHumanoid) {
  checkBroadPhase(testing::loadRobot(testing::kSmall), 0.10, 400, 23);
}

TEST(DistanceBroadPhase, PrunedSweepEqualsBruteForceOnTheThousandPairRobot) {
  const Model m = testing::loadRobot("many_segment_humanoid");
  // The benchmark robot (bringup/robots/make_many_segment_humanoid.py).
  EXPECT_GE(robotPairCount(m), 1000);
  checkBroadPhase(m, 0.10, 150, 24);
}

/// The tight model (convex pieces, the mesh robot's fit): pairs inside the prune distance identical
/// to the brute force, skipped ones lower bounds; each pair's narrow phase stops its searches early
/// and starts from the primitive pair that won last time, which must change the work only.
TEST(DistanceBroadPhase, PrunedSweepEqualsBruteForceOnTheTightModel) {
  const Model m = testing::loadRobot("mesh_humanoid");
  ASSERT_GT(m.pieces.size(), 20u) << "the mesh robot is loaded with its fit's convex pieces";
  checkBroadPhase(m, 0.10, 300, 25);
  checkBroadPhase(m, 0.02, 300, 26);
}

/// A trajectory of small steps: each call moves `fraction` of the way to a random configuration,
/// and every `jump_every`-th call jumps to it.
struct Trajectory {
  Trajectory(const Model& model, unsigned seed, int jump_every, double fraction)
      : m(model), rng(seed), q(test::randomConfiguration(model, rng)), every(jump_every), step(fraction) {}
  const Eigen::VectorXd& next() {
    const Eigen::VectorXd target = test::randomConfiguration(m, rng);
    q = calls++ % every == 0 ? target : Eigen::VectorXd(q + step * (target - q));
    return q;
  }
  const Model& m;
  std::mt19937_64 rng;
  Eigen::VectorXd q;
  int every;
  double step;
  int calls = 0;
};

/// What a DistanceData carries from one call to the next (the last winner of each pair, each primitive
/// pair's and each far pair's lower bound less how far its pieces moved) changes the work, never the
/// result: along a trajectory of small steps (where the carried bounds skip searches) with a jump
/// every 20 cycles, a DistanceData used every cycle gives the same closest pair and the same bits for
/// every pair within the prune distance as a fresh one, with and without the broad phase. A pair
/// beyond it may be a lower bound in one and exact in the other (the closest pair's refinement visits
/// the pairs whose bound is below the closest so far, and the carried bounds differ): a lower bound is
/// at most the exact distance and above the prune distance, and two exact values are the same bits.
TEST(DistanceTightModel, ResultsDoNotDependOnEarlierCycles) {
  const Model m = testing::loadRobot("mesh_humanoid");
  KinematicsData kin(m);
  // Once with every joint moving, once with the first half of the joints held (the links they alone
  // move stay where they are: their segments are not placed again, and must be where a fresh
  // placement puts them).
  for (const bool half_held : {false, true}) {
    for (const double prune : {std::numeric_limits<double>::infinity(), 0.04}) {
      DistanceOptions options;
      options.row_threshold = 0.04;
      options.prune_distance = prune;
      DistanceData reused(m);
      Trajectory path(m, 41, 20, 0.02);
      const Eigen::VectorXd held = path.q;
      long compared = 0, bounded = 0, searches_reused = 0, searches_fresh = 0, still = 0;
      std::vector<Eigen::Isometry3d> before(m.links.size(), Eigen::Isometry3d::Identity());
      for (int c = 0; c < 300; ++c) {
        Eigen::VectorXd q = path.next();
        if (half_held) q.head(m.nq / 2) = held.head(m.nq / 2);
        ASSERT_TRUE(computeForwardKinematics(m, kin, q));
        for (int s = 0; s < m.num_robot_segments; ++s) {
          const int link = m.segments[static_cast<std::size_t>(s)].link;
          still +=
              kin.X_B_L[static_cast<std::size_t>(link)].matrix() == before[static_cast<std::size_t>(link)].matrix();
        }
        before = kin.X_B_L;
        DistanceData fresh(m), exact(m);
        computeSegmentDistances(m, kin, reused, options);
        computeSegmentDistances(m, kin, fresh, options);
        searches_reused += reused.num_piece_searches;
        searches_fresh += fresh.num_piece_searches;
        computeSegmentDistances(m, kin, exact);
        ASSERT_EQ(reused.closest, fresh.closest) << "cycle " << c;
        for (std::size_t p = 0; p < m.primitives.size(); ++p) {
          ASSERT_EQ(reused.prim_B[p].start, fresh.prim_B[p].start) << "primitive " << p << " cycle " << c;
          ASSERT_EQ(reused.prim_B[p].d, fresh.prim_B[p].d) << "primitive " << p << " cycle " << c;
        }
        for (std::size_t i = 0; i < m.pairs.size(); ++i) {
          if (!fresh.pairs[i].active) continue;
          const std::string name = m.segments[fresh.pairs[i].seg_a].name + "-" + m.segments[fresh.pairs[i].seg_b].name;
          const std::string where = name + " cycle " + std::to_string(c) + " prune " + std::to_string(prune);
          ASSERT_EQ(reused.pairs[i].active, fresh.pairs[i].active) << where;
          if (exact.pairs[i].distance <= prune) {
            ASSERT_TRUE(reused.pairs[i].exact && fresh.pairs[i].exact) << where;
          }
          bool inexact = false;
          for (const DistanceData* d : {&reused, &fresh}) {
            if (d->pairs[i].exact) continue;
            inexact = true;
            EXPECT_LE(d->pairs[i].distance, exact.pairs[i].distance) << where;
            EXPECT_GT(d->pairs[i].distance, prune) << where;
          }
          if (inexact) {
            ++bounded;
            continue;
          }
          ASSERT_EQ(reused.pairs[i].distance, fresh.pairs[i].distance) << where;
          expectSamePair(fresh, reused, i, name);
          ++compared;
        }
      }
      std::printf(
          "tight model along a trajectory (%s), prune %.3f m: %ld exact pairs identical, %ld left as lower "
          "bounds; %ld searches with what the last cycles carried, %ld without; %ld segment-cycles still\n",
          half_held ? "half the joints held" : "every joint moving", prune, compared, bounded, searches_reused,
          searches_fresh, still);
      EXPECT_GT(compared, prune < 1.0 ? 300 : 300 * 100);
      // Not vacuous: the carried bounds did skip searches (few here: most of this robot's links are one
      // piece, so a pair's one search is its answer; on Romeo's crossed arms they halve the searches).
      // With the broad phase, a far pair's carried bound skips it before any search.
      EXPECT_LT(searches_reused, searches_fresh);
      if (half_held) {
        EXPECT_GT(still, 300) << "held joints must leave segments where they were";
      }
    }
  }
}

/// computeListedPairDistances with a give-up distance on the tight model (the predictive guard asks
/// only whether a pair is below d_r + predict_margin): a listed pair within it is the full sweep's bit
/// for bit; one beyond is either that too or inexact with a lower bound above give_up and at most the
/// full sweep's distance.
TEST(DistanceListedPairs, TightPairsBeyondTheGiveUpDistanceComeOutAsLowerBounds) {
  const Model m = testing::loadRobot("mesh_humanoid");
  KinematicsData kin(m);
  DistanceData full(m), listed(m);
  DistanceOptions no_rows;
  no_rows.row_threshold = -std::numeric_limits<double>::infinity();
  std::mt19937_64 rng(32);
  std::vector<int> pairs;
  for (int i = 0; i < static_cast<int>(m.pairs.size()); ++i) pairs.push_back(i);
  constexpr double kGiveUp = 0.06;
  long within = 0, bounded = 0, exact_beyond = 0;
  for (int c = 0; c < 150; ++c) {
    ASSERT_TRUE(computeForwardKinematics(m, kin, test::randomConfiguration(m, rng)));
    computeSegmentDistances(m, kin, full.slots, full, no_rows);
    computeListedPairDistances(m, kin, full.slots, listed, pairs.data(), static_cast<int>(pairs.size()), kGiveUp);
    for (std::size_t i = 0; i < m.pairs.size(); ++i) {
      const PairDistance& f = full.pairs[i];
      const PairDistance& l = listed.pairs[i];
      ASSERT_EQ(l.active, f.active) << "pair " << i;
      if (!f.active) continue;
      if (!l.exact) {
        ++bounded;
        EXPECT_GT(f.distance, kGiveUp) << "pair " << i << ": a pair within the give-up distance must be exact";
        EXPECT_GT(l.distance, kGiveUp) << "pair " << i;
        EXPECT_LE(l.distance, f.distance) << "pair " << i << ": not a lower bound";
        continue;
      }
      (f.distance <= kGiveUp ? within : exact_beyond) += 1;
      EXPECT_EQ(l.distance, f.distance) << "pair " << i;
      EXPECT_EQ(l.p_B_a, f.p_B_a) << "pair " << i;
      EXPECT_EQ(l.nhat_B, f.nhat_B) << "pair " << i;
    }
  }
  std::printf(
      "tight model, give-up %.3f m: %ld pairs within it identical, %ld beyond it left as lower bounds, "
      "%ld beyond it exact (capsule pairs)\n",
      kGiveUp, within, bounded, exact_beyond);
  EXPECT_GT(within, 150);
  EXPECT_GT(bounded, 150 * 20);
}

/// computeListedPairDistances carries each primitive pair's lower bound to the next call on the same
/// DistanceData (the guard's predictions of one cycle differ by a fraction of a step), less how far its
/// primitives moved: along a trajectory of small steps, with a sweep on the same data now and then (the
/// controller's walking check shares it), every listed pair comes out as from a fresh DistanceData, bit
/// for bit, and the carried bounds save searches.
TEST(DistanceListedPairs, CarriedBoundsChangeNoResultAlongATrajectory) {
  const Model m = testing::loadRobot("mesh_humanoid");
  KinematicsData kin(m);
  std::vector<int> pairs;
  for (int i = 0; i < static_cast<int>(m.pairs.size()); ++i) pairs.push_back(i);
  DistanceOptions no_rows;
  no_rows.row_threshold = -std::numeric_limits<double>::infinity();
  for (const double give_up : {0.06, std::numeric_limits<double>::infinity()}) {
    DistanceData reused(m);
    Trajectory path(m, 43, 40, 0.01);
    long compared = 0, bounded = 0, searches_reused = 0, searches_fresh = 0;
    for (int c = 0; c < 400; ++c) {
      ASSERT_TRUE(computeForwardKinematics(m, kin, path.next()));
      if (c % 7 == 3) computeSegmentDistances(m, kin, reused.slots, reused, no_rows);
      DistanceData fresh(m);
      computeListedPairDistances(m, kin, reused.slots, reused, pairs.data(), static_cast<int>(pairs.size()), give_up);
      searches_reused += reused.num_piece_searches;
      computeListedPairDistances(m, kin, fresh.slots, fresh, pairs.data(), static_cast<int>(pairs.size()), give_up);
      searches_fresh += fresh.num_piece_searches;
      for (std::size_t i = 0; i < m.pairs.size(); ++i) {
        const PairDistance& f = fresh.pairs[i];
        const PairDistance& r = reused.pairs[i];
        ASSERT_EQ(r.active, f.active) << "pair " << i << " call " << c;
        if (!f.active) continue;
        ASSERT_EQ(r.exact, f.exact) << "pair " << i << " call " << c << " give-up " << give_up;
        if (!f.exact) {  // both lower bounds above give_up (how far above may differ)
          EXPECT_GT(r.distance, give_up) << "pair " << i << " call " << c;
          ++bounded;
          continue;
        }
        ASSERT_EQ(r.distance, f.distance) << "pair " << i << " call " << c << " give-up " << give_up;
        expectSamePair(fresh, reused, i, "pair " + std::to_string(i));
        ++compared;
      }
    }
    std::printf(
        "listed pairs along a trajectory, give-up %.3f m: %ld exact identical, %ld lower bounds; "
        "%ld searches with carried bounds, %ld without\n",
        give_up, compared, bounded, searches_reused, searches_fresh);
    EXPECT_GT(compared, 300);
    EXPECT_LT(searches_reused, searches_fresh);  // not vacuous: the carried bounds skipped searches
  }
}

/// listPairsNear (the guard's listing, once a cycle): at a configuration where no point moved more
/// than the reach from where it was listed, a pair offered only its listed primitive pairs comes out
/// as without the listing: exact pairs bit for bit, the others lower bounds above give_up. The reach
/// is a bound of each primitive's motion computed here: |centre moved| + |R1 - R0|_F * sphere radius.
TEST(DistanceListedPairs, APairListedOnceComesOutAsWithoutTheListingWithinItsReach) {
  const Model m = testing::loadRobot("mesh_humanoid");
  KinematicsData kin0(m), kin1(m);
  DistanceData now(m);
  PairListing listing(m);
  DistanceOptions prune;
  prune.prune_distance = 0.1;
  std::vector<int> pairs;
  for (int i = 0; i < static_cast<int>(m.pairs.size()); ++i) pairs.push_back(i);
  std::vector<double> reach(pairs.size());
  constexpr double kGiveUp = 0.15;
  std::mt19937_64 rng(45);
  long compared = 0, bounded = 0, listed = 0;
  for (int c = 0; c < 300; ++c) {
    const Eigen::VectorXd q0 = test::randomConfiguration(m, rng);
    const Eigen::VectorXd q1 = q0 + 0.04 * (test::randomConfiguration(m, rng) - q0);
    ASSERT_TRUE(computeForwardKinematics(m, kin0, q0));
    ASSERT_TRUE(computeForwardKinematics(m, kin1, q1));
    computeSegmentDistances(m, kin0, now, prune);  // its bounding spheres: the listing's
    auto motion = [&](const Segment& seg) {
      double most = 0.0;
      for (int p = seg.first_primitive; p < seg.first_primitive + seg.num_primitives; ++p) {
        const Primitive& prim = m.primitives[static_cast<std::size_t>(p)];
        const std::size_t l = static_cast<std::size_t>(linkOf(seg, prim));
        const Eigen::Vector3d c = 0.5 * (prim.a_L + prim.b_L);
        const double r = 0.5 * (prim.b_L - prim.a_L).norm() + prim.radius;
        most = std::max(most, (kin1.X_B_L[l] * c - kin0.X_B_L[l] * c).norm() +
                                  (kin1.X_B_L[l].linear() - kin0.X_B_L[l].linear()).norm() * r);
      }
      return most;
    };
    for (std::size_t k = 0; k < pairs.size(); ++k)
      reach[k] = motion(m.segments[m.pairs[k].a]) + motion(m.segments[m.pairs[k].b]);
    listPairsNear(m, now, pairs.data(), static_cast<int>(pairs.size()), kGiveUp, reach.data(), listing);
    DistanceData with(m), without(m);
    computeListedPairDistances(m, kin1, with.slots, with, pairs.data(), static_cast<int>(pairs.size()), kGiveUp,
                               &listing);
    computeListedPairDistances(m, kin1, without.slots, without, pairs.data(), static_cast<int>(pairs.size()), kGiveUp);
    for (std::size_t i = 0; i < m.pairs.size(); ++i) {
      const PairDistance& w = with.pairs[i];
      const PairDistance& o = without.pairs[i];
      const std::string name =
          m.segments[o.seg_a].name + "-" + m.segments[o.seg_b].name + " configuration " + std::to_string(c);
      ASSERT_EQ(w.exact, o.exact) << name << ": " << w.distance << " with the listing, " << o.distance << " without";
      listed += listing.count[i] >= 0 ? 1 : 0;
      if (!o.exact) {
        EXPECT_GT(w.distance, kGiveUp) << name;
        ++bounded;
        continue;
      }
      ASSERT_EQ(w.distance, o.distance) << name;
      expectSamePair(without, with, i, name);
      compared += listing.count[i] >= 0 && o.distance <= kGiveUp ? 1 : 0;
    }
  }
  std::printf("listed once: %ld listed pairs within give-up %.3f m identical, %ld lower bounds, %ld listings\n",
              compared, kGiveUp, bounded, listed);
  EXPECT_GT(compared, 300);  // not vacuous: listed pairs within give_up
}

/// computeListedPairDistances (the predictive guard's): the listed pairs come out as the full sweep
/// computes them, bit for bit (with a slot, enabled and then disabled), and no other entry changes.
TEST(DistanceListedPairs, ListedPairsEqualTheFullSweepAndNothingElseChanges) {
  const Model m = testing::loadRobot("many_segment_humanoid");
  KinematicsData kin(m);
  DistanceData full(m), listed(m);
  DistanceOptions no_rows;
  no_rows.row_threshold = -std::numeric_limits<double>::infinity();
  ASSERT_TRUE(attachBodySchemaSegment(m, full, 1, m.linkIndex("r_hand"), Vector3d(0, 0, -0.08),
                                      Vector3d(0.15, 0, -0.08), 0.02));
  std::mt19937_64 rng(31);
  std::vector<int> pairs;
  long compared = 0, untouched = 0, inactive = 0;
  for (int c = 0; c < 60; ++c) {
    if (c == 30) full.slots[1].enabled = false;  // the slot's pairs must come out inactive
    ASSERT_TRUE(computeForwardKinematics(m, kin, test::randomConfiguration(m, rng)));
    computeSegmentDistances(m, kin, full.slots, full, no_rows);
    // A sentinel in every entry, then every third pair (a different third each time) listed.
    for (PairDistance& pd : listed.pairs) pd.distance = -1234.5;
    pairs.clear();
    for (int i = c % 3; i < static_cast<int>(m.pairs.size()); i += 3) pairs.push_back(i);
    computeListedPairDistances(m, kin, full.slots, listed, pairs.data(), static_cast<int>(pairs.size()));
    for (std::size_t i = 0; i < m.pairs.size(); ++i) {
      const PairDistance& f = full.pairs[i];
      const PairDistance& l = listed.pairs[i];
      if (static_cast<int>(i) % 3 != c % 3) {
        EXPECT_EQ(l.distance, -1234.5) << "pair " << i << " was not listed and must stay as it was";
        ++untouched;
        continue;
      }
      ASSERT_EQ(l.active, f.active) << "pair " << i;
      if (!f.active) {
        ++inactive;
        continue;
      }
      EXPECT_EQ(l.distance, f.distance) << "pair " << i;
      EXPECT_EQ(l.p_B_a, f.p_B_a) << "pair " << i;
      EXPECT_EQ(l.p_B_b, f.p_B_b) << "pair " << i;
      EXPECT_EQ(l.nhat_B, f.nhat_B) << "pair " << i;
      EXPECT_FALSE(l.has_row);
      ++compared;
    }
  }
  EXPECT_GT(compared, 60 * 300);
  EXPECT_GT(untouched, 60 * 600);
  EXPECT_GT(inactive, 30 * 50) << "the disabled slot's pairs (and the unused slots') come out inactive";
}

// ---------------------------------------------------------------- sweep kernels
// The AVX2 kernels (four primitive pairs, four bounding-sphere gaps per instruction) against the
// scalar ones, which the tests above check against FCL and the brute force: the same bits, on
// whole robots (every field of every pair, pruned and unpruned, with a body-schema slot) and on
// primitive pairs made to hit every branch of the scalar code (parallel, anti-parallel, points,
// coincident cores, NaN and infinite coordinates, batches not a multiple of four).

/// Whether two doubles are the same bits, or both NaN (a NaN's sign and payload carry nothing).
bool sameBits(double a, double b) { return (std::isnan(a) && std::isnan(b)) || std::memcmp(&a, &b, sizeof a) == 0; }

TEST(DistanceSweepKernels, TheFastestKernelIsAvx2WhereTheCpuHasIt) {
  __builtin_cpu_init();
  const bool avx2 = __builtin_cpu_supports("avx2");
  std::printf("this CPU %s AVX2: the sweep runs the %s kernel\n", avx2 ? "has" : "has no",
              fastestSweepKernel() == SweepKernel::kAvx2 ? "AVX2" : "scalar");
  EXPECT_EQ(fastestSweepKernel(), avx2 ? SweepKernel::kAvx2 : SweepKernel::kScalar);
  EXPECT_EQ(DistanceData(testing::loadRobot(testing::kAsimo)).kernel, fastestSweepKernel());
}

void checkKernelsAgree(const Model& m, int configurations, unsigned seed) {
  KinematicsData kin(m);
  DistanceData scalar(m), fast(m);
  scalar.kernel = SweepKernel::kScalar;
  fast.kernel = fastestSweepKernel();
  ASSERT_TRUE(attachBodySchemaSegment(m, scalar, 2, m.linkIndex("l_hand"), Vector3d(0, 0, -0.08),
                                      Vector3d(0.2, 0, -0.08), 0.02));
  fast.slots = scalar.slots;
  std::mt19937_64 rng(seed);
  long compared = 0;
  for (int c = 0; c < configurations; ++c) {
    ASSERT_TRUE(computeForwardKinematics(m, kin, test::randomConfiguration(m, rng)));
    DistanceOptions options;
    options.row_threshold = 0.04;
    if (c % 2 == 1) options.prune_distance = 0.10;
    computeSegmentDistances(m, kin, scalar, options);
    computeSegmentDistances(m, kin, fast, options);
    ASSERT_EQ(fast.closest, scalar.closest) << "configuration " << c;
    ASSERT_EQ(fast.num_exact_pairs, scalar.num_exact_pairs);
    ASSERT_EQ(fast.num_pruned_pairs, scalar.num_pruned_pairs);
    ASSERT_TRUE(sameBits(fast.pruned_floor, scalar.pruned_floor));
    for (std::size_t i = 0; i < m.pairs.size(); ++i) {
      const PairDistance& a = scalar.pairs[i];
      const PairDistance& b = fast.pairs[i];
      const std::string name = m.segments[a.seg_a].name + "-" + m.segments[a.seg_b].name;
      ASSERT_EQ(b.active, a.active) << name;
      ASSERT_EQ(b.exact, a.exact) << name;
      ASSERT_EQ(b.has_row, a.has_row) << name;
      ASSERT_TRUE(sameBits(b.distance, a.distance)) << name << ": " << b.distance << " vs " << a.distance;
      if (!a.active || !a.exact) continue;
      expectSamePair(scalar, fast, i, name);
      ++compared;
    }
  }
  std::printf("%s, %d configurations: %ld exact pairs identical\n", m.name.c_str(), configurations, compared);
  EXPECT_GT(compared, configurations * 50);
}

TEST(DistanceSweepKernels, FastSweepEqualsScalarSweepBitForBitOnWholeRobots) {
  checkKernelsAgree(testing::loadRobot(testing::kAsimo), 200, 41);
  checkKernelsAgree(testing::loadRobot("many_segment_humanoid"), 80, 42);
  checkKernelsAgree(testing::loadRobot(testing::kSmall), 120, 43);
}

TEST(DistanceSweepKernels, KernelsGiveTheSameBitsOnEveryBranch) {
  // Primitives (start, end): random ones, then the scalar code's special cases.
  std::mt19937_64 rng(44);
  std::uniform_real_distribution<double> u(-0.3, 0.3);
  auto rnd = [&] { return Vector3d(u(rng), u(rng), u(rng)); };
  const double nan = std::numeric_limits<double>::quiet_NaN(), inf = std::numeric_limits<double>::infinity();
  std::vector<SegmentB> prim;
  for (int k = 0; k < 200; ++k) prim.emplace_back(rnd(), rnd());
  const Vector3d p(0.1, 0.2, 0.3), d(0.05, -0.02, 0.1);
  prim.emplace_back(p, p + d);                                                      // 200
  prim.emplace_back(p + Vector3d(0, 0.03, 0), p + Vector3d(0, 0.03, 0) + 2.0 * d);  // parallel to 200
  prim.emplace_back(p + d, p - d);                                                  // anti-parallel, overlapping 200
  prim.emplace_back(p, p);                                                          // a point (sphere)
  prim.emplace_back(p + 0.5 * d, p + 0.5 * d);                                      // a point on 200's core
  prim.emplace_back(p + d, p + d + 1e-9 * Vector3d(1, 1, 0));                       // nearly a point
  prim.emplace_back(p, p + d * (1.0 + 1e-15));                                      // nearly identical to 200
  prim.emplace_back(Vector3d(nan, 0, 0), Vector3d(0, 0, 0));                        // NaN
  prim.emplace_back(Vector3d(0, inf, 0), Vector3d(0, 0, 1));                        // infinite
  prim.emplace_back(Vector3d(1e200, 0, 0), Vector3d(-1e200, 0, 1));                 // huge
  const int special_begin = 200, nprim = static_cast<int>(prim.size());
  std::vector<int> a, b;
  for (int i = special_begin; i < nprim; ++i)
    for (int j = 0; j < nprim; ++j) {  // every special one against everything
      a.push_back(i);
      b.push_back(j);
      a.push_back(j);
      b.push_back(i);
    }
  std::uniform_int_distribution<int> pick(0, special_begin - 1);
  for (int k = 0; k < 2003; ++k) {  // not a multiple of four: the tail runs the scalar code
    a.push_back(pick(rng));
    b.push_back(pick(rng));
  }
  const int n = static_cast<int>(a.size());
  std::vector<double> core0(n), s0(n), t0(n), core1(n), s1(n), t1(n);
  detail::coreDistancesScalar(prim.data(), a.data(), b.data(), n, core0.data(), s0.data(), t0.data());
  if (detail::avx2Available())
    detail::coreDistancesAvx2(prim.data(), a.data(), b.data(), n, core1.data(), s1.data(), t1.data());
  else  // no AVX2 here: the comparison below checks the scalar kernel against itself per call
    detail::coreDistancesScalar(prim.data(), a.data(), b.data(), n, core1.data(), s1.data(), t1.data());
  int nan_results = 0;
  for (int k = 0; k < n; ++k) {
    ASSERT_TRUE(sameBits(core1[k], core0[k]))
        << "pair " << a[k] << "-" << b[k] << ": " << core1[k] << " vs " << core0[k];
    ASSERT_TRUE(sameBits(s1[k], s0[k])) << "pair " << a[k] << "-" << b[k];
    ASSERT_TRUE(sameBits(t1[k], t0[k])) << "pair " << a[k] << "-" << b[k];
    nan_results += std::isnan(core0[k]);
    // The scalar kernel is geometry.hpp's closest points (checked against FCL in geometry_test).
    double s, t;
    closestParametersSegmentSegment(prim[a[k]], prim[b[k]], s, t);
    ASSERT_TRUE(sameBits(s, s0[k]) && sameBits(t, t0[k])) << "pair " << a[k] << "-" << b[k];
  }
  EXPECT_GT(nan_results, 0) << "the NaN primitive must reach the kernels";

  // The broad phase's gaps: centres (x, y, z, 0) and radius sums.
  std::vector<double> c4;
  for (const SegmentB& q : prim) c4.insert(c4.end(), {q.start.x(), q.start.y(), q.start.z(), 0.0});
  std::vector<double> rsum(n), gap0(n), gap1(n);
  for (int k = 0; k < n; ++k) rsum[k] = 0.01 * (k % 7);
  detail::boundGapsScalar(c4.data(), a.data(), b.data(), rsum.data(), n, gap0.data());
  if (detail::avx2Available())
    detail::boundGapsAvx2(c4.data(), a.data(), b.data(), rsum.data(), n, gap1.data());
  else
    detail::boundGapsScalar(c4.data(), a.data(), b.data(), rsum.data(), n, gap1.data());
  for (int k = 0; k < n; ++k) {
    ASSERT_TRUE(sameBits(gap1[k], gap0[k])) << "pair " << a[k] << "-" << b[k];
    if (std::isfinite(gap0[k])) {  // independent: Eigen's norm, to rounding
      EXPECT_NEAR(gap0[k], (prim[a[k]].start - prim[b[k]].start).norm() - rsum[k], 1e-12);
    }
  }
}

TEST(DistanceBroadPhase, BoundingSpheresEncloseEveryPrimitive) {
  // Independent of the sweep: sample points on every primitive's surface and check the segment's
  // bounding sphere (in the link frame) contains them.
  const Model m = testing::loadRobot("many_segment_humanoid");
  const DistanceData dist(m);
  std::mt19937_64 rng(25);
  std::normal_distribution<double> normal;
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  for (int s = 0; s < m.num_robot_segments; ++s) {
    const Segment& seg = m.segments[s];
    for (int p = seg.first_primitive; p < seg.first_primitive + seg.num_primitives; ++p) {
      const Primitive& prim = m.primitives[p];
      for (int k = 0; k < 200; ++k) {
        const Vector3d dir = Vector3d(normal(rng), normal(rng), normal(rng)).normalized();
        const Vector3d x = prim.a_L + unit(rng) * (prim.b_L - prim.a_L) + prim.radius * dir;
        EXPECT_LE((x - dist.bound_center_L[s]).norm(), dist.bound_radius[s] + 1e-12) << seg.name;
      }
    }
  }
}

// ---------------------------------------------------------------- segments of several links
/// The mesh robot with each forearm and its hand as one segment (collision YAML `segments:`).
Model meshRobotWithForearmSegments() {
  CollisionConfig config = loadCollisionConfig(testing::robotPath("mesh_humanoid.collision.yaml"));
  config.segments = {{"l_forearm", {"l_hand"}}, {"r_forearm", {"r_hand"}}};
  return loadModel(testing::robotPath("mesh_humanoid.urdf"), config);
}

/// A segment of several links is the closest of its link pairs: against the same robot with a segment
/// per link (the independent answer: pair by pair, the sweep tested above), at random configurations,
/// each pair of the grouped model is the least of the per-link pairs it is made of (the same link
/// pairs: a hand-upper arm pair is checked inside the forearm segment's pair with the upper arm,
/// whose forearm-upper arm link pair is adjacent, not checked), with and without the broad phase; its
/// witness points, normal and row are those of that per-link pair (the row on every joint, the wrist
/// between forearm and hand included: the gradient of the distance).
TEST(DistanceSegmentsOfSeveralLinks, EachPairIsTheClosestOfItsLinkPairs) {
  const Model flat = testing::loadRobot("mesh_humanoid");
  const Model grouped = meshRobotWithForearmSegments();
  ASSERT_EQ(grouped.num_robot_segments, flat.num_robot_segments - 2);
  ASSERT_EQ(grouped.pieces.size(), flat.pieces.size());
  const int l_forearm = grouped.segmentIndex("l_forearm");
  ASSERT_GE(l_forearm, 0);
  EXPECT_EQ(grouped.segmentIndex("l_hand"), l_forearm) << "a link of a segment names the segment";
  // Which grouped pair each per-link pair falls in (by link names), and the reverse.
  std::vector<int> grouped_pair_of(flat.pairs.size(), -1);
  int upper_arm_pair = -1;
  for (std::size_t i = 0; i < flat.pairs.size(); ++i) {
    const SegmentPair& p = flat.pairs[i];
    if (flat.segments[p.b].body_schema_slot) continue;
    const int a = grouped.segmentIndex(flat.segments[p.a].name), b = grouped.segmentIndex(flat.segments[p.b].name);
    ASSERT_GE(a, 0);
    ASSERT_GE(b, 0);
    ASSERT_NE(a, b) << "a per-link pair inside one segment is not checked";
    for (std::size_t j = 0; j < grouped.pairs.size(); ++j)
      if ((grouped.pairs[j].a == std::min(a, b) && grouped.pairs[j].b == std::max(a, b))) grouped_pair_of[i] = j;
    ASSERT_GE(grouped_pair_of[i], 0) << flat.segments[p.a].name << "-" << flat.segments[p.b].name;
  }
  for (std::size_t j = 0; j < grouped.pairs.size(); ++j)
    if (grouped.segments[grouped.pairs[j].a].name == "l_upper_arm" && grouped.pairs[j].b == l_forearm)
      upper_arm_pair = static_cast<int>(j);
  ASSERT_GE(upper_arm_pair, 0) << "the hand-upper arm link pair keeps the segment pair checked";
  const std::vector<std::array<int, 2>> adjacent{{flat.linkIndex("l_upper_arm"), flat.linkIndex("l_forearm")}};
  EXPECT_EQ(grouped.pairs[static_cast<std::size_t>(upper_arm_pair)].unchecked_links, adjacent);
  const int wrist = grouped.qIndex("l_wrist_pitch");
  KinematicsData kin_flat(flat), kin_grouped(grouped);
  DistanceData dist_flat(flat), dist_grouped(grouped);
  std::mt19937_64 rng(61);
  long compared = 0, multi = 0, skipped = 0, on_wrist = 0;
  for (const double prune : {std::numeric_limits<double>::infinity(), 0.05}) {
    DistanceOptions options;
    options.prune_distance = prune;
    for (int c = 0; c < 150; ++c) {
      const Eigen::VectorXd q = test::randomConfiguration(flat, rng);
      ASSERT_TRUE(computeForwardKinematics(flat, kin_flat, q));
      ASSERT_TRUE(computeForwardKinematics(grouped, kin_grouped, q));
      computeSegmentDistances(flat, kin_flat, dist_flat);  // every pair exact: the answer
      computeSegmentDistances(grouped, kin_grouped, dist_grouped, options);
      for (std::size_t j = 0; j < grouped.pairs.size(); ++j) {
        const PairDistance& g = dist_grouped.pairs[j];
        if (grouped.segments[grouped.pairs[j].b].body_schema_slot) continue;
        double least = std::numeric_limits<double>::infinity();
        int from = -1, members = 0;
        for (std::size_t i = 0; i < flat.pairs.size(); ++i)
          if (grouped_pair_of[i] == static_cast<int>(j)) {
            ++members;
            if (dist_flat.pairs[i].distance < least) least = dist_flat.pairs[i].distance, from = static_cast<int>(i);
          }
        ASSERT_GE(from, 0);
        const std::string name = grouped.segments[g.seg_a].name + "-" + grouped.segments[g.seg_b].name;
        if (!g.exact) {
          ++skipped;
          EXPECT_GT(g.distance, prune) << name;
          EXPECT_LE(g.distance, least + 1e-12) << name << ": a skipped pair's bound is a lower bound";
          continue;
        }
        ++compared;
        multi += members > 1 ? 1 : 0;
        ASSERT_NEAR(g.distance, least, 1e-12) << name << " configuration " << c;
        const PairDistance& f = dist_flat.pairs[static_cast<std::size_t>(from)];
        if (least <= 0.0) continue;  // touching pieces: any common point
        // The per-link pair may list the two the other way round (a hand after a foot).
        const bool swapped = grouped.segmentIndex(flat.segments[f.seg_a].name) != g.seg_a;
        EXPECT_LT((g.p_B_a - (swapped ? f.p_B_b : f.p_B_a)).norm(), 1e-9) << name;
        EXPECT_LT((g.nhat_B - (swapped ? -f.nhat_B : f.nhat_B)).norm(), 1e-9) << name;
        if (!g.has_row) continue;
        // The row: the per-link pair's, every column (the witness points' Jacobians on their own
        // links: the wrist joint between forearm and hand moves a hand point).
        ASSERT_TRUE(f.has_row);
        for (int k = 0; k < grouped.nq; ++k)
          EXPECT_NEAR(dist_grouped.rows(static_cast<Eigen::Index>(j), k), dist_flat.rows(from, k), 1e-9)
              << name << " joint " << grouped.q_names[static_cast<std::size_t>(k)];
        if (g.seg_a == l_forearm || g.seg_b == l_forearm)
          on_wrist += dist_grouped.rows(static_cast<Eigen::Index>(j), wrist) != 0.0 ? 1 : 0;
      }
    }
  }
  std::printf(
      "grouped mesh robot: %ld pairs equal to the least of their link pairs (%ld of several link pairs), "
      "%ld skipped by the broad phase (lower bounds)\n",
      compared, multi, skipped);
  EXPECT_GT(multi, 300);
  EXPECT_GT(skipped, 100);
  EXPECT_GT(on_wrist, 100) << "rows of forearm-segment pairs won by the hand move with the wrist joint";
}

/// A segment is placed into B again only when one of its links moved: with every joint held but the
/// left wrist, the left forearm segment's own link stays where it was while its hand block moves, so
/// the segment must be placed again. Along a trajectory, a DistanceData used every call has every
/// primitive, every bounding sphere and every pair within the prune distance exactly where a fresh
/// one has them.
TEST(DistanceSegmentsOfSeveralLinks, ASegmentWhoseBlockMovedIsPlacedAgain) {
  const Model m = meshRobotWithForearmSegments();
  const int wrist = m.qIndex("l_wrist_pitch");
  ASSERT_GE(wrist, 0);
  KinematicsData kin(m);
  DistanceOptions options;
  options.prune_distance = 0.1;
  DistanceData reused(m);
  Trajectory path(m, 47, 25, 0.05);
  const Eigen::VectorXd held = path.q;
  long compared = 0;
  for (int c = 0; c < 200; ++c) {
    Eigen::VectorXd q = held;
    q[wrist] = path.next()[wrist];
    ASSERT_TRUE(computeForwardKinematics(m, kin, q));
    DistanceData fresh(m);
    computeSegmentDistances(m, kin, reused, options);
    computeSegmentDistances(m, kin, fresh, options);
    for (std::size_t p = 0; p < m.primitives.size(); ++p) {
      ASSERT_EQ(reused.prim_B[p].start, fresh.prim_B[p].start) << "primitive " << p << " call " << c;
      ASSERT_EQ(reused.prim_B[p].d, fresh.prim_B[p].d) << "primitive " << p << " call " << c;
    }
    ASSERT_EQ(reused.bound_center4_B, fresh.bound_center4_B) << "call " << c;
    ASSERT_EQ(reused.bound_radius, fresh.bound_radius) << "call " << c;
    for (std::size_t i = 0; i < m.pairs.size(); ++i) {
      if (!fresh.pairs[i].exact || fresh.pairs[i].distance > options.prune_distance) continue;
      ASSERT_TRUE(reused.pairs[i].exact) << "pair " << i << " call " << c;
      ASSERT_EQ(reused.pairs[i].distance, fresh.pairs[i].distance) << "pair " << i << " call " << c;
      ++compared;
    }
  }
  EXPECT_GE(compared, 100);
}

/// A segment's bounding sphere (the broad phase) holds each of its primitives wherever the joints
/// between its link and theirs put them: after each sweep, surface points of every primitive at random
/// configurations lie in the sphere of that call (a segment of several links: made around its
/// primitives each call; the others: fixed in the link).
TEST(DistanceSegmentsOfSeveralLinks, BoundingSpheresHoldEveryPrimitiveInEveryPosture) {
  const Model m = meshRobotWithForearmSegments();
  DistanceData dist(m);
  KinematicsData kin(m);
  DistanceOptions options;
  options.prune_distance = 0.05;
  std::mt19937_64 rng(62);
  std::normal_distribution<double> normal;
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  int checked = 0;
  for (int c = 0; c < 100; ++c) {
    ASSERT_TRUE(computeForwardKinematics(m, kin, test::randomConfiguration(m, rng)));
    computeSegmentDistances(m, kin, dist, options);
    for (int s = 0; s < m.num_robot_segments; ++s) {
      const Segment& seg = m.segments[s];
      const double* c4 = dist.bound_center4_B.data() + 4 * s;
      const Vector3d centre(c4[0], c4[1], c4[2]);
      for (int p = seg.first_primitive; p < seg.first_primitive + seg.num_primitives; ++p) {
        const Primitive& prim = m.primitives[p];
        const Eigen::Isometry3d& X = kin.X_B_L[linkOf(seg, prim)];
        for (int k = 0; k < 20; ++k, ++checked) {
          const Vector3d dir = Vector3d(normal(rng), normal(rng), normal(rng)).normalized();
          const Vector3d x = X * (prim.a_L + unit(rng) * (prim.b_L - prim.a_L) + prim.radius * dir);
          ASSERT_LE((x - centre).norm(), dist.bound_radius[s] + 1e-12) << seg.name;
        }
      }
    }
  }
  EXPECT_GT(checked, 10000);
}

/// A body-schema segment hung on a link of a segment of several links is never checked against that
/// segment (as against the segment of its own link), and is against the others.
TEST(DistanceSegmentsOfSeveralLinks, ASlotOnTheHandSkipsTheSegmentThatHasTheHand) {
  const Model m = meshRobotWithForearmSegments();
  DistanceData dist(m);
  KinematicsData kin(m);
  std::mt19937_64 rng(63);
  ASSERT_TRUE(computeForwardKinematics(m, kin, test::randomConfiguration(m, rng)));
  ASSERT_TRUE(attachBodySchemaSegment(m, dist, 0, m.linkIndex("l_hand"), Vector3d(0, 0, 0), Vector3d(0.1, 0, 0), 0.02));
  computeSegmentDistances(m, kin, dist);
  int active = 0;
  for (std::size_t i = 0; i < m.pairs.size(); ++i) {
    if (m.pairs[i].b != m.num_robot_segments) continue;
    if (m.pairs[i].a == m.segmentIndex("l_forearm"))
      EXPECT_FALSE(dist.pairs[i].active);
    else
      active += dist.pairs[i].active ? 1 : 0;
  }
  EXPECT_EQ(active, m.num_robot_segments - 1);
}

// ---------------------------------------------------------------- body schema
TEST(DistanceBodySchema, SlotCapsuleOnTheHandIsChecked) {
  const Model m = testing::loadRobot(testing::kAsimo);
  KinematicsData kin(m);
  DistanceData dist(m);
  std::mt19937_64 rng(5);
  ASSERT_TRUE(computeForwardKinematics(m, kin, test::randomConfiguration(m, rng)));
  const int hand = m.linkIndex("l_hand");
  const int hand_seg = m.segmentIndex("l_hand");
  const int forearm_seg = m.segmentIndex("l_forearm");
  // A 20 cm stick held in the left hand, never checked against the left forearm.
  const Vector3d a_L(0, 0, -0.08), b_L(0.2, 0, -0.08);
  ASSERT_TRUE(attachBodySchemaSegment(m, dist, 1, hand, a_L, b_L, 0.02, std::uint64_t{1} << forearm_seg));
  computeSegmentDistances(m, kin, dist);
  const int slot_seg = m.num_robot_segments + 1;
  int active = 0, compared = 0;
  for (const PairDistance& pd : dist.pairs) {
    if (pd.seg_b != slot_seg) {
      if (m.segments[pd.seg_b].body_schema_slot) {
        EXPECT_FALSE(pd.active);
      }
      continue;
    }
    const bool expect_active = pd.seg_a != hand_seg && pd.seg_a != forearm_seg;
    EXPECT_EQ(pd.active, expect_active) << m.segments[pd.seg_a].name;
    if (!pd.active) continue;
    ++active;
    // Against FCL with the stick placed by hand.
    const Eigen::Isometry3d& X = kin.X_B_L[hand];
    const Segment& S = m.segments[pd.seg_a];
    double best = std::numeric_limits<double>::infinity();
    for (int p = S.first_primitive; p < S.first_primitive + S.num_primitives; ++p) {
      const Primitive& P = m.primitives[p];
      const Eigen::Isometry3d& XA = kin.X_B_L[S.link];
      fcl::Transform3d Xa, Xb;
      const auto ga = fclShape(XA * P.a_L, P.sphere ? Vector3d(XA * P.a_L) : Vector3d(XA * P.b_L), P.radius, Xa);
      const auto gb = fclShape(X * a_L, X * b_L, 0.02, Xb);
      fcl::DistanceRequestd request;
      fcl::DistanceResultd result;
      fcl::distance(ga.get(), Xa, gb.get(), Xb, request, result);
      best = std::min(best, result.min_distance);
    }
    if (best > 1e-9) {  // FCL gives no distance for touching / penetrating spheres
      EXPECT_NEAR(pd.distance, best, 1e-9) << S.name;
      ++compared;
    }
    EXPECT_LT((pd.p_B_a - pd.p_B_b - pd.distance * pd.nhat_B).norm(), 1e-12);
    // The row of a slot pair uses the slot's link (the hand) for p_b.
    Eigen::MatrixXd Ja(3, m.nq), Jb(3, m.nq);
    computePointJacobian(m, kin, S.link, pd.p_B_a, Ja);
    computePointJacobian(m, kin, hand, pd.p_B_b, Jb);
    const Eigen::Index i = &pd - dist.pairs.data();
    EXPECT_LT((dist.rows.row(i) - pd.nhat_B.transpose() * (Ja - Jb)).cwiseAbs().maxCoeff(), 1e-12);
  }
  EXPECT_EQ(active, m.num_robot_segments - 2);
  EXPECT_GE(compared, active - 3);
  // Detach: inactive again, distance +inf, and the closest pair is a robot pair.
  ASSERT_TRUE(detachBodySchemaSegment(dist, 1));
  computeSegmentDistances(m, kin, dist);
  for (const PairDistance& pd : dist.pairs)
    if (pd.seg_b == slot_seg) {
      EXPECT_FALSE(pd.active);
      EXPECT_EQ(pd.distance, std::numeric_limits<double>::infinity());
    }
  EXPECT_FALSE(m.segments[dist.pairs[dist.closest].seg_b].body_schema_slot);
}

/// The sweep skips the slot pairs while every slot stays disabled and their entries are already
/// inactive; whatever computed a slot pair in between (the sweep itself, computeListedPairDistances)
/// makes the next sweep clear them again.
TEST(DistanceBodySchema, SlotPairsComeOutInactiveAfterEveryWayOfComputingThem) {
  const Model m = testing::loadRobot(testing::kAsimo);
  KinematicsData kin(m);
  DistanceData dist(m);
  std::mt19937_64 rng(6);
  ASSERT_TRUE(computeForwardKinematics(m, kin, test::randomConfiguration(m, rng)));
  BodySchemaSlots held{}, none{};
  DistanceData holder(m);
  ASSERT_TRUE(attachBodySchemaSegment(m, holder, 0, m.linkIndex("r_hand"), Vector3d(0, 0, -0.08),
                                      Vector3d(0.2, 0, -0.08), 0.02));
  held = holder.slots;
  std::vector<int> slot_pairs;
  for (std::size_t i = 0; i < m.pairs.size(); ++i)
    if (m.segments[m.pairs[i].b].body_schema_slot) slot_pairs.push_back(static_cast<int>(i));
  ASSERT_FALSE(slot_pairs.empty());
  auto activeSlotPairs = [&] {
    int n = 0;
    for (const int i : slot_pairs) {
      const PairDistance& pd = dist.pairs[static_cast<std::size_t>(i)];
      if (pd.active)
        ++n;
      else
        EXPECT_EQ(pd.distance, std::numeric_limits<double>::infinity());
    }
    return n;
  };
  computeSegmentDistances(m, kin, none, dist);
  EXPECT_EQ(activeSlotPairs(), 0);
  computeSegmentDistances(m, kin, held, dist);  // the sweep computes them
  const int with_slot = activeSlotPairs();
  EXPECT_GT(with_slot, 0);
  computeSegmentDistances(m, kin, none, dist);
  EXPECT_EQ(activeSlotPairs(), 0);
  computeSegmentDistances(m, kin, none, dist);  // skipped: still inactive
  EXPECT_EQ(activeSlotPairs(), 0);
  // The predictive guard's listed pairs compute them on the same data with the slot held ...
  computeListedPairDistances(m, kin, held, dist, slot_pairs.data(), static_cast<int>(slot_pairs.size()));
  EXPECT_EQ(activeSlotPairs(), with_slot);
  // ... and the next sweep without it clears them.
  computeSegmentDistances(m, kin, none, dist);
  EXPECT_EQ(activeSlotPairs(), 0);
}

TEST(DistanceBodySchema, BadArgumentsAreRejectedAndChangeNothing) {
  const Model m = testing::loadRobot(testing::kAsimo);
  DistanceData dist(m);
  const Vector3d a(0, 0, 0), b(0.1, 0, 0);
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const double inf = std::numeric_limits<double>::infinity();
  const int nlinks = static_cast<int>(m.links.size());
  EXPECT_FALSE(attachBodySchemaSegment(m, dist, -1, 0, a, b, 0.1));
  EXPECT_FALSE(attachBodySchemaSegment(m, dist, kBodySchemaSlots, 0, a, b, 0.1));
  EXPECT_FALSE(attachBodySchemaSegment(m, dist, 0, -1, a, b, 0.1));
  EXPECT_FALSE(attachBodySchemaSegment(m, dist, 0, nlinks, a, b, 0.1));
  EXPECT_FALSE(attachBodySchemaSegment(m, dist, 0, 0, a, b, 0.0));
  EXPECT_FALSE(attachBodySchemaSegment(m, dist, 0, 0, a, b, -0.1));
  EXPECT_FALSE(attachBodySchemaSegment(m, dist, 0, 0, a, b, nan));
  EXPECT_FALSE(attachBodySchemaSegment(m, dist, 0, 0, a, b, inf));
  EXPECT_FALSE(attachBodySchemaSegment(m, dist, 0, 0, Vector3d(nan, 0, 0), b, 0.1));
  EXPECT_FALSE(attachBodySchemaSegment(m, dist, 0, 0, a, Vector3d(0, inf, 0), 0.1));
  for (const BodySchemaSlot& s : dist.slots) {
    EXPECT_FALSE(s.enabled);
    EXPECT_EQ(s.radius, 0.0);
  }
  EXPECT_FALSE(detachBodySchemaSegment(dist, -1));
  EXPECT_FALSE(detachBodySchemaSegment(dist, kBodySchemaSlots));
}

// The boundary check of body-schema samples (reflex_controller): hand-computed sizes against the
// documented default limits, each fault with its value, limit and field name; the segments the
// shipped behaviors and scenarios attach pass.
TEST(DistanceBodySchema, CheckRejectsAbsurdSegmentsAndNamesTheBadValue) {
  const Model m = testing::loadRobot(testing::kAsimo);
  const BodySchemaLimits lim;  // defaults: radius 0.5, physical length / reach 1.0, virtual 4.0
  const int hand = m.linkIndex("l_hand");
  const int head = m.linkIndex("head");
  ASSERT_GE(hand, 0);
  ASSERT_GE(head, 0);
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const double inf = std::numeric_limits<double>::infinity();
  const Vector3d o = Vector3d::Zero();

  // Accepted: the grasped bar of bringup/behavior/bar_occlusion.yaml (0.30 m, r 0.02), the bar of the
  // grasped_bar scenario, a sphere exactly at the radius limit, a capsule exactly at the length limit.
  EXPECT_TRUE(
      checkBodySchemaSegment(m, hand, Vector3d(0, -0.15, -0.06), Vector3d(0, 0.15, -0.06), 0.02, false, lim).ok());
  EXPECT_TRUE(
      checkBodySchemaSegment(m, hand, Vector3d(-0.16, 0, -0.06), Vector3d(0.16, 0, -0.06), 0.02, false, lim).ok());
  EXPECT_TRUE(checkBodySchemaSegment(m, hand, o, o, 0.5, false, lim).ok());
  EXPECT_TRUE(checkBodySchemaSegment(m, hand, Vector3d(-0.5, 0, 0), Vector3d(0.5, 0, 0), 0.01, false, lim).ok());
  // A gaze line from the head camera to an object on the floor 3 m ahead (the behavior host's
  // default max_range), expressed in the head link frame at q = 0: a virtual segment, accepted.
  KinematicsData kin(m);
  const Eigen::Isometry3d X_head_B = kin.X_B_L[head].inverse();
  const Vector3d cam_B = kin.X_B_L[m.linkIndex("head_camera")].translation();
  const Vector3d a_gaze = X_head_B * cam_B, b_gaze = X_head_B * Vector3d(3.0, 0.0, 0.0);
  ASSERT_GT((b_gaze - a_gaze).norm(), 3.0);
  EXPECT_TRUE(checkBodySchemaSegment(m, head, a_gaze, b_gaze, 0.03, true, lim).ok());
  // ... but the same line as a physical segment is too long for anything a link holds.
  const BodySchemaCheck phys = checkBodySchemaSegment(m, head, a_gaze, b_gaze, 0.03, false, lim);
  EXPECT_EQ(phys.fault, BodySchemaFault::kTooLong);
  EXPECT_NEAR(phys.value, (b_gaze - a_gaze).norm(), 1e-12);
  EXPECT_STREQ(phys.key, "max_length");

  // The 1 km sphere of the earlier review.
  BodySchemaCheck c = checkBodySchemaSegment(m, hand, o, o, 1000.0, false, lim);
  EXPECT_EQ(c.fault, BodySchemaFault::kRadiusTooLarge);
  EXPECT_EQ(c.value, 1000.0);
  EXPECT_EQ(c.limit, 0.5);
  EXPECT_STREQ(c.key, "max_radius");
  EXPECT_EQ(checkBodySchemaSegment(m, head, o, o, 0.51, true, lim).fault, BodySchemaFault::kRadiusTooLarge)
      << "the radius bound holds for virtual segments too";
  // Length: (0.3, 0.4, 1.2) is 1.3 m long: too long for a physical segment, fine for a virtual one.
  const Vector3d a(0.0, 0.0, 0.0), b(0.3, 0.4, 1.2);
  c = checkBodySchemaSegment(m, hand, a, b, 0.02, false, lim);
  EXPECT_EQ(c.fault, BodySchemaFault::kTooLong);
  EXPECT_NEAR(c.value, 1.3, 1e-12);
  EXPECT_EQ(c.limit, 1.0);
  EXPECT_TRUE(checkBodySchemaSegment(m, hand, a, b, 0.02, true, lim).ok());
  // Reach: a short segment far from the link (a sphere 1.2 m from the hand origin; 5 m virtual).
  c = checkBodySchemaSegment(m, hand, Vector3d(0, 1.2, 0), Vector3d(0, 1.2, 0), 0.02, false, lim);
  EXPECT_EQ(c.fault, BodySchemaFault::kTooFar);
  EXPECT_NEAR(c.value, 1.2, 1e-12);
  EXPECT_STREQ(c.key, "max_reach");
  c = checkBodySchemaSegment(m, head, Vector3d(0, 0, 5.0), Vector3d(0, 0, 4.5), 0.02, true, lim);
  EXPECT_EQ(c.fault, BodySchemaFault::kTooFar);
  EXPECT_NEAR(c.value, 5.0, 1e-12);
  EXPECT_STREQ(c.key, "max_virtual_reach");
  c = checkBodySchemaSegment(m, head, Vector3d(0, 0, -2.1), Vector3d(0, 0, 2.1), 0.02, true, lim);
  EXPECT_EQ(c.fault, BodySchemaFault::kTooLong);
  EXPECT_STREQ(c.key, "max_virtual_length");
  // Non-finite, non-positive and unknown link: no size limit, the bad value is reported.
  c = checkBodySchemaSegment(m, hand, Vector3d(0, nan, 0), b, 0.02, false, lim);
  EXPECT_EQ(c.fault, BodySchemaFault::kNonFinite);
  EXPECT_TRUE(std::isnan(c.value));
  EXPECT_STREQ(c.key, "");
  EXPECT_EQ(checkBodySchemaSegment(m, hand, a, Vector3d(-inf, 0, 0), 0.02, false, lim).fault,
            BodySchemaFault::kNonFinite);
  EXPECT_EQ(checkBodySchemaSegment(m, hand, a, a, inf, false, lim).fault, BodySchemaFault::kNonFinite);
  EXPECT_EQ(checkBodySchemaSegment(m, hand, a, a, 0.0, false, lim).fault, BodySchemaFault::kRadiusNotPositive);
  EXPECT_EQ(checkBodySchemaSegment(m, hand, a, a, -0.01, false, lim).fault, BodySchemaFault::kRadiusNotPositive);
  EXPECT_EQ(checkBodySchemaSegment(m, -1, a, a, 0.02, false, lim).fault, BodySchemaFault::kUnknownLink);
  EXPECT_EQ(checkBodySchemaSegment(m, static_cast<int>(m.links.size()), a, a, 0.02, false, lim).fault,
            BodySchemaFault::kUnknownLink);
  // Limits are parameters: a tighter radius bound rejects what the default accepts.
  BodySchemaLimits tight;
  tight.max_radius = 0.01;
  EXPECT_EQ(checkBodySchemaSegment(m, hand, a, a, 0.02, false, tight).fault, BodySchemaFault::kRadiusTooLarge);
  for (BodySchemaFault f : {BodySchemaFault::kRadiusTooLarge, BodySchemaFault::kTooLong, BodySchemaFault::kTooFar})
    EXPECT_NE(std::string(describe(f)).find("limit"), std::string::npos);
}

TEST(DistanceBodySchema, CoincidentCoresGetTheLinkFallbackNormal) {
  // A sphere on the world link centred exactly on the head sphere's centre at q = 0.
  const Model m = testing::loadRobot(testing::kAsimo);
  KinematicsData kin(m);
  DistanceData dist(m);
  const int head = m.linkIndex("head");
  const Segment& hs = m.segments[m.segmentIndex("head")];
  const Vector3d centre_B = kin.X_B_L[head] * m.primitives[hs.first_primitive].a_L;
  ASSERT_TRUE(attachBodySchemaSegment(m, dist, 0, 0, centre_B, centre_B, 0.05));
  computeSegmentDistances(m, kin, dist);
  bool found = false;
  for (std::size_t i = 0; i < dist.pairs.size(); ++i) {
    const PairDistance& pd = dist.pairs[i];
    if (pd.seg_a != m.segmentIndex("head") || pd.seg_b != m.num_robot_segments) continue;
    found = true;
    ASSERT_TRUE(pd.active);
    EXPECT_FALSE(pd.well_defined);
    EXPECT_NEAR(pd.distance, -(0.14 + 0.05), 1e-12);
    // Fallback: from the slot's link origin (world) towards the head link origin.
    const Vector3d expected = kin.X_B_L[head].translation().normalized();
    EXPECT_LT((pd.nhat_B - expected).norm(), 1e-12);
    EXPECT_LT((pd.p_B_a - pd.p_B_b - pd.distance * pd.nhat_B).norm(), 1e-12);
    EXPECT_TRUE(dist.rows.row(static_cast<Eigen::Index>(i)).allFinite());
  }
  EXPECT_TRUE(found);
}

// ---------------------------------------------------------------- bad joint values at run time
TEST(DistanceRuntime, NonFiniteJointValuesKeepTheLastValidResult) {
  const Model m = testing::loadRobot(testing::kAsimo);
  KinematicsData kin(m);
  DistanceData dist(m);
  std::mt19937_64 rng(9);
  const Eigen::VectorXd q = test::randomConfiguration(m, rng);
  ASSERT_TRUE(computeForwardKinematics(m, kin, q));
  computeSegmentDistances(m, kin, dist);
  const std::vector<PairDistance> before = dist.pairs;
  for (const double bad : {std::numeric_limits<double>::quiet_NaN(), std::numeric_limits<double>::infinity(),
                           -std::numeric_limits<double>::infinity()}) {
    Eigen::VectorXd qb = test::randomConfiguration(m, rng);
    qb[m.qIndex("l_elbow")] = bad;
    EXPECT_FALSE(computeForwardKinematics(m, kin, qb));
    computeSegmentDistances(m, kin, dist);
    EXPECT_TRUE(dist.rows.allFinite());
    for (std::size_t i = 0; i < before.size(); ++i) {
      if (!before[i].active) continue;
      EXPECT_EQ(dist.pairs[i].distance, before[i].distance);
      EXPECT_EQ(dist.pairs[i].p_B_a, before[i].p_B_a);
      EXPECT_TRUE(dist.pairs[i].nhat_B.allFinite());
    }
  }
}

}  // namespace
}  // namespace reflex::control
