#include "reflex/common/error.hpp"
#include "reflex/control/pair_sampling.hpp"

#include "reflex/control/distance.hpp"
#include "reflex/control/kinematics.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <map>
#include <random>
#include <set>
#include <stdexcept>

namespace reflex::control {
namespace {

using NamePair = std::pair<std::string, std::string>;

NamePair ordered(std::string a, std::string b) {
  if (b < a) std::swap(a, b);
  return {a, b};
}

std::set<NamePair> robotPairs(const Model& m) {
  std::set<NamePair> out;
  for (const auto& p : m.pairs)
    if (!m.segments[p.a].body_schema_slot && !m.segments[p.b].body_schema_slot)
      out.insert(ordered(m.segments[p.a].name, m.segments[p.b].name));
  return out;
}

std::string mm(double metres) {
  char buf[32];
  std::snprintf(buf, sizeof(buf), "%.1f mm", metres * 1000.0);
  return buf;
}

}  // namespace

namespace {

/// A configuration drawn uniformly within the limits (an infinite limit: +-pi), into q; with `only`,
/// only the joints it marks (the others keep their values).
void randomConfiguration(const Model& m, std::mt19937_64& rng, Eigen::VectorXd& q,
                         const std::vector<bool>* only = nullptr) {
  for (int i = 0; i < m.nq; ++i) {
    if (only && !(*only)[static_cast<std::size_t>(i)]) continue;
    const double lo = std::isfinite(m.q_lower[i]) ? m.q_lower[i] : -M_PI;
    const double hi = std::isfinite(m.q_upper[i]) ? m.q_upper[i] : M_PI;
    q[i] = lo == hi ? lo : std::uniform_real_distribution<double>(lo, hi)(rng);
  }
}

/// Which pairs a set of joints moves (index into report.pairs, through `keep`): one of them on the
/// path between the two links (the joints above one link and not above the other).
std::vector<bool> movedBy(const Model& m, const std::vector<int>& keep, std::size_t npairs,
                          const std::vector<std::string>& names, const char* what) {
  std::vector<bool> in_set(static_cast<std::size_t>(m.nq), false);
  for (const auto& name : names) {
    const int qi = m.qIndex(name);
    if (qi < 0) throw reflex::Error(std::string(what) + " '" + name + "' is not a movable joint of " + m.name);
    in_set[static_cast<std::size_t>(qi)] = true;
  }
  std::vector<bool> moved(npairs, false);
  for (std::size_t i = 0; i < m.pairs.size(); ++i) {
    if (keep[i] < 0) continue;
    const auto& sa = m.link_support[m.segments[m.pairs[i].a].link];
    const auto& sb = m.link_support[m.segments[m.pairs[i].b].link];
    for (const auto* from : {&sa, &sb})
      for (const int qi : *from) {
        const auto& other = from == &sa ? sb : sa;
        if (in_set[static_cast<std::size_t>(qi)] && std::find(other.begin(), other.end(), qi) == other.end())
          moved[static_cast<std::size_t>(keep[i])] = true;
      }
  }
  return moved;
}

/// Always in collision only where the real parts are (confirm_collision): the first configuration
/// where they are apart settles it (SampledPair::confirm_apart).
void confirmApart(const Model& m, const PairSamplingOptions& options, const std::vector<int>& keep,
                  PairSamplingReport& report, KinematicsData& kin) {
  Eigen::VectorXd q(m.nq);
  std::vector<int> candidates;  // index into m.pairs
  for (std::size_t i = 0; i < m.pairs.size(); ++i)
    if (keep[i] >= 0 &&
        report.pairs[static_cast<std::size_t>(keep[i])].in_collision >= options.always_fraction * options.samples)
      candidates.push_back(static_cast<int>(i));
  std::mt19937_64 crng(options.seed + 7);
  for (int n = 0; n < options.confirm_samples && !candidates.empty(); ++n) {
    randomConfiguration(m, crng, q);
    computeForwardKinematics(m, kin, q);
    for (auto it = candidates.begin(); it != candidates.end();) {
      const SegmentPair& p = m.pairs[static_cast<std::size_t>(*it)];
      if (options.confirm_collision(p.a, p.b, kin)) {
        ++it;
        continue;
      }
      report.pairs[static_cast<std::size_t>(keep[static_cast<std::size_t>(*it)])].confirm_apart = n + 1;
      it = candidates.erase(it);
    }
  }
}

}  // namespace

PairSamplingReport samplePairs(const Model& all_pairs, const Model& non_adjacent, const PairSamplingOptions& options,
                               const std::function<void(double)>& progress) {
  if (!(options.samples > 0)) throw reflex::Error("samples " + std::to_string(options.samples) + " must be positive");
  if (!(options.always_fraction > 0.0 && options.always_fraction <= 1.0))
    throw reflex::Error("always fraction " + std::to_string(options.always_fraction) + " must be in (0, 1]");
  if (!(options.near_distance >= 0.0) || !std::isfinite(options.near_distance))
    throw reflex::Error("near distance " + std::to_string(options.near_distance) + " must be >= 0 m");
  PairSamplingReport report;
  report.robot = non_adjacent.name;
  report.options = options;
  const std::set<NamePair> checked = robotPairs(non_adjacent);
  for (const auto& p : robotPairs(all_pairs))
    if (!checked.count(p)) report.adjacent.push_back(p);

  // Sample on the model without the adjacent pairs (their distances are not needed: on Romeo they
  // are half of all pairs).
  const Model& m = non_adjacent;
  std::vector<int> keep;  // index into m.pairs -> report.pairs
  std::map<NamePair, int> slot;
  for (const auto& p : checked) {
    slot[p] = static_cast<int>(report.pairs.size());
    report.pairs.push_back(SampledPair{p.first, p.second});
  }
  keep.assign(m.pairs.size(), -1);
  for (std::size_t i = 0; i < m.pairs.size(); ++i) {
    const auto& p = m.pairs[i];
    if (m.segments[p.a].body_schema_slot || m.segments[p.b].body_schema_slot) continue;
    const auto it = slot.find(ordered(m.segments[p.a].name, m.segments[p.b].name));
    if (it != slot.end()) keep[i] = it->second;
  }

  // Pairs farther apart than max(near_distance, 0.1 m) are not computed exactly (their distance is a
  // lower bound, PairDistance::exact false): the verdicts only ask what happens below near_distance,
  // and the convex pieces' exact distance is what costs (a PR2 set-up: 5x faster).
  DistanceOptions sweep;
  sweep.prune_distance = std::max(options.near_distance, 0.1);
  std::mt19937_64 rng(options.seed);
  KinematicsData kin(m);
  DistanceData dist(m);
  Eigen::VectorXd q(m.nq);
  const int step = std::max(1, options.samples / 100);
  for (int n = 0; n < options.samples; ++n) {
    randomConfiguration(m, rng, q);
    computeForwardKinematics(m, kin, q);
    computeSegmentDistances(m, kin, dist, sweep);
    for (std::size_t i = 0; i < dist.pairs.size(); ++i) {
      if (keep[i] < 0) continue;
      SampledPair& sp = report.pairs[keep[i]];
      const double d = dist.pairs[i].distance;
      sp.in_collision += d <= 0.0 ? 1 : 0;  // convex pieces that overlap report 0, capsules a depth
      sp.min_distance = std::min(sp.min_distance, d);
      sp.max_distance = std::max(sp.max_distance, d);
    }
    if (progress && (n + 1) % step == 0) progress(static_cast<double>(n + 1) / options.samples);
  }
  const std::vector<bool> pair_driven =
      options.driven_joints.empty() ? std::vector<bool>(report.pairs.size(), true)
                                    : movedBy(m, keep, report.pairs.size(), options.driven_joints, "driven joint");
  // The standing posture: the distance of every pair no arm joint moves (it is what the robot stands with).
  std::vector<bool> by_arm(report.pairs.size(), true);
  std::vector<double> standing(report.pairs.size(), std::numeric_limits<double>::infinity());
  if (options.standing.size() == m.nq) {
    by_arm = movedBy(m, keep, report.pairs.size(), options.arm_joints, "arm joint");
    computeForwardKinematics(m, kin, options.standing);
    computeSegmentDistances(m, kin, dist);
    for (std::size_t i = 0; i < dist.pairs.size(); ++i)
      if (keep[i] >= 0) standing[static_cast<std::size_t>(keep[i])] = dist.pairs[i].distance;
  }
  // How far Reflex's own motions take each pair: the driven joints random, every other joint in the
  // standing posture (a neck Reflex does not turn keeps the head where it stands).
  std::vector<double> reach(report.pairs.size(), -std::numeric_limits<double>::infinity());
  if (options.exclude_always_near && options.standing.size() == m.nq) {
    std::vector<bool> driven_q(static_cast<std::size_t>(m.nq), options.driven_joints.empty());
    for (const auto& name : options.driven_joints) driven_q[static_cast<std::size_t>(m.qIndex(name))] = true;
    for (int n = 0; n < std::max(1, options.samples / 2); ++n) {
      q = options.standing;
      randomConfiguration(m, rng, q, &driven_q);
      computeForwardKinematics(m, kin, q);
      computeSegmentDistances(m, kin, dist, sweep);
      for (std::size_t i = 0; i < dist.pairs.size(); ++i)
        if (keep[i] >= 0)
          reach[static_cast<std::size_t>(keep[i])] =
              std::max(reach[static_cast<std::size_t>(keep[i])], dist.pairs[i].distance);
    }
  }
  if (options.confirm_collision) confirmApart(m, options, keep, report, kin);
  for (std::size_t k = 0; k < report.pairs.size(); ++k) {
    auto& sp = report.pairs[k];
    sp.standing_distance = standing[k];
    sp.driven_max_distance = reach[k];
    if (!pair_driven[k])
      sp.verdict = PairVerdict::kNotDriven;
    else if (sp.in_collision >= options.always_fraction * options.samples && sp.confirm_apart == 0)
      sp.verdict = PairVerdict::kAlwaysInCollision;
    else if (!by_arm[k] && standing[k] <= options.touch_distance)
      sp.verdict = PairVerdict::kTouchingStanding;
    else if (options.exclude_always_near && std::min(sp.max_distance, sp.driven_max_distance) < options.near_distance)
      sp.verdict = PairVerdict::kAlwaysNear;
    else if (sp.min_distance > options.near_distance)
      sp.verdict = PairVerdict::kNeverClose;
  }
  return report;
}

std::string exclusionYaml(const PairSamplingReport& r) {
  const auto& o = r.options;
  std::string y;
  y += "# Collision configuration of " + r.robot + ", proposed by sampling " + std::to_string(o.samples) +
       " random configurations\n# within the joint limits (seed " + std::to_string(o.seed) +
       "; reflex_inspect --sample-pairs). Review every entry before use.\n";
  y += "#\n# Adjacent pairs (never checked while exclude_adjacent is true):\n";
  for (const auto& [a, b] : r.adjacent) y += "#   [" + a + ", " + b + "]\n";
  y += "exclude_adjacent: true\nexclude:\n";
  int always = 0, never = 0, checked = 0;
  for (const auto& p : r.pairs) {
    if (p.verdict != PairVerdict::kAlwaysInCollision) continue;
    ++always;
    y += "  # always in collision (" + std::to_string(p.in_collision) + " of " + std::to_string(o.samples) +
         " samples, deepest " + mm(p.min_distance) + "): checked, it would hold the robot in e-stop\n";
    y += "  - [" + p.a + ", " + p.b + "]\n";
  }
  int undriven = 0, undriven_near = 0;
  for (const auto& p : r.pairs) {
    if (p.verdict != PairVerdict::kNotDriven) continue;
    ++undriven;
    const bool near = p.min_distance < o.near_distance;
    undriven_near += near ? 1 : 0;
    y += std::string("  # ") + (near ? "WARNING: " : "") + "moved by no joint Reflex drives (sampled " +
         mm(p.min_distance) + " to " + mm(p.max_distance) + " over the joints that do move them" +
         (near ? "; they can come close: the robot's own controller must protect them" : "") +
         "): not checked, Reflex can neither cause nor prevent their contact\n";
    y += "  - [" + p.a + ", " + p.b + "]\n";
  }
  int standing = 0;
  for (const auto& p : r.pairs) {
    if (p.verdict != PairVerdict::kTouchingStanding) continue;
    ++standing;
    y += "  # WARNING: no arm joint moves them and they are " + mm(p.standing_distance) +
         " apart in the standing posture (at most " + mm(o.touch_distance) +
         ": the red zone would latch at start): not checked; the robot's own controller must keep them apart\n";
    y += "  - [" + p.a + ", " + p.b + "]\n";
  }
  int always_near = 0;
  for (const auto& p : r.pairs) {
    if (p.verdict != PairVerdict::kAlwaysNear) continue;
    ++always_near;
    const bool touch = p.min_distance <= o.touch_distance;
    y += std::string("  # ") + (touch ? "WARNING: " : "") + "never farther apart than " +
         mm(std::min(p.max_distance, p.driven_max_distance)) + " (closest " + mm(p.min_distance) +
         "), always inside d_a " + mm(o.near_distance) +
         ": the avoidance would act at every posture and the arm could follow no target; not checked" +
         (p.confirm_apart > 0 ? " (the model overlaps in " + std::to_string(p.in_collision) +
                                    " samples, but the "
                                    "meshes are apart in one: not excluded as always in collision)"
                              : std::string()) +
         (touch ? " (they can touch: the joint limits and the robot's own controller must keep them apart)" : "") +
         "\n";
    y += "  - [" + p.a + ", " + p.b + "]\n";
  }
  for (const auto& p : r.pairs) {
    if (p.verdict != PairVerdict::kNeverClose) continue;
    ++never;
    y += "  # never closer than " + mm(o.near_distance) + " (closest " + mm(p.min_distance) +
         "): left checked; uncomment to exclude\n";
    y += "  # - [" + p.a + ", " + p.b + "]\n";
  }
  for (const auto& p : r.pairs) checked += p.verdict == PairVerdict::kChecked ? 1 : 0;
  if (always == 0 && undriven == 0 && standing == 0 && always_near == 0) y += "  []\n";
  y += "# " + std::to_string(always) + " always in collision, " + std::to_string(never) + " never close, " +
       std::to_string(checked) + " checked, " + std::to_string(r.adjacent.size()) + " adjacent";
  if (standing > 0) y += ", " + std::to_string(standing) + " touching in the standing posture";
  if (always_near > 0) y += ", " + std::to_string(always_near) + " always inside d_a";
  if (!o.driven_joints.empty())
    y += ", " + std::to_string(undriven) + " moved by no joint Reflex drives (" + std::to_string(undriven_near) +
         " of them closer than " + mm(o.near_distance) + " in some sample)";
  y += "\n";
  return y;
}

}  // namespace reflex::control
