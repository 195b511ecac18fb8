// Walking and the plant step (simulation.hpp) with the controller.
//
// What is checked against what:
// - Velocity (item 5): over random sequences of walk start / stop / restart commands (any time, any
//   goal, speed and step period, including zero, negative, huge and non-finite ones) and random arm
//   velocities (also beyond the limits and NaN), no joint of the plant ever moves by more than
//   model.v_max * dt in one cycle, and WalkingPattern::step alone never asks for more. The bound is
//   the URDF's velocity limit, read independently of the code under test.
// - E-stop (item 1): while the e-stop is latched or recovering, the walking joints do not move
//   (compared sample to sample of the recorded run), and walking resumes and completes afterwards.
// - Segments no arm can move (item 1, the decision in control/README.md): walking into a physical
//   segment fixed to the root link stops in front of it (no pair below d_r + predict_margin, no
//   e-stop) and completes once it is removed; a physical segment attached overlapping a part of the
//   body that no arm moves is refused, one that an arm can move away from is accepted.
#include "support/robot.hpp"

#include "reflex/control/simulation.hpp"

#include <gtest/gtest.h>

#include <cstdio>
#include <limits>
#include <random>

namespace reflex::control {
namespace {

using testing::defaultControllerModel;
using testing::shippedModel;

TEST(Walking, ASecondWalkCommandMidWalkMovesNoJointFasterThanItsLimit) {
  // The case: a second walk command 0.5 s into a walk restarted the pattern from phase 0
  // (ankle 0.39 rad, hip 0.34 rad in one 5 ms cycle).
  const Model& model = shippedModel();
  const double dt = 0.005;
  WalkingPattern walking(model);
  Eigen::VectorXd q = restConfiguration(model, defaultControllerModel());
  walking.start(1.0, 0.3);
  double worst = 0.0;  // max over joints and cycles of |dq| / (v_max dt)
  for (int k = 0; k < 400; ++k) {
    if (k == 100 || k == 250) walking.start(1.0, 0.3);  // restart mid-walk
    const Eigen::VectorXd before = q;
    walking.step(dt, q);
    for (const int j : walking.joints()) worst = std::max(worst, std::abs(q[j] - before[j]) / (model.v_max[j] * dt));
  }
  EXPECT_LE(worst, 1.0 + 1e-12);
  EXPECT_GT(worst, 0.5) << "the legs did move at a good fraction of their limit";
}

TEST(Walking, AnyCommandSequenceKeepsEveryJointOfThePlantWithinItsVelocityLimitAndHoldsUnlessClear) {
  const Model& model = shippedModel();
  const ControllerModel& cm = defaultControllerModel();
  const double dt = cm.params.period;
  const double nan = std::numeric_limits<double>::quiet_NaN(), inf = std::numeric_limits<double>::infinity();
  const double odd[] = {0.0, -0.5, 1e-12, 1e9, nan, inf, -inf};
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  double worst_plant = 0.0, worst_pattern = 0.0;
  int commands = 0, held_cycles = 0;
  for (int seq = 0; seq < 60; ++seq) {
    ControllerData data(model, cm);
    KinematicRobot robot(model, restConfiguration(model, cm));
    WalkingPattern walking(model);
    Eigen::VectorXd scratch(model.nq), qdot(model.nq);
    for (int k = 0; k < 600; ++k) {
      if (u(rng) < 0.03) {  // a command at a random cycle
        ++commands;
        const double r = u(rng);
        auto pick = [&](double lo, double hi) { return u(rng) < 0.2 ? odd[rng() % 7] : lo + (hi - lo) * u(rng); };
        if (r < 0.2)
          walking.stop();
        else
          walking.start(pick(-0.5, 3.0), pick(0.0, 2.0), pick(0.0, 4.0));
      }
      // The pattern alone, from the robot's current positions.
      Eigen::VectorXd q_pattern = robot.jointPositions();
      const WalkingPattern::Snapshot s = walking.snapshot();
      walking.step(dt, q_pattern);
      walking.restore(s);
      for (int j = 0; j < model.nq; ++j)
        worst_pattern =
            std::max(worst_pattern, std::abs(q_pattern[j] - robot.jointPositions()[j]) / (model.v_max[j] * dt));
      // The plant: arm velocities anywhere up to 3x their limit, sometimes NaN; the controller's result.
      for (int j = 0; j < model.nq; ++j) qdot[j] = (u(rng) < 0.01 ? nan : 3.0 * (2.0 * u(rng) - 1.0) * model.v_max[j]);
      data.qdot = qdot;
      // The controller's result: mostly clear, sometimes latched, recovering or bad input, in
      // which walking must hold (item 1).
      const double pr = u(rng);
      const ControlResult result = pr < 0.8    ? ControlResult::kOk
                                   : pr < 0.87 ? ControlResult::kRecovering
                                   : pr < 0.94 ? ControlResult::kFrozen
                                               : ControlResult::kBadInput;
      const Eigen::VectorXd before = robot.jointPositions();
      stepPlant(model, cm, data, result, robot, &walking, dt, scratch);
      for (int j = 0; j < model.nq; ++j) {
        const double moved = std::abs(robot.jointPositions()[j] - before[j]);
        ASSERT_TRUE(std::isfinite(robot.jointPositions()[j])) << model.q_names[j];
        worst_plant = std::max(worst_plant, moved / (model.v_max[j] * dt));
      }
      if (result != ControlResult::kOk) {
        ++held_cycles;
        for (const int j : walking.joints()) ASSERT_EQ(robot.jointPositions()[j], before[j]) << model.q_names[j];
      }
    }
  }
  std::printf("%d random walk commands: worst |dq| / (v_max dt) = %.6f (plant), %.6f (pattern)\n", commands,
              worst_plant, worst_pattern);
  EXPECT_GT(commands, 500);
  EXPECT_GT(held_cycles, 5000);
  EXPECT_LE(worst_plant, 1.0 + 1e-9);
  EXPECT_LE(worst_pattern, 1.0 + 1e-9);
  EXPECT_GT(worst_plant, 0.99) << "the arms were driven at their limit";
}

TEST(Walking, LegMotionFadesInAndOutWithoutJumps) {
  // A walking controller starts and stops smoothly: no walking joint moves faster than its limit,
  // and the legs are back at rest after the fade-out.
  const Model& model = shippedModel();
  WalkingPattern walking(model);
  Eigen::VectorXd q = restConfiguration(model, defaultControllerModel());
  Eigen::VectorXd prev = q;
  walking.start(0.3, 0.3, 0.8);
  double worst = 0.0;
  bool stopped = false;
  for (int k = 0; k < 400; ++k) {
    walking.step(0.005, q);
    for (const int j : walking.joints()) worst = std::max(worst, std::abs(q[j] - prev[j]) / (model.v_max[j] * 0.005));
    prev = q;
    if (!walking.walking()) stopped = true;
  }
  EXPECT_TRUE(stopped);
  EXPECT_LE(worst, 1.0 + 1e-12);
  EXPECT_NEAR(walking.travelled(), 0.3, 1e-12);
  const Eigen::VectorXd rest = restConfiguration(model, defaultControllerModel());
  for (const int j : walking.joints())
    if (model.q_names[j] != "heel_x") {
      EXPECT_NEAR(q[j], rest[j], 1e-9) << model.q_names[j] << " back at rest after the fade-out";
    }
}

std::vector<int> walkingJoints(const Model& model) { return WalkingPattern(model).joints(); }

TEST(WalkingAndEstop, WalkingHoldsWhileTheEstopIsLatchedOrRecovering) {
  // A physical segment fixed to the root link is attached where the right hand is (an arm can move
  // away from it, so it is accepted): the e-stop latches; 0.3 s later it is reset and the arm
  // recovers. Walking, commanded all along, must not move while latched or recovering.
  const Model& model = shippedModel();
  const ControllerModel& cm = defaultControllerModel();
  Scenario s;
  s.duration = 4.0;
  s.walk_distance = 0.4;
  s.walk_speed = 0.25;
  s.walk_start = 0.1;
  bool attached = false;
  s.script = [&](double t, ControlInput& in, ScenarioContext& ctx) {
    in.reset_estop = false;
    if (t >= 0.5 && !attached) {
      const Eigen::Vector3d hand = ctx.data.arms[kRight].hand_B;
      attached = ctx.attach(0, "world", hand, hand + Eigen::Vector3d(0.0, 0.0, 0.02), 0.03, false);
    }
    if (std::abs(t - 0.8) < 1e-9) in.reset_estop = true;
    if (std::abs(t - 1.5) < 1e-9) ctx.detach(0);
  };
  const SimResult r = runScenario(model, cm, s);
  ASSERT_TRUE(attached);
  ASSERT_TRUE(r.estop_fired);
  const std::vector<int> legs = walkingJoints(model);
  int latched = 0, recovering = 0;
  for (std::size_t k = 0; k + 1 < r.samples.size(); ++k) {
    const EstopState e = r.samples[k].estop;
    if (e == EstopState::kClear) continue;
    (e == EstopState::kLatched ? latched : recovering) += 1;
    for (const int j : legs) {
      ASSERT_EQ(r.samples[k + 1].q[j], r.samples[k].q[j])
          << model.q_names[j] << " moved at t = " << r.samples[k].t << " s while the e-stop was "
          << (e == EstopState::kLatched ? "latched" : "recovering");
    }
  }
  EXPECT_GT(latched, 10);
  EXPECT_GT(recovering, 0);
  EXPECT_EQ(r.samples.back().estop, EstopState::kClear);
  const int heel = model.qIndex("heel_x");
  EXPECT_NEAR(r.samples.back().q[heel] - r.samples.front().q[heel], s.walk_distance, 1e-9) << "walking completed";
  EXPECT_LE(r.max_joint_speed_ratio, 1.0 + 1e-9);
}

TEST(WalkingAndEstop, WalkingStopsInFrontOfASegmentOnTheRootThatNoArmCanMoveAndResumesWhenItIsGone) {
  // The case: a physical segment fixed to the root link in front of the chest, and a walk
  // towards it. Before: the chest reached 3.6 mm, the e-stop latched, and after a reset walking
  // went on through the segment (-192 mm). Now the walking guard holds the legs in front of it.
  const Model& model = shippedModel();
  const ControllerModel& cm = defaultControllerModel();
  ControllerData probe(model, cm);
  const Eigen::VectorXd q0 = restConfiguration(model, cm);
  ASSERT_NE(computeControl(model, cm, probe, q0, ControlInput{}), ControlResult::kBadInput);
  const Eigen::Vector3d chest = probe.kin.X_B_L[model.linkIndex("chest")].translation();
  const Eigen::Vector3d post = chest + Eigen::Vector3d(0.30, 0.0, 0.0);  // 30 cm in front of the chest
  Scenario s;
  s.duration = 6.0;
  s.walk_distance = 0.6;
  s.walk_speed = 0.25;
  s.walk_start = 0.0;
  bool attached = false;
  double t_removed = -1.0;
  s.script = [&](double t, ControlInput& in, ScenarioContext& ctx) {
    in.reset_estop = std::abs(t - 3.0) < 1e-9;  // an operator resets whatever latched (nothing should)
    if (!attached && t == 0.0)
      attached =
          ctx.attach(0, "world", post - Eigen::Vector3d(0, 0, 0.1), post + Eigen::Vector3d(0, 0, 0.1), 0.04, false);
    if (t_removed < 0.0 && t >= 3.5) {
      ctx.detach(0);
      t_removed = t;
    }
  };
  const SimResult r = runScenario(model, cm, s);
  ASSERT_TRUE(attached);
  const int heel = model.qIndex("heel_x");
  double closest = 1.0, heel_at_removal = 0.0;
  for (const SimSample& x : r.samples) {
    if (x.t < t_removed) closest = std::min(closest, x.min_distance);
    if (x.t <= t_removed) heel_at_removal = x.q[heel] - r.samples.front().q[heel];
  }
  std::printf(
      "closest %.3f mm while the segment stood (floor %.3f mm); walked %.3f m before its removal; "
      "%llu walking steps held\n",
      closest * 1e3, (cm.params.d_r + cm.params.predict_margin) * 1e3, heel_at_removal,
      static_cast<unsigned long long>(r.walking_holds));
  EXPECT_FALSE(r.estop_fired);
  EXPECT_GE(closest, cm.params.d_r + cm.params.predict_margin - 1e-9);
  EXPECT_GT(r.walking_holds, 100U);
  EXPECT_LT(heel_at_removal, 0.35) << "the robot stopped in front of the segment";
  EXPECT_NEAR(r.samples.back().q[heel] - r.samples.front().q[heel], s.walk_distance, 1e-9)
      << "walking completed once the segment was gone";
}

TEST(BodySchema, APhysicalSegmentTouchingAPartNoArmCanMoveIsRefused) {
  const Model& model = shippedModel();
  const ControllerModel& cm = defaultControllerModel();
  ControllerData data(model, cm);
  const Eigen::VectorXd q = restConfiguration(model, cm);
  ASSERT_EQ(computeControl(model, cm, data, q, ControlInput{}), ControlResult::kOk);
  const int world = model.linkIndex("world"), chest = model.linkIndex("chest");
  const Eigen::Vector3d chest_B = data.kin.X_B_L[chest] * Eigen::Vector3d(0.0, 0.0, 0.06);
  const Eigen::Vector3d hand_B = data.arms[kRight].hand_B;
  const Eigen::Vector3d z(0, 0, 0.05);
  // On the root, through the chest: no arm can take them apart.
  SegmentAttach a = attachControllerSegment(model, cm, data, 1, world, chest_B - z, chest_B + z, 0.05, 0, false, q);
  EXPECT_FALSE(a.attached);
  ASSERT_GE(a.refusing_pair, 0);
  const std::string trunk = model.segments[a.other_segment].name;
  EXPECT_TRUE(trunk == "chest" || trunk == "body") << trunk;
  EXPECT_LT(a.distance, 0.0);
  EXPECT_FALSE(data.dist.slots[1].enabled) << "the slot stays as it was";
  // Carried by the chest (a backpack) but reaching into the head: refused too.
  const Eigen::Vector3d head_L =
      data.kin.X_B_L[chest].inverse() * data.kin.X_B_L[model.linkIndex("head")].translation();
  const std::uint64_t own = std::uint64_t{1} << model.segmentIndex("chest");
  a = attachControllerSegment(model, cm, data, 1, chest, head_L, head_L + z, 0.03, own, false, q);
  EXPECT_FALSE(a.attached);
  ASSERT_GE(a.refusing_pair, 0);
  EXPECT_EQ(model.segments[a.other_segment].name, "head");
  // On the root, touching the right hand: an arm can move away, so it is accepted (it latches the
  // e-stop, and recovery moves the arm out).
  a = attachControllerSegment(model, cm, data, 2, world, hand_B, hand_B, 0.03, 0, false, q);
  EXPECT_TRUE(a.attached);
  EXPECT_EQ(a.refusing_pair, -1);
  // A virtual segment (a gaze line) through the chest is never refused: it never triggers the e-stop.
  a = attachControllerSegment(model, cm, data, 3, world, chest_B - z, chest_B + z, 0.05, 0, true, q);
  EXPECT_TRUE(a.attached);
  EXPECT_TRUE(data.dist.slots[3].is_virtual);
  // Updating an attached slot into such an overlap leaves the old placement in place.
  const Eigen::Vector3d away = chest_B + Eigen::Vector3d(0.6, 0.0, 0.0);
  a = attachControllerSegment(model, cm, data, 1, world, away, away, 0.05, 0, false, q);
  ASSERT_TRUE(a.attached);
  a = attachControllerSegment(model, cm, data, 1, world, chest_B, chest_B, 0.05, 0, false, q);
  EXPECT_FALSE(a.attached);
  EXPECT_TRUE(data.dist.slots[1].enabled);
  EXPECT_TRUE(data.dist.slots[1].a_L.isApprox(away));
}

}  // namespace
}  // namespace reflex::control
