#include "reflex/control/distance.hpp"

#include "reflex/control/geometry.hpp"
#include "segment_kernels.hpp"

#include <algorithm>
#include <cassert>
#include <cmath>

#if defined(__GNUC__)
#define REFLEX_ALWAYS_INLINE __attribute__((always_inline))
#else
#define REFLEX_ALWAYS_INLINE
#endif

namespace reflex::control {

namespace {

/// Whether segment `seg` has a primitive on a link other than its own.
bool severalLinks(const Model& model, const Segment& seg) {
  for (int p = seg.first_primitive; p < seg.first_primitive + seg.num_primitives; ++p)
    if (linkOf(seg, model.primitives[static_cast<std::size_t>(p)]) != seg.link) return true;
  return false;
}

/// The link blocks of every segment of several links (DistanceData::seg_block ..): its primitives of
/// one link (contiguous), with their bounding sphere in that link's frame.
void buildLinkBlocks(const Model& model, DistanceData& d) {
  for (std::size_t s = 0; s < model.segments.size(); ++s) {
    d.seg_block.push_back(static_cast<int>(d.block_first.size()));
    const Segment& seg = model.segments[s];
    if (!d.several_links[s]) continue;
    for (int p = seg.first_primitive; p < seg.first_primitive + seg.num_primitives; ++p) {
      const int link = linkOf(seg, model.primitives[static_cast<std::size_t>(p)]);
      if (d.block_first.size() == static_cast<std::size_t>(d.seg_block.back()) || d.block_link.back() != link) {
        d.block_first.push_back(p);
        d.block_end.push_back(p);
        d.block_link.push_back(link);
      }
      d.block_end.back() = p + 1;
    }
  }
  d.seg_block.push_back(static_cast<int>(d.block_first.size()));
  for (std::size_t k = 0; k < d.block_first.size(); ++k) {
    Eigen::Vector3d lo = Eigen::Vector3d::Constant(std::numeric_limits<double>::infinity()), hi = -lo;
    for (int p = d.block_first[k]; p < d.block_end[k]; ++p) {
      const Primitive& prim = model.primitives[static_cast<std::size_t>(p)];
      lo = lo.cwiseMin(prim.a_L).cwiseMin(prim.b_L);
      hi = hi.cwiseMax(prim.a_L).cwiseMax(prim.b_L);
    }
    const Eigen::Vector3d c = 0.5 * (lo + hi);
    double r = 0.0;
    for (int p = d.block_first[k]; p < d.block_end[k]; ++p) {
      const Primitive& prim = model.primitives[static_cast<std::size_t>(p)];
      r = std::max(r, std::max((prim.a_L - c).norm(), (prim.b_L - c).norm()) + prim.radius);
    }
    d.block_center_L.push_back(c);
    d.block_radius.push_back(r);
  }
  d.block_center_B.assign(d.block_first.size(), Eigen::Vector3d::Zero());
}

/// Every robot segment's bounding sphere in its link frame (a segment of several links: none here, an
/// infinite one until each call makes one around its primitives where they are).
void buildSegmentSpheres(const Model& model, DistanceData& d) {
  d.bound_center_L.assign(model.segments.size(), Eigen::Vector3d::Zero());
  d.bound_center4_B.assign(4 * model.segments.size(), 0.0);
  d.bound_radius.assign(model.segments.size(), 0.0);
  for (std::size_t s = 0; s < model.segments.size(); ++s) {
    const Segment& seg = model.segments[s];
    if (seg.body_schema_slot || seg.num_primitives == 0) continue;
    if (severalLinks(model, seg)) {  // made each call around its primitives (boundPrimitivesWhereTheyAre)
      d.bound_radius[s] = std::numeric_limits<double>::infinity();
      continue;
    }
    Eigen::Vector3d lo = Eigen::Vector3d::Constant(std::numeric_limits<double>::infinity());
    Eigen::Vector3d hi = -lo;
    for (int p = seg.first_primitive; p < seg.first_primitive + seg.num_primitives; ++p) {
      const Primitive& prim = model.primitives[static_cast<std::size_t>(p)];
      lo = lo.cwiseMin(prim.a_L).cwiseMin(prim.b_L);
      hi = hi.cwiseMax(prim.a_L).cwiseMax(prim.b_L);
    }
    const Eigen::Vector3d c = 0.5 * (lo + hi);
    double r = 0.0;
    for (int p = seg.first_primitive; p < seg.first_primitive + seg.num_primitives; ++p) {
      const Primitive& prim = model.primitives[static_cast<std::size_t>(p)];
      r = std::max(r, std::max((prim.a_L - c).norm(), (prim.b_L - c).norm()) + prim.radius);
    }
    d.bound_center_L[s] = c;
    d.bound_radius[s] = r;
  }
}

}  // namespace

DistanceData::DistanceData(const Model& model)
    : pairs(model.pairs.size()),
      rows(Eigen::MatrixXd::Zero(static_cast<Eigen::Index>(model.pairs.size()), model.nq)),
      prim_B(model.primitives.size()),
      prim_r(model.primitives.size(), 0.0),
      pair_common(model.pairs.size(), -1) {
  for (std::size_t i = 0; i < model.pairs.size(); ++i) {
    const SegmentPair& p = model.pairs[i];
    pairs[i].seg_a = p.a;
    pairs[i].seg_b = p.b;
    pp_begin.push_back(static_cast<int>(pp_a.size()));
    const Segment& sa = model.segments[p.a];
    const Segment& sb = model.segments[p.b];
    if (sa.body_schema_slot || sb.body_schema_slot) {
      slot_pairs.push_back(static_cast<int>(i));
      continue;
    }
    robot_pairs.push_back(static_cast<int>(i));
    pair_common[i] = static_cast<int>(commonSupport(model, sa.link, sb.link));
    for (int a = sa.first_primitive; a < sa.first_primitive + sa.num_primitives; ++a) {
      for (int b = sb.first_primitive; b < sb.first_primitive + sb.num_primitives; ++b) {
        pp_a.push_back(a);
        pp_b.push_back(b);
        const std::array<int, 2> links{linkOf(sa, model.primitives[static_cast<std::size_t>(a)]),
                                       linkOf(sb, model.primitives[static_cast<std::size_t>(b)])};
        const bool unchecked = std::binary_search(p.unchecked_links.begin(), p.unchecked_links.end(), links);
        pp_unchecked.push_back(unchecked ? 1 : 0);
        any_pp_unchecked = any_pp_unchecked || unchecked;
      }
    }
  }
  pp_begin.push_back(static_cast<int>(pp_a.size()));
  prim_link.assign(model.primitives.size(), -1);
  link_segment.assign(model.links.size(), -1);
  for (int s = 0; s < model.num_robot_segments; ++s) {
    const Segment& seg = model.segments[static_cast<std::size_t>(s)];
    if (seg.link >= 0) link_segment[static_cast<std::size_t>(seg.link)] = s;
    for (int p = seg.first_primitive; p < seg.first_primitive + seg.num_primitives; ++p) {
      prim_link[static_cast<std::size_t>(p)] = linkOf(seg, model.primitives[static_cast<std::size_t>(p)]);
      link_segment[static_cast<std::size_t>(prim_link[static_cast<std::size_t>(p)])] = s;
    }
  }
  exact_pairs.assign(robot_pairs.size(), -1);
  // The tight model: cores of the capsules as two-vertex pieces; which pairs have a piece.
  core_piece.resize(model.primitives.size());
  for (std::size_t p = 0; p < model.primitives.size(); ++p) {
    core_piece[p].vertices_L = {model.primitives[p].a_L, model.primitives[p].b_L};
    core_piece[p].bound_center_L = 0.5 * (model.primitives[p].a_L + model.primitives[p].b_L);
  }
  pair_has_piece.assign(model.pairs.size(), 0);
  piece_winner.assign(model.pairs.size(), {-1, -1});
  upper_search.assign(model.pairs.size(), UpperSearch{});
  auto hasPiece = [&](const Segment& seg) {
    for (int p = seg.first_primitive; p < seg.first_primitive + seg.num_primitives; ++p)
      if (model.primitives[static_cast<std::size_t>(p)].piece >= 0) return true;
    return false;
  };
  std::size_t most_candidates = 1;
  for (std::size_t i = 0; i < model.pairs.size(); ++i) {
    const Segment& sa = model.segments[model.pairs[i].a];
    const Segment& sb = model.segments[model.pairs[i].b];
    pair_has_piece[i] = hasPiece(sa) || hasPiece(sb);
    most_candidates = std::max(most_candidates, static_cast<std::size_t>(std::max(sa.num_primitives, 1)) *
                                                    static_cast<std::size_t>(std::max(sb.num_primitives, 1)));
  }
  piece_candidates.resize(most_candidates);
  // Bounding sphere of every robot segment in its link frame: centred on the middle of the box
  // around its primitives' end points; the radius reaches the farthest end point plus its radius
  // (a capsule lies inside the spheres around its two ends' hull, so the sphere encloses it).
  buildSegmentSpheres(model, *this);
  several_links.assign(model.segments.size(), 0);
  for (int s = 0; s < model.num_robot_segments; ++s)
    several_links[static_cast<std::size_t>(s)] = severalLinks(model, model.segments[static_cast<std::size_t>(s)]);
  buildLinkBlocks(model, *this);
  seg_placed.assign(model.segments.size(), 0);
  pair_several.assign(model.pairs.size(), 0);
  for (std::size_t i = 0; i < model.pairs.size(); ++i)
    pair_several[i] = several_links[static_cast<std::size_t>(model.pairs[i].a)] ||
                      several_links[static_cast<std::size_t>(model.pairs[i].b)];
  for (const int i : robot_pairs) {
    const SegmentPair& p = model.pairs[static_cast<std::size_t>(i)];
    if (pair_several[static_cast<std::size_t>(i)]) rp_dynamic.push_back(static_cast<int>(rp_a.size()));
    rp_a.push_back(p.a);
    rp_b.push_back(p.b);
    rp_rsum.push_back(bound_radius[static_cast<std::size_t>(p.a)] + bound_radius[static_cast<std::size_t>(p.b)]);
  }
  rp_gap.assign(robot_pairs.size(), 0.0);
  segment_stamp.assign(model.segments.size(), 0U);
  // Per primitive, the radius of its bounding sphere (about its core's middle); per segment the most
  // primitives, for the kept lists (robot segments only).
  prim_sphere_r.assign(model.primitives.size(), 0.0);
  std::size_t most_primitives = 1;
  for (const Segment& seg : model.segments) {
    most_primitives = std::max(most_primitives, static_cast<std::size_t>(std::max(seg.num_primitives, 1)));
    if (seg.body_schema_slot) continue;
    for (int p = seg.first_primitive; p < seg.first_primitive + seg.num_primitives; ++p) {
      const Primitive& prim = model.primitives[static_cast<std::size_t>(p)];
      prim_sphere_r[static_cast<std::size_t>(p)] = 0.5 * (prim.b_L - prim.a_L).norm() + prim.radius;
    }
  }
  pp_lower.assign(pp_a.size(), -std::numeric_limits<double>::infinity());
  pp_hint.assign(pp_a.size(), ConvexHint{});
  prim_odometer.assign(model.primitives.size(), 0.0);
  pair_lower.assign(model.pairs.size(), -std::numeric_limits<double>::infinity());
  seg_odometer.assign(model.segments.size(), 0.0);
  last_X.assign(model.links.size(), Eigen::Isometry3d::Identity());
  list_pp.assign(pp_a.size(), 0);
  kept_a.assign(most_primitives, 0);
  kept_b.assign(most_primitives, 0);
  kept_a2.assign(most_primitives, 0);
  kept_b2.assign(most_primitives, 0);
  list_end.assign(robot_pairs.size(), 0);
  list_floor.assign(robot_pairs.size(), 0.0);
  list_a.assign(pp_a.size(), 0);
  list_b.assign(pp_a.size(), 0);
  pp_s.assign(pp_a.size(), 0.0);
  pp_t.assign(pp_a.size(), 0.0);
  pp_core.assign(pp_a.size(), 0.0);
}

namespace {

/// Subtracted from a carried lower bound: the rounding of the motion bound.
constexpr double kCarryMargin = 1e-9;
/// Added to an upper bound a listing is cut at: the rounding of a bounding-sphere gap (m).
constexpr double kListMargin = 1e-6;

/// Primitive pair pp's carried lower bound now (-inf: none): the bound stored at some earlier call,
/// less how far each of its primitives has moved since (its odometer then is in the stored value).
inline double carriedBound(const DistanceData& data, int pp, int pa, int pb) {
  return data.pp_lower[static_cast<std::size_t>(pp)] - data.prim_odometer[static_cast<std::size_t>(pa)] -
         data.prim_odometer[static_cast<std::size_t>(pb)] - kCarryMargin;
}

/// Stores `lower`, a lower bound of primitive pair pp's distance at this call's poses, to be carried.
inline void storeBound(DistanceData& data, int pp, int pa, int pb, double lower) {
  data.pp_lower[static_cast<std::size_t>(pp)] =
      lower + data.prim_odometer[static_cast<std::size_t>(pa)] + data.prim_odometer[static_cast<std::size_t>(pb)];
}

/// Whether primitive pair pp's carried bound is beyond `within`: it is then left out of a listing
/// (nothing computed for it, its stored bound kept), and `left_out` lowered to that bound.
inline bool carriedBeyond(const DistanceData& data, int pp, int pa, int pb, double within, double& left_out) {
  const double carried = carriedBound(data, pp, pa, pb);
  if (!(carried > within)) return false;
  left_out = std::min(left_out, carried);
  return true;
}

/// The index in pp_a / pp_b of primitives pa and pb of robot pair i (segments sa, sb).
inline int primitivePairIndex(const DistanceData& data, int i, const Segment& sa, const Segment& sb, int pa, int pb) {
  return data.pp_begin[static_cast<std::size_t>(i)] + (pa - sa.first_primitive) * sb.num_primitives +
         (pb - sb.first_primitive);
}

/// Whether primitives pa, pb of pair i are on a link pair the model does not check (never for a pair
/// with a body-schema slot, which has no primitive pairs listed).
inline bool uncheckedPrimitivePair(const DistanceData& data, int i, const Segment& sa, const Segment& sb, int pa,
                                   int pb) {
  return data.any_pp_unchecked && data.pair_common[static_cast<std::size_t>(i)] >= 0 &&
         data.pp_unchecked[static_cast<std::size_t>(primitivePairIndex(data, i, sa, sb, pa, pb))];
}

/// The primitives k of [first, end) (from[k] with a list `from`) whose bounding sphere lies within
/// `within` of the sphere (c, r) into kept[0 .. n); `left_out` lowered to the smallest gap of the others.
inline void keepNearSphere(const DistanceData& data, const int* from, int first, int end, const Eigen::Vector3d& c,
                           double r, double within, int* kept, int& n, double& left_out) {
  n = 0;
  for (int k = first; k < end; ++k) {
    const int p = from ? from[k] : k;
    const SegmentB& w = data.prim_B[static_cast<std::size_t>(p)];
    const double gap = (w.start + 0.5 * w.d - c).norm() - data.prim_sphere_r[static_cast<std::size_t>(p)] - r;
    if (gap > within)
      left_out = std::min(left_out, gap);
    else
      kept[n++] = p;
  }
}

/// Calls emit(pa, pb, pp) for robot pair i's primitive pairs that can be within `within` (their link
/// pair checked). Each segment first keeps its primitives near the other segment's sphere. A segment
/// of several links then goes block (link) by block: a block pair whose spheres are farther apart is
/// skipped, each block's kept primitives are kept again near the other block's sphere (as the
/// per-link pairs of the same robot would be), and a primitive pair whose spheres are apart is left
/// out. `left_out` is lowered to the smallest gap of what is left out (a lower bound of its distance).
/// Every segment's spheres of this call must be in place.
template <class Emit>
void listNearPairs(DistanceData& data, int i, const Segment& sa, int a, const Segment& sb, int b, double within,
                   double& left_out, Emit&& emit) {
  auto sphere = [&](int s, Eigen::Vector3d& c, double& r) {
    const double* c4 = data.bound_center4_B.data() + 4 * s;
    c = Eigen::Vector3d(c4[0], c4[1], c4[2]);
    r = data.bound_radius[static_cast<std::size_t>(s)];
  };
  Eigen::Vector3d ca, cb;
  double ra, rb;
  sphere(a, ca, ra);
  sphere(b, cb, rb);
  int na = 0, nb = 0;
  int* kept_a = data.kept_a.data();
  int* kept_b = data.kept_b.data();
  keepNearSphere(data, nullptr, sa.first_primitive, sa.first_primitive + sa.num_primitives, cb, rb, within, kept_a, na,
                 left_out);
  keepNearSphere(data, nullptr, sb.first_primitive, sb.first_primitive + sb.num_primitives, ca, ra, within, kept_b, nb,
                 left_out);
  // Every pair of the two lists; with `spheres`, only those whose primitives' spheres are within.
  auto cross = [&](const int* xa, int nxa, const int* xb, int nxb, bool spheres) {
    for (int ka = 0; ka < nxa; ++ka) {
      const int pa = xa[ka];
      const SegmentB& wa = data.prim_B[static_cast<std::size_t>(pa)];
      const Eigen::Vector3d c_pa = wa.start + 0.5 * wa.d;
      const double r_pa = data.prim_sphere_r[static_cast<std::size_t>(pa)];
      for (int kb = 0; kb < nxb; ++kb) {
        const int pb = xb[kb];
        const int pp = primitivePairIndex(data, i, sa, sb, pa, pb);
        if (data.any_pp_unchecked && data.pp_unchecked[static_cast<std::size_t>(pp)]) continue;
        if (spheres) {
          const SegmentB& wb = data.prim_B[static_cast<std::size_t>(pb)];
          const double gap =
              (c_pa - (wb.start + 0.5 * wb.d)).norm() - r_pa - data.prim_sphere_r[static_cast<std::size_t>(pb)];
          if (gap > within) {
            left_out = std::min(left_out, gap);
            continue;
          }
        }
        emit(pa, pb, pp);
      }
    }
  };
  const bool several_a = data.several_links[static_cast<std::size_t>(a)] != 0;
  const bool several_b = data.several_links[static_cast<std::size_t>(b)] != 0;
  if (!several_a && !several_b) {
    cross(kept_a, na, kept_b, nb, /*spheres=*/false);  // the sweep's kernel computes them all at once
    return;
  }
  // The blocks of a segment over its kept primitives (ascending, so each block's are consecutive):
  // f(begin, end, centre, radius) with [begin, end) indices into the kept list.
  auto blocks = [&](int s, bool several, const int* kept, int n, const Eigen::Vector3d& c, double r, auto&& f) {
    if (!several) {
      if (n > 0) f(0, n, c, r);
      return;
    }
    int at = 0;
    for (int k = data.seg_block[static_cast<std::size_t>(s)]; k < data.seg_block[static_cast<std::size_t>(s) + 1];
         ++k) {
      const int begin = at;
      while (at < n && kept[at] < data.block_end[static_cast<std::size_t>(k)]) ++at;
      if (at > begin)
        f(begin, at, data.block_center_B[static_cast<std::size_t>(k)], data.block_radius[static_cast<std::size_t>(k)]);
    }
  };
  int* again_a = data.kept_a2.data();
  int* again_b = data.kept_b2.data();
  blocks(a, several_a, kept_a, na, ca, ra, [&](int xa0, int xa1, const Eigen::Vector3d& cx, double rx) {
    blocks(b, several_b, kept_b, nb, cb, rb, [&](int xb0, int xb1, const Eigen::Vector3d& cy, double ry) {
      const double gap = (cx - cy).norm() - rx - ry;
      if (gap > within) {
        left_out = std::min(left_out, gap);
        return;
      }
      int nxa = 0, nxb = 0;
      keepNearSphere(data, kept_a, xa0, xa1, cy, ry, within, again_a, nxa, left_out);
      keepNearSphere(data, kept_b, xb0, xb1, cx, rx, within, again_b, nxb, left_out);
      cross(again_a, nxa, again_b, nxb, /*spheres=*/true);
    });
  });
}

/// Whether a pair that involves a body-schema slot is checked this cycle; sets the links.
bool slotPairActive(const Model& model, const DistanceData& data, const BodySchemaSlots& slots, const SegmentPair& pair,
                    int& link_a, int& link_b) {
  const Segment& sa = model.segments[pair.a];
  const Segment& sb = model.segments[pair.b];
  if (sa.body_schema_slot) {
    const BodySchemaSlot& slot = slots[static_cast<std::size_t>(pair.a - model.num_robot_segments)];
    if (!slot.enabled) return false;
    link_a = slot.link;
  }
  if (sb.body_schema_slot) {
    const BodySchemaSlot& slot = slots[static_cast<std::size_t>(pair.b - model.num_robot_segments)];
    if (!slot.enabled) return false;
    link_b = slot.link;
    if ((slot.ignore_mask >> pair.a) & 1U) return false;
    // never against the segment that has the link it hangs on
    if (data.link_segment[static_cast<std::size_t>(slot.link)] == pair.a) return false;
  }
  return true;
}

/// Pair i's avoidance row, n^T (J_pa - J_pb), with each witness point's Jacobian on the link of its
/// primitive (pa, pb; a body-schema slot's primitive: the slot's link_a / link_b). A robot pair of
/// single-link segments writes only its links' common support columns (the rest stay 0 from set-up);
/// a pair with a segment of several links, whose winning links change, and a slot pair write the row.
REFLEX_ALWAYS_INLINE inline void writeRow(const Model& model, const KinematicsData& kin, DistanceData& data, int i,
                                          int pa, int pb, int link_a, int link_b, const Eigen::Vector3d& p_a,
                                          const Eigen::Vector3d& p_b, const Eigen::Vector3d& n) {
  const int common = data.pair_common[static_cast<std::size_t>(i)];
  if (common >= 0 && !data.pair_several[static_cast<std::size_t>(i)]) {
    computeDirectionalRowOnSupport(model, kin, link_a, p_a, link_b, p_b, n, static_cast<std::size_t>(common),
                                   data.rows.row(i).data());
    return;
  }
  const int la =
      data.prim_link[static_cast<std::size_t>(pa)] >= 0 ? data.prim_link[static_cast<std::size_t>(pa)] : link_a;
  const int lb =
      data.prim_link[static_cast<std::size_t>(pb)] >= 0 ? data.prim_link[static_cast<std::size_t>(pb)] : link_b;
  computeDirectionalRow(model, kin, la, p_a, lb, p_b, n, data.rows.row(i));
}

/// Writes pair i's result from its closest primitive pair (pa, pb: core distance `core`, parameters
/// s, t; surface distance `best`): normal, witness points and, below the threshold, the row.
/// Inlined into every loop (GCC otherwise keeps one out-of-line copy: a call per pair).
REFLEX_ALWAYS_INLINE inline void finishPair(const Model& model, const KinematicsData& kin, DistanceData& data,
                                            const DistanceOptions& options, int i, int link_a, int link_b, double best,
                                            double core, int pa, int pb, double s, double t) {
  PairDistance& out = data.pairs[i];
  const SegmentB& A = data.prim_B[pa];
  const SegmentB& B = data.prim_B[pb];
  const Eigen::Vector3d c_a = A.start + s * A.d;
  const Eigen::Vector3d c_b = B.start + t * B.d;
  // Unit normal from b towards a; coincident cores: the direction between the link origins.
  Eigen::Vector3d n;
  out.well_defined = core > kCoincidentEps;
  if (out.well_defined) {
    n = (c_a - c_b) * (1.0 / core);
  } else {
    n = kin.X_B_L[link_a].translation() - kin.X_B_L[link_b].translation();
    const double norm = n.norm();
    n = norm > kCoincidentEps ? Eigen::Vector3d(n / norm) : Eigen::Vector3d::UnitZ();
  }
  out.active = true;
  out.exact = true;
  out.distance = best;
  out.nhat_B = n;
  out.p_B_a = c_a - data.prim_r[pa] * n;
  out.p_B_b = c_b + data.prim_r[pb] * n;
  out.has_row = best < options.row_threshold;
  if (!out.has_row) return;
  writeRow(model, kin, data, i, pa, pb, link_a, link_b, out.p_B_a, out.p_B_b, n);
}

/// Pair i's result from witness points on the real shapes (the tight model): p_a on a's surface, p_b
/// on b's, unit normal n from b towards a, distance d; below the threshold, the row.
REFLEX_ALWAYS_INLINE inline void finishPairPoints(const Model& model, const KinematicsData& kin, DistanceData& data,
                                                  const DistanceOptions& options, int i, int link_a, int link_b,
                                                  double d, int pa, int pb, const Eigen::Vector3d& p_a,
                                                  const Eigen::Vector3d& p_b, const Eigen::Vector3d& n) {
  PairDistance& out = data.pairs[i];
  out.well_defined = true;
  out.active = true;
  out.exact = true;
  out.distance = d;
  out.nhat_B = n;
  out.p_B_a = p_a;
  out.p_B_b = p_b;
  out.has_row = d < options.row_threshold;
  if (!out.has_row) return;
  writeRow(model, kin, data, i, pa, pb, link_a, link_b, p_a, p_b, n);
}

/// What pieceDistance found.
enum class PieceOutcome : std::uint8_t { kApart, kTouching, kAbove };

/// The exact distance of primitives pa (on link_a) and pb (on link_b) on their real shapes: a convex
/// piece as it is, a capsule as its core and radius. kApart: d, p_a, p_b, n. kTouching: the pieces (or
/// cores) touch or overlap, there is no direction; p_a is a common point. kAbove: the distance is
/// proven above `stop_above` (d: a lower bound of it, > stop_above), nothing else computed.
inline PieceOutcome pieceDistance(const Model& model, const KinematicsData& kin, const DistanceData& data, int pa,
                                  int pb, int link_a, int link_b, double stop_above, const Eigen::Vector3d& towards_b,
                                  double& d, Eigen::Vector3d& p_a, Eigen::Vector3d& p_b, Eigen::Vector3d& n,
                                  ConvexHint* hint = nullptr) {
  const Primitive& A = model.primitives[static_cast<std::size_t>(pa)];
  const Primitive& B = model.primitives[static_cast<std::size_t>(pb)];
  const ConvexPiece& ca =
      A.piece >= 0 ? model.pieces[static_cast<std::size_t>(A.piece)] : data.core_piece[static_cast<std::size_t>(pa)];
  const ConvexPiece& cb =
      B.piece >= 0 ? model.pieces[static_cast<std::size_t>(B.piece)] : data.core_piece[static_cast<std::size_t>(pb)];
  const double ra = A.piece >= 0 ? 0.0 : data.prim_r[static_cast<std::size_t>(pa)];
  const double rb = B.piece >= 0 ? 0.0 : data.prim_r[static_cast<std::size_t>(pb)];
  // Each primitive placed by its own link (a segment of several links), a slot's by the slot's.
  const int la =
      data.prim_link[static_cast<std::size_t>(pa)] >= 0 ? data.prim_link[static_cast<std::size_t>(pa)] : link_a;
  const int lb =
      data.prim_link[static_cast<std::size_t>(pb)] >= 0 ? data.prim_link[static_cast<std::size_t>(pb)] : link_b;
  const ConvexDistance c =
      computeConvexDistance(ca, kin.X_B_L[static_cast<std::size_t>(la)], cb, kin.X_B_L[static_cast<std::size_t>(lb)],
                            nullptr, stop_above + ra + rb, towards_b, hint);
  if (c.above) {
    d = c.distance - ra - rb;
    return PieceOutcome::kAbove;
  }
  if (!(c.distance > kCoincidentEps)) {
    p_a = c.p_B_a;
    return PieceOutcome::kTouching;
  }
  n = (c.p_B_a - c.p_B_b) * (1.0 / c.distance);
  d = c.distance - ra - rb;
  p_a = c.p_B_a - ra * n;
  p_b = c.p_B_b + rb * n;
  return PieceOutcome::kApart;
}

/// pieceDistance of primitives pa, pb of pair i, or, when upperBoundOfPair searched that primitive
/// pair this call, its result (the same bits: a search only stops earlier above stop_above), unless
/// that search stopped above a bound not above this stop_above.
inline PieceOutcome searchOrReuse(const Model& model, const KinematicsData& kin, DistanceData& data, int i, int pa,
                                  int pb, int link_a, int link_b, double stop_above, const Eigen::Vector3d& towards_b,
                                  double& d, Eigen::Vector3d& p_a, Eigen::Vector3d& p_b, Eigen::Vector3d& n,
                                  ConvexHint* hint) {
  const DistanceData::UpperSearch& u = data.upper_search[static_cast<std::size_t>(i)];
  // A search that stopped above its own bound answers only a question about a bound below that.
  if (u.call == data.search_call && u.pa == pa && u.pb == pb &&
      (static_cast<PieceOutcome>(u.outcome) != PieceOutcome::kAbove || u.d > stop_above)) {
    PieceOutcome o = static_cast<PieceOutcome>(u.outcome);
    d = u.d, p_a = u.p_a, p_b = u.p_b, n = u.n;
    if (o == PieceOutcome::kApart && d > stop_above) o = PieceOutcome::kAbove;  // as a search stopped there
    return o;
  }
  ++data.num_piece_searches;
  return pieceDistance(model, kin, data, pa, pb, link_a, link_b, stop_above, towards_b, d, p_a, p_b, n, hint);
}

/// Pair i of the tight model: the least exact distance over its primitive pairs, visited by
/// `each(f)` calling f(pa, pb, capsule distance, core distance, s, t) for each. The primitive pair of
/// the smallest capsule distance (a lower bound of the exact one) goes first; of the rest only those
/// whose bound is below the best exact distance found, nearest first, and each search stops as soon
/// as it proves its pair not closer than the best (computeConvexDistance's stop_above). Among equal
/// distances the lowest (pa, pb) wins, so the order does not change the result.
/// With a finite `give_up` (the broad phase's distance) a pair proven farther than it is left
/// inexact: returns false with `floor`, a lower bound of its distance (> give_up), and writes nothing.
/// Allocation-free (sorted in place in DistanceData::piece_candidates).
template <class Each>
bool finishPiecePair(const Model& model, const KinematicsData& kin, DistanceData& data, const DistanceOptions& options,
                     int i, int link_a, int link_b, double give_up, double& floor, Each&& each) {
  DistanceData::PieceCandidate* cand = data.piece_candidates.data();
  std::size_t count = 0, first = 0, last = 0;
  bool have_last = false;
  std::array<int, 2>& winner = data.piece_winner[static_cast<std::size_t>(i)];
  each([&](int pa, int pb, double bound, double core, double s, double t, int pp, double carried) {
    // A bound that is not a number is taken first (never skipped on its account). A bound carried from
    // the last cycle (its lower bound then, less how far the two pieces can have moved since) may be
    // the better one: never for two capsules, whose capsule distance is their distance.
    double key = bound == bound ? bound : -std::numeric_limits<double>::infinity();
    if (carried > key && (model.primitives[static_cast<std::size_t>(pa)].piece >= 0 ||
                          model.primitives[static_cast<std::size_t>(pb)].piece >= 0))
      key = carried;
    if (count == 0 || key < cand[first].bound) first = count;
    if (pa == winner[0] && pb == winner[1]) last = count, have_last = true;
    cand[count++] = {key, core, s, t, pa, pb, pp, key};
  });
  // The pair that won last time goes first when it can still win (it usually does again: its
  // distance then rules out nearly every other), else the one of the smallest bound.
  if (have_last && !(cand[last].bound > give_up)) first = last;
  std::swap(cand[0], cand[first]);
  double best = std::numeric_limits<double>::infinity();
  floor = std::numeric_limits<double>::infinity();
  bool on_pieces = false, overlap = false;
  int cap_pa = -1, cap_pb = -1;
  double cap_core = 0.0, cap_s = 0.0, cap_t = 0.0;
  Eigen::Vector3d best_pa = Eigen::Vector3d::Zero(), best_pb = Eigen::Vector3d::Zero(),
                  best_n = Eigen::Vector3d::UnitZ();
  // Whether (pa, pb) at distance d replaces the best so far.
  auto better = [&](double d, int pa, int pb) {
    return cap_pa < 0 || d < best || (d == best && (pa < cap_pa || (pa == cap_pa && pb < cap_pb)));
  };
  auto evaluate = [&](DistanceData::PieceCandidate& c) {
    const int pa = c.pa, pb = c.pb;
    const bool capsules = model.primitives[static_cast<std::size_t>(pa)].piece < 0 &&
                          model.primitives[static_cast<std::size_t>(pb)].piece < 0;
    if (capsules) {  // two capsules: exact as they are
      if (better(c.bound, pa, pb)) {
        best = c.bound, on_pieces = false, overlap = false;
        cap_pa = pa, cap_pb = pb, cap_core = c.core, cap_s = c.s, cap_t = c.t;
      }
      return;
    }
    double d;
    Eigen::Vector3d p_a, p_b, n;
    // The first search direction: between the closest points of the two capsules' cores.
    const SegmentB& A = data.prim_B[static_cast<std::size_t>(pa)];
    const SegmentB& B = data.prim_B[static_cast<std::size_t>(pb)];
    const Eigen::Vector3d towards_b = (B.start + c.t * B.d) - (A.start + c.s * A.d);
    const PieceOutcome o =
        searchOrReuse(model, kin, data, i, pa, pb, link_a, link_b, cap_pa >= 0 ? best : give_up, towards_b, d, p_a, p_b,
                      n, c.pp >= 0 ? &data.pp_hint[static_cast<std::size_t>(c.pp)] : nullptr);
    c.lower = o == PieceOutcome::kTouching ? 0.0 : std::max(c.lower, d);
    if (o == PieceOutcome::kAbove) {
      floor = std::min(floor, d);
      return;
    }
    if (o == PieceOutcome::kApart) {
      if (better(d, pa, pb)) {
        best = d, on_pieces = true, overlap = false, best_pa = p_a, best_pb = p_b, best_n = n;
        cap_pa = pa, cap_pb = pb, cap_core = c.core, cap_s = c.s, cap_t = c.t;
      }
      return;
    }
    // The pieces touch or overlap: distance 0, "the real shapes touch or overlap" (they may be apart
    // by up to the pieces' gaps, or intersect; the tight model does not estimate a depth, and the
    // capsules' depth can be far below the truth), at the common point, along the capsules' direction
    // (the way that separates their cores).
    if (!better(0.0, pa, pb)) return;
    Eigen::Vector3d dir = -towards_b;
    if (!(dir.norm() > kCoincidentEps))
      dir = kin.X_B_L[static_cast<std::size_t>(link_a)].translation() -
            kin.X_B_L[static_cast<std::size_t>(link_b)].translation();
    const double len = dir.norm();
    best = 0.0, on_pieces = true, overlap = true, best_pa = p_a, best_pb = p_a;
    best_n = len > kCoincidentEps ? Eigen::Vector3d(dir / len) : Eigen::Vector3d::UnitZ();
    cap_pa = pa, cap_pb = pb, cap_core = c.core, cap_s = c.s, cap_t = c.t;
  };
  // Only a primitive pair whose bound is not above `cut` (the best exact distance, give_up while
  // there is none) can matter; every one after the first above it is farther still.
  auto cut = [&] { return cap_pa >= 0 ? best : give_up; };
  if (count > 0 && !(cand[0].bound > give_up)) evaluate(cand[0]);
  std::size_t live = 1;
  for (std::size_t k = 1; k < count; ++k) {
    if (!(cand[k].bound > cut()))
      std::swap(cand[live++], cand[k]);
    else
      floor = std::min(floor, cand[k].bound);
  }
  std::sort(cand + 1, cand + live, [](const DistanceData::PieceCandidate& x, const DistanceData::PieceCandidate& y) {
    return x.bound < y.bound;
  });
  for (std::size_t k = 1; k < live; ++k) {
    if (cand[k].bound > cut()) {
      floor = std::min(floor, cand[k].bound);
      break;
    }
    evaluate(cand[k]);
  }
  // Every listed candidate's lower bound at these poses, for the next cycle to carry.
  for (std::size_t k = 0; k < count; ++k) {
    if (cand[k].pp < 0) continue;
    storeBound(data, cand[k].pp, cand[k].pa, cand[k].pb, cand[k].lower);
  }
  if (cap_pa < 0) {  // every primitive pair proven farther than give_up
    if (count > 0 && cand[0].bound > give_up) floor = std::min(floor, cand[0].bound);
    return false;
  }
  winner = {cap_pa, cap_pb};
  if (on_pieces) {
    finishPairPoints(model, kin, data, options, i, link_a, link_b, best, cap_pa, cap_pb, best_pa, best_pb, best_n);
    data.pairs[static_cast<std::size_t>(i)].well_defined = !overlap;  // overlapping pieces: the capsules' normal
  } else {
    finishPair(model, kin, data, options, i, link_a, link_b, best, cap_core, cap_pa, cap_pb, cap_s, cap_t);
  }
  return true;
}

/// An upper bound of robot pair i's distance (+inf: none found, or none at most `stop_above`): the
/// exact distance of one of its primitive pairs, the one that won last time, else the primitives
/// nearest the other segment's bounding sphere (this call's: the caller has them). A primitive pair
/// proven farther than stop_above is not searched further (the caller's listing is cut there anyway).
double upperBoundOfPair(const Model& model, const KinematicsData& kin, DistanceData& data, int i, const Segment& sa,
                        const Segment& sb, int link_a, int link_b,
                        double stop_above = std::numeric_limits<double>::infinity()) {
  const std::array<int, 2>& w = data.piece_winner[static_cast<std::size_t>(i)];
  int pa = w[0], pb = w[1];
  if (pa < sa.first_primitive || pa >= sa.first_primitive + sa.num_primitives || pb < sb.first_primitive ||
      pb >= sb.first_primitive + sb.num_primitives) {
    auto nearest = [&](const Segment& seg, int other) {
      const double* c4 = data.bound_center4_B.data() + 4 * other;
      const Eigen::Vector3d c(c4[0], c4[1], c4[2]);
      int best = seg.first_primitive;
      double best_gap = std::numeric_limits<double>::infinity();
      for (int p = seg.first_primitive; p < seg.first_primitive + seg.num_primitives; ++p) {
        const SegmentB& x = data.prim_B[static_cast<std::size_t>(p)];
        const double gap = (x.start + 0.5 * x.d - c).norm() - data.prim_sphere_r[static_cast<std::size_t>(p)];
        if (gap < best_gap) best_gap = gap, best = p;
      }
      return best;
    };
    const SegmentPair& pair = model.pairs[static_cast<std::size_t>(i)];
    pa = nearest(sa, pair.b);
    pb = nearest(sb, pair.a);
  }
  if (uncheckedPrimitivePair(data, i, sa, sb, pa, pb)) return std::numeric_limits<double>::infinity();
  const SegmentB& A = data.prim_B[static_cast<std::size_t>(pa)];
  const SegmentB& B = data.prim_B[static_cast<std::size_t>(pb)];
  double s, t;
  (void)detail::coreDistance(A, B, s, t);
  const Eigen::Vector3d towards_b = (B.start + t * B.d) - (A.start + s * A.d);
  double d = 0.0;
  Eigen::Vector3d p_a = Eigen::Vector3d::Zero(), p_b = Eigen::Vector3d::Zero(), n = Eigen::Vector3d::UnitZ();
  ++data.num_piece_searches;
  const PieceOutcome o = pieceDistance(model, kin, data, pa, pb, link_a, link_b, stop_above, towards_b, d, p_a, p_b, n);
  data.upper_search[static_cast<std::size_t>(i)] = {pa,  pb, data.search_call, static_cast<std::uint8_t>(o), d, p_a,
                                                    p_b, n};
  if (o == PieceOutcome::kTouching) return 0.0;
  if (o == PieceOutcome::kAbove) return std::numeric_limits<double>::infinity();
  return d == d ? d : std::numeric_limits<double>::infinity();
}

/// The closest primitive pair of segments sa and sb, computed directly (slot pairs, refinement);
/// the same arithmetic and order as the flat loop of computeSegmentDistances.
/// `give_up` (a pair of the tight model only): a pair proven farther than it comes out inexact, its
/// distance a lower bound above give_up (finishPiecePair); +inf: always exact.
void computeSegmentPair(const Model& model, const KinematicsData& kin, DistanceData& data,
                        const DistanceOptions& options, int i, const Segment& sa, const Segment& sb, int link_a,
                        int link_b, double give_up = std::numeric_limits<double>::infinity(), bool bounds_fresh = false,
                        bool carry = false, const PairListing* listing = nullptr) {
  const SegmentB* prim = data.prim_B.data();
  const double* radius = data.prim_r.data();
  if (data.pair_common[static_cast<std::size_t>(i)] < 0) data.slot_pairs_inactive = false;  // a slot pair
  if (data.pair_has_piece[static_cast<std::size_t>(i)]) {
    // With a finite give_up, a robot pair lists only the primitive pairs that can be within it (as the
    // sweep does with its prune distance: listNearPairs); `left_out` is the smallest gap of those it
    // leaves out. Asked for the exact distance, a robot pair (its bounding spheres of this call in
    // place) lists only those within an upper bound of it: one primitive pair's exact distance.
    const int nka = sa.num_primitives, nkb = sb.num_primitives;
    double left_out = std::numeric_limits<double>::infinity();
    const bool robot = !sa.body_schema_slot && !sb.body_schema_slot && nka * nkb > 4;
    double within = give_up;
    if (robot && bounds_fresh && !(give_up < std::numeric_limits<double>::infinity()))
      within = upperBoundOfPair(model, kin, data, i, sa, sb, link_a, link_b);
    const bool filter = robot && within < std::numeric_limits<double>::infinity();
    // With `carry` (a listed pair or a refinement: its primitives measured this call), each primitive pair's
    // carried lower bound (carriedBound: less how far its primitives moved since) is offered.
    auto offer = [&](auto&& f, int pa, int pb, int pp) {
      double s, t;
      const double core = detail::coreDistance(prim[pa], prim[pb], s, t);
      const double carried = pp >= 0 ? carriedBound(data, pp, pa, pb) : -std::numeric_limits<double>::infinity();
      f(pa, pb, core - radius[pa] - radius[pb], core, s, t, pp, carried);
    };
    // A pair listed beforehand (listPairsNear, valid for these poses) offers its listed primitive pairs.
    const bool listed = listing && listing->count[static_cast<std::size_t>(i)] >= 0;
    if (listed) left_out = listing->floor[static_cast<std::size_t>(i)];
    double floor;
    const bool finished = finishPiecePair(model, kin, data, options, i, link_a, link_b, give_up, floor, [&](auto&& f) {
      if (listed) {
        const int first = data.pp_begin[static_cast<std::size_t>(i)];
        const int end = first + listing->count[static_cast<std::size_t>(i)];
        for (int k = first; k < end; ++k)
          offer(f, listing->pa[static_cast<std::size_t>(k)], listing->pb[static_cast<std::size_t>(k)],
                carry ? listing->pp[static_cast<std::size_t>(k)] : -1);
        return;
      }
      if (filter) {
        // As the sweep lists (coreDistancesOfExactPairs): with `carry`, a primitive pair carried
        // beyond `within` is left out with that bound.
        const SegmentPair& pair = model.pairs[static_cast<std::size_t>(i)];
        listNearPairs(data, i, sa, pair.a, sb, pair.b, within, left_out, [&](int pa, int pb, int pp) {
          if (carry && carriedBeyond(data, pp, pa, pb, within, left_out)) return;
          offer(f, pa, pb, carry ? pp : -1);
        });
        return;
      }
      for (int pa = sa.first_primitive; pa < sa.first_primitive + nka; ++pa)
        for (int pb = sb.first_primitive; pb < sb.first_primitive + nkb; ++pb)
          if (!uncheckedPrimitivePair(data, i, sa, sb, pa, pb))
            offer(f, pa, pb, carry && robot ? primitivePairIndex(data, i, sa, sb, pa, pb) : -1);
    });
    if (!finished) {
      PairDistance& out = data.pairs[static_cast<std::size_t>(i)];
      out.active = true;
      out.exact = false;
      out.has_row = false;
      out.distance = std::min(floor, left_out);
    }
    return;
  }
  double best = std::numeric_limits<double>::infinity(), best_core = 0.0, best_s = 0.0, best_t = 0.0;
  int best_pa = sa.first_primitive, best_pb = sb.first_primitive;
  for (int pa = sa.first_primitive; pa < sa.first_primitive + sa.num_primitives; ++pa) {
    for (int pb = sb.first_primitive; pb < sb.first_primitive + sb.num_primitives; ++pb) {
      if (uncheckedPrimitivePair(data, i, sa, sb, pa, pb)) continue;
      double s, t;
      const double core = detail::coreDistance(prim[pa], prim[pb], s, t);
      const double d = core - radius[pa] - radius[pb];
      if (d < best) {
        best = d;
        best_core = core;
        best_s = s;
        best_t = t;
        best_pa = pa;
        best_pb = pb;
      }
    }
  }
  finishPair(model, kin, data, options, i, link_a, link_b, best, best_core, best_pa, best_pb, best_s, best_t);
}

/// The bounding sphere of segment s of several links (its primitives already in B this call): about
/// the middle of its primitives' sphere centres' box, through the farthest sphere. Its radius changes
/// with the joints between its links, so the sums of its robot pairs are redone in the broad phase.
void boundPrimitivesWhereTheyAre(DistanceData& data, const Segment& seg, int s) {
  Eigen::Vector3d lo = Eigen::Vector3d::Constant(std::numeric_limits<double>::infinity()), hi = -lo;
  for (int p = seg.first_primitive; p < seg.first_primitive + seg.num_primitives; ++p) {
    const SegmentB& w = data.prim_B[static_cast<std::size_t>(p)];
    const Eigen::Vector3d c = w.start + 0.5 * w.d;
    lo = lo.cwiseMin(c);
    hi = hi.cwiseMax(c);
  }
  const Eigen::Vector3d centre = 0.5 * (lo + hi);
  double r = 0.0;
  for (int p = seg.first_primitive; p < seg.first_primitive + seg.num_primitives; ++p) {
    const SegmentB& w = data.prim_B[static_cast<std::size_t>(p)];
    r = std::max(r, (w.start + 0.5 * w.d - centre).norm() + data.prim_sphere_r[static_cast<std::size_t>(p)]);
  }
  double* c4 = data.bound_center4_B.data() + 4 * s;
  c4[0] = centre.x();
  c4[1] = centre.y();
  c4[2] = centre.z();
  // NaN poses: an infinite sphere (never skipped on its account; the NaN shows in the pair).
  data.bound_radius[static_cast<std::size_t>(s)] = r == r ? r : std::numeric_limits<double>::infinity();
}

/// Whether every link robot segment s's primitives move with is, bit for bit, where the segment's last
/// measure left it (data.last_X): then it has not moved since it was last placed (placeSegment).
bool segmentWhereMeasured(const KinematicsData& kin, const DistanceData& data, const Segment& seg, int s) {
  auto same = [&](int l) {
    return kin.X_B_L[static_cast<std::size_t>(l)].matrix() == data.last_X[static_cast<std::size_t>(l)].matrix();
  };
  if (!same(seg.link)) return false;
  for (int k = data.seg_block[static_cast<std::size_t>(s)]; k < data.seg_block[static_cast<std::size_t>(s) + 1]; ++k)
    if (!same(data.block_link[static_cast<std::size_t>(k)])) return false;
  return true;
}

/// How far each primitive of robot segment s can have moved since its links' poses in data.last_X
/// (its bounding sphere's centre moved, plus its radius times 2 sin(theta / 2) of its link's turn
/// theta), added to its odometer; then last_X of the segment's links takes these poses.
void measureSegmentMotion(const Model& model, const KinematicsData& kin, DistanceData& data, int s) {
  const Segment& seg = model.segments[static_cast<std::size_t>(s)];
  auto turnOf = [&](const Eigen::Isometry3d& X, const Eigen::Isometry3d& X0) {
    return std::sqrt(std::max(0.0, 3.0 - (X.linear().array() * X0.linear().array()).sum()));
  };
  const double seg_turn =
      turnOf(kin.X_B_L[static_cast<std::size_t>(seg.link)], data.last_X[static_cast<std::size_t>(seg.link)]);
  double most = 0.0;
  for (int p = seg.first_primitive; p < seg.first_primitive + seg.num_primitives; ++p) {
    const Primitive& prim = model.primitives[static_cast<std::size_t>(p)];
    const std::size_t link = static_cast<std::size_t>(linkOf(seg, prim));  // a finger's own link
    const Eigen::Isometry3d& X = kin.X_B_L[link];
    const Eigen::Isometry3d& X0 = data.last_X[link];
    const double turn = prim.link >= 0 ? turnOf(X, X0) : seg_turn;
    const Eigen::Vector3d c_L = 0.5 * (prim.a_L + prim.b_L);
    double m = (X * c_L - X0 * c_L).norm() + turn * data.prim_sphere_r[static_cast<std::size_t>(p)];
    m = m == m ? m : std::numeric_limits<double>::infinity();
    data.prim_odometer[static_cast<std::size_t>(p)] += m;
    most = std::max(most, m);
  }
  data.seg_odometer[static_cast<std::size_t>(s)] += most;
  data.last_X[static_cast<std::size_t>(seg.link)] = kin.X_B_L[static_cast<std::size_t>(seg.link)];
  for (int k = data.seg_block[static_cast<std::size_t>(s)]; k < data.seg_block[static_cast<std::size_t>(s) + 1]; ++k) {
    const std::size_t l = static_cast<std::size_t>(data.block_link[static_cast<std::size_t>(k)]);
    data.last_X[l] = kin.X_B_L[l];
  }
}

/// Segment s's primitives (core start, direction and radius) into B for this cycle's kinematics; a
/// disabled body-schema slot is left as it was. With `bound`, a robot segment's bounding sphere
/// centre too. A robot segment of the tight model is measured too (measureSegmentMotion).
void placeSegment(const Model& model, const KinematicsData& kin, const BodySchemaSlots& slots, DistanceData& data,
                  int s, bool bound) {
  const Segment& seg = model.segments[s];
  if (seg.body_schema_slot) {
    const BodySchemaSlot& slot = slots[static_cast<std::size_t>(s - model.num_robot_segments)];
    if (!slot.enabled) return;
    const Eigen::Isometry3d& X = kin.X_B_L[slot.link];
    data.prim_B[seg.first_primitive].set(X * slot.a_L, X * slot.b_L);
    data.prim_r[seg.first_primitive] = slot.radius;
    ConvexPiece& core = data.core_piece[static_cast<std::size_t>(seg.first_primitive)];  // 2 vertices: no allocation
    core.vertices_L[0] = slot.a_L;
    core.vertices_L[1] = slot.b_L;
    return;
  }
  const Eigen::Isometry3d& X = kin.X_B_L[seg.link];
  const bool several = data.several_links[static_cast<std::size_t>(s)] != 0;
  // The tight model: the segment is measured here too (how far it moved since its last measure, which
  // placed it). One whose links did not move is neither measured nor placed again (a still torso, legs,
  // head), unless its bounding sphere is asked for and was not made at these poses.
  const bool tight = !model.pieces.empty();
  const bool still = tight && segmentWhereMeasured(kin, data, seg, s);
  if (tight) {
    std::uint8_t& placed = data.seg_placed[static_cast<std::size_t>(s)];
    if (still && placed >= (bound ? 2 : 1)) return;
    placed = bound ? 2 : 1;
    if (!still) measureSegmentMotion(model, kin, data, s);
  }
  const int block_begin = data.seg_block[static_cast<std::size_t>(s)];
  const int block_end = data.seg_block[static_cast<std::size_t>(s) + 1];
  if (bound && !several) {
    const Eigen::Vector3d c = X * data.bound_center_L[s];
    double* c4 = data.bound_center4_B.data() + 4 * s;
    c4[0] = c.x();
    c4[1] = c.y();
    c4[2] = c.z();
  }
  for (int p = seg.first_primitive; p < seg.first_primitive + seg.num_primitives; ++p) {
    const Primitive& prim = model.primitives[p];
    const Eigen::Isometry3d& X_p = prim.link >= 0 ? kin.X_B_L[static_cast<std::size_t>(prim.link)] : X;
    SegmentB& w = data.prim_B[p];
    w.start = X_p * prim.a_L;
    if (prim.sphere) {  // no second end point to transform
      w.d.setZero();
      w.dd = 0.0;
      w.inv_dd = 0.0;
    } else {
      w.d = X_p.linear() * (prim.b_L - prim.a_L);
      w.dd = w.d.squaredNorm();
      w.inv_dd = w.dd > kPointSegmentSq ? 1.0 / w.dd : 0.0;
    }
    data.prim_r[p] = prim.radius;
  }
  if (bound && several) {
    boundPrimitivesWhereTheyAre(data, seg, s);
    for (int k = block_begin; k < block_end; ++k)
      data.block_center_B[static_cast<std::size_t>(k)] =
          kin.X_B_L[static_cast<std::size_t>(data.block_link[static_cast<std::size_t>(k)])] *
          data.block_center_L[static_cast<std::size_t>(k)];
  }
}

}  // namespace

void computeSegmentDistances(const Model& model, const KinematicsData& kin, DistanceData& data,
                             const DistanceOptions& options) {
  computeSegmentDistances(model, kin, data.slots, data, options);
}

namespace {

/// What computeSegmentDistances's steps hand on: the robot pairs computed exactly (the broad phase's
/// survivors, or every robot pair), the smallest lower bound of a skipped pair, and the flat list of
/// primitive pairs whose core distances step 3 computed.
struct Sweep {
  bool prune = false;
  const int* exact_pairs = nullptr;
  int nexact = 0;
  double pruned_floor = std::numeric_limits<double>::infinity();
  /// The exact pairs' primitive pairs were listed (list_end, list_pp): with the broad phase, or when
  /// some link pairs are not checked; else they are pp_a / pp_b in pair order.
  bool listed = false;
  const int* list_a = nullptr;
  const int* list_b = nullptr;
  int nlist = 0;
};

/// A new call: the searches counted from here; an upper bound's search of an earlier call is not reused.
void nextSearchCall(DistanceData& data) {
  data.num_piece_searches = 0;
  if (++data.search_call == 0) {  // wrapped: no old entry may pass for this call's
    for (DistanceData::UpperSearch& u : data.upper_search) u.call = 0;
    data.search_call = 1;
  }
}

/// Step 2, the broad phase: robot pairs whose bounding spheres are more than prune_distance apart get
/// that gap as a lower bound; the others are listed in sw.exact_pairs for step 4.
void broadPhase(DistanceData& data, const DistanceOptions& options, Sweep& sw) {
  constexpr double kInf = std::numeric_limits<double>::infinity();
  sw.exact_pairs = data.robot_pairs.data();
  sw.nexact = static_cast<int>(data.robot_pairs.size());
  data.num_pruned_pairs = 0;
  sw.pruned_floor = kInf;
  if (sw.prune) {
    // Every robot pair's gap (a kernel: no branch), then, without a branch either (which way a pair
    // goes is data-dependent and mispredicts), each pair's entry as skipped (the exact ones are
    // overwritten in step 4) and the kept ones appended to the exact list.
    const int nrobot = static_cast<int>(data.robot_pairs.size());
    for (const int r : data.rp_dynamic)  // a segment of several links: its sphere of this call
      data.rp_rsum[static_cast<std::size_t>(r)] = data.bound_radius[static_cast<std::size_t>(data.rp_a[r])] +
                                                  data.bound_radius[static_cast<std::size_t>(data.rp_b[r])];
    if (data.kernel == SweepKernel::kAvx2)
      detail::boundGapsAvx2(data.bound_center4_B.data(), data.rp_a.data(), data.rp_b.data(), data.rp_rsum.data(),
                            nrobot, data.rp_gap.data());
    else
      detail::boundGapsScalar(data.bound_center4_B.data(), data.rp_a.data(), data.rp_b.data(), data.rp_rsum.data(),
                              nrobot, data.rp_gap.data());
    int nexact = 0;
    double pruned_floor = kInf;
    const double prune_distance = options.prune_distance;
    for (int r = 0; r < nrobot; ++r) {
      const int i = data.robot_pairs[static_cast<std::size_t>(r)];
      double gap = data.rp_gap[static_cast<std::size_t>(r)];
      // A bound carried from an earlier sweep may be the better one (the tight model's far pairs).
      const double carried = data.pair_lower[static_cast<std::size_t>(i)] -
                             data.seg_odometer[static_cast<std::size_t>(data.rp_a[static_cast<std::size_t>(r)])] -
                             data.seg_odometer[static_cast<std::size_t>(data.rp_b[static_cast<std::size_t>(r)])] -
                             kCarryMargin;
      gap = carried > gap ? carried : gap;  // a NaN gap stays NaN
      PairDistance& out = data.pairs[static_cast<std::size_t>(i)];
      out.active = true;
      out.exact = false;
      out.has_row = false;
      out.distance = gap;
      const bool keep = !(gap > prune_distance);  // NaN: kept (computed, so the NaN shows)
      data.exact_pairs[static_cast<std::size_t>(nexact)] = i;
      nexact += keep ? 1 : 0;
      pruned_floor = std::min(pruned_floor, keep ? kInf : gap);
    }
    data.num_pruned_pairs = nrobot - nexact;
    sw.exact_pairs = data.exact_pairs.data();
    sw.nexact = nexact;
    sw.pruned_floor = pruned_floor;
  }
  data.num_exact_pairs = sw.nexact;
  data.pruned_floor = sw.pruned_floor;
  data.last_pruned = sw.prune;
}

/// Step 3: the core closest points of the exact pairs' primitive pairs, in one tight loop over a flat
/// list (independent iterations: the long sqrt / division latency chains of neighbouring pairs
/// overlap; the AVX2 kernel runs four at a time).
void coreDistancesOfExactPairs(const Model& model, const KinematicsData& kin, DistanceData& data,
                               const DistanceOptions& options, Sweep& sw) {
  constexpr double kInf = std::numeric_limits<double>::infinity();
  sw.list_a = data.pp_a.data();
  sw.list_b = data.pp_b.data();
  sw.nlist = static_cast<int>(data.pp_a.size());
  sw.listed = sw.prune || data.any_pp_unchecked;
  if (sw.listed) {
    // A pair of the tight model keeps only the primitives of each segment whose bounding sphere lies
    // within prune_distance of the other segment's: the others' primitive pairs are farther than it
    // (their smallest sphere gap, list_floor, is a lower bound of their distance). A torso of 48
    // pieces against a finger keeps the few pieces near the finger.
    const double prune_distance = options.prune_distance;
    int nlist = 0;
    const int nexact = sw.nexact;  // locals: the list writes below could alias sw's fields
    const int* exact_pairs = sw.exact_pairs;
    for (int e = 0; e < nexact; ++e) {
      const int i = exact_pairs[e];
      const int count = data.pp_begin[i + 1] - data.pp_begin[i];
      double floor = kInf;
      if (sw.prune && data.pair_has_piece[static_cast<std::size_t>(i)] && count > 4) {
        const SegmentPair& pair = model.pairs[i];
        const Segment& sa = model.segments[pair.a];
        const Segment& sb = model.segments[pair.b];
        // Only primitive pairs that can beat an upper bound of the pair's distance can win: one
        // primitive pair's exact distance (last call's winner), when it is below prune_distance.
        const double upper = upperBoundOfPair(model, kin, data, i, sa, sb, sa.link, sb.link, prune_distance);
        const double within = std::min(prune_distance, upper + kListMargin);
        // A primitive pair whose carried bound is beyond `within` is left out too (its bound kept as it
        // was): no core distance, no candidate.
        listNearPairs(data, i, sa, pair.a, sb, pair.b, within, floor, [&](int pa, int pb, int pp) {
          if (carriedBeyond(data, pp, pa, pb, within, floor)) return;
          data.list_a[nlist] = pa;
          data.list_b[nlist] = pb;
          data.list_pp[static_cast<std::size_t>(nlist++)] = pp;
        });
      } else {
        for (int k = data.pp_begin[i]; k < data.pp_begin[i + 1]; ++k) {
          if (data.any_pp_unchecked && data.pp_unchecked[static_cast<std::size_t>(k)]) continue;
          data.list_a[nlist] = data.pp_a[k];
          data.list_b[nlist] = data.pp_b[k];
          data.list_pp[static_cast<std::size_t>(nlist++)] = k;
        }
      }
      data.list_end[static_cast<std::size_t>(e)] = nlist;
      data.list_floor[static_cast<std::size_t>(e)] = floor;
    }
    sw.list_a = data.list_a.data();
    sw.list_b = data.list_b.data();
    sw.nlist = nlist;
  }
  const SegmentB* prim = data.prim_B.data();
  if (data.kernel == SweepKernel::kAvx2)
    detail::coreDistancesAvx2(prim, sw.list_a, sw.list_b, sw.nlist, data.pp_core.data(), data.pp_s.data(),
                              data.pp_t.data());
  else
    detail::coreDistancesScalar(prim, sw.list_a, sw.list_b, sw.nlist, data.pp_core.data(), data.pp_s.data(),
                                data.pp_t.data());
}

/// Step 4: every exactly computed robot pair, the best of its primitive pairs (the next entries of the
/// list), then normal, witness points and row. A pair of the tight model: its capsules' distance
/// first; above prune_distance it is skipped like the broad phase's (that distance its lower bound),
/// else computed on the pieces. The exact list is compacted in place to the pairs computed exactly.
void finishExactPairs(const Model& model, const KinematicsData& kin, DistanceData& data, const DistanceOptions& options,
                      Sweep& sw) {
  constexpr double kInf = std::numeric_limits<double>::infinity();
  const bool prune = sw.prune;
  const double* radius = data.prim_r.data();
  const int* list_a = sw.list_a;
  const int* list_b = sw.list_b;
  const int nexact = sw.nexact;  // locals: the writes below could alias sw's fields
  const int* exact_pairs = sw.exact_pairs;
  double pruned_floor = sw.pruned_floor;
  int nkept = 0;
  for (int e = 0, j = 0; e < nexact; ++e) {
    const int i = exact_pairs[e];
    const SegmentPair& pair = model.pairs[i];
    const int end =
        sw.listed ? data.list_end[static_cast<std::size_t>(e)] : j + data.pp_begin[i + 1] - data.pp_begin[i];
    assert(end > j ||
           (prune && data.pair_has_piece[static_cast<std::size_t>(i)]));  // every robot segment has a primitive
    if (data.pair_has_piece[static_cast<std::size_t>(i)]) {
      const int begin = j;
      double bound = prune ? data.list_floor[static_cast<std::size_t>(e)] : kInf;  // the primitives left out
      double listed = kInf;
      for (; j < end; ++j) listed = std::min(listed, data.pp_core[j] - radius[list_a[j]] - radius[list_b[j]]);
      // A pair left inexact, like the broad phase's: `lower` a lower bound of its distance.
      auto skip = [&](double lower) {
        PairDistance& out = data.pairs[static_cast<std::size_t>(i)];
        out.active = true;
        out.exact = false;
        out.has_row = false;
        out.distance = lower;
        pruned_floor = std::min(pruned_floor, lower);
        ++data.num_pruned_pairs;
        if (lower < kInf)  // carried to the next sweeps (broadPhase)
          data.pair_lower[static_cast<std::size_t>(i)] = lower + data.seg_odometer[static_cast<std::size_t>(pair.a)] +
                                                         data.seg_odometer[static_cast<std::size_t>(pair.b)];
      };
      if (prune && listed > options.prune_distance) {  // none listed within it (or none listed: +inf)
        skip(std::min(bound, listed));
        continue;
      }
      double floor;
      if (!finishPiecePair(model, kin, data, options, i, model.segments[pair.a].link, model.segments[pair.b].link,
                           prune ? options.prune_distance : kInf, floor, [&](auto&& f) {
                             for (int k = begin; k < end; ++k) {
                               const int pp = sw.listed ? data.list_pp[static_cast<std::size_t>(k)] : k;
                               const double carried = carriedBound(data, pp, list_a[k], list_b[k]);
                               f(list_a[k], list_b[k], data.pp_core[k] - radius[list_a[k]] - radius[list_b[k]],
                                 data.pp_core[k], data.pp_s[k], data.pp_t[k], pp, carried);
                             }
                           })) {  // its pieces are all farther than prune_distance: skipped
        skip(std::min(floor, bound));
        continue;
      }
      if (prune) data.exact_pairs[static_cast<std::size_t>(nkept)] = i;
      ++nkept;
      continue;
    }
    if (prune) data.exact_pairs[static_cast<std::size_t>(nkept)] = i;
    ++nkept;
    int j_best = j;
    double best = data.pp_core[j] - radius[list_a[j]] - radius[list_b[j]];
    for (++j; j < end; ++j) {
      const double d = data.pp_core[j] - radius[list_a[j]] - radius[list_b[j]];
      if (d < best) {
        best = d;
        j_best = j;
      }
    }
    finishPair(model, kin, data, options, i, model.segments[pair.a].link, model.segments[pair.b].link, best,
               data.pp_core[j_best], list_a[j_best], list_b[j_best], data.pp_s[j_best], data.pp_t[j_best]);
  }
  sw.nexact = nkept;  // without the tight model's skipped pairs (exact_pairs compacted in place)
  sw.pruned_floor = pruned_floor;
  data.num_exact_pairs = nkept;
  data.pruned_floor = pruned_floor;
}

/// Step 5: the pairs with a body-schema slot, usually all disabled; each computed directly when
/// active. Returns whether a slot is enabled.
bool computeSlotPairs(const Model& model, const KinematicsData& kin, const BodySchemaSlots& slots, DistanceData& data,
                      const DistanceOptions& options) {
  bool any_slot = false;
  for (const BodySchemaSlot& slot : slots) any_slot = any_slot || slot.enabled;
  data.any_slot_enabled = any_slot;
  // Nothing to do when every slot is disabled and every slot pair is already inactive (the usual
  // cycle: a robot holds nothing; a model has 4 slots x its segments of such pairs).
  if (!any_slot && data.slot_pairs_inactive) return false;
  for (const int i : data.slot_pairs) {
    const SegmentPair& pair = model.pairs[i];
    const Segment& sa = model.segments[pair.a];
    const Segment& sb = model.segments[pair.b];
    int link_a = sa.link, link_b = sb.link;
    if (!any_slot || !slotPairActive(model, data, slots, pair, link_a, link_b)) {
      PairDistance& out = data.pairs[i];
      out.active = false;
      out.has_row = false;
      out.distance = std::numeric_limits<double>::infinity();
      continue;
    }
    computeSegmentPair(model, kin, data, options, i, sa, sb, link_a, link_b);
  }
  data.slot_pairs_inactive = !any_slot;
  return any_slot;
}

}  // namespace

void computeSegmentDistances(const Model& model, const KinematicsData& kin, const BodySchemaSlots& slots,
                             DistanceData& data, const DistanceOptions& options) {
  assert(data.pairs.size() == model.pairs.size());
  assert(data.prim_B.size() == model.primitives.size());
  Sweep sw;
  sw.prune = options.prune_distance < std::numeric_limits<double>::infinity();

  // 1. Every enabled primitive's core into B, once (a primitive takes part in several pairs); with
  //    the broad phase, every robot segment's bounding sphere centre too; how far each moved.
  const int nseg = static_cast<int>(model.segments.size());
  nextSearchCall(data);
  for (int s = 0; s < nseg; ++s) placeSegment(model, kin, slots, data, s, sw.prune);
  // 2.-4. The robot pairs: broad phase, core distances, then each kept pair exactly.
  broadPhase(data, options, sw);
  coreDistancesOfExactPairs(model, kin, data, options, sw);
  finishExactPairs(model, kin, data, options, sw);
  // 5. The body-schema slots' pairs.
  const bool any_slot = computeSlotPairs(model, kin, slots, data, options);

  // 6. The closest active pair (the lowest index among equals): over the exact pairs; then a skipped
  //    pair whose lower bound is below that distance is computed exactly, so `closest` is the true one.
  data.closest = -1;
  if (!options.find_closest) return;
  ClosestPair closest;
  for (int e = 0; e < sw.nexact; ++e) closest.offer(data.pairs[sw.exact_pairs[e]].distance, sw.exact_pairs[e]);
  if (any_slot)
    for (const int i : data.slot_pairs)
      if (data.pairs[i].active) closest.offer(data.pairs[i].distance, i);
  refineClosest(model, kin, data, options, data.robot_pairs, closest);
  data.closest = closest.pair;
}

void computeListedPairDistances(const Model& model, const KinematicsData& kin, const BodySchemaSlots& slots,
                                DistanceData& data, const int* pairs, int count, double give_up,
                                const PairListing* listing) {
  assert(data.pairs.size() == model.pairs.size());
  // Each segment of the listed pairs into B once: a stamp per segment marks this call's.
  if (++data.segment_stamp_now == 0) {  // wrapped: no stale stamp may equal the new one
    std::fill(data.segment_stamp.begin(), data.segment_stamp.end(), 0U);
    data.segment_stamp_now = 1;
  }
  const std::uint32_t now = data.segment_stamp_now;
  // Lower bounds are carried from earlier calls on `data` (the guard's predictions of one cycle differ
  // by a fraction of a step): a primitive pair proven far then is skipped without a search.
  nextSearchCall(data);
  DistanceOptions no_rows;
  no_rows.row_threshold = -std::numeric_limits<double>::infinity();
  for (int k = 0; k < count; ++k) {
    const int i = pairs[k];
    const SegmentPair& pair = model.pairs[static_cast<std::size_t>(i)];
    const Segment& sa = model.segments[pair.a];
    const Segment& sb = model.segments[pair.b];
    int link_a = sa.link, link_b = sb.link;
    if ((sa.body_schema_slot || sb.body_schema_slot) && !slotPairActive(model, data, slots, pair, link_a, link_b)) {
      PairDistance& out = data.pairs[static_cast<std::size_t>(i)];
      out.active = false;
      out.has_row = false;
      out.distance = std::numeric_limits<double>::infinity();
      continue;
    }
    for (const int s : {pair.a, pair.b}) {
      if (data.segment_stamp[static_cast<std::size_t>(s)] == now) continue;
      data.segment_stamp[static_cast<std::size_t>(s)] = now;
      placeSegment(model, kin, slots, data, s, true);  // with the bounding sphere (give_up's filter)
    }
    computeSegmentPair(model, kin, data, no_rows, i, sa, sb, link_a, link_b, give_up, /*bounds_fresh=*/true,
                       /*carry=*/true, listing);
  }
}

PairListing::PairListing(const Model& model)
    : count(model.pairs.size(), -1), floor(model.pairs.size(), std::numeric_limits<double>::infinity()) {
  std::size_t total = 0;  // every robot pair's primitive pairs (DistanceData::pp_a's size)
  for (const SegmentPair& p : model.pairs) {
    const Segment& sa = model.segments[p.a];
    const Segment& sb = model.segments[p.b];
    if (!sa.body_schema_slot && !sb.body_schema_slot)
      total += static_cast<std::size_t>(sa.num_primitives) * static_cast<std::size_t>(sb.num_primitives);
  }
  pa.assign(total, 0);
  pb.assign(total, 0);
  pp.assign(total, 0);
}

void listPairsNear(const Model& model, DistanceData& now, const int* pairs, int count, double give_up,
                   const double* reach, PairListing& out) {
  for (int k = 0; k < count; ++k) {
    const int i = pairs[k];
    const SegmentPair& pair = model.pairs[static_cast<std::size_t>(i)];
    const Segment& sa = model.segments[pair.a];
    const Segment& sb = model.segments[pair.b];
    int& n = out.count[static_cast<std::size_t>(i)];
    n = -1;
    // The pairs computeSegmentPair would list itself (with pieces, of robot segments, more than 4).
    if (sa.body_schema_slot || sb.body_schema_slot || !now.pair_has_piece[static_cast<std::size_t>(i)] ||
        sa.num_primitives * sb.num_primitives <= 4 || !(reach[k] >= 0.0))
      continue;
    const int first = now.pp_begin[static_cast<std::size_t>(i)];
    double left_out = std::numeric_limits<double>::infinity();
    n = 0;
    listNearPairs(now, i, sa, pair.a, sb, pair.b, give_up + reach[k], left_out, [&](int a, int b, int p) {
      const std::size_t at = static_cast<std::size_t>(first + n++);
      out.pa[at] = a;
      out.pb[at] = b;
      out.pp[at] = p;
    });
    // A primitive pair left out was farther than give_up + reach: it still is farther than give_up.
    out.floor[static_cast<std::size_t>(i)] = left_out - reach[k];
  }
}

SweepKernel fastestSweepKernel() { return detail::avx2Available() ? SweepKernel::kAvx2 : SweepKernel::kScalar; }

void refinePairDistance(const Model& model, const KinematicsData& kin, DistanceData& data, int pair,
                        const DistanceOptions& options) {
  if (pair < 0 || pair >= static_cast<int>(data.pairs.size()) || data.pairs[pair].exact) return;
  const SegmentPair& p = model.pairs[pair];
  const Segment& sa = model.segments[p.a];
  const Segment& sb = model.segments[p.b];
  // Skipped by the broad phase: the bounding spheres of that call are in place, and its primitives
  // measured (their carried bounds hold for these poses).
  computeSegmentPair(model, kin, data, options, pair, sa, sb, sa.link, sb.link, std::numeric_limits<double>::infinity(),
                     /*bounds_fresh=*/data.last_pruned, /*carry=*/data.last_pruned);
}

bool attachBodySchemaSegment(const Model& model, DistanceData& data, int slot, int link, const Eigen::Vector3d& a_L,
                             const Eigen::Vector3d& b_L, double radius, std::uint64_t ignore_mask) {
  if (slot < 0 || slot >= kBodySchemaSlots) return false;
  if (link < 0 || link >= static_cast<int>(model.links.size())) return false;
  if (!(radius > 0.0) || !std::isfinite(radius) || !a_L.allFinite() || !b_L.allFinite()) return false;
  BodySchemaSlot& s = data.slots[slot];
  s.enabled = true;
  s.link = link;
  s.a_L = a_L;
  s.b_L = b_L;
  s.radius = radius;
  s.ignore_mask = ignore_mask;
  return true;
}

BodySchemaCheck checkBodySchemaSegment(const Model& model, int link, const Eigen::Vector3d& a_L,
                                       const Eigen::Vector3d& b_L, double radius, bool virtual_segment,
                                       const BodySchemaLimits& limits) {
  BodySchemaCheck c;
  auto fail = [&c](BodySchemaFault f, double value, double limit, const char* key) {
    c.fault = f;
    c.value = value;
    c.limit = limit;
    c.key = key;
    return c;
  };
  if (link < 0 || link >= static_cast<int>(model.links.size()))
    return fail(BodySchemaFault::kUnknownLink, static_cast<double>(link), 0.0, "");
  if (!std::isfinite(radius)) return fail(BodySchemaFault::kNonFinite, radius, 0.0, "");
  for (int i = 0; i < 3; ++i) {
    if (!std::isfinite(a_L[i])) return fail(BodySchemaFault::kNonFinite, a_L[i], 0.0, "");
    if (!std::isfinite(b_L[i])) return fail(BodySchemaFault::kNonFinite, b_L[i], 0.0, "");
  }
  if (!(radius > 0.0)) return fail(BodySchemaFault::kRadiusNotPositive, radius, 0.0, "");
  if (radius > limits.max_radius)
    return fail(BodySchemaFault::kRadiusTooLarge, radius, limits.max_radius, "max_radius");
  const double length = (b_L - a_L).norm();
  const double max_length = virtual_segment ? limits.max_virtual_length : limits.max_length;
  if (length > max_length)
    return fail(BodySchemaFault::kTooLong, length, max_length, virtual_segment ? "max_virtual_length" : "max_length");
  const double reach = std::max(a_L.norm(), b_L.norm());
  const double max_reach = virtual_segment ? limits.max_virtual_reach : limits.max_reach;
  if (reach > max_reach)
    return fail(BodySchemaFault::kTooFar, reach, max_reach, virtual_segment ? "max_virtual_reach" : "max_reach");
  return c;
}

const char* describe(BodySchemaFault fault) {
  switch (fault) {
    case BodySchemaFault::kNone: return "accepted";
    case BodySchemaFault::kUnknownLink: return "unknown parent link";
    case BodySchemaFault::kNonFinite: return "non-finite radius or endpoint";
    case BodySchemaFault::kRadiusNotPositive: return "radius not positive";
    case BodySchemaFault::kRadiusTooLarge: return "radius above the limit";
    case BodySchemaFault::kTooLong: return "length |point_b - point_a| above the limit";
    case BodySchemaFault::kTooFar: return "endpoint farther from the parent link origin than the limit";
  }
  return "unknown fault";
}

bool detachBodySchemaSegment(DistanceData& data, int slot) {
  if (slot < 0 || slot >= kBodySchemaSlots) return false;
  data.slots[slot].enabled = false;
  return true;
}

}  // namespace reflex::control
