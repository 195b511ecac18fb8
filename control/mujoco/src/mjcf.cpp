// MJCF generation from the project's Model (see mjcf.hpp for what it contains and why).
#include "reflex/common/error.hpp"
#include "reflex/mujoco/mjcf.hpp"

#include <Eigen/Eigenvalues>

#include "reflex/mujoco/mujoco_robot.hpp"

#include <mujoco/mujoco.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <sstream>
#include <stdexcept>

namespace reflex::mujoco {
namespace {

using control::JointType;
using control::Model;

constexpr double kTwoPi = 6.283185307179586;

// Shortest round-trip text of a double.
std::string num(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.17g", v);
  return buf;
}

std::string vec(const Eigen::Vector3d& v) { return num(v.x()) + " " + num(v.y()) + " " + num(v.z()); }

// XML attribute text: the five characters XML reserves, escaped.
std::string esc(const std::string& s) {
  std::string out;
  for (char c : s) {
    switch (c) {
      case '&': out += "&amp;"; break;
      case '<': out += "&lt;"; break;
      case '>': out += "&gt;"; break;
      case '"': out += "&quot;"; break;
      case '\'': out += "&apos;"; break;
      default: out += c;
    }
  }
  return out;
}

void requirePositive(double v, const char* name) {
  if (!(v > 0.0) || !std::isfinite(v))
    throw reflex::Error(std::string("MJCF option ") + name + " = " + num(v) + " must be finite and positive");
}

void checkOptions(const MjcfOptions& o) {
  requirePositive(o.timestep, "timestep");
  requirePositive(o.margin, "margin");
  requirePositive(o.density, "density");
  requirePositive(o.min_mass, "min_mass");
  requirePositive(o.min_inertia, "min_inertia");
  requirePositive(o.limb_bandwidth_hz, "limb_bandwidth_hz");
  requirePositive(o.base_bandwidth_hz, "base_bandwidth_hz");
  requirePositive(o.limb_effort, "limb_effort");
  requirePositive(o.base_effort, "base_effort");
  if (!(o.limb_armature >= 0.0) || !std::isfinite(o.limb_armature))
    throw reflex::Error("MJCF option limb_armature = " + num(o.limb_armature) + " must be >= 0");
  if (!(o.limb_damping >= 0.0) || !std::isfinite(o.limb_damping))
    throw reflex::Error("MJCF option limb_damping = " + num(o.limb_damping) + " must be >= 0");
  if (!(o.gravity >= 0.0) || !std::isfinite(o.gravity))
    throw reflex::Error("MJCF option gravity = " + num(o.gravity) + " must be >= 0");
}

// The children of every link, in Model order (topological: a parent before its children).
std::vector<std::vector<int>> childrenOf(const Model& model) {
  std::vector<std::vector<int>> children(model.links.size());
  for (std::size_t i = 1; i < model.links.size(); ++i) children[model.links[i].parent].push_back(static_cast<int>(i));
  return children;
}

}  // namespace

bool repairInertial(const MjcfOptions& o, double& mass, Eigen::Matrix3d& I, std::string* what) {
  std::ostringstream why;  // 6 significant digits: the values as a person reads them
  why.precision(6);
  const auto num = [](double v) {
    std::ostringstream os;
    os.precision(6);
    os << v;
    return os.str();
  };
  bool repaired = false;
  if (!(mass >= o.min_mass)) {
    why << "mass " << num(mass) << " -> " << num(o.min_mass) << " kg";
    mass = o.min_mass;
    repaired = true;
  }
  const Eigen::Matrix3d sym = 0.5 * (I + I.transpose());
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(sym.allFinite() ? sym : Eigen::Matrix3d::Zero());
  Eigen::Vector3d l = eig.eigenvalues();  // ascending
  const Eigen::Vector3d before = l;
  for (int k = 0; k < 3; ++k) l[k] = std::max(l[k], o.min_inertia);
  // MuJoCo's triangle inequality (A + B >= C): the two smaller raised to half the largest, with a
  // margin of 1e-6 of it. At exact equality MuJoCo's own eigen-decomposition of the written full
  // inertia can round A + B below C and refuse the model (Romeo's RElbowYawLink did).
  constexpr double kTriangleMargin = 1e-6;
  if (l[0] + l[1] < l[2] * (1.0 + kTriangleMargin))
    l[0] = l[1] = std::max(l[1], 0.5 * l[2] * (1.0 + 2.0 * kTriangleMargin));
  if (!sym.allFinite() || (l - before).cwiseAbs().maxCoeff() > 0.0) {
    if (repaired) why << ", ";
    why << "principal inertia [" << num(before[0]) << " " << num(before[1]) << " " << num(before[2]) << "] -> ["
        << num(l[0]) << " " << num(l[1]) << " " << num(l[2]) << "] kg m^2";
    I = eig.eigenvectors() * l.asDiagonal() * eig.eigenvectors().transpose();
    repaired = true;
  }
  if (what) *what = why.str();
  return repaired;
}

std::vector<std::string> inertialRepairs(const control::Model& model, const MjcfOptions& options) {
  std::vector<std::string> out;
  for (const auto& link : model.links) {
    if (!link.has_inertial || link.parent < 0) continue;  // the root link is MuJoCo's world body
    double mass = link.mass;
    Eigen::Matrix3d I = link.inertia_L;
    std::string what;
    if (repairInertial(options, mass, I, &what))
      out.push_back("link '" + link.name + "': URDF <inertial> " + what +
                    " (MuJoCo refuses a body without mass or with an impossible inertia)");
  }
  return out;
}

namespace {

// At most this many contacts at once (nconmax) and four constraint rows each (njmax).
constexpr int kMaxContacts = 400;

class MjcfWriter {
 public:
  MjcfWriter(const Model& model, const MjcfOptions& options, const std::vector<ServoGains>& gains)
      : model_(model),
        options_(options),
        gains_(gains),
        children_(childrenOf(model)),
        geoms_of_link_(model.links.size()) {
    // Each primitive in the body of the link it moves with (a segment of several links: its own).
    for (int s = 0; s < model.num_robot_segments; ++s) {
      const auto& seg = model.segments[s];
      for (int k = 0; k < seg.num_primitives; ++k)
        geoms_of_link_[static_cast<std::size_t>(control::linkOf(seg, model.primitives[seg.first_primitive + k]))]
            .push_back({s, k});
    }
  }

