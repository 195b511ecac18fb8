// Grasped bar, occlusion and walking modules with fake inputs: the segments they attach (frames,
// endpoints against hand-computed geometry), switching, motion priority, and what stop removes.
#include "modules_test_support.hpp"

#include <reflex/modules/body_schema.hpp>

#include <cmath>

namespace reflex::modules {
namespace {

using testing::at;
using testing::frameAt;
using testing::object;
using testing::TestHost;

TEST(GraspedBar, AttachesTheBarToTheHandWithItsPriorityAndDetachesAtStop) {
  TestHost h(
      "modules:\n  - {name: bar, type: grasped_bar, config: {hand: left, point_a: [0, -0.15, -0.06], "
      "point_b: [0, 0.15, -0.06], radius: 0.02, motion_priority: 3}}\n");
  EXPECT_EQ(h->claims().segments, std::vector<std::string>{"grasped_bar"});
  EXPECT_FALSE(h->claims().priority);
  h->start(at(0.0));
  ASSERT_EQ(h.sink.attached.size(), 1u);
  const SegmentSpec& s = h.sink.attached[0];
  EXPECT_EQ(s.name, "grasped_bar");
  EXPECT_EQ(s.parent_link, "l_hand");
  EXPECT_TRUE(s.capsule);
  EXPECT_FALSE(s.virtual_segment);
  EXPECT_TRUE(s.enabled);
  EXPECT_EQ(s.a_L, Eigen::Vector3d(0, -0.15, -0.06));
  EXPECT_EQ(s.b_L, Eigen::Vector3d(0, 0.15, -0.06));
  EXPECT_DOUBLE_EQ(s.radius, 0.02);
  EXPECT_EQ(s.motion_priority, 3);
  for (double t = 0.1; t < 1.0; t += 0.1) h->tick(at(t));
  EXPECT_EQ(h.sink.attached.size(), 1u);  // no spin: unchanged, not republished
  h->stop(at(1.0));
  EXPECT_EQ(h.sink.events.back(), "detach:grasped_bar");
  EXPECT_TRUE(h->segments().empty());
  EXPECT_EQ(h->stats().forced_cleanups, 0u);
}

TEST(GraspedBar, SpinsAboutItsAxisThroughTheCentre) {
  TestHost h(
      "modules:\n  - {name: bar, type: grasped_bar, config: {hand: right, point_a: [0, -0.15, -0.06], "
      "point_b: [0, 0.15, -0.06], spin_rate: 1.5707963267948966, spin_axis: [1, 0, 0], "
      "spin_center: [0, 0, -0.06], update_period: 0.1}}\n");
  h->start(at(0.0));
  for (int k = 1; k <= 10; ++k) h->tick(at(0.1 * k));
  const SegmentSpec& s = h->segments().at("grasped_bar");
  EXPECT_EQ(s.parent_link, "r_hand");
  // After 1 s at pi/2 rad/s about x: (0, -0.15, 0) from the centre turns to (0, 0, -0.15).
  EXPECT_NEAR((s.a_L - Eigen::Vector3d(0.0, 0.0, -0.06 - 0.15)).norm(), 0.0, 1e-9);
  EXPECT_NEAR((s.b_L - Eigen::Vector3d(0.0, 0.0, -0.06 + 0.15)).norm(), 0.0, 1e-9);
  EXPECT_NEAR((s.a_L - s.b_L).norm(), 0.30, 1e-12);  // a rigid bar
}

TEST(GraspedBar, TimedAttachDetachAndArmPriority) {
  TestHost h(
      "modules:\n  - {name: bar, type: grasped_bar, config: {hand: left, attach_after: 1.0, detach_after: 2.0, "
      "update_period: 0.05, arm_priority: true}}\n");
  EXPECT_TRUE(h->claims().priority);
  h->start(at(0.0));
  double attached_at = -1.0, detached_at = -1.0;
  for (int k = 1; k <= 60; ++k) {
    const double t = 0.05 * k;
    h->tick(at(t));
    const bool on = h->segments().count("grasped_bar") > 0;
    if (on && attached_at < 0.0) attached_at = t;
    if (!on && attached_at > 0.0 && detached_at < 0.0) detached_at = t;
    if (on)
      EXPECT_EQ(h->priority(), ArmPriority::kLeftHigher);
    else
      EXPECT_EQ(h->priority(), ArmPriority::kEqual);
  }
  EXPECT_NEAR(attached_at, 1.0, 0.05 + 1e-9);
  EXPECT_NEAR(detached_at, 2.0, 0.05 + 1e-9);
}

// Occlusion: the capsule in the head frame, mapped back to the base frame, runs from the camera
// towards the target and ends end_margin before it.
void expectGazeLine(const BehaviorHost& host, const SegmentSpec& s, const Eigen::Vector3d& target_B, double margin) {
  const RobotState& r = host.robot();
  EXPECT_EQ(s.parent_link, "head");
  EXPECT_TRUE(s.virtual_segment);
  const Eigen::Vector3d a_B = r.X_B_head() * s.a_L, b_B = r.X_B_head() * s.b_L;
  const Eigen::Vector3d cam = r.camera_B();
  EXPECT_NEAR((a_B - cam).norm(), 0.0, 1e-9);
  EXPECT_NEAR((b_B - target_B).norm(), margin, 1e-9);
  EXPECT_NEAR((b_B - cam).cross(target_B - cam).norm(), 0.0, 1e-9);
  EXPECT_GT((b_B - cam).dot(target_B - cam), 0.0);
}

TEST(Occlusion, CapsuleFromTheHeadCameraToAFixedPointFollowsTheHead) {
  TestHost h(
      "modules:\n  - {name: eyes, type: occlusion, config: {point: [0.5, -0.02, 0.85], radius: 0.03, "
      "end_margin: 0.1, min_change: 0.001}}\n");
  EXPECT_FALSE(h->claims().objects);
  h->start(at(0.0));
  ASSERT_EQ(h.sink.attached.size(), 1u);
  EXPECT_TRUE(h.sink.attached[0].enabled);
  EXPECT_DOUBLE_EQ(h.sink.attached[0].radius, 0.03);
  expectGazeLine(*h.host, h.sink.attached[0], {0.5, -0.02, 0.85}, 0.1);
  // The head pitches down: the capsule, in the head frame, is recomputed and still hits the point.
  JointStateSample js;
  js.source = "controller";  // the default joint_state_sources
  js.names = {"neck_pitch", "neck_yaw"};
  js.positions = {0.4, 0.2};
  h->onJointState(js, at(0.1));
  h->tick(at(0.1));
  ASSERT_EQ(h.sink.attached.size(), 2u);
  expectGazeLine(*h.host, h.sink.attached[1], {0.5, -0.02, 0.85}, 0.1);
  EXPECT_GT((h.sink.attached[1].b_L - h.sink.attached[0].b_L).norm(), 0.01);
  h->stop(at(0.2));
  EXPECT_EQ(h.sink.events.back(), "detach:gaze_line");
}

TEST(Occlusion, FollowsTheObjectAndSwitchesOffWhenCoveredOrLost) {
  TestHost h(
      "inputs: {known_objects: [cup]}\n"
      "modules:\n  - {name: eyes, type: occlusion, config: {object: cup, cover_distance: 0.08, lost_timeout: 0.5, "
      "end_margin: 0.05}}\n");
  EXPECT_TRUE(h->claims().objects);
  h->start(at(0.0));
  ASSERT_EQ(h.sink.attached.size(), 1u);
  EXPECT_FALSE(h.sink.attached[0].enabled);  // nothing looked at yet
  const Eigen::Vector3d cup(0.5, -0.05, 0.9);
  h->onObjects(frameAt(0.1, {object("cup", cup)}), at(0.1));
  EXPECT_TRUE(h->segments().at("gaze_line").enabled);
  expectGazeLine(*h.host, h->segments().at("gaze_line"), cup, 0.05);
  // The cup is brought to the right hand (its hand point at rest): covered -> off.
  const Eigen::Vector3d hand = h->robot().handPoint_B(Hand::kRight);
  h->onObjects(frameAt(0.2, {object("cup", hand + Eigen::Vector3d(0.05, 0.0, 0.0))}), at(0.2));
  EXPECT_FALSE(h->segments().at("gaze_line").enabled);
  h->onObjects(frameAt(0.3, {object("cup", hand + Eigen::Vector3d(0.10, 0.0, 0.0))}), at(0.3));
  EXPECT_TRUE(h->segments().at("gaze_line").enabled);  // 0.10 > cover_distance
  // Not seen any more: off after lost_timeout.
  for (double t = 0.35; t <= 0.79; t += 0.05) h->tick(at(t));
  EXPECT_TRUE(h->segments().at("gaze_line").enabled);
  for (double t = 0.85; t <= 1.0; t += 0.05) h->tick(at(t));
  EXPECT_FALSE(h->segments().at("gaze_line").enabled);
  h->stop(at(1.0));
  EXPECT_TRUE(h->segments().empty());
  EXPECT_EQ(h->stats().forced_cleanups, 0u);
}

TEST(Walking, SendsTheGoalAfterTheDelayAndStopsAtStop) {
  TestHost h(
      "modules:\n  - {name: walk, type: walking, config: {goal: [1.5, 0.2, 0.1], speed: 0.25, start_after: 1.0}}\n");
  EXPECT_TRUE(h->claims().walk);
  h->start(at(0.0));
  for (int k = 1; k < 19; ++k) h->tick(at(0.05 * k));
  EXPECT_TRUE(h.sink.walks.empty());
  for (int k = 19; k <= 22; ++k) h->tick(at(0.05 * k));
  ASSERT_EQ(h.sink.walks.size(), 1u);
  EXPECT_EQ(h.sink.walks[0], (WalkGoal{1.5, 0.2, 0.1, 0.25, false}));
  h->stop(at(2.0));
  ASSERT_EQ(h.sink.walks.size(), 2u);
  EXPECT_TRUE(h.sink.walks[1].stop);
}

TEST(Walking, RelativeGoalAddsTheRobotPosition) {
  TestHost h(
      "modules:\n  - {name: walk, type: walking, config: {goal: [1.5, 0.0, 0.0], relative: true, start_after: 0.5}}\n");
  h->start(at(0.0));
  JointStateSample js;
  js.source = "controller";  // the default joint_state_sources
  js.names = {"heel_x", "heel_y"};
  js.positions = {0.4, -0.1};
  h->onJointState(js, at(0.1));
  for (int k = 1; k <= 12; ++k) h->tick(at(0.05 * k));
  ASSERT_EQ(h.sink.walks.size(), 1u);
  EXPECT_NEAR(h.sink.walks[0].x, 1.9, 1e-12);
  EXPECT_NEAR(h.sink.walks[0].y, -0.1, 1e-12);
}

}  // namespace
}  // namespace reflex::modules
