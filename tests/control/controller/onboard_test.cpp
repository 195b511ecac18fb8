// OnboardController (control/include/reflex/control/onboard.hpp): the controller's
// whole reaction to its inputs, without processes. Checked against independent answers:
// - staleness: the timeout from the options (hold at exactly input_timeout after the last sign of
//   life, retract strictly after it), and the rest posture from restConfiguration + forward kinematics;
//   a resumed controller's hold (holdHandsHere): the hands' own positions by forward kinematics;
// - body schema by name: the distance module called directly (attachBodySchemaSegment +
//   computeSegmentDistances on a DistanceData of its own) for the attached segment and for a refusal's
//   distance; the refusal causes from BodySchemaLimits and kBodySchemaSlots;
// - walking: the heel's analytic travel (speed x dt per cycle the controller is clear, nothing while
//   the e-stop is latched or recovering: the paper's rule as control/README.md states it);
// - priority: the paper's rule (Sec. 7.2: the given priority; a grasped object with priority makes
//   its arm higher) and computeControl called directly with that priority (same joint velocities);
// - the plant loop: the pre-issue-13 loop written out here (computeControl + stepPlant on a
//   KinematicRobot) gives bit-identical joint positions over 1200 cycles with walking;
// - the robot port: a port without state gets no command; the command is measured + qdot dt.
// - rejections: one counter per cause, each cause provoked by a value on its
//   own side of the documented bound (max_target_distance, kWalkGoalTolerance), the latest cause named;
// - the closest pair's names: segment_a is the arm's own segment, checked against the
//   robot's naming (l_* segments move with the left arm, r_* with the right) over a crossing-arms run.
#include "support/robot.hpp"

#include "reflex/control/onboard.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <limits>
#include <string>

