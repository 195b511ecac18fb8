// Self-distances between collision segments (paper Sec. 4, 7.3), every cycle, for every checked pair.
//
// Sign convention (the one every controller sign follows from):
//   d      surface-to-surface distance between segments a and b (radii subtracted; < 0 if penetrating)
//   p_B_a  witness point on a's surface, p_B_b on b's surface, both in the base frame B
//   nhat_B = (p_B_a - p_B_b) / d, unit, pointing from b towards a
//   row    = nhat_B^T (J_B_pa - J_B_pb)  (1 x nq; each witness point's Jacobian on the link of its
//            primitive, a finger's in a segment of several links): the rate of d, so a positive row velocity
//          row * qdot > 0 separates the pair.
// Coincident core points: the normal falls back to the direction between the two links' origins
// (else +z), `well_defined` is false, and everything stays finite.
//
// The tight model: a primitive with a convex piece (Primitive::piece, convex.hpp) is only the bound of
// that piece; the distance, witness points and normal of a pair are then those of the pieces (exact,
// GJK), never above the distance between the real shapes. Where two pieces touch or overlap the
// capsules' answer (negative, a lower bound) stands.
//
// Body schema (Sec. 8.5): every model has kBodySchemaSlots run-time slots, one capsule each, that take
// part in the pair checks once enabled (grasped objects, virtual occlusion segments).
#pragma once

#include "reflex/control/geometry.hpp"
#include "reflex/control/kinematics.hpp"
#include "reflex/control/model.hpp"

#include <Eigen/Core>

#include <array>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <vector>

namespace reflex::control {

/// Distance result of one checked segment pair. Invariants (checked by tests): when `active`,
/// |nhat_B| = 1, p_B_a - p_B_b = distance * nhat_B, distance is finite.
struct PairDistance {
  // The fields every cycle writes for every pair (also those the broad phase skips) first, so they
  // share a cache line.
  int seg_a = -1, seg_b = -1;  ///< segment indices (a < b)
  double distance = std::numeric_limits<double>::infinity();
  bool well_defined = true;  ///< false when the core points coincided (fallback normal)
  bool active = false;       ///< false for pairs of disabled body-schema slots (distance = inf)
  bool has_row = false;      ///< rows.row(i) is valid for this cycle
  /// false: skipped by the broad phase (DistanceOptions::prune_distance) this cycle. `distance` is
  /// then a lower bound of the true distance, above prune_distance (the segments' bounding spheres'
  /// gap); witness points and normal are not computed (left as they were), has_row is false.
  /// refinePairDistance makes it exact. Always true without pruning.
  bool exact = true;
  Eigen::Vector3d p_B_a = Eigen::Vector3d::Zero();
  Eigen::Vector3d p_B_b = Eigen::Vector3d::Zero();
  Eigen::Vector3d nhat_B = Eigen::Vector3d::UnitZ();
};

/// Longest body-schema segment name (bytes, without the NUL): the bus's bound on a key string
/// (bus::kMaxKeyStringBytes, which reflex_controller checks is the same); a longer name is refused.
inline constexpr std::size_t kBodySchemaNameBytes = 255;

/// A run-time body-schema segment (Sec. 8.5): a capsule (or sphere if a_L == b_L) attached to a link,
/// and everything the controller knows about it. This is the one record of a slot: the distance
/// computation reads the geometry (enabled .. ignore_mask), the controller `is_virtual`, the onboard
/// controller `motion_priority` and `name`. Plain data of fixed size: copying a slot never allocates.
struct BodySchemaSlot {
  bool enabled = false;
  int link = 0;  ///< link the endpoints are expressed in
  Eigen::Vector3d a_L = Eigen::Vector3d::Zero();
  Eigen::Vector3d b_L = Eigen::Vector3d::Zero();
  double radius = 0.0;
  std::uint64_t ignore_mask = 0;  ///< bit i set: never checked against segment i
  /// Virtual (occlusion, Sec. 8.5.2) segment: avoided like any other, never triggers the e-stop nor
  /// counts as the closest physical pair. Set by attachControllerSegment.
  bool is_virtual = false;
  /// > 0 on a physical segment held by an arm: that arm gets priority (OnboardController::step).
  int motion_priority = 0;
  /// The bus name (BodySchemaChange.segment_name) that holds the slot, NUL-terminated; "" = the slot
  /// is free. A slot may be named and disabled (a change with enabled = false keeps its slot).
  std::array<char, kBodySchemaNameBytes + 1> name{};
};

/// The body-schema slots of a model (index = segment - Model::num_robot_segments).
using BodySchemaSlots = std::array<BodySchemaSlot, kBodySchemaSlots>;

struct DistanceOptions {
  /// Avoidance rows are computed for pairs with distance below this (m). +inf: every pair.
  double row_threshold = std::numeric_limits<double>::infinity();
  /// Broad phase: a robot-robot pair whose segments' bounding spheres (fixed in
  /// the link frame, enclosing every primitive) are more than this apart (m) is not computed
  /// exactly: PairDistance::exact = false, distance = that gap (a lower bound). Every pair whose
  /// true distance is at most prune_distance is computed exactly, bit for bit as without pruning,
  /// and so is the closest pair (`closest`, its distance identical to the unpruned sweep's).
  /// +inf (default): no pruning, every pair exact. Pairs with a body-schema slot are always exact.
  /// A robot pair of convex pieces (the tight model) whose enclosing capsules are more than this apart
  /// is skipped the same way (its distance: the capsules' distance, a lower bound).
  double prune_distance = std::numeric_limits<double>::infinity();
  /// The sweep's last step: the closest active pair into DistanceData::closest. false: closest = -1
  /// (a caller that finds the closest pairs it needs itself, as the controller's cycle does, saves a
  /// walk over the pairs and the refinements that go with it).
  bool find_closest = true;
};

/// The sweep's primitive-pair kernel (computeSegmentDistances). Both give the same bits (the same
/// IEEE operations in the same order); kAvx2 runs four pairs per instruction on a CPU that has AVX2.
enum class SweepKernel : std::uint8_t { kScalar, kAvx2 };

/// The fastest kernel this CPU runs (kAvx2 where it has AVX2, else kScalar): DistanceData's default.
SweepKernel fastestSweepKernel();

/// Per-cycle distance results and scratch, sized from the model.
struct DistanceData {
  explicit DistanceData(const Model& model);

