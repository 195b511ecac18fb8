#include "reflex/modules/pointing.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>

namespace reflex::modules {

std::optional<Eigen::Vector3d> pointingTarget(const Eigen::Vector3d& s_B, const Eigen::Vector3d& o_B, PointingMode mode,
                                              double ray_distance, double reach) {
  const Eigen::Vector3d d_B = o_B - s_B;
  const double dist = d_B.norm();
  if (!(dist > 1e-6) || !std::isfinite(dist)) return std::nullopt;
  const Eigen::Vector3d u_B = d_B / dist;
  if (mode == PointingMode::kRay) return Eigen::Vector3d(s_B + ray_distance * u_B);
  if (dist <= reach) return o_B;
  return Eigen::Vector3d(s_B + reach * u_B);
}

void PointingModule::configure(const ConfigNode& c, const RobotState& robot) {
  c.rejectUnknown({"hands", "objects", "mode", "ray_distance", "reach", "lost_timeout", "min_confidence", "assignment",
                   "swap_margin", "swap_hold", "priority_rule", "priority_margin", "priority_tie", "step_period"});
  const auto hands = c.strings("hands", {"left", "right"});
  config_.hands[0] = config_.hands[1] = false;
  for (const auto& h : hands) {
    if (h == "left") {
      config_.hands[0] = true;
    } else if (h == "right") {
      config_.hands[1] = true;
    } else {
      c.fail("hands", "not a list of hands", "a list of left / right");
    }
  }
  if (!config_.hands[0] && !config_.hands[1]) c.fail("hands", "names no hand", "at least one of left / right");
  config_.objects = c.strings("objects", {});
  config_.mode = c.choice("mode", "ray", {"ray", "object"}) == "ray" ? PointingMode::kRay : PointingMode::kObject;
  const double arm_reach = std::min(robot.armReach(Hand::kLeft), robot.armReach(Hand::kRight));
  config_.reach = c.number("reach", arm_reach, 0.05, 2.0);
  config_.ray_distance = c.number("ray_distance", std::min(0.40, config_.reach), 0.05, config_.reach);
  config_.lost_timeout = c.number("lost_timeout", config_.lost_timeout, 0.05, 60.0);
  config_.min_confidence = c.number("min_confidence", config_.min_confidence, 0.0, 1.0);
  config_.assignment =
      c.choice("assignment", "sticky", {"sticky", "nearest"}) == "sticky" ? Assignment::kSticky : Assignment::kNearest;
  config_.swap_margin = c.number("swap_margin", config_.swap_margin, 0.0, 2.0);
  config_.swap_hold = c.number("swap_hold", config_.swap_hold, 0.0, 60.0);
  const std::string rule = c.choice("priority_rule", "first_assigned",
                                    {"first_assigned", "nearer_object", "equal", "left", "right", "none"});
  config_.priority_rule = rule == "first_assigned"  ? PriorityRule::kFirstAssigned
                          : rule == "nearer_object" ? PriorityRule::kNearerObject
                          : rule == "equal"         ? PriorityRule::kEqual
                          : rule == "left"          ? PriorityRule::kLeft
                          : rule == "right"         ? PriorityRule::kRight
                                                    : PriorityRule::kNone;
  config_.priority_margin = c.number("priority_margin", config_.priority_margin, 0.0, 2.0);
  config_.priority_tie = c.choice("priority_tie", "right", {"left", "right"}) == "left" ? Hand::kLeft : Hand::kRight;
  config_.step_period = c.number("step_period", config_.step_period, 0.005, 1.0);
}

Claims PointingModule::claims() const {
  Claims c;
  c.hands[0] = config_.hands[0];
  c.hands[1] = config_.hands[1];
  c.priority = config_.priority_rule != PriorityRule::kNone;
  c.objects = true;
  return c;
}

void PointingModule::start(ModuleContext& ctx) {
  tracks_.clear();
  assign_[0] = assign_[1] = Assigned{};
  swap_since_ = -1.0;
  reassignments_ = 0;
  priority_ = ArmPriority::kEqual;
  publish(ctx);
}

void PointingModule::onObjects(const ObjectsFrame& frame, ModuleContext& ctx) { update(ctx, &frame); }

void PointingModule::onJointState(ModuleContext& ctx) {
  // The shoulders moved (body, walking): the targets on the rays move with them.
  publish(ctx);
}

void PointingModule::step(ModuleContext& ctx) { update(ctx, nullptr); }

void PointingModule::update(ModuleContext& ctx, const ObjectsFrame* frame) {
  const double t = ctx.now().t;
  std::vector<std::string> fresh;  // seen in this frame
  if (frame) {
    for (const auto& o : frame->objects) {
      if (o.confidence < config_.min_confidence) continue;
      if (!config_.objects.empty() &&
          std::find(config_.objects.begin(), config_.objects.end(), o.name) == config_.objects.end())
        continue;
      Track& tr = tracks_[o.name];
      tr.p_B = o.p_B;
      tr.last_seen = t;
      fresh.push_back(o.name);
    }
  }
  // 1. Lost objects free their hands.
  for (Hand h : kBothHands) {
    Assigned& a = assign_[handIndex(h)];
    if (a.object.empty()) continue;
    const Track& tr = tracks_[a.object];
    if (t - tr.last_seen > config_.lost_timeout) {
      std::ostringstream m;
      m << "'" << a.object << "' not seen for " << (t - tr.last_seen) << " s (> lost_timeout " << config_.lost_timeout
        << " s): " << handName(h) << " hand has no target";
      ctx.log(m.str());
      a = Assigned{};
    }
  }
  // 2. Fresh, unassigned objects get free hands: cheapest (object, hand) pair first.
  const RobotState& robot = ctx.robot();
  std::sort(fresh.begin(), fresh.end());
  for (;;) {
    double best = std::numeric_limits<double>::infinity();
    int best_hand = -1;
    const std::string* best_obj = nullptr;
    for (const auto& name : fresh) {
      if (assign_[0].object == name || assign_[1].object == name) continue;
      for (Hand h : kBothHands) {
        const int i = handIndex(h);
        if (!config_.hands[i] || !assign_[i].object.empty()) continue;
        const double cost = (tracks_[name].p_B - robot.shoulder_B(h)).norm();
        if (cost < best) {
          best = cost;
          best_hand = i;
          best_obj = &name;
        }
      }
    }
    if (best_hand < 0) break;
    assign_[best_hand] = Assigned{*best_obj, t};
    ctx.log("'" + *best_obj + "' assigned to the " + handName(static_cast<Hand>(best_hand)) + " hand");
  }
  if (frame && config_.assignment == Assignment::kNearest) considerReassignment(ctx);
  publish(ctx);
}

void PointingModule::considerReassignment(ModuleContext& ctx) {
  // Tracked objects are moved between hands only if the other assignment is cheaper by swap_margin,
  // continuously for swap_hold seconds.
  if (!config_.hands[0] || !config_.hands[1]) return;
  const std::string& l = assign_[0].object;
  const std::string& r = assign_[1].object;
  if (l.empty() && r.empty()) return;
  const RobotState& robot = ctx.robot();
  auto cost = [&](const std::string& obj, Hand h) {
    return obj.empty() ? 0.0 : (tracks_[obj].p_B - robot.shoulder_B(h)).norm();
  };
  const double current = cost(l, Hand::kLeft) + cost(r, Hand::kRight);
  const double swapped = cost(r, Hand::kLeft) + cost(l, Hand::kRight);
  const double t = ctx.now().t;
  if (swapped + config_.swap_margin < current) {
    if (swap_since_ < 0.0) swap_since_ = t;
    if (t - swap_since_ >= config_.swap_hold) {
      std::swap(assign_[0], assign_[1]);
      assign_[0].since = assign_[1].since = t;
      swap_since_ = -1.0;
      ++reassignments_;
      ctx.log("hands swapped: left=" + (assign_[0].object.empty() ? std::string("-") : assign_[0].object) +
              " right=" + (assign_[1].object.empty() ? std::string("-") : assign_[1].object));
    }
  } else {
    swap_since_ = -1.0;
  }
}

ArmPriority PointingModule::decidePriority(const RobotState& robot) {
  switch (config_.priority_rule) {
    case PriorityRule::kNone:
    case PriorityRule::kEqual: return ArmPriority::kEqual;
    case PriorityRule::kLeft: return ArmPriority::kLeftHigher;
    case PriorityRule::kRight: return ArmPriority::kRightHigher;
    case PriorityRule::kFirstAssigned:
    case PriorityRule::kNearerObject: break;
  }
  const bool given[2] = {!assign_[0].object.empty(), !assign_[1].object.empty()};
  if (!given[0] && !given[1]) return ArmPriority::kEqual;
  if (given[0] != given[1]) return higher(given[0] ? Hand::kLeft : Hand::kRight);
  if (config_.priority_rule == PriorityRule::kFirstAssigned) {
    if (assign_[0].since < assign_[1].since) return ArmPriority::kLeftHigher;
    if (assign_[1].since < assign_[0].since) return ArmPriority::kRightHigher;
    return higher(config_.priority_tie);
  }
  double d[2];
  for (Hand h : kBothHands) d[handIndex(h)] = (tracks_[assign_[handIndex(h)].object].p_B - robot.shoulder_B(h)).norm();
  if (priority_ == ArmPriority::kLeftHigher)
    return d[1] + config_.priority_margin < d[0] ? ArmPriority::kRightHigher : priority_;
  if (priority_ == ArmPriority::kRightHigher)
    return d[0] + config_.priority_margin < d[1] ? ArmPriority::kLeftHigher : priority_;
  if (d[0] < d[1]) return ArmPriority::kLeftHigher;
  if (d[1] < d[0]) return ArmPriority::kRightHigher;
  return higher(config_.priority_tie);
}

void PointingModule::publish(ModuleContext& ctx) {
  const RobotState& robot = ctx.robot();
  for (Hand h : kBothHands) {
    const int i = handIndex(h);
    if (!config_.hands[i]) continue;
    const Assigned& a = assign_[i];
    if (a.object.empty()) {
      ctx.setHand(h, HandTarget::none());
      continue;
    }
    const auto target =
        pointingTarget(robot.shoulder_B(h), tracks_[a.object].p_B, config_.mode, config_.ray_distance, config_.reach);
    if (!target) {  // the object is at the shoulder: nothing to point along
      if (!degenerate_logged_[i])
        ctx.log(std::string("'") + a.object + "' is at the shoulder: " + handName(h) + " hand has no target");
      degenerate_logged_[i] = true;
      ctx.setHand(h, HandTarget::none());
      continue;
    }
    degenerate_logged_[i] = false;
    ctx.setHand(h, HandTarget::at(*target, a.object));
  }
  if (config_.priority_rule != PriorityRule::kNone) {
    priority_ = decidePriority(robot);
    ctx.setPriority(priority_);
  }
}

void PointingModule::stop(ModuleContext& ctx) {
  for (Hand h : kBothHands)
    if (config_.hands[handIndex(h)]) ctx.setHand(h, HandTarget::none());
  if (config_.priority_rule != PriorityRule::kNone) ctx.setPriority(ArmPriority::kEqual);
  assign_[0] = assign_[1] = Assigned{};
}

std::string PointingModule::status() const {
  auto n = [](const std::string& s) { return s.empty() ? std::string("-") : s; };
  return "left=" + n(assign_[0].object) + " right=" + n(assign_[1].object) + " priority=" + priorityName(priority_);
}

}  // namespace reflex::modules