  std::string write() {
    int primitive_pairs = 0;
    for (const auto& pair : model_.pairs)
      if (pair.b < model_.num_robot_segments)
        primitive_pairs += model_.segments[pair.a].num_primitives * model_.segments[pair.b].num_primitives;
    out_ << "<mujoco model=\"" << esc(model_.name) << "\">\n"
         << "  <compiler angle=\"radian\" inertiafromgeom=\"auto\" boundmass=\"0\" boundinertia=\"0\"/>\n"
         << "  <option timestep=\"" << num(options_.timestep) << "\" gravity=\"0 0 " << num(-options_.gravity)
         << "\" integrator=\"Euler\"/>\n"
         // Up to 2 contacts per primitive pair (parallel capsules), constraint rows for contacts
         // (pyramidal, condim 3: 4 rows) and joint limits.
         // Capped: a robot of convex pieces has tens of thousands of primitive pairs, of which a few
         // touch at once, and MuJoCo 2.2 sizes mjData by njmax squared.
         << "  <size nconmax=\"" << std::min(2 * primitive_pairs + 16, kMaxContacts) << "\" njmax=\""
         << std::min(8 * primitive_pairs, 4 * kMaxContacts) + 2 * model_.nq + 64 << "\"/>\n"
         << "  <default><geom contype=\"0\" conaffinity=\"0\" density=\"" << num(options_.density)
         << "\"/></default>\n";
    writeMeshes();
    out_ << "  <worldbody>\n";
    writeGeoms(0, "    ");
    for (int child : children_[0]) writeBody(child, "    ");
    out_ << "  </worldbody>\n";
    writeContactPairs();
    writeActuators();
    out_ << "</mujoco>\n";
    return out_.str();
  }

 private:
  void writeBody(int l, const std::string& in) {
    const auto& link = model_.links[l];
    const Eigen::Quaterniond quat(link.X_P_J.linear());
    out_ << in << "<body name=\"" << esc(link.name) << "\" pos=\"" << vec(link.X_P_J.translation()) << "\" quat=\""
         << num(quat.w()) << " " << num(quat.x()) << " " << num(quat.y()) << " " << num(quat.z()) << "\">\n";
    const std::string in2 = in + "  ";
    if (link.has_inertial) {
      double mass = link.mass;
      Eigen::Matrix3d I = link.inertia_L;
      repairInertial(options_, mass, I, nullptr);
      out_ << in2 << "<inertial pos=\"" << vec(link.com_L) << "\" mass=\"" << num(mass) << "\" fullinertia=\""
           << num(I(0, 0)) << " " << num(I(1, 1)) << " " << num(I(2, 2)) << " " << num(I(0, 1)) << " " << num(I(0, 2))
           << " " << num(I(1, 2)) << "\"/>\n";
    } else if (geoms_of_link_[static_cast<std::size_t>(l)].empty()) {
      const std::string i = num(options_.min_inertia);
      out_ << in2 << "<inertial pos=\"0 0 0\" mass=\"" << num(options_.min_mass) << "\" diaginertia=\"" << i << " " << i
           << " " << i << "\"/>\n";
    }
    if (link.type != JointType::kFixed) writeJoint(link, in2);
    writeGeoms(l, in2);
    for (int child : children_[l]) writeBody(child, in2);
    out_ << in << "</body>\n";
  }

