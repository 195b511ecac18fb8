#include "reflex/control/onboard.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>

namespace reflex::control {

namespace {

std::string rangeError(const char* key, double value, const char* range) {
  char buf[200];
  std::snprintf(buf, sizeof(buf), "onboard controller: %s = %g is outside its range %s", key, value, range);
  return buf;
}

}  // namespace

const char* rejectCauseName(RejectCause cause) noexcept {
  switch (cause) {
    case RejectCause::kHandTargetNotFinite: return "hand_target_not_finite";
    case RejectCause::kHandTargetTooFar: return "hand_target_too_far";
    case RejectCause::kSchemaBadSegment: return "body_schema_bad_segment";
    case RejectCause::kSchemaNoSlot: return "body_schema_no_slot";
    case RejectCause::kSchemaUnresolvable: return "body_schema_unresolvable";
    case RejectCause::kWalkBadValue: return "walk_bad_value";
    case RejectCause::kWalkUnsupportedGoal: return "walk_goal_y_or_yaw_not_zero";
  }
  return "?";
}

void OnboardController::reject(RejectCause cause) noexcept {
  OnboardCounts& c = report_.counts;
  ++c.rejected[static_cast<std::size_t>(cause)];
  c.last_rejection = static_cast<int>(cause);
  ++c.targets_rejected;
  switch (cause) {
    case RejectCause::kHandTargetNotFinite:
    case RejectCause::kHandTargetTooFar: ++c.hand_targets_rejected; break;
    case RejectCause::kSchemaBadSegment:
    case RejectCause::kSchemaNoSlot:
    case RejectCause::kSchemaUnresolvable: ++c.schema_rejected; break;
    case RejectCause::kWalkBadValue:
    case RejectCause::kWalkUnsupportedGoal: ++c.walk_rejected; break;
  }
}

std::uint64_t graspIgnoreMask(const Model& model, const ControllerModel& cm, int link) noexcept {
  if (link < 0 || link >= static_cast<int>(model.links.size())) return 0;
  auto armJoint = [&](int q) {
    for (const auto& arm : cm.arms)
      for (int k = 0; k < arm.n; ++k)
        if (arm.q[k] == q) return true;
    return false;
  };
  // The root of the rigid body: up through fixed joints.
  int root = link;
  while (model.links[static_cast<std::size_t>(root)].parent >= 0 &&
         model.links[static_cast<std::size_t>(root)].type == JointType::kFixed)
    root = model.links[static_cast<std::size_t>(root)].parent;
  bool on_arm = false;  // held by an arm (a hand): its fingers hold the object too
  for (const auto& arm : cm.arms)
    on_arm = on_arm || (static_cast<std::size_t>(link) < arm.link_in_arm.size() &&
                        arm.link_in_arm[static_cast<std::size_t>(link)]);
  std::uint64_t mask = 0;
  for (int s = 0; s < model.num_robot_segments; ++s) {
    // On or below the rigid body: joined to it by fixed joints, and on an arm also by the joints below
    // that are no arm joint (the fingers of a hand).
    int l = model.segments[static_cast<std::size_t>(s)].link;
    bool joined = false;
    for (; l >= 0; l = model.links[static_cast<std::size_t>(l)].parent) {
      if (l == root) {
        joined = true;
        break;
      }
      const int q = model.links[static_cast<std::size_t>(l)].q_index;
      if (q >= 0 && (!on_arm || armJoint(q))) break;  // off an arm: the rigid body only
    }
    if (joined) mask |= std::uint64_t{1} << s;
  }
  // The nearest link above the rigid body that carries a segment (the wrist).
  for (int l = model.links[static_cast<std::size_t>(root)].parent; l >= 0;
       l = model.links[static_cast<std::size_t>(l)].parent) {
    int seg = -1;
    for (int s = 0; s < model.num_robot_segments && seg < 0; ++s)
      if (model.segments[static_cast<std::size_t>(s)].link == l) seg = s;
    if (seg >= 0) {
      mask |= std::uint64_t{1} << seg;
      break;
    }
  }
  return mask;
}

std::vector<int> drivenJoints(const Model& model, const ControllerModel& cm) {
  std::vector<int> driven;
  for (const auto& arm : cm.arms)
    for (int i = 0; i < arm.n; ++i) driven.push_back(arm.q[i]);
  const WalkingPattern walking(model);
  for (const int j : walking.joints())
    if (std::find(driven.begin(), driven.end(), j) == driven.end()) driven.push_back(j);
  return driven;
}

OnboardController::OnboardController(const Model& model, const ControllerModel& cm, RobotPort& port,
                                     const Eigen::VectorXd& q0, const OnboardOptions& options)
    : model_(model),
      cm_(cm),
      port_(port),
      options_(options),
      data_(model, cm),
      integrator_(model, q0.size() == model.nq ? q0 : Eigen::VectorXd::Zero(model.nq)),
      walking_(model) {
  if (!(options.input_timeout > 0.0) || !std::isfinite(options.input_timeout))
    throw ConfigError(rangeError("input_timeout", options.input_timeout, "(0, inf) s"));
  if (!(options.max_target_distance > 0.0))
    throw ConfigError(rangeError("max_target_distance", options.max_target_distance, "(0, inf] m"));
  if (!(options.max_walk_speed > 0.0) || !std::isfinite(options.max_walk_speed))
    throw ConfigError(rangeError("max_walk_speed", options.max_walk_speed, "(0, inf) m/s"));
  if (q0.size() != model.nq)
    throw ConfigError("onboard controller: the initial configuration has " + std::to_string(q0.size()) +
                      " entries, the model '" + model.name + "' has " + std::to_string(model.nq) + " joints");
  for (int i = 0; i < model.nq; ++i)
    if (!std::isfinite(q0[i]))
      throw ConfigError("onboard controller: the initial position of joint '" + model.q_names[i] + "' is " +
                        std::to_string(q0[i]) + " (not finite)");
  q_measured_ = q0;
  q_command_ = q0;
  qdot_command_.setZero(model.nq);
  q_scratch_ = q0;
  driven_ = reflex::control::drivenJoints(model, cm);
}

int OnboardController::slotOf(const std::string& name) const noexcept {
  for (int s = 0; s < kBodySchemaSlots; ++s)
    if (data_.dist.slots[s].name[0] != '\0' && name.compare(data_.dist.slots[s].name.data()) == 0) return s;
  return -1;
}

int OnboardController::setHandTargets(const std::array<HandCommand, 2>& hands, double now) noexcept {
  ++report_.counts.targets_received;
  last_targets_rx_ = now;
  int rejected = 0;
  for (int a = 0; a < 2; ++a) {
    const HandCommand& h = hands[a];
    const bool given = h.status == HandStatus::kGiven;
    // Never followed; the hand keeps what it had. !(norm <= max): no NaN passes.
    if (given && !h.target_B.allFinite()) {
      ++rejected;
      reject(RejectCause::kHandTargetNotFinite);
      continue;
    }
    if (given && !(h.target_B.norm() <= options_.max_target_distance)) {
      ++rejected;
      reject(RejectCause::kHandTargetTooFar);
      continue;
    }
    input_.hands[a].status = h.status;
    if (given) input_.hands[a].target_B = h.target_B;
  }
  return rejected;
}

void OnboardController::setControlInput(const ControlInput& input, double now) noexcept {
  input_.hands = input.hands;
  priority_ = input.priority;
  if (input.reset_estop) reset_ = true;
  last_targets_rx_ = now;
}

bool OnboardController::holdHandsHere(double now) noexcept {
  if (!computeForwardKinematics(model_, data_.kin, q_command_)) return false;
  for (int a = 0; a < 2; ++a) {
    input_.hands[a].status = HandStatus::kGiven;
    input_.hands[a].target_B = data_.kin.X_B_L[cm_.arms[a].hand_link] * cm_.arms[a].hand_point_L;
  }
  last_targets_rx_ = now;
  return true;
}

const BodySchemaOutcome& OnboardController::changeBodySchema(const BodySchemaRequest& rq) noexcept {
  BodySchemaOutcome& out = schema_outcome_;
  out = BodySchemaOutcome{};
  static const std::string kEmpty;
  const std::string& name = rq.name ? *rq.name : kEmpty;
  const std::string& parent = rq.parent_link ? *rq.parent_link : kEmpty;
  const int known = slotOf(name);
  if (rq.operation == BodySchemaRequest::Operation::kDetach || !rq.enabled) {
    if (known < 0) return out;  // kUnknownName: nothing to take away
    detachBodySchemaSegment(data_.dist, known);
    BodySchemaSlot& freed = data_.dist.slots[known];
    freed.is_virtual = false;
    freed.motion_priority = 0;
    if (rq.operation == BodySchemaRequest::Operation::kDetach) freed.name[0] = '\0';  // the slot is free
    out.kind = BodySchemaOutcome::Kind::kDetached;
    out.slot = known;
    return out;
  }
  int slot = known;
  for (int s = 0; s < kBodySchemaSlots && slot < 0; ++s)
    if (data_.dist.slots[s].name[0] == '\0') slot = s;
  const int link = model_.linkIndex(parent);
  const Eigen::Vector3d& a = rq.a_L;
  const Eigen::Vector3d& b = rq.b_L;
  // Pairs never checked: the segment against its own link's segment, and a physical one (a grasped
  // object) against everything it touches by construction: every link rigidly attached to its link
  // (fixed joints, up or down: a second wrist link, a frame below the hand), every link below it (the
  // fingers that hold it) and the nearest link above its rigid body that has a segment (the wrist). A
  // virtual (gaze) line starts in the head.
  std::uint64_t ignore = 0;
  const int own = model_.segmentIndex(parent);
  if (own >= 0) ignore |= std::uint64_t{1} << own;
  if (rq.is_virtual) {
    const int head = model_.segmentIndex("head");
    if (head >= 0) ignore |= std::uint64_t{1} << head;
  } else if (link >= 0) {
    ignore |= graspIgnoreMask(model_, cm_, link);
  }
  // The boundary check (bounds: BodySchemaLimits), then the placement check at the expected configuration.
  out.check = checkBodySchemaSegment(model_, link, a, b, rq.radius, rq.is_virtual, BodySchemaLimits{});
  // A name longer than a slot holds (the bus never carries one: bus::kMaxKeyStringBytes) is refused
  // whole, never stored cut short (two names alike in their first 255 bytes would share a slot).
  const bool name_fits = name.size() <= kBodySchemaNameBytes;
  if (out.check.ok() && name_fits)
    out.attach =
        attachControllerSegment(model_, cm_, data_, slot, link, a, b, rq.radius, ignore, rq.is_virtual, q_command_);
  if (out.attach.attached) {
    BodySchemaSlot& held = data_.dist.slots[slot];  // attachControllerSegment set is_virtual
    held.motion_priority = rq.motion_priority;
    if (known < 0) {  // fits: name_fits; copied into the slot's own array, no allocation
      name.copy(held.name.data(), name.size());
      held.name[name.size()] = '\0';
    }
    out.kind = BodySchemaOutcome::Kind::kAttached;
    out.slot = slot;
    return out;
  }
  char* const line = out.text;
  const std::size_t size = sizeof(out.text);
  if (out.attach.refusing_pair >= 0) {  // control/README.md: a segment no arm can move away from
    out.kind = BodySchemaOutcome::Kind::kRejectedUnresolvable;
    reject(RejectCause::kSchemaUnresolvable);
    std::snprintf(
        line, size,
        "body-schema segment '%s' rejected: %.1f mm from '%s', which no arm can move away from it (link '%s')",
        name.c_str(), out.attach.distance * 1e3, model_.segments[out.attach.other_segment].name.c_str(),
        parent.c_str());
  } else if (out.check.ok() && !name_fits) {
    out.kind = BodySchemaOutcome::Kind::kRejectedCheck;
    reject(RejectCause::kSchemaBadSegment);
    std::snprintf(line, size,
                  "body-schema segment '%.40s...' rejected: its name has %zu bytes, more than %zu (link '%s')",
                  name.c_str(), name.size(), kBodySchemaNameBytes, parent.c_str());
  } else if (out.check.ok()) {
    out.kind = BodySchemaOutcome::Kind::kRejectedNoSlot;
    reject(RejectCause::kSchemaNoSlot);
    std::snprintf(line, size, "body-schema segment '%s' rejected: no free slot (link '%s')", name.c_str(),
                  parent.c_str());
  } else if (*out.check.key != '\0') {
    out.kind = BodySchemaOutcome::Kind::kRejectedCheck;
    reject(RejectCause::kSchemaBadSegment);
    std::snprintf(line, size, "body-schema segment '%s' rejected: %s: %g m > %s %g m (link '%s', %s)", name.c_str(),
                  describe(out.check.fault), out.check.value, out.check.key, out.check.limit, parent.c_str(),
                  rq.is_virtual ? "virtual" : "physical");
  } else {
    out.kind = BodySchemaOutcome::Kind::kRejectedCheck;
    reject(RejectCause::kSchemaBadSegment);
    std::snprintf(line, size, "body-schema segment '%s' rejected: %s (value %g, link '%s')", name.c_str(),
                  describe(out.check.fault), out.check.value, parent.c_str());
  }
  return out;
}

bool OnboardController::walkCommand(bool stop, double goal_x, double goal_y, double goal_yaw, double speed) noexcept {
  if (stop) {
    walking_.stop();
    return true;
  }
  if (!(std::isfinite(goal_x) && std::isfinite(speed) && speed > 0.0)) {
    reject(RejectCause::kWalkBadValue);
    return false;
  }
  // !(|v| <= tol): a NaN goal_y / goal_yaw is refused too (the walking pattern cannot honour it).
  if (!(std::abs(goal_y) <= kWalkGoalTolerance) || !(std::abs(goal_yaw) <= kWalkGoalTolerance)) {
    reject(RejectCause::kWalkUnsupportedGoal);
    return false;
  }
  const int heel = model_.qIndex("heel_x");
  const double x = heel >= 0 ? q_command_[heel] : 0.0;
  walking_.start(goal_x - x, std::min(speed, options_.max_walk_speed));
  walk_active_ = true;
  return true;
}

bool OnboardController::startWalking(double distance, double speed) noexcept {
  walk_active_ = true;
  return walking_.start(distance, speed);
}

const CycleReport& OnboardController::step(double now, double cycle_dt) noexcept {
  // !(0 < dt <= period), NaN included: one period (the timer's cycle).
  const double dt = cycle_dt > 0.0 && cycle_dt <= cm_.params.period ? cycle_dt : cm_.params.period;
  CycleReport& r = report_;
  ++r.counts.cycles;
  r.now = now;
  // Staleness: the target source is silent (no sample, no heartbeat) for input_timeout -> retract.
  const double last_sign = std::max(last_targets_rx_, last_source_heartbeat_);
  const bool stale_now = last_sign < 0.0 || now - last_sign > options_.input_timeout;
  if (stale_now && !stale_) ++r.counts.stale_events;
  stale_ = stale_now;
  r.inputs_stale = stale_;
  ControlInput in = input_;
  if (stale_) in.hands[kLeft].status = in.hands[kRight].status = HandStatus::kNoTarget;
  in.priority = priority_;
  if (in.priority == MotionPriority::kEqual) {  // a grasped object with priority makes its arm higher
    for (int s = 0; s < kBodySchemaSlots; ++s) {
      const BodySchemaSlot& slot = data_.dist.slots[s];
      if (!slot.enabled || slot.is_virtual || slot.motion_priority <= 0) continue;
      for (int a = 0; a < 2; ++a)
        if (cm_.arms[a].link_in_arm[slot.link])
          in.priority = a == kLeft ? MotionPriority::kLeftHigher : MotionPriority::kRightHigher;
    }
  }
  r.commands = in.hands;
  r.priority = in.priority;

  // The robot's measured state; without one nothing is computed and nothing commanded (the robot holds).
  const Eigen::VectorXd* q = port_.measuredPositions(now);
  if (q == nullptr || q->size() != model_.nq) {
    if (robot_ok_) ++r.counts.robot_stale_events;
    robot_ok_ = false;
    anchor_ = true;
    ++r.counts.robot_stale_cycles;
    r.robot_state_ok = false;
    r.walking_advanced = false;
    return r;  // the reset request waits for a cycle that computes
  }
  robot_ok_ = true;
  r.robot_state_ok = true;
  q_measured_ = *q;
  in.reset_estop = reset_;
  in.dt = dt;
  reset_ = false;
  if (anchor_) {  // first state, or the first after none: the robot held itself where it is measured
    for (int i = 0; i < model_.nq; ++i)
      q_command_[i] = std::clamp(q_measured_[i], model_.q_lower[i], model_.q_upper[i]);
    anchor_ = false;
  }

  // Control (allocation-free), then the plant step on a one-cycle integrator: the arm joints from the
  // measured state, the walking joints from the last command (walking owns them; a state never moves
  // them).
  const ControlResult cr = computeControl(model_, cm_, data_, q_measured_, in);
  integrator_.reset(q_measured_);
  for (const int j : walking_.joints())
    if (data_.arm_joint[static_cast<std::size_t>(j)] == 0) integrator_.setJointPosition(j, q_command_[j]);
  r.walking_advanced =
      stepPlant(model_, cm_, data_, cr, integrator_, walk_active_ ? &walking_ : nullptr, dt, q_scratch_);
  if (cr == ControlResult::kFrozen) {
    // e-stop latched: hold what was last commanded (q_command_ as it is), not what the state says.
  } else {
    q_command_ = integrator_.jointPositions();
  }
  // The command's bounds, whatever the state said: positions inside the limits, velocities within
  // v_max (the port rejects states further than stateLimitTolerance past a limit, so the two agree).
  for (int i = 0; i < model_.nq; ++i) {
    q_command_[i] = std::clamp(q_command_[i], model_.q_lower[i], model_.q_upper[i]);
    qdot_command_[i] = std::clamp((q_command_[i] - q_measured_[i]) / dt, -model_.v_max[i], model_.v_max[i]);
  }
  port_.command(q_command_, qdot_command_, dt);
  ++r.counts.computed_cycles;
  fillReport(cr);
  return r;
}

bool OnboardController::segmentMovesWithArm(int segment, int arm) const noexcept {
  const Segment& seg = model_.segments[static_cast<std::size_t>(segment)];
  const int link = seg.body_schema_slot
                       ? data_.dist.slots[static_cast<std::size_t>(segment - model_.num_robot_segments)].link
                       : seg.link;
  return link >= 0 && cm_.arms[static_cast<std::size_t>(arm)].link_in_arm[static_cast<std::size_t>(link)];
}

void OnboardController::fillReport(ControlResult result) noexcept {
  CycleReport& r = report_;
  r.result = result;
  r.estop = data_.estop;
  for (int a = 0; a < 2; ++a) {
    const ArmStatus& s = data_.arms[a];
    ArmReport& ar = r.arms[a];
    ar.f = s.f;
    ar.distance = s.distance;
    ar.zone = s.zone;
    ar.closest_pair = s.closest_pair;
    ar.segment_a = ar.segment_b = nullptr;
    if (s.closest_pair >= 0) {
      // The arm's own segment first (control.idl ArmStatus.closest_segment_a): the pair's second one
      // when only that one moves with this arm (Model::pairs orders the left arm before the right).
      const PairDistance& pd = data_.dist.pairs[static_cast<std::size_t>(s.closest_pair)];
      const bool b_is_arms = segmentMovesWithArm(pd.seg_b, a) && !segmentMovesWithArm(pd.seg_a, a);
      ar.segment_a = model_.segments[b_is_arms ? pd.seg_b : pd.seg_a].name.c_str();
      ar.segment_b = model_.segments[b_is_arms ? pd.seg_a : pd.seg_b].name.c_str();
    }
  }
  // Distances of this cycle (computed inside the controller for the measured q).
  r.min_distance = data_.closest_physical.distance;
  r.min_pair = data_.closest_physical.pair;
  r.virtual_distance = data_.closest_virtual.distance;
  r.virtual_pair = data_.closest_virtual.pair;
  r.arm_distance = data_.closest_between_arms.distance;  // exact under the broad phase
  r.counts.estop_count = data_.estop_count;
  r.counts.guard_count = data_.guard_count;
  r.counts.walking_holds = data_.walking_hold_count;
  r.counts.bad_input_count = data_.bad_input_count;
}

}  // namespace reflex::control
