#include "reflex/modules/host.hpp"

#include "reflex/modules/module_call.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <set>
#include <sstream>
#include <stdexcept>
#include <tuple>

namespace reflex::modules {

const char* priorityName(ArmPriority p) {
  switch (p) {
    case ArmPriority::kLeftHigher: return "left_higher";
    case ArmPriority::kRightHigher: return "right_higher";
    case ArmPriority::kEqual: break;
  }
  return "equal";
}

HostConfig parseHostConfig(const ConfigNode& root, const ModuleRegistry& registry) {
  root.rejectUnknown({"process", "robot", "inputs", "tick_period", "joint_state_period", "plugins", "modules"});
  // `plugins` is read (and loaded) before this, by loadModulePlugins (plugin.hpp): types are checked below.
  HostConfig c;
  c.file = root.file();
  c.process = root.string("process", c.process);
  c.robot = readRobotConfig(root.child("robot"));
  const ConfigNode in = root.child("inputs");
  in.rejectUnknown(
      {"known_objects", "future_tolerance", "max_range", "frames", "object_sources", "joint_state_sources"});
  c.inputs.known_objects = in.strings("known_objects", {});
  c.inputs.future_tolerance = in.number("future_tolerance", c.inputs.future_tolerance, 0.0, 60.0);
  c.inputs.max_range = in.number("max_range", c.inputs.max_range, 0.1, 100.0);
  c.inputs.frames = in.strings("frames", c.inputs.frames);
  if (c.inputs.frames.empty()) in.fail("frames", "names no frame", "at least one base frame");
  // Writers whose samples are accepted (identities, never a name inside the message).
  for (auto [key, list, example] :
       {std::make_tuple("object_sources", &c.inputs.object_sources, "vision"),
        std::make_tuple("joint_state_sources", &c.inputs.joint_state_sources, "controller")}) {
    *list = in.strings(key, *list);
    if (list->empty())
      in.fail(key, "names no identity",
              std::string("at least one identity whose samples are accepted (e.g. ") + example + ")");
    for (const auto& src : *list) {
      if (src.empty()) in.fail(key, "holds an empty identity name", "a list of non-empty identity names");
    }
  }
  c.tick_period = root.number("tick_period", c.tick_period, 0.001, 1.0);
  c.joint_state_period = root.number("joint_state_period", c.joint_state_period, 0.0, 10.0);
  if (!root.has("modules")) root.fail("modules", "missing", "a list of modules");
  std::set<std::string> names;
  for (const ConfigNode& m : root.list("modules")) {
    m.rejectUnknown({"name", "type", "config"});
    ModuleEntry e{"", m.string("type", ""), m.child("config")};
    if (e.type.empty()) m.fail("type", "missing", "one of " + registry.typeList());
    if (!registry.has(e.type)) m.fail("type", "unknown module type", "one of " + registry.typeList());
    e.name = m.string("name", e.type);
    if (!names.insert(e.name).second) m.fail("name", "duplicate module name", "a name no other module has");
    c.modules.push_back(std::move(e));
  }
  if (c.modules.empty()) root.fail("modules", "the list of modules is empty", "at least one module");
  return c;
}

HostConfig loadHostConfig(const std::string& path, const ModuleRegistry& registry) {
  return parseHostConfig(ConfigNode::loadFile(path), registry);
}

namespace {

// The calls the host makes into a module.
enum ModuleCall {
  kFactory,
  kConfigure,
  kClaims,
  kStepPeriod,
  kStart,
  kOnObjects,
  kOnJointState,
  kStep,
  kStop,
  kStatus,
  kDestructor,
  kCallCount
};
constexpr std::array<const char*, kCallCount> kCallNames = {
    "the factory",    "configure()", "claims()", "stepPeriod()", "start()",       "onObjects()",
    "onJointState()", "step()",      "stop()",   "status()",     "the destructor"};

}  // namespace

// One module with its claims, step timer and context.
struct BehaviorHost::Slot {
  std::unique_ptr<Module> module;
  std::string type;
  Claims claims;
  double next_step = 0.0;
  std::unique_ptr<Context> ctx;
  // "step() of module 'x' (type t, plugin /abs/lib.so)", one per call, written before the first call:
  // the call mark points at them, and a signal handler or a watchdog cannot format a string.
  std::array<std::string, kCallCount> what;
};

namespace {

// Runs `fn` (one call into the module of `slot`) marked and guarded: see host.hpp's opening block.
template <class Slot, class Fn>
auto callModule(const Slot& slot, ModuleCall call, Fn&& fn) -> decltype(fn()) {
  const std::string& what = slot.what[call];
  const ModuleCallMark mark(what.c_str());
  try {
    return fn();
  } catch (const ConfigError& e) {
    if (call == kFactory || call == kConfigure) throw;
    throw ModuleError(what + " threw: " + e.what());
  } catch (const std::exception& e) {
    throw ModuleError(what + " threw: " + e.what());
  } catch (...) {
    throw ModuleError(what + " threw something that is not a std::exception (an int, a string literal, ...)");
  }
}

}  // namespace

class BehaviorHost::Context final : public ModuleContext {
 public:
  Context(BehaviorHost& host, Slot& slot) : host_(host), slot_(slot) {}
  Now current;

