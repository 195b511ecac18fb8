// The robot as the behavior modules see it: the kinematic model (reflex::control, loaded once from
// URDF) and the link poses of the latest joint state from the bus (reflex/joint_state), or of the
// rest configuration (every joint at 0, clamped into its limits) until a joint state arrives.
//
// Modules ask for points in the base frame B (the model's root link frame, the controller's too):
// shoulders, hand points, head and head camera poses. All names come from RobotConfig (defaults fit
// bringup/robots/asimo_like.urdf) and are checked when the model is loaded.
#pragma once

#include "reflex/modules/config.hpp"
#include "reflex/modules/types.hpp"

#include <reflex/control/kinematics.hpp>
#include <reflex/control/model.hpp>

#include <Eigen/Geometry>

#include <string>
#include <vector>

namespace reflex::modules {

/// The default robot: the shipped asimo_like.urdf (reflex/common/shipped.hpp says where it is found).
std::string defaultRobotUrdf();

struct RobotConfig {
  std::string urdf = defaultRobotUrdf();  ///< robot description
  std::string collision;                  ///< collision YAML ("" = next to the URDF)
  std::string left_shoulder = "l_shoulder", right_shoulder = "r_shoulder";
  std::string left_hand = "l_hand", right_hand = "r_hand";
  std::string head = "head", head_camera = "head_camera";
  /// The hand's reaching point in the hand link frame [m] (the controller's hand_point).
  Eigen::Vector3d hand_point_L = Eigen::Vector3d(0.0, 0.0, -0.06);
  std::string source = "<defaults>";  ///< where it was read from
};

/// Reads the `robot:` section (keys: urdf, collision, left_shoulder, right_shoulder, left_hand,
/// right_hand, head, head_camera, hand_point). Paths are relative to the configuration file.
RobotConfig readRobotConfig(const ConfigNode& node);

class RobotState {
 public:
  /// Loads the model; throws ConfigError naming the URDF or the unknown link and its config key.
  explicit RobotState(const RobotConfig& config);

  /// Takes a joint state: joints are matched by name (unknown names are ignored). Returns false and
  /// keeps the previous state if names and positions differ in length or a matched value is not
  /// finite. Allocates only when the joint name list changes.
  bool update(const JointStateSample& js);
  /// True once a joint state was accepted (before: the rest configuration).
  bool fromJointState() const { return from_joint_state_; }

  const control::Model& model() const { return model_; }
  const RobotConfig& config() const { return config_; }
  const Eigen::VectorXd& q() const { return kin_.q; }
  /// Position of a joint by name; `def` if the model has no such joint.
  double jointPosition(const std::string& name, double def = 0.0) const;

  /// Pose of a link in B; link from model().linkIndex.
  const Eigen::Isometry3d& X_B_L(int link) const { return kin_.X_B_L[static_cast<std::size_t>(link)]; }
  Eigen::Vector3d shoulder_B(Hand h) const;
  /// The hand's reaching point in B.
  Eigen::Vector3d handPoint_B(Hand h) const;
  int handLink(Hand h) const { return hand_link_[handIndex(h)]; }
  const std::string& handLinkName(Hand h) const { return h == Hand::kLeft ? config_.left_hand : config_.right_hand; }
  int headLink() const { return head_link_; }
  const Eigen::Isometry3d& X_B_head() const { return X_B_L(head_link_); }
  Eigen::Vector3d camera_B() const { return X_B_L(camera_link_).translation(); }
  /// Distance from the shoulder to the hand point with every arm joint at zero (arm stretched) [m].
  double armReach(Hand h) const { return reach_[handIndex(h)]; }

 private:
  RobotConfig config_;
  control::Model model_;
  control::KinematicsData kin_;
  Eigen::VectorXd q_scratch_;
  std::vector<std::string> names_cache_;
  std::vector<int> index_cache_;
  int shoulder_link_[2] = {-1, -1}, hand_link_[2] = {-1, -1};
  int head_link_ = -1, camera_link_ = -1;
  double reach_[2] = {0.0, 0.0};
  bool from_joint_state_ = false;
};

}  // namespace reflex::modules
