// Pointing module (paper Sec. 8.4) with fake inputs: geometry against hand-computed answers,
// assignment stability while objects cross (and a naive rule that does flip-flop on the same data),
// lost-target timing, the priority rules, and what stop removes.
#include "modules_test_support.hpp"

#include <reflex/modules/pointing.hpp>

#include <cmath>
#include <cstdio>
#include <random>

namespace reflex::modules {
namespace {

using testing::at;
using testing::frameAt;
using testing::object;
using testing::TestHost;

std::string pointingConfig(const std::string& extra) {
  return "inputs: {known_objects: [cup, can, ball]}\n"
         "modules:\n"
         "  - name: pointing\n"
         "    type: pointing\n"
         "    config: {" +
         extra + "}\n";
}

// ---------------------------------------------------------------- geometry (analytic)

TEST(PointingTarget, RayModeIsOnTheShoulderObjectRayAtTheConfiguredDistance) {
  const Eigen::Vector3d s(0.0, -0.23, 1.04);
  const Eigen::Vector3d o = s + Eigen::Vector3d(0.8, 0.0, 0.6);  // |o - s| = 1, direction (0.8, 0, 0.6)
  const auto t = pointingTarget(s, o, PointingMode::kRay, 0.4, 0.48);
  ASSERT_TRUE(t.has_value());
  EXPECT_NEAR(t->x(), 0.32, 1e-12);
  EXPECT_NEAR(t->y(), -0.23, 1e-12);
  EXPECT_NEAR(t->z(), 1.04 + 0.24, 1e-12);
  // Also when the object is nearer than ray_distance: still on the ray, at ray_distance.
  const auto near = pointingTarget(s, s + Eigen::Vector3d(0.0, 0.0, -0.1), PointingMode::kRay, 0.4, 0.48);
  ASSERT_TRUE(near.has_value());
  EXPECT_NEAR((*near - Eigen::Vector3d(0.0, -0.23, 0.64)).norm(), 0.0, 1e-12);
}

TEST(PointingTarget, ObjectModeIsTheObjectWithinReachElseOnTheRayAtReach) {
  const Eigen::Vector3d s(0.0, 0.23, 1.04);
  const Eigen::Vector3d beyond = s + Eigen::Vector3d(0.3, 0.0, -0.4);  // 0.5 away: beyond 0.48
  const Eigen::Vector3d within = s + Eigen::Vector3d(0.3, 0.0, 0.0);   // 0.3 away
  const auto a = pointingTarget(s, within, PointingMode::kObject, 0.4, 0.48);
  ASSERT_TRUE(a.has_value());
  EXPECT_EQ(*a, within);
  const auto b = pointingTarget(s, beyond, PointingMode::kObject, 0.4, 0.48);
  ASSERT_TRUE(b.has_value());
  // (0.3, 0, -0.4) has length 0.5: the target is 0.48 along it.
  EXPECT_NEAR((*b - (s + 0.48 * Eigen::Vector3d(0.6, 0.0, -0.8))).norm(), 0.0, 1e-12);
}

TEST(PointingTarget, ObjectAtTheShoulderHasNoDirection) {
  const Eigen::Vector3d s(0.0, 0.23, 1.04);
  EXPECT_FALSE(pointingTarget(s, s, PointingMode::kRay, 0.4, 0.48).has_value());
  EXPECT_FALSE(pointingTarget(s, s, PointingMode::kObject, 0.4, 0.48).has_value());
}

TEST(PointingRobot, ShouldersAndReachMatchTheRobotDescription) {
  TestHost h(pointingConfig(""));
  // asimo_like.urdf: chest at 0.88 m, shoulders 0.16 above it and 0.23 to the side; arm 0.22 + 0.20
  // + hand point 0.06 (controller's hand_point).
  EXPECT_NEAR((testing::shoulder(*h.host, Hand::kLeft) - Eigen::Vector3d(0.0, 0.23, 1.04)).norm(), 0.0, 0.01);
  EXPECT_NEAR((testing::shoulder(*h.host, Hand::kRight) - Eigen::Vector3d(0.0, -0.23, 1.04)).norm(), 0.0, 0.01);
  EXPECT_NEAR(h->robot().armReach(Hand::kLeft), 0.48, 1e-9);
  EXPECT_NEAR(h->robot().armReach(Hand::kRight), 0.48, 1e-9);
}

TEST(Pointing, HandTargetsPointAtTheirObjectsOnTheRay) {
  TestHost h(pointingConfig("mode: ray, ray_distance: 0.35"));
  h->start(at(0.0));
  const Eigen::Vector3d cup(0.46, -0.13, 0.95), can(0.46, 0.13, 0.96);
  h->onObjects(frameAt(0.1, {object("cup", cup), object("can", can)}), at(0.1));
  const HandTarget& r = h->hand(Hand::kRight);
  const HandTarget& l = h->hand(Hand::kLeft);
  ASSERT_TRUE(r.given && l.given);
  EXPECT_EQ(r.object, "cup");  // cup on the robot's right -> right hand
  EXPECT_EQ(l.object, "can");
  for (auto [hand, obj] : {std::pair{Hand::kRight, cup}, std::pair{Hand::kLeft, can}}) {
    const Eigen::Vector3d s = testing::shoulder(*h.host, hand);
    const Eigen::Vector3d t = h->hand(hand).p_B;
    EXPECT_NEAR((t - s).norm(), 0.35, 1e-12);
    EXPECT_NEAR((t - s).cross(obj - s).norm(), 0.0, 1e-12);  // collinear
    EXPECT_GT((t - s).dot(obj - s), 0.0);                    // same direction
  }
}

TEST(Pointing, ObjectModeGivesTheObjectWhenWithinReach) {
  TestHost h(pointingConfig("mode: object, reach: 0.45"));
  h->start(at(0.0));
  const Eigen::Vector3d sr = testing::shoulder(*h.host, Hand::kRight);
  const Eigen::Vector3d cup = sr + Eigen::Vector3d(0.40, 0.05, -0.05);  // 0.406 m away
  const Eigen::Vector3d sl = testing::shoulder(*h.host, Hand::kLeft);
  const Eigen::Vector3d can = sl + Eigen::Vector3d(0.6, 0.0, 0.0);  // 0.6 m away: beyond reach
  h->onObjects(frameAt(0.1, {object("cup", cup), object("can", can)}), at(0.1));
  EXPECT_EQ(h->hand(Hand::kRight).p_B, cup);
  EXPECT_NEAR((h->hand(Hand::kLeft).p_B - (sl + Eigen::Vector3d(0.45, 0.0, 0.0))).norm(), 0.0, 1e-12);
}

// ---------------------------------------------------------------- assignment stability

struct Crossing {
  int changes[2] = {0, 0};  // object changes per hand between consecutive given targets
  std::string first[2];
};

Crossing countChanges(const testing::RecordingSink& sink) {
  Crossing c;
  std::string last[2];
  for (const auto& hs : sink.hands) {
    const HandTarget* t[2] = {&hs.left, &hs.right};
    for (int i = 0; i < 2; ++i) {
      if (!t[i]->given) continue;
      if (c.first[i].empty()) c.first[i] = t[i]->object;
      if (!last[i].empty() && last[i] != t[i]->object) ++c.changes[i];
      last[i] = t[i]->object;
    }
  }
  return c;
}

// The flagship's crossing (bringup/sessions/flagship/scene.yaml, 40-52 s): the cup goes from the
// robot's right to its left, the can the other way, passing 4.5 cm apart in front of the chest; then
// they wiggle back and forth across the middle several times. 10 Hz, 5 mm detection noise.
void feedCrossing(TestHost& h, double t0) {
  std::mt19937 rng(7);
  std::normal_distribution<double> noise(0.0, 0.005);
  auto n = [&] { return Eigen::Vector3d(noise(rng), noise(rng), noise(rng)); };
  double t = t0;
  for (int k = 0; k <= 120; ++k, t += 0.1) {  // 12 s: cross completely
    const double a = k / 120.0;
    const Eigen::Vector3d cup(0.43, -0.13 + 0.26 * a, 0.97), can(0.465, 0.13 - 0.26 * a, 0.95);
    h->onObjects(frameAt(t, {object("cup", cup + n()), object("can", can + n())}), at(t));
    h->tick(at(t + 0.05));
  }
  for (int k = 0; k <= 200; ++k, t += 0.1) {  // 20 s: wiggle across the middle, period 2 s
    const double y = 0.06 * std::sin(2.0 * M_PI * k / 20.0);
    const Eigen::Vector3d cup(0.43, y, 0.97), can(0.465, -y, 0.95);
    h->onObjects(frameAt(t, {object("cup", cup + n()), object("can", can + n())}), at(t));
    h->tick(at(t + 0.05));
  }
}

TEST(PointingAssignment, StickyNeverSwapsWhileObjectsCross) {
  TestHost h(pointingConfig("assignment: sticky"));
  h->start(at(0.0));
  h->onObjects(frameAt(0.0, {object("cup", {0.43, -0.13, 0.97}), object("can", {0.465, 0.13, 0.95})}), at(0.0));
  feedCrossing(h, 0.1);
  const Crossing c = countChanges(h.sink);
  EXPECT_EQ(c.first[1], "cup");
  EXPECT_EQ(c.first[0], "can");
  EXPECT_EQ(c.changes[0], 0);
  EXPECT_EQ(c.changes[1], 0);
  EXPECT_EQ(h->hand(Hand::kRight).object, "cup");
  EXPECT_EQ(h->hand(Hand::kLeft).object, "can");
}

TEST(PointingAssignment, NearestWithHysteresisSwapsOnceNaiveRuleFlipFlops) {
  // Positive control: without margin and hold the same data makes the hands flip-flop.
  TestHost naive(pointingConfig("assignment: nearest, swap_margin: 0.0, swap_hold: 0.0"));
  naive->start(at(0.0));
  feedCrossing(naive, 0.0);
  const Crossing cn = countChanges(naive.sink);
  EXPECT_GE(cn.changes[1], 10) << "the scenario must provoke flip-flopping without hysteresis";
  std::printf("naive rule (no margin, no hold): %d right-hand object changes\n", cn.changes[1]);

  TestHost h(pointingConfig("assignment: nearest, swap_margin: 0.10, swap_hold: 1.0"));
  h->start(at(0.0));
  feedCrossing(h, 0.0);
  const Crossing c = countChanges(h.sink);
  // Exactly one swap: when the objects have fully crossed (cost better by > 0.10 m for 1 s); the
  // wiggle around the middle (at most 0.06 m aside) never reaches the margin.
  EXPECT_EQ(c.changes[0], 1);
  EXPECT_EQ(c.changes[1], 1);
  EXPECT_EQ(h->hand(Hand::kRight).object, "can");
}

// ---------------------------------------------------------------- lost targets

TEST(PointingLost, HandGetsNoTargetAfterLostTimeoutAndPointsAgainWhenSeen) {
  TestHost h(pointingConfig("lost_timeout: 1.0, step_period: 0.05"));
  h->start(at(0.0));
  const Eigen::Vector3d cup(0.46, -0.13, 0.95), can(0.46, 0.13, 0.96);
  double t = 0.0;
  double left_none_at = -1.0, left_back_at = -1.0;
  const double last_can = 4.9;
  for (; t < 10.0; t += 0.01) {
    const int k = static_cast<int>(std::lround(t * 100.0));
    if (k % 10 == 0) {  // 10 Hz frames; the can is hidden between 5 s and 8 s
      std::vector<ObjectObservation> objs{object("cup", cup)};
      if (t < 5.0 - 1e-9 || t > 8.0 - 1e-9) objs.push_back(object("can", can));
      h->onObjects(frameAt(t, objs), at(t));
    }
    if (k % 2 == 0) h->tick(at(t));  // 50 Hz timer
    const bool given = h->hand(Hand::kLeft).given;
    if (t > 5.0 && !given && left_none_at < 0.0) left_none_at = t;
    if (left_none_at > 0.0 && given && left_back_at < 0.0) left_back_at = t;
    if (t > 1.0 && t < 5.0 + 0.9) {
      ASSERT_TRUE(given) << "t = " << t;  // still held during a loss shorter than the timeout
    }
    ASSERT_TRUE(h->hand(Hand::kRight).given) << "the cup is never lost, t = " << t;
  }
  // Off no earlier than the timeout and at most one step period (+ one tick) later.
  EXPECT_GT(left_none_at, last_can + 1.0);
  EXPECT_LE(left_none_at, last_can + 1.0 + 0.05 + 0.02 + 1e-9);
  EXPECT_NEAR(left_back_at, 8.0, 1e-6);
  EXPECT_EQ(h->hand(Hand::kLeft).object, "can");
}

TEST(PointingLost, VisionSilentTurnsBothHandsOffByTheTimer) {
  TestHost h(pointingConfig("lost_timeout: 0.5"));
  h->start(at(0.0));
  h->onObjects(frameAt(0.0, {object("cup", {0.46, -0.13, 0.95}), object("can", {0.46, 0.13, 0.96})}), at(0.0));
  ASSERT_TRUE(h->hand(Hand::kLeft).given && h->hand(Hand::kRight).given);
  for (double t = 0.02; t <= 0.48; t += 0.02) h->tick(at(t));
  EXPECT_TRUE(h->hand(Hand::kLeft).given && h->hand(Hand::kRight).given);
  for (double t = 0.5; t <= 0.7; t += 0.02) h->tick(at(t));
  EXPECT_FALSE(h->hand(Hand::kLeft).given);
  EXPECT_FALSE(h->hand(Hand::kRight).given);
  EXPECT_EQ(h->priority(), ArmPriority::kEqual);
}

TEST(Pointing, LowConfidenceAndFilteredObjectsAreNotPointedAt) {
  TestHost h(pointingConfig("objects: [cup, can], min_confidence: 0.5"));
  h->start(at(0.0));
  h->onObjects(frameAt(0.0, {object("cup", {0.46, -0.13, 0.95}, 0.4), object("ball", {0.46, 0.13, 0.96})}), at(0.0));
  EXPECT_FALSE(h->hand(Hand::kLeft).given);
  EXPECT_FALSE(h->hand(Hand::kRight).given);
  h->onObjects(frameAt(0.1, {object("cup", {0.46, -0.13, 0.95}, 0.6)}), at(0.1));
  EXPECT_TRUE(h->hand(Hand::kRight).given);
}

TEST(Pointing, OneObjectGoesToTheNearerShoulderAndOneHandOnlyUsesThatHand) {
  TestHost h(pointingConfig(""));
  h->start(at(0.0));
  h->onObjects(frameAt(0.0, {object("can", {0.46, 0.13, 0.96})}), at(0.0));
  EXPECT_TRUE(h->hand(Hand::kLeft).given);
  EXPECT_FALSE(h->hand(Hand::kRight).given);

  TestHost r(pointingConfig("hands: [right]"));
  EXPECT_FALSE(r->claims().hands[0]);
  r->start(at(0.0));
  r->onObjects(frameAt(0.0, {object("can", {0.46, 0.13, 0.96})}), at(0.0));
  EXPECT_EQ(r->hand(Hand::kRight).object, "can");
  EXPECT_FALSE(r->hand(Hand::kLeft).given);
}

// ---------------------------------------------------------------- priority rules

TEST(PointingPriority, FirstAssignedHandIsHigher) {
  TestHost h(pointingConfig("priority_rule: first_assigned, lost_timeout: 0.5"));
  h->start(at(0.0));
  EXPECT_EQ(h->priority(), ArmPriority::kEqual);
  const Eigen::Vector3d cup(0.46, -0.13, 0.95), can(0.46, 0.13, 0.96);
  h->onObjects(frameAt(0.0, {object("cup", cup)}), at(0.0));
  EXPECT_EQ(h->priority(), ArmPriority::kRightHigher);  // only the right hand has a target
  h->onObjects(frameAt(1.0, {object("cup", cup), object("can", can)}), at(1.0));
  EXPECT_EQ(h->priority(), ArmPriority::kRightHigher);  // the right hand was assigned first
  h->onObjects(frameAt(1.2, {object("can", can)}), at(1.2));
  h->onObjects(frameAt(1.8, {object("can", can)}), at(1.8));  // cup lost (> 0.5 s)
  EXPECT_FALSE(h->hand(Hand::kRight).given);
  EXPECT_EQ(h->priority(), ArmPriority::kLeftHigher);
  h->onObjects(frameAt(2.0, {object("cup", cup), object("can", can)}), at(2.0));
  EXPECT_EQ(h->priority(), ArmPriority::kLeftHigher);  // now the left hand has had its object longer
}

TEST(PointingPriority, SameFrameUsesTheTieHand) {
  TestHost h(pointingConfig("priority_rule: first_assigned, priority_tie: left"));
  h->start(at(0.0));
  h->onObjects(frameAt(0.0, {object("cup", {0.46, -0.13, 0.95}), object("can", {0.46, 0.13, 0.96})}), at(0.0));
  EXPECT_EQ(h->priority(), ArmPriority::kLeftHigher);
}

TEST(PointingPriority, NearerObjectWithHysteresis) {
  TestHost h(pointingConfig("priority_rule: nearer_object, priority_margin: 0.03"));
  h->start(at(0.0));
  const Eigen::Vector3d sl = testing::shoulder(*h.host, Hand::kLeft), sr = testing::shoulder(*h.host, Hand::kRight);
  const Eigen::Vector3d fwd(1.0, 0.0, 0.0);
  auto feed = [&](double t, double dl, double dr) {
    h->onObjects(frameAt(t, {object("can", sl + dl * fwd), object("cup", sr + dr * fwd)}), at(t));
  };
  feed(0.0, 0.40, 0.45);
  EXPECT_EQ(h->priority(), ArmPriority::kLeftHigher);
  feed(0.1, 0.40, 0.39);  // right nearer by 0.01 < margin: no switch
  EXPECT_EQ(h->priority(), ArmPriority::kLeftHigher);
  feed(0.2, 0.40, 0.36);  // nearer by 0.04 > margin
  EXPECT_EQ(h->priority(), ArmPriority::kRightHigher);
  feed(0.3, 0.38, 0.36);  // left nearer? no: 0.38 > 0.36
  EXPECT_EQ(h->priority(), ArmPriority::kRightHigher);
  EXPECT_EQ(h.sink.priorities.size(), 3u);  // equal at start, left, right: published on change only
}

TEST(PointingPriority, FixedAndNoneRules) {
  const Eigen::Vector3d cup(0.46, -0.13, 0.95), can(0.46, 0.13, 0.96);
  for (auto [rule, want] : {std::pair{"left", ArmPriority::kLeftHigher}, std::pair{"right", ArmPriority::kRightHigher},
                            std::pair{"equal", ArmPriority::kEqual}}) {
    TestHost h(pointingConfig(std::string("priority_rule: ") + rule));
    h->start(at(0.0));
    h->onObjects(frameAt(0.0, {object("cup", cup), object("can", can)}), at(0.0));
    EXPECT_EQ(h->priority(), want) << rule;
  }
  TestHost none(pointingConfig("priority_rule: none"));
  EXPECT_FALSE(none->claims().priority);
  none->start(at(0.0));
  none->onObjects(frameAt(0.0, {object("cup", cup), object("can", can)}), at(0.0));
  EXPECT_TRUE(none.sink.priorities.empty());
}

// ---------------------------------------------------------------- stop

TEST(PointingStop, RemovesHandTargetsAndPriority) {
  TestHost h(pointingConfig("priority_rule: first_assigned"));
  h->start(at(0.0));
  h->onObjects(frameAt(0.0, {object("cup", {0.46, -0.13, 0.95}), object("can", {0.46, 0.13, 0.96})}), at(0.0));
  ASSERT_TRUE(h.sink.hands.back().left.given && h.sink.hands.back().right.given);
  ASSERT_NE(h.sink.priorities.back(), ArmPriority::kEqual);
  h->stop(at(1.0));
  EXPECT_FALSE(h.sink.hands.back().left.given);
  EXPECT_FALSE(h.sink.hands.back().right.given);
  EXPECT_EQ(h.sink.priorities.back(), ArmPriority::kEqual);
  EXPECT_EQ(h->stats().forced_cleanups, 0u);  // the module removed it itself
  // After stop, inputs are ignored.
  h->onObjects(frameAt(1.1, {object("cup", {0.46, -0.13, 0.95})}), at(1.1));
  EXPECT_FALSE(h.sink.hands.back().right.given);
}

}  // namespace
}  // namespace reflex::modules
