// The scenarios' frame of reference: landmarks of a robot at its rest posture, and
// the map that carries the seven scenarios from the reference robot's coordinates to any robot.
#include "reflex/control/scenarios.hpp"

#include "reflex/control/kinematics.hpp"

#include <algorithm>
#include <cmath>
#include <iomanip>
#include <limits>
#include <sstream>

namespace reflex::control {
namespace {

// asimo_like (bringup/robots/asimo_like.urdf) with defaultControllerConfig(), measured by
// scenarioFrame at its rest posture (17 significant digits: they read back to the same doubles).
// Controller test Experiments.TheReferenceFrameIsTheShippedRobots checks them against the robot.
const Eigen::Vector3d kRefChest(0.0, 0.0, 1.04);
constexpr double kRefHalfWidth = 0.23000000000000001;
constexpr double kRefArmLength = 0.47999999999999998;
constexpr double kRefTrunkHalfWidth = 0.14999999999919045;

// Two landmarks closer than this are the same (the reference robot measured with another compiler's
// rounding is still the reference robot, and its scenarios keep their exact numbers).
constexpr double kSameLandmark = 1e-9;

std::string mm(double v) {
  std::ostringstream os;
  os << std::fixed << std::setprecision(1) << v * 1000.0;
  return os.str();
}

}  // namespace

Eigen::Vector3d ScenarioFrame::place(const Eigen::Vector3d& p_ref) const {
  if (reference) return p_ref;  // bit for bit: the scenarios' numbers on the robot they were written for
  return chest + axes * scale.cwiseProduct(p_ref - kRefChest);
}

double ScenarioFrame::length(double l_ref) const { return reference ? l_ref : l_ref * scale.x(); }

ScenarioFrame referenceScenarioFrame() {
  ScenarioFrame f;
  f.chest = kRefChest;
  f.half_width = kRefHalfWidth;
  f.arm_length = kRefArmLength;
  f.trunk_half_width = kRefTrunkHalfWidth;
  f.shoulder[kLeft] = kRefChest + Eigen::Vector3d(0.0, kRefHalfWidth, 0.0);
  f.shoulder[kRight] = kRefChest - Eigen::Vector3d(0.0, kRefHalfWidth, 0.0);
  f.reference = true;
  return f;
}

ScenarioFrame scenarioFrame(const Model& model, const ControllerModel& cm) {
  KinematicsData kin(model);
  computeForwardKinematics(model, kin, restConfiguration(model, cm));
  ScenarioFrame f;
  double length[2] = {0.0, 0.0};
  for (int a = 0; a < 2; ++a) {
    const ControllerModel::Arm& arm = cm.arms[a];
    // A link frame is its parent joint's frame (URDF): the arm's joints are the origins of the links
    // they move. Their distances are fixed by the links, so the sum is the straight arm's reach.
    Eigen::Vector3d previous = kin.X_B_L[model.q_link[arm.q[0]]].translation();
    f.shoulder[a] = previous;
    for (int i = 1; i < arm.n; ++i) {
      const Eigen::Vector3d joint = kin.X_B_L[model.q_link[arm.q[i]]].translation();
      length[a] += (joint - previous).norm();
      previous = joint;
    }
    f.hand_rest[a] = kin.X_B_L[arm.hand_link] * arm.hand_point_L;
    length[a] += (f.hand_rest[a] - previous).norm();
  }
  f.chest = 0.5 * (f.shoulder[kLeft] + f.shoulder[kRight]);
  f.half_width = 0.5 * (f.shoulder[kLeft] - f.shoulder[kRight]).norm();
  f.arm_length = 0.5 * (length[kLeft] + length[kRight]);
  // The scenarios are written in x forward, y left, z up (REP 103, the shipped robots' root frame).
  // Another robot's forward is found from its arms: left is from the right shoulder to the left one,
  // level, up is the root's z, forward = left x up. The shoulders must be side by side (level within
  // 30 degrees): a robot lying on its side cannot be placed in them.
  const Eigen::Vector3d across = f.shoulder[kLeft] - f.shoulder[kRight];
  const Eigen::Vector3d level(across.x(), across.y(), 0.0);
  if (!(level.norm() > 0.5 * across.norm()))
    throw ConfigError("the scenarios need the root frame's z up: robot '" + model.name +
                      "' has its shoulders one above the other (left at z = " + mm(f.shoulder[kLeft].z()) +
                      " mm, right at z = " + mm(f.shoulder[kRight].z()) + " mm)");
  const Eigen::Vector3d left = level.normalized();
  f.axes.col(0) = left.cross(Eigen::Vector3d::UnitZ());
  f.axes.col(1) = left;
  f.axes.col(2) = Eigen::Vector3d::UnitZ();
  if (!(f.arm_length > 0.0))
    throw ConfigError("robot '" + model.name + "': the arms' joints and hand points coincide (arm length 0)");
  // The trunk: the segment on the link the left arm's first joint hangs from (or what that link is
  // fixed to). Its width, not the shoulders', says where "inside the body" and "beside it" are.
  const int hung_from = model.links[static_cast<std::size_t>(model.q_link[cm.arms[kLeft].q[0]])].parent;
  for (int l = hung_from; l >= 0 && f.trunk_segment < 0; l = model.links[static_cast<std::size_t>(l)].parent)
    for (int s = 0; s < model.num_robot_segments && f.trunk_segment < 0; ++s)
      if (model.segments[static_cast<std::size_t>(s)].link == l) f.trunk_segment = s;
  if (f.trunk_segment < 0)
    throw ConfigError("the scenarios need collision geometry on the trunk the arms hang from: robot '" + model.name +
                      "' has none on link '" + model.links[static_cast<std::size_t>(std::max(hung_from, 0))].name +
                      "' nor on any link above it");
  const Segment& trunk = model.segments[static_cast<std::size_t>(f.trunk_segment)];
  double y_lo = std::numeric_limits<double>::infinity(), y_hi = -y_lo;
  for (int p = trunk.first_primitive; p < trunk.first_primitive + trunk.num_primitives; ++p) {
    const Primitive& prim = model.primitives[static_cast<std::size_t>(p)];
    for (const Eigen::Vector3d& end : {prim.a_L, prim.b_L}) {
      const double y = left.dot(kin.X_B_L[static_cast<std::size_t>(linkOf(trunk, prim))] * end);
      y_lo = std::min(y_lo, y - prim.radius);
      y_hi = std::max(y_hi, y + prim.radius);
    }
  }
  f.trunk_half_width = 0.5 * (y_hi - y_lo);
  f.reference = (f.axes - Eigen::Matrix3d::Identity()).norm() < kSameLandmark &&
                (f.chest - kRefChest).norm() < kSameLandmark &&
                std::abs(f.half_width - kRefHalfWidth) < kSameLandmark &&
                std::abs(f.arm_length - kRefArmLength) < kSameLandmark &&
                std::abs(f.trunk_half_width - kRefTrunkHalfWidth) < kSameLandmark;
  if (!f.reference)
    f.scale = Eigen::Vector3d(f.arm_length / kRefArmLength, f.trunk_half_width / kRefTrunkHalfWidth,
                              f.arm_length / kRefArmLength);
  return f;
}

const ScenarioFrame& ScenarioContext::frame() {
  if (!frame_cache) frame_cache = scenarioFrame(model, cm);
  return *frame_cache;
}

namespace {

/// How far the arm's hand point stays from p_B after damped least squares from the rest posture,
/// joints clamped to their limits (m).
double reachResidual(const Model& model, const ControllerModel& cm, int arm, const Eigen::Vector3d& p_B) {
  const ControllerModel::Arm& a = cm.arms[static_cast<std::size_t>(arm)];
  KinematicsData kin(model);
  Eigen::VectorXd q = restConfiguration(model, cm);
  Eigen::MatrixXd J(3, model.nq), Ja(3, a.n);
  double residual = std::numeric_limits<double>::infinity();
  for (int it = 0; it < 400; ++it) {
    computeForwardKinematics(model, kin, q);
    const Eigen::Vector3d hand = kin.X_B_L[static_cast<std::size_t>(a.hand_link)] * a.hand_point_L;
    const Eigen::Vector3d e = p_B - hand;
    residual = e.norm();
    if (residual < 1e-4) break;
    J.setZero();
    computePointJacobian(model, kin, a.hand_link, hand, J);
    for (int i = 0; i < a.n; ++i) Ja.col(i) = J.col(a.q[static_cast<std::size_t>(i)]);
    Eigen::VectorXd dq = Ja.transpose() * (Ja * Ja.transpose() + 1e-4 * Eigen::Matrix3d::Identity()).ldlt().solve(e);
    const double largest = dq.cwiseAbs().maxCoeff();
    if (largest > 0.2) dq *= 0.2 / largest;  // small steps: the clamping below stays meaningful
    for (int i = 0; i < a.n; ++i) {
      const int j = a.q[static_cast<std::size_t>(i)];
      q[j] = std::clamp(q[j] + dq[i], model.q_lower[j], model.q_upper[j]);
    }
  }
  return residual;
}

}  // namespace

Eigen::Vector3d ScenarioContext::reachable(int arm, const Eigen::Vector3d& p_B) {
  auto& cache = reach_cache[arm];
  for (const auto& entry : cache)
    if (entry[0] == p_B) return entry[1];
  constexpr double kReached = 0.002;
  Eigen::Vector3d answer = p_B;
  if (reachResidual(model, cm, arm, p_B) > kReached) {
    const Eigen::Vector3d rest = frame().hand_rest[static_cast<std::size_t>(arm)];
    double lo = 0.0, hi = 1.0;  // fractions of the way from the rest hand point to p_B
    for (int i = 0; i < 14; ++i) {
      const double mid = 0.5 * (lo + hi);
      (reachResidual(model, cm, arm, rest + mid * (p_B - rest)) <= kReached ? lo : hi) = mid;
    }
    answer = rest + 0.9 * lo * (p_B - rest);
  }
  cache.push_back({p_B, answer});
  return answer;
}

int ScenarioContext::carrierSegment(int link) const {
  for (int l = link; l >= 0; l = model.links[static_cast<std::size_t>(l)].parent) {
    for (int s = 0; s < model.num_robot_segments; ++s)
      if (model.segments[static_cast<std::size_t>(s)].link == l) return s;
    if (model.links[static_cast<std::size_t>(l)].type != JointType::kFixed) return -1;  // only what it is fixed to
  }
  return -1;
}

}  // namespace reflex::control
