// Body-schema modules (paper Sec. 8.5): extra segments the controller avoids like its own.
//
// GraspedBarModule (Sec. 8.5.1, Fig. 14): a grasped object, a capsule rigidly attached to a hand
//   (endpoints in the hand link frame), with a motion priority above the arms' (0): the other arm
//   avoids it, it is an obstacle only. It can spin about an axis through a centre in the hand frame
//   (the "rotating bar" of Fig. 14), be attached after a delay and detached after a time. With
//   arm_priority: true it also writes the motion priority "bar hand higher" (Sec. 7.2).
//
// OcclusionModule (Sec. 8.5.2, Fig. 15): a virtual capsule from the head camera to the object being
//   looked at (an object of vision by name, or a fixed point in the base frame), expressed in the head
//   link frame and recomputed as the head and the object move. The arms avoid it, so they do not hide
//   the object from the cameras. It is switched off (enabled = false) when a hand covers the object
//   (hand point within cover_distance of it), when the object has not been seen for lost_timeout, or
//   when the object is too close to the camera for a capsule; it ends end_margin short of the object
//   so that a hand can still reach the object itself.
//
// Both detach their segment at stop.
#pragma once

#include "reflex/modules/module.hpp"

#include <Eigen/Core>

#include <string>

namespace reflex::modules {

class GraspedBarModule final : public Module {
 public:
  struct Config {
    Hand hand = Hand::kLeft;
    std::string segment = "grasped_bar";
    Eigen::Vector3d a_L = Eigen::Vector3d(0.0, -0.15, -0.06);  ///< [m] hand link frame
    Eigen::Vector3d b_L = Eigen::Vector3d(0.0, 0.15, -0.06);
    double radius = 0.02;
    int motion_priority = 1;
    double spin_rate = 0.0;                                  ///< [rad/s]
    Eigen::Vector3d spin_axis_L = Eigen::Vector3d::UnitZ();  ///< unit, hand link frame
    Eigen::Vector3d spin_center_L = Eigen::Vector3d(0.0, 0.0, -0.06);
    double attach_after = 0.0;   ///< [s]
    double detach_after = 0.0;   ///< [s] 0 = never
    double update_period = 0.1;  ///< [s]
    bool arm_priority = false;
  };

  explicit GraspedBarModule(std::string name) : Module(std::move(name)) {}
  void configure(const ConfigNode& config, const RobotState& robot) override;
  Claims claims() const override;
  double stepPeriod() const override { return config_.update_period; }
  void start(ModuleContext& ctx) override;
  void step(ModuleContext& ctx) override;
  void stop(ModuleContext& ctx) override;
  std::string status() const override;
  const Config& config() const { return config_; }

  /// The bar's segment at `elapsed` seconds after start (spin applied).
  SegmentSpec segmentAt(double elapsed) const;

 private:
  void update(ModuleContext& ctx);
  Config config_;
  std::string hand_link_;
  double t0_ = 0.0;
  bool attached_ = false;
};

class OcclusionModule final : public Module {
 public:
  struct Config {
    std::string segment = "gaze_line";
    std::string object;                                 ///< object to look at ("" = point)
    Eigen::Vector3d point_B = Eigen::Vector3d::Zero();  ///< fixed target if object is ""
    double radius = 0.03;
    double end_margin = 0.10;      ///< [m] the capsule ends this far before the object
    double cover_distance = 0.08;  ///< [m] hand point this close to the object = covered
    bool cover_hands[2] = {true, true};
    double lost_timeout = 1.0;    ///< [s]
    double update_period = 0.05;  ///< [s]
    double min_change = 0.005;    ///< [m] endpoint motion that is republished
  };

  explicit OcclusionModule(std::string name) : Module(std::move(name)) {}
  void configure(const ConfigNode& config, const RobotState& robot) override;
  Claims claims() const override;
  double stepPeriod() const override { return config_.update_period; }
  void start(ModuleContext& ctx) override;
  void onObjects(const ObjectsFrame& frame, ModuleContext& ctx) override;
  void step(ModuleContext& ctx) override;
  void stop(ModuleContext& ctx) override;
  std::string status() const override;
  const Config& config() const { return config_; }
  bool covered() const { return covered_; }

 private:
  void update(ModuleContext& ctx);
  Config config_;
  bool have_target_ = false;
  Eigen::Vector3d target_B_ = Eigen::Vector3d::Zero();
  double last_seen_ = -1.0;
  bool covered_ = false;
  bool published_ = false;
  SegmentSpec last_;
};

/// Walking-goal module (Sec. 8.3.2, Fig. 11): sends a walking goal in the world (odometry) frame,
/// after start_after seconds; relative: true adds the robot's position at that moment (joints
/// x_joint / y_joint of the joint state). Stop sends "stop walking".
class WalkingModule final : public Module {
 public:
  struct Config {
    Eigen::Vector3d goal = Eigen::Vector3d::Zero();  ///< x [m], y [m], yaw [rad]
    double speed = 0.3;
    bool relative = false;
    double start_after = 0.0;
    std::string x_joint = "heel_x", y_joint = "heel_y";
  };
  explicit WalkingModule(std::string name) : Module(std::move(name)) {}
  void configure(const ConfigNode& config, const RobotState& robot) override;
  Claims claims() const override;
  double stepPeriod() const override { return 0.05; }
  void start(ModuleContext& ctx) override;
  void step(ModuleContext& ctx) override;
  void stop(ModuleContext& ctx) override;
  std::string status() const override;

 private:
  Config config_;
  double t0_ = 0.0;
  bool sent_ = false;
  WalkGoal goal_;
};

}  // namespace reflex::modules
