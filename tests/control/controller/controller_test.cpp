// Unit tests of controller.hpp and redundancy.hpp against independent answers: Eq. 13 by hand,
// Eq. 17-18 on hand-made forces, the sign convention by finite differences of the distance,
// nullspace projection by J N = 0, the e-stop latch and its release, motion priority.
#include "support/robot.hpp"

#include "reflex/control/redundancy.hpp"
#include "reflex/control/simulation.hpp"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <fstream>
#include <limits>
#include <map>
#include <string>
#include <cstdio>
#include <random>

namespace reflex::control {
namespace {

using testing::defaultControllerModel;
using testing::shippedModel;

/// A configuration drawn uniformly inside the joint limits, each clipped to [-bound, bound].
Eigen::VectorXd randomConfiguration(const Model& model, std::mt19937& rng, double bound) {
  std::uniform_real_distribution<double> u(0.0, 1.0);
  Eigen::VectorXd q(model.nq);
  for (int i = 0; i < model.nq; ++i) {
    const double lo = std::max(model.q_lower[i], -bound), hi = std::min(model.q_upper[i], bound);
    q[i] = lo + (hi - lo) * u(rng);
  }
  return q;
}

TEST(BlendingCoefficient, MatchesEquation13) {
  const double da = 0.040, db = 0.010;
  EXPECT_DOUBLE_EQ(blendingCoefficient(0.0, da, db), 1.0);
  EXPECT_DOUBLE_EQ(blendingCoefficient(-0.01, da, db), 1.0);
  EXPECT_DOUBLE_EQ(blendingCoefficient(db, da, db), 1.0);
  EXPECT_DOUBLE_EQ(blendingCoefficient(0.025, da, db), 0.5);  // midway
  EXPECT_DOUBLE_EQ(blendingCoefficient(0.034, da, db), 0.2);  // (0.034 - 0.04) / (0.01 - 0.04)
  EXPECT_DOUBLE_EQ(blendingCoefficient(da, da, db), 0.0);
  EXPECT_DOUBLE_EQ(blendingCoefficient(0.5, da, db), 0.0);
  EXPECT_DOUBLE_EQ(blendingCoefficient(std::nan(""), da, db), 1.0);  // unknown distance: most cautious
}

TEST(Zones, Boundaries) {
  ControllerParams p;
  EXPECT_EQ(zoneOf(0.050, p), Zone::kFree);
  EXPECT_EQ(zoneOf(0.040, p), Zone::kFree);
  EXPECT_EQ(zoneOf(0.039, p), Zone::kYellow);
  EXPECT_EQ(zoneOf(0.009, p), Zone::kOrange);
  EXPECT_EQ(zoneOf(0.004, p), Zone::kRed);
  EXPECT_EQ(zoneOf(std::nan(""), p), Zone::kRed);
}

// The exact boundary values, as the paper puts them (Sec. 7.1: the red zone is a
// distance LESS than d_r; Eq. 13: f(d) = 1 for d <= d_b, so d_b itself is orange; f(d_a) = 0, so d_a
// is free), and control.idl's documentation of the Zone enumerators says the same.
TEST(Zones, ExactBoundariesFollowThePaperAndTheIdl) {
  ControllerParams p;
  const double inf = std::numeric_limits<double>::infinity();
  EXPECT_EQ(zoneOf(std::nextafter(p.d_r, 0.0), p), Zone::kRed);
  EXPECT_EQ(zoneOf(p.d_r, p), Zone::kOrange);
  EXPECT_EQ(zoneOf(p.d_b, p), Zone::kOrange);
  EXPECT_DOUBLE_EQ(blendingCoefficient(p.d_b, p.d_a, p.d_b), 1.0);
  EXPECT_EQ(zoneOf(std::nextafter(p.d_b, inf), p), Zone::kYellow);
  EXPECT_EQ(zoneOf(std::nextafter(p.d_a, 0.0), p), Zone::kYellow);
  EXPECT_EQ(zoneOf(p.d_a, p), Zone::kFree);
  EXPECT_DOUBLE_EQ(blendingCoefficient(p.d_a, p.d_a, p.d_b), 0.0);
  // control.idl: one comment per enumerator, with these inequalities.
  std::ifstream idl(std::string(REFLEX_SOURCE_DIR) + "/idl/control.idl");
  ASSERT_TRUE(idl.good());
  std::map<std::string, std::string> comment;
  for (std::string line; std::getline(idl, line);) {
    for (const char* e : {"ZONE_FREE", "ZONE_YELLOW", "ZONE_ORANGE", "ZONE_RED"}) {
      const auto at = line.find(e);
      if (at != std::string::npos && line.find("//") != std::string::npos) comment[e] = line.substr(line.find("//"));
    }
  }
  EXPECT_THAT(comment["ZONE_FREE"], ::testing::HasSubstr("d >= d_a"));
  EXPECT_THAT(comment["ZONE_YELLOW"], ::testing::HasSubstr("d_b < d < d_a"));
  EXPECT_THAT(comment["ZONE_ORANGE"], ::testing::HasSubstr("d_r <= d <= d_b"));
  EXPECT_THAT(comment["ZONE_RED"], ::testing::HasSubstr("d < d_r"));
}

TEST(VirtualForces, Equations17And18OnHandMadePairs) {
  // Two pairs: d1 = 0.02 along +x at p1, d2 = 0.03 along +y at p2; k = 10, d_a = 0.04.
  VirtualForceSum sum;
  const Eigen::Vector3d p1(0.1, 0.0, 0.0), p2(0.0, 0.2, 0.0);
  sum.add(10.0, 0.04, 0.02, Eigen::Vector3d::UnitX(), p1);  // |F1| = 0.2
  sum.add(10.0, 0.04, 0.03, Eigen::Vector3d::UnitY(), p2);  // |F2| = 0.1
  sum.add(10.0, 0.04, 0.05, Eigen::Vector3d::UnitZ(), p2);  // outside the yellow zone: no force
  // Eq. 17: (0.2 * (0.2, 0, 0) + 0.1 * (0, 0.1, 0)) / 0.3
  EXPECT_NEAR(sum.force().x(), 0.04 / 0.3, 1e-15);
  EXPECT_NEAR(sum.force().y(), 0.01 / 0.3, 1e-15);
  EXPECT_NEAR(sum.force().z(), 0.0, 1e-15);
  // Eq. 18: (0.2 * p1 + 0.1 * p2) / 0.3
  EXPECT_TRUE(sum.point().isApprox((0.2 * p1 + 0.1 * p2) / 0.3, 1e-14));
  // One pair alone gives back Eq. 6 and its own point.
  VirtualForceSum one;
  one.add(10.0, 0.04, 0.01, -Eigen::Vector3d::UnitZ(), p1);
  EXPECT_TRUE(one.force().isApprox(Eigen::Vector3d(0, 0, -0.3), 1e-14));
  EXPECT_TRUE(one.point().isApprox(p1, 1e-14));
  EXPECT_TRUE(VirtualForceSum{}.force().isZero());
}

TEST(Redundancy, NullspaceProjectorsAnnihilateTheTask) {
  std::mt19937 rng(7);
  std::normal_distribution<double> g(0.0, 0.3);
  for (int trial = 0; trial < 200; ++trial) {
    const int n = 3 + trial % 6;
    TaskJacobian J(3, n);
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < n; ++j) J(i, j) = g(rng);
    if (trial % 5 == 0) J.row(2) = 0.5 * J.row(0) - 2.0 * J.row(1);  // rank deficient (singular)
    ArmMatrix N;
    nullspaceProjector(J, N);
    ArmVector xi(n);
    for (int j = 0; j < n; ++j) xi[j] = g(rng);
    EXPECT_LT((J * (N * xi)).norm(), 1e-12) << "trial " << trial;
    EXPECT_LT((N * N - N).norm(), 1e-10);                        // a projector
    EXPECT_LT((N - N.transpose()).norm(), 1e-12);                // orthogonal
    EXPECT_NEAR(N.trace(), n - (trial % 5 == 0 ? 2 : 3), 1e-9);  // rank of the nullspace
    ArmRow row(n);
    for (int j = 0; j < n; ++j) row[j] = g(rng);
    ArmMatrix Nr;
    nullspaceProjector(row, Nr);
    EXPECT_LT(std::abs(row.dot((Nr * xi).transpose())), 1e-12);
    // The damped inverse tends to the exact one as lambda -> 0 on a well-conditioned J.
    TaskJacobianInverse Jp;
    dampedPseudoInverse(J, 1e-9, Jp);
    if (trial % 5 != 0) {
      EXPECT_LT((J * Jp - Eigen::Matrix3d::Identity()).norm(), 1e-6);
    }
  }
}

/// A configuration with the right forearm close to the chest.
Eigen::VectorXd closeToChest(const Model& model, const ControllerModel& cm) {
  Eigen::VectorXd q = restConfiguration(model, cm);
  q[model.qIndex("r_shoulder_pitch")] = -0.9;
  q[model.qIndex("r_shoulder_roll")] = 0.15;
  q[model.qIndex("r_shoulder_yaw")] = 0.6;
  q[model.qIndex("r_elbow")] = -1.6;
  return q;
}

TEST(SignConvention, PositiveRowVelocitySeparatesThePair) {
  const Model& model = shippedModel();
  KinematicsData kin(model);
  DistanceData dist(model);
  std::mt19937 rng(3);
  int checked = 0;
  for (int trial = 0; trial < 300; ++trial) {
    const Eigen::VectorXd q = randomConfiguration(model, rng, 1.5);
    computeForwardKinematics(model, kin, q);
    computeSegmentDistances(model, kin, dist);
    for (std::size_t p = 0; p < dist.pairs.size(); ++p) {
      if (!dist.pairs[p].active || dist.pairs[p].distance < 0.01) continue;
      const Eigen::VectorXd row = dist.rows.row(static_cast<Eigen::Index>(p)).transpose();
      if (row.norm() < 1e-3) continue;
      const double eps = 1e-4;
      computeForwardKinematics(model, kin, q + eps * row / row.norm());
      computeSegmentDistances(model, kin, dist);
      const double d_plus = dist.pairs[p].distance;
      computeForwardKinematics(model, kin, q);
      computeSegmentDistances(model, kin, dist);
      EXPECT_GT(d_plus, dist.pairs[p].distance) << "pair " << p;  // moving along +row separates
      ++checked;
    }
  }
  EXPECT_GT(checked, 1000);
}

TEST(Controller, CollisionAvoidanceAloneSeparatesInTheOrangeZone) {
  const Model& model = shippedModel();
  const ControllerModel& cm = defaultControllerModel();
  ControllerData data(model, cm);
  Eigen::VectorXd q = closeToChest(model, cm);
  // Find an elbow angle that puts the forearm in the orange zone.
  double d = 1.0;
  for (double e = -1.6; e > -2.5; e -= 0.01) {
    q[model.qIndex("r_elbow")] = e;
    ControlInput probe;
    computeControl(model, cm, data, q, probe);
    d = data.arms[kRight].distance;
    if (d < 0.009 && d > 0.006) break;
  }
  ASSERT_LT(d, 0.010);
  ASSERT_GT(d, cm.params.d_r);
  ControlInput in;
  in.hands[kRight] = {HandStatus::kGiven, Eigen::Vector3d(0.0, 0.0, 0.9)};  // inside the chest
  ASSERT_EQ(computeControl(model, cm, data, q, in), ControlResult::kOk);
  EXPECT_DOUBLE_EQ(data.arms[kRight].f, 1.0);
  const int p = data.arms[kRight].closest_pair;
  const double rate = data.dist.rows.row(p).dot(data.qdot);
  EXPECT_GT(rate, 0.0) << "the collision controller must separate the closest pair";
  // Integrating one step increases the distance.
  const double d0 = data.dist.pairs[p].distance;
  const Eigen::VectorXd q1 = q + data.qdot * cm.params.period;
  computeControl(model, cm, data, q1, in);
  EXPECT_GT(data.dist.pairs[p].distance, d0);
}

TEST(Controller, NullspaceTermsLeaveTheReachingTaskUnchanged) {
  const Model& model = shippedModel();
  ControllerConfig config = defaultControllerConfig();
  config.params.alpha_jla = 0.0;
  config.params.alpha_ca = 0.0;
  const ControllerModel plain = makeControllerModel(model, config);
  config.params.alpha_jla = 3.0;
  config.params.alpha_ca = 40.0;
  const ControllerModel with_null = makeControllerModel(model, config);
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  int compared = 0;
  for (int trial = 0; trial < 100; ++trial) {
    Eigen::VectorXd q = restConfiguration(model, plain);
    for (const auto& arm : plain.arms)
      for (int i = 0; i < arm.n; ++i) q[arm.q[i]] += 0.3 * u(rng);
    ControllerData a(model, plain), b(model, with_null);
    computeControl(model, plain, a, q, ControlInput{});  // where the hands are
    ControlInput in;
    for (int s = 0; s < 2; ++s)
      in.hands[s] = {HandStatus::kGiven, a.arms[s].hand_B + 0.03 * Eigen::Vector3d(u(rng), u(rng), u(rng))};
    computeControl(model, plain, a, q, in);
    computeControl(model, with_null, b, q, in);
    for (int s = 0; s < 2; ++s) {
      if (a.arms[s].f != 0.0) continue;  // the comparison is about the whole-body controller alone
      const auto& arm = plain.arms[s];
      Eigen::MatrixXd J(3, model.nq);
      computePointJacobian(model, a.kin, arm.hand_link, a.arms[s].hand_B, J);
      const Eigen::Vector3d va = J * a.qdot, vb = J * b.qdot;
      double speed_ratio = 0.0;
      for (int i = 0; i < model.nq; ++i)
        speed_ratio =
            std::max({speed_ratio, std::abs(a.qdot[i]) / model.v_max[i], std::abs(b.qdot[i]) / model.v_max[i]});
      if (speed_ratio >= 1.0 - 1e-9) continue;  // velocity scaling would change both
      bool at_limit = false;
      for (int i = 0; i < arm.n; ++i)
        at_limit |= q[arm.q[i]] <= model.q_lower[arm.q[i]] || q[arm.q[i]] >= model.q_upper[arm.q[i]];
      if (at_limit) continue;  // a joint held at its limit is not the nullspace's business
      EXPECT_LT((va - vb).norm(), 1e-9) << "trial " << trial << " arm " << s;
      EXPECT_GT((a.qdot - b.qdot).norm(), 1e-6);  // the nullspace terms did move the joints
      ++compared;
    }
  }
  EXPECT_GT(compared, 40);
}

TEST(Controller, RedZoneLatchesAndReleasesOnlyWithSeparatingMotion) {
  const Model& model = shippedModel();
  const ControllerModel& cm = defaultControllerModel();
  ControllerData data(model, cm);
  Eigen::VectorXd q = closeToChest(model, cm);
  double e = -1.6;
  for (; e > -2.5; e -= 0.002) {  // push the forearm into the red zone (the robot would never do this)
    q[model.qIndex("r_elbow")] = e;
    ControllerData probe(model, cm);
    computeControl(model, cm, probe, q, ControlInput{});
    if (probe.arms[kRight].distance < 0.004) break;
  }
  ControlInput in;
  in.hands[kRight] = {HandStatus::kGiven, Eigen::Vector3d(0.3, -0.2, 0.9)};
  EXPECT_EQ(computeControl(model, cm, data, q, in), ControlResult::kFrozen);
  EXPECT_EQ(data.estop, EstopState::kLatched);
  EXPECT_TRUE(data.qdot.isZero());
  EXPECT_EQ(data.estop_count, 1U);
  // Latched: it stays frozen cycle after cycle without a reset, even if targets change.
  in.hands[kLeft] = {HandStatus::kGiven, Eigen::Vector3d(0.3, 0.2, 0.9)};
  for (int k = 0; k < 10; ++k) {
    EXPECT_EQ(computeControl(model, cm, data, q, in), ControlResult::kFrozen);
    EXPECT_TRUE(data.qdot.isZero());
  }
  // Reset: only motion that separates every red pair, until the pair is out of the red zone.
  in.reset_estop = true;
  int recovering = 0;
  for (int k = 0; k < 400 && data.estop != EstopState::kClear; ++k) {
    const ControlResult r = computeControl(model, cm, data, q, in);
    in.reset_estop = false;
    if (r == ControlResult::kRecovering) {
      ++recovering;
      for (std::size_t p = 0; p < data.dist.pairs.size(); ++p) {
        const auto& pd = data.dist.pairs[p];
        if (pd.active && pd.distance < cm.params.d_r) {
          EXPECT_GE(data.dist.rows.row(static_cast<Eigen::Index>(p)).dot(data.qdot), 0.0);
        }
      }
      // Only the arm joints move during recovery.
      for (int i = 0; i < model.nq; ++i) {
        bool arm_joint = false;
        for (const auto& arm : cm.arms)
          for (int j = 0; j < arm.n; ++j) arm_joint |= arm.q[j] == i;
        if (!arm_joint) {
          EXPECT_EQ(data.qdot[i], 0.0);
        }
      }
    }
    q += data.qdot * cm.params.period;
  }
  EXPECT_GT(recovering, 0);
  EXPECT_EQ(data.estop, EstopState::kClear);
  EXPECT_EQ(computeControl(model, cm, data, q, in), ControlResult::kOk);
  EXPECT_GE(data.arms[kRight].distance, cm.params.d_r);
}

TEST(Controller, HigherPriorityArmIsUntouchedByTheOtherArm) {
  // With LEFT_HIGHER the left arm ignores the right arm completely: its joint trajectory is the same
  // whether the right arm crosses into it or stays at rest.
  const Model& model = shippedModel();
  const ControllerModel& cm = defaultControllerModel();
  auto run = [&](bool right_crosses) {
    Scenario s;
    s.duration = 4.0;
    s.script = [right_crosses](double, ControlInput& in, ScenarioContext&) {
      in.priority = MotionPriority::kLeftHigher;
      in.hands[kLeft] = {HandStatus::kGiven, Eigen::Vector3d(0.30, -0.08, 0.90)};
      if (right_crosses)
        in.hands[kRight] = {HandStatus::kGiven, Eigen::Vector3d(0.30, 0.08, 0.90)};
      else
        in.hands[kRight].status = HandStatus::kNoTarget;
    };
    return runScenario(model, cm, s);
  };
  const SimResult crossing = run(true), alone = run(false);
  ASSERT_EQ(crossing.samples.size(), alone.samples.size());
  double max_diff = 0.0, max_right_diff = 0.0;
  for (std::size_t k = 0; k < crossing.samples.size(); ++k) {
    for (int i = 0; i < cm.arms[kLeft].n; ++i) {
      const int qi = cm.arms[kLeft].q[i];
      max_diff = std::max(max_diff, std::abs(crossing.samples[k].q[qi] - alone.samples[k].q[qi]));
    }
    for (int i = 0; i < cm.arms[kRight].n; ++i) {
      const int qi = cm.arms[kRight].q[i];
      max_right_diff = std::max(max_right_diff, std::abs(crossing.samples[k].q[qi] - alone.samples[k].q[qi]));
    }
  }
  EXPECT_EQ(max_diff, 0.0);
  EXPECT_GT(max_right_diff, 0.1);                   // the right arm did move in the crossing run
  EXPECT_GE(crossing.min_distance, cm.params.d_r);  // and it avoided the left arm
  EXPECT_FALSE(crossing.estop_fired);
}

TEST(Controller, BadInputGivesADefinedSafeOutput) {
  const Model& model = shippedModel();
  const ControllerModel& cm = defaultControllerModel();
  ControllerData data(model, cm);
  Eigen::VectorXd q = restConfiguration(model, cm);
  ControlInput in;
  in.hands[kLeft] = {HandStatus::kGiven, Eigen::Vector3d(std::nan(""), 0.0, 1.0)};
  in.hands[kRight] = {HandStatus::kGiven, Eigen::Vector3d(0.3, -0.2, std::numeric_limits<double>::infinity())};
  EXPECT_EQ(computeControl(model, cm, data, q, in), ControlResult::kOk);  // NaN targets are dropped
  EXPECT_TRUE(data.qdot.allFinite());
  EXPECT_EQ(data.bad_input_count, 2U);
  Eigen::VectorXd bad = q;
  bad[3] = std::nan("");
  EXPECT_EQ(computeControl(model, cm, data, bad, in), ControlResult::kBadInput);
  EXPECT_TRUE(data.qdot.isZero());
  EXPECT_EQ(computeControl(model, cm, data, Eigen::VectorXd::Zero(3), in), ControlResult::kBadInput);
  EXPECT_TRUE(data.qdot.isZero());
}

TEST(PredictiveGuard, NoStepEndsBelowTheFloorAndCloserThanBefore) {
  // With guard_margin = 0 the first-order filter lets pairs decay towards d_r itself, so only the
  // predictive guard keeps them above d_r + predict_margin. Each cycle's step is applied to a
  // kinematic robot and the distances at the new configuration are computed independently (own
  // kinematics and distance data): no physical pair may end below the floor closer than it was.
  const Model& model = shippedModel();
  ControllerModel cm = defaultControllerModel();
  cm.params.guard_margin = 0.0;
  const double floor = cm.params.d_r + cm.params.predict_margin;
  ControllerData data(model, cm);
  KinematicRobot robot(model, restConfiguration(model, cm));
  KinematicsData kin(model);
  DistanceData dist(model);
  // Targets that ask for collisions, changing every 0.4 s: inside the chest, across the body into
  // the other hand, with the motion priority flipping.
  const Eigen::Vector3d inside(0.02, 0.0, 0.95), across_l(0.30, -0.08, 0.90), across_r(0.30, 0.08, 0.90);
  const Eigen::Vector3d low_l(0.10, -0.05, 0.75), low_r(0.10, 0.05, 0.75);
  const std::array<std::array<Eigen::Vector3d, 2>, 4> phases{
      {{across_l, across_r}, {inside, across_r}, {low_l, inside}, {across_l, low_r}}};
  double closest = 1.0;
  int checked = 0, held = 0;
  for (int k = 0; k < 1600; ++k) {
    const int phase = (k / 80) % 4;
    ControlInput in;
    in.hands[kLeft] = {HandStatus::kGiven, phases[phase][kLeft]};
    in.hands[kRight] = {HandStatus::kGiven, phases[phase][kRight]};
    in.priority = static_cast<MotionPriority>((k / 120) % 3);
    const Eigen::VectorXd q = robot.jointPositions();
    const std::uint64_t guard_before = data.guard_count;
    ASSERT_EQ(computeControl(model, cm, data, q, in), ControlResult::kOk) << "cycle " << k;
    // A step the guard shortened is held outright once it would move nothing (an arm pressed at the
    // floor): every arm step it leaves moves some joint by at least a nanoradian, or none at all.
    if (data.guard_count > guard_before) {
      for (int a = 0; a < 2; ++a) {
        double largest = 0.0;
        for (int i = 0; i < cm.arms[a].n; ++i)
          largest = std::max(largest, std::abs(data.qdot[cm.arms[a].q[i]]) * cm.params.period);
        if (largest == 0.0) ++held;
        EXPECT_TRUE(largest == 0.0 || largest >= 1e-9)
            << "cycle " << k << " arm " << a << ": a vanishing step " << largest << " rad left moving";
      }
    }
    robot.command(data.qdot, cm.params.period);
    ASSERT_TRUE(computeForwardKinematics(model, kin, robot.jointPositions()));
    computeSegmentDistances(model, kin, dist);
    for (std::size_t i = 0; i < dist.pairs.size(); ++i) {
      if (!dist.pairs[i].active) continue;
      closest = std::min(closest, dist.pairs[i].distance);
      if (dist.pairs[i].distance < floor) {
        ++checked;
        EXPECT_GE(dist.pairs[i].distance, data.dist.pairs[i].distance - 1e-12) << "cycle " << k << " pair " << i;
      }
    }
  }
  EXPECT_GT(data.guard_count, 0U) << "the targets drove pairs to the guard";
  EXPECT_GT(held, 0) << "the targets pressed an arm at the floor";
  EXPECT_GE(closest, floor - 1e-12);
  EXPECT_LT(closest, cm.params.d_r + cm.params.guard_margin + 0.002) << "pairs did come close";
  EXPECT_EQ(data.estop_count, 0U);
  std::printf(
      "closest %.3f mm, floor %.3f mm, guard shortened %llu steps (%d arm steps held), %d pair-cycles below "
      "the floor\n",
      closest * 1e3, floor * 1e3, static_cast<unsigned long long>(data.guard_count), held, checked);
}

TEST(PredictiveGuard, JointLeversBoundHowFarAnySegmentPointMoves) {
  // The guard's cheap exit rests on lever_j: no point of a segment surface moves more than
  // lever_j * |dq_j| when joint j alone moves by dq_j. Checked on random configurations by moving
  // each joint alone and measuring, for every primitive, its endpoints pushed outwards by the radius.
  const Model& model = shippedModel();
  const ControllerModel& cm = defaultControllerModel();
  const ControllerData data(model, cm);
  KinematicsData k0(model), k1(model);
  std::mt19937 rng(5);
  double tightest = 0.0;
  for (int trial = 0; trial < 50; ++trial) {
    const Eigen::VectorXd q = randomConfiguration(model, rng, 3.0);
    ASSERT_TRUE(computeForwardKinematics(model, k0, q));
    for (int j = 0; j < model.nq; ++j) {
      const double dq = 0.01;
      Eigen::VectorXd q1 = q;
      q1[j] += dq;
      ASSERT_TRUE(computeForwardKinematics(model, k1, q1));
      for (int s = 0; s < model.num_robot_segments; ++s) {
        const Segment& seg = model.segments[s];
        for (int k = 0; k < seg.num_primitives; ++k) {
          const Primitive& prim = model.primitives[seg.first_primitive + k];
          for (const Eigen::Vector3d& p_L : {prim.a_L, prim.b_L}) {
            // The surface point farthest out: the endpoint pushed outwards by the radius.
            const Eigen::Vector3d out = p_L.norm() > 0 ? Eigen::Vector3d(p_L + prim.radius * p_L.normalized())
                                                       : Eigen::Vector3d(prim.radius, 0, 0);
            const double moved = (k1.X_B_L[seg.link] * out - k0.X_B_L[seg.link] * out).norm();
            EXPECT_LE(moved, data.lever[j] * dq + 1e-12) << model.q_names[j] << " moves " << seg.name;
            if (moved > 0) tightest = std::max(tightest, moved / (data.lever[j] * dq));
          }
        }
      }
    }
  }
  EXPECT_GT(tightest, 0.5) << "the levers are bounds, but not absurdly loose ones";
}

// ---------------------------------------------------------------- broad phase
// The control cycle skips pairs whose bounding spheres are beyond max(d_safe, d_a) (d_b in the
// guards). Its output must be the brute force's bit for bit: every built-in scenario and a closed
// loop where the predictive guard acts, run with ControllerModel::broad_phase on and off, on the
// shipped robot and on the >= 1,000-pair robot, give identical commands, statuses and reports.
namespace broad_phase {

void expectSameRuns(const SimResult& pruned, const SimResult& brute, const std::string& what) {
  ASSERT_EQ(pruned.samples.size(), brute.samples.size()) << what;
  for (std::size_t k = 0; k < brute.samples.size(); ++k) {
    const SimSample& p = pruned.samples[k];
    const SimSample& b = brute.samples[k];
    ASSERT_EQ(p.q, b.q) << what << " cycle " << k;
    ASSERT_EQ(p.qdot, b.qdot) << what << " cycle " << k;
    ASSERT_EQ(p.min_distance, b.min_distance) << what << " cycle " << k;
    ASSERT_EQ(p.min_pair, b.min_pair) << what << " cycle " << k;
    ASSERT_EQ(p.virtual_distance, b.virtual_distance) << what << " cycle " << k;
    ASSERT_EQ(p.arm_distance, b.arm_distance) << what << " cycle " << k;
    for (int a = 0; a < 2; ++a) {
      ASSERT_EQ(p.arms[a].distance, b.arms[a].distance) << what << " cycle " << k << " arm " << a;
      ASSERT_EQ(p.arms[a].closest_pair, b.arms[a].closest_pair) << what << " cycle " << k << " arm " << a;
      ASSERT_EQ(p.arms[a].f, b.arms[a].f) << what << " cycle " << k;
      ASSERT_EQ(p.arms[a].force_dir_B, b.arms[a].force_dir_B) << what << " cycle " << k;
    }
  }
  EXPECT_EQ(pruned.guard_cycles, brute.guard_cycles) << what;
  EXPECT_EQ(pruned.walking_holds, brute.walking_holds) << what;
  EXPECT_EQ(pruned.estop_fired, brute.estop_fired) << what;
  EXPECT_EQ(pruned.min_distance, brute.min_distance) << what;
}

// One cycle of the pruned controller against the brute force's: everything the broad phase may change.
void expectSameCycle(const ControllerData& dp, const ControllerData& db, const std::string& what) {
  ASSERT_EQ(dp.qdot, db.qdot) << what;
  ASSERT_EQ(dp.closest_physical.distance, db.closest_physical.distance) << what;
  ASSERT_EQ(dp.closest_physical.pair, db.closest_physical.pair) << what;
  ASSERT_EQ(dp.closest_virtual.distance, db.closest_virtual.distance) << what;
  ASSERT_EQ(dp.closest_between_arms.distance, db.closest_between_arms.distance) << what;
  ASSERT_EQ(dp.closest_between_arms.pair, db.closest_between_arms.pair) << what;
  ASSERT_EQ(dp.guard_count, db.guard_count) << what;
  ASSERT_EQ(dp.estop, db.estop) << what;
  for (int a = 0; a < 2; ++a) {
    ASSERT_EQ(dp.arms[a].distance, db.arms[a].distance) << what << " arm " << a;
    ASSERT_EQ(dp.arms[a].closest_pair, db.arms[a].closest_pair) << what << " arm " << a;
    ASSERT_EQ(dp.arms[a].f, db.arms[a].f) << what << " arm " << a;
  }
}

// Whether the cycle's closest physical pair or closest pair between the arms is a robot pair the
// broad phase skipped and the cycle refined (exact, but not in the sweep's exact list).
bool cycleRefinedAClosestPair(const ControllerData& data) {
  const std::vector<int>& exact = data.dist.exactList();
  for (const int c : {data.closest_physical.pair, data.closest_between_arms.pair})
    if (c >= 0 && data.dist.pair_common[static_cast<std::size_t>(c)] >= 0 &&
        !std::binary_search(exact.begin(), exact.begin() + data.dist.num_exact_pairs, c))
      return true;
  return false;
}

void checkRobot(const Model& model, const ControllerConfig& config = defaultControllerConfig(), bool scenarios = true,
                long* listed_pairs = nullptr) {
  ControllerModel pruned = makeControllerModel(model, config);
  ControllerModel brute = pruned;
  brute.broad_phase = false;
  ASSERT_TRUE(pruned.broad_phase);
  for (const Scenario& sc : builtinScenarios()) {
    if (!scenarios) break;
    expectSameRuns(runScenario(model, pruned, sc), runScenario(model, brute, sc), model.name + " " + sc.name);
  }
  // A closed loop whose targets jump into the chest and across, priority flipping, guard_margin 0:
  // the predictive guard acts (the benchmark's GuardActing loop).
  pruned.params.guard_margin = brute.params.guard_margin = 0.0;
  ControllerData dp(model, pruned), db(model, brute);
  Eigen::VectorXd qp = restConfiguration(model, pruned), qb = qp;
  const Eigen::Vector3d inside(0.02, 0.0, 0.95), across_l(0.30, -0.08, 0.90), across_r(0.30, 0.08, 0.90);
  const Eigen::Vector3d low_l(0.10, -0.05, 0.75), low_r(0.10, 0.05, 0.75);
  const Eigen::Vector3d phases[4][2] = {{across_l, across_r}, {inside, across_r}, {low_l, inside}, {across_l, low_r}};
  long skipped = 0, predicted_pruned = 0, predicted_brute = 0;
  for (int k = 0; k < 1600; ++k) {
    ControlInput in;
    for (int a = 0; a < 2; ++a) in.hands[a] = {HandStatus::kGiven, phases[(k / 80) % 4][a]};
    in.priority = static_cast<MotionPriority>((k / 120) % 3);
    ASSERT_EQ(computeControl(model, pruned, dp, qp, in), computeControl(model, brute, db, qb, in)) << k;
    ASSERT_NO_FATAL_FAILURE(expectSameCycle(dp, db, model.name + " cycle " + std::to_string(k)));
    EXPECT_EQ(db.dist.num_pruned_pairs, 0);
    skipped += dp.dist.num_pruned_pairs;
    predicted_pruned += dp.num_guard_pairs;
    predicted_brute += db.num_guard_pairs;
    for (int g = 0; g < dp.num_guard_pairs && listed_pairs; ++g)
      *listed_pairs +=
          dp.guard_listing.count[static_cast<std::size_t>(dp.guard_pairs[static_cast<std::size_t>(g)])] > 0;
    qp += dp.qdot * pruned.params.period;
    qb += db.qdot * brute.params.period;
  }
  EXPECT_EQ(dp.guard_count, db.guard_count);
  EXPECT_GT(dp.guard_count, 0U) << "the loop must make the predictive guard act";
  EXPECT_GT(skipped, 1600) << "the broad phase must skip pairs, else this test compares nothing";
  // The guard's per-pair bound: the brute force predicts every physical pair an arm moves; with the
  // bound, the guard predicts far fewer pairs and decides the same (qdot and guard_count above).
  std::printf("%s: the guard predicted %ld pairs over the loop with its per-pair bound, %ld without\n",
              model.name.c_str(), predicted_pruned, predicted_brute);
  EXPECT_GT(predicted_brute, 20 * predicted_pruned) << "the guard's per-pair bound must leave pairs out";
  EXPECT_GT(predicted_pruned, 0) << "the guard must predict some pairs, else this test compares nothing";
}

}  // namespace broad_phase

TEST(BroadPhase, ControlOutputIsTheBruteForcesBitForBitOnTheShippedRobot) { broad_phase::checkRobot(shippedModel()); }

// The tight model (convex pieces): the guard lists each predicted pair's primitive pairs once a cycle
// (listPairsNear) with the broad phase, and per prediction without it.
TEST(BroadPhase, ControlOutputIsTheBruteForcesBitForBitOnTheMeshRobot) {
  long listed = 0;
  broad_phase::checkRobot(testing::loadRobot("mesh_humanoid"),
                          loadControllerConfig(testing::robotPath("mesh_humanoid.controller.yaml")),
                          /*scenarios=*/false, &listed);  // the closed loop alone (its config has no head camera)
  std::printf("mesh_humanoid: %ld predicted pairs offered only the primitive pairs listed once a cycle\n", listed);
  EXPECT_GT(listed, 40) << "the guard must use its listing, else this test compares nothing";
}

TEST(BroadPhase, ControlOutputIsTheBruteForcesBitForBitOnTheThousandPairRobot) {
  const std::string urdf = std::string(REFLEX_SOURCE_DIR) + "/bringup/robots/many_segment_humanoid.urdf";
  broad_phase::checkRobot(loadModel(urdf, loadCollisionConfig(defaultCollisionConfigPath(urdf))));
}

// A closest pair may be one the broad phase skipped: the cycle refines it (exact, but not in the
// sweep's exact list). The controller's closest physical pair and closest pair between the arms must
// still be the brute force's. With the defaults no shipped robot reaches that case (some pair is
// always within the 0.10 m broad-phase distance); with d_safe = d_a = 0.02 the 1,343-pair robot does
// in most configurations (when a refined pair was passed over as exact, the closest physical pair was
// wrong in 79 % of them: 37.98 mm reported, 37.92 mm true).
TEST(BroadPhase, ClosestPairsAreTheBruteForcesWhenTheCycleRefinedThem) {
  const std::string urdf = std::string(REFLEX_SOURCE_DIR) + "/bringup/robots/many_segment_humanoid.urdf";
  const Model model = loadModel(urdf, loadCollisionConfig(defaultCollisionConfigPath(urdf)));
  ControllerConfig config = defaultControllerConfig();
  config.params.d_a = config.params.d_safe = 0.02;
  ControllerModel pruned = makeControllerModel(model, config);
  ControllerModel brute = pruned;
  brute.broad_phase = false;
  ASSERT_TRUE(pruned.broad_phase);
  ControllerData dp(model, pruned), db(model, brute);
  const Eigen::VectorXd rest = restConfiguration(model, pruned);
  std::mt19937 rng(14);
  std::uniform_real_distribution<double> offset(-0.5, 0.5);
  int refined_closest = 0;
  const ControlInput no_targets;
  for (int k = 0; k < 400; ++k) {
    Eigen::VectorXd q = rest;
    for (int j = 0; j < model.nq; ++j) q[j] += offset(rng);
    ASSERT_EQ(computeControl(model, pruned, dp, q, no_targets), computeControl(model, brute, db, q, no_targets)) << k;
    if (broad_phase::cycleRefinedAClosestPair(dp)) ++refined_closest;  // the case under test
    ASSERT_NO_FATAL_FAILURE(broad_phase::expectSameCycle(dp, db, "configuration " + std::to_string(k)));
  }
  EXPECT_GT(refined_closest, 100) << "the configurations must reach the case, else this test compares nothing";
}

// The same comparison as an attack: random zones (d_r < d_b < d_a <= d_safe, half of them with
// d_safe = d_a), zero to two body-schema slots on random links (one virtual), a closed loop towards
// random targets with the priority flipping, or independent random configurations; every output the
// broad phase may change must be the brute force's. (Before the fix it found the case above in 2
// of 40 trials on the 1,343-pair robot.)
void attackBroadPhase(const Model& model, unsigned seed, int* refined_closest) {
  std::mt19937 rng(seed);
  auto uniform = [&](double lo, double hi) { return std::uniform_real_distribution<double>(lo, hi)(rng); };
  for (int trial = 0; trial < 40; ++trial) {
    ControllerConfig config = defaultControllerConfig();
    ControllerParams& params = config.params;
    params.d_r = uniform(0.002, 0.01);
    params.d_b = params.d_r + uniform(0.002, 0.03);
    params.d_a = params.d_b + uniform(0.002, 0.05);
    params.d_safe = trial % 4 < 2 ? params.d_a : params.d_a + uniform(0.0, 0.2);
    params.estop_release_margin = std::min(params.estop_release_margin, params.d_b - params.d_r);
    if (trial % 3 == 0) params.guard_margin = 0.0;
    const ControllerModel pruned = makeControllerModel(model, config);
    ControllerModel brute = pruned;
    brute.broad_phase = false;
    ControllerData dp(model, pruned), db(model, brute);
    for (int slot = 0; slot < trial % 3; ++slot) {
      const int link = std::uniform_int_distribution<int>(1, static_cast<int>(model.links.size()) - 1)(rng);
      const Eigen::Vector3d a(uniform(-0.1, 0.1), uniform(-0.1, 0.1), uniform(-0.1, 0.1));
      const Eigen::Vector3d b(uniform(-0.2, 0.2), uniform(-0.2, 0.2), uniform(-0.2, 0.2));
      const double radius = uniform(0.01, 0.05);
      ASSERT_TRUE(attachBodySchemaSegment(model, dp.dist, slot, link, a, b, radius));
      ASSERT_TRUE(attachBodySchemaSegment(model, db.dist, slot, link, a, b, radius));
      dp.dist.slots[slot].is_virtual = db.dist.slots[slot].is_virtual = slot == 1;
    }
    const Eigen::VectorXd rest = restConfiguration(model, pruned);
    auto randomConfiguration = [&] {
      Eigen::VectorXd q = rest;
      for (int j = 0; j < model.nq; ++j) q[j] += uniform(-0.5, 0.5);
      return q;
    };
    Eigen::VectorXd q = randomConfiguration();
    const std::string what = model.name + " seed " + std::to_string(seed) + " trial " + std::to_string(trial);
    for (int k = 0; k < 300; ++k) {
      ControlInput in;
      for (int h = 0; h < 2; ++h)
        in.hands[h] = {HandStatus::kGiven, Eigen::Vector3d(uniform(0.0, 0.4), uniform(-0.3, 0.3), uniform(0.7, 1.1))};
      in.priority = static_cast<MotionPriority>(k / 50 % 3);
      ASSERT_EQ(computeControl(model, pruned, dp, q, in), computeControl(model, brute, db, q, in))
          << what << " cycle " << k;
      if (broad_phase::cycleRefinedAClosestPair(dp)) ++*refined_closest;
      ASSERT_NO_FATAL_FAILURE(broad_phase::expectSameCycle(dp, db, what + " cycle " + std::to_string(k)));
      // Odd trials: independent random configurations; even ones: the closed loop, a jump every 100.
      if (trial % 2 == 1) {
        q = randomConfiguration();
      } else {
        q += dp.qdot * pruned.params.period;
        if (k % 100 == 99)
          for (int j = 0; j < model.nq; ++j) q[j] += uniform(-0.2, 0.2);
      }
    }
  }
}

TEST(BroadPhase, ControlOutputIsTheBruteForcesForRandomZonesSlotsAndConfigurations) {
  const std::string urdf = std::string(REFLEX_SOURCE_DIR) + "/bringup/robots/many_segment_humanoid.urdf";
  const Model many = loadModel(urdf, loadCollisionConfig(defaultCollisionConfigPath(urdf)));
  int refined_closest = 0;
  for (const unsigned seed : {1U, 2U}) {
    attackBroadPhase(shippedModel(), seed, &refined_closest);
    attackBroadPhase(many, seed, &refined_closest);
  }
  std::printf("cycles whose closest pair the cycle refined: %d\n", refined_closest);
  EXPECT_GT(refined_closest, 0) << "the attack must reach a refined closest pair";
}

}  // namespace
}  // namespace reflex::control
