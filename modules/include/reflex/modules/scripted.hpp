// Scripted-target module: a timeline of hand targets and motion priorities, for the paper's
// experiments with given targets (Sec. 8.2, 8.3.1 crossing arms, 8.5.1 grasped bar) over the bus.
//
// Events happen at t seconds after start and hold until the next event of the same kind (the
// controller makes its own linear trajectory to each new target, Sec. 8). The timeline comes from
//   timeline: inline YAML list of {t, left, right, priority}, any subset of the last three:
//             left / right: [x, y, z] in the base frame [m], or none ("no target": the hand retracts);
//             priority: left | right | equal;
//   file:     a YAML file with such a list under "timeline:", or a CSV file (.csv) with the header
//             t,hand,x,y,z  and rows  "1.5,right,0.35,-0.1,1.0"  "4,left,none,,"  "2,priority,left,,".
// Events must be in time order; targets finite and within 2 m of the base origin (the controller's
// limit). With loop_period > 0 the timeline restarts every loop_period seconds.
// The module claims the hands (and the priority) its timeline mentions.
#pragma once

#include "reflex/modules/module.hpp"

#include <string>
#include <vector>

namespace reflex::modules {

struct TimelineEvent {
  double t = 0.0;  ///< [s] after start
  enum class Kind { kHand, kPriority } kind = Kind::kHand;
  Hand hand = Hand::kLeft;                     ///< kHand
  HandTarget target;                           ///< kHand
  ArmPriority priority = ArmPriority::kEqual;  ///< kPriority
};

/// Reads a timeline CSV (see above). Throws ConfigError "<file>:<line>: column '<c>': ... '<value>'".
std::vector<TimelineEvent> readTimelineCsv(const std::string& path);
/// Reads a YAML timeline list; `node`'s key `key` holds it.
std::vector<TimelineEvent> readTimelineYaml(const ConfigNode& node, const std::string& key);

class ScriptedModule final : public Module {
 public:
  explicit ScriptedModule(std::string name) : Module(std::move(name)) {}
  void configure(const ConfigNode& config, const RobotState& robot) override;
  Claims claims() const override;
  double stepPeriod() const override { return step_period_; }
  void start(ModuleContext& ctx) override;
  void step(ModuleContext& ctx) override;
  void stop(ModuleContext& ctx) override;
  std::string status() const override;

  const std::vector<TimelineEvent>& timeline() const { return events_; }

 private:
  void advance(ModuleContext& ctx);

  std::vector<TimelineEvent> events_;
  double loop_period_ = 0.0;
  double step_period_ = 0.02;
  bool hands_[2] = {false, false};
  bool priority_ = false;
  double t0_ = 0.0;
  std::size_t next_ = 0;
  int loops_ = 0;
};

}  // namespace reflex::modules
