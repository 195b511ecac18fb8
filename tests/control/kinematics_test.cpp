// Tests of control/include/reflex/control/kinematics.hpp: forward kinematics and Jacobians against
// a hand-computed planar arm, against KDL (kdl_parser reads the same URDF independently), and
// against central finite differences; the relative Jacobian and the directional (avoidance) row;
// NaN / Inf / wrong-size joint vectors.
#include "reflex/control/kinematics.hpp"

#include "test_support.hpp"

#include <gtest/gtest.h>
#include <kdl/chainfksolverpos_recursive.hpp>
#include <kdl/chainjnttojacsolver.hpp>
#include <kdl/tree.hpp>
#include <kdl_parser/kdl_parser.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <random>
#include <string>
#include <vector>

namespace reflex::control {
namespace {

using Eigen::Vector3d;

// ---------------------------------------------------------------- hand-computed planar arm
// Two revolute joints about z (link lengths 1 and 0.5) and a prismatic joint along the second
// link's x axis: tip = R(q1) [1, 0, 0] + R(q1 + q2) [0.5 + q3, 0, 0].
const char* kPlanarArm = R"(<?xml version="1.0"?>
<robot name="planar">
  <link name="base"/>
  <link name="l1"/>
  <link name="l2"/>
  <link name="slider"><collision><geometry><sphere radius="0.05"/></geometry></collision></link>
  <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/>
    <axis xyz="0 0 1"/><limit lower="-3" upper="3" velocity="1" effort="1"/></joint>
  <joint name="j2" type="revolute"><parent link="l1"/><child link="l2"/><origin xyz="1 0 0"/>
    <axis xyz="0 0 1"/><limit lower="-3" upper="3" velocity="1" effort="1"/></joint>
  <joint name="j3" type="prismatic"><parent link="l2"/><child link="slider"/><origin xyz="0.5 0 0"/>
    <axis xyz="1 0 0"/><limit lower="0" upper="0.3" velocity="1" effort="1"/></joint>
</robot>)";

TEST(KinematicsPlanar, HandComputedPositionAndJacobian) {
  const Model m = loadModelFromString(kPlanarArm, CollisionConfig{}, "planar");
  ASSERT_EQ(m.nq, 3);
  KinematicsData kin(m);
  const double q1 = 0.7, q2 = -1.9, q3 = 0.2;
  ASSERT_TRUE(computeForwardKinematics(m, kin, Eigen::Vector3d(q1, q2, q3)));
  const int tip = m.linkIndex("slider");
  const double L2 = 0.5 + q3;
  const Vector3d p(std::cos(q1) + L2 * std::cos(q1 + q2), std::sin(q1) + L2 * std::sin(q1 + q2), 0);
  EXPECT_LT((kin.X_B_L[tip].translation() - p).norm(), 1e-15);
  Eigen::Matrix3d R_expected = Eigen::AngleAxisd(q1 + q2, Vector3d::UnitZ()).toRotationMatrix();
  EXPECT_LT((kin.X_B_L[tip].linear() - R_expected).norm(), 1e-15);
  Eigen::MatrixXd J(3, 3);
  computePointJacobian(m, kin, tip, p, J);
  Eigen::Matrix3d J_expected;
  J_expected << -std::sin(q1) - L2 * std::sin(q1 + q2), -L2 * std::sin(q1 + q2), std::cos(q1 + q2),
      std::cos(q1) + L2 * std::cos(q1 + q2), L2 * std::cos(q1 + q2), std::sin(q1 + q2), 0, 0, 0;
  EXPECT_LT((J - J_expected).norm(), 1e-15);
  // A point on l1 does not move with j2, j3.
  computePointJacobian(m, kin, m.linkIndex("l1"), Vector3d(std::cos(q1), std::sin(q1), 0), J);
  EXPECT_EQ(J.col(1).norm(), 0.0);
  EXPECT_EQ(J.col(2).norm(), 0.0);
  EXPECT_NEAR(J(0, 0), -std::sin(q1), 1e-15);
}

// ---------------------------------------------------------------- against KDL
struct KdlChain {
  std::string tip;
  KDL::Chain chain;
  std::vector<int> q_of_joint;  // Reflex q index of each movable KDL chain joint
};

KdlChain kdlChain(const Model& m, const KDL::Tree& tree, const std::string& tip) {
  KdlChain c;
  c.tip = tip;
  EXPECT_TRUE(tree.getChain(m.links[0].name, tip, c.chain)) << tip;
  for (const KDL::Segment& s : c.chain.segments) {
    if (s.getJoint().getType() == KDL::Joint::None) continue;
    const int qi = m.qIndex(s.getJoint().getName());
    EXPECT_GE(qi, 0) << s.getJoint().getName();
    c.q_of_joint.push_back(qi);
  }
  EXPECT_EQ(static_cast<unsigned>(c.q_of_joint.size()), c.chain.getNrOfJoints());
  return c;
}

void checkAgainstKdl(const std::string& robot, const std::vector<std::string>& tips, int configurations,
                     std::uint64_t seed) {
  const Model m = testing::loadRobot(robot);
  KDL::Tree tree;
  ASSERT_TRUE(kdl_parser::treeFromFile(testing::robotPath(robot + ".urdf"), tree));
  std::vector<KdlChain> chains;
  for (const auto& tip : tips) chains.push_back(kdlChain(m, tree, tip));

  KinematicsData kin(m);
  std::mt19937_64 rng(seed);
  double max_p = 0.0, max_r = 0.0, max_j = 0.0;
  Eigen::MatrixXd J(3, m.nq);
  for (int c = 0; c < configurations; ++c) {
    const Eigen::VectorXd q = test::randomConfiguration(m, rng);
    ASSERT_TRUE(computeForwardKinematics(m, kin, q));
    for (const KdlChain& kc : chains) {
      KDL::JntArray kq(kc.chain.getNrOfJoints());
      for (std::size_t k = 0; k < kc.q_of_joint.size(); ++k) kq(k) = q[kc.q_of_joint[k]];
      KDL::Frame F;
      KDL::ChainFkSolverPos_recursive fk(kc.chain);
      ASSERT_GE(fk.JntToCart(kq, F), 0);
      const int link = m.linkIndex(kc.tip);
      const Eigen::Isometry3d& X = kin.X_B_L[link];
      for (int r = 0; r < 3; ++r) {
        max_p = std::max(max_p, std::abs(X.translation()[r] - F.p(r)));
        for (int col = 0; col < 3; ++col) max_r = std::max(max_r, std::abs(X.linear()(r, col) - F.M(r, col)));
      }
      // Jacobian of the tip origin and of a random point on the tip link (KDL: changeRefPoint).
      KDL::ChainJntToJacSolver jac_solver(kc.chain);
      KDL::Jacobian kj(kc.chain.getNrOfJoints());
      ASSERT_GE(jac_solver.JntToJac(kq, kj), 0);
      for (const bool offset : {false, true}) {
        const Vector3d p_L = offset ? test::randomPoint(rng, 0.2) : Vector3d::Zero();
        const Vector3d p_B = X * p_L;
        KDL::Jacobian kjp(kc.chain.getNrOfJoints());
        const Vector3d off_B = p_B - X.translation();
        KDL::changeRefPoint(kj, KDL::Vector(off_B.x(), off_B.y(), off_B.z()), kjp);
        computePointJacobian(m, kin, link, p_B, J);
        Eigen::MatrixXd expected = Eigen::MatrixXd::Zero(3, m.nq);
        for (std::size_t k = 0; k < kc.q_of_joint.size(); ++k)
          for (int r = 0; r < 3; ++r) expected(r, kc.q_of_joint[k]) = kjp(r, k);
        max_j = std::max(max_j, (J - expected).cwiseAbs().maxCoeff());
      }
    }
  }
  EXPECT_LT(max_p, 1e-9);
  EXPECT_LT(max_r, 1e-9);
  EXPECT_LT(max_j, 1e-9);
  std::printf("%s vs KDL, %d configurations x %zu tips: max |dp| %.3g m, max |dR| %.3g, max |dJ| %.3g\n", robot.c_str(),
              configurations, tips.size(), max_p, max_r, max_j);
}

TEST(KinematicsKdl, ShippedRobotTipsAgreeWithKdl) {
  checkAgainstKdl(testing::kAsimo, {"l_hand", "r_hand", "head_camera", "head_camera_right", "l_foot", "r_foot"}, 250,
                  1);
}

TEST(KinematicsKdl, SecondHumanoidTipsAgreeWithKdl) {
  checkAgainstKdl(testing::kSmall, {"l_hand", "r_hand", "camera", "l_foot", "r_foot"}, 250, 2);
}

// ---------------------------------------------------------------- against finite differences
Vector3d pointAt(const Model& m, KinematicsData& kin, const Eigen::VectorXd& q, int link, const Vector3d& p_L) {
  EXPECT_TRUE(computeForwardKinematics(m, kin, q));
  return kin.X_B_L[link] * p_L;
}

TEST(KinematicsFiniteDifferences, JacobiansRelativeJacobianAndRowOfEveryLink) {
  for (const char* robot : {testing::kAsimo, testing::kSmall}) {
    const Model m = testing::loadRobot(robot);
    KinematicsData kin(m), kin_fd(m);
    std::mt19937_64 rng(21);
    const double h = 1e-6;
    double max_j = 0.0, max_rel = 0.0, max_row = 0.0;
    Eigen::MatrixXd J(3, m.nq), J2(3, m.nq), Jrel(3, m.nq), Jfd(3, m.nq), Jfd2(3, m.nq);
    Eigen::RowVectorXd row(m.nq);
    const int nlinks = static_cast<int>(m.links.size());
    for (int c = 0; c < 5; ++c) {
      const Eigen::VectorXd q = test::randomConfiguration(m, rng);
      for (int link = 0; link < nlinks; ++link) {
        const Vector3d p_L = test::randomPoint(rng, 0.2);
        const int link2 = static_cast<int>(rng() % nlinks);
        const Vector3d p2_L = test::randomPoint(rng, 0.2);
        for (int j = 0; j < m.nq; ++j) {
          Eigen::VectorXd qp = q, qm = q;
          qp[j] += h;
          qm[j] -= h;
          Jfd.col(j) = (pointAt(m, kin_fd, qp, link, p_L) - pointAt(m, kin_fd, qm, link, p_L)) / (2 * h);
          Jfd2.col(j) = (pointAt(m, kin_fd, qp, link2, p2_L) - pointAt(m, kin_fd, qm, link2, p2_L)) / (2 * h);
        }
        ASSERT_TRUE(computeForwardKinematics(m, kin, q));
        const Vector3d p_B = kin.X_B_L[link] * p_L, p2_B = kin.X_B_L[link2] * p2_L;
        computePointJacobian(m, kin, link, p_B, J);
        computePointJacobian(m, kin, link2, p2_B, J2);
        max_j = std::max(max_j, (J - Jfd).cwiseAbs().maxCoeff());
        computeRelativeJacobian(m, kin, link, p_B, link2, p2_B, Jrel);
        max_rel = std::max(max_rel, (Jrel - (Jfd - Jfd2)).cwiseAbs().maxCoeff());
        EXPECT_LT((Jrel - (J - J2)).cwiseAbs().maxCoeff(), 1e-14);
        const Vector3d n = test::randomUnit(rng);
        computeDirectionalRow(m, kin, link, p_B, link2, p2_B, n, row);
        max_row = std::max(max_row, (row - n.transpose() * (Jfd - Jfd2)).cwiseAbs().maxCoeff());
      }
    }
    EXPECT_LT(max_j, 1e-6);
    EXPECT_LT(max_rel, 1e-6);
    EXPECT_LT(max_row, 1e-6);
    std::printf("%s vs central differences (h = 1e-6), every link: max |dJ| %.3g, relative %.3g, row %.3g\n", robot,
                max_j, max_rel, max_row);
  }
}

// ---------------------------------------------------------------- from a nearby configuration
/// computeForwardKinematics with `near` (the kinematics of a configuration that differs in a few
/// joints): every pose, axis and twist bit for bit as computed from scratch, whichever joints differ.
TEST(KinematicsNear, PosesFromANearbyConfigurationAreTheSameBits) {
  for (const char* robot : {testing::kAsimo, "mesh_humanoid"}) {
    const Model m = testing::loadRobot(robot);
    KinematicsData near(m), from_near(m), scratch(m);
    std::mt19937_64 rng(44);
    long copied_links = 0;
    for (int c = 0; c < 200; ++c) {
      const Eigen::VectorXd q0 = test::randomConfiguration(m, rng);
      Eigen::VectorXd q = q0;
      // 0 to 3 joints moved (0: all copied), or every joint (c % 10 == 9: none copied).
      const Eigen::VectorXd other = test::randomConfiguration(m, rng);
      if (c % 10 == 9) q = other;
      for (int k = 0; k < c % 4; ++k) {
        const int j = static_cast<int>(rng() % static_cast<unsigned>(m.nq));
        q[j] = other[j];
      }
      ASSERT_TRUE(computeForwardKinematics(m, near, q0));
      ASSERT_TRUE(computeForwardKinematics(m, from_near, q, &near));
      ASSERT_TRUE(computeForwardKinematics(m, scratch, q));
      for (std::size_t l = 0; l < m.links.size(); ++l) {
        ASSERT_TRUE(from_near.X_B_L[l].matrix() == scratch.X_B_L[l].matrix()) << robot << " link " << l;
        ASSERT_TRUE(from_near.axis_B[l] == scratch.axis_B[l]) << robot << " link " << l;
        copied_links += near.X_B_L[l].matrix() == scratch.X_B_L[l].matrix() ? 1 : 0;
      }
      ASSERT_TRUE(from_near.twist_B == scratch.twist_B) << robot;
      ASSERT_TRUE(from_near.q == q) << robot;
    }
    EXPECT_GT(copied_links, 200 * static_cast<long>(m.links.size()) / 4) << robot;  // the copy path ran
  }
}

TEST(KinematicsKept, PosesKeptFromTheLastCallAreTheSameBits) {
  // One KinematicsData along a walk through random configurations, each step moving some joints and
  // holding the others (the arms reach, the legs stand): every pose, axis and twist the same bits as
  // a KinematicsData made for that configuration alone. It fails when a link keeps its pose although
  // its parent moved (a held wrist on a moving shoulder) or its own joint changed.
  for (const char* robot : {testing::kAsimo, "mesh_humanoid"}) {
    const Model m = testing::loadRobot(robot);
    KinematicsData along(m);
    std::mt19937_64 rng(45);
    Eigen::VectorXd q = test::randomConfiguration(m, rng);
    long kept_links = 0;
    for (int c = 0; c < 300; ++c) {
      const Eigen::VectorXd other = test::randomConfiguration(m, rng);
      // Steps 0 to 3: none, one, a few or half of the joints move (those a shuffled order puts first).
      std::vector<int> order(static_cast<std::size_t>(m.nq));
      for (int j = 0; j < m.nq; ++j) order[static_cast<std::size_t>(j)] = j;
      std::shuffle(order.begin(), order.end(), rng);
      const int moving = std::array<int, 4>{0, 1, 3, m.nq / 2}[static_cast<std::size_t>(c % 4)];
      for (int k = 0; k < moving; ++k)
        q[order[static_cast<std::size_t>(k)]] = other[order[static_cast<std::size_t>(k)]];
      ASSERT_TRUE(computeForwardKinematics(m, along, q));
      KinematicsData alone(m);
      ASSERT_TRUE(computeForwardKinematics(m, alone, q));
      for (std::size_t l = 0; l < m.links.size(); ++l) {
        ASSERT_TRUE(along.X_B_L[l].matrix() == alone.X_B_L[l].matrix()) << robot << " step " << c << " link " << l;
        ASSERT_TRUE(along.axis_B[l] == alone.axis_B[l]) << robot << " step " << c << " link " << l;
        kept_links += along.moved[l] ? 0 : 1;
      }
      ASSERT_TRUE(along.twist_B == alone.twist_B) << robot << " step " << c;
      ASSERT_TRUE(along.q == q) << robot;
    }
    EXPECT_GT(kept_links, 300 * static_cast<long>(m.links.size()) / 4) << robot;  // the keeping path ran
  }
}

// ---------------------------------------------------------------- bad joint vectors
TEST(KinematicsRuntime, NonFiniteOrWrongSizeJointVectorIsRejectedAndDataKept) {
  const Model m = testing::loadRobot(testing::kAsimo);
  KinematicsData kin(m);
  std::mt19937_64 rng(4);
  const Eigen::VectorXd q = test::randomConfiguration(m, rng);
  ASSERT_TRUE(computeForwardKinematics(m, kin, q));
  const std::vector<Eigen::Isometry3d> X_before = kin.X_B_L;
  const std::vector<Vector3d> axis_before = kin.axis_B;
  auto unchanged = [&] {
    for (std::size_t i = 0; i < X_before.size(); ++i) {
      if (!(kin.X_B_L[i].matrix() == X_before[i].matrix())) return false;
      if (!(kin.axis_B[i] == axis_before[i])) return false;
    }
    return kin.q == q && kin.q.allFinite();
  };
  for (const double bad : {std::numeric_limits<double>::quiet_NaN(), std::numeric_limits<double>::infinity(),
                           -std::numeric_limits<double>::infinity()}) {
    for (const int j : {0, m.nq / 2, m.nq - 1}) {
      Eigen::VectorXd qb = test::randomConfiguration(m, rng);
      qb[j] = bad;
      EXPECT_FALSE(computeForwardKinematics(m, kin, qb));
      EXPECT_TRUE(unchanged());
    }
  }
  EXPECT_FALSE(computeForwardKinematics(m, kin, Eigen::VectorXd::Zero(m.nq - 1)));
  EXPECT_FALSE(computeForwardKinematics(m, kin, Eigen::VectorXd::Zero(m.nq + 1)));
  EXPECT_TRUE(unchanged());
  Eigen::MatrixXd J(3, m.nq);
  computePointJacobian(m, kin, m.linkIndex("l_hand"), kin.X_B_L[m.linkIndex("l_hand")].translation(), J);
  EXPECT_TRUE(J.allFinite());
}

}  // namespace
}  // namespace reflex::control