  void writeJoint(const control::Link& link, const std::string& indent) {
    const int qi = link.q_index;
    const double lo = model_.q_lower[qi], hi = model_.q_upper[qi];
    const bool limited = std::isfinite(lo) && std::isfinite(hi);
    const ServoGains g = gains_.empty() ? ServoGains{} : gains_[qi];
    out_ << indent << "<joint name=\"" << esc(link.joint_name) << "\" type=\""
         << (link.type == JointType::kRevolute ? "hinge" : "slide") << "\" pos=\"0 0 0\" axis=\"" << vec(link.axis_J)
         << "\" limited=\"" << (limited ? "true" : "false") << "\"";
    if (limited) out_ << " range=\"" << num(lo) << " " << num(hi) << "\"";
    // The servo's velocity gain is joint damping: MuJoCo's Euler integrator treats it implicitly, which
    // keeps the stiff chain of parallel virtual joints (heel_x and body_x both along x, joined by
    // nearly massless links) stable at the 0.5 ms step; the servo's kd * qdot_ref is in ctrl.
    out_ << " armature=\"" << num(g.armature) << "\" damping=\"" << num(g.damping + g.kd) << "\"/>\n";
  }

  // A convex piece of the tight model (mesh_fit.hpp) as a MuJoCo mesh (MuJoCo collides its convex hull):
  // the judge measures the shape the controller measures, not the capsule around it. A piece thinner
  // than 0.2 mm along an axis (a flat patch) gets its vertices copied 0.1 mm to either side: MuJoCo
  // refuses a mesh without volume, and the judge's shape only grows.
  void writeMeshes() {
    bool any = false;
    for (int s = 0; s < model_.num_robot_segments; ++s) {
      const auto& seg = model_.segments[s];
      for (int k = 0; k < seg.num_primitives; ++k) {
        const int piece = model_.primitives[seg.first_primitive + k].piece;
        if (piece < 0) continue;
        if (!any) out_ << "  <asset>\n";
        any = true;
        std::vector<Eigen::Vector3d> v = model_.pieces[static_cast<std::size_t>(piece)].vertices_L;
        Eigen::Vector3d mean = Eigen::Vector3d::Zero();
        for (const auto& x : v) mean += x;
        mean /= static_cast<double>(v.size());
        Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
        for (const auto& x : v) cov += (x - mean) * (x - mean).transpose();
        const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(cov);
        for (int axis = 0; axis < 3; ++axis) {
          const Eigen::Vector3d u = eig.eigenvectors().col(axis);
          double lo = 1e30, hi = -1e30;
          for (const auto& x : v) lo = std::min(lo, u.dot(x)), hi = std::max(hi, u.dot(x));
          if (hi - lo >= 2e-4) continue;
          const std::size_t n = v.size();
          for (std::size_t i = 0; i < n; ++i) {
            v.push_back(v[i] + 1e-4 * u);
            v[i] -= 1e-4 * u;
          }
        }
        out_ << "    <mesh name=\"" << esc(meshName(s, k)) << "\" vertex=\"";
        for (std::size_t i = 0; i < v.size(); ++i) out_ << (i ? " " : "") << vec(v[i]);
        out_ << "\"/>\n";
      }
    }
    if (any) out_ << "  </asset>\n";
  }

  std::string meshName(int s, int k) const { return geomName(model_, s, k) + "_piece"; }

  void writeGeoms(int l, const std::string& in) {
    for (const auto& [s, k] : geoms_of_link_[static_cast<std::size_t>(l)]) {
      const auto& p = model_.primitives[model_.segments[s].first_primitive + k];
      out_ << in << "<geom name=\"" << esc(geomName(model_, s, k)) << "\" ";
      if (p.piece >= 0)
        out_ << "type=\"mesh\" mesh=\"" << esc(meshName(s, k)) << "\"/>\n";
      else if (p.sphere)
        out_ << "type=\"sphere\" pos=\"" << vec(p.a_L) << "\" size=\"" << num(p.radius) << "\"/>\n";
      else
        out_ << "type=\"capsule\" fromto=\"" << vec(p.a_L) << " " << vec(p.b_L) << "\" size=\"" << num(p.radius)
             << "\"/>\n";
    }
  }

