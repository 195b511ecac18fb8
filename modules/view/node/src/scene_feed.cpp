// The bus samples of a scene folded into one view::SceneInput (scene_feed.hpp).
#include "reflex/view_node/scene_feed.hpp"

namespace reflex::view_node {
namespace {

view::ArmState armState(const msg::ArmStatus& a) {
  view::ArmState s;
  s.valid = true;
  s.blend_f = a.blend_f();
  s.closest_a = a.closest_segment_a();
  s.closest_b = a.closest_segment_b();
  s.distance = a.distance();
  const int z = static_cast<int>(a.zone());
  s.zone = z >= 0 && z <= 3 ? static_cast<view::Zone>(z) : view::Zone::kRed;  // unknown: the worst
  s.estop_latched = a.estop_latched();
  return s;
}

view::HandTargetState targetState(const msg::HandTarget& t) {
  view::HandTargetState s;
  s.given = t.status() == msg::TARGET_GIVEN;
  s.p_B = Eigen::Vector3d(t.position_base().x(), t.position_base().y(), t.position_base().z());
  s.object = t.object_name();
  return s;
}

}  // namespace

SceneFeed::SceneFeed(const view::SceneModel& scene) : scene_(scene) {
  input_.q = Eigen::VectorXd::Zero(scene.model.nq);
}

void SceneFeed::add(const msg::JointState& s) {
  ++stats_.joint_states;
  int unknown = 0, rejected = 0;
  view::jointPositionsToQ(scene_, s.names(), s.positions(), input_.q, &unknown, &rejected);
  stats_.joint_entries_skipped += static_cast<std::uint64_t>(unknown + rejected);
  input_.stamp_ns = s.header().stamp_ns();
  fresh_ = true;
}

void SceneFeed::add(const msg::ControlStatus& s) {
  ++stats_.statuses;
  input_.arms[0] = armState(s.left());
  input_.arms[1] = armState(s.right());
}

void SceneFeed::add(const msg::HandTargets& s) {
  ++stats_.hand_targets;
  input_.targets[0] = targetState(s.left());
  input_.targets[1] = targetState(s.right());
}

void SceneFeed::add(const msg::ObjectTargets& s) {
  ++stats_.object_frames;
  // Positions in another frame than the robot's base are not base-frame positions: not drawn.
  if (s.frame_id() != "base_link" && s.frame_id() != scene_.root_frame) {
    ++stats_.object_frames_other_frame;
    return;
  }
  input_.objects.clear();
  for (const msg::ObjectTarget& o : s.objects()) {
    view::ObjectState obj;
    obj.name = o.name();
    obj.p_B = Eigen::Vector3d(o.position_base().x(), o.position_base().y(), o.position_base().z());
    obj.confidence = o.confidence();
    input_.objects.push_back(std::move(obj));
  }
}

void SceneFeed::add(const msg::BodySchemaChange& c) {
  ++stats_.schema_changes;
  if (c.operation() == msg::SCHEMA_DETACH) {
    schema_.erase(c.segment_name());
  } else if (schema_.size() < kMaxSchemaSegments || schema_.count(c.segment_name())) {
    view::SchemaSegmentState& b = schema_[c.segment_name()];
    b.name = c.segment_name();
    b.parent_link = c.parent_link();
    b.capsule = c.shape() == msg::SHAPE_CAPSULE;
    b.a_L = Eigen::Vector3d(c.point_a().x(), c.point_a().y(), c.point_a().z());
    b.b_L = Eigen::Vector3d(c.point_b().x(), c.point_b().y(), c.point_b().z());
    b.radius = c.radius();
    b.enabled = c.enabled();
    b.virtual_segment = c.virtual_segment();
  }
  input_.schema_segments.clear();
  for (const auto& kv : schema_) input_.schema_segments.push_back(kv.second);
}

std::string dumpJson(const nlohmann::json& message) {
  return message.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace);
}

}  // namespace reflex::view_node
