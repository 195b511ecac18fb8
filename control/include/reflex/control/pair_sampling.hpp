// Which pairs to check, found by sampling, as MoveIt's setup assistant does it:
// N random configurations within the joint limits; every pair of robot segments that the adjacency
// rule does not already drop is classified by the distances it takes over the samples:
//   always in collision  penetrating (distance <= 0) in at least `always_fraction` of the samples;
//                        checking it would hold the robot in the red zone (e-stop) from the start;
//   never close          never closer than `near_distance` (default d_a = 40 mm, where avoidance
//                        begins) in any sample: avoidance would never act on it;
//   not driven           (only when `driven_joints` is given, as reflex_setup does) no joint Reflex
//                        drives lies on the kinematic path between the two links (two fingers of one
//                        hand, a thigh and the pelvis of a robot whose legs Reflex does not walk):
//                        Reflex can neither bring them together nor keep them apart, and a red zone
//                        on them would freeze the arms for nothing. Excluded, each with the distances
//                        sampled over the joints that do move them; one that comes closer than
//                        `near_distance` is written with a WARNING (the robot's own controller must
//                        protect it).
//   touching standing    (only when `standing` is given) no arm joint moves the pair and it is at most
//                        `touch_distance` apart in the standing posture (coarse leg meshes that
//                        overlap with the legs straight): the red zone would latch at start. Excluded
//                        with a WARNING.
//   always near          (only with `exclude_always_near`) never farther apart than `near_distance`
//                        in any sample, or in any of samples/2 more where only the driven joints move
//                        and the others keep the standing posture (iCub's right shoulder link and its
//                        head, a neck Reflex does not turn; its shoulder links and upper arm): the avoidance would act
//                        at every posture and hold the arm off every target. Excluded, with a WARNING
//                        when the pair comes within `touch_distance`.
//   checked              everything else.
// The result is written as a commented exclusion list for the user to review: always-in-collision
// pairs as active entries, never-close pairs COMMENTED OUT (random sampling can miss the rare
// configuration where they meet, and a dropped pair is protection lost: the user opts in), adjacent
// pairs listed for information.
#pragma once

#include "reflex/control/model.hpp"

#include <Eigen/Core>

#include <cstdint>
#include <functional>
#include <limits>
#include <string>
#include <utility>
#include <vector>

namespace reflex::control {

struct KinematicsData;

struct PairSamplingOptions {
  int samples = 10000;            ///< random configurations (> 0)
  std::uint64_t seed = 1;         ///< the same seed gives the same report
  double always_fraction = 0.95;  ///< in (0, 1]
  double near_distance = 0.04;    ///< m, >= 0
  /// Joint names Reflex drives (arms, walking). Empty: every joint counts as driven (no kNotDriven).
  std::vector<std::string> driven_joints;
  /// The standing posture (size nq; empty: none) and the arms' joints: a pair no arm joint moves that is
  /// at most `touch_distance` apart there is kTouchingStanding.
  Eigen::VectorXd standing;
  std::vector<std::string> arm_joints;
  double touch_distance = 0.0;  ///< m: reflex_setup gives d_r + estop_release_margin
  /// kAlwaysNear: a pair never farther apart than near_distance in any sample (reflex_setup: true).
  bool exclude_always_near = false;
  /// If set, a pair found in collision in always_fraction of the samples is always in collision only
  /// if this says the real parts intersect in each of `confirm_samples` more random configurations
  /// (segment indices of the non-adjacent model, its kinematics at that configuration). reflex_setup:
  /// the original meshes (meshesIntersect), as the tight model may overlap where they do not.
  std::function<bool(int seg_a, int seg_b, const KinematicsData& kin)> confirm_collision;
  int confirm_samples = 1000;
};

enum class PairVerdict { kChecked, kAlwaysInCollision, kNeverClose, kNotDriven, kTouchingStanding, kAlwaysNear };

struct SampledPair {
  std::string a, b;      ///< segment names
  int in_collision = 0;  ///< samples with distance <= 0 (overlapping pieces report 0)
  double min_distance = std::numeric_limits<double>::infinity();
  double max_distance = -std::numeric_limits<double>::infinity();  ///< above max(near_distance, 0.1 m): a lower bound
  double standing_distance = std::numeric_limits<double>::infinity();  ///< m, in options.standing
  /// m: the largest with only the driven joints moving (the others standing); +inf: not sampled
  double driven_max_distance = std::numeric_limits<double>::infinity();
  int confirm_apart = 0;  ///< samples of the confirmation where confirm_collision said apart (0: not asked or none)
  PairVerdict verdict = PairVerdict::kChecked;
};

struct PairSamplingReport {
  std::string robot;
  PairSamplingOptions options;
  std::vector<SampledPair> pairs;                             ///< non-adjacent robot pairs
  std::vector<std::pair<std::string, std::string>> adjacent;  ///< dropped by the adjacency rule
};

/// Samples `options.samples` configurations uniformly within the limits (continuous joints in
/// [-pi, pi]). `all_pairs` is the robot loaded with exclude_adjacent false and no exclusions;
/// `non_adjacent` the same robot with exclude_adjacent true (their difference is the adjacent set).
/// `progress` (optional) is called with the fraction done, at most ~100 times.
/// Throws reflex::Error naming a bad option.
PairSamplingReport samplePairs(const Model& all_pairs, const Model& non_adjacent, const PairSamplingOptions& options,
                               const std::function<void(double)>& progress = {});

/// The report as a collision-configuration YAML (exclude_adjacent + exclude), every entry commented
/// with its reason and the distances seen.
std::string exclusionYaml(const PairSamplingReport& report);

}  // namespace reflex::control
