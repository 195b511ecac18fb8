#include "reflex/control/controller.hpp"

#include <Eigen/Cholesky>
#include <Eigen/LU>

#include <algorithm>
#include <cmath>
#include <limits>

namespace reflex::control {
namespace {

using VecA = ArmVector;
using MatA = ArmMatrix;
using Mat3A = TaskJacobian;
using MatA3 = TaskJacobianInverse;
using RowA = ArmRow;

constexpr double kInf = std::numeric_limits<double>::infinity();

/// The arm (kLeft / kRight) that moves segment s this cycle, or -1.
int ownerArm(const Model& model, const ControllerModel& cm, const DistanceData& dist, int s) {
  if (!model.segments[s].body_schema_slot) {
    for (int a = 0; a < 2; ++a)
      if ((cm.arms[a].segment_mask >> s) & 1U) return a;
    return -1;
  }
  const int link = dist.slots[s - model.num_robot_segments].link;
  for (int a = 0; a < 2; ++a)
    if (cm.arms[a].link_in_arm[link]) return a;
  return -1;
}

int segmentLink(const Model& model, const DistanceData& dist, int s) {
  return model.segments[s].body_schema_slot ? dist.slots[s - model.num_robot_segments].link
                                            : model.segments[s].link;
}

/// True if `link` lies strictly below `ancestor` in the link tree (O(depth), allocation-free).
bool descendsFrom(const Model& model, int link, int ancestor) {
  for (int l = model.links[static_cast<std::size_t>(link)].parent; l >= 0; l = model.links[static_cast<std::size_t>(l)].parent)
    if (l == ancestor) return true;
  return false;
}

/// The side of a pair on which arm `a`'s virtual force acts (Eq. 14-16): +1 for seg_a (the force
/// acts at p_W_a along +nhat_W), -1 for seg_b. For a pair with another body part that is the arm's
/// own segment. For a pair of two segments that arm `a` both moves (shoulder-hand, upper arm-hand, a
/// grasped object against the upper arm) it is the DISTAL one, whose link descends from the other's:
/// the paper's S_i are the forearm and the hand, and the force must push the hand away from the
/// shoulder, not the shoulder away from the hand (that flips its direction in the Eq. 17 merge and
/// can drive the closest pair together; issue 16, item 7). Two segments on one link: seg_a.
int forceSide(const Model& model, const DistanceData& dist, const PairDistance& pd, int owner_a, int owner_b, int a) {
  if (owner_a != a) return -1;
  if (owner_b != a) return 1;
  return descendsFrom(model, segmentLink(model, dist, pd.seg_b), segmentLink(model, dist, pd.seg_a)) ? -1 : 1;
}

bool higherPriority(MotionPriority p, int arm) {
  return (p == MotionPriority::kLeftHigher && arm == kLeft) || (p == MotionPriority::kRightHigher && arm == kRight);
}

/// Gathers the arm's columns of a 3 x nq matrix.
void gather(const ControllerModel::Arm& arm, const Eigen::MatrixXd& full, Mat3A& out) {
  out.resize(3, arm.n);
  for (int i = 0; i < arm.n; ++i) out.col(i) = full.col(arm.q[i]);
}

/// What one arm's pair contributes to the merged force (Eq. 14-18).
struct PairTerm {
  int pair;
  int sign;          ///< +1: the arm's point is p_W_a, -1: p_W_b
  double weight;     ///< |F_ij|
};

}  // namespace

void VirtualForceSum::add(double k, double d_a, double d, const Eigen::Vector3d& e, const Eigen::Vector3d& p_cp1) {
  if (!(d < d_a)) return;
  const double magnitude = k * (d_a - d);  // |F_ij|, Eq. 14
  weighted_force += magnitude * (magnitude * e);
  weighted_point += magnitude * p_cp1;
  weight += magnitude;
}

Eigen::Vector3d VirtualForceSum::force() const {
  return weight > 0.0 ? Eigen::Vector3d(weighted_force / weight) : Eigen::Vector3d::Zero();
}

Eigen::Vector3d VirtualForceSum::point() const {
  return weight > 0.0 ? Eigen::Vector3d(weighted_point / weight) : Eigen::Vector3d::Zero();
}

double blendingCoefficient(double d, double d_a, double d_b) {
  if (!(d > d_b)) return 1.0;  // also NaN -> maximal caution
  if (d > d_a) return 0.0;
  return (d - d_a) / (d_b - d_a);
}

Zone zoneOf(double d, const ControllerParams& p) {
  // Sec. 7.1: red below d_r (the e-stop's own test, d < d_r); Eq. 13: f = 1 up to and including d_b.
  if (!(d >= p.d_r)) return Zone::kRed;
  if (d <= p.d_b) return Zone::kOrange;
  if (d < p.d_a) return Zone::kYellow;
  return Zone::kFree;
}

ControllerData::ControllerData(const Model& model, const ControllerModel& cm)
    : kin(model),
      dist(model),
      qdot(Eigen::VectorXd::Zero(model.nq)),
      qdot_uncontrolled(Eigen::VectorXd::Zero(model.nq)),
      q_prev(Eigen::VectorXd::Zero(model.nq)),
      arm_joint(static_cast<std::size_t>(model.nq), 0),
      q_next(Eigen::VectorXd::Zero(model.nq)),
      kin_next(model),
      dist_next(model),
      dist_hold(model),
      J_full(Eigen::MatrixXd::Zero(3, model.nq)),
      J_rel_full(Eigen::MatrixXd::Zero(3, model.nq)) {
  for (const auto& arm : cm.arms)
    for (int i = 0; i < arm.n; ++i) arm_joint[static_cast<std::size_t>(arm.q[i])] = 1;
  // reach[l]: the farthest segment surface below link l, measured along the chain from l's origin
  // (joint offsets summed, so it bounds every configuration).
  const std::size_t nl = model.links.size();
  std::vector<double> reach(nl, 0.0);
  for (const Segment& seg : model.segments) {
    if (seg.body_schema_slot || seg.link < 0) continue;
    for (int k = 0; k < seg.num_primitives; ++k) {
      const Primitive& prim = model.primitives[static_cast<std::size_t>(seg.first_primitive + k)];
      reach[static_cast<std::size_t>(seg.link)] = std::max(reach[static_cast<std::size_t>(seg.link)],
                                                           std::max(prim.a_L.norm(), prim.b_L.norm()) + prim.radius);
    }
  }
  for (std::size_t l = nl; l-- > 1;) {  // children after parents: accumulate bottom-up
    const int parent = model.links[l].parent;
    if (parent < 0) continue;
    reach[static_cast<std::size_t>(parent)] =
        std::max(reach[static_cast<std::size_t>(parent)], model.links[l].X_P_J.translation().norm() + reach[l]);
  }
  lever = Eigen::VectorXd::Zero(model.nq);
  for (int j = 0; j < model.nq; ++j) {
    const Link& link = model.links[static_cast<std::size_t>(model.q_link[j])];
    lever[j] = link.type == JointType::kPrismatic ? 1.0 : reach[static_cast<std::size_t>(model.q_link[j])];
  }
}

namespace {

/// Controller for one arm: Eq. 1-18 on its own joints. Writes the arm's joint velocities into qdot.
void computeArm(const Model& model, const ControllerModel& cm, ControllerData& data, int a,
                const ControlInput& input, bool recovery_only) {
  const ControllerParams& P = cm.params;
  const ControllerModel::Arm& arm = cm.arms[a];
  ArmStatus& status = data.arms[a];
  Trajectory& traj = data.trajectories[a];
  const int n = arm.n;
  const double dt = P.period;

  VecA q(n);
  for (int i = 0; i < n; ++i) q[i] = data.kin.q[arm.q[i]];

  // Hand, its Jacobian, the linear trajectory (Sec. 8) and the task velocity.
  const Eigen::Vector3d r = data.kin.X_W_L[arm.hand_link] * arm.hand_point_L;
  status.hand_W = r;
  computePointJacobian(model, data.kin, arm.hand_link, r, data.J_full);
  Mat3A J;
  gather(arm, data.J_full, J);

  const HandCommand& cmd = input.hands[a];
  const bool given = cmd.status == HandStatus::kGiven && !recovery_only;
  Eigen::Vector3d rdot = Eigen::Vector3d::Zero();
  if (given) {
    if (!traj.active) {
      traj.active = true;
      traj.ref_W = r;
    }
    traj.goal_W = cmd.target_W;
    const Eigen::Vector3d delta = traj.goal_W - traj.ref_W;
    const double step = P.trajectory_speed * dt;
    const double len = delta.norm();
    Eigen::Vector3d v_ref = Eigen::Vector3d::Zero();
    if (len <= step) {
      traj.ref_W = traj.goal_W;
    } else {
      v_ref = delta * (P.trajectory_speed / len);
      traj.ref_W += v_ref * dt;
    }
    rdot = v_ref + P.reach_gain * (traj.ref_W - r);
    const double speed = rdot.norm();
    if (speed > P.max_task_speed) rdot *= P.max_task_speed / speed;
  } else {
    traj.active = false;
    traj.ref_W = r;
  }
  status.reference_W = traj.ref_W;

  // Pairs of this arm, their merged virtual force (Eq. 14-18) and the closest distance.
  std::array<PairTerm, 64> terms;  // pairs inside the yellow zone
  int nterms = 0;
  std::array<int, 64> guarded;     // pairs inside the orange zone, for the safety filter
  int nguarded = 0;
  VirtualForceSum forces;
  RowA xi_row_sum = RowA::Zero(n);  // sum of row^T (d_safe - d) for Eq. 5
  double d_min = kInf;
  double d_arm_contact = kInf, d_static_contact = kInf;
  int closest = -1;
  for (const int p : arm.candidate_pairs) {
    const PairDistance& pd = data.dist.pairs[p];
    if (!pd.active) continue;
    const int oa = ownerArm(model, cm, data.dist, pd.seg_a);
    const int ob = ownerArm(model, cm, data.dist, pd.seg_b);
    if (oa != a && ob != a) continue;
    const int sign = forceSide(model, data.dist, pd, oa, ob, a);
    const int other = oa == a ? ob : oa;
    const bool arm_pair = other >= 0 && other != a;
    if (arm_pair || other < 0) {
      // For the step cap below: contacts with the other arm, and with everything that is not it.
      if (arm_pair) d_arm_contact = std::min(d_arm_contact, pd.distance);
      else d_static_contact = std::min(d_static_contact, pd.distance);
    }
    // Motion priority (Sec. 7.2): the higher-priority arm ignores the other arm (it is the obstacle).
    if (arm_pair && higherPriority(input.priority, a) && !recovery_only) continue;
    if (pd.distance < d_min) {
      d_min = pd.distance;
      closest = p;
    }
    if (pd.has_row && pd.distance < P.d_safe && !recovery_only) {
      for (int i = 0; i < n; ++i) xi_row_sum[i] += data.dist.rows(p, arm.q[i]) * (P.d_safe - pd.distance);
    }
    if (pd.distance < P.d_b && pd.has_row && nguarded < static_cast<int>(guarded.size())) guarded[nguarded++] = p;
    if (pd.distance < P.d_a && nterms < static_cast<int>(terms.size())) {
      // e_f,ij points from the other segment towards the arm's closest point (Eq. 16).
      forces.add(P.k_virtual, P.d_a, pd.distance, sign * pd.nhat_W, sign > 0 ? pd.p_W_a : pd.p_W_b);
      terms[nterms++] = {p, sign, P.k_virtual * (P.d_a - pd.distance)};
    }
  }
  status.distance = d_min;
  status.closest_pair = closest;
  status.zone = zoneOf(d_min, P);
  const double f = P.mode == AvoidanceMode::kOff ? 0.0 : blendingCoefficient(d_min, P.d_a, P.d_b);
  status.f = f;

  // Merged force, point and avoidance Jacobian (weighted relative Jacobians of the pairs).
  Mat3A J_ca = Mat3A::Zero(3, n);
  double F_mag = 0.0;
  Eigen::Vector3d e_all = Eigen::Vector3d::Zero();
  const double weight_sum = forces.weight;
  const Eigen::Vector3d F_all = forces.force();
  const Eigen::Vector3d P_all = forces.point();
  if (weight_sum > 0.0) {
    F_mag = F_all.norm();
    if (F_mag > 1e-12) e_all = F_all / F_mag;
    Mat3A J_rel(3, n);
    for (int t = 0; t < nterms; ++t) {
      const PairDistance& pd = data.dist.pairs[terms[t].pair];
      const int la = segmentLink(model, data.dist, pd.seg_a);
      const int lb = segmentLink(model, data.dist, pd.seg_b);
      computeRelativeJacobian(model, data.kin, la, pd.p_W_a, lb, pd.p_W_b, data.J_rel_full);
      gather(arm, data.J_rel_full, J_rel);
      J_ca += (terms[t].weight / weight_sum) * terms[t].sign * J_rel;  // rate of p1 - p2 (arm side first)
    }
  }
  status.force = F_mag;
  status.force_dir_W = e_all;
  status.force_point_W = P_all;

  // Nullspace criteria: joint-limit avoidance (Eq. 4), rest posture without a target.
  VecA xi_jla(n);
  for (int i = 0; i < n; ++i) {
    const int qi = arm.q[i];
    const double lo = model.q_lower[qi], hi = model.q_upper[qi];
    const double half = 0.5 * (hi - lo);
    xi_jla[i] = std::isfinite(half) && half > 0.0 ? -P.alpha_jla * (q[i] - 0.5 * (hi + lo)) / (half * half) : 0.0;
  }
  VecA xi_rest = VecA::Zero(n);
  if (!given) xi_rest = -P.alpha_rest * (q - arm.rest.head(n));

  // The virtual-force term of Eq. 8 along the merged direction: row^+ |F^all|.
  const RowA row_ca = e_all.transpose() * J_ca;  // J_ca|row,y in the merged avoidance frame
  VecA row_pinv;
  dampedPseudoInverse(row_ca, P.damping, row_pinv);
  VecA qdot_force = VecA::Zero(n);
  if (F_mag > 0.0) qdot_force = row_pinv * F_mag;
  // three_dof: the whole merged force, J_ca^+ F^all (Eq. 8 with a 3-D task).
  MatA3 Jca_pinv;
  if (P.mode == AvoidanceMode::kThreeDof) dampedPseudoInverse(J_ca, P.damping, Jca_pinv);
  status.qdot_force = P.mode == AvoidanceMode::kThreeDof && !recovery_only ? VecA(Jca_pinv * (F_mag * e_all)) : qdot_force;

  VecA qdot(n);
  if (recovery_only) {
    // Only the separating motion of Eq. 8: nothing in the nullspace.
    qdot = qdot_force;
  } else {
    // Whole-body motion, Eq. 2-5.
    MatA3 J_pinv;
    dampedPseudoInverse(J, P.damping, J_pinv);
    MatA N_wbm;
    nullspaceProjector(J, N_wbm);
    VecA xi_ca = VecA::Zero(n);
    if (P.mode != AvoidanceMode::kOff) xi_ca = P.alpha_ca * xi_row_sum.transpose();
    VecA qdot_wbm(n);
    if (given) qdot_wbm = J_pinv * rdot + N_wbm * (xi_ca + xi_jla);
    else qdot_wbm = xi_ca + xi_jla + xi_rest;

    if (P.mode == AvoidanceMode::kOff || f <= 0.0) {
      qdot = qdot_wbm;
    } else {
      // Collision avoidance, Eq. 8-12: the virtual force along one direction, reaching in its nullspace.
      VecA xi_t(n);
      if (given) xi_t = -P.alpha_t * (J.transpose() * (r - traj.ref_W));  // Eq. 12, W_t = I
      else xi_t = xi_rest;
      VecA qdot_ca(n);
      if (P.mode == AvoidanceMode::kOneDof) {
        MatA N_ca;
        nullspaceProjector(row_ca, N_ca);
        qdot_ca = qdot_force + N_ca * xi_t;
      } else {
        MatA N_ca;
        nullspaceProjector(J_ca, N_ca);
        qdot_ca = status.qdot_force + N_ca * xi_t;
      }
      qdot = (1.0 - f) * qdot_wbm + f * qdot_ca;  // Eq. 1
    }
  }

  // Joint position limits: a step never crosses a limit (the robot would clamp the motion away, so
  // what it does would differ from what the filter below checked). The box contains 0.
  VecA v_lo(n), v_hi(n);
  for (int i = 0; i < n; ++i) {
    const int qi = arm.q[i];
    v_lo[i] = std::min(0.0, (model.q_lower[qi] - q[i]) / dt);
    v_hi[i] = std::max(0.0, (model.q_upper[qi] - q[i]) / dt);
    qdot[i] = std::clamp(qdot[i], v_lo[i], v_hi[i]);
  }

  // Safety filter (not in the paper): inside the orange zone, this arm may approach a pair no faster
  // than guard_rate (d - d_r - guard_margin), so the distance decays at most exponentially towards a
  // floor above d_r. Merging several pairs into one direction (Eq. 17) and the reaching gradient in
  // the collision controller's nullspace can otherwise leak motion into a pair that is not the merged
  // direction; this removes exactly that component and nothing else (inactive above d_b).
  if (P.mode != AvoidanceMode::kOff && !recovery_only) {
    // What moves each guarded pair besides this arm, fixed for this cycle (computed once, not per
    // iteration). The higher-priority arm was computed first (computeControl orders them): its motion
    // is known, so the pair's approach includes it (the obstacle arm does not avoid). Walking and
    // balance move the legs (and everything above them) without asking: their estimated motion counts
    // too (legs always win, Sec. 7.2); qdot_uncontrolled is zero on the arm joints.
    std::array<double, 64> other_rate{};
    const int b = 1 - a;
    for (int g = 0; g < nguarded; ++g) {
      const int p = guarded[g];
      if (higherPriority(input.priority, b)) {
        for (int i = 0; i < cm.arms[b].n; ++i)
          other_rate[g] += data.dist.rows(p, cm.arms[b].q[i]) * data.qdot[cm.arms[b].q[i]];
      }
      for (int j = 0; j < model.nq; ++j) other_rate[g] += data.dist.rows(p, j) * data.qdot_uncontrolled[j];
    }
    for (int iter = 0; iter < 6; ++iter) {
      bool changed = false;
      for (int g = 0; g < nguarded; ++g) {
        const int p = guarded[g];
        const double d = data.dist.pairs[p].distance;
        RowA row(n), free_row(n);
        for (int i = 0; i < n; ++i) {
          row[i] = data.dist.rows(p, arm.q[i]);
          // A joint whose correction would leave its limit box cannot take it.
          const bool blocked = (row[i] > 0.0 && qdot[i] >= v_hi[i]) || (row[i] < 0.0 && qdot[i] <= v_lo[i]);
          free_row[i] = blocked ? 0.0 : row[i];
        }
        const double rr = free_row.squaredNorm();
        if (rr < 1e-12) continue;
        const double allowed = -P.guard_rate * std::max(0.0, d - P.d_r - P.guard_margin);
        const double rate = row.dot(qdot.transpose()) + other_rate[g];
        if (rate < allowed - 1e-12) {
          qdot += free_row.transpose() * ((allowed - rate) / rr);
          for (int i = 0; i < n; ++i) qdot[i] = std::clamp(qdot[i], v_lo[i], v_hi[i]);
          changed = true;
        }
      }
      if (!changed) break;
    }
  }

  // Joint velocity limits: uniform scaling keeps the direction (and every filtered pair's bound).
  double scale = 1.0;
  for (int i = 0; i < n; ++i) {
    const int qi = arm.q[i];
    const double v = std::abs(qdot[i]);
    if (v > model.v_max[qi]) scale = std::min(scale, model.v_max[qi] / v);
  }
  qdot *= scale;

  // Step cap inside the orange zone (part of the safety filter): the filter bounds the approach to
  // first order along each pair's current normal, but a large step can make another primitive of the
  // same segment the closest one (the chest has three). So no point of the arm may move more than half the remaining gap above d_r in one cycle: sum |qdot_i| * lever_i * dt <= (d - d_r) / 2, with
  // lever_i the distance from joint i to the hand plus 0.1 m. Scaling keeps every bound above.
  // Against the other arm only with equal priority: a yielding arm must be free to get out of the way,
  // and a higher-priority arm is untouched by the other arm (Sec. 7.2; the e-stop is the last resort).
  const bool equal = input.priority == MotionPriority::kEqual;
  const double d_cap = equal ? std::min(d_static_contact, d_arm_contact) : d_static_contact;
  if (P.mode != AvoidanceMode::kOff && !recovery_only && d_cap < P.d_b) {
    double sweep = 0.0;
    for (int i = 0; i < n; ++i) {
      const double lever = (r - data.kin.X_W_L[model.q_link[arm.q[i]]].translation()).norm() + 0.1;
      sweep += std::abs(qdot[i]) * lever * dt;
    }
    const double budget = 0.5 * std::max(0.0, d_cap - P.d_r);
    if (sweep > budget) qdot *= budget / sweep;
  }
  for (int i = 0; i < n; ++i) data.qdot[arm.q[i]] = qdot[i];
}

/// A pair between physical segments (a virtual occlusion slot never counts for safety).
bool isPhysical(const Model& model, const ControllerData& data, const PairDistance& pd) {
  const int sb = pd.seg_b;
  return !(model.segments[sb].body_schema_slot && data.slot_virtual[sb - model.num_robot_segments]);
}

/// Distances (no avoidance rows) of every pair at configuration q, with this cycle's body-schema
/// slots, into `out` (kin_next is the scratch). False if q is not finite (out is then untouched).
bool computeDistancesAt(const Model& model, ControllerData& data, const Eigen::Ref<const Eigen::VectorXd>& q,
                        DistanceData& out) {
  if (!computeForwardKinematics(model, data.kin_next, q)) return false;
  out.slots = data.dist.slots;
  DistanceOptions no_rows;
  no_rows.row_threshold = -kInf;
  computeSegmentDistances(model, data.kin_next, out, no_rows);
  return true;
}

/// Predicts the configuration one period ahead: q + dt (scaled arm velocities + uncontrolled ones).
void predict(const Model& model, const ControllerModel& cm, ControllerData& data,
             const Eigen::Ref<const Eigen::VectorXd>& q, const std::array<double, 2>& scale, DistanceData& out) {
  const double dt = cm.params.period;
  for (int j = 0; j < model.nq; ++j) data.q_next[j] = q[j] + dt * data.qdot_uncontrolled[j];
  for (int a = 0; a < 2; ++a)
    for (int i = 0; i < cm.arms[a].n; ++i) data.q_next[cm.arms[a].q[i]] += dt * scale[a] * data.qdot[cm.arms[a].q[i]];
  if (!computeDistancesAt(model, data, data.q_next, out)) {
    for (auto& pd : out.pairs) pd.distance = -kInf;  // cannot happen for finite q; counts as a hit
  }
}

/// Predictive guard (not in the paper; ControllerParams::predict_margin). d_phys: this cycle's
/// closest physical pair (computeControl's red-zone check). The two filters inside
/// computeArm bound the approach to first order; this one checks the step itself. Each arm's step is
/// halved (at most six times, then dropped) while, one period ahead, some physical pair of that arm
/// would end below d_r + predict_margin AND closer than it is now and than it would be if the arms
/// held still (so walking motion that no arm step can undo is not blamed on the arms). On the
/// kinematic robot the prediction is exact for the arms, so no arm motion ever enters the red zone.
void predictiveGuard(const Model& model, const ControllerModel& cm, ControllerData& data,
                     const Eigen::Ref<const Eigen::VectorXd>& q, double d_phys) {
  const ControllerParams& P = cm.params;
  const double floor = P.d_r + P.predict_margin;
  // Cheap exit: in one period no point moves more than sum |qdot_j| lever_j dt (body-schema slots
  // add their own extent to every lever), so no distance changes by more than twice that.
  double slot_extent = 0.0;
  for (const BodySchemaSlot& slot : data.dist.slots)
    if (slot.enabled) slot_extent = std::max(slot_extent, std::max(slot.a_L.norm(), slot.b_L.norm()) + slot.radius);
  double sweep = 0.0;
  for (int j = 0; j < model.nq; ++j)
    sweep += std::abs(data.qdot[j] + data.qdot_uncontrolled[j]) * (data.lever[j] + slot_extent) * P.period;
  if (d_phys - 2.0 * sweep > floor) return;

  bool have_hold = false;
  std::array<double, 2> scale{1.0, 1.0};
  for (int iter = 0; iter < 8; ++iter) {
    predict(model, cm, data, q, scale, data.dist_next);
    std::array<bool, 2> hit{false, false};
    for (std::size_t i = 0; i < data.dist_next.pairs.size(); ++i) {
      const PairDistance& pn = data.dist_next.pairs[i];
      const PairDistance& p0 = data.dist.pairs[i];
      if (!pn.active || !isPhysical(model, data, pn)) continue;
      if (!(pn.distance < floor) || !(pn.distance < p0.distance)) continue;
      const int oa = ownerArm(model, cm, data.dist_next, pn.seg_a);
      const int ob = ownerArm(model, cm, data.dist_next, pn.seg_b);
      const bool movable = (oa >= 0 && scale[oa] > 0.0) || (ob >= 0 && scale[ob] > 0.0);
      if (!movable) continue;
      if (!have_hold) {
        const std::array<double, 2> zero{0.0, 0.0};
        predict(model, cm, data, q, zero, data.dist_hold);
        have_hold = true;
      }
      if (!(pn.distance < data.dist_hold.pairs[i].distance)) continue;  // no worse than holding still
      if (oa >= 0) hit[oa] = true;
      if (ob >= 0) hit[ob] = true;
    }
    if (!hit[0] && !hit[1]) break;
    for (int a = 0; a < 2; ++a)
      if (hit[a]) scale[a] = iter < 6 ? 0.5 * scale[a] : 0.0;
  }
  if (scale[0] < 1.0 || scale[1] < 1.0) {
    ++data.guard_count;
    for (int a = 0; a < 2; ++a)
      for (int i = 0; i < cm.arms[a].n; ++i) data.qdot[cm.arms[a].q[i]] *= scale[a];
  }
}

}  // namespace

bool isArmIndependent(const Model& model, const ControllerModel& cm, const ControllerData& data, int s) {
  return ownerArm(model, cm, data.dist, s) < 0;
}

bool checkWalkingStep(const Model& model, const ControllerModel& cm, ControllerData& data,
                      const Eigen::Ref<const Eigen::VectorXd>& q_next) {
  if (!computeDistancesAt(model, data, q_next, data.dist_next)) return false;
  const double floor = cm.params.d_r + cm.params.predict_margin;
  for (std::size_t i = 0; i < data.dist_next.pairs.size(); ++i) {
    const PairDistance& pn = data.dist_next.pairs[i];
    if (!pn.active || !isPhysical(model, data, pn)) continue;
    if (!(pn.distance < floor) || !(pn.distance < data.dist.pairs[i].distance)) continue;
    if (isArmIndependent(model, cm, data, pn.seg_a) && isArmIndependent(model, cm, data, pn.seg_b)) return false;
  }
  return true;
}

int findUnresolvableContact(const Model& model, const ControllerModel& cm, ControllerData& data, int slot,
                            const Eigen::Ref<const Eigen::VectorXd>& q) {
  if (slot < 0 || slot >= kBodySchemaSlots || !data.dist.slots[static_cast<std::size_t>(slot)].enabled) return -1;
  const int s = model.num_robot_segments + slot;
  if (!isArmIndependent(model, cm, data, s)) return -1;
  if (!computeDistancesAt(model, data, q, data.dist_next)) return -1;
  const double limit = cm.params.d_r + cm.params.estop_release_margin;
  for (std::size_t i = 0; i < data.dist_next.pairs.size(); ++i) {
    const PairDistance& pd = data.dist_next.pairs[i];
    if (!pd.active || (pd.seg_a != s && pd.seg_b != s)) continue;
    const int other = pd.seg_a == s ? pd.seg_b : pd.seg_a;
    if (isArmIndependent(model, cm, data, other) && !(pd.distance >= limit)) return static_cast<int>(i);
  }
  return -1;
}

SegmentAttach attachControllerSegment(const Model& model, const ControllerModel& cm, ControllerData& data, int slot,
                                      int link, const Eigen::Vector3d& a_L, const Eigen::Vector3d& b_L, double radius,
                                      std::uint64_t ignore_mask, bool is_virtual,
                                      const Eigen::Ref<const Eigen::VectorXd>& q) {
  SegmentAttach result;
  if (slot < 0 || slot >= kBodySchemaSlots) return result;
  const BodySchemaSlot previous = data.dist.slots[static_cast<std::size_t>(slot)];
  if (!attachBodySchemaSegment(model, data.dist, slot, link, a_L, b_L, radius, ignore_mask)) return result;
  const int pair = is_virtual ? -1 : findUnresolvableContact(model, cm, data, slot, q);
  if (pair >= 0) {
    data.dist.slots[static_cast<std::size_t>(slot)] = previous;
    const PairDistance& pd = data.dist_next.pairs[static_cast<std::size_t>(pair)];
    result.refusing_pair = pair;
    result.other_segment = pd.seg_a == model.num_robot_segments + slot ? pd.seg_b : pd.seg_a;
    result.distance = pd.distance;
    return result;
  }
  data.slot_virtual[static_cast<std::size_t>(slot)] = is_virtual;
  result.attached = true;
  return result;
}

ControlResult computeControl(const Model& model, const ControllerModel& cm, ControllerData& data,
                             const Eigen::Ref<const Eigen::VectorXd>& q, const ControlInput& input) {
  data.qdot.setZero();
  if (!computeForwardKinematics(model, data.kin, q)) {
    ++data.bad_input_count;
    return ControlResult::kBadInput;
  }
  // Velocity of the joints the controller does not command, from the previous measured q.
  for (int j = 0; j < model.nq; ++j) {
    const double v = data.have_prev && !data.arm_joint[static_cast<std::size_t>(j)]
                         ? (q[j] - data.q_prev[j]) / cm.params.period : 0.0;
    data.qdot_uncontrolled[j] = std::isfinite(v) ? v : 0.0;
  }
  data.q_prev = q;
  data.have_prev = true;
  ControlInput in = input;
  for (auto& hand : in.hands) {
    if (hand.status == HandStatus::kGiven && !hand.target_W.allFinite()) {
      hand.status = HandStatus::kNoTarget;  // a NaN target is never followed
      ++data.bad_input_count;
    }
  }
  DistanceOptions options;
  options.row_threshold = std::max(cm.params.d_safe, cm.params.d_a);
  computeSegmentDistances(model, data.kin, data.dist, options);

  // Red zone (Sec. 7.1): the closest physical pair.
  double d_phys = kInf;
  int pair_phys = -1;
  for (std::size_t i = 0; i < data.dist.pairs.size(); ++i) {
    const PairDistance& pd = data.dist.pairs[i];
    if (!pd.active || !isPhysical(model, data, pd)) continue;
    if (pd.distance < d_phys) {
      d_phys = pd.distance;
      pair_phys = static_cast<int>(i);
    }
  }
  if (cm.params.estop && data.estop == EstopState::kClear && d_phys < cm.params.d_r) {
    data.estop = EstopState::kLatched;
    data.estop_pair = pair_phys;
    ++data.estop_count;
  }
  if (data.estop == EstopState::kLatched) {
    if (!in.reset_estop) {
      for (int a = 0; a < 2; ++a) {
        data.trajectories[a].active = false;
        data.arms[a].f = 1.0;
        data.arms[a].qdot_force.setZero();
        data.arms[a].zone = Zone::kRed;
      }
      return ControlResult::kFrozen;
    }
    data.estop = EstopState::kRecovering;
  }
  if (data.estop == EstopState::kRecovering) {
    if (d_phys >= cm.params.d_r + cm.params.estop_release_margin) {
      data.estop = EstopState::kClear;
    } else {
      for (int a = 0; a < 2; ++a) computeArm(model, cm, data, a, in, true);
      // Allowed only if every red pair separates (row * qdot >= 0); otherwise stay frozen.
      for (std::size_t i = 0; i < data.dist.pairs.size(); ++i) {
        const PairDistance& pd = data.dist.pairs[i];
        if (!pd.active || pd.distance >= cm.params.d_r || !pd.has_row) continue;
        if (data.dist.rows.row(static_cast<Eigen::Index>(i)).dot(data.qdot) < 0.0) {
          data.qdot.setZero();
          break;
        }
      }
      if (!data.qdot.allFinite()) data.qdot.setZero();
      return ControlResult::kRecovering;
    }
  }

  // The higher-priority arm first, so the other arm's safety filter knows its motion (Sec. 7.2).
  const int first = in.priority == MotionPriority::kRightHigher ? kRight : kLeft;
  computeArm(model, cm, data, first, in, false);
  computeArm(model, cm, data, 1 - first, in, false);
  if (cm.params.mode != AvoidanceMode::kOff && data.qdot.allFinite()) predictiveGuard(model, cm, data, q, d_phys);
  if (!data.qdot.allFinite()) {
    data.qdot.setZero();
    ++data.bad_input_count;
    return ControlResult::kBadInput;
  }
  return ControlResult::kOk;
}

}  // namespace reflex::control
