// Pointing module (paper Sec. 8.4, Fig. 12-13): the robot points at the objects a person holds.
//
// From the object targets of vision and the robot's joint state it
//   1. assigns objects to hands, stably: an object keeps its hand as long as it is tracked
//      (assignment: sticky), so objects crossing in front of the chest never make the hands swap;
//      with assignment: nearest the cheaper assignment (sum of shoulder-object distances) is adopted
//      only when it is better by swap_margin for swap_hold seconds (hysteresis, no flip-flop);
//      a new or re-found object gets a free hand, nearest shoulder first;
//   2. computes each hand's target from its shoulder s and object o (pointingTarget):
//        mode ray:    s + ray_distance * (o - s) / |o - s|      (on the shoulder-object ray)
//        mode object: o if |o - s| <= reach, else s + reach * (o - s) / |o - s|
//      and sets the hand "given" with the object's name;
//   3. turns a hand to "no target" when its object has not been seen for lost_timeout seconds
//      (the controller then retracts it to rest, Fig. 12 top centre), also if vision goes silent;
//   4. sets the motion priority between the arms (Sec. 7.2, 9.1) by priority_rule:
//        first_assigned: the hand that has had its object longest is higher (tie: priority_tie);
//        nearer_object:  the hand whose object is nearer its shoulder is higher, switching only when
//                        the other is nearer by priority_margin;
//        equal / left / right: fixed; none: this module does not write the priority.
//      With only one hand given, that hand is higher (except fixed rules); with none, equal.
#pragma once

#include "reflex/modules/module.hpp"

#include <Eigen/Core>

#include <map>
#include <optional>
#include <string>
#include <vector>

namespace reflex::modules {

enum class PointingMode { kRay, kObject };

/// The hand target that points from shoulder s_B at object o_B (see the header comment).
/// nullopt if the object is (numerically) at the shoulder: there is no direction to point in.
std::optional<Eigen::Vector3d> pointingTarget(const Eigen::Vector3d& s_B, const Eigen::Vector3d& o_B, PointingMode mode,
                                              double ray_distance, double reach);

class PointingModule final : public Module {
 public:
  enum class Assignment { kSticky, kNearest };
  enum class PriorityRule { kNone, kEqual, kLeft, kRight, kFirstAssigned, kNearerObject };

  struct Config {
    bool hands[2] = {true, true};
    std::vector<std::string> objects;  ///< objects to point at; empty = every accepted object
    PointingMode mode = PointingMode::kRay;
    double ray_distance = 0.40;   ///< [m] from the shoulder, mode ray
    double reach = 0.0;           ///< [m] mode object; 0 = the robot's arm reach
    double lost_timeout = 1.0;    ///< [s]
    double min_confidence = 0.0;  ///< objects below are not "seen"
    Assignment assignment = Assignment::kSticky;
    double swap_margin = 0.10;  ///< [m] assignment nearest
    double swap_hold = 1.0;     ///< [s] assignment nearest
    PriorityRule priority_rule = PriorityRule::kFirstAssigned;
    double priority_margin = 0.03;     ///< [m] nearer_object hysteresis
    Hand priority_tie = Hand::kRight;  ///< first_assigned / nearer_object tie
    double step_period = 0.05;         ///< [s] lost-timeout checks without frames
  };

  explicit PointingModule(std::string name) : Module(std::move(name)) {}
  void configure(const ConfigNode& config, const RobotState& robot) override;
  Claims claims() const override;
  double stepPeriod() const override { return config_.step_period; }
  void start(ModuleContext& ctx) override;
  void onObjects(const ObjectsFrame& frame, ModuleContext& ctx) override;
  void onJointState(ModuleContext& ctx) override;
  void step(ModuleContext& ctx) override;
  void stop(ModuleContext& ctx) override;
  std::string status() const override;

  const Config& config() const { return config_; }
  /// The object assigned to a hand ("" if none).
  const std::string& assigned(Hand h) const { return assign_[handIndex(h)].object; }
  /// Number of assignment changes between two tracked objects (swaps / moves), since start.
  int reassignments() const { return reassignments_; }

 private:
  struct Track {
    Eigen::Vector3d p_B = Eigen::Vector3d::Zero();
    double last_seen = -1.0;
  };
  struct Assigned {
    std::string object;  ///< "" = free
    double since = 0.0;
  };
  void update(ModuleContext& ctx, const ObjectsFrame* frame);
  void considerReassignment(ModuleContext& ctx);
  void publish(ModuleContext& ctx);
  ArmPriority decidePriority(const RobotState& robot);

  Config config_;
  std::map<std::string, Track> tracks_;
  Assigned assign_[2];
  double swap_since_ = -1.0;
  int reassignments_ = 0;
  ArmPriority priority_ = ArmPriority::kEqual;
  bool degenerate_logged_[2] = {false, false};
};

}  // namespace reflex::modules
