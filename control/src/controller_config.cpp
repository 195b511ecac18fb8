#include "reflex/control/controller.hpp"

#include "reflex/common/yaml_reader.hpp"
#include "reflex/control/distance.hpp"
#include "reflex/control/kinematics.hpp"

#include <cerrno>
#include <cstring>
#include <sys/stat.h>

#include <cmath>
#include <iomanip>
#include <limits>
#include <set>
#include <sstream>
#include <utility>

namespace reflex::control {
namespace {

/// Every numeric key of the controller YAML and the ControllerParams field it sets.
constexpr std::pair<const char*, double ControllerParams::*> kParamFields[] = {
    {"d_a", &ControllerParams::d_a},
    {"d_b", &ControllerParams::d_b},
    {"d_r", &ControllerParams::d_r},
    {"period", &ControllerParams::period},
    {"k_virtual", &ControllerParams::k_virtual},
    {"alpha_ca", &ControllerParams::alpha_ca},
    {"d_safe", &ControllerParams::d_safe},
    {"alpha_t", &ControllerParams::alpha_t},
    {"alpha_jla", &ControllerParams::alpha_jla},
    {"alpha_rest", &ControllerParams::alpha_rest},
    {"damping", &ControllerParams::damping},
    {"reach_gain", &ControllerParams::reach_gain},
    {"max_task_speed", &ControllerParams::max_task_speed},
    {"trajectory_speed", &ControllerParams::trajectory_speed},
    {"estop_release_margin", &ControllerParams::estop_release_margin},
    {"guard_rate", &ControllerParams::guard_rate},
    {"guard_margin", &ControllerParams::guard_margin},
    {"predict_margin", &ControllerParams::predict_margin}};

std::string str(double v) {
  std::ostringstream os;
  os << std::setprecision(15) << v;
  return os.str();
}

[[noreturn]] void raiseConfigError(const std::string& message) { throw ConfigError(message); }

ArmConfig defaultArm(const std::string& side) {
  ArmConfig arm;
  const std::string s = side.substr(0, 1);
  arm.name = side;
  arm.joints = {s + "_shoulder_pitch", s + "_shoulder_roll", s + "_shoulder_yaw", s + "_elbow", s + "_wrist"};
  arm.hand_link = s + "_hand";
  arm.hand_point_L = Eigen::Vector3d(0, 0, -0.06);
  const double out = side == "left" ? 1.0 : -1.0;
  arm.rest = {0.15, out * 0.25, 0.0, -0.5, 0.0};
  return arm;
}

}  // namespace

ControllerConfig defaultControllerConfig() {
  ControllerConfig config;
  config.arms[kLeft] = defaultArm("left");
  config.arms[kRight] = defaultArm("right");
  return config;
}

std::vector<ParamRange> controllerParamRanges(const ControllerParams& p) {
  // Table order is check order: a bound that depends on other keys comes after them, so the
  // first error names the key that is out of its own range.
  const double gap = p.d_b - p.d_r;
  return {
      {"d_r", p.d_r, 0.0, true, "0", 0.05, false, "0.05", "m",
       "the red zone: a positive distance, at most 5 cm (the e-stop fires below it)"},
      {"d_b", p.d_b, p.d_r, true, "d_r", 0.1, false, "0.1", "m", "zones ordered d_r < d_b < d_a (Eq. 13)"},
      {"d_a", p.d_a, p.d_b, true, "d_b", 0.2, false, "0.2", "m",
       "zones ordered d_r < d_b < d_a; at most 20 cm (every pair below it is merged, Eq. 17)"},
      {"d_safe", p.d_safe, p.d_a, false, "d_a", 0.5, false, "0.5", "m",
       "Eq. 5 acts on pairs below d_safe: it must include the yellow zone, and at most 0.5 m"},
      {"period", p.period, 0.001, false, "0.001", 0.1, false, "0.1", "s",
       "1 kHz .. 10 Hz: a cycle computes in well under 1 ms; shorter periods are overruns every cycle"},
      {"k_virtual", p.k_virtual, 0.5, false, "0.5", 0.5 / p.period, false, "0.5 / period", "1/s",
       "the yellow zone must separate pairs (>= 0.5/s), and k * period <= 0.5 so one cycle never "
       "moves more than half the way to d_a"},
      {"alpha_ca", p.alpha_ca, 0.0, false, "0", 100.0, false, "100", "1/(m s)", "Eq. 5 gradient step; 0 disables it"},
      {"alpha_t", p.alpha_t, 1.0, false, "1", 1.0 / p.period, false, "1 / period", "1/s",
       "Eq. 12 is the only reaching term inside the yellow zone (0 never reaches there); "
       "alpha_t * period <= 1 keeps the discrete gradient step from overshooting"},
      {"alpha_jla", p.alpha_jla, 0.0, false, "0", 10.0, false, "10", "1/s", "Eq. 4 gradient step; 0 disables it"},
      {"alpha_rest", p.alpha_rest, 0.0, false, "0", 1.0 / p.period, false, "1 / period", "1/s",
       "attraction to the rest posture (0: a hand without target stays where it is); "
       "alpha_rest * period <= 1 (no overshoot)"},
      {"damping", p.damping, 0.001, false, "0.001", 0.2, false, "0.2", "m",
       "singularity-robust inverse: at least 1 mm (0 is singular), at most 0.2 m"},
      {"reach_gain", p.reach_gain, 1.0, false, "1", 1.0 / p.period, false, "1 / period", "1/s",
       "trajectory tracking: 0 never corrects a tracking error; reach_gain * period <= 1 (no overshoot)"},
      {"max_task_speed", p.max_task_speed, 0.05, false, "0.05", 2.0, false, "2", "m/s",
       "the hand's task-space speed limit"},
      {"trajectory_speed", p.trajectory_speed, 0.01, false, "0.01", p.max_task_speed, false, "max_task_speed", "m/s",
       "the reference may not run faster than the hand is allowed to follow it"},
      {"guard_rate", p.guard_rate, 1.0, false, "1", 0.5 / p.period, false, "0.5 / period", "1/s",
       "safety filter: at least 1/s (else nothing can approach in the orange zone), and "
       "guard_rate * period <= 0.5 so two arms approaching each other cannot overshoot the floor"},
      {"guard_margin", p.guard_margin, 0.0, false, "0", gap, true, "d_b - d_r", "m",
       "the safety filter's floor d_r + guard_margin lies below d_b"},
      {"predict_margin", p.predict_margin, 0.0, false, "0", gap, true, "d_b - d_r", "m",
       "the predictive guard's floor d_r + predict_margin lies below d_b"},
      {"estop_release_margin", p.estop_release_margin, 0.0, false, "0", gap, false, "d_b - d_r", "m",
       "recovery ends when every pair is above d_r + this; the recovery's only motion is the virtual "
       "force, which fades towards d_a, so the release must lie inside the orange zone to be reachable"},
  };
}

bool ParamRange::contains(double v) const {
  if (!std::isfinite(v)) return false;
  const bool above = lo_open ? v > lo : v >= lo;
  const bool below = hi_open ? v < hi : v <= hi;
  return above && below;
}

std::string ParamRange::describe() const {
  std::string r = lo_open ? "(" : "[";
  r += lo_text == str(lo) ? lo_text : lo_text + " = " + str(lo);
  r += ", ";
  r += hi_text == str(hi) ? hi_text : hi_text + " = " + str(hi);
  r += hi_open ? ")" : "]";
  return r + " " + unit;
}

void validateControllerParams(const ControllerParams& p, const std::string& src) {
  for (const ParamRange& range : controllerParamRanges(p)) {
    if (range.contains(range.value)) continue;
    throw ConfigError(src + ": " + range.key + ": outside its range (value '" + str(range.value) + "', expected " +
                      range.describe() + ": " + range.why + ")");
  }
}

double* controllerParamField(ControllerParams& params, const std::string& key) {
  for (const auto& [name, field] : kParamFields)
    if (key == name) return &(params.*field);
  return nullptr;
}

ControllerConfig loadControllerConfig(const std::string& yaml_path) {
  ControllerConfig config = defaultControllerConfig();
  config.source = yaml_path;
  // An empty file is the defaults; errors name FILE:LINE:COL: KEY.PATH (control/docs/configuration.md).
  const common::ConfigNode root =
      common::ConfigNode::loadFile(yaml_path, "controller configuration", &raiseConfigError, /*allow_empty=*/true);
  ControllerParams& p = config.params;
  std::vector<std::string> known = {"avoidance", "camera_link", "arms"};
  for (const auto& [name, field] : kParamFields) known.emplace_back(name);
  root.rejectUnknown(known);
  // Any finite number here; the ranges (which depend on each other) are checked below, all keys read.
  constexpr double kAny = std::numeric_limits<double>::max();
  for (const auto& [name, field] : kParamFields) p.*field = root.number(name, p.*field, -kAny, kAny);
  const std::string mode = root.choice("avoidance", "three_dof", {"one_dof", "three_dof", "off"});
  if (root.has("avoidance"))
    p.mode = mode == "one_dof" ? AvoidanceMode::kOneDof
             : mode == "off"   ? AvoidanceMode::kOff
                               : AvoidanceMode::kThreeDof;
  config.camera_link = root.string("camera_link", config.camera_link);
  const common::ConfigNode arms = root.child("arms");
  arms.rejectUnknown({"left", "right"});
  for (const auto& [side, node] : arms.entries()) {
    ArmConfig& arm = config.arms[side == "left" ? kLeft : kRight];
    const common::ConfigNode f = arms.child(side);
    f.rejectUnknown({"joints", "hand_link", "hand_point", "rest"});
    arm.joints = f.strings("joints", arm.joints);
    arm.hand_link = f.string("hand_link", arm.hand_link);
    arm.hand_point_L = f.vec3("hand_point", arm.hand_point_L);
    if (f.has("rest")) arm.rest = f.at("rest", "a list of joint angles (rad)").asNumbers();
  }
  for (const ParamRange& range : controllerParamRanges(p)) {
    if (range.contains(range.value)) continue;
    const std::string expected = range.describe() + ": " + range.why;
    if (root.has(range.key)) root.fail(range.key, "outside its range", expected);
    // A default that another key's value moved out of range (k_virtual with a longer period).
    throw ConfigError(root.where(range.key) + ": outside its range (value '" + str(range.value) +
                      "', the default, expected " + expected + ")");
  }
  return config;
}

std::string defaultControllerConfigPath(const std::string& urdf_path) {
  return robotFileBeside(urdf_path, ".controller.yaml");
}

ControllerConfig loadControllerConfigFor(const std::string& urdf_path, const std::string& yaml_path) {
  struct stat st {};
  if (!yaml_path.empty()) {
    if (::stat(yaml_path.c_str(), &st) != 0)
      throw ConfigError("--controller '" + yaml_path + "': no such controller configuration file (" +
                        std::strerror(errno) + ")");
    return loadControllerConfig(yaml_path);
  }
  const std::string guess = defaultControllerConfigPath(urdf_path);
  if (::stat(guess.c_str(), &st) != 0) return defaultControllerConfig();  // nothing there: the defaults
  return loadControllerConfig(guess);  // something there: read it (a FIFO or device is refused)
}

std::string describeControllerConfig(const ControllerConfig& config, const std::string& urdf_path) {
  const std::string beside = defaultControllerConfigPath(urdf_path);
  std::string out;
  if (config.source == "<defaults>")
    out = "controller configuration: built-in defaults (no " + beside + " beside the URDF)";
  else
    out = "controller configuration " + config.source +
          (config.source == beside ? " (beside the URDF)" : " (--controller)");
  for (std::size_t a = 0; a < config.arms.size(); ++a) {
    const ArmConfig& arm = config.arms[a];
    out += std::string(a == 0 ? ": " : ", ") + "arm " + arm.name + " to hand '" + arm.hand_link + "' (" +
           std::to_string(arm.joints.size()) + " joints)";
  }
  return out;
}

ControllerModel makeControllerModel(const Model& model, const ControllerConfig& config) {
  validateControllerParams(config.params, config.source);
  if (model.segments.size() > static_cast<std::size_t>(kMaxSegments))
    throw ConfigError(config.source + ": robot " + model.name + " has " + std::to_string(model.segments.size()) +
                      " segments (collision segments and body-schema slots); at most " + std::to_string(kMaxSegments) +
                      " are supported");
  ControllerModel cm;
  cm.params = config.params;
  std::set<int> used;
  for (int a = 0; a < 2; ++a) {
    const ArmConfig& ac = config.arms[a];
    ControllerModel::Arm& arm = cm.arms[a];
    const std::string where = config.source + ": arm '" + ac.name + "'";
    arm.name = ac.name;
    if (ac.joints.empty() || static_cast<int>(ac.joints.size()) > kMaxArmDof)
      throw ConfigError(where + ": needs 1.." + std::to_string(kMaxArmDof) + " joints, got " +
                        std::to_string(ac.joints.size()));
    arm.n = static_cast<int>(ac.joints.size());
    for (int i = 0; i < arm.n; ++i) {
      const int qi = model.qIndex(ac.joints[i]);
      if (qi < 0) throw ConfigError(where + ": unknown joint '" + ac.joints[i] + "' in robot " + model.name);
      if (!used.insert(qi).second) throw ConfigError(where + ": joint '" + ac.joints[i] + "' is used twice");
      arm.q[i] = qi;
    }
    arm.hand_link = model.linkIndex(ac.hand_link);
    if (arm.hand_link < 0) throw ConfigError(where + ": unknown hand link '" + ac.hand_link + "'");
    arm.hand_point_L = ac.hand_point_L;
    if (static_cast<int>(ac.rest.size()) != arm.n)
      throw ConfigError(where + ": rest has " + std::to_string(ac.rest.size()) + " values for " +
                        std::to_string(arm.n) + " joints");
    for (int i = 0; i < arm.n; ++i) {
      const int qi = arm.q[i];
      if (ac.rest[i] < model.q_lower[qi] || ac.rest[i] > model.q_upper[qi])
        throw ConfigError(where + ": rest value " + str(ac.rest[i]) + " of joint '" + ac.joints[i] +
                          "' is outside its limits [" + str(model.q_lower[qi]) + ", " + str(model.q_upper[qi]) + "]");
      arm.rest[i] = ac.rest[i];
    }
    // Links moved by the arm: descendants of the link of its first joint.
    arm.link_in_arm.assign(model.links.size(), false);
    arm.link_in_arm[model.q_link[arm.q[0]]] = true;
    for (std::size_t l = 0; l < model.links.size(); ++l)
      if (model.links[l].parent >= 0 && arm.link_in_arm[model.links[l].parent]) arm.link_in_arm[l] = true;
    if (!arm.link_in_arm[arm.hand_link])
      throw ConfigError(where + ": hand link '" + ac.hand_link + "' is not moved by the arm's joints");
    for (int s = 0; s < model.num_robot_segments; ++s)
      if (arm.link_in_arm[model.segments[s].link]) arm.segment_mask |= (std::uint64_t{1} << s);
    for (std::size_t i = 0; i < model.pairs.size(); ++i) {
      const SegmentPair& pr = model.pairs[i];
      const bool mine = ((arm.segment_mask >> pr.a) & 1U) || ((arm.segment_mask >> pr.b) & 1U);
      const bool slot = model.segments[pr.b].body_schema_slot;
      if (mine || slot) arm.candidate_pairs.push_back(static_cast<int>(i));
    }
  }
  // A segment of several links (a hand with its fingers) moves as one body for the controller: its row
  // is taken on its link. No arm joint may lie between that link and another of its links.
  for (int s = 0; s < model.num_robot_segments; ++s) {
    const Segment& seg = model.segments[static_cast<std::size_t>(s)];
    for (int p = seg.first_primitive; p < seg.first_primitive + seg.num_primitives; ++p) {
      for (int l = linkOf(seg, model.primitives[static_cast<std::size_t>(p)]); l != seg.link && l >= 0;
           l = model.links[static_cast<std::size_t>(l)].parent) {
        const int qi = model.links[static_cast<std::size_t>(l)].q_index;
        if (qi >= 0 && used.count(qi))
          throw ConfigError(
              config.source + ": segment '" + seg.name + "' takes in link '" +
              model.links[static_cast<std::size_t>(linkOf(seg, model.primitives[static_cast<std::size_t>(p)]))].name +
              "', which arm joint '" + model.q_names[static_cast<std::size_t>(qi)] + "' moves against '" +
              model.links[static_cast<std::size_t>(seg.link)].name +
              "': a segment's links move as one body; leave it out of the segment (collision YAML "
              "'segments:')");
      }
    }
  }
  // Ownership, once: the left arm first (as the per-pair lookup it replaces did).
  cm.link_owner.assign(model.links.size(), -1);
  for (std::size_t l = 0; l < model.links.size(); ++l)
    for (int a = 1; a >= 0; --a)
      if (cm.arms[a].link_in_arm[l]) cm.link_owner[l] = a;
  cm.segment_owner.assign(static_cast<std::size_t>(model.num_robot_segments), -1);
  for (int s = 0; s < model.num_robot_segments; ++s)
    cm.segment_owner[static_cast<std::size_t>(s)] = cm.link_owner[static_cast<std::size_t>(model.segments[s].link)];
  checkRestPostureClearOfRedZone(model, cm, config.source);
  return cm;
}

Eigen::VectorXd restConfiguration(const Model& model, const ControllerModel& cm) {
  Eigen::VectorXd q(model.nq);
  for (int i = 0; i < model.nq; ++i) q[i] = std::min(std::max(0.0, model.q_lower[i]), model.q_upper[i]);
  for (const auto& arm : cm.arms)
    for (int i = 0; i < arm.n; ++i) q[arm.q[i]] = arm.rest[i];
  return q;
}

void checkRestPostureClearOfRedZone(const Model& model, const ControllerModel& cm, const std::string& source) {
  if (!cm.params.estop) return;
  KinematicsData kin(model);
  DistanceData dist(model);  // no body-schema slot enabled: robot pairs only
  if (!computeForwardKinematics(model, kin, restConfiguration(model, cm))) return;  // rest is inside the limits
  DistanceOptions no_rows;                                                          // only the distances are read
  no_rows.row_threshold = -std::numeric_limits<double>::infinity();
  computeSegmentDistances(model, kin, dist, no_rows);
  if (dist.closest < 0) return;
  const PairDistance& pd = dist.pairs[static_cast<std::size_t>(dist.closest)];
  const double floor = cm.params.d_r + cm.params.estop_release_margin;
  if (!(pd.distance < floor)) return;
  const Segment& a = model.segments[static_cast<std::size_t>(pd.seg_a)];
  const Segment& b = model.segments[static_cast<std::size_t>(pd.seg_b)];
  const bool arm_moves = cm.segment_owner[static_cast<std::size_t>(pd.seg_a)] >= 0 ||
                         cm.segment_owner[static_cast<std::size_t>(pd.seg_b)] >= 0;
  auto mm = [](double m) {
    std::ostringstream out;
    out << std::fixed << std::setprecision(2) << m * 1000.0 << " mm";
    return out.str();
  };
  throw ConfigError(source + ": d_r " + mm(cm.params.d_r) + " + estop_release_margin " +
                    mm(cm.params.estop_release_margin) + " = " + mm(floor) + " is above the distance of '" + a.name +
                    "' and '" + b.name + "' at the rest posture, " + mm(pd.distance) +
                    ": the red-zone e-stop would latch there" +
                    (arm_moves ? " whenever the arms rest" : " and never release (no arm moves either segment)") +
                    "; make d_r + estop_release_margin at most " + mm(pd.distance) +
                    (arm_moves ? " or move the arms' rest posture"
                               : " or, if the two can never come closer, exclude the pair (collision configuration)"));
}

}  // namespace reflex::control
