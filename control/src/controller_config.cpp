#include "reflex/control/controller.hpp"

#include "reflex/common/files.hpp"

#include <yaml-cpp/yaml.h>

#include <cmath>
#include <set>
#include <sstream>

namespace reflex::control {
namespace {

std::string str(double v) {
  std::ostringstream os;
  os << v;
  return os.str();
}

double readNumber(const YAML::Node& node, const std::string& where) {
  double v = 0.0;
  try {
    v = node.as<double>();
  } catch (const YAML::Exception&) {
    throw ConfigError(where + ": expected a number, got '" + YAML::Dump(node) + "'");
  }
  if (!std::isfinite(v)) throw ConfigError(where + ": value " + YAML::Dump(node) + " is not finite");
  return v;
}

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

void validateControllerParams(const ControllerParams& p, const std::string& src) {
  auto positive = [&](double v, const char* name) {
    if (!(v > 0.0) || !std::isfinite(v)) throw ConfigError(src + ": " + name + " = " + str(v) + " must be positive");
  };
  auto nonneg = [&](double v, const char* name) {
    if (!(v >= 0.0) || !std::isfinite(v)) throw ConfigError(src + ": " + name + " = " + str(v) + " must be >= 0");
  };
  positive(p.d_r, "d_r");
  positive(p.d_b, "d_b");
  positive(p.d_a, "d_a");
  if (!(p.d_r < p.d_b && p.d_b < p.d_a))
    throw ConfigError(src + ": thresholds must satisfy d_r < d_b < d_a, got d_r = " + str(p.d_r) +
                      ", d_b = " + str(p.d_b) + ", d_a = " + str(p.d_a));
  positive(p.period, "period");
  if (p.period > 0.1) throw ConfigError(src + ": period = " + str(p.period) + " s is too long (max 0.1)");
  positive(p.k_virtual, "k_virtual");
  nonneg(p.alpha_ca, "alpha_ca");
  positive(p.d_safe, "d_safe");
  if (!(p.d_safe >= p.d_a))
    throw ConfigError(src + ": d_safe = " + str(p.d_safe) + " must be >= d_a = " + str(p.d_a) + " (Eq. 5)");
  nonneg(p.alpha_t, "alpha_t");
  nonneg(p.alpha_jla, "alpha_jla");
  nonneg(p.alpha_rest, "alpha_rest");
  positive(p.damping, "damping");
  nonneg(p.reach_gain, "reach_gain");
  positive(p.max_task_speed, "max_task_speed");
  positive(p.trajectory_speed, "trajectory_speed");
  nonneg(p.estop_release_margin, "estop_release_margin");
  positive(p.guard_rate, "guard_rate");
  if (p.guard_rate * p.period > 0.5)
    throw ConfigError(src + ": guard_rate * period = " + str(p.guard_rate * p.period) +
                      " must be <= 0.5 so two arms approaching each other cannot overshoot the floor");
  nonneg(p.guard_margin, "guard_margin");
  if (!(p.d_r + p.guard_margin < p.d_b))
    throw ConfigError(src + ": d_r + guard_margin = " + str(p.d_r + p.guard_margin) + " must be below d_b = " + str(p.d_b));
  nonneg(p.predict_margin, "predict_margin");
  if (!(p.d_r + p.predict_margin < p.d_b))
    throw ConfigError(src + ": d_r + predict_margin = " + str(p.d_r + p.predict_margin) + " must be below d_b = " + str(p.d_b));
}

ControllerConfig loadControllerConfig(const std::string& yaml_path) {
  ControllerConfig config = defaultControllerConfig();
  config.source = yaml_path;
  if (const std::string why = common::inputFileProblem(yaml_path); !why.empty())
    throw ConfigError("controller configuration " + why);  // a FIFO or device would block or never end
  YAML::Node root;
  try {
    root = YAML::LoadFile(yaml_path);
  } catch (const YAML::BadFile&) {
    throw ConfigError(yaml_path + ": cannot open controller configuration");
  } catch (const YAML::Exception& e) {
    throw ConfigError(yaml_path + ": malformed YAML: " + e.what());
  }
  if (root.IsNull()) return config;
  if (!root.IsMap()) throw ConfigError(yaml_path + ": top level must be a map");
  ControllerParams& p = config.params;
  const std::pair<const char*, double*> numbers[] = {
      {"d_a", &p.d_a}, {"d_b", &p.d_b}, {"d_r", &p.d_r}, {"period", &p.period},
      {"k_virtual", &p.k_virtual}, {"alpha_ca", &p.alpha_ca}, {"d_safe", &p.d_safe},
      {"alpha_t", &p.alpha_t}, {"alpha_jla", &p.alpha_jla}, {"alpha_rest", &p.alpha_rest},
      {"damping", &p.damping}, {"reach_gain", &p.reach_gain}, {"max_task_speed", &p.max_task_speed},
      {"trajectory_speed", &p.trajectory_speed}, {"estop_release_margin", &p.estop_release_margin},
      {"guard_rate", &p.guard_rate}, {"guard_margin", &p.guard_margin},
      {"predict_margin", &p.predict_margin}};
  for (const auto& kv : root) {
    std::string key;
    try {
      key = kv.first.as<std::string>();
    } catch (const YAML::Exception&) {
      throw ConfigError(yaml_path + ": a key must be a name, got '" + YAML::Dump(kv.first) + "'");
    }
    const std::string where = yaml_path + ": " + key;
    // A value of the wrong kind (a map where a name or list is expected) surfaces from yaml-cpp as a
    // raw conversion error without the file name (fuzz finding): name the file and key instead.
    try {
    bool done = false;
    for (const auto& [name, target] : numbers) {
      if (key == name) {
        *target = readNumber(kv.second, where);
        done = true;
      }
    }
    if (done) continue;
    if (key == "avoidance") {
      const std::string mode = kv.second.as<std::string>();
      if (mode == "one_dof") p.mode = AvoidanceMode::kOneDof;
      else if (mode == "three_dof") p.mode = AvoidanceMode::kThreeDof;
      else if (mode == "off") p.mode = AvoidanceMode::kOff;
      else throw ConfigError(where + ": unknown avoidance mode '" + mode + "' (one_dof, three_dof, off)");
    } else if (key == "arms") {
      if (!kv.second.IsMap()) throw ConfigError(where + ": must be a map with 'left' and 'right'");
      for (const auto& arm_kv : kv.second) {
        const std::string side = arm_kv.first.as<std::string>();
        if (side != "left" && side != "right")
          throw ConfigError(where + ": unknown arm '" + side + "' (left, right)");
        ArmConfig& arm = config.arms[side == "left" ? kLeft : kRight];
        for (const auto& f : arm_kv.second) {
          const std::string fk = f.first.as<std::string>();
          const std::string fw = where + "." + side + "." + fk;
          if (fk == "joints") {
            arm.joints = f.second.as<std::vector<std::string>>();
          } else if (fk == "hand_link") {
            arm.hand_link = f.second.as<std::string>();
          } else if (fk == "hand_point") {
            if (!f.second.IsSequence() || f.second.size() != 3) throw ConfigError(fw + ": expected [x, y, z]");
            for (int i = 0; i < 3; ++i) arm.hand_point_L[i] = readNumber(f.second[i], fw);
          } else if (fk == "rest") {
            if (!f.second.IsSequence()) throw ConfigError(fw + ": expected a list of joint angles");
            arm.rest.clear();
            for (const auto& v : f.second) arm.rest.push_back(readNumber(v, fw));
          } else {
            throw ConfigError(fw + ": unknown key (joints, hand_link, hand_point, rest)");
          }
        }
      }
    } else {
      throw ConfigError(where + ": unknown key");
    }
    } catch (const YAML::Exception& e) {
      throw ConfigError(where + ": value of the wrong kind (" + e.what() + "): '" + YAML::Dump(kv.second) + "'");
    }
  }
  validateControllerParams(p, yaml_path);
  return config;
}

ControllerModel makeControllerModel(const Model& model, const ControllerConfig& config) {
  validateControllerParams(config.params, config.source);
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
  return cm;
}

}  // namespace reflex::control
