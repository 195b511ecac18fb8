#include "reflex/modules/scripted.hpp"

#include "reflex/common/files.hpp"

#include <cmath>
#include <fstream>
#include <sstream>

namespace reflex::modules {

namespace {
constexpr double kMaxTargetDistance = 2.0;  // [m] the controller rejects farther targets

std::string trim(const std::string& s) {
  const auto b = s.find_first_not_of(" \t\r");
  if (b == std::string::npos) return "";
  const auto e = s.find_last_not_of(" \t\r");
  return s.substr(b, e - b + 1);
}

void checkOrder(std::vector<TimelineEvent>& events, const std::string& where, double t) {
  if (!events.empty() && t < events.back().t) {
    std::ostringstream m;
    m << where << ": events out of time order: t " << t << " after t " << events.back().t;
    throw ConfigError(m.str());
  }
}

ArmPriority parsePriority(const std::string& s, bool& ok) {
  ok = true;
  if (s == "left") return ArmPriority::kLeftHigher;
  if (s == "right") return ArmPriority::kRightHigher;
  if (s == "equal") return ArmPriority::kEqual;
  ok = false;
  return ArmPriority::kEqual;
}
}  // namespace

std::vector<TimelineEvent> readTimelineCsv(const std::string& path) {
  if (const std::string why = common::inputFileProblem(path); !why.empty())
    throw ConfigError("timeline file " + why);  // a FIFO or device would block or never end
  std::ifstream in(path);
  if (!in) throw ConfigError("timeline file '" + path + "' cannot be opened");
  std::vector<TimelineEvent> events;
  std::string line;
  int line_no = 0;
  bool header = false;
  while (std::getline(in, line)) {
    ++line_no;
    line = trim(line);
    if (line.empty() || line[0] == '#') continue;
    std::vector<std::string> cols;
    std::stringstream ss(line);
    std::string col;
    while (std::getline(ss, col, ',')) cols.push_back(trim(col));
    while (cols.size() < 5) cols.emplace_back();
    const std::string where = path + ":" + std::to_string(line_no);
    if (!header) {
      if (cols.size() != 5 || cols[0] != "t" || cols[1] != "hand" || cols[2] != "x" || cols[3] != "y" || cols[4] != "z")
        throw ConfigError(where + ": expected the header 't,hand,x,y,z', got '" + line + "'");
      header = true;
      continue;
    }
    if (cols.size() != 5) throw ConfigError(where + ": expected 5 columns (t,hand,x,y,z), got '" + line + "'");
    auto number = [&](int c, const char* name) {
      std::size_t used = 0;
      double v = 0.0;
      try {
        v = std::stod(cols[c], &used);
      } catch (const std::exception&) {
        used = 0;
      }
      if (used == 0 || used != cols[c].size() || !std::isfinite(v))
        throw ConfigError(where + ": column '" + name + "': expected a finite number, got '" + cols[c] + "'");
      return v;
    };
    TimelineEvent e;
    e.t = number(0, "t");
    if (e.t < 0.0) throw ConfigError(where + ": column 't': expected a time >= 0, got '" + cols[0] + "'");
    if (cols[1] == "priority") {
      bool ok = false;
      e.kind = TimelineEvent::Kind::kPriority;
      e.priority = parsePriority(cols[2], ok);
      if (!ok)
        throw ConfigError(where + ": column 'x': expected left, right or equal for a priority, got '" + cols[2] + "'");
    } else if (cols[1] == "left" || cols[1] == "right") {
      e.hand = cols[1] == "left" ? Hand::kLeft : Hand::kRight;
      if (cols[2] == "none") {
        e.target = HandTarget::none();
      } else {
        const Eigen::Vector3d p(number(2, "x"), number(3, "y"), number(4, "z"));
        if (p.norm() > kMaxTargetDistance)
          throw ConfigError(where + ": target '" + cols[2] + "," + cols[3] + "," + cols[4] +
                            "' is farther than 2 m from the base origin");
        e.target = HandTarget::at(p);
      }
    } else {
      throw ConfigError(where + ": column 'hand': expected left, right or priority, got '" + cols[1] + "'");
    }
    checkOrder(events, where, e.t);
    events.push_back(e);
  }
  if (!header) throw ConfigError(path + ": empty timeline (expected the header 't,hand,x,y,z')");
  if (events.empty()) throw ConfigError(path + ": the timeline has no events");
  return events;
}

std::vector<TimelineEvent> readTimelineYaml(const ConfigNode& node, const std::string& key) {
  std::vector<TimelineEvent> events;
  for (const ConfigNode& e : node.list(key)) {
    e.rejectUnknown({"t", "left", "right", "priority"});
    const double t = e.requiredNumber("t", 0.0, 1e6);
    if (!e.has("left") && !e.has("right") && !e.has("priority")) e.failAt("t", "event without left, right or priority");
    checkOrder(events, e.where("t"), t);
    for (Hand h : kBothHands) {
      const char* k = handName(h);
      if (!e.has(k)) continue;
      TimelineEvent ev;
      ev.t = t;
      ev.hand = h;
      const YAML::Node v = e.raw(k);
      if (v.IsScalar() && v.Scalar() == "none") {
        ev.target = HandTarget::none();
      } else {
        const Eigen::Vector3d p = e.vec3(k, Eigen::Vector3d::Zero());
        if (p.norm() > kMaxTargetDistance)
          e.fail(k, "target farther than 2 m from the base origin", "[x, y, z] within 2 m, or none");
        ev.target = HandTarget::at(p);
      }
      events.push_back(ev);
    }
    if (e.has("priority")) {
      TimelineEvent ev;
      ev.t = t;
      ev.kind = TimelineEvent::Kind::kPriority;
      bool ok = false;
      ev.priority = parsePriority(e.string("priority", ""), ok);
      if (!ok) e.fail("priority", "unknown value", "one of left, right, equal");
      events.push_back(ev);
    }
  }
  return events;
}

void ScriptedModule::configure(const ConfigNode& c, const RobotState& /*robot*/) {
  c.rejectUnknown({"timeline", "file", "loop_period", "step_period"});
  if (c.has("timeline") == c.has("file"))
    c.failAt("timeline", "give exactly one of 'timeline' (inline list) or 'file'");
  if (c.has("timeline")) {
    events_ = readTimelineYaml(c, "timeline");
  } else {
    const std::string path = c.resolvePath(c.string("file", ""));
    if (path.size() >= 4 && path.compare(path.size() - 4, 4, ".csv") == 0) {
      events_ = readTimelineCsv(path);
    } else {
      events_ = readTimelineYaml(ConfigNode::loadFile(path), "timeline");
    }
  }
  if (events_.empty())
    c.fail(c.has("timeline") ? "timeline" : "file", "the timeline has no events", "at least one event");
  loop_period_ = c.number("loop_period", 0.0, 0.0, 1e6);
  if (loop_period_ > 0.0 && loop_period_ <= events_.back().t)
    c.fail("loop_period", "not longer than the last event's time", "0 (no loop) or longer than the last event's time");
  step_period_ = c.number("step_period", step_period_, 0.001, 1.0);
  for (const auto& e : events_) {
    if (e.kind == TimelineEvent::Kind::kHand)
      hands_[handIndex(e.hand)] = true;
    else
      priority_ = true;
  }
}

Claims ScriptedModule::claims() const {
  Claims c;
  c.hands[0] = hands_[0];
  c.hands[1] = hands_[1];
  c.priority = priority_;
  return c;
}

void ScriptedModule::start(ModuleContext& ctx) {
  t0_ = ctx.now().t;
  next_ = 0;
  loops_ = 0;
  advance(ctx);
}

void ScriptedModule::step(ModuleContext& ctx) { advance(ctx); }

void ScriptedModule::advance(ModuleContext& ctx) {
  auto applyUntil = [&](double t) {
    while (next_ < events_.size() && events_[next_].t <= t) {
      const TimelineEvent& e = events_[next_++];
      if (e.kind == TimelineEvent::Kind::kHand)
        ctx.setHand(e.hand, e.target);
      else
        ctx.setPriority(e.priority);
    }
  };
  double t = ctx.now().t - t0_;
  if (loop_period_ > 0.0 && t >= loop_period_) {
    applyUntil(loop_period_);  // finish the lap, then start the next one
    const double laps = std::floor(t / loop_period_);
    t0_ += laps * loop_period_;
    t -= laps * loop_period_;
    next_ = 0;
    loops_ += static_cast<int>(laps);
  }
  applyUntil(t);
}

void ScriptedModule::stop(ModuleContext& ctx) {
  for (Hand h : kBothHands)
    if (hands_[handIndex(h)]) ctx.setHand(h, HandTarget::none());
  if (priority_) ctx.setPriority(ArmPriority::kEqual);
}

std::string ScriptedModule::status() const {
  return "event " + std::to_string(next_) + "/" + std::to_string(events_.size()) + " loops=" + std::to_string(loops_);
}

}  // namespace reflex::modules
