#include "reflex/control/distance.hpp"

#include "reflex/control/geometry.hpp"

#include <cassert>
#include <cmath>

namespace reflex::control {

DistanceData::DistanceData(const Model& model)
    : pairs(model.pairs.size()),
      rows(Eigen::MatrixXd::Zero(static_cast<Eigen::Index>(model.pairs.size()), model.nq)),
      prim_a_W(model.primitives.size(), Eigen::Vector3d::Zero()),
      prim_b_W(model.primitives.size(), Eigen::Vector3d::Zero()) {
  for (std::size_t i = 0; i < model.pairs.size(); ++i) {
    pairs[i].seg_a = model.pairs[i].a;
    pairs[i].seg_b = model.pairs[i].b;
  }
}

namespace {


bool segmentEnabled(const Model& model, const DistanceData& data, int s) {
  const Segment& seg = model.segments[s];
  return !seg.body_schema_slot || data.slots[s - model.num_robot_segments].enabled;
}

int segmentLink(const Model& model, const DistanceData& data, int s) {
  const Segment& seg = model.segments[s];
  return seg.body_schema_slot ? data.slots[s - model.num_robot_segments].link : seg.link;
}

double primitiveRadius(const Model& model, const DistanceData& data, int s, int p) {
  const Segment& seg = model.segments[s];
  return seg.body_schema_slot ? data.slots[s - model.num_robot_segments].radius : model.primitives[p].radius;
}

}  // namespace

void computeSegmentDistances(const Model& model, const KinematicsData& kin, DistanceData& data,
                             const DistanceOptions& options) {
  assert(data.pairs.size() == model.pairs.size());
  // 1. Every enabled primitive's core into W, once.
  const int nseg = static_cast<int>(model.segments.size());
  for (int s = 0; s < nseg; ++s) {
    const Segment& seg = model.segments[s];
    if (seg.body_schema_slot) {
      const BodySchemaSlot& slot = data.slots[s - model.num_robot_segments];
      if (!slot.enabled) continue;
      const Eigen::Isometry3d& X = kin.X_W_L[slot.link];
      data.prim_a_W[seg.first_primitive] = X * slot.a_L;
      data.prim_b_W[seg.first_primitive] = X * slot.b_L;
      continue;
    }
    const Eigen::Isometry3d& X = kin.X_W_L[seg.link];
    for (int p = seg.first_primitive; p < seg.first_primitive + seg.num_primitives; ++p) {
      data.prim_a_W[p] = X * model.primitives[p].a_L;
      data.prim_b_W[p] = model.primitives[p].sphere ? data.prim_a_W[p] : Eigen::Vector3d(X * model.primitives[p].b_L);
    }
  }

  // 2. Every checked pair: the minimum over its primitive pairs.
  data.closest = -1;
  double closest_d = std::numeric_limits<double>::infinity();
  const int npairs = static_cast<int>(model.pairs.size());
  for (int i = 0; i < npairs; ++i) {
    const SegmentPair& pair = model.pairs[i];
    PairDistance& out = data.pairs[i];
    out.has_row = false;
    bool active = segmentEnabled(model, data, pair.a) && segmentEnabled(model, data, pair.b);
    if (active && model.segments[pair.b].body_schema_slot) {
      const BodySchemaSlot& slot = data.slots[pair.b - model.num_robot_segments];
      active = !((slot.ignore_mask >> pair.a) & 1U) && model.segments[pair.a].link != slot.link;
    }
    out.active = active;
    if (!active) {
      out.distance = std::numeric_limits<double>::infinity();
      continue;
    }
    const Segment& sa = model.segments[pair.a];
    const Segment& sb = model.segments[pair.b];
    const int link_a = segmentLink(model, data, pair.a);
    const int link_b = segmentLink(model, data, pair.b);
    Eigen::Vector3d fallback = kin.X_W_L[link_a].translation() - kin.X_W_L[link_b].translation();
    const double fn = fallback.norm();
    fallback = fn > kCoincidentEps ? Eigen::Vector3d(fallback / fn) : Eigen::Vector3d::UnitZ();

    double best = std::numeric_limits<double>::infinity();
    for (int pa = sa.first_primitive; pa < sa.first_primitive + sa.num_primitives; ++pa) {
      const double ra = primitiveRadius(model, data, pair.a, pa);
      for (int pb = sb.first_primitive; pb < sb.first_primitive + sb.num_primitives; ++pb) {
        const double rb = primitiveRadius(model, data, pair.b, pb);
        double d;
        Eigen::Vector3d p_a, p_b, n;
        const bool wd = capsuleCapsuleDistance(data.prim_a_W[pa], data.prim_b_W[pa], ra, data.prim_a_W[pb],
                                               data.prim_b_W[pb], rb, fallback, d, p_a, p_b, n);
        if (d < best) {
          best = d;
          out.distance = d;
          out.p_W_a = p_a;
          out.p_W_b = p_b;
          out.nhat_W = n;
          out.well_defined = wd;
        }
      }
    }
    if (out.distance < options.row_threshold) {
      computeDirectionalRow(model, kin, link_a, out.p_W_a, link_b, out.p_W_b, out.nhat_W, data.rows.row(i));
      out.has_row = true;
    }
    if (out.distance < closest_d) {
      closest_d = out.distance;
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