  const Now& now() const override { return current; }
  const RobotState& robot() const override { return *host_.robot_; }

  void setHand(Hand hand, const HandTarget& target) override {
    if (!slot_.claims.hands[handIndex(hand)]) denied(std::string("the ") + handName(hand) + " hand");
    HandTarget t = target;
    if (t.given && !t.p_B.allFinite()) {
      ++host_.stats_.outputs_rejected;
      host_.logLine(slot_.module->name() + ": non-finite " + handName(hand) + " hand target replaced by 'no target'");
      t = HandTarget::none();
    }
    if (!t.given) t = HandTarget::none();
    HandTarget& cur = host_.hands_[handIndex(hand)];
    if (cur != t) {
      cur = t;
      host_.hands_dirty_ = true;
    }
  }
  void setPriority(ArmPriority p) override {
    if (!slot_.claims.priority) denied("the motion priority");
    if (host_.priority_ != p) {
      host_.priority_ = p;
      host_.priority_dirty_ = true;
    }
  }
  void attachSegment(const SegmentSpec& s) override {
    checkSegment(s.name);
    const bool ok = s.radius > 0.0 && std::isfinite(s.radius) && s.a_L.allFinite() && s.b_L.allFinite() &&
                    !s.parent_link.empty() && host_.robot_->model().linkIndex(s.parent_link) >= 0;
    if (!ok) {
      ++host_.stats_.outputs_rejected;
      host_.logLine(slot_.module->name() + ": segment '" + s.name + "' not attached (bad radius, endpoint or link '" +
                    s.parent_link + "')");
      return;
    }
    auto it = host_.segments_.find(s.name);
    if (it != host_.segments_.end() && it->second == s) return;
    host_.segments_[s.name] = s;
    host_.sink_.segmentAttached(s);
    ++host_.stats_.segment_changes_published;
  }
  void detachSegment(const std::string& name) override {
    checkSegment(name);
    if (host_.segments_.erase(name) == 0) return;
    host_.sink_.segmentDetached(name);
    ++host_.stats_.segment_changes_published;
  }
  void setWalk(const WalkGoal& g) override {
    if (!slot_.claims.walk) denied("walking");
    if (!g.stop && !(std::isfinite(g.x) && std::isfinite(g.y) && std::isfinite(g.yaw) && std::isfinite(g.speed) &&
                     g.speed > 0.0)) {
      ++host_.stats_.outputs_rejected;
      host_.logLine(slot_.module->name() + ": walking goal with a non-finite value or speed <= 0 not sent");
      return;
    }
    if (host_.walk_ && *host_.walk_ == g) return;
    host_.walk_ = g;
    host_.sink_.walk(g);
    ++host_.stats_.walk_published;
  }
  void log(const std::string& line) override { host_.logLine(slot_.module->name() + ": " + line); }

 private:
  [[noreturn]] void denied(const std::string& what) const {
    throw std::logic_error("module '" + slot_.module->name() + "' wrote " + what + " without claiming it");
  }
  void checkSegment(const std::string& name) const {
    const auto& segs = slot_.claims.segments;
    if (std::find(segs.begin(), segs.end(), name) == segs.end()) denied("segment '" + name + "'");
  }