  std::vector<PairDistance> pairs;                                              ///< same order as Model::pairs
  Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> rows;  ///< npairs x nq
  /// The body schema computeSegmentDistances(model, kin, data) uses. ControllerData::dist.slots is
  /// the controller's body schema, its one owner; the scratch DistanceData of the predictive guards
  /// leave theirs unused and are computed with data.dist.slots (passed const&, never copied).
  BodySchemaSlots slots;
  int closest = -1;  ///< index of the active pair with the smallest distance, -1 if none (or not asked for)
  // Scratch of computeSegmentDistances (built from the model here; values valid only during the call).
  // Per primitive:
  std::vector<SegmentB> prim_B;  ///< core segment in B (start, direction, squared length)
  std::vector<double> prim_r;    ///< radius (body-schema slots: the slot's)
  // Per pair: commonSupport of its two links for a robot pair (its row then has nonzero entries only
  // in those links' support columns, written each time, the rest zero from set-up; a pair with a
  // segment of several links writes its whole row); -1 for a pair with a body-schema slot (whose row
  // is zeroed each time).
  std::vector<int> pair_common;
  // The primitive pairs of all robot-robot pairs, flat, so that they are computed in one tight loop:
  // pair i owns entries [pp_begin[i], pp_begin[i + 1]) (none for pairs with a body-schema slot).
  std::vector<int> pp_a, pp_b, pp_begin;
  // Per primitive pair (pp index): 1 when its two links are a pair the model does not check
  // (SegmentPair::unchecked_links; only where a segment has several links): it is never listed.
  // any_pp_unchecked: some entry is 1 (every cycle then lists its primitive pairs, also unpruned).
  std::vector<char> pp_unchecked;
  bool any_pp_unchecked = false;
  // Per primitive, the link it moves with (linkOf; -1 for a body-schema slot's, whose link is the
  // slot's); per link, the robot segment that has it (-1: none).
  std::vector<int> prim_link, link_segment;
  // Segments of several links: their primitives move against their link, so their bounding sphere is
  // made each call around the primitives where they are (bound_center4_B, bound_radius written by the
  // transform), and the sums of the robot pairs that have one (rp_dynamic: indices into rp_a) redone.
  std::vector<char> several_links;
  std::vector<char> pair_several;  ///< per pair: one of its segments has several links
  std::vector<int> rp_dynamic;
  // A segment of several links in blocks, one per link (its primitives of that link are contiguous):
  // segment s's blocks are [seg_block[s], seg_block[s + 1]); each block its primitives [first, end),
  // its bounding sphere in its link's frame and this call's centre in B. A pair lists its primitive
  // pairs block pair by block pair, each skipped when their spheres are apart (as the per-link pairs
  // of the same robot would be).
  std::vector<int> seg_block, block_first, block_end, block_link;
  std::vector<Eigen::Vector3d> block_center_L, block_center_B;
  std::vector<double> block_radius;
  // The tight model, per robot segment: 0 never placed into B, 1 placed at the poses of its last measure
  // (last_X: a link is in one robot segment, and placing a segment measures it), 2 with its bounding
  // sphere too. A segment whose links are where they were is not placed again (a still torso, legs,
  // head): only the work depends on it.
  std::vector<std::uint8_t> seg_placed;
  // The primitive pairs the sweep computes this cycle, in pair order (the broad phase's survivors';
  // all of pp_a / pp_b without it), and their segment parameters and core distance (scratch).
  std::vector<int> list_a, list_b;
  std::vector<double> pp_s, pp_t, pp_core;
  // With the broad phase, per exact pair (exact list order): where its entries of list_a / list_b end,
  // and the smallest bounding-sphere gap of a primitive it left out (+inf: none). A pair of the tight
  // model lists only the primitives of each segment whose bounding sphere (radius prim_sphere_r, about
  // the core's middle) is within prune_distance of the other segment's.
  std::vector<int> list_end;
  std::vector<double> list_floor;
  std::vector<double> prim_sphere_r;
  std::vector<int> kept_a, kept_b, kept_a2, kept_b2;
  std::vector<int> list_pp;  ///< per list entry, its index in pp_a / pp_b
  // Carried bounds (the tight model): per primitive pair (pp index), a lower bound of its distance at
  // the poses of the call that last computed it plus both primitives' odometers then (-inf: none);
  // per primitive its odometer, the sum of how far it can have moved between the calls that placed
  // it (m), and per link of a robot segment its pose when that segment was last measured (placed).
  // The stored value less both odometers now bounds the distance now, however many calls ago it was
  // computed: a primitive pair proven far is skipped without a search. Only the work depends on them.
  std::vector<double> pp_lower;
  // Per primitive pair, what its last search left (computeConvexDistance's `hint`: the direction that
  // proved it far, the first support pair). Only the work depends on it.
  std::vector<ConvexHint> pp_hint;
  std::vector<double> prim_odometer;
  std::vector<Eigen::Isometry3d> last_X;
  // The same for whole pairs of the tight model: per pair, a lower bound of its distance from the
  // sweep that last skipped it after a look at its pieces, plus both segments' odometers then (-inf:
  // none); per segment, its odometer (the sum of the most any of its primitives moved at each
  // measure). A pair whose carried bound is above the prune distance is skipped in the broad phase,
  // with no search and no listing: far pairs stay skipped while they move less than their margin.
  std::vector<double> pair_lower;
  std::vector<double> seg_odometer;
  /// Exact convex-distance searches (computeConvexDistance calls) since the last computeSegmentDistances
  /// or computeListedPairDistances began: the narrow phase's work (benchmarks and tests read it).
  int num_piece_searches = 0;
  // The tight model (Primitive::piece): per pair, whether a primitive of either segment is a convex
  // piece (the pair's distance is then the least over its primitive pairs of computeConvexDistance on
  // the pieces, a capsule side by its core and radius); per primitive, its core as a piece of two
  // vertices (link frame; a body-schema slot's written each cycle), for a piece meeting a capsule.
  std::vector<char> pair_has_piece;
  std::vector<ConvexPiece> core_piece;
  // One tight-model pair's primitive pairs with their capsule distance (a lower bound of the exact
  // one), sorted so the exact distances are computed nearest first and the rest skipped as soon as a
  // bound reaches the best found (scratch, sized at set-up to the largest pair).
  struct PieceCandidate {
    double bound, core, s, t;
    int pa, pb;
    int pp;        ///< its index in pp_a / pp_b (-1: nothing carried: a slot pair or a refinement)
    double lower;  ///< its lower bound at this call's poses (the bound, or what its search proved)
  };
  std::vector<PieceCandidate> piece_candidates;
  /// Per pair of the tight model: the primitive pair that gave its distance last time ({-1, -1}: none
  /// yet), tried first next time. Only the work depends on it, never the result.
  std::vector<std::array<int, 2>> piece_winner;
  /// Per pair: the search of one primitive pair that bounded its distance from above (its listing is
  /// cut there; or that stopped once it proved that primitive pair beyond the prune distance) during
  /// call `call` (search_call counts the calls), reused when that primitive pair is evaluated in the
  /// same call instead of searching it again.
  struct UpperSearch {
    int pa = -1, pb = -1;
    std::uint32_t call = 0;
    std::uint8_t outcome = 0;
    double d = 0.0;
    Eigen::Vector3d p_a = Eigen::Vector3d::Zero(), p_b = Eigen::Vector3d::Zero(), n = Eigen::Vector3d::UnitZ();
  };
  std::vector<UpperSearch> upper_search;
  std::uint32_t search_call = 1;
  /// The kernel computeSegmentDistances runs (fastestSweepKernel() unless set: tests run both).
  SweepKernel kernel = fastestSweepKernel();
  std::vector<int> robot_pairs, slot_pairs;  ///< indices into pairs
  // Broad phase, per segment (robot segments only): bounding sphere centre in the link frame and its
  // radius (m): every primitive of the segment lies inside it; the centre in B this cycle, 4 doubles
  // per segment (x, y, z, 0).
  std::vector<Eigen::Vector3d> bound_center_L;
  std::vector<double> bound_radius;
  std::vector<double> bound_center4_B;
  // Per robot pair (robot_pairs' order): its two segments, their bounding radii's sum, and this
  // cycle's gap between the spheres (m, scratch).
  std::vector<int> rp_a, rp_b;
  std::vector<double> rp_rsum, rp_gap;
  std::vector<int> exact_pairs;  ///< robot pairs the broad phase kept this cycle (scratch)
  /// The robot pairs the last computeSegmentDistances computed exactly, ascending: its first
  /// num_exact_pairs entries (exact_pairs with the broad phase, robot_pairs without). A pair made
  /// exact later by refinePairDistance is not in it.
  const std::vector<int>& exactList() const { return last_pruned ? exact_pairs : robot_pairs; }
  bool last_pruned = false;       ///< the last computeSegmentDistances used the broad phase
  bool any_slot_enabled = false;  ///< ... and was given an enabled body-schema slot
  /// Every body-schema slot pair's entry is inactive (distance +inf, no row): nothing has computed one
  /// since computeSegmentDistances last cleared them (or since construction).
  bool slot_pairs_inactive = true;
  int num_exact_pairs = 0;
  /// The smallest lower bound of a pair the broad phase skipped in the last computeSegmentDistances
  /// (m); +inf when it skipped none.
  double pruned_floor = std::numeric_limits<double>::infinity();
  int num_pruned_pairs = 0;  ///< robot pairs the broad phase skipped this cycle
  // computeListedPairDistances: per segment, the call that last put it into B (scratch).
  std::vector<std::uint32_t> segment_stamp;
  std::uint32_t segment_stamp_now = 0;
};

/// Calls f(pair_index, is_robot_pair) for every pair the last computeSegmentDistances computed
/// exactly, in ascending pair order: the robot pairs of its exact list merged with the active
/// body-schema slot pairs (none when every slot is disabled). Pairs made exact later by
/// refinePairDistance are not visited. Allocation-free.
template <class F>
void forEachExactPair(const DistanceData& data, F&& f) {
  const std::vector<int>& exact = data.exactList();
  const int nexact = data.num_exact_pairs;
  const int nslot = data.any_slot_enabled ? static_cast<int>(data.slot_pairs.size()) : 0;
  if (nslot == 0) {  // the usual cycle, no slot enabled: the exact list alone, without the merge
    for (int e = 0; e < nexact; ++e) f(exact[static_cast<std::size_t>(e)], true);
    return;
  }
  for (int e = 0, s = 0; e < nexact || s < nslot;) {
    const bool robot =
        s >= nslot || (e < nexact && exact[static_cast<std::size_t>(e)] < data.slot_pairs[static_cast<std::size_t>(s)]);
    const int p = robot ? exact[static_cast<std::size_t>(e++)] : data.slot_pairs[static_cast<std::size_t>(s++)];
    if (robot || data.pairs[static_cast<std::size_t>(p)].active) f(p, robot);
  }
}

/// Computes every checked pair's distance, witness points, normal and (below the threshold) row.
/// Call after computeForwardKinematics. Allocates nothing, never throws.
void computeSegmentDistances(const Model& model, const KinematicsData& kin, DistanceData& data,
                             const DistanceOptions& options = {});

/// The same with the body schema `slots` (read, never copied) instead of data.slots: a second
/// DistanceData (a predicted configuration) computed with the body schema of the first.
void computeSegmentDistances(const Model& model, const KinematicsData& kin, const BodySchemaSlots& slots,
                             DistanceData& data, const DistanceOptions& options = {});

/// Computes exactly (no row, no broad phase) only the `count` pairs listed in `pairs` (indices into
/// Model::pairs), with the body schema `slots`: each comes out as computeSegmentDistances gives it
/// without pruning (the same arithmetic, so the same distance bit for bit), a pair of a disabled
/// slot inactive. Every other entry of data.pairs, and `closest`, are left as they were. For a
/// caller that needs a few pairs at many configurations (the predictive guard). With a finite
/// `give_up`, a listed pair of the tight model (convex pieces) whose pieces are proven farther apart
/// than give_up may come out inexact instead (exact = false, distance a lower bound above give_up):
/// for a caller that only asks whether a pair is below give_up. Allocates nothing, never throws.
/// The primitive pairs of some robot pairs that can come within a distance while every point moves at
/// most a given reach (listPairsNear): for a caller that computes the same pairs at several nearby
/// configurations (the predictive guard's predictions of one cycle), so each lists them once.
/// Sized from the model; allocates nothing after construction.
struct PairListing {
  explicit PairListing(const Model& model);
  /// Per pair (index into Model::pairs): how many primitive pairs are listed, -1 if the pair is not
  /// listed (it is then computed as without a listing).
  std::vector<int> count;
  /// Per pair i, its listed primitives and primitive-pair index at [DistanceData::pp_begin[i], + count)
  /// (within the range of its primitive pairs, the same in every DistanceData of the model).
  std::vector<int> pa, pb, pp;
  /// Per pair: a lower bound of the distance of every primitive pair left out, at any configuration
  /// within the reach (m).
  std::vector<double> floor;
};

/// Lists into `out`, for each of pairs[0 .. count), the primitive pairs (on checked link pairs) whose
/// bounding spheres in `now` are within give_up + reach[k] (`now`: the last computeSegmentDistances
/// with the broad phase, whose bounding spheres are in place): at any configuration where no point has
/// moved more than reach[k] (both segments' motion together) from now's, every primitive pair that
/// can be within give_up is listed. Pairs with a body-schema slot, and pairs of capsules alone, are
/// not listed. Allocates nothing, never throws.
void listPairsNear(const Model& model, DistanceData& now, const int* pairs, int count, double give_up,
                   const double* reach, PairListing& out);

/// With `listing` (made by listPairsNear with the same give_up, valid for `kin`: no point moved
/// farther than its reach since), a listed pair offers only its listed primitive pairs: the same
/// result (an inexact distance may be a different lower bound above give_up).
void computeListedPairDistances(const Model& model, const KinematicsData& kin, const BodySchemaSlots& slots,
                                DistanceData& data, const int* pairs, int count,
                                double give_up = std::numeric_limits<double>::infinity(),
                                const PairListing* listing = nullptr);

/// Computes pair `pair` exactly (after computeSegmentDistances for the same kinematics and options):
/// for a pair the broad phase skipped, the result computeSegmentDistances gives without pruning
/// (row only below options.row_threshold). Other pairs: unchanged. Allocates nothing, never throws.
void refinePairDistance(const Model& model, const KinematicsData& kin, DistanceData& data, int pair,
                        const DistanceOptions& options = {});

/// The closest pair of one kind (the sweep's `closest`, an arm's, the controller's physical, virtual
/// and between-the-arms pairs). Ties: the lower pair index.
struct ClosestPair {
  double distance = std::numeric_limits<double>::infinity();  ///< m; +inf if none
  int pair = -1;                                              ///< index into Model::pairs, -1 if none
  /// Takes pair `i` at distance `d` if it is closer (or as close with a lower index).
  void offer(double d, int i) {
    if (d < distance || (d == distance && i < pair)) {
      distance = d;
      pair = i;
    }
  }
};

/// The closest-pair rule under the broad phase, in one place. `best` holds the closest of the pairs
/// computed exactly; a pair the broad phase skipped has only a lower bound (PairDistance::exact
/// false), so each of `candidates` (indices into data.pairs, visited in order) whose distance or
/// bound is below best.distance and that `admit(i)` accepts is computed exactly (refinePairDistance)
/// and offered to `best`. A skipped pair whose bound is not below the best cannot be closer, so `best`
/// ends as it would without pruning. Nothing to do (and no call of admit) unless the smallest
/// skipped bound (data.pruned_floor) is below best.distance. Allocates nothing, never throws.
template <class Admit>
void refineClosest(const Model& model, const KinematicsData& kin, DistanceData& data, const DistanceOptions& options,
                   const std::vector<int>& candidates, ClosestPair& best, Admit&& admit) {
  if (!(data.pruned_floor < best.distance)) return;
  for (const int i : candidates) {
    const PairDistance& pd = data.pairs[static_cast<std::size_t>(i)];
    if (!(pd.distance < best.distance) || !admit(i)) continue;
    if (!pd.exact) refinePairDistance(model, kin, data, i, options);
    best.offer(pd.distance, i);
  }
}

/// refineClosest over every candidate.
inline void refineClosest(const Model& model, const KinematicsData& kin, DistanceData& data,
                          const DistanceOptions& options, const std::vector<int>& candidates, ClosestPair& best) {
  refineClosest(model, kin, data, options, candidates, best, [](int) { return true; });
}

/// Enables body-schema slot `slot` with a capsule [a_L, b_L] of `radius` on `link`, never checked
/// against the segments in `ignore_mask` (the owner link's segment is always ignored).
/// Returns false (and changes nothing) for a bad slot, link, radius or non-finite point.
bool attachBodySchemaSegment(const Model& model, DistanceData& data, int slot, int link, const Eigen::Vector3d& a_L,
                             const Eigen::Vector3d& b_L, double radius, std::uint64_t ignore_mask = 0);

/// Disables a slot (its name, is_virtual and motion_priority are the caller's). Returns false for a
/// bad slot index.
bool detachBodySchemaSegment(DistanceData& data, int slot);

/// Bounds a body-schema segment from the bus must satisfy before it is attached (the boundary check
/// of reflex_controller; attachBodySchemaSegment itself checks only slot, link and finiteness).
/// A segment beyond them is a bad sample, not a real object: a 1 km sphere on a hand would put every
/// pair in the red zone and freeze the robot in e-stop. Lengths in metres, in the parent link frame.
/// Physical segments (grasped objects) are objects the hand holds: within reach of the link.
/// Virtual segments (Sec. 8.5.2, a gaze line from the head camera to a seen object) may be as long as
/// the view: 4 m covers an object at the behavior host's default max_range (3 m from the base
/// origin) seen from the head. reflex_controller uses these documented defaults.
struct BodySchemaLimits {
  double max_radius = 0.5;          ///< radius, both kinds (the behavior modules' configuration bound)
  double max_length = 1.0;          ///< core length |b_L - a_L| of a physical segment
  double max_reach = 1.0;           ///< |a_L|, |b_L| of a physical segment (distance from the link origin)
  double max_virtual_length = 4.0;  ///< core length of a virtual segment
  double max_virtual_reach = 4.0;   ///< |a_L|, |b_L| of a virtual segment
};

/// Why checkBodySchemaSegment refused a segment.
enum class BodySchemaFault : std::uint8_t {
  kNone = 0,
  kUnknownLink,        ///< link index outside the model
  kNonFinite,          ///< radius or an endpoint coordinate NaN / Inf
  kRadiusNotPositive,  ///< radius <= 0
  kRadiusTooLarge,     ///< radius > max_radius
  kTooLong,            ///< |b_L - a_L| > max_length (max_virtual_length)
  kTooFar,             ///< |a_L| or |b_L| > max_reach (max_virtual_reach)
};

/// Outcome of checkBodySchemaSegment: the fault, the offending value and the limit it broke (with
/// the name of that BodySchemaLimits field; "" where no size limit applies).
struct BodySchemaCheck {
  BodySchemaFault fault = BodySchemaFault::kNone;
  double value = 0.0;    ///< the bad value (m): radius, length or endpoint distance
  double limit = 0.0;    ///< the limit it broke (m)
  const char* key = "";  ///< the BodySchemaLimits field broken, e.g. "max_radius"
  bool ok() const { return fault == BodySchemaFault::kNone; }
};

/// Checks a body-schema segment (capsule [a_L, b_L] of `radius` on `link`) against `limits`.
/// Allocation-free, never throws (called in the 5 ms loop for every sample).
BodySchemaCheck checkBodySchemaSegment(const Model& model, int link, const Eigen::Vector3d& a_L,
                                       const Eigen::Vector3d& b_L, double radius, bool virtual_segment,
                                       const BodySchemaLimits& limits);

/// A short English description of a fault, e.g. "radius above the limit".
const char* describe(BodySchemaFault fault);

}  // namespace reflex::control
