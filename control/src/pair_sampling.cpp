#include "reflex/control/pair_sampling.hpp"

#include "reflex/control/distance.hpp"
#include "reflex/control/kinematics.hpp"

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

PairSamplingReport samplePairs(const Model& all_pairs, const Model& non_adjacent, const PairSamplingOptions& options,
                               const std::function<void(double)>& progress) {
  if (!(options.samples > 0)) throw std::invalid_argument("samples " + std::to_string(options.samples) + " must be positive");
  if (!(options.always_fraction > 0.0 && options.always_fraction <= 1.0))
    throw std::invalid_argument("always fraction " + std::to_string(options.always_fraction) + " must be in (0, 1]");
  if (!(options.near_distance >= 0.0) || !std::isfinite(options.near_distance))
    throw std::invalid_argument("near distance " + std::to_string(options.near_distance) + " must be >= 0 m");
  PairSamplingReport report;
  report.robot = non_adjacent.name;
  report.options = options;
  const std::set<NamePair> checked = robotPairs(non_adjacent);
  for (const auto& p : robotPairs(all_pairs))
    if (!checked.count(p)) report.adjacent.push_back(p);

  // Sample on the model that has every pair; keep the non-adjacent ones.
  const Model& m = all_pairs;
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

  std::mt19937_64 rng(options.seed);
  KinematicsData kin(m);
  DistanceData dist(m);
  Eigen::VectorXd q(m.nq);
  const int step = std::max(1, options.samples / 100);
  for (int n = 0; n < options.samples; ++n) {
    for (int i = 0; i < m.nq; ++i) {
      const double lo = std::isfinite(m.q_lower[i]) ? m.q_lower[i] : -M_PI;
      const double hi = std::isfinite(m.q_upper[i]) ? m.q_upper[i] : M_PI;
      q[i] = lo == hi ? lo : std::uniform_real_distribution<double>(lo, hi)(rng);
    }
    computeForwardKinematics(m, kin, q);
    computeSegmentDistances(m, kin, dist);
    for (std::size_t i = 0; i < dist.pairs.size(); ++i) {
      if (keep[i] < 0) continue;
      SampledPair& sp = report.pairs[keep[i]];
      const double d = dist.pairs[i].distance;
      sp.in_collision += d < 0.0 ? 1 : 0;
      sp.min_distance = std::min(sp.min_distance, d);
      sp.max_distance = std::max(sp.max_distance, d);
    }
    if (progress && (n + 1) % step == 0) progress(static_cast<double>(n + 1) / options.samples);
  }
  for (auto& sp : report.pairs) {
    if (sp.in_collision >= options.always_fraction * options.samples) sp.verdict = PairVerdict::kAlwaysInCollision;
    else if (sp.min_distance > options.near_distance) sp.verdict = PairVerdict::kNeverClose;
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
  for (const auto& p : r.pairs) {
    if (p.verdict != PairVerdict::kNeverClose) continue;
    ++never;
    y += "  # never closer than " + mm(o.near_distance) + " (closest " + mm(p.min_distance) +
         "): left checked; uncomment to exclude\n";
    y += "  # - [" + p.a + ", " + p.b + "]\n";
  }
  for (const auto& p : r.pairs) checked += p.verdict == PairVerdict::kChecked ? 1 : 0;
  if (always == 0) y += "  []\n";
  y += "# " + std::to_string(always) + " always in collision, " + std::to_string(never) + " never close, " +
       std::to_string(checked) + " checked, " + std::to_string(r.adjacent.size()) + " adjacent\n";
  return y;
}

}  // namespace reflex::control
