// The 5 ms control path allocates nothing: operator new and (not under AddressSanitizer) malloc /
// calloc / realloc, which Eigen's dynamic matrices use, are counted (support/count_allocations.hpp);
// a full controller cycle (kinematics, every pair, both controllers, blend, safety filter, predictive guard, e-stop logic, body-schema slots) must leave the count unchanged, and so
// must the plant step (walking and its guard) and the controller's body-schema attach, and the
// onboard controller (onboard.hpp: every input call and step(), with its refusals) that
// reflex_controller and runScenario drive.
#include "support/robot.hpp"

#include "reflex/control/onboard.hpp"
#include "reflex/control/simulation.hpp"

#include <gtest/gtest.h>

#include "support/count_allocations.hpp"

namespace reflex::control {
namespace {

using reflex::testing::AllocationCount;

TEST(ControllerAllocation, ACycleAllocatesNothing) {
  const Model& model = testing::shippedModel();
  const ControllerModel& cm = testing::defaultControllerModel();
  for (const AvoidanceMode mode : {AvoidanceMode::kOneDof, AvoidanceMode::kThreeDof}) {
    ControllerModel cmm = cm;
    cmm.params.mode = mode;
    ControllerData data(model, cmm);
    attachBodySchemaSegment(model, data.dist, 0, model.linkIndex("l_hand"), Eigen::Vector3d(-0.16, 0, -0.06),
                            Eigen::Vector3d(0.16, 0, -0.06), 0.015);
    Eigen::VectorXd q = restConfiguration(model, cmm);
    ControlInput in;
    in.hands[kLeft] = {HandStatus::kGiven, Eigen::Vector3d(0.30, -0.08, 0.90)};  // crossing: avoidance active
    in.hands[kRight] = {HandStatus::kGiven, Eigen::Vector3d(0.30, 0.08, 0.90)};
    computeControl(model, cmm, data, q, in);  // warm-up
    long max_f = 0;
    AllocationCount cycles;
    for (int k = 0; k < 1500; ++k) {
      computeControl(model, cmm, data, q, in);
      q += data.qdot * cmm.params.period;
      if (data.arms[kLeft].f > 0.5) ++max_f;
    }
    EXPECT_EQ(cycles.count(), 0) << "allocations in 1500 cycles";
    EXPECT_GT(max_f, 0) << "the cycles exercised the collision controller";
    // The predictive guard's path: with the first-order floor at d_r (guard_margin 0) and the
    // targets jumping between crossing, into the chest and low across, the guard shortens steps; still nothing
    // is allocated.
    ControllerModel guarded = cmm;
    guarded.params.guard_margin = 0.0;
    ControllerData gdata(model, guarded);
    Eigen::VectorXd gq = restConfiguration(model, guarded);
    ControlInput gin = in;
    computeControl(model, guarded, gdata, gq, gin);
    const Eigen::Vector3d inside(0.02, 0.0, 0.95), across_l(0.30, -0.08, 0.90), across_r(0.30, 0.08, 0.90);
    const Eigen::Vector3d low_l(0.10, -0.05, 0.75), low_r(0.10, 0.05, 0.75);
    const Eigen::Vector3d phases[4][2] = {{across_l, across_r}, {inside, across_r}, {low_l, inside}, {across_l, low_r}};
    AllocationCount guard_cycles;
    for (int k = 0; k < 1500; ++k) {
      for (int a = 0; a < 2; ++a) gin.hands[a].target_B = phases[(k / 80) % 4][a];
      gin.priority = static_cast<MotionPriority>((k / 120) % 3);
      computeControl(model, guarded, gdata, gq, gin);
      gq += gdata.qdot * guarded.params.period;
    }
    EXPECT_EQ(guard_cycles.count(), 0) << "allocations with the predictive guard acting";
    EXPECT_GT(gdata.guard_count, 0U) << "the guard shortened steps in these cycles";
    // The e-stop path too.
    in.reset_estop = true;
    AllocationCount estop_cycle;
    computeControl(model, cmm, data, q, in);
    EXPECT_EQ(estop_cycle.count(), 0);
  }
}

TEST(ControllerAllocation, ThePlantStepWalkingGuardAndSegmentCheckAllocateNothing) {
  // stepPlant (arms, walking, the walking guard, a held step taken back) and attachControllerSegment
  // (attach, placement check, refusal) run inside the 5 ms loop of reflex_controller.
  const Model& model = testing::shippedModel();
  const ControllerModel& cm = testing::defaultControllerModel();
  ControllerData data(model, cm);
  KinematicRobot robot(model, restConfiguration(model, cm));
  WalkingPattern walking(model);
  Eigen::VectorXd scratch = robot.jointPositions();
  ControlResult cr = computeControl(model, cm, data, robot.jointPositions(), ControlInput{});
  const Eigen::Vector3d chest = data.kin.X_B_L[model.linkIndex("chest")].translation();
  const Eigen::Vector3d post = chest + Eigen::Vector3d(0.30, 0.0, 0.0);
  const int world = model.linkIndex("world");
  walking.start(0.6, 0.25);
  AllocationCount counted;
  const SegmentAttach refused =
      attachControllerSegment(model, cm, data, 1, world, chest, chest, 0.05, 0, false, robot.jointPositions());
  const SegmentAttach obstacle =
      attachControllerSegment(model, cm, data, 0, world, post - Eigen::Vector3d(0, 0, 0.1),
                              post + Eigen::Vector3d(0, 0, 0.1), 0.04, 0, false, robot.jointPositions());
  for (int k = 0; k < 800; ++k) {
    cr = computeControl(model, cm, data, robot.jointPositions(), ControlInput{});
    stepPlant(model, cm, data, cr, robot, &walking, cm.params.period, scratch);
  }
  EXPECT_EQ(counted.count(), 0) << "allocations in 800 plant steps";
  EXPECT_FALSE(refused.attached);
  EXPECT_TRUE(obstacle.attached);
  EXPECT_GT(data.walking_hold_count, 0U) << "the walking guard held steps";
}

TEST(ControllerAllocation, TheOnboardControllersInputsAndStepAllocateNothing) {
  const Model& model = testing::shippedModel();
  const ControllerModel& cm = testing::defaultControllerModel();
  const Eigen::VectorXd q0 = restConfiguration(model, cm);
  KinematicPort port(q0);
  OnboardController ctl(model, cm, port, q0);
  std::array<HandCommand, 2> crossing;
  crossing[kLeft] = {HandStatus::kGiven, Eigen::Vector3d(0.30, -0.08, 0.90)};
  crossing[kRight] = {HandStatus::kGiven, Eigen::Vector3d(0.30, 0.08, 0.90)};
  std::array<HandCommand, 2> bad = crossing;
  bad[kLeft].target_B.x() = std::nan("");
  // Names and links as a DDS sample holds them (made before counting).
  const std::string cup = "a_cup_with_a_name_longer_than_the_small_string_buffer", hand = "l_hand";
  const std::string pack = "pack", world = "world", unknown = "no_such_link";
  ctl.step(0.0);  // warm-up
  const Eigen::Vector3d chest = ctl.data().kin.X_B_L[model.linkIndex("chest")].translation();
  BodySchemaRequest attach;
  attach.name = &cup;
  attach.parent_link = &hand;
  attach.a_L = Eigen::Vector3d(-0.16, 0, -0.06);
  attach.b_L = Eigen::Vector3d(0.16, 0, -0.06);
  attach.radius = 0.015;
  attach.motion_priority = 1;
  BodySchemaRequest refused = attach;
  refused.name = &pack;
  refused.parent_link = &world;
  refused.a_L = refused.b_L = chest;
  refused.radius = 0.05;
  BodySchemaRequest unknown_link = attach;
  unknown_link.name = &pack;
  unknown_link.parent_link = &unknown;
  BodySchemaRequest detach = attach;
  detach.operation = BodySchemaRequest::Operation::kDetach;
  ControlInput scripted;
  scripted.hands = crossing;
  long stepped = 0;
  AllocationCount counted;
  double t = 0.0;
  for (int k = 0; k < 1000; ++k, t += 0.005) {
    if (k % 50 == 0) ctl.setHandTargets(k % 100 == 0 ? crossing : bad, t);
    if (k % 200 == 10) ctl.changeBodySchema(attach);
    if (k % 200 == 20) ctl.changeBodySchema(refused);
    if (k % 200 == 30) ctl.changeBodySchema(unknown_link);
    if (k % 200 == 150) ctl.changeBodySchema(detach);
    if (k % 300 == 40) ctl.walkCommand(false, 0.4, 0.2);
    if (k % 300 == 200) ctl.walkCommand(true, 0.0, 0.0);
    if (k % 300 == 210) ctl.walkCommand(false, std::nan(""), 0.2);
    if (k % 100 == 60) ctl.noteSourceHeartbeat(t);
    if (k == 500) ctl.setControlInput(scripted, t);
    if (k == 600) ctl.holdHandsHere(t);
    if (k == 700) ctl.requestEstopReset();
    ctl.setPriority(static_cast<MotionPriority>((k / 120) % 3));
    // Every other cycle spans 2 ms, as a cycle per arriving robot state at 500 Hz does (step(now, dt)).
    stepped += (k % 2 == 1 ? ctl.step(t, 0.002) : ctl.step(t)).robot_state_ok;
  }
  EXPECT_EQ(counted.count(), 0) << "allocations in 1000 onboard cycles with every input";
  EXPECT_EQ(stepped, 1000);
  EXPECT_GT(ctl.report().counts.schema_rejected, 0U);
  EXPECT_GT(ctl.report().counts.hand_targets_rejected, 0U);
  EXPECT_GT(ctl.report().counts.walk_rejected, 0U);
}

}  // namespace
}  // namespace reflex::control