  BehaviorHost& host_;
  Slot& slot_;
};

BehaviorHost::BehaviorHost(const HostConfig& config, const ModuleRegistry& registry, OutputSink& sink, LogFn log,
                           const std::string& only_module)
    : process_name_(config.process),
      inputs_(config.inputs),
      joint_state_period_(config.joint_state_period),
      sink_(sink),
      log_(std::move(log)) {
  if (!log_) log_ = [](const std::string& line) { std::fprintf(stderr, "%s\n", line.c_str()); };
  robot_ = std::make_unique<RobotState>(config.robot);
  std::string names;
  for (const ModuleEntry& e : config.modules) {
    names += (names.empty() ? "" : ", ") + e.name;
    if (!only_module.empty() && e.name != only_module) continue;
    auto slot = std::make_unique<Slot>();
    slot->type = e.type;
    const auto plugin = config.type_plugins.find(e.type);
    const std::string origin =
        plugin == config.type_plugins.end() ? std::string("built in") : "plugin " + plugin->second;
    for (int c = 0; c < kCallCount; ++c)
      slot->what[c] = std::string(kCallNames[c]) + " of module '" + e.name + "' (type " + e.type + ", " + origin + ")";
    slot->module = callModule(*slot, kFactory, [&] { return registry.create(e.type, e.name); });
    callModule(*slot, kConfigure, [&] { slot->module->configure(e.config, *robot_); });
    slot->claims = callModule(*slot, kClaims, [&] { return slot->module->claims(); });
    slot->ctx = std::make_unique<Context>(*this, *slot);
    slots_.push_back(std::move(slot));
  }
  if (!only_module.empty() && slots_.empty()) {
    throw ConfigError(config.file + ": no module named '" + only_module + "' (modules in this file: " + names + ")");
  }
  if (!only_module.empty()) process_name_ = only_module;
  // No output may have two writers in one process.
  std::map<std::string, std::string> owner;
  auto claim = [&](const std::string& what, const Slot& s) {
    auto [it, fresh] = owner.emplace(what, s.module->name());
    if (!fresh) {
      throw ConfigError(config.file + ": modules '" + it->second + "' and '" + s.module->name() + "' both write " +
                        what + " (one output, one module)");
    }
  };
  for (const auto& s : slots_) {
    const Claims& c = s->claims;
    for (Hand h : kBothHands) {
      if (c.hands[handIndex(h)]) {
        claim(std::string("the ") + handName(h) + " hand target", *s);
        claims_.hands[handIndex(h)] = true;
      }
    }
    if (c.priority) claim("the motion priority", *s);
    if (c.walk) claim("the walking command", *s);
    for (const auto& seg : c.segments) {
      claim("body-schema segment '" + seg + "'", *s);
      claims_.segments.push_back(seg);
    }
    claims_.priority |= c.priority;
    claims_.walk |= c.walk;
    claims_.objects |= c.objects;
  }
}

BehaviorHost::~BehaviorHost() {
  // Last built, first destroyed (as stop()); each destructor marked, since it is the module's code too.
  for (auto it = slots_.rbegin(); it != slots_.rend(); ++it) {
    const ModuleCallMark mark((*it)->what[kDestructor].c_str());
    (*it)->module.reset();
  }
}

std::vector<std::string> BehaviorHost::moduleNames() const {
  std::vector<std::string> out;
  for (const auto& s : slots_) out.push_back(s->module->name());
  return out;
}

void BehaviorHost::logLine(const std::string& line) { log_(process_name_ + ": " + line); }

void BehaviorHost::logRejected(std::uint64_t count, const std::string& line) {
  // The first few of each kind, then every 100th: a flood of bad samples cannot flood the log.
  if (count <= 5 || count % 100 == 0) logLine(line + " (" + std::to_string(count) + " so far)");
}

void BehaviorHost::flush() {
  if (hands_dirty_) {
    sink_.handTargets(hands_[0], hands_[1]);
    ++stats_.hand_targets_published;
    hands_dirty_ = false;
  }
  if (priority_dirty_) {
    sink_.motionPriority(priority_);
    ++stats_.priority_published;
    priority_dirty_ = false;
  }
}

void BehaviorHost::start(const Now& now) {
  if (running_ || stopped_) throw std::logic_error("BehaviorHost::start called twice");
  running_ = true;
  // The hands and the priority this process owns start as "no target" / equal, published once.
  hands_dirty_ = claims_.hands[0] || claims_.hands[1];
  priority_dirty_ = claims_.priority;
  for (auto& s : slots_) {
    s->ctx->current = now;
    callModule(*s, kStart, [&] { s->module->start(*s->ctx); });
    s->next_step = now.t + callModule(*s, kStepPeriod, [&] { return s->module->stepPeriod(); });
  }
  flush();
}

void BehaviorHost::onObjects(const ObjectsFrame& frame, const Now& now) {
  if (!running_) return;
  ++stats_.frames_received;
  // The writer first: a frame from a writer the configuration does not name is never looked at.
  const auto& sources = inputs_.object_sources;
  if (std::find(sources.begin(), sources.end(), frame.source) == sources.end()) {
    ++stats_.frames_rejected_source;
    std::string accepted;
    for (const auto& s : sources) accepted += (accepted.empty() ? "'" : ", '") + s + "'";
    logRejected(stats_.frames_rejected_source,
                "object targets frame " + std::to_string(frame.image_index) + " rejected: written by " +
                    (frame.source.empty() ? std::string("an unknown participant") : "'" + frame.source + "'") +
                    ", not one of inputs.object_sources (" + accepted + ")");
    return;
  }
  const double tol_ns = inputs_.future_tolerance * 1e9;
  const auto ahead = [&](std::int64_t stamp) {
    return stamp != 0 && static_cast<double>(stamp - now.wall_ns) > tol_ns;
  };
  if (ahead(frame.stamp_ns) || ahead(frame.capture_stamp_ns)) {
    ++stats_.frames_rejected_future;
    std::ostringstream m;
    m << "object targets frame " << frame.image_index << " rejected: stamped "
      << 1e-9 * static_cast<double>(std::max(frame.stamp_ns, frame.capture_stamp_ns) - now.wall_ns)
      << " s in the future (tolerance " << inputs_.future_tolerance << " s)";
    logRejected(stats_.frames_rejected_future, m.str());
    return;
  }
  const auto& frames = inputs_.frames;
  if (std::find(frames.begin(), frames.end(), frame.frame_id) == frames.end()) {
    ++stats_.frames_rejected_frame;
    std::string accepted;
    for (const auto& f : frames) accepted += (accepted.empty() ? "'" : ", '") + f + "'";
    logRejected(stats_.frames_rejected_frame, "object targets frame " + std::to_string(frame.image_index) +
                                                  " rejected: unknown frame_id '" + frame.frame_id +
                                                  "' (accepted: " + accepted + ")");
    return;
  }
  scratch_.stamp_ns = frame.stamp_ns;
  scratch_.capture_stamp_ns = frame.capture_stamp_ns;
  scratch_.image_index = frame.image_index;
  scratch_.source = frame.source;
  scratch_.objects.clear();
  const auto& known = inputs_.known_objects;
  for (const ObjectObservation& o : frame.objects) {
    if (!o.p_B.allFinite() || !std::isfinite(o.confidence) || o.confidence < 0.0 || o.confidence > 1.0) {
      ++stats_.objects_rejected_invalid;
      logRejected(stats_.objects_rejected_invalid,
                  "object '" + o.name + "' rejected: non-finite position or confidence outside [0, 1]");
    } else if (o.name.empty() || (!known.empty() && std::find(known.begin(), known.end(), o.name) == known.end())) {
      ++stats_.objects_rejected_unknown;
      logRejected(stats_.objects_rejected_unknown,
                  "object '" + o.name + "' (tag " + std::to_string(o.tag_id) + ") rejected: unknown object");
    } else if (o.p_B.norm() > inputs_.max_range) {
      ++stats_.objects_rejected_range;
      logRejected(stats_.objects_rejected_range, "object '" + o.name + "' rejected: farther than max_range");
    } else if (std::any_of(scratch_.objects.begin(), scratch_.objects.end(),
                           [&](const ObjectObservation& a) { return a.name == o.name; })) {
      ++stats_.objects_rejected_duplicate;
      logRejected(stats_.objects_rejected_duplicate, "object '" + o.name + "' rejected: twice in one frame");
    } else {
      ++stats_.objects_accepted;
      scratch_.objects.push_back(o);
    }
  }
  for (auto& s : slots_) {
    if (!s->claims.objects) continue;
    s->ctx->current = now;
    callModule(*s, kOnObjects, [&] { s->module->onObjects(scratch_, *s->ctx); });
  }
  flush();
}

void BehaviorHost::onJointState(const JointStateSample& js, const Now& now) {
  if (!running_) return;
  ++stats_.joint_states;
  const auto& sources = inputs_.joint_state_sources;
  if (std::find(sources.begin(), sources.end(), js.source) == sources.end()) {
    ++stats_.joint_states_rejected_source;
    logRejected(stats_.joint_states_rejected_source,
                "joint state rejected: written by " +
                    (js.source.empty() ? std::string("an unknown participant") : "'" + js.source + "'") +
                    ", not one of inputs.joint_state_sources");
    return;
  }
  if (!robot_->update(js)) {
    ++stats_.joint_states_rejected;
    logRejected(stats_.joint_states_rejected, "joint state rejected: names/positions mismatch or non-finite value");
    return;
  }
  if (now.t - last_joint_dispatch_ < joint_state_period_) return;
  last_joint_dispatch_ = now.t;
  for (auto& s : slots_) {
    s->ctx->current = now;
    callModule(*s, kOnJointState, [&] { s->module->onJointState(*s->ctx); });
  }
  flush();
}

void BehaviorHost::tick(const Now& now) {
  if (!running_) return;
  for (auto& s : slots_) {
    const double period = callModule(*s, kStepPeriod, [&] { return s->module->stepPeriod(); });
    if (period <= 0.0 || now.t < s->next_step) continue;
    s->ctx->current = now;
    callModule(*s, kStep, [&] { s->module->step(*s->ctx); });
    s->next_step += period;
    if (s->next_step <= now.t) s->next_step = now.t + period;  // missed steps are skipped, not queued
  }
  flush();
}

void BehaviorHost::stop(const Now& now) {
  if (!running_) return;
  for (auto it = slots_.rbegin(); it != slots_.rend(); ++it) {
    Slot& s = **it;
    s.ctx->current = now;
    callModule(s, kStop, [&] { s.module->stop(*s.ctx); });
    // Whatever the module left behind is removed here, and reported.
    for (Hand h : kBothHands) {
      if (s.claims.hands[handIndex(h)] && hands_[handIndex(h)].given) {
        ++stats_.forced_cleanups;
        logLine(s.module->name() + " left its " + handName(h) + " hand with a target at stop; set to 'no target'");
        s.ctx->setHand(h, HandTarget::none());
      }
    }
    if (s.claims.priority && priority_ != ArmPriority::kEqual) {
      ++stats_.forced_cleanups;
      logLine(s.module->name() + " left the motion priority set at stop; set to equal");
      s.ctx->setPriority(ArmPriority::kEqual);
    }
    for (const auto& name : s.claims.segments) {
      if (segments_.count(name)) {
        ++stats_.forced_cleanups;
        logLine(s.module->name() + " left segment '" + name + "' attached at stop; detached");
        s.ctx->detachSegment(name);
      }
    }
    if (s.claims.walk && walk_ && !walk_->stop) {
      ++stats_.forced_cleanups;
      logLine(s.module->name() + " left walking on at stop; stopped");
      WalkGoal g = *walk_;
      g.stop = true;
      s.ctx->setWalk(g);
    }
  }
  flush();
  running_ = false;
  stopped_ = true;
}

std::string BehaviorHost::status() const {
  std::ostringstream m;
  for (const auto& s : slots_) {
    const std::string st = callModule(*s, kStatus, [&] { return s->module->status(); });
    m << s->module->name() << (st.empty() ? "" : "[" + st + "]") << " ";
  }
  m << "frames=" << stats_.frames_received << " objects=" << stats_.objects_accepted << " rejected="
    << stats_.rejectedObjects() + stats_.frames_rejected_future + stats_.frames_rejected_frame +
           stats_.frames_rejected_source
    << " joint_states=" << stats_.joint_states;
  return m.str();
}

}  // namespace reflex::modules
