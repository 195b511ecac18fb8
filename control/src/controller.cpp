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
/// The predictive guard shortens a hit arm's step at least this much per try, and aims at this share of
/// the step it estimates the hit pairs allow (predictiveGuard).
constexpr double kGuardShrink = 0.5;
constexpr double kGuardAim = 0.9;
/// A hit arm's step shortened so far that no point of the arm would move more than this (m) is held
/// instead: the same to a micrometre, and holding still is never a hit.
constexpr double kGuardNegligibleMove = 1e-6;

/// The arm (kLeft / kRight) that moves segment s this cycle, or -1 (ControllerModel's ownership; a
/// body-schema slot belongs to the arm of the link it hangs on).
int ownerArm(const Model& model, const ControllerModel& cm, const DistanceData& dist, int s) {
  if (!model.segments[s].body_schema_slot) return cm.segment_owner[static_cast<std::size_t>(s)];
  return cm.link_owner[static_cast<std::size_t>(dist.slots[s - model.num_robot_segments].link)];
}

int segmentLink(const Model& model, const DistanceData& dist, int s) {
  return model.segments[s].body_schema_slot ? dist.slots[s - model.num_robot_segments].link : model.segments[s].link;
}

/// True if `link` lies strictly below `ancestor` in the link tree (O(depth), allocation-free).
bool descendsFrom(const Model& model, int link, int ancestor) {
  for (int l = model.links[static_cast<std::size_t>(link)].parent; l >= 0;
       l = model.links[static_cast<std::size_t>(l)].parent)
    if (l == ancestor) return true;
  return false;
}

/// Pair facts for arm `a` (ArmPairFacts) from the owners and links of the pair's two segments.
/// `side`: the side of a pair on which arm `a`'s virtual force acts (Eq. 14-16): +1 for seg_a (the force
/// acts at p_B_a along +nhat_B), -1 for seg_b. For a pair with another body part that is the arm's
/// own segment. For a pair of two segments that arm `a` both moves (shoulder-hand, upper arm-hand, a
/// grasped object against the upper arm) it is the DISTAL one, whose link descends from the other's:
/// the paper's S_i are the forearm and the hand, and the force must push the hand away from the
/// shoulder, not the shoulder away from the hand (that flips its direction in the Eq. 17 merge and
/// can drive the closest pair together). Two segments on one link: seg_a.
ArmPairFacts makeArmPairFacts(const Model& model, const std::vector<std::uint64_t>& columns, int a, int owner_a,
                              int owner_b, int link_a, int link_b) {
  ArmPairFacts f;
  f.link_a = link_a;
  f.link_b = link_b;
  if (owner_a != a && owner_b != a) return f;
  const int other = owner_a == a ? owner_b : owner_a;
  f.flags = ArmPairFacts::kInvolved;
  if (other >= 0 && other != a)
    f.flags |= ArmPairFacts::kOtherArm;
  else if (other < 0)
    f.flags |= ArmPairFacts::kStatic;
  if (columns[static_cast<std::size_t>(link_a)] != 0) f.flags |= ArmPairFacts::kMovesA;
  if (columns[static_cast<std::size_t>(link_b)] != 0) f.flags |= ArmPairFacts::kMovesB;
  f.side = owner_a != a ? -1 : owner_b != a ? 1 : descendsFrom(model, link_b, link_a) ? -1 : 1;
  return f;
}

/// The distance options of the control cycle: exact distances for every pair that can feed a term
/// (within d_safe, Eq. 5, or the yellow zone, Eq. 6); pairs beyond that take no part in any term, so
/// the broad phase may skip them (their distance is then a lower bound above the threshold).
DistanceOptions cycleDistanceOptions(const ControllerModel& cm) {
  DistanceOptions options;
  // Rows are read for the orange-zone pairs (safety filter), the red ones (recovery) and, by the
  // tests, the yellow ones; Eq. 5's gradient is summed from witness points and normals
  // (collectPairTerms), so the pairs between d_a and d_safe need none.
  options.row_threshold = cm.params.d_a;
  if (cm.broad_phase) options.prune_distance = std::max(cm.params.d_safe, cm.params.d_a);
  options.find_closest = false;  // findClosestPairs finds every closest pair the cycle needs
  return options;
}

bool higherPriority(MotionPriority p, int arm) {
  return (p == MotionPriority::kLeftHigher && arm == kLeft) || (p == MotionPriority::kRightHigher && arm == kRight);
}

/// Gathers the arm's columns of a 3 x nq matrix.
void gather(const ControllerModel::Arm& arm, const Eigen::MatrixXd& full, Mat3A& out) {
  out.resize(3, arm.n);
  for (int i = 0; i < arm.n; ++i) out.col(i) = full.col(arm.q[i]);
}

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
      guard_listing(model),
      q_next(Eigen::VectorXd::Zero(model.nq)),
      kin_next(model),
      dist_next(model),
      dist_hold(model),
      J_full(Eigen::MatrixXd::Zero(3, model.nq)) {
  std::size_t most_pairs = 0;
  for (const auto& arm : cm.arms) {
    for (int i = 0; i < arm.n; ++i) arm_joint[static_cast<std::size_t>(arm.q[i])] = 1;
    most_pairs = std::max(most_pairs, arm.candidate_pairs.size());
  }
  for (int a = 0; a < 2; ++a) {
    const ControllerModel::Arm& arm = cm.arms[static_cast<std::size_t>(a)];
    std::vector<std::uint64_t>& masks = arm_columns_of_link[static_cast<std::size_t>(a)];
    masks.assign(model.links.size(), 0);
    for (std::size_t l = 0; l < model.links.size(); ++l)
      for (const int qi : model.link_support[l])
        for (int i = 0; i < arm.n; ++i)
          if (arm.q[static_cast<std::size_t>(i)] == qi) masks[l] |= std::uint64_t{1} << i;
  }
  // One entry per candidate pair: the pair-term stage can never run out of room.
  arm_ws.force_terms.resize(most_pairs);
  arm_ws.guarded_pairs.resize(most_pairs);
  arm_ws.other_rate.resize(most_pairs);
  // reach[l]: the farthest segment surface below link l, measured along the chain from l's origin
  // (joint offsets summed, so it bounds every configuration).
  const std::size_t nl = model.links.size();
  std::vector<double> reach(nl, 0.0);
  for (const Segment& seg : model.segments) {
    if (seg.body_schema_slot || seg.link < 0) continue;
    for (int k = 0; k < seg.num_primitives; ++k) {
      const Primitive& prim = model.primitives[static_cast<std::size_t>(seg.first_primitive + k)];
      const std::size_t l = static_cast<std::size_t>(linkOf(seg, prim));  // a finger's on the finger
      reach[l] = std::max(reach[l], std::max(prim.a_L.norm(), prim.b_L.norm()) + prim.radius);
    }
  }
  for (std::size_t l = nl; l-- > 1;) {  // children after parents: accumulate bottom-up
    const int parent = model.links[l].parent;
    if (parent < 0) continue;
    reach[static_cast<std::size_t>(parent)] =
        std::max(reach[static_cast<std::size_t>(parent)], model.links[l].X_P_J.translation().norm() + reach[l]);
  }
  link_sweep.assign(nl, 0.0);
  for (int a = 0; a < 2; ++a) {
    std::vector<ArmPairFacts>& facts = arm_pair_facts[static_cast<std::size_t>(a)];
    facts.assign(model.pairs.size(), ArmPairFacts{});
    for (std::size_t i = 0; i < model.pairs.size(); ++i) {
      const SegmentPair& pr = model.pairs[i];
      if (pr.b >= model.num_robot_segments) continue;  // a body-schema slot's owner changes with its link
      facts[i] = makeArmPairFacts(
          model, arm_columns_of_link[static_cast<std::size_t>(a)], a, cm.segment_owner[static_cast<std::size_t>(pr.a)],
          cm.segment_owner[static_cast<std::size_t>(pr.b)], model.segments[pr.a].link, model.segments[pr.b].link);
    }
  }
  for (std::size_t i = 0; i < model.pairs.size(); ++i)  // the left arm's pairs with the right arm
    if (arm_pair_facts[kLeft][i].flags & ArmPairFacts::kOtherArm) between_arm_pairs.push_back(static_cast<int>(i));
  grad_link_index.assign(nl, -1);
  arm_ws.grad_link.assign(nl, -1);
  arm_ws.grad_M.assign(nl, Eigen::Vector3d::Zero());
  arm_ws.grad_N.assign(nl, Eigen::Vector3d::Zero());
  guard_pairs.assign(model.pairs.size(), -1);
  guard_reach.assign(model.pairs.size(), 0.0);
  lever = Eigen::VectorXd::Zero(model.nq);
  for (int j = 0; j < model.nq; ++j) {
    const Link& link = model.links[static_cast<std::size_t>(model.q_link[j])];
    lever[j] = link.type == JointType::kPrismatic ? 1.0 : reach[static_cast<std::size_t>(model.q_link[j])];
  }
}