namespace reflex::control {
namespace {

using testing::defaultControllerModel;
using testing::shippedModel;

constexpr double kDt = 0.005;

std::array<HandCommand, 2> crossing() {
  std::array<HandCommand, 2> h;
  h[kLeft] = {HandStatus::kGiven, Eigen::Vector3d(0.30, -0.08, 0.90)};
  h[kRight] = {HandStatus::kGiven, Eigen::Vector3d(0.30, 0.08, 0.90)};
  return h;
}

std::array<HandCommand, 2> reachable() {
  std::array<HandCommand, 2> h;
  h[kLeft] = {HandStatus::kGiven, Eigen::Vector3d(0.30, 0.20, 0.85)};
  h[kRight] = {HandStatus::kGiven, Eigen::Vector3d(0.30, -0.20, 0.85)};
  return h;
}

Eigen::Vector3d handAt(const Model& model, const ControllerModel& cm, const Eigen::VectorXd& q, int arm) {
  KinematicsData kin(model);
  EXPECT_TRUE(computeForwardKinematics(model, kin, q));
  return kin.X_B_L[cm.arms[arm].hand_link] * cm.arms[arm].hand_point_L;
}

// ---------------------------------------------------------------- staleness

// holdHandsHere (a controller resumed from a saved robot state, reflex_controller --robot-state): the
// hands hold where they are, targets at their own positions (forward kinematics here), until the
// source is heard or input_timeout passes, then retract like after any silence. Deterministic here:
// the system test (faults_controller_restart_test) sees the hold only while discovery is slower
// than the resumed controller's first cycle.
TEST(OnboardStaleness, AResumedControllerHoldsTheHandsWhereTheyAreUntilTheSourceOrTheTimeout) {
  const Model& model = shippedModel();
  const ControllerModel& cm = defaultControllerModel();
  // A configuration away from rest: the arms after reaching apart for 2 s.
  Eigen::VectorXd q_start;
  {
    const Eigen::VectorXd q0 = restConfiguration(model, cm);
    KinematicPort port(q0);
    OnboardController reach(model, cm, port, q0, OnboardOptions{});
    for (int k = 0; k < 400; ++k) {
      reach.setHandTargets(reachable(), k * kDt);
      reach.step(k * kDt);
    }
    q_start = port.positions();
  }
  const std::array<Eigen::Vector3d, 2> h0 = {handAt(model, cm, q_start, kLeft), handAt(model, cm, q_start, kRight)};
  ASSERT_GT((h0[kLeft] - handAt(model, cm, restConfiguration(model, cm), kLeft)).norm(), 0.05)
      << "the start is away from rest (a retract would show)";

  for (const bool source_comes : {false, true}) {
    SCOPED_TRACE(source_comes ? "the source is heard at 0.25 s" : "the source stays silent");
    KinematicPort port(q_start);
    OnboardOptions options;
    options.input_timeout = 0.5;
    OnboardController ctl(model, cm, port, q_start, options);
    ASSERT_TRUE(ctl.holdHandsHere(0.0));
    double held = 0.0;
    for (int k = 1; k < 50; ++k) {  // t < 0.25 s: holding
      const CycleReport& r = ctl.step(k * kDt);
      ASSERT_FALSE(r.inputs_stale) << "t = " << k * kDt;
      for (int a = 0; a < 2; ++a) {
        ASSERT_EQ(r.commands[a].status, HandStatus::kGiven);
        EXPECT_LT((r.commands[a].target_B - h0[a]).norm(), 1e-12) << "the hold's target is the hand itself";
        held = std::max(held, (handAt(model, cm, port.positions(), a) - h0[a]).norm());
      }
    }
    EXPECT_LT(held, 1e-3) << "the hands hold within 1 mm";
    if (source_comes) {
      ctl.setHandTargets(crossing(), 0.25);
      const CycleReport& r = ctl.step(0.25);
      EXPECT_FALSE(r.inputs_stale);
      EXPECT_EQ(r.commands[kLeft].target_B, crossing()[kLeft].target_B) << "the source's targets replace the hold";
      for (int k = 51; k <= 140; ++k) EXPECT_FALSE(ctl.step(k * kDt).inputs_stale) << "0.5 s after the source's sample";
      continue;
    }
    for (int k = 50; k <= 99; ++k) ASSERT_FALSE(ctl.step(k * kDt).inputs_stale) << "held until input_timeout";
    const CycleReport& late = ctl.step(0.5 + kDt);
    EXPECT_TRUE(late.inputs_stale) << "then stale";
    EXPECT_EQ(late.commands[kLeft].status, HandStatus::kNoTarget);
    for (int k = 0; k < 200; ++k) ctl.step(0.5 + (k + 2) * kDt);
    EXPECT_GT((handAt(model, cm, port.positions(), kLeft) - h0[kLeft]).norm(), 0.02) << "and the arms retract";
  }
}

TEST(OnboardStaleness, HoldsUntilExactlyTheTimeoutThenRetractsToRest) {
  const Model& model = shippedModel();
  const ControllerModel& cm = defaultControllerModel();
  const Eigen::VectorXd q0 = restConfiguration(model, cm);
  KinematicPort port(q0);
  OnboardOptions options;
  options.input_timeout = 0.5;  // the independent answer: the configured timeout
  OnboardController ctl(model, cm, port, q0, options);
  // Before any sign of life the inputs are stale.
  EXPECT_TRUE(ctl.step(0.0).inputs_stale);
  ctl.setHandTargets(reachable(), 0.0);
  // Times as exact binary fractions so "now - last == timeout" is exact.
  int k = 1;
  for (; k * 0.0625 <= 0.5; ++k) {
    const CycleReport& r = ctl.step(k * 0.0625);
    ASSERT_FALSE(r.inputs_stale) << "held at t = " << k * 0.0625;
    ASSERT_EQ(r.commands[kLeft].status, HandStatus::kGiven);
  }
  EXPECT_EQ(k * 0.0625, 0.5625);
  EXPECT_FALSE(ctl.step(0.5).inputs_stale) << "exactly input_timeout after the sample: still held";
  const CycleReport& late = ctl.step(std::nextafter(0.5, 1.0));
  EXPECT_TRUE(late.inputs_stale) << "strictly later than input_timeout: stale";
  EXPECT_EQ(late.commands[kLeft].status, HandStatus::kNoTarget);
  EXPECT_EQ(late.commands[kRight].status, HandStatus::kNoTarget);
  EXPECT_EQ(late.counts.stale_events, 1U) << "the first staleness (before any input) is not an event";

  // A heartbeat of the source extends the hold by the same timeout; a new source forgets it.
  ctl.setHandTargets(reachable(), 1.0);
  ctl.noteSourceHeartbeat(1.4);
  EXPECT_FALSE(ctl.step(1.9).inputs_stale) << "0.5 s after the heartbeat";
  EXPECT_TRUE(ctl.step(std::nextafter(1.9, 2.0)).inputs_stale);
  EXPECT_EQ(ctl.report().counts.stale_events, 2U);
  ctl.setHandTargets(reachable(), 3.0);
  ctl.noteSourceHeartbeat(3.25);
  ctl.newTargetSource();
  EXPECT_TRUE(ctl.step(std::nextafter(3.5, 4.0)).inputs_stale) << "the old source's heartbeat no longer counts";

  // Retract: from here the arms move exactly as the controller told "no target" for both hands
  // (computeControl + stepPlant written out, from the same configuration).
  ControllerData ref(model, cm);
  KinematicRobot robot(model, port.positions());
  Eigen::VectorXd scratch = port.positions();
  double t = 4.0;
  for (int i = 0; i < 1200; ++i, t += kDt) {
    ASSERT_TRUE(ctl.step(t).inputs_stale);
    const ControlResult cr = computeControl(model, cm, ref, robot.jointPositions(), ControlInput{});
    stepPlant(model, cm, ref, cr, robot, nullptr, kDt, scratch);
  }
  EXPECT_LT((port.positions() - robot.jointPositions()).cwiseAbs().maxCoeff(), 1e-9);
  EXPECT_GT((port.positions() - q0).cwiseAbs().maxCoeff(), 0.0);
}

TEST(OnboardStaleness, HeldTargetsAreReachedAndRejectedTargetsKeepThePreviousOne) {
  const Model& model = shippedModel();
  const ControllerModel& cm = defaultControllerModel();
  const Eigen::VectorXd q0 = restConfiguration(model, cm);
  KinematicPort port(q0);
  OnboardController ctl(model, cm, port, q0);
  ctl.setHandTargets(reachable(), 0.0);
  std::array<HandCommand, 2> bad = reachable();
  bad[kLeft].target_B.x() = std::nan("");
  bad[kRight].target_B = Eigen::Vector3d(2.0, 0.1, 0.0);  // 2.0025 m > max_target_distance 2 m
  EXPECT_EQ(ctl.setHandTargets(bad, 0.0), 2);
  EXPECT_EQ(ctl.report().counts.hand_targets_rejected, 2U);
  EXPECT_EQ(ctl.report().counts.targets_rejected, 2U);
  EXPECT_EQ(ctl.report().counts.targets_received, 2U);
  double t = 0.0;
  for (int i = 0; i < 370; ++i, t += kDt) {  // 1.85 s: no further sample, one heartbeat at 0.9 s
    if (i == 180) ctl.noteSourceHeartbeat(t);
    const CycleReport& r = ctl.step(t);
    ASSERT_FALSE(r.inputs_stale);
    ASSERT_TRUE(r.commands[kLeft].target_B.isApprox(reachable()[kLeft].target_B));
  }
  for (int a = 0; a < 2; ++a)
    EXPECT_LT((handAt(model, cm, port.positions(), a) - reachable()[a].target_B).norm(), 0.01) << "arm " << a;
}

// ---------------------------------------------------------------- body schema by name

BodySchemaRequest attachRequest(const std::string& name, const std::string& link, const Eigen::Vector3d& a,
                                const Eigen::Vector3d& b, double radius, bool is_virtual = false, int priority = 0) {
  BodySchemaRequest rq;
  rq.name = &name;
  rq.parent_link = &link;
  rq.a_L = a;
  rq.b_L = b;
  rq.radius = radius;
  rq.is_virtual = is_virtual;
  rq.motion_priority = priority;
  return rq;
}

TEST(OnboardBodySchema, AttachByNameMatchesTheDistanceModuleAndDetachFreesTheSlot) {
  const Model& model = shippedModel();
  const ControllerModel& cm = defaultControllerModel();
  const Eigen::VectorXd q0 = restConfiguration(model, cm);
  KinematicPort port(q0);
  OnboardController ctl(model, cm, port, q0);
  const std::string cup = "cup", hand = "l_hand";
  const Eigen::Vector3d a(-0.16, 0.0, -0.06), b(0.16, 0.0, -0.06);
  const BodySchemaOutcome& out = ctl.changeBodySchema(attachRequest(cup, hand, a, b, 0.015));
  ASSERT_EQ(out.kind, BodySchemaOutcome::Kind::kAttached) << out.text;
  EXPECT_EQ(ctl.slotOf(cup), 0);
  const CycleReport& r = ctl.step(0.0);
  // The independent answer: the distance module with the same slot on its own DistanceData.
  KinematicsData kin(model);
  DistanceData dist(model);
  ASSERT_TRUE(computeForwardKinematics(model, kin, q0));
  const int link = model.linkIndex(hand);
  std::uint64_t ignore = std::uint64_t{1} << model.segmentIndex(hand);
  ignore |= std::uint64_t{1} << model.segmentIndex(model.links[model.links[link].parent].name);
  ASSERT_TRUE(attachBodySchemaSegment(model, dist, 0, link, a, b, 0.015, ignore));
  computeSegmentDistances(model, kin, dist);
  double dmin = std::numeric_limits<double>::infinity();
  for (const auto& pd : dist.pairs)
    if (pd.active) dmin = std::min(dmin, pd.distance);
  EXPECT_NEAR(r.min_distance, dmin, 1e-12);
  int slot_pairs = 0;
  for (std::size_t i = 0; i < dist.pairs.size(); ++i) {
    if (!dist.pairs[i].active || dist.pairs[i].seg_b != model.num_robot_segments) continue;
    ++slot_pairs;
    EXPECT_NEAR(ctl.data().dist.pairs[i].distance, dist.pairs[i].distance, 1e-12) << "pair " << i;
  }
  EXPECT_GT(slot_pairs, 5);

  // The same name again re-places its slot; another name takes the next slot.
  const std::string other = "tray";
  EXPECT_EQ(ctl.changeBodySchema(attachRequest(cup, hand, a, b, 0.02)).slot, 0);
  EXPECT_EQ(ctl.changeBodySchema(attachRequest(other, "r_hand", a, b, 0.02)).slot, 1);
  // Disabled: the segment is gone but the name keeps its slot; detached: the slot is free.
  BodySchemaRequest off = attachRequest(cup, hand, a, b, 0.02);
  off.enabled = false;
  EXPECT_EQ(ctl.changeBodySchema(off).kind, BodySchemaOutcome::Kind::kDetached);
  EXPECT_FALSE(ctl.data().dist.slots[0].enabled);
  EXPECT_EQ(ctl.slotOf(cup), 0);
  BodySchemaRequest det = off;
  det.operation = BodySchemaRequest::Operation::kDetach;
  EXPECT_EQ(ctl.changeBodySchema(det).kind, BodySchemaOutcome::Kind::kDetached);
  EXPECT_EQ(ctl.slotOf(cup), -1);
  EXPECT_EQ(ctl.changeBodySchema(det).kind, BodySchemaOutcome::Kind::kUnknownName) << "a second detach: nothing";
  EXPECT_EQ(ctl.report().counts.schema_rejected, 0U);
}

TEST(OnboardBodySchema, RefusalsAreNamedAndCounted) {
  const Model& model = shippedModel();
  const ControllerModel& cm = defaultControllerModel();
  const Eigen::VectorXd q0 = restConfiguration(model, cm);
  KinematicPort port(q0);
  OnboardController ctl(model, cm, port, q0);
  const Eigen::Vector3d z = Eigen::Vector3d::Zero(), x(0.1, 0.0, 0.0);
  const BodySchemaLimits limits;
  // Beyond BodySchemaLimits::max_radius.
  const std::string big = "boulder";
  const BodySchemaOutcome& r1 = ctl.changeBodySchema(attachRequest(big, "l_hand", z, x, limits.max_radius * 2.0));
  EXPECT_EQ(r1.kind, BodySchemaOutcome::Kind::kRejectedCheck);
  EXPECT_EQ(r1.check.fault, BodySchemaFault::kRadiusTooLarge);
  EXPECT_NE(std::string(r1.text).find("'boulder' rejected"), std::string::npos) << r1.text;
  EXPECT_NE(std::string(r1.text).find("max_radius"), std::string::npos) << r1.text;
  // An unknown link.
  const std::string lost = "lost";
  const BodySchemaOutcome& r2 = ctl.changeBodySchema(attachRequest(lost, "no_such_link", z, x, 0.02));
  EXPECT_EQ(r2.check.fault, BodySchemaFault::kUnknownLink);
  EXPECT_NE(std::string(r2.text).find("link 'no_such_link'"), std::string::npos) << r2.text;
  // NaN.
  const std::string nan_name = "nan";
  const BodySchemaOutcome& r3 =
      ctl.changeBodySchema(attachRequest(nan_name, "l_hand", z, Eigen::Vector3d(std::nan(""), 0, 0), 0.02));
  EXPECT_EQ(r3.check.fault, BodySchemaFault::kNonFinite);
  // A physical segment on the root overlapping the chest: no arm can move it apart (README rule 2).
  KinematicsData kin(model);
  ASSERT_TRUE(computeForwardKinematics(model, kin, q0));
  const Eigen::Vector3d chest = kin.X_B_L[model.linkIndex("chest")].translation();
  const std::string pack = "pack";
  const BodySchemaOutcome& r4 = ctl.changeBodySchema(attachRequest(pack, "world", chest, chest, 0.05));
  ASSERT_EQ(r4.kind, BodySchemaOutcome::Kind::kRejectedUnresolvable) << r4.text;
  EXPECT_NE(std::string(r4.text).find("which no arm can move away from it (link 'world')"), std::string::npos)
      << r4.text;
  // Its distance, from the distance module directly: the sphere against the segment it names.
  DistanceData dist(model);
  ASSERT_TRUE(attachBodySchemaSegment(model, dist, 0, model.linkIndex("world"), chest, chest, 0.05));
  computeSegmentDistances(model, kin, dist);
  const int other = r4.attach.other_segment;
  ASSERT_GE(other, 0);
  EXPECT_NE(std::string(r4.text).find("'" + model.segments[other].name + "'"), std::string::npos);
  bool found = false;
  for (const auto& pd : dist.pairs)
    if (pd.active && pd.seg_a == other && pd.seg_b == model.num_robot_segments) {
      EXPECT_NEAR(pd.distance, r4.attach.distance, 1e-12);
      found = true;
    }
  EXPECT_TRUE(found);
  EXPECT_EQ(ctl.slotOf(pack), -1) << "a refused name holds no slot";
  // No free slot: kBodySchemaSlots names fill every slot, the next is refused.
  std::vector<std::string> names;
  for (int s = 0; s <= kBodySchemaSlots; ++s) names.push_back("obj" + std::to_string(s));
  for (int s = 0; s < kBodySchemaSlots; ++s)
    ASSERT_EQ(ctl.changeBodySchema(attachRequest(names[s], "r_hand", z, x, 0.01)).kind,
              BodySchemaOutcome::Kind::kAttached);
  const BodySchemaOutcome& r5 = ctl.changeBodySchema(attachRequest(names.back(), "r_hand", z, x, 0.01));
  EXPECT_EQ(r5.kind, BodySchemaOutcome::Kind::kRejectedNoSlot);
  EXPECT_NE(std::string(r5.text).find("no free slot"), std::string::npos) << r5.text;
  EXPECT_EQ(ctl.report().counts.schema_rejected, 5U);
  EXPECT_EQ(ctl.report().counts.targets_rejected, 5U);
}

// A slot is one record (BodySchemaSlot in data().dist.slots): geometry, virtual,
// motion priority and name, written by changeBodySchema and read from there by the controller. The
// answers are the request's own values; a name of kBodySchemaNameBytes bytes fits exactly, one byte
// more is refused whole (never stored cut short, where it would take the slot of its 255-byte prefix).
TEST(OnboardBodySchema, ASlotIsOneRecordOfGeometryVirtualPriorityAndNameAndALongerNameIsRefused) {
  const Model& model = shippedModel();
  const ControllerModel& cm = defaultControllerModel();
  const Eigen::VectorXd q0 = restConfiguration(model, cm);
  KinematicPort port(q0);
  OnboardController ctl(model, cm, port, q0);
  const Eigen::Vector3d a(0.0, 0.0, -0.05), b(0.0, 0.0, -0.08);
  const std::string longest(kBodySchemaNameBytes, 'n');
  const BodySchemaOutcome& out = ctl.changeBodySchema(attachRequest(longest, "r_hand", a, b, 0.012, false, 2));
  ASSERT_EQ(out.kind, BodySchemaOutcome::Kind::kAttached) << out.text;
  const BodySchemaSlot& slot = ctl.data().dist.slots[static_cast<std::size_t>(out.slot)];
  EXPECT_TRUE(slot.enabled);
  EXPECT_EQ(slot.link, model.linkIndex("r_hand"));
  EXPECT_EQ(slot.a_L, a);
  EXPECT_EQ(slot.b_L, b);
  EXPECT_EQ(slot.radius, 0.012);
  EXPECT_FALSE(slot.is_virtual);
  EXPECT_EQ(slot.motion_priority, 2);
  EXPECT_EQ(std::string(slot.name.data()), longest);
  EXPECT_EQ(ctl.slotOf(longest), out.slot);
  const std::string gaze = "gaze";
  const BodySchemaOutcome& v = ctl.changeBodySchema(attachRequest(gaze, "head", a, b, 0.01, true, 0));
  ASSERT_EQ(v.kind, BodySchemaOutcome::Kind::kAttached) << v.text;
  EXPECT_TRUE(ctl.data().dist.slots[static_cast<std::size_t>(v.slot)].is_virtual);
  // One byte more than a slot holds (and than the bus carries): refused, counted, named; nothing changed.
  const BodySchemaSlots before = ctl.data().dist.slots;
  const std::string too_long = longest + "n";
  const BodySchemaOutcome& r = ctl.changeBodySchema(attachRequest(too_long, "l_hand", a, b, 0.012));
  EXPECT_EQ(r.kind, BodySchemaOutcome::Kind::kRejectedCheck);
  EXPECT_NE(std::string(r.text).find("its name has 256 bytes, more than 255"), std::string::npos) << r.text;
  EXPECT_EQ(ctl.report().counts.schema_rejected, 1U);
  EXPECT_EQ(ctl.report().counts.last_rejection, static_cast<int>(RejectCause::kSchemaBadSegment));
  EXPECT_EQ(ctl.slotOf(too_long), -1);
  for (int s = 0; s < kBodySchemaSlots; ++s) {
    EXPECT_EQ(ctl.data().dist.slots[s].enabled, before[s].enabled);
    EXPECT_EQ(ctl.data().dist.slots[s].link, before[s].link);
    EXPECT_EQ(std::string(ctl.data().dist.slots[s].name.data()), std::string(before[s].name.data()));
  }
  // Disabled (enabled = false): the name keeps its slot, priority and virtual are cleared; detached: free.
  BodySchemaRequest off = attachRequest(longest, "r_hand", a, b, 0.012);
  off.enabled = false;
  EXPECT_EQ(ctl.changeBodySchema(off).kind, BodySchemaOutcome::Kind::kDetached);
  EXPECT_FALSE(slot.enabled);
  EXPECT_EQ(slot.motion_priority, 0);
  EXPECT_EQ(ctl.slotOf(longest), out.slot);
  off.operation = BodySchemaRequest::Operation::kDetach;
  EXPECT_EQ(ctl.changeBodySchema(off).kind, BodySchemaOutcome::Kind::kDetached);
  EXPECT_EQ(slot.name[0], '\0');
  EXPECT_EQ(ctl.slotOf(longest), -1);
}

// ---------------------------------------------------------------- walking

TEST(OnboardWalking, TheHeelTravelsSpeedTimesDtPerClearCycleAndHoldsInEstopAndRecovery) {
  const Model& model = shippedModel();
  const ControllerModel& cm = defaultControllerModel();
  const Eigen::VectorXd q0 = restConfiguration(model, cm);
  KinematicPort port(q0);
  OnboardController ctl(model, cm, port, q0);
  const int heel = model.qIndex("heel_x");
  ASSERT_GE(heel, 0);
  EXPECT_FALSE(ctl.walkCommand(false, std::nan(""), 0.2));
  EXPECT_FALSE(ctl.walkCommand(false, 0.5, 0.0));
  EXPECT_EQ(ctl.report().counts.walk_rejected, 2U);
  EXPECT_EQ(port.positions()[heel], q0[heel]) << "a rejected command does not walk";
  const double speed = 0.2;
  ASSERT_TRUE(ctl.walkCommand(false, q0[heel] + 0.5, speed));
  int clear_cycles = 0;
  double t = 0.0;
  for (int k = 0; k < 40; ++k, t += kDt) clear_cycles += ctl.step(t).result == ControlResult::kOk;
  EXPECT_EQ(clear_cycles, 40);
  EXPECT_NEAR(port.positions()[heel] - q0[heel], 40 * speed * kDt, 1e-12);
  // A physical segment on the root where the right hand is: the e-stop latches.
  const Eigen::Vector3d hand = ctl.data().arms[kRight].hand_B;
  const std::string post = "post";
  ASSERT_EQ(ctl.changeBodySchema(attachRequest(post, "world", hand, hand + Eigen::Vector3d(0, 0, 0.02), 0.03)).kind,
            BodySchemaOutcome::Kind::kAttached);
  int latched = 0, recovering = 0;
  for (int k = 0; k < 600; ++k, t += kDt) {
    if (k == 60) ctl.requestEstopReset();
    if (k == 300) {
      BodySchemaRequest det = attachRequest(post, "world", hand, hand, 0.03);
      det.operation = BodySchemaRequest::Operation::kDetach;
      ctl.changeBodySchema(det);
    }
    const double before = port.positions()[heel];
    const CycleReport& r = ctl.step(t);
    if (r.result == ControlResult::kOk) {
      ++clear_cycles;
      ASSERT_TRUE(r.walking_advanced || r.counts.walking_holds > 0);
    } else {
      (r.estop == EstopState::kLatched ? latched : recovering) += 1;
      ASSERT_EQ(port.positions()[heel], before)
          << "the heel moved while the e-stop was " << (r.estop == EstopState::kLatched ? "latched" : "recovering");
      ASSERT_FALSE(r.walking_advanced);
    }
  }
  EXPECT_GT(latched, 10);
  EXPECT_GT(recovering, 0);
  EXPECT_EQ(ctl.report().estop, EstopState::kClear);
  EXPECT_EQ(ctl.report().counts.walking_holds, 0U);
  // The analytic travel: speed x dt per clear cycle, up to the goal.
  EXPECT_NEAR(port.positions()[heel] - q0[heel], std::min(0.5, clear_cycles * speed * kDt), 1e-9);
  // Speed capped at max_walk_speed (0.5 m/s), goal relative to where the heel is now.
  const double x1 = port.positions()[heel];
  ASSERT_TRUE(ctl.walkCommand(false, x1 + 1.0, 50.0));
  for (int k = 0; k < 20; ++k, t += kDt) ASSERT_EQ(ctl.step(t).result, ControlResult::kOk);
  EXPECT_NEAR(port.positions()[heel] - x1, 20 * 0.5 * kDt, 1e-12);
  ASSERT_TRUE(ctl.walkCommand(true, 0.0, 0.0));
  const double x2 = port.positions()[heel];
  for (int k = 0; k < 20; ++k, t += kDt) ctl.step(t);
  EXPECT_EQ(port.positions()[heel], x2) << "stop: the heel stops at once";
}

// ---------------------------------------------------------------- priority

TEST(OnboardPriority, GivenPriorityOrAGraspedObjectsArmAndTheSameVelocitiesAsComputeControl) {
  const Model& model = shippedModel();
  const ControllerModel& cm = defaultControllerModel();
  const Eigen::VectorXd q0 = restConfiguration(model, cm);
  KinematicPort port(q0);
  OnboardController ctl(model, cm, port, q0);
  ControllerData ref(model, cm);  // computeControl directly, the same inputs
  double t = 0.0;
  auto check = [&](MotionPriority expected, const char* what) {
    const Eigen::VectorXd q = port.positions();
    const CycleReport& r = ctl.step(t);
    EXPECT_EQ(r.priority, expected) << what;
    ControlInput in;
    in.hands = crossing();
    in.priority = expected;
    computeControl(model, cm, ref, q, in);
    for (int i = 0; i < model.nq; ++i)
      ASSERT_EQ(ctl.data().qdot[i], ref.qdot[i]) << what << ", joint " << model.q_names[i];
    t += kDt;
  };
  ctl.setHandTargets(crossing(), 0.0);
  for (int k = 0; k < 50; ++k) check(MotionPriority::kEqual, "no priority given");
  ctl.setPriority(MotionPriority::kLeftHigher);
  for (int k = 0; k < 50; ++k) check(MotionPriority::kLeftHigher, "left given");
  ctl.setPriority(MotionPriority::kEqual);
  const std::string cup = "cup", gaze = "gaze";
  const Eigen::Vector3d a(0.0, 0.0, -0.05), b(0.0, 0.0, -0.08);
  // A virtual segment with priority does not count; a grasped object in the right hand does.
  ASSERT_EQ(ctl.changeBodySchema(attachRequest(gaze, "l_hand", a, b, 0.01, true, 1)).kind,
            BodySchemaOutcome::Kind::kAttached);
  ref.dist.slots = ctl.data().dist.slots;  // the reference needs the same slots: mirror them
  for (int k = 0; k < 20; ++k) check(MotionPriority::kEqual, "virtual segment with priority");
  ASSERT_EQ(ctl.changeBodySchema(attachRequest(cup, "r_hand", a, b, 0.01, false, 1)).kind,
            BodySchemaOutcome::Kind::kAttached);
  ref.dist.slots = ctl.data().dist.slots;
  for (int k = 0; k < 50; ++k) check(MotionPriority::kRightHigher, "grasped object in the right hand");
  ctl.setPriority(MotionPriority::kLeftHigher);
  for (int k = 0; k < 20; ++k) check(MotionPriority::kLeftHigher, "a given priority wins over the object's");
}

// ---------------------------------------------------------------- the plant loop and the port

TEST(OnboardPlant, TheSameJointPositionsAsThePreIssue13LoopWithWalking) {
  const Model& model = shippedModel();
  const ControllerModel& cm = defaultControllerModel();
  const Eigen::VectorXd q0 = restConfiguration(model, cm);
  KinematicPort port(q0);
  OnboardController ctl(model, cm, port, q0);
  // The loop reflex_controller ran before the robot port existed, written out.
  ControllerData data(model, cm);
  KinematicRobot robot(model, q0);
  WalkingPattern walking(model);
  Eigen::VectorXd scratch = q0;
  ControlInput in;
  in.hands = crossing();
  ctl.setHandTargets(crossing(), 0.0);
  const int heel = model.qIndex("heel_x");
  ASSERT_TRUE(ctl.walkCommand(false, q0[heel] + 0.3, 0.25));
  walking.start(0.3, 0.25);
  int not_ok = 0;
  double max_f = 0.0;
  for (int k = 0; k < 1200; ++k) {
    const double t = k * kDt;
    if (k % 100 == 0) ctl.setHandTargets(k % 200 == 0 ? crossing() : reachable(), t);
    in.hands = k / 100 % 2 == 0 ? crossing() : reachable();
    ctl.step(t);
    const ControlResult cr = computeControl(model, cm, data, robot.jointPositions(), in);
    not_ok += cr != ControlResult::kOk;
    max_f = std::max({max_f, data.arms[kLeft].f, data.arms[kRight].f});
    stepPlant(model, cm, data, cr, robot, &walking, kDt, scratch);
    for (int i = 0; i < model.nq; ++i)
      ASSERT_EQ(port.positions()[i], robot.jointPositions()[i]) << "cycle " << k << " " << model.q_names[i];
    ASSERT_EQ(ctl.report().result, cr);
  }
  EXPECT_NEAR(port.positions()[heel] - q0[heel], 0.3, 1e-9) << "walked the whole way";
  EXPECT_GT(max_f, 0.5) << "the arms met (avoidance acted)";
  EXPECT_EQ(not_ok, 0);
  EXPECT_EQ(ctl.report().counts.guard_count, data.guard_count);
}

class ScriptedPort final : public RobotPort {
 public:
  explicit ScriptedPort(const Eigen::VectorXd& q) : q_(q), q_end_(q), qdot_(q) {}
  const Eigen::VectorXd* measuredPositions(double) noexcept override { return have_ ? &q_ : nullptr; }
  void command(const Eigen::VectorXd& q_end, const Eigen::VectorXd& qdot, double dt) noexcept override {
    q_end_ = q_end;
    qdot_ = qdot;
    dt_ = dt;
    ++commands_;
  }
  Eigen::VectorXd q_, q_end_, qdot_;
  double dt_ = 0.0;
  bool have_ = false;
  int commands_ = 0;
};

TEST(OnboardPort, NoStateNoCommandAndTheCommandIsMeasuredPlusQdotDt) {
  const Model& model = shippedModel();
  const ControllerModel& cm = defaultControllerModel();
  const Eigen::VectorXd q0 = restConfiguration(model, cm);
  ScriptedPort port(q0);
  OnboardController ctl(model, cm, port, q0);
  ctl.setHandTargets(reachable(), 0.0);
  for (int k = 0; k < 5; ++k) EXPECT_FALSE(ctl.step(k * kDt).robot_state_ok);
  EXPECT_EQ(port.commands_, 0);
  EXPECT_EQ(ctl.report().counts.robot_stale_events, 1U);
  EXPECT_EQ(ctl.report().counts.robot_stale_cycles, 5U);
  port.have_ = true;
  // A measured state that is not where the controller sent the robot (servo lag): it computes from it.
  port.q_ = q0;
  const std::vector<int> driven = drivenJoints(model, cm);
  for (int k = 5; k < 60; ++k) {
    port.q_[cm.arms[kLeft].q[1]] += 0.001;  // the robot drifts
    const Eigen::VectorXd measured = port.q_;
    const CycleReport& r = ctl.step(k * kDt);
    ASSERT_TRUE(r.robot_state_ok);
    ASSERT_EQ(port.dt_, kDt);
    for (int i = 0; i < model.nq; ++i) {
      const bool arm = std::find(driven.begin(), driven.begin() + cm.arms[0].n + cm.arms[1].n, i) !=
                       driven.begin() + cm.arms[0].n + cm.arms[1].n;
      const double v = std::clamp(ctl.data().qdot[i], -model.v_max[i], model.v_max[i]);
      const double expect = arm ? std::clamp(measured[i] + v * kDt, model.q_lower[i], model.q_upper[i]) : measured[i];
      ASSERT_NEAR(port.q_end_[i], expect, 1e-15) << model.q_names[i];
      ASSERT_NEAR(port.qdot_[i], (port.q_end_[i] - measured[i]) / kDt, 1e-9) << model.q_names[i];
      ASSERT_LE(std::abs(port.qdot_[i]), model.v_max[i] * (1.0 + 1e-12)) << model.q_names[i];
    }
    // the robot follows halfway
    port.q_ = measured + 0.5 * (port.q_end_ - measured);
  }
  EXPECT_EQ(port.commands_, 55);
  port.have_ = false;
  EXPECT_FALSE(ctl.step(1.0).robot_state_ok);
  EXPECT_EQ(ctl.report().counts.robot_stale_events, 2U);
  EXPECT_EQ(port.commands_, 55) << "no command without state";
}

TEST(OnboardPort, AShorterCycleCommandsMeasuredPlusQdotTimesItsOwnDtAndWalksAndTracksOverIt) {
  // step(now, dt), a cycle per arriving robot state (reflex_controller --trigger state): with dt = 2 ms
  // the command is measured + qdot dt (qdot within v_max), its velocities (q_end - measured) / dt, so no
  // joint is asked to cover more than v_max dt; the heel walks speed x dt per cycle (the analytic travel)
  // and the trajectory's reference advances trajectory_speed x dt (ControllerParams). A dt outside
  // (0, period] is one period, bit-identical to step(now).
  const Model& model = shippedModel();
  const ControllerModel& cm = defaultControllerModel();
  const double period = cm.params.period;
  const double dt = 0.002;
  const Eigen::VectorXd q0 = restConfiguration(model, cm);
  ScriptedPort port(q0);
  port.have_ = true;
  OnboardController ctl(model, cm, port, q0);
  ctl.setHandTargets(crossing(), 0.0);
  const int heel = model.qIndex("heel_x");
  ASSERT_GE(heel, 0);
  const double speed = 0.2;
  ASSERT_TRUE(ctl.walkCommand(false, q0[heel] + 0.5, speed));
  double worst_ratio = 0.0;  // max |q_end - measured| / (v_max dt) over the arm joints
  Eigen::Vector3d ref_before = Eigen::Vector3d::Zero();
  for (int k = 0; k < 200; ++k) {
    const Eigen::VectorXd measured = port.q_;
    const double heel_before = ctl.commandedPositions()[heel];
    const CycleReport& r = ctl.step(k * dt, dt);
    ASSERT_TRUE(r.robot_state_ok);
    ASSERT_EQ(port.dt_, dt);
    for (const int i : ctl.drivenJoints()) {
      ASSERT_LE(std::abs(port.qdot_[i]), model.v_max[i] * (1.0 + 1e-12)) << model.q_names[i];
      if (model.q_names[i] == "heel_x" || !ctl.data().arm_joint[static_cast<std::size_t>(i)]) continue;
      ASSERT_NEAR(port.qdot_[i], (port.q_end_[i] - measured[i]) / dt, 1e-9) << model.q_names[i];
      ASSERT_LE(std::abs(port.q_end_[i] - measured[i]), model.v_max[i] * dt * (1.0 + 1e-12)) << model.q_names[i];
      worst_ratio = std::max(worst_ratio, std::abs(port.q_end_[i] - measured[i]) / (model.v_max[i] * dt));
    }
    if (r.result == ControlResult::kOk && r.walking_advanced) {
      ASSERT_NEAR(port.q_end_[heel] - heel_before, speed * dt, 1e-12) << "cycle " << k;
    }
    // The reference of the left arm, while far from its goal, advances trajectory_speed x dt.
    const Eigen::Vector3d ref = ctl.data().arms[kLeft].reference_B;
    if (k >= 1 && k <= 10) {
      ASSERT_NEAR((ref - ref_before).norm(), cm.params.trajectory_speed * dt, 1e-12) << "cycle " << k;
    }
    ref_before = ref;
    port.q_ = port.q_end_;  // the robot is where it was sent at the next state
  }
  std::printf("2 ms cycles: the largest arm step is %.3f of v_max x dt\n", worst_ratio);
  EXPECT_GT(worst_ratio, 0.5) << "the arms moved fast enough for the bound to matter";
  // Out of range: one period, exactly as step(now).
  for (const double bad : {0.0, -0.001, std::nan(""), 2.0 * period, std::numeric_limits<double>::infinity()}) {
    ScriptedPort pa(q0), pb(q0);
    pa.have_ = pb.have_ = true;
    OnboardController a(model, cm, pa, q0), b(model, cm, pb, q0);
    a.setHandTargets(crossing(), 0.0);
    b.setHandTargets(crossing(), 0.0);
    for (int k = 0; k < 20; ++k) {
      a.step(k * period, bad);
      b.step(k * period);
      pa.q_ = pa.q_end_;
      pb.q_ = pb.q_end_;
    }
    EXPECT_EQ(pa.dt_, period) << "dt " << bad;
    for (int i = 0; i < model.nq; ++i) ASSERT_EQ(pa.q_end_[i], pb.q_end_[i]) << "dt " << bad << " " << model.q_names[i];
  }
}

TEST(OnboardSetup, BadOptionsAndInitialConfigurationsAreNamed) {
  const Model& model = shippedModel();
  const ControllerModel& cm = defaultControllerModel();
  const Eigen::VectorXd q0 = restConfiguration(model, cm);
  KinematicPort port(q0);
  OnboardOptions o;
  o.input_timeout = 0.0;
  try {
    OnboardController c(model, cm, port, q0, o);
    ADD_FAILURE() << "accepted input_timeout 0";
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("input_timeout = 0"), std::string::npos) << e.what();
  }
  Eigen::VectorXd bad = q0;
  bad[3] = std::nan("");
  try {
    OnboardController c(model, cm, port, bad);
    ADD_FAILURE() << "accepted a NaN initial position";
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("'" + model.q_names[3] + "'"), std::string::npos) << e.what();
  }
  EXPECT_THROW(OnboardController(model, cm, port, Eigen::VectorXd::Zero(3)), ConfigError);
}

}  // namespace
// ---------------------------------------------------------------- rejections and closest names

