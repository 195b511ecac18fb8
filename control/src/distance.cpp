#include "reflex/control/distance.hpp"

#include "reflex/control/geometry.hpp"

#include <cassert>
#include <cmath>

namespace reflex::control {

DistanceData::DistanceData(const Model& model)
    : pairs(model.pairs.size()),
      rows(Eigen::MatrixXd::Zero(static_cast<Eigen::Index>(model.pairs.size()), model.nq)),
      prim_W(model.primitives.size()),
      prim_r(model.primitives.size(), 0.0) {
  for (std::size_t i = 0; i < model.pairs.size(); ++i) {
    pairs[i].seg_a = model.pairs[i].a;
    pairs[i].seg_b = model.pairs[i].b;
  }
}

namespace {

/// Whether segment s takes part this cycle, and the link it moves with.
inline bool segmentState(const Model& model, const DistanceData& data, int s, int& link) {
  const Segment& seg = model.segments[s];
  if (!seg.body_schema_slot) {
    link = seg.link;
    return true;
  }
  const BodySchemaSlot& slot = data.slots[s - model.num_robot_segments];
  link = slot.link;
  return slot.enabled;
}

}  // namespace

void computeSegmentDistances(const Model& model, const KinematicsData& kin, DistanceData& data,
                             const DistanceOptions& options) {
  assert(data.pairs.size() == model.pairs.size());
  assert(data.prim_W.size() == model.primitives.size());
  constexpr double kInf = std::numeric_limits<double>::infinity();

  // 1. Every enabled primitive's core into W, once (a primitive takes part in several pairs).
  const int nseg = static_cast<int>(model.segments.size());
  for (int s = 0; s < nseg; ++s) {
    const Segment& seg = model.segments[s];
    if (seg.body_schema_slot) {
      const BodySchemaSlot& slot = data.slots[s - model.num_robot_segments];
      if (!slot.enabled) continue;
      const Eigen::Isometry3d& X = kin.X_W_L[slot.link];
      data.prim_W[seg.first_primitive].set(X * slot.a_L, X * slot.b_L);
      data.prim_r[seg.first_primitive] = slot.radius;
      continue;
    }
    const Eigen::Isometry3d& X = kin.X_W_L[seg.link];
    for (int p = seg.first_primitive; p < seg.first_primitive + seg.num_primitives; ++p) {
      const Primitive& prim = model.primitives[p];
      SegmentW& w = data.prim_W[p];
      w.start = X * prim.a_L;
      if (prim.sphere) {
        w.d.setZero();
        w.dd = 0.0;
        w.inv_dd = 0.0;
      } else {
        w.d = X.linear() * (prim.b_L - prim.a_L);
        w.dd = w.d.squaredNorm();
        w.inv_dd = w.dd > kPointSegmentSq ? 1.0 / w.dd : 0.0;
      }
      data.prim_r[p] = prim.radius;
    }
  }

  // 2. Every checked pair: the minimum over its primitive pairs (closest points of the cores first;
  //    normal and witness points only for the best primitive pair).
  data.closest = -1;
  double closest_d = kInf;
  const int npairs = static_cast<int>(model.pairs.size());
  for (int i = 0; i < npairs; ++i) {
    const SegmentPair& pair = model.pairs[i];
    PairDistance& out = data.pairs[i];
    out.has_row = false;
    int link_a = 0, link_b = 0;
    bool active = segmentState(model, data, pair.a, link_a) && segmentState(model, data, pair.b, link_b);
    if (active && model.segments[pair.b].body_schema_slot) {
      const BodySchemaSlot& slot = data.slots[pair.b - model.num_robot_segments];
      active = !((slot.ignore_mask >> pair.a) & 1U) && model.segments[pair.a].link != slot.link;
    }
    out.active = active;
    if (!active) {
      out.distance = kInf;
      continue;
    }
    const Segment& sa = model.segments[pair.a];
    const Segment& sb = model.segments[pair.b];
    double best = kInf, best_core = 0.0, best_s = 0.0, best_t = 0.0;
    int best_pa = sa.first_primitive, best_pb = sb.first_primitive;
    for (int pa = sa.first_primitive; pa < sa.first_primitive + sa.num_primitives; ++pa) {
      const SegmentW& A = data.prim_W[pa];
      const double ra = data.prim_r[pa];
      for (int pb = sb.first_primitive; pb < sb.first_primitive + sb.num_primitives; ++pb) {
        const SegmentW& B = data.prim_W[pb];
        const double rb = data.prim_r[pb];
        double s, t;
        closestParametersSegmentSegment(A, B, s, t);
        const double dx = (A.start.x() + s * A.d.x()) - (B.start.x() + t * B.d.x());
        const double dy = (A.start.y() + s * A.d.y()) - (B.start.y() + t * B.d.y());
        const double dz = (A.start.z() + s * A.d.z()) - (B.start.z() + t * B.d.z());
        const double core = std::sqrt(dx * dx + dy * dy + dz * dz);
        const double d = core - ra - rb;
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
    const SegmentW& A = data.prim_W[best_pa];
    const SegmentW& B = data.prim_W[best_pb];
    const Eigen::Vector3d best_ca = A.start + best_s * A.d;
    const Eigen::Vector3d best_cb = B.start + best_t * B.d;
    // Unit normal from b towards a; coincident cores: the direction between the link origins.
    Eigen::Vector3d n;
    out.well_defined = best_core > kCoincidentEps;
    if (out.well_defined) {
      n = (best_ca - best_cb) / best_core;
    } else {
      n = kin.X_W_L[link_a].translation() - kin.X_W_L[link_b].translation();
      const double norm = n.norm();
      n = norm > kCoincidentEps ? Eigen::Vector3d(n / norm) : Eigen::Vector3d::UnitZ();
    }
    out.distance = best;
    out.nhat_W = n;
    out.p_W_a = best_ca - data.prim_r[best_pa] * n;
    out.p_W_b = best_cb + data.prim_r[best_pb] * n;
    if (best < options.row_threshold) {
      computeDirectionalRow(model, kin, link_a, out.p_W_a, link_b, out.p_W_b, n, data.rows.row(i));
      out.has_row = true;
    }
    if (best < closest_d) {
      closest_d = best;
      data.closest = i;
    }
  }
}

bool attachBodySchemaSegment(const Model& model, DistanceData& data, int slot, int link,
                             const Eigen::Vector3d& a_L, const Eigen::Vector3d& b_L, double radius,
                             std::uint64_t ignore_mask) {
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

bool detachBodySchemaSegment(DistanceData& data, int slot) {
  if (slot < 0 || slot >= kBodySchemaSlots) return false;
  data.slots[slot].enabled = false;
  return true;
}

}  // namespace reflex::control