namespace {

/// Stage 1, the reaching task (Sec. 8): the hand point, its Jacobian, the linear trajectory towards
/// the target and the task velocity of Eq. 2 (limited to max_task_speed). No target (or recovery):
/// the trajectory is reset to the hand.
void followTrajectory(const Model& model, const ControllerModel& cm, ControllerData& data, int a,
                      const ControlInput& input, bool recovery_only, ArmWorkspace& ws) {
  const ControllerParams& params = cm.params;
  const ControllerModel::Arm& arm = cm.arms[a];
  Trajectory& traj = data.trajectories[a];
  const double dt = input.dt > 0.0 && input.dt < params.period ? input.dt : params.period;  // ControlInput::dt
  ws.q.resize(arm.n);
  for (int i = 0; i < arm.n; ++i) ws.q[i] = data.kin.q[arm.q[i]];
  ws.hand_B = data.kin.X_B_L[arm.hand_link] * arm.hand_point_L;
  data.arms[a].hand_B = ws.hand_B;
  computePointJacobian(model, data.kin, arm.hand_link, ws.hand_B, data.J_full);
  gather(arm, data.J_full, ws.J_hand);

  const HandCommand& cmd = input.hands[a];
  ws.target_given = cmd.status == HandStatus::kGiven && !recovery_only;
  ws.hand_velocity_B.setZero();
  if (ws.target_given) {
    if (!traj.active) {
      traj.active = true;
      traj.ref_B = ws.hand_B;
    }
    traj.goal_B = cmd.target_B;
    const Eigen::Vector3d to_goal = traj.goal_B - traj.ref_B;
    const double step = params.trajectory_speed * dt;
    const double remaining = to_goal.norm();
    Eigen::Vector3d v_ref = Eigen::Vector3d::Zero();
    if (remaining <= step) {
      traj.ref_B = traj.goal_B;
    } else {
      v_ref = to_goal * (params.trajectory_speed / remaining);
      traj.ref_B += v_ref * dt;
    }
    ws.hand_velocity_B = v_ref + params.reach_gain * (traj.ref_B - ws.hand_B);
    const double speed = ws.hand_velocity_B.norm();
    if (speed > params.max_task_speed) ws.hand_velocity_B *= params.max_task_speed / speed;
  } else {
    traj.active = false;
    traj.ref_B = ws.hand_B;
  }
  data.arms[a].reference_B = traj.ref_B;
}

/// Stage 2, the arm's pair terms: for every candidate pair the arm moves, its share of the merged
/// force (Eq. 14-18, inside the yellow zone), of the Eq. 5 gradient (within d_safe), the safety
/// filter's list (inside the orange zone), the step cap's contacts, and the arm's closest pair,
/// zone and f(d) (Eq. 13) into the status. Motion priority (Sec. 7.2): the higher-priority arm
/// ignores the other arm (it is the obstacle).
void collectPairTerms(const Model& model, const ControllerModel& cm, ControllerData& data, int a,
                      const ControlInput& input, bool recovery_only, ArmWorkspace& ws) {
  const ControllerParams& params = cm.params;
  const ControllerModel::Arm& arm = cm.arms[a];
  ArmStatus& status = data.arms[a];
  ws.num_force_terms = 0;
  ws.num_guarded = 0;
  ws.forces = VirtualForceSum{};
  ws.avoidance_gradient = ArmRow::Zero(arm.n);
  ws.d_other_arm = kInf;
  ws.d_static = kInf;
  // Eq. 5's gradient sum_p (d_safe - d_p) row_p on the arm's columns, without the rows: with the
  // twist (w, v) of arm joint i, row_p[i] = [i moves link_a] (w . (p_a x n) + v . n)
  // - [i moves link_b] (w . (p_b x n) + v . n). So the pairs' weighted (p x n, n) are summed per link
  // (ws.grad_*), and each arm column takes w . M + v . N over the links its joint moves (below).
  const std::vector<std::uint64_t>& columns = data.arm_columns_of_link[static_cast<std::size_t>(a)];
  ws.num_grad_links = 0;
  auto accumulate = [&](int link, const Eigen::Vector3d& p_B, const Eigen::Vector3d& n_B, double w) {
    int& k = data.grad_link_index[static_cast<std::size_t>(link)];
    if (k < 0) {
      k = ws.num_grad_links++;
      ws.grad_link[static_cast<std::size_t>(k)] = link;
      ws.grad_M[static_cast<std::size_t>(k)].setZero();
      ws.grad_N[static_cast<std::size_t>(k)].setZero();
    }
    ws.grad_M[static_cast<std::size_t>(k)] += w * p_B.cross(n_B);
    ws.grad_N[static_cast<std::size_t>(k)] += w * n_B;
  };
  // Motion priority (Sec. 7.2): the higher-priority arm ignores the other arm (not in recovery).
  const bool skip_other_arm = higherPriority(input.priority, a) && !recovery_only;
  // One pair's terms, from what the pair is to this arm (f).
  auto take = [&](int p, const PairDistance& pd, const ArmPairFacts& f) {
    if (!(f.flags & ArmPairFacts::kInvolved)) return;
    const double d = pd.distance;
    const bool with_other_arm = (f.flags & ArmPairFacts::kOtherArm) != 0;
    if (with_other_arm)
      ws.d_other_arm = std::min(ws.d_other_arm, d);
    else if (f.flags & ArmPairFacts::kStatic)
      ws.d_static = std::min(ws.d_static, d);
    if (with_other_arm && skip_other_arm) return;
    if (d < params.d_safe && !recovery_only) {
      const double w = params.d_safe - d;
      if (f.flags & ArmPairFacts::kMovesA) accumulate(f.link_a, pd.p_B_a, pd.nhat_B, w);
      if (f.flags & ArmPairFacts::kMovesB) accumulate(f.link_b, pd.p_B_b, pd.nhat_B, -w);
    }
    // Both lists hold one entry per candidate pair at most (sized at set-up): never full here.
    if (d < params.d_b && pd.has_row) ws.guarded_pairs[static_cast<std::size_t>(ws.num_guarded++)] = p;
    if (d < params.d_a) {
      // e_f,ij points from the other segment towards the arm's closest point (Eq. 16).
      ws.forces.add(params.k_virtual, params.d_a, d, f.side * pd.nhat_B, f.side > 0 ? pd.p_B_a : pd.p_B_b);
      ws.force_terms[static_cast<std::size_t>(ws.num_force_terms++)] = {p, f.side, params.k_virtual * (params.d_a - d)};
    }
  };
  // The pairs the sweep computed exactly, in ascending pair order (the candidate pairs' order). A
  // robot pair the broad phase skipped is beyond d_safe, d_a and d_b: it feeds no term and no
  // contact (it can only be the arm's closest pair, which findClosestPairs found).
  const ArmPairFacts* facts = data.arm_pair_facts[static_cast<std::size_t>(a)].data();
  forEachExactPair(data.dist, [&](int p, bool robot) {
    const PairDistance& pd = data.dist.pairs[static_cast<std::size_t>(p)];
    if (robot) {
      take(p, pd, facts[p]);
    } else {  // a body-schema slot's pair: its owner and link follow the slot's link
      take(p, pd,
           makeArmPairFacts(model, columns, a, ownerArm(model, cm, data.dist, pd.seg_a),
                            ownerArm(model, cm, data.dist, pd.seg_b), segmentLink(model, data.dist, pd.seg_a),
                            segmentLink(model, data.dist, pd.seg_b)));
    }
  });
  std::array<double, kMaxArmDof> gradient{};
  for (int k = 0; k < ws.num_grad_links; ++k) {
    const int link = ws.grad_link[static_cast<std::size_t>(k)];
    data.grad_link_index[static_cast<std::size_t>(link)] = -1;
    const Eigen::Vector3d& M = ws.grad_M[static_cast<std::size_t>(k)];
    const Eigen::Vector3d& N = ws.grad_N[static_cast<std::size_t>(k)];
    const std::uint64_t mask = columns[static_cast<std::size_t>(link)];
    for (int i = 0; i < arm.n; ++i) {
      if (!((mask >> i) & 1U)) continue;
      const auto twist = data.kin.twist_B.col(arm.q[static_cast<std::size_t>(i)]);
      gradient[static_cast<std::size_t>(i)] += twist.head<3>().dot(M) + twist.tail<3>().dot(N);
    }
  }
  for (int i = 0; i < arm.n; ++i) ws.avoidance_gradient[i] = gradient[static_cast<std::size_t>(i)];
  // The arm's closest pair (findClosestPairs, exact also where the broad phase skipped pairs): of
  // every pair it moves, or without the other arm's when the other arm is its obstacle.
  const ClosestPair& best = data.arm_closest[static_cast<std::size_t>(a)][skip_other_arm ? 1 : 0];
  const double d_min = best.distance;
  status.distance = d_min;
  status.closest_pair = best.pair;
  status.zone = zoneOf(d_min, params);
  status.f = params.mode == AvoidanceMode::kOff ? 0.0 : blendingCoefficient(d_min, params.d_a, params.d_b);
}

/// Stage 3, the merged avoidance task (Eq. 17-18): F^all, its direction and point, and J_avoid, the
/// force-weighted relative Jacobians of the yellow-zone pairs (rate of p1 - p2, arm side first).
void mergeAvoidanceJacobian(const Model& model, const ControllerModel::Arm& arm, ControllerData& data, int a,
                            ArmStatus& status, ArmWorkspace& ws) {
  ws.J_avoid = TaskJacobian::Zero(3, arm.n);
  ws.force_magnitude = 0.0;
  ws.force_dir_B.setZero();
  const double weight_sum = ws.forces.weight;
  const Eigen::Vector3d F_all = ws.forces.force();
  if (weight_sum > 0.0) {
    ws.force_magnitude = F_all.norm();
    if (ws.force_magnitude > 1e-12) ws.force_dir_B = F_all / ws.force_magnitude;
    // Each term's relative Jacobian (computeRelativeJacobian) on the arm's columns only: column i
    // is (w x p_a + v) if joint i moves link_a, minus (w x p_b + v) if it moves link_b (twist (w, v)).
    const std::vector<std::uint64_t>& columns = data.arm_columns_of_link[static_cast<std::size_t>(a)];
    for (int t = 0; t < ws.num_force_terms; ++t) {
      const ArmWorkspace::ForceTerm& term = ws.force_terms[static_cast<std::size_t>(t)];
      const PairDistance& pd = data.dist.pairs[term.pair];
      const std::uint64_t on_a = columns[static_cast<std::size_t>(segmentLink(model, data.dist, pd.seg_a))];
      const std::uint64_t on_b = columns[static_cast<std::size_t>(segmentLink(model, data.dist, pd.seg_b))];
      const double weight = (term.weight / weight_sum) * term.side;
      for (int i = 0; i < arm.n; ++i) {
        const bool moves_a = (on_a >> i) & 1U, moves_b = (on_b >> i) & 1U;
        if (!moves_a && !moves_b) continue;
        const auto twist = data.kin.twist_B.col(arm.q[static_cast<std::size_t>(i)]);
        Eigen::Vector3d col = Eigen::Vector3d::Zero();
        if (moves_a) col += twist.head<3>().cross(pd.p_B_a) + twist.tail<3>();
        if (moves_b) col -= twist.head<3>().cross(pd.p_B_b) + twist.tail<3>();
        ws.J_avoid.col(i) += weight * col;
      }
    }
  }
  status.force = ws.force_magnitude;
  status.force_dir_B = ws.force_dir_B;
  status.force_point_B = ws.forces.point();
}

/// Stage 4, the two controllers and their blend: whole-body motion (Eq. 2-5, with joint-limit
/// avoidance Eq. 4 and the rest posture without a target in its nullspace), collision avoidance
/// (Eq. 8-12: the merged virtual force, reaching in its nullspace), blended by f(d) (Eq. 1). In
/// recovery only the separating term of Eq. 8. Writes ws.qdot and status.qdot_force.
void blendControllers(const Model& model, const ControllerModel& cm, ControllerData& data, int a, bool recovery_only,
                      ArmWorkspace& ws) {
  const ControllerParams& params = cm.params;
  const ControllerModel::Arm& arm = cm.arms[a];
  ArmStatus& status = data.arms[a];
  const int n = arm.n;
  VecA xi_jla(n);
  for (int i = 0; i < n; ++i) {
    const int qi = arm.q[i];
    const double lo = model.q_lower[qi], hi = model.q_upper[qi];
    const double half = 0.5 * (hi - lo);
    xi_jla[i] =
        std::isfinite(half) && half > 0.0 ? -params.alpha_jla * (ws.q[i] - 0.5 * (hi + lo)) / (half * half) : 0.0;
  }
  VecA xi_rest = VecA::Zero(n);
  if (!ws.target_given) xi_rest = -params.alpha_rest * (ws.q - arm.rest.head(n));

  // The virtual-force term of Eq. 8 along the merged direction: row^+ |F^all|.
  const RowA avoid_row = ws.force_dir_B.transpose() * ws.J_avoid;  // J_ca|row,y in the merged frame
  VecA avoid_row_pinv;
  dampedPseudoInverse(avoid_row, params.damping, avoid_row_pinv);
  VecA qdot_force = VecA::Zero(n);
  if (ws.force_magnitude > 0.0) qdot_force = avoid_row_pinv * ws.force_magnitude;
  // three_dof: the whole merged force, J_ca^+ F^all (Eq. 8 with a 3-D task).
  MatA3 J_avoid_pinv;
  if (params.mode == AvoidanceMode::kThreeDof) dampedPseudoInverse(ws.J_avoid, params.damping, J_avoid_pinv);
  status.qdot_force = params.mode == AvoidanceMode::kThreeDof && !recovery_only
                          ? VecA(J_avoid_pinv * (ws.force_magnitude * ws.force_dir_B))
                          : qdot_force;

  ws.qdot.resize(n);
  if (recovery_only) {
    ws.qdot = qdot_force;  // only the separating motion of Eq. 8: nothing in the nullspace
    return;
  }
  // Whole-body motion, Eq. 2-5.
  MatA3 J_hand_pinv;
  dampedPseudoInverse(ws.J_hand, params.damping, J_hand_pinv);
  MatA N_wbm;
  nullspaceProjector(ws.J_hand, N_wbm);
  VecA xi_ca = VecA::Zero(n);
  if (params.mode != AvoidanceMode::kOff) xi_ca = params.alpha_ca * ws.avoidance_gradient.transpose();
  VecA qdot_wbm(n);
  if (ws.target_given)
    qdot_wbm = J_hand_pinv * ws.hand_velocity_B + N_wbm * (xi_ca + xi_jla);
  else
    qdot_wbm = xi_ca + xi_jla + xi_rest;

  if (params.mode == AvoidanceMode::kOff || status.f <= 0.0) {
    ws.qdot = qdot_wbm;
    return;
  }
  // Collision avoidance, Eq. 8-12: the virtual force along one direction, reaching in its nullspace.
  VecA xi_t(n);
  if (ws.target_given)
    xi_t = -params.alpha_t * (ws.J_hand.transpose() * (ws.hand_B - data.trajectories[a].ref_B));  // Eq. 12, W_t = I
  else
    xi_t = xi_rest;
  VecA qdot_ca(n);
  MatA N_ca;
  if (params.mode == AvoidanceMode::kOneDof) {
    nullspaceProjector(avoid_row, N_ca);
    qdot_ca = qdot_force + N_ca * xi_t;
  } else {
    nullspaceProjector(ws.J_avoid, N_ca);
    qdot_ca = status.qdot_force + N_ca * xi_t;
  }
  ws.qdot = (1.0 - status.f) * qdot_wbm + status.f * qdot_ca;  // Eq. 1
}

/// Stage 5, joint position limits: a step never crosses a limit (the robot would clamp the motion
/// away, so what it does would differ from what the filter checked). The box [v_lo, v_hi] holds 0.
void limitToJointRange(const Model& model, const ControllerModel::Arm& arm, double dt, ArmWorkspace& ws) {
  ws.v_lo.resize(arm.n);
  ws.v_hi.resize(arm.n);
  for (int i = 0; i < arm.n; ++i) {
    const int qi = arm.q[i];
    ws.v_lo[i] = std::min(0.0, (model.q_lower[qi] - ws.q[i]) / dt);
    ws.v_hi[i] = std::max(0.0, (model.q_upper[qi] - ws.q[i]) / dt);
    ws.qdot[i] = std::clamp(ws.qdot[i], ws.v_lo[i], ws.v_hi[i]);
  }
}

/// Stage 6, the safety filter (not in the paper): inside the orange zone, this arm may approach a
/// pair no faster than guard_rate (d - d_r - guard_margin), so the distance decays at most
/// exponentially towards a floor above d_r. Merging several pairs into one direction (Eq. 17) and
/// the reaching gradient in the collision controller's nullspace can otherwise leak motion into a
/// pair that is not the merged direction; this removes exactly that component and nothing else.
void applySafetyFilter(const Model& model, const ControllerModel& cm, ControllerData& data, int a,
                       const ControlInput& input, ArmWorkspace& ws) {
  const ControllerParams& params = cm.params;
  const ControllerModel::Arm& arm = cm.arms[a];
  const int n = arm.n;
  // What moves each guarded pair besides this arm, fixed for this cycle (computed once, not per
  // iteration). The higher-priority arm was computed first (computeControl orders them): its motion
  // is known, so the pair's approach includes it (the obstacle arm does not avoid). Walking and
  // balance move the legs (and everything above them) without asking: their estimated motion counts
  // too (legs always win, Sec. 7.2); qdot_uncontrolled is zero on the arm joints.
  const ControllerModel::Arm& other_arm = cm.arms[1 - a];
  const bool other_arm_known = higherPriority(input.priority, 1 - a);
  ws.other_approach = 0.0;
  for (int g = 0; g < ws.num_guarded; ++g) {
    const int p = ws.guarded_pairs[static_cast<std::size_t>(g)];
    double rate = 0.0;
    if (other_arm_known) {
      for (int i = 0; i < other_arm.n; ++i) rate += data.dist.rows(p, other_arm.q[i]) * data.qdot[other_arm.q[i]];
    }
    for (int j = 0; j < model.nq; ++j) rate += data.dist.rows(p, j) * data.qdot_uncontrolled[j];
    ws.other_rate[static_cast<std::size_t>(g)] = rate;
    ws.other_approach = std::max(ws.other_approach, -rate);
  }
  for (int iter = 0; iter < 6; ++iter) {
    bool changed = false;
    for (int g = 0; g < ws.num_guarded; ++g) {
      const int p = ws.guarded_pairs[static_cast<std::size_t>(g)];
      const double d = data.dist.pairs[p].distance;
      RowA row(n), free_row(n);
      for (int i = 0; i < n; ++i) {
        row[i] = data.dist.rows(p, arm.q[i]);
        // A joint whose correction would leave its limit box cannot take it.
        const bool blocked = (row[i] > 0.0 && ws.qdot[i] >= ws.v_hi[i]) || (row[i] < 0.0 && ws.qdot[i] <= ws.v_lo[i]);
        free_row[i] = blocked ? 0.0 : row[i];
      }
      const double free_norm_sq = free_row.squaredNorm();
      if (free_norm_sq < 1e-12) continue;
      const double allowed = -params.guard_rate * std::max(0.0, d - params.d_r - params.guard_margin);
      const double rate = row.dot(ws.qdot.transpose()) + ws.other_rate[static_cast<std::size_t>(g)];
      if (rate < allowed - 1e-12) {
        ws.qdot += free_row.transpose() * ((allowed - rate) / free_norm_sq);
        for (int i = 0; i < n; ++i) ws.qdot[i] = std::clamp(ws.qdot[i], ws.v_lo[i], ws.v_hi[i]);
        changed = true;
      }
    }
    if (!changed) break;
  }
}

/// Stage 7, joint velocity limits: uniform scaling keeps the direction (and every filtered pair's bound).
void scaleToVelocityLimits(const Model& model, const ControllerModel::Arm& arm, ArmWorkspace& ws) {
  double scale = 1.0;
  for (int i = 0; i < arm.n; ++i) {
    const int qi = arm.q[i];
    const double v = std::abs(ws.qdot[i]);
    if (v > model.v_max[qi]) scale = std::min(scale, model.v_max[qi] / v);
  }
  ws.qdot *= scale;
}

/// Stage 8, the step cap inside the orange zone (part of the safety filter): the filter bounds the
/// approach to first order along each pair's current normal, but a large step can make another
/// primitive of the same segment the closest one (the chest has three). So no point of the arm may
/// move more than half the remaining gap above d_r in one cycle: sum |qdot_i| * lever_i * dt <=
/// (d - d_r) / 2, with lever_i the distance from joint i to the hand plus 0.1 m, unless something
/// else (the legs walking, a higher-priority arm) approaches one of the arm's orange pairs this
/// cycle faster than 1 mm/s (ArmWorkspace::other_approach): freezing the arm would let it be hit
/// (a walking thigh into a hand hanging at its joint limits, bench_soak seed 1373 on
/// many_segment_humanoid), so the filtered step stands and the predictive guard checks it. Scaling
/// keeps every bound above. Against the other arm only with equal priority: a yielding arm must be
/// free to get out of the way, and a higher-priority arm is untouched by the other arm (Sec. 7.2;
/// the e-stop is the last resort).
void capStepInOrangeZone(const ControllerModel& cm, const ControllerData& data, const ControllerModel::Arm& arm,
                         const Model& model, const ControlInput& input, ArmWorkspace& ws) {
  const ControllerParams& params = cm.params;
  const bool equal = input.priority == MotionPriority::kEqual;
  const double d_contact = equal ? std::min(ws.d_static, ws.d_other_arm) : ws.d_static;
  if (!(d_contact < params.d_b)) return;
  double sweep = 0.0;
  for (int i = 0; i < arm.n; ++i) {
    const double lever = (ws.hand_B - data.kin.X_B_L[model.q_link[arm.q[i]]].translation()).norm() + 0.1;
    sweep += std::abs(ws.qdot[i]) * lever * params.period;
  }
  // Not while the rest of the robot brings one of the arm's orange pairs closer (walking, balance,
  // a higher-priority arm) at a real speed: against a moving obstacle a frozen arm is hit, so the arm
  // keeps the step the filter shaped to get away, and the predictive guard checks it one period
  // ahead. (The speed floor keeps the cap against a still body whose measured joints only jitter.)
  constexpr double kMovingObstacleSpeed = 0.001;  // m/s
  if (ws.other_approach > kMovingObstacleSpeed) return;
  const double budget = 0.5 * std::max(0.0, d_contact - params.d_r);
  if (sweep > budget) ws.qdot *= budget / sweep;
}

/// Controller for one arm: Eq. 1-18 on its own joints, stage by stage (ArmWorkspace). Writes the
/// arm's joint velocities into data.qdot. recovery_only: leaving a latched e-stop, only the
/// separating motion of Eq. 8.
void computeArm(const Model& model, const ControllerModel& cm, ControllerData& data, int a, const ControlInput& input,
                bool recovery_only) {
  const ControllerModel::Arm& arm = cm.arms[a];
  ArmWorkspace& ws = data.arm_ws;
  followTrajectory(model, cm, data, a, input, recovery_only, ws);
  collectPairTerms(model, cm, data, a, input, recovery_only, ws);
  mergeAvoidanceJacobian(model, arm, data, a, data.arms[a], ws);
  blendControllers(model, cm, data, a, recovery_only, ws);
  limitToJointRange(model, arm, cm.params.period, ws);
  const bool filter = cm.params.mode != AvoidanceMode::kOff && !recovery_only;
  if (filter) applySafetyFilter(model, cm, data, a, input, ws);
  scaleToVelocityLimits(model, arm, ws);
  if (filter) capStepInOrangeZone(cm, data, arm, model, input, ws);
  for (int i = 0; i < arm.n; ++i) data.qdot[arm.q[i]] = ws.qdot[i];
}

/// A pair between physical segments (a virtual occlusion slot never counts for safety).
bool isPhysical(const Model& model, const ControllerData& data, const PairDistance& pd) {
  const int sb = pd.seg_b;
  return !(model.segments[sb].body_schema_slot &&
           data.dist.slots[static_cast<std::size_t>(sb - model.num_robot_segments)].is_virtual);
}

/// What a body-schema slot's pair is to arm a (ArmPairFacts::kInvolved, kOtherArm), from the owners
/// of its segments (a robot pair's facts are ControllerData::arm_pair_facts).
std::uint8_t slotPairFlags(int a, int owner_a, int owner_b) {
  if (owner_a != a && owner_b != a) return 0;
  const int other = owner_a == a ? owner_b : owner_a;
  return ArmPairFacts::kInvolved | (other >= 0 && other != a ? ArmPairFacts::kOtherArm : 0);
}

/// Every closest pair a cycle reports, ties to the lower pair index: the closest physical pair, the
/// closest virtual one, the closest between the two arms, and each arm's (of every pair it moves, and
/// without the other arm's: data.arm_closest). First the pairs the sweep computed exactly, then one
/// walk over the skipped robot pairs: one whose lower bound is below the closest of a kind it belongs
/// to is computed exactly and offered to that kind (refineClosest's rule for several kinds at once),
/// so every one is what the unpruned sweep gives.
void findClosestPairs(const Model& model, const ControllerModel& cm, ControllerData& data) {
  ClosestPair physical, virtual_slot, between_arms;
  std::array<std::array<ClosestPair, 2>, 2> arm{};
  // Whether a pair of these facts is of an arm's kind k (0: every pair the arm moves, 1: not the other arm's).
  auto armKind = [](std::uint8_t flags, std::size_t k) {
    return (flags & ArmPairFacts::kInvolved) && (k == 0 || !(flags & ArmPairFacts::kOtherArm));
  };
  auto offerToArms = [&](int i, double d, std::uint8_t left, std::uint8_t right) {
    const std::array<std::uint8_t, 2> flags{left, right};
    for (std::size_t a = 0; a < 2; ++a)
      for (std::size_t k = 0; k < 2; ++k)
        if (armKind(flags[a], k)) arm[a][k].offer(d, i);
  };
  const std::vector<ArmPairFacts>& left_facts = data.arm_pair_facts[kLeft];
  const std::vector<ArmPairFacts>& right_facts = data.arm_pair_facts[kRight];
  // The pairs the sweep computed exactly (robot pairs are all physical).
  forEachExactPair(data.dist, [&](int i, bool robot) {
    const PairDistance& pd = data.dist.pairs[static_cast<std::size_t>(i)];
    if (robot) {
      const std::uint8_t left = left_facts[static_cast<std::size_t>(i)].flags;
      physical.offer(pd.distance, i);
      if (left & ArmPairFacts::kOtherArm) between_arms.offer(pd.distance, i);
      offerToArms(i, pd.distance, left, right_facts[static_cast<std::size_t>(i)].flags);
      return;
    }
    if (isPhysical(model, data, pd))
      physical.offer(pd.distance, i);
    else
      virtual_slot.offer(pd.distance, i);
    const int owner_a = ownerArm(model, cm, data.dist, pd.seg_a);
    const int owner_b = ownerArm(model, cm, data.dist, pd.seg_b);
    offerToArms(i, pd.distance, slotPairFlags(kLeft, owner_a, owner_b), slotPairFlags(kRight, owner_a, owner_b));
  });
  const DistanceOptions options = cycleDistanceOptions(cm);
  // Between the arms a skipped pair is the closest every cycle the hands are apart: the one with the
  // smallest bound goes first, its true distance then rules out nearly all the others.
  if (data.dist.pruned_floor < between_arms.distance) {
    int first = -1;
    double first_bound = between_arms.distance;
    for (const int i : data.between_arm_pairs) {
      const PairDistance& pd = data.dist.pairs[static_cast<std::size_t>(i)];
      if (!pd.exact && pd.distance < first_bound) {
        first_bound = pd.distance;
        first = i;
      }
    }
    if (first >= 0) {
      refinePairDistance(model, data.kin, data.dist, first, options);
      between_arms.offer(data.dist.pairs[static_cast<std::size_t>(first)].distance, first);
    }
  }
  // The skipped robot pairs (never slot pairs), in one walk. A pair is refined when its bound is below
  // the closest of some kind it belongs to, and offered to each such kind. The kinds only get closer
  // during the walk, so a bound at or above the farthest of them at the start rules a pair out. A pair
  // already refined (by the sweep or the step above) is exact but not in the sweep's list: the walk
  // takes it too (BroadPhase.ClosestPairsAreTheBruteForcesWhenTheCycleRefinedThem).
  double farthest = std::max(physical.distance, between_arms.distance);
  for (const auto& of_arm : arm) farthest = std::max({farthest, of_arm[0].distance, of_arm[1].distance});
  if (data.dist.pruned_floor < farthest) {
    for (const int i : data.dist.robot_pairs) {
      PairDistance& pd = data.dist.pairs[static_cast<std::size_t>(i)];
      const double bound = pd.distance;
      if (!(bound < farthest)) continue;
      const std::uint8_t left = left_facts[static_cast<std::size_t>(i)].flags;
      const std::array<std::uint8_t, 2> flags{left, right_facts[static_cast<std::size_t>(i)].flags};
      // The kinds pair i belongs to whose closest its bound is below.
      const bool to_physical = bound < physical.distance;
      const bool to_between = (left & ArmPairFacts::kOtherArm) && bound < between_arms.distance;
      std::array<std::array<bool, 2>, 2> to_arm{};
      bool any = to_physical || to_between;
      for (std::size_t a = 0; a < 2; ++a)
        for (std::size_t k = 0; k < 2; ++k) {
          to_arm[a][k] = armKind(flags[a], k) && bound < arm[a][k].distance;
          any = any || to_arm[a][k];
        }
      if (!any) continue;
      if (!pd.exact) refinePairDistance(model, data.kin, data.dist, i, options);
      const double d = pd.distance;
      if (to_physical) physical.offer(d, i);
      if (to_between) between_arms.offer(d, i);
      for (std::size_t a = 0; a < 2; ++a)
        for (std::size_t k = 0; k < 2; ++k)
          if (to_arm[a][k]) arm[a][k].offer(d, i);
    }
  }
  data.closest_physical = physical;
  data.closest_virtual = virtual_slot;
  data.closest_between_arms = between_arms;
  data.arm_closest = arm;
}

/// Distances (no avoidance rows) of every pair at configuration q, with this cycle's body-schema
/// slots, into `out` (kin_next is the scratch). False if q is not finite (out is then untouched).
/// Pairs farther than d_b may be skipped by the broad phase (distance: a lower bound above d_b): every
/// caller compares with d_r + predict_margin or d_r + estop_release_margin, both at most d_b.
bool computeDistancesAt(const Model& model, const ControllerModel& cm, ControllerData& data,
                        const Eigen::Ref<const Eigen::VectorXd>& q, DistanceData& out) {
  if (!computeForwardKinematics(model, data.kin_next, q)) return false;
  DistanceOptions no_rows;
  no_rows.row_threshold = -kInf;
  no_rows.find_closest = false;  // the callers compare every pair with a floor
  if (cm.broad_phase) no_rows.prune_distance = cm.params.d_b;
  computeSegmentDistances(model, data.kin_next, data.dist.slots, out, no_rows);  // this cycle's schema, not copied
  return true;
}

/// Predicts the configuration one period ahead, q + dt (scaled arm velocities + uncontrolled ones),
/// and computes there the guard's listed pairs (data.guard_pairs) into `out`, exactly.
void predict(const Model& model, const ControllerModel& cm, ControllerData& data,
             const Eigen::Ref<const Eigen::VectorXd>& q, const std::array<double, 2>& scale, DistanceData& out) {
  const double dt = cm.params.period;
  for (int j = 0; j < model.nq; ++j) data.q_next[j] = q[j] + dt * data.qdot_uncontrolled[j];
  for (int a = 0; a < 2; ++a)
    for (int i = 0; i < cm.arms[a].n; ++i) data.q_next[cm.arms[a].q[i]] += dt * scale[a] * data.qdot[cm.arms[a].q[i]];
  if (!computeForwardKinematics(model, data.kin_next, data.q_next, &data.kin)) {  // only moving joints' links
    for (auto& pd : out.pairs) pd.distance = -kInf;  // cannot happen for finite q; counts as a hit
    return;
  }
  // Only whether a pair ends below d_r + predict_margin matters (predictiveGuard): a pair of the tight
  // model proven above it is left a lower bound (above it too: never a hit, the same outcome).
  const double floor = cm.params.d_r + cm.params.predict_margin;
  // With the broad phase, the primitive pairs predictiveGuard listed once this cycle.
  computeListedPairDistances(model, data.kin_next, data.dist.slots, out, data.guard_pairs.data(), data.num_guard_pairs,
                             floor, cm.broad_phase ? &data.guard_listing : nullptr);
}

/// The predictive guard's search (predictiveGuard): each arm's scale of its step, 1 if no physical
/// pair of the listed guard pairs (data.guard_pairs) is a hit one period ahead, else shortened until
/// none is (at most six tries, then 0; 0 at once when the shortened step would move no point of the
/// arm more than kGuardNegligibleMove, `arm_move`: how far its whole step can move one).
std::array<double, 2> guardStepScales(const Model& model, const ControllerModel& cm, ControllerData& data,
                                      const Eigen::Ref<const Eigen::VectorXd>& q, double floor,
                                      const std::array<double, 2>& arm_move) {
  // Holding the arms still leaves the robot where it is unless walking or balance moves it: then the
  // distances of holding still are this cycle's (a pair the sweep left as a lower bound is above the
  // floor either way, so every comparison below comes out the same), and the hold is not predicted.
  bool have_hold = false, hold_is_now = true;
  for (int j = 0; j < model.nq; ++j) hold_is_now = hold_is_now && data.qdot_uncontrolled[j] == 0.0;
  std::array<double, 2> scale{1.0, 1.0};
  for (int iter = 0; iter < 8; ++iter) {
    predict(model, cm, data, q, scale, data.dist_next);
    std::array<bool, 2> hit{false, false};
    std::array<double, 2> shrink{kGuardShrink, kGuardShrink};  // each hit arm's next scale / this one
    for (int k = 0; k < data.num_guard_pairs; ++k) {
      const std::size_t i = static_cast<std::size_t>(data.guard_pairs[static_cast<std::size_t>(k)]);
      const PairDistance& pn = data.dist_next.pairs[i];
      const PairDistance& p0 = data.dist.pairs[i];
      if (!pn.active || !isPhysical(model, data, pn)) continue;
      if (!(pn.distance < floor) || !(pn.distance < p0.distance)) continue;
      // Ownership from this cycle's body schema (data.dist.slots, which the prediction used).
      const int owner_a = ownerArm(model, cm, data.dist, pn.seg_a);
      const int owner_b = ownerArm(model, cm, data.dist, pn.seg_b);
      const bool movable = (owner_a >= 0 && scale[owner_a] > 0.0) || (owner_b >= 0 && scale[owner_b] > 0.0);
      if (!movable) continue;
      if (!have_hold && !hold_is_now) {
        const std::array<double, 2> zero{0.0, 0.0};
        predict(model, cm, data, q, zero, data.dist_hold);
        have_hold = true;
      }
      const double held = hold_is_now ? p0.distance : data.dist_hold.pairs[i].distance;
      if (!(pn.distance < held)) continue;  // no worse than holding still
      // The pair is no hit at or above `least`. From now (scale 0) to this step its distance is taken
      // as straight: the fraction of the step that ends at `least`, with a tenth to spare, is the next
      // try (at most half: the search still ends within the iterations). Pressed at the floor that is
      // almost zero at once. Only exact distances enter: `least` is below the floor, and the start is
      // capped at d_b (within the sweep's prune distance, so exact with or without the broad phase).
      const double least = std::min({floor, p0.distance, held});
      const double start = std::min(p0.distance, cm.params.d_b);
      const double fraction = (start - least) / (start - pn.distance);
      const double next = fraction >= 0.0 ? std::min(kGuardShrink, kGuardAim * fraction) : kGuardShrink;
      for (const int owner : {owner_a, owner_b}) {
        if (owner < 0) continue;
        hit[owner] = true;
        shrink[owner] = std::min(shrink[owner], next);
      }
    }
    if (!hit[0] && !hit[1]) break;
    for (int a = 0; a < 2; ++a) {
      if (!hit[a]) continue;
      scale[a] = iter < 6 ? shrink[a] * scale[a] : 0.0;
      // An arm pressed at the floor gets a vanishing step (its pairs have nothing left to give): held,
      // it needs no more predictions.
      if (scale[a] * arm_move[a] < kGuardNegligibleMove) scale[a] = 0.0;
    }
    if (scale[0] == 0.0 && scale[1] == 0.0) break;  // no arm moves: no pair can count as a hit
  }
  return scale;
}

/// Predictive guard (not in the paper; ControllerParams::predict_margin). d_phys: this cycle's
/// closest physical pair (computeControl's red-zone check). The two filters inside
/// computeArm bound the approach to first order; this one checks the step itself. Each arm's step is
/// shortened (at most six times, each to at most half, then dropped; dropped at once below a
/// micrometre of motion) while, one period ahead, some
/// physical pair of that arm would end below d_r + predict_margin AND closer than it is now and than
/// it would be if the arms held still (so walking motion that no arm step can undo is not blamed on
/// the arms). Each try aims where the hit pairs, taken as straight from now to the step, end at what
/// they may: an arm pressed at the floor is held after one prediction (its step would shrink to
/// nothing), not after eight. On the kinematic robot the prediction is exact for the arms, so no arm motion ever
/// enters the red zone.
void predictiveGuard(const Model& model, const ControllerModel& cm, ControllerData& data,
                     const Eigen::Ref<const Eigen::VectorXd>& q, double d_phys) {
  const ControllerParams& params = cm.params;
  const double floor = params.d_r + params.predict_margin;
  data.num_guard_pairs = 0;
  // Cheap exit: in one period no point moves more than sum |qdot_j| lever_j dt (body-schema slots
  // add their own extent to every lever), so no distance changes by more than twice that.
  double slot_extent = 0.0;
  for (const BodySchemaSlot& slot : data.dist.slots)
    if (slot.enabled) slot_extent = std::max(slot_extent, std::max(slot.a_L.norm(), slot.b_L.norm()) + slot.radius);
  double sweep = 0.0;
  for (int j = 0; j < model.nq; ++j)
    sweep += std::abs(data.qdot[j] + data.qdot_uncontrolled[j]) * (data.lever[j] + slot_extent) * params.period;
  if (d_phys - 2.0 * sweep > floor) return;
  // The same bound per pair: a point of a segment moves at most the sum over the joints that move
  // its link (data.link_sweep, accumulated down the tree), so a pair whose distance (or the broad
  // phase's lower bound) minus both its segments' sweeps stays above the floor cannot end below it
  // in any prediction (each scales the arms' steps by at most 1). Only if some pair can is the step
  // predicted; the outcome is the one the full check gives.
  for (std::size_t l = 0; l < model.links.size(); ++l) {
    const int parent = model.links[l].parent;
    double s = parent >= 0 ? data.link_sweep[static_cast<std::size_t>(parent)] : 0.0;
    const int j = model.links[l].q_index;
    if (j >= 0) s += std::abs(data.qdot[j] + data.qdot_uncontrolled[j]) * (data.lever[j] + slot_extent) * params.period;
    data.link_sweep[l] = s;
  }
  // A segment of several links (a hand with its fingers) is looked up by its link: it takes the most
  // any of its links can move (fingers the robot closes itself move more than the hand).
  for (int sg = 0; sg < model.num_robot_segments; ++sg) {
    if (!data.dist.several_links[static_cast<std::size_t>(sg)]) continue;
    double& own = data.link_sweep[static_cast<std::size_t>(model.segments[static_cast<std::size_t>(sg)].link)];
    for (int k = data.dist.seg_block[static_cast<std::size_t>(sg)];
         k < data.dist.seg_block[static_cast<std::size_t>(sg) + 1]; ++k)
      own = std::max(own, data.link_sweep[static_cast<std::size_t>(data.dist.block_link[static_cast<std::size_t>(k)])]);
  }
  // The pairs the step can bring below the floor, and only those, are predicted: a physical pair
  // that an arm moves and whose bound does not clear the floor. Every other pair can never count
  // as a hit below (it ends above the floor, or no arm's scale can change it). A pair the sweep
  // skipped is at least pruned_floor away (refined ones too): if two of the largest link sweeps
  // cannot close that, only the sweep's exact pairs and the slot pairs need a look.
  data.num_guard_pairs = 0;
  double most_sweep = 0.0;
  for (const double s : data.link_sweep) most_sweep = std::max(most_sweep, s);
  auto consider = [&](int i, const PairDistance& pd, int owner_a, int owner_b, int link_a, int link_b) {
    if (owner_a < 0 && owner_b < 0) return;
    const double reach =
        data.link_sweep[static_cast<std::size_t>(link_a)] + data.link_sweep[static_cast<std::size_t>(link_b)];
    // Without the broad phase (tests' brute-force reference): every such pair, whatever its bound.
    if (!cm.broad_phase || !(pd.distance - reach > floor)) {
      data.guard_reach[static_cast<std::size_t>(data.num_guard_pairs)] = reach;
      data.guard_pairs[static_cast<std::size_t>(data.num_guard_pairs++)] = i;
    }
  };
  if (data.dist.pruned_floor - 2.0 * most_sweep > floor) {
    forEachExactPair(data.dist, [&](int i, bool robot) {
      const PairDistance& pd = data.dist.pairs[static_cast<std::size_t>(i)];
      if (robot) {
        const ArmPairFacts& left = data.arm_pair_facts[kLeft][static_cast<std::size_t>(i)];
        if ((left.flags | data.arm_pair_facts[kRight][static_cast<std::size_t>(i)].flags) & ArmPairFacts::kInvolved)
          consider(i, pd, cm.segment_owner[static_cast<std::size_t>(pd.seg_a)],
                   cm.segment_owner[static_cast<std::size_t>(pd.seg_b)], left.link_a, left.link_b);
      } else if (isPhysical(model, data, pd)) {
        consider(i, pd, ownerArm(model, cm, data.dist, pd.seg_a), ownerArm(model, cm, data.dist, pd.seg_b),
                 segmentLink(model, data.dist, pd.seg_a), segmentLink(model, data.dist, pd.seg_b));
      }
    });
  } else {
    const int npairs = static_cast<int>(data.dist.pairs.size());
    for (int i = 0; i < npairs; ++i) {
      const PairDistance& pd = data.dist.pairs[static_cast<std::size_t>(i)];
      if (!pd.active || !isPhysical(model, data, pd)) continue;
      consider(i, pd, ownerArm(model, cm, data.dist, pd.seg_a), ownerArm(model, cm, data.dist, pd.seg_b),
               segmentLink(model, data.dist, pd.seg_a), segmentLink(model, data.dist, pd.seg_b));
    }
  }
  if (data.num_guard_pairs == 0) return;
  // Every prediction below moves each point at most its link's sweep from this cycle's poses (the
  // sweep's, bounding spheres in place with the broad phase): list the primitive pairs once.
  if (cm.broad_phase)
    listPairsNear(model, data.dist, data.guard_pairs.data(), data.num_guard_pairs, floor, data.guard_reach.data(),
                  data.guard_listing);

  // How far each arm's own step can move a point of it (its joints' share of the sweep above).
  std::array<double, 2> arm_move{0.0, 0.0};
  for (int a = 0; a < 2; ++a)
    for (int i = 0; i < cm.arms[a].n; ++i) {
      const int j = cm.arms[a].q[i];
      arm_move[a] += std::abs(data.qdot[j]) * (data.lever[j] + slot_extent) * params.period;
    }
  const std::array<double, 2> scale = guardStepScales(model, cm, data, q, floor, arm_move);
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
  if (!computeDistancesAt(model, cm, data, q_next, data.dist_next)) return false;
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
  if (!computeDistancesAt(model, cm, data, q, data.dist_next)) return -1;
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
  data.dist.slots[static_cast<std::size_t>(slot)].is_virtual = is_virtual;
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
  const double cycle_dt =
      input.dt > 0.0 && input.dt < cm.params.period ? input.dt : cm.params.period;  // ControlInput::dt
  for (int j = 0; j < model.nq; ++j) {
    const double v =
        data.have_prev && !data.arm_joint[static_cast<std::size_t>(j)] ? (q[j] - data.q_prev[j]) / cycle_dt : 0.0;
    data.qdot_uncontrolled[j] = std::isfinite(v) ? v : 0.0;
  }
  data.q_prev = q;
  data.have_prev = true;
  ControlInput in = input;
  for (auto& hand : in.hands) {
    if (hand.status == HandStatus::kGiven && !hand.target_B.allFinite()) {
      hand.status = HandStatus::kNoTarget;  // a NaN target is never followed
      ++data.bad_input_count;
    }
  }
  computeSegmentDistances(model, data.kin, data.dist, cycleDistanceOptions(cm));

  // Red zone (Sec. 7.1): the closest physical pair (and, for the callers, the closest virtual one).
  findClosestPairs(model, cm, data);
  const double d_phys = data.closest_physical.distance;
  const int pair_phys = data.closest_physical.pair;
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
