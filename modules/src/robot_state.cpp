#include "reflex/common/shipped.hpp"
#include "reflex/modules/robot_state.hpp"

#include <reflex/control/urdf_loader.hpp>

#include <algorithm>
#include <cmath>

namespace reflex::modules {

std::string defaultRobotUrdf() { return reflex::common::defaultUrdf(); }

RobotConfig readRobotConfig(const ConfigNode& node) {
  node.rejectUnknown({"urdf", "collision", "left_shoulder", "right_shoulder", "left_hand", "right_hand", "head",
                      "head_camera", "hand_point"});
  RobotConfig c;
  if (node.has("urdf")) c.urdf = node.resolvePath(node.string("urdf", ""));
  if (node.has("collision")) c.collision = node.resolvePath(node.string("collision", ""));
  c.left_shoulder = node.string("left_shoulder", c.left_shoulder);
  c.right_shoulder = node.string("right_shoulder", c.right_shoulder);
  c.left_hand = node.string("left_hand", c.left_hand);
  c.right_hand = node.string("right_hand", c.right_hand);
  c.head = node.string("head", c.head);
  c.head_camera = node.string("head_camera", c.head_camera);
  c.hand_point_L = node.vec3("hand_point", c.hand_point_L);
  c.source = node.path().empty() ? node.file() : node.file() + " (" + node.path() + ")";
  return c;
}

namespace {
control::Model loadRobot(const RobotConfig& c) {
  try {
    const std::string coll = c.collision.empty() ? control::defaultCollisionConfigPath(c.urdf) : c.collision;
    return control::loadModel(c.urdf, control::loadCollisionConfig(coll));
  } catch (const control::ModelError& e) {
    throw ConfigError(c.source + ": robot.urdf '" + c.urdf + "': " + e.what());
  }
}
int linkOrThrow(const control::Model& m, const RobotConfig& c, const char* key, const std::string& name) {
  const int i = m.linkIndex(name);
  if (i < 0) {
    throw ConfigError(c.source + ": robot." + key + ": no link '" + name + "' in '" + c.urdf + "'");
  }
  return i;
}
}  // namespace

RobotState::RobotState(const RobotConfig& config)
    : config_(config), model_(loadRobot(config)), kin_(model_), q_scratch_(Eigen::VectorXd::Zero(model_.nq)) {
  shoulder_link_[0] = linkOrThrow(model_, config_, "left_shoulder", config_.left_shoulder);
  shoulder_link_[1] = linkOrThrow(model_, config_, "right_shoulder", config_.right_shoulder);
  hand_link_[0] = linkOrThrow(model_, config_, "left_hand", config_.left_hand);
  hand_link_[1] = linkOrThrow(model_, config_, "right_hand", config_.right_hand);
  head_link_ = linkOrThrow(model_, config_, "head", config_.head);
  camera_link_ = linkOrThrow(model_, config_, "head_camera", config_.head_camera);
  // Every arm joint at zero = arm stretched (the reach); then the rest configuration.
  Eigen::VectorXd q0 = Eigen::VectorXd::Zero(model_.nq);
  control::computeForwardKinematics(model_, kin_, q0);
  for (Hand h : kBothHands) reach_[handIndex(h)] = (handPoint_B(h) - shoulder_B(h)).norm();
  for (int i = 0; i < model_.nq; ++i) q0[i] = std::clamp(0.0, model_.q_lower[i], model_.q_upper[i]);
  control::computeForwardKinematics(model_, kin_, q0);
}

bool RobotState::update(const JointStateSample& js) {
  if (js.names.size() != js.positions.size()) return false;
  if (js.names != names_cache_) {
    names_cache_ = js.names;
    index_cache_.resize(js.names.size());
    for (std::size_t i = 0; i < js.names.size(); ++i) index_cache_[i] = model_.qIndex(js.names[i]);
  }
  q_scratch_ = kin_.q;
  for (std::size_t i = 0; i < js.positions.size(); ++i) {
    const int qi = index_cache_[i];
    if (qi < 0) continue;
    if (!std::isfinite(js.positions[i])) return false;
    q_scratch_[qi] = js.positions[i];
  }
  if (!control::computeForwardKinematics(model_, kin_, q_scratch_)) return false;
  from_joint_state_ = true;
  return true;
}

double RobotState::jointPosition(const std::string& name, double def) const {
  const int i = model_.qIndex(name);
  return i < 0 ? def : kin_.q[i];
}

Eigen::Vector3d RobotState::shoulder_B(Hand h) const { return X_B_L(shoulder_link_[handIndex(h)]).translation(); }

Eigen::Vector3d RobotState::handPoint_B(Hand h) const { return X_B_L(hand_link_[handIndex(h)]) * config_.hand_point_L; }

}  // namespace reflex::modules