TEST(OnboardRejections, OneCounterPerCauseAtTheBoundsAndTheLatestCauseNamed) {
  const Model& model = shippedModel();
  const ControllerModel& cm = defaultControllerModel();
  const Eigen::VectorXd q0 = restConfiguration(model, cm);
  KinematicPort port(q0);
  OnboardController ctl(model, cm, port, q0);
  auto count = [&](RejectCause c) { return ctl.report().counts.rejected[static_cast<std::size_t>(c)]; };
  auto last = [&] { return ctl.report().counts.last_rejection; };
  EXPECT_EQ(last(), -1) << "nothing refused yet";
  // Hands: at exactly max_target_distance accepted, the next double beyond it refused; NaN refused.
  std::array<HandCommand, 2> hands = reachable();
  hands[kLeft].target_B = Eigen::Vector3d(2.0, 0.0, 0.0);  // |t| = 2 m = max_target_distance: followed
  hands[kRight].target_B = Eigen::Vector3d(std::nextafter(2.0, 3.0), 0.0, 0.0);
  EXPECT_EQ(ctl.setHandTargets(hands, 0.0), 1);
  EXPECT_EQ(count(RejectCause::kHandTargetTooFar), 1U);
  EXPECT_EQ(last(), static_cast<int>(RejectCause::kHandTargetTooFar));
  hands[kRight].target_B.z() = std::nan("");
  EXPECT_EQ(ctl.setHandTargets(hands, 0.0), 1);
  EXPECT_EQ(count(RejectCause::kHandTargetNotFinite), 1U);
  EXPECT_EQ(count(RejectCause::kHandTargetTooFar), 1U) << "a NaN target is its own cause";
  EXPECT_EQ(last(), static_cast<int>(RejectCause::kHandTargetNotFinite));
  // Walking: goal_y / goal_yaw within kWalkGoalTolerance are 0; beyond it (or NaN) the goal is refused whole.
  const int heel = model.qIndex("heel_x");
  ASSERT_GE(heel, 0);
  EXPECT_FALSE(ctl.walkCommand(false, q0[heel] + 0.5, std::nextafter(kWalkGoalTolerance, 1.0), 0.0, 0.2));
  EXPECT_FALSE(ctl.walkCommand(false, q0[heel] + 0.5, 0.0, -0.3, 0.2));
  EXPECT_FALSE(ctl.walkCommand(false, q0[heel] + 0.5, 0.0, std::nan(""), 0.2));
  EXPECT_EQ(count(RejectCause::kWalkUnsupportedGoal), 3U);
  EXPECT_EQ(last(), static_cast<int>(RejectCause::kWalkUnsupportedGoal));
  EXPECT_STREQ(rejectCauseName(RejectCause::kWalkUnsupportedGoal), "walk_goal_y_or_yaw_not_zero");
  EXPECT_FALSE(ctl.walkCommand(false, q0[heel] + 0.5, 0.0, 0.0, -0.2));
  EXPECT_EQ(count(RejectCause::kWalkBadValue), 1U);
  ctl.setHandTargets(reachable(), 0.0);  // ordinary targets for the cycles below
  for (int k = 0; k < 20; ++k) ctl.step(kDt * k);
  EXPECT_EQ(port.positions()[heel], q0[heel]) << "a refused goal is not walked, not even along x";
  EXPECT_TRUE(ctl.walkCommand(true, 0.0, 5.0, 5.0, 0.0)) << "a stop ignores its goal";
  ASSERT_TRUE(ctl.walkCommand(false, q0[heel] + 0.5, -kWalkGoalTolerance, kWalkGoalTolerance, 0.2));
  double t = 0.1;
  for (int k = 0; k < 20; ++k, t += kDt) ctl.step(t);
  EXPECT_GT(port.positions()[heel], q0[heel]) << "goal_y / goal_yaw at the tolerance walk along x";
  // Body schema: a segment beyond BodySchemaLimits (radius 10 m) is its own cause.
  const std::string big = "big";
  const Eigen::Vector3d p(0.3, 0.0, 1.5);
  EXPECT_EQ(ctl.changeBodySchema(attachRequest(big, "world", p, p, 10.0)).kind,
            BodySchemaOutcome::Kind::kRejectedCheck);
  EXPECT_EQ(count(RejectCause::kSchemaBadSegment), 1U);
  EXPECT_EQ(last(), static_cast<int>(RejectCause::kSchemaBadSegment));
  // The groups are the causes summed; the total is every refusal.
  const OnboardCounts& c = ctl.report().counts;
  EXPECT_EQ(c.hand_targets_rejected, 2U);
  EXPECT_EQ(c.walk_rejected, 4U);
  EXPECT_EQ(c.schema_rejected, 1U);
  EXPECT_EQ(c.targets_rejected, 7U);
  EXPECT_EQ(c.targets_received, 3U);
  std::uint64_t sum = 0;
  for (const std::uint64_t n : c.rejected) sum += n;
  EXPECT_EQ(sum, c.targets_rejected);
}

