// The merged virtual force of Eq. 14-18 against an independent re-implementation
// written here from the paper, on random yellow-zone states of the shipped robot.
//
// What is checked against what:
// - ArmStatus::qdot_force (the virtual-force term row^+ |F^all| of computeControl) equals this
//   file's own Eq. 14-18 + Eq. 8: per pair F_ij = k (d_a - d) e_ij with e_ij pointing from the other
//   segment towards the arm's segment; for a pair of two segments of the same arm the arm's segment
//   is the DISTAL one (its link descends from the other's in the link tree, found here by walking
//   parents; the paper's S_i are the forearm and the hand). Before the fix the code put such a
//   pair's force on the proximal segment (the one listed first), which flips e_ij in the merge.
// - Property (the rates use DistanceData::rows, themselves checked against finite differences of
//   the distance in control_distance_test): the virtual-force term never approaches the arm's
//   closest pair, and never approaches a yellow pair that the merge of the arm's other yellow pairs
//   would have separated (adding a pair's own force never turns it from separating into approaching).
//   Both are measured over every state; what is asserted and why is said at the assertions.
#include "support/robot.hpp"

#include "reflex/control/redundancy.hpp"

#include <gtest/gtest.h>

#include <cstdio>
#include <random>
#include <vector>

namespace reflex::control {
namespace {

using testing::defaultControllerModel;
using testing::shippedModel;

bool descends(const Model& model, int link, int ancestor) {
  for (int l = model.links[static_cast<std::size_t>(link)].parent; l >= 0;
       l = model.links[static_cast<std::size_t>(l)].parent)
    if (l == ancestor) return true;
  return false;
}

/// One yellow pair as this test sees it: which side is the arm's point.
struct Term {
  int pair = -1;
  double weight = 0.0;    // |F_ij| = k (d_a - d)
  Eigen::Vector3d e;      // unit, from the other segment towards the arm's point
  Eigen::MatrixXd J_rel;  // 3 x n: rate of (arm point - other point), arm columns
};

/// The arm's yellow pairs (equal priority, no e-stop: every pair that involves the arm).
std::vector<Term> yellowTerms(const Model& model, const ControllerModel& cm, const ControllerData& data, int a) {
  const ControllerParams& P = cm.params;
  const ControllerModel::Arm& arm = cm.arms[a];
  std::vector<Term> terms;
  Eigen::MatrixXd J_full(3, model.nq);
  for (std::size_t p = 0; p < data.dist.pairs.size(); ++p) {
    const PairDistance& pd = data.dist.pairs[p];
    if (!pd.active || !(pd.distance < P.d_a)) continue;
    const int la = model.segments[pd.seg_a].link, lb = model.segments[pd.seg_b].link;
    const bool in_a = arm.link_in_arm[la], in_b = arm.link_in_arm[lb];
    if (!in_a && !in_b) continue;
    bool arm_is_a = in_a;
    if (in_a && in_b) arm_is_a = !descends(model, lb, la);  // the distal segment carries the force
    Term t;
    t.pair = static_cast<int>(p);
    t.weight = P.k_virtual * (P.d_a - pd.distance);
    t.e = arm_is_a ? pd.nhat_B : Eigen::Vector3d(-pd.nhat_B);
    computeRelativeJacobian(model, data.kin, la, pd.p_B_a, lb, pd.p_B_b, J_full);
    t.J_rel.resize(3, arm.n);
    for (int i = 0; i < arm.n; ++i) t.J_rel.col(i) = (arm_is_a ? 1.0 : -1.0) * J_full.col(arm.q[i]);
    terms.push_back(t);
  }
  return terms;
}

/// Eq. 17 (merged force), Eq. 8 along its direction with the weighted relative Jacobians:
/// qdot = row^T |F| / (row row^T + lambda^2), row = e_all^T sum_i (w_i / W) J_rel,i. Skips `skip`.
Eigen::VectorXd virtualForceTerm(const std::vector<Term>& terms, int n, double damping, int skip = -1) {
  Eigen::Vector3d weighted = Eigen::Vector3d::Zero();
  double W = 0.0;
  for (std::size_t i = 0; i < terms.size(); ++i) {
    if (static_cast<int>(i) == skip) continue;
    weighted += terms[i].weight * terms[i].weight * terms[i].e;
    W += terms[i].weight;
  }
  Eigen::VectorXd qdot = Eigen::VectorXd::Zero(n);
  if (!(W > 0.0)) return qdot;
  const Eigen::Vector3d F = weighted / W;
  const double F_mag = F.norm();
  if (!(F_mag > 1e-12)) return qdot;
  Eigen::MatrixXd J_ca = Eigen::MatrixXd::Zero(3, n);
  for (std::size_t i = 0; i < terms.size(); ++i)
    if (static_cast<int>(i) != skip) J_ca += (terms[i].weight / W) * terms[i].J_rel;
  const Eigen::RowVectorXd row = (F / F_mag).transpose() * J_ca;
  return row.transpose() * (F_mag / (row.squaredNorm() + damping * damping));
}

double rate(const ControllerModel::Arm& arm, const ControllerData& data, int pair, const Eigen::VectorXd& qdot_arm) {
  double r = 0.0;
  for (int i = 0; i < arm.n; ++i) r += data.dist.rows(pair, arm.q[i]) * qdot_arm[i];
  return r;
}

/// True if some other yellow pair of the arm pushes against term `c` (e_i . e_c < 0): the arm is
/// squeezed between two obstacles along that pair's direction.
bool squeezed(const std::vector<Term>& terms, std::size_t c) {
  for (const Term& t : terms)
    if (t.e.dot(terms[c].e) < 0.0) return true;
  return false;
}

TEST(MergedForce, SameArmPairsPushTheDistalSegmentAndTheMergeNeverApproachesTheClosestPair) {
  const Model& model = shippedModel();
  const ControllerModel& cm = defaultControllerModel();
  const ControllerParams& P = cm.params;
  ControllerData data(model, cm);
  std::mt19937 rng(16);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  const Eigen::VectorXd rest = restConfiguration(model, cm);
  std::vector<char> arm_joint(static_cast<std::size_t>(model.nq), 0);
  for (const auto& arm : cm.arms)
    for (int i = 0; i < arm.n; ++i) arm_joint[static_cast<std::size_t>(arm.q[i])] = 1;
  const int want = 20000;
  int states = 0, with_same_arm = 0, multi = 0, free_checked = 0, yellow_checked = 0;
  int closest_approaching = 0, yellow_flipped = 0, squeezed_states = 0, squeezed_approaching = 0, squeezed_flipped = 0;
  double worst_squeezed = 0.0, max_diff = 0.0;
  for (int draw = 0; draw < 4000000 && states < want; ++draw) {
    // Arms anywhere inside their limits; the neck, the body and the legs up to 0.3 rad (m) off rest.
    Eigen::VectorXd q = rest;
    for (int j = 0; j < model.nq; ++j) {
      double lo = model.q_lower[j], hi = model.q_upper[j];
      if (!arm_joint[static_cast<std::size_t>(j)]) {
        lo = std::max(lo, rest[j] - 0.3);
        hi = std::min(hi, rest[j] + 0.3);
      }
      if (std::isfinite(lo) && std::isfinite(hi)) q[j] = lo + (hi - lo) * u(rng);
    }
    ASSERT_NE(computeControl(model, cm, data, q, ControlInput{}), ControlResult::kBadInput);
    if (data.estop != EstopState::kClear) {  // a pair in the red zone: not a yellow-zone state
      data.estop = EstopState::kClear;
      continue;
    }
    for (int a = 0; a < 2; ++a) {
      const ArmStatus& st = data.arms[a];
      if (!(st.distance >= P.d_b && st.distance < P.d_a)) continue;  // the arm's closest pair is yellow
      const ControllerModel::Arm& arm = cm.arms[a];
      const std::vector<Term> terms = yellowTerms(model, cm, data, a);
      ASSERT_FALSE(terms.empty());
      ++states;
      bool same_arm = false;
      std::size_t closest = terms.size();
      for (std::size_t i = 0; i < terms.size(); ++i) {
        const SegmentPair& sp = model.pairs[terms[i].pair];
        same_arm |= arm.link_in_arm[model.segments[sp.a].link] && arm.link_in_arm[model.segments[sp.b].link];
        if (terms[i].pair == st.closest_pair) closest = i;
      }
      ASSERT_LT(closest, terms.size()) << "the closest pair is one of the arm's yellow pairs";
      if (terms.size() > 1) ++multi;
      if (same_arm && terms.size() > 1) ++with_same_arm;
      // 1. The code's virtual-force term is the independent one.
      const Eigen::VectorXd mine = virtualForceTerm(terms, arm.n, P.damping);
      ASSERT_EQ(st.qdot_force.size(), arm.n);
      const Eigen::VectorXd code = st.qdot_force;
      const double diff = (mine - code).norm();
      max_diff = std::max(max_diff, diff);
      EXPECT_LT(diff, 1e-9 * (1.0 + mine.norm())) << "draw " << draw << " arm " << a << " (" << terms.size()
                                                  << " yellow pairs" << (same_arm ? ", a same-arm pair" : "") << ")";
      // 2. The closest pair is never approached by the virtual-force term, unless another yellow
      //    pair pushes the arm the opposite way (squeezed: measured, reported, not asserted).
      const double r_closest = rate(arm, data, st.closest_pair, code);
      if (squeezed(terms, closest)) {
        ++squeezed_states;
        if (r_closest < -1e-12) {
          ++squeezed_approaching;
          worst_squeezed = std::min(worst_squeezed, r_closest);
        }
      } else {
        ++free_checked;
        if (r_closest < -1e-12) {
          ++closest_approaching;
          ADD_FAILURE() << "draw " << draw << " arm " << a << ": the closest pair approaches at " << r_closest * 1e3
                        << " mm/s";
        }
      }
      // 3. A yellow pair that the merge of the others separates is still separated once its own
      //    force joins the merge (same exception).
      for (std::size_t i = 0; i < terms.size() && terms.size() > 1; ++i) {
        const Eigen::VectorXd without = virtualForceTerm(terms, arm.n, P.damping, static_cast<int>(i));
        if (rate(arm, data, terms[i].pair, without) < 0.0) continue;  // the others alone approach it
        const bool flipped = rate(arm, data, terms[i].pair, code) < -1e-12;
        if (squeezed(terms, i)) {
          squeezed_flipped += flipped;
          continue;
        }
        ++yellow_checked;
        if (flipped) {
          ++yellow_flipped;
          ADD_FAILURE() << "draw " << draw << " arm " << a << ": yellow pair " << terms[i].pair
                        << " approached after its own force joined the merge";
        }
      }
    }
  }
  std::printf(
      "%d yellow-zone arm states (%d merge several pairs, %d of them with a same-arm pair); "
      "max |code - independent| = %.2e rad/s\n"
      "not squeezed: closest pair approached in %d of %d; %d of %d yellow pairs flipped by their own force\n"
      "squeezed (another yellow pair pushes against the closest one): closest pair approached in %d of %d "
      "(worst %.2f mm/s); %d yellow pairs flipped\n",
      states, multi, with_same_arm, max_diff, closest_approaching, free_checked, yellow_flipped, yellow_checked,
      squeezed_approaching, squeezed_states, worst_squeezed * 1e3, squeezed_flipped);
  EXPECT_GE(states, want);
  EXPECT_GE(with_same_arm, 1000) << "the draw must exercise merges with a same-arm pair";
  EXPECT_GE(yellow_checked, 3000);
  EXPECT_EQ(closest_approaching, 0);
  EXPECT_EQ(yellow_flipped, 0);
}

}  // namespace
}  // namespace reflex::control