  void writeContactPairs() {
    out_ << "  <contact>\n";
    const std::string margin = num(options_.margin);
    for (const auto& pair : model_.pairs) {
      if (pair.b >= model_.num_robot_segments) continue;  // body-schema slots: not part of this robot
      const auto& a = model_.segments[pair.a];
      const auto& b = model_.segments[pair.b];
      for (int i = 0; i < a.num_primitives; ++i)
        for (int j = 0; j < b.num_primitives; ++j) {
          const std::array<int, 2> links{control::linkOf(a, model_.primitives[a.first_primitive + i]),
                                         control::linkOf(b, model_.primitives[b.first_primitive + j])};
          if (std::binary_search(pair.unchecked_links.begin(), pair.unchecked_links.end(), links)) continue;
          out_ << "    <pair geom1=\"" << esc(geomName(model_, pair.a, i)) << "\" geom2=\""
               << esc(geomName(model_, pair.b, j)) << "\" condim=\"3\" margin=\"" << margin << "\" gap=\"" << margin
               << "\"/>\n";
        }
    }
    out_ << "  </contact>\n";
  }

  void writeActuators() {
    out_ << "  <actuator>\n";
    for (int qi = 0; qi < model_.nq; ++qi) {
      const ServoGains g = gains_.empty() ? ServoGains{} : gains_[qi];
      const double effort = gains_.empty() ? 1.0 : g.effort;
      out_ << "    <general name=\"" << esc(model_.q_names[qi]) << "\" joint=\"" << esc(model_.q_names[qi])
           << "\" gaintype=\"fixed\" gainprm=\"1\" biastype=\"affine\" biasprm=\"0 " << num(-g.kp)
           << " 0\" ctrllimited=\"false\" forcelimited=\"true\" forcerange=\"" << num(-effort) << " " << num(effort)
           << "\"/>\n";
    }
    out_ << "  </actuator>\n";
  }

  const Model& model_;
  const MjcfOptions& options_;
  const std::vector<ServoGains>& gains_;
  std::vector<std::vector<int>> children_;
  std::vector<std::vector<std::pair<int, int>>> geoms_of_link_;  ///< per link: (segment, primitive k)
  std::ostringstream out_;
};

}  // namespace

std::string geomName(const control::Model& model, int segment, int k) {
  return model.segments[segment].name + "/" + std::to_string(k);
}

std::vector<JointClass> classifyJoints(const control::Model& model) {
  // below_segment[l]: l or an ancestor of l carries a collision segment. The base chain: the movable
  // joints down to (and including) the one that moves the first segment-carrying link of each path.
  std::vector<bool> below_segment(model.links.size(), false);
  for (int s = 0; s < model.num_robot_segments; ++s) below_segment[model.segments[s].link] = true;
  for (std::size_t l = 1; l < model.links.size(); ++l)
    if (below_segment[model.links[l].parent]) below_segment[l] = true;
  std::vector<JointClass> classes(model.nq, JointClass::kLimb);
  for (int qi = 0; qi < model.nq; ++qi)  // the joint moves q_link: base if no ancestor carries a segment
    if (!below_segment[model.links[model.q_link[qi]].parent]) classes[qi] = JointClass::kBase;
  return classes;
}

std::string makeMjcf(const control::Model& model, const MjcfOptions& options, const std::vector<ServoGains>& gains) {
  checkOptions(options);
  if (!gains.empty() && static_cast<int>(gains.size()) != model.nq)
    throw reflex::Error("makeMjcf: " + std::to_string(gains.size()) + " servo gains for " + std::to_string(model.nq) +
                        " joints");
  return MjcfWriter(model, options, gains).write();
}

std::vector<ServoGains> servoGains(const control::Model& model, const MjcfOptions& options) {
  checkOptions(options);
  const std::vector<JointClass> classes = classifyJoints(model);
  // Armature and damping first (they change the inertia the gains are designed for).
  std::vector<ServoGains> gains(model.nq);
  for (int qi = 0; qi < model.nq; ++qi) {
    gains[qi].joint_class = classes[qi];
    const bool limb = classes[qi] == JointClass::kLimb;
    gains[qi].armature =
        limb && model.links[model.q_link[qi]].type == JointType::kRevolute ? options.limb_armature : 0.0;
    gains[qi].damping = limb ? options.limb_damping : 0.0;
    gains[qi].effort = limb ? options.limb_effort : options.base_effort;
  }
  const MjModelPtr m = compileMjcf(makeMjcf(model, options, gains));
  for (int qi = 0; qi < model.nq; ++qi) {
    const int joint = mj_name2id(m.get(), mjOBJ_JOINT, model.q_names[qi].c_str());
    const double inertia = m->dof_M0[m->jnt_dofadr[joint]];
    const double w =
        kTwoPi * (gains[qi].joint_class == JointClass::kLimb ? options.limb_bandwidth_hz : options.base_bandwidth_hz);
    gains[qi].kp = inertia * w * w;
    gains[qi].kd = 2.0 * inertia * w;
  }
  return gains;
}

}  // namespace reflex::mujoco