TEST(OnboardClosestPair, SegmentAIsTheArmsOwnSegment) {
  const Model& model = shippedModel();
  const ControllerModel& cm = defaultControllerModel();
  const Eigen::VectorXd q0 = restConfiguration(model, cm);
  KinematicPort port(q0);
  OnboardController ctl(model, cm, port, q0);
  ctl.setHandTargets(crossing(), 0.0);
  // The shipped robot names its segments by side: l_* move with the left arm, r_* with the right one.
  const char* own[2] = {"l_", "r_"};
  int arm_pairs = 0, named = 0, reordered = 0;
  double t = 0.0;
  for (int k = 0; k < 800; ++k, t += kDt) {  // 4 s: the forearms meet in front of the chest
    ctl.noteSourceHeartbeat(t);
    const CycleReport& r = ctl.step(t);
    for (int a = 0; a < 2; ++a) {
      const ArmReport& ar = r.arms[static_cast<std::size_t>(a)];
      ASSERT_EQ(ar.closest_pair < 0, ar.segment_a == nullptr);
      ASSERT_EQ(ar.closest_pair < 0, ar.segment_b == nullptr);
      if (ar.closest_pair < 0) continue;
      ++named;
      const std::string seg_a = ar.segment_a, seg_b = ar.segment_b;
      ASSERT_EQ(seg_a.rfind(own[a], 0), 0U) << "arm " << a << " closest " << seg_a << " / " << seg_b;
      // Against the model's pair: the same two segments, in either order.
      const SegmentPair& pair = model.pairs[static_cast<std::size_t>(ar.closest_pair)];
      const std::string pa = model.segments[pair.a].name, pb = model.segments[pair.b].name;
      ASSERT_TRUE((seg_a == pa && seg_b == pb) || (seg_a == pb && seg_b == pa)) << seg_a << " / " << seg_b;
      if (seg_b.rfind(own[1 - a], 0) == 0) ++arm_pairs;
      if (pa.rfind(own[1 - a], 0) == 0) {  // the model lists the other arm's segment first
        ++reordered;
        EXPECT_EQ(seg_a, pb);
      }
    }
  }
  EXPECT_GT(named, 0);
  EXPECT_GT(arm_pairs, 100) << "the arms were each other's closest pair for a while (crossing)";
  EXPECT_GT(reordered, 0) << "a pair whose first segment is the other arm's was reported (the case the order fixes)";
}

}  // namespace reflex::control
