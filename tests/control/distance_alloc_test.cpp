// The per-cycle path (computeForwardKinematics + computeSegmentDistances, also with body-schema
// slots attached, and the Jacobian functions) makes no heap allocation: operator new and (not under
// AddressSanitizer) malloc / calloc / realloc, which Eigen's dynamic matrices use, are counted
// (support/count_allocations.hpp).
#include "reflex/control/distance.hpp"
#include "reflex/control/kinematics.hpp"
#include "test_support.hpp"
#include "support/count_allocations.hpp"

#include <gtest/gtest.h>

#include <atomic>
#include <cstdlib>
#include <limits>
#include <memory>
#include <new>
#include <random>
#include <vector>

namespace reflex::control {
namespace {

using AllocationCounter = reflex::testing::AllocationCount;

TEST(DistanceAlloc, CounterSeesOperatorNewAndEigenAllocations) {
  {
    AllocationCounter c;
    auto v = std::make_unique<std::vector<int>>(100);
    EXPECT_GE(c.count(), 2);
  }
  if (reflex::testing::kCountsMalloc) {
    AllocationCounter c;
    Eigen::MatrixXd m(50, 50);  // std::malloc inside Eigen
    m.setZero();
    EXPECT_GE(c.count(), 1);
  }
}

void runCycles(const char* robot) {
  const Model model = testing::loadRobot(robot);
  KinematicsData kin(model);
  DistanceData dist(model);
  std::mt19937_64 rng(17);
  std::vector<Eigen::VectorXd> qs;
  for (int i = 0; i < 50; ++i) qs.push_back(test::randomConfiguration(model, rng));
  Eigen::VectorXd q_nan = qs[0];
  q_nan[0] = std::numeric_limits<double>::quiet_NaN();
  Eigen::MatrixXd J(3, model.nq);
  Eigen::RowVectorXd row(model.nq);
  const int hand = model.linkIndex("l_hand");
  const int head = model.linkIndex("head");
  const DistanceOptions rows_on{};
  const DistanceOptions rows_off{-std::numeric_limits<double>::infinity()};
  const DistanceOptions rows_near{0.04};
  const DistanceOptions pruned{0.04, 0.04};  // the controller's: rows and broad phase at d_a
  std::vector<int> listed;
  for (int p = 0; p < static_cast<int>(model.pairs.size()); p += 2) listed.push_back(p);
  DistanceData scratch(model);
  PairListing listing(model);
  const std::vector<double> reach(listed.size(), 0.01);
  KinematicsData kin_near(model);

  AllocationCounter counter;
  for (int i = 0; i < 50; ++i) {
    computeForwardKinematics(model, kin, qs[i]);
    computeSegmentDistances(model, kin, dist, rows_on);
    computeSegmentDistances(model, kin, dist, rows_off);
    computeSegmentDistances(model, kin, dist, rows_near);
    computeSegmentDistances(model, kin, dist, pruned);
    computeListedPairDistances(model, kin, dist.slots, scratch, listed.data(), static_cast<int>(listed.size()));
    computeListedPairDistances(model, kin, dist.slots, scratch, listed.data(), static_cast<int>(listed.size()), 0.02);
    listPairsNear(model, dist, listed.data(), static_cast<int>(listed.size()), 0.02, reach.data(), listing);
    computeListedPairDistances(model, kin, dist.slots, scratch, listed.data(), static_cast<int>(listed.size()), 0.02,
                               &listing);
    computeForwardKinematics(model, kin_near, qs[(i + 1) % 50], &kin);
    computePointJacobian(model, kin, hand, kin.X_B_L[hand].translation(), J);
    computeRelativeJacobian(model, kin, hand, kin.X_B_L[hand].translation(), head, kin.X_B_L[head].translation(), J);
    computeDirectionalRow(model, kin, hand, kin.X_B_L[hand].translation(), head, kin.X_B_L[head].translation(),
                          Eigen::Vector3d::UnitX(), row);
    // Body schema at run time: attach, check, detach.
    if (i == 10)
      attachBodySchemaSegment(model, dist, 0, hand, Eigen::Vector3d(0, 0, -0.05), Eigen::Vector3d(0.2, 0, -0.05), 0.02,
                              0);
    if (i == 20)
      attachBodySchemaSegment(model, dist, 3, head, Eigen::Vector3d::Zero(), Eigen::Vector3d(0.5, 0, 0), 0.03);
    if (i == 40) detachBodySchemaSegment(dist, 0);
    computeForwardKinematics(model, kin, q_nan);  // rejected, still no allocation
  }
  const long allocations = counter.count();
  EXPECT_EQ(allocations, 0) << robot;
  // The loop really ran the slots (else the test would prove less than it claims).
  EXPECT_TRUE(dist.slots[3].enabled);
  EXPECT_GE(dist.closest, 0);
}

TEST(DistanceAlloc, PerCycleRoutinesDoNotAllocateOnTheShippedRobot) { runCycles(testing::kAsimo); }

TEST(DistanceAlloc, PerCycleRoutinesDoNotAllocateOnTheSecondHumanoid) { runCycles(testing::kSmall); }

// The tight model: convex pieces, the narrow phase's candidate lists and early stops.
TEST(DistanceAlloc, PerCycleRoutinesDoNotAllocateOnTheTightModel) { runCycles("mesh_humanoid"); }

}  // namespace
}  // namespace reflex::control
