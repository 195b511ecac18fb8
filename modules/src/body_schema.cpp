#include "reflex/modules/body_schema.hpp"

#include <Eigen/Geometry>

#include <cmath>
#include <sstream>

namespace reflex::modules {

// ---------------------------------------------------------------- grasped bar (Sec. 8.5.1)

void GraspedBarModule::configure(const ConfigNode& c, const RobotState& robot) {
  c.rejectUnknown({"hand", "segment", "point_a", "point_b", "radius", "motion_priority", "spin_rate", "spin_axis",
                   "spin_center", "attach_after", "detach_after", "update_period", "arm_priority"});
  config_.hand = c.choice("hand", "left", {"left", "right"}) == "left" ? Hand::kLeft : Hand::kRight;
  config_.segment = c.string("segment", config_.segment);
  config_.a_L = c.vec3("point_a", config_.a_L);
  config_.b_L = c.vec3("point_b", config_.b_L);
  if ((config_.a_L - config_.b_L).norm() < 1e-6)
    c.fail("point_b", "equals point_a", "a point different from point_a (a capsule)");
  config_.radius = c.number("radius", config_.radius, 0.001, 0.5);
  config_.motion_priority = c.integer("motion_priority", config_.motion_priority, 0, 1000);
  config_.spin_rate = c.number("spin_rate", config_.spin_rate, -20.0, 20.0);
  config_.spin_axis_L = c.vec3("spin_axis", config_.spin_axis_L);
  if (config_.spin_axis_L.norm() < 1e-9) c.fail("spin_axis", "is zero", "a non-zero axis");
  config_.spin_axis_L.normalize();
  config_.spin_center_L = c.vec3("spin_center", robot.config().hand_point_L);
  config_.attach_after = c.number("attach_after", config_.attach_after, 0.0, 1e6);
  config_.detach_after = c.number("detach_after", config_.detach_after, 0.0, 1e6);
  if (config_.detach_after > 0.0 && config_.detach_after <= config_.attach_after)
    c.fail("detach_after", "not after attach_after", "0 (never) or later than attach_after");
  config_.update_period = c.number("update_period", config_.update_period, 0.005, 1.0);
  config_.arm_priority = c.boolean("arm_priority", config_.arm_priority);
  hand_link_ = robot.handLinkName(config_.hand);
}

Claims GraspedBarModule::claims() const {
  Claims c;
  c.segments = {config_.segment};
  c.priority = config_.arm_priority;
  return c;
}

SegmentSpec GraspedBarModule::segmentAt(double elapsed) const {
  SegmentSpec s;
  s.name = config_.segment;
  s.parent_link = hand_link_;
  s.capsule = true;
  const Eigen::AngleAxisd spin(config_.spin_rate * elapsed, config_.spin_axis_L);
  s.a_L = config_.spin_center_L + spin * (config_.a_L - config_.spin_center_L);
  s.b_L = config_.spin_center_L + spin * (config_.b_L - config_.spin_center_L);
  s.radius = config_.radius;
  s.motion_priority = config_.motion_priority;
  s.enabled = true;
  s.virtual_segment = false;
  return s;
}

void GraspedBarModule::start(ModuleContext& ctx) {
  t0_ = ctx.now().t;
  attached_ = false;
  if (config_.arm_priority) ctx.setPriority(ArmPriority::kEqual);
  update(ctx);
}

void GraspedBarModule::step(ModuleContext& ctx) { update(ctx); }

void GraspedBarModule::update(ModuleContext& ctx) {
  const double e = ctx.now().t - t0_;
  const bool want = e >= config_.attach_after && (config_.detach_after <= 0.0 || e < config_.detach_after);
  if (want) {
    if (!attached_) ctx.log("'" + config_.segment + "' attached to " + hand_link_);
    ctx.attachSegment(segmentAt(e));
    if (config_.arm_priority) ctx.setPriority(higher(config_.hand));
  } else if (attached_) {
    ctx.log("'" + config_.segment + "' detached from " + hand_link_);
    ctx.detachSegment(config_.segment);
    if (config_.arm_priority) ctx.setPriority(ArmPriority::kEqual);
  }
  attached_ = want;
}

void GraspedBarModule::stop(ModuleContext& ctx) {
  ctx.detachSegment(config_.segment);
  if (config_.arm_priority) ctx.setPriority(ArmPriority::kEqual);
  attached_ = false;
}

std::string GraspedBarModule::status() const { return config_.segment + (attached_ ? " attached" : " detached"); }

// ---------------------------------------------------------------- occlusion (Sec. 8.5.2)

void OcclusionModule::configure(const ConfigNode& c, const RobotState& /*robot*/) {
  c.rejectUnknown({"segment", "object", "point", "radius", "end_margin", "cover_distance", "cover_hands",
                   "lost_timeout", "update_period", "min_change"});
  config_.segment = c.string("segment", config_.segment);
  if (c.has("object") == c.has("point"))
    c.failAt("object", "give exactly one of 'object' (a vision object's name) or 'point' ([x, y, z])");
  config_.object = c.string("object", "");
  config_.point_B = c.vec3("point", config_.point_B);
  config_.radius = c.number("radius", config_.radius, 0.001, 0.5);
  config_.end_margin = c.number("end_margin", config_.end_margin, 0.0, 2.0);
  config_.cover_distance = c.number("cover_distance", config_.cover_distance, 0.0, 1.0);
  const auto hands = c.strings("cover_hands", {"left", "right"});
  config_.cover_hands[0] = config_.cover_hands[1] = false;
  for (const auto& h : hands) {
    if (h == "left")
      config_.cover_hands[0] = true;
    else if (h == "right")
      config_.cover_hands[1] = true;
    else
      c.fail("cover_hands", "not a list of hands", "a list of left / right");
  }
  config_.lost_timeout = c.number("lost_timeout", config_.lost_timeout, 0.05, 60.0);
  config_.update_period = c.number("update_period", config_.update_period, 0.005, 1.0);
  config_.min_change = c.number("min_change", config_.min_change, 0.0, 0.5);
}

Claims OcclusionModule::claims() const {
  Claims c;
  c.segments = {config_.segment};
  c.objects = !config_.object.empty();
  return c;
}

void OcclusionModule::start(ModuleContext& ctx) {
  have_target_ = config_.object.empty();
  target_B_ = config_.point_B;
  last_seen_ = -1.0;
  published_ = false;
  covered_ = false;
  update(ctx);
}

void OcclusionModule::onObjects(const ObjectsFrame& frame, ModuleContext& ctx) {
  for (const auto& o : frame.objects) {
    if (o.name != config_.object) continue;
    target_B_ = o.p_B;
    last_seen_ = ctx.now().t;
    have_target_ = true;
  }
  update(ctx);
}

void OcclusionModule::step(ModuleContext& ctx) { update(ctx); }

void OcclusionModule::update(ModuleContext& ctx) {
  const RobotState& robot = ctx.robot();
  const bool seen = config_.object.empty() || (have_target_ && ctx.now().t - last_seen_ <= config_.lost_timeout);
  covered_ = false;
  for (Hand h : kBothHands)
    if (config_.cover_hands[handIndex(h)] && (robot.handPoint_B(h) - target_B_).norm() <= config_.cover_distance)
      covered_ = true;
  const Eigen::Vector3d cam_B = robot.camera_B();
  const double length = (target_B_ - cam_B).norm();
  const bool long_enough = length - config_.end_margin > config_.radius;

  SegmentSpec s = last_;
  s.name = config_.segment;
  s.parent_link = robot.config().head;
  s.capsule = true;
  s.radius = config_.radius;
  s.virtual_segment = true;
  s.motion_priority = 0;
  s.enabled = have_target_ && seen && !covered_ && long_enough;
  if (have_target_ && long_enough) {
    const Eigen::Isometry3d X_head_B = robot.X_B_head().inverse();
    const Eigen::Vector3d end_B = target_B_ - config_.end_margin * (target_B_ - cam_B) / length;
    s.a_L = X_head_B * cam_B;
    s.b_L = X_head_B * end_B;
  } else if (!published_) {
    // Nothing to look at yet: a placeholder inside the head, disabled.
    const Eigen::Isometry3d X_head_B = robot.X_B_head().inverse();
    s.a_L = X_head_B * cam_B;
    s.b_L = s.a_L + Eigen::Vector3d(0.0, 0.0, 0.01);
  }
  const bool moved =
      !published_ || (s.a_L - last_.a_L).norm() > config_.min_change || (s.b_L - last_.b_L).norm() > config_.min_change;
  if (published_ && s.enabled != last_.enabled) {
    ctx.log(std::string("'") + config_.segment + "' switched " + (s.enabled ? "on" : "off") +
            (covered_ ? " (a hand covers the object)"
             : !seen  ? " (object not seen)"
                      : ""));
  }
  if (moved || s.enabled != last_.enabled) {
    ctx.attachSegment(s);
    last_ = s;
    published_ = true;
  }
}

void OcclusionModule::stop(ModuleContext& ctx) {
  ctx.detachSegment(config_.segment);
  published_ = false;
}

std::string OcclusionModule::status() const {
  return config_.segment + (last_.enabled ? " on" : " off") + (covered_ ? " covered" : "");
}

// ---------------------------------------------------------------- walking goal (Sec. 8.3.2)

void WalkingModule::configure(const ConfigNode& c, const RobotState& robot) {
  c.rejectUnknown({"goal", "speed", "relative", "start_after", "x_joint", "y_joint"});
  if (!c.has("goal")) c.fail("goal", "missing", "[x, y, yaw] in the world frame");
  config_.goal = c.vec3("goal", config_.goal);
  config_.speed = c.number("speed", config_.speed, 0.01, 2.0);
  config_.relative = c.boolean("relative", config_.relative);
  config_.start_after = c.number("start_after", config_.start_after, 0.0, 1e6);
  config_.x_joint = c.string("x_joint", config_.x_joint);
  config_.y_joint = c.string("y_joint", config_.y_joint);
  if (config_.relative) {
    if (robot.model().qIndex(config_.x_joint) < 0)
      c.fail("x_joint", "no such joint in the robot", "a joint of the robot");
    if (robot.model().qIndex(config_.y_joint) < 0)
      c.fail("y_joint", "no such joint in the robot", "a joint of the robot");
  }
}

Claims WalkingModule::claims() const {
  Claims c;
  c.walk = true;
  return c;
}

void WalkingModule::start(ModuleContext& ctx) {
  t0_ = ctx.now().t;
  sent_ = false;
  step(ctx);
}

void WalkingModule::step(ModuleContext& ctx) {
  if (sent_ || ctx.now().t - t0_ < config_.start_after) return;
  goal_ = WalkGoal{config_.goal.x(), config_.goal.y(), config_.goal.z(), config_.speed, false};
  if (config_.relative) {
    goal_.x += ctx.robot().jointPosition(config_.x_joint);
    goal_.y += ctx.robot().jointPosition(config_.y_joint);
  }
  std::ostringstream m;
  m << "walking to (" << goal_.x << ", " << goal_.y << ", yaw " << goal_.yaw << ") at " << goal_.speed << " m/s";
  ctx.log(m.str());
  ctx.setWalk(goal_);
  sent_ = true;
}

void WalkingModule::stop(ModuleContext& ctx) {
  if (!sent_) return;
  WalkGoal g = goal_;
  g.stop = true;
  ctx.setWalk(g);
}

std::string WalkingModule::status() const { return sent_ ? "goal sent" : "waiting"; }

}  // namespace reflex::modules
