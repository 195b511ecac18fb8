// Scene channels (scene.hpp): frame transforms, scene entities and status as foxglove JSON.
#include "reflex/view/scene.hpp"

#include <reflex/control/geometry.hpp>
#include <reflex/control/urdf_loader.hpp>

#include <Eigen/Geometry>

#include <algorithm>
#include <array>
#include <cmath>
#include <utility>

namespace reflex::view {
namespace {

using nlohmann::json;

json stampJson(std::int64_t stamp_ns) {
  // foxglove `time`: sec >= 0, nsec in [0, 1e9). A negative stamp (never from the bus) becomes 0.
  const std::int64_t ns = std::max<std::int64_t>(stamp_ns, 0);
  return json{{"sec", ns / 1000000000}, {"nsec", ns % 1000000000}};
}

json vec3Json(const Eigen::Vector3d& v) { return json{{"x", v.x()}, {"y", v.y()}, {"z", v.z()}}; }

json quatJson(const Eigen::Quaterniond& q) { return json{{"x", q.x()}, {"y", q.y()}, {"z", q.z()}, {"w", q.w()}}; }

json poseJson(const Eigen::Vector3d& p, const Eigen::Quaterniond& q) {
  return json{{"position", vec3Json(p)}, {"orientation", quatJson(q)}};
}

json colourJson(const Rgba& c) { return json{{"r", c.r}, {"g", c.g}, {"b", c.b}, {"a", c.a}}; }

json sphereJson(const Eigen::Vector3d& centre, double diameter, const Rgba& c) {
  return json{{"pose", poseJson(centre, Eigen::Quaterniond::Identity())},
              {"size", vec3Json(Eigen::Vector3d::Constant(diameter))},
              {"color", colourJson(c)}};
}

json textJson(const Eigen::Vector3d& p, const std::string& text, const Rgba& c) {
  return json{{"pose", poseJson(p, Eigen::Quaterniond::Identity())},
              {"billboard", true},
              {"font_size", 14.0},
              {"scale_invariant", true},
              {"color", colourJson(c)},
              {"text", text}};
}

/// An entity in the root frame with every primitive list foxglove.SceneEntity requires, empty (the
/// caller fills the ones it draws).
json entityJson(const SceneModel& scene, std::int64_t stamp_ns, const std::string& id) {
  return json{{"timestamp", stampJson(stamp_ns)},
              {"frame_id", scene.root_frame},
              {"id", id},
              {"lifetime", json{{"sec", 0}, {"nsec", 0}}},
              {"frame_locked", false},
              {"metadata", json::array()},
              {"arrows", json::array()},
              {"cubes", json::array()},
              {"spheres", json::array()},
              {"cylinders", json::array()},
              {"lines", json::array()},
              {"triangles", json::array()},
              {"texts", json::array()},
              {"models", json::array()}};
}

json keyValue(const std::string& key, const std::string& value) { return json{{"key", key}, {"value", value}}; }

/// A capsule a_B -> b_B of `radius` (a sphere at a_B when `sphere`): one CylinderPrimitive along the
/// core and two SpherePrimitives at its ends (foxglove has no capsule).
void appendCapsule(json& entity, const Eigen::Vector3d& a_B, const Eigen::Vector3d& b_B, double radius, bool sphere,
                   const Rgba& colour) {
  const double diameter = 2.0 * radius;
  entity["spheres"].push_back(sphereJson(a_B, diameter, colour));
  if (sphere) return;
  entity["spheres"].push_back(sphereJson(b_B, diameter, colour));
  const Eigen::Vector3d axis_B = b_B - a_B;
  const Eigen::Quaterniond R_B_cyl = Eigen::Quaterniond::FromTwoVectors(Eigen::Vector3d::UnitZ(), axis_B);
  entity["cylinders"].push_back(json{{"pose", poseJson(0.5 * (a_B + b_B), R_B_cyl)},
                                     {"size", vec3Json(Eigen::Vector3d(diameter, diameter, axis_B.norm()))},
                                     {"bottom_scale", 1.0},
                                     {"top_scale", 1.0},
                                     {"color", colourJson(colour)}});
}

/// One collision segment: a cylinder and two spheres per capsule, a sphere per sphere primitive.
void appendSegmentEntity(const SceneModel& scene, const SceneData& data, int s, json& entity) {
  const control::Model& model = scene.model;
  const control::Segment& seg = model.segments[static_cast<std::size_t>(s)];
  const Rgba colour = data.segment_in_arm[static_cast<std::size_t>(s)]
                          ? zoneColour(data.segment_zone[static_cast<std::size_t>(s)])
                          : neutralColour();
  for (int k = 0; k < seg.num_primitives; ++k) {
    const control::Primitive& prim = model.primitives[static_cast<std::size_t>(seg.first_primitive + k)];
    const Eigen::Isometry3d& X_B_L = data.kin.X_B_L[static_cast<std::size_t>(control::linkOf(seg, prim))];
    appendCapsule(entity, X_B_L * prim.a_L, X_B_L * prim.b_L, prim.radius, prim.sphere, colour);
  }
  const std::string zone = data.segment_in_arm[static_cast<std::size_t>(s)]
                               ? zoneName(data.segment_zone[static_cast<std::size_t>(s)])
                               : "none";
  entity["metadata"].push_back(keyValue("segment", seg.name));
  entity["metadata"].push_back(keyValue("zone", zone));
}

bool finite(const Eigen::Vector3d& p) { return p.allFinite(); }

/// The joint's own motion for q (revolute: rotation about axis_J; prismatic: translation along it).
Eigen::Isometry3d jointMotion(const control::Link& link, double q) {
  Eigen::Isometry3d X = Eigen::Isometry3d::Identity();
  if (link.type == control::JointType::kRevolute) X.linear() = Eigen::AngleAxisd(q, link.axis_J).toRotationMatrix();
  if (link.type == control::JointType::kPrismatic) X.translation() = q * link.axis_J;
  return X;
}

}  // namespace

Rgba zoneColour(Zone zone) {
  switch (zone) {
    case Zone::kYellow: return {0.95, 0.85, 0.10, 0.85};
    case Zone::kOrange: return {1.00, 0.50, 0.05, 0.90};
    case Zone::kRed: return {0.90, 0.05, 0.05, 0.95};
    case Zone::kFree:
    default: return {0.20, 0.70, 0.35, 0.75};
  }
}

Rgba neutralColour() { return {0.60, 0.62, 0.66, 0.55}; }

std::vector<Rgba> objectColours(const std::vector<std::string>& names) {
  // cyan, violet, pink, mint, sand, sky: away from the zones (green, yellow, orange, red), the targets
  // (blue, magenta), the schema's tan and the page's white closest line.
  static const std::array<Rgba, 6> kPalette{Rgba{0.10, 0.80, 0.90, 0.9}, Rgba{0.62, 0.45, 1.00, 0.9},
                                            Rgba{1.00, 0.55, 0.75, 0.9}, Rgba{0.45, 1.00, 0.75, 0.9},
                                            Rgba{0.95, 0.85, 0.60, 0.9}, Rgba{0.55, 0.75, 1.00, 0.9}};
  std::vector<Rgba> colours;
  colours.reserve(names.size());
  std::array<bool, kPalette.size()> taken{};
  for (const std::string& name : names) {
    std::uint32_t h = 2166136261u;  // FNV-1a: the same name, the same colour, on every machine
    for (const char ch : name) h = (h ^ static_cast<unsigned char>(ch)) * 16777619u;
    std::size_t k = h % kPalette.size();
    for (std::size_t tries = 0; tries < kPalette.size() && taken[k]; ++tries) k = (k + 1) % kPalette.size();
    taken[k] = true;  // all taken (more than 6 objects): shared from here on
    colours.push_back(kPalette[k]);
  }
  return colours;
}

const char* zoneName(Zone zone) {
  switch (zone) {
    case Zone::kYellow: return "yellow";
    case Zone::kOrange: return "orange";
    case Zone::kRed: return "red";
    case Zone::kFree:
    default: return "free";
  }
}

SceneModel makeSceneModel(control::Model model, const control::ControllerConfig& config) {
  const control::ControllerModel cm = control::makeControllerModel(model, config);
  SceneModel scene;
  for (std::size_t i = 0; i < 2; ++i) {
    scene.arm_names[i] = cm.arms[i].name.empty() ? scene.arm_names[i] : cm.arms[i].name;
    scene.arm_segments[i] = cm.arms[i].segment_mask;
  }
  scene.d_a = cm.params.d_a;
  scene.d_b = cm.params.d_b;
  scene.d_r = cm.params.d_r;
  scene.root_frame = model.links.empty() ? std::string("world") : model.links.front().name;
  scene.model = std::move(model);
  return scene;
}

SceneModel loadSceneModel(const std::string& urdf, const std::string& collision, const std::string& controller) {
  const control::CollisionConfig cc = control::loadCollisionConfigFor(urdf, collision);
  control::Model model = control::loadModel(urdf, cc);
  // The controller's rule (control::loadControllerConfigFor): --controller, else beside the URDF.
  const control::ControllerConfig config = control::loadControllerConfigFor(urdf, controller);
  SceneModel scene = makeSceneModel(std::move(model), config);
  scene.controller_note = control::describeControllerConfig(config, urdf);
  return scene;
}

SceneData::SceneData(const SceneModel& scene)
    : kin(scene.model),
      dist(scene.model),
      segment_zone(scene.model.segments.size(), Zone::kFree),
      segment_in_arm(scene.model.segments.size(), false) {}

int jointPositionsToQ(const SceneModel& scene, const std::vector<std::string>& names,
                      const std::vector<double>& positions, Eigen::VectorXd& q, int* unknown, int* rejected) {
  const control::Model& model = scene.model;
  if (q.size() != model.nq) q = Eigen::VectorXd::Zero(model.nq);
  int set = 0, not_known = 0, bad = 0;
  const std::size_t n = std::min(names.size(), positions.size());
  not_known += static_cast<int>(std::max(names.size(), positions.size()) - n);
  for (std::size_t i = 0; i < n; ++i) {
    const int k = model.qIndex(names[i]);
    if (k < 0) {
      ++not_known;
    } else if (!std::isfinite(positions[i])) {
      ++bad;
    } else {
      q[k] = positions[i];
      ++set;
    }
  }
  if (unknown) *unknown = not_known;
  if (rejected) *rejected = bad;
  return set;
}

bool updateScene(const SceneModel& scene, SceneData& data, const SceneInput& input) {
  const control::Model& model = scene.model;
  if (!control::computeForwardKinematics(model, data.kin, input.q)) return false;
  control::DistanceOptions options;
  options.row_threshold = -std::numeric_limits<double>::infinity();  // no avoidance rows: drawing only
  control::computeSegmentDistances(model, data.kin, data.dist, options);

  std::fill(data.segment_zone.begin(), data.segment_zone.end(), Zone::kFree);
  std::fill(data.segment_in_arm.begin(), data.segment_in_arm.end(), false);
  auto colour = [&](int s, Zone z) {
    if (s < 0 || s >= static_cast<int>(model.segments.size())) return;
    const auto i = static_cast<std::size_t>(s);
    if (!data.segment_in_arm[i] || static_cast<int>(z) > static_cast<int>(data.segment_zone[i]))
      data.segment_zone[i] = z;
    data.segment_in_arm[i] = true;
  };
  for (std::size_t arm = 0; arm < 2; ++arm) {
    data.closest_pair[arm] = -1;
    const ArmState& st = input.arms[arm];
    if (!st.valid) continue;
    for (int s = 0; s < model.num_robot_segments && s < 64; ++s)
      if (scene.arm_segments[arm] & (std::uint64_t{1} << s)) colour(s, st.zone);
    const int a = model.segmentIndex(st.closest_a);
    const int b = model.segmentIndex(st.closest_b);
    if (a < 0 || b < 0) continue;
    colour(a, st.zone);
    colour(b, st.zone);
    const int lo = std::min(a, b), hi = std::max(a, b);
    for (std::size_t p = 0; p < model.pairs.size(); ++p)
      if (model.pairs[p].a == lo && model.pairs[p].b == hi && data.dist.pairs[p].active)
        data.closest_pair[arm] = static_cast<int>(p);
  }
  // The lines: the named pair's witness points, or for a body-schema slot (the view does not know the
  // controller's slot numbering) the nearest enabled schema segment of the input to the arm's segment.
  for (std::size_t arm = 0; arm < 2; ++arm) {
    data.closest_line[arm] = false;
    const int p = data.closest_pair[arm];
    if (p >= 0) {
      const control::PairDistance& pd = data.dist.pairs[static_cast<std::size_t>(p)];
      data.closest_a_B[arm] = pd.p_B_a;
      data.closest_b_B[arm] = pd.p_B_b;
      data.closest_line[arm] = finite(pd.p_B_a) && finite(pd.p_B_b);
      continue;
    }
    const ArmState& st = input.arms[arm];
    const int a = model.segmentIndex(st.closest_a);
    const int b = model.segmentIndex(st.closest_b);
    if (!st.valid || a < 0 || a >= model.num_robot_segments || b < model.num_robot_segments) continue;
    const control::Segment& seg = model.segments[static_cast<std::size_t>(a)];
    double best = std::numeric_limits<double>::infinity();
    for (const SchemaSegmentState& sch : input.schema_segments) {
      const int link = model.linkIndex(sch.parent_link);
      if (!sch.enabled || link < 0 || !(sch.radius > 0.0) || !std::isfinite(sch.radius) || !finite(sch.a_L) ||
          !finite(sch.b_L))
        continue;
      const Eigen::Isometry3d& X_B_S = data.kin.X_B_L[static_cast<std::size_t>(link)];
      const Eigen::Vector3d s0 = X_B_S * sch.a_L, s1 = X_B_S * (sch.capsule ? sch.b_L : sch.a_L);
      for (int k = 0; k < seg.num_primitives; ++k) {
        const control::Primitive& prim = model.primitives[static_cast<std::size_t>(seg.first_primitive + k)];
        const Eigen::Isometry3d& X_B_A = data.kin.X_B_L[static_cast<std::size_t>(control::linkOf(seg, prim))];
        double d = 0.0;
        Eigen::Vector3d pa, pb, n;
        control::capsuleCapsuleDistance(X_B_A * prim.a_L, X_B_A * prim.b_L, prim.radius, s0, s1, sch.radius,
                                        Eigen::Vector3d::UnitZ(), d, pa, pb, n);
        if (d < best && finite(pa) && finite(pb)) {
          best = d;
          data.closest_a_B[arm] = pa;
          data.closest_b_B[arm] = pb;
          data.closest_line[arm] = true;
        }
      }
    }
  }
  return true;
}

std::string base64(const std::vector<std::uint8_t>& data) {
  static const char kAlphabet[] = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  out.reserve((data.size() + 2) / 3 * 4);
  std::size_t i = 0;
  for (; i + 3 <= data.size(); i += 3) {  // 3 bytes -> 4 characters of 6 bits
    const std::uint32_t v = (std::uint32_t{data[i]} << 16) | (std::uint32_t{data[i + 1]} << 8) | data[i + 2];
    for (int shift = 18; shift >= 0; shift -= 6) out.push_back(kAlphabet[(v >> shift) & 63U]);
  }
  const std::size_t rest = data.size() - i;  // 1 or 2 bytes: 2 or 3 characters and padding
  if (rest > 0) {
    const std::uint32_t v = (std::uint32_t{data[i]} << 16) | (rest == 2 ? std::uint32_t{data[i + 1]} << 8 : 0U);
    out.push_back(kAlphabet[(v >> 18) & 63U]);
    out.push_back(kAlphabet[(v >> 12) & 63U]);
    out.push_back(rest == 2 ? kAlphabet[(v >> 6) & 63U] : '=');
    out.push_back('=');
  }
  return out;
}

nlohmann::json buildCompressedImage(std::int64_t stamp_ns, const std::string& frame_id, const std::string& format,
                                    const std::vector<std::uint8_t>& data) {
  return json{{"timestamp", stampJson(stamp_ns)}, {"frame_id", frame_id}, {"data", base64(data)}, {"format", format}};
}

nlohmann::json buildFrameTransforms(const SceneModel& scene, const SceneData& data, const SceneInput& input) {
  const control::Model& model = scene.model;
  json transforms = json::array();
  for (std::size_t l = 1; l < model.links.size(); ++l) {
    const control::Link& link = model.links[l];
    if (link.parent < 0) continue;
    // parent -> child from the joint itself (X_P_J * motion(q)); composing these from the root gives
    // X_B_L of computeForwardKinematics (tested), so a viewer's tree matches the controller's.
    const double q = link.q_index >= 0 ? data.kin.q[link.q_index] : 0.0;
    const Eigen::Isometry3d X_P_L = link.X_P_J * jointMotion(link, q);
    transforms.push_back(json{{"timestamp", stampJson(input.stamp_ns)},
                              {"parent_frame_id", model.links[static_cast<std::size_t>(link.parent)].name},
                              {"child_frame_id", link.name},
                              {"translation", vec3Json(X_P_L.translation())},
                              {"rotation", quatJson(Eigen::Quaterniond(X_P_L.rotation()))}});
  }
  return json{{"transforms", std::move(transforms)}};
}

nlohmann::json buildSceneUpdate(const SceneModel& scene, const SceneData& data, const SceneInput& input) {
  const control::Model& model = scene.model;
  json entities = json::array();
  for (int s = 0; s < model.num_robot_segments; ++s) {
    json e = entityJson(scene, input.stamp_ns, "segment/" + model.segments[static_cast<std::size_t>(s)].name);
    appendSegmentEntity(scene, data, s, e);
    entities.push_back(std::move(e));
  }
  for (std::size_t arm = 0; arm < 2; ++arm) {
    json e = entityJson(scene, input.stamp_ns, "closest/" + scene.arm_names[arm]);
    if (data.closest_line[arm]) {
      {
        const Rgba c = zoneColour(input.arms[arm].zone);
        e["lines"].push_back(
            json{{"type", 2},  // LINE_LIST: one segment a -> b
                 {"pose", poseJson(Eigen::Vector3d::Zero(), Eigen::Quaterniond::Identity())},
                 {"thickness", 3.0},
                 {"scale_invariant", true},
                 {"points", json::array({vec3Json(data.closest_a_B[arm]), vec3Json(data.closest_b_B[arm])})},
                 {"color", colourJson({c.r, c.g, c.b, 1.0})},
                 {"colors", json::array()},
                 {"indices", json::array()}});
        e["metadata"].push_back(keyValue("pair", input.arms[arm].closest_a + "," + input.arms[arm].closest_b));
      }
    }
    entities.push_back(std::move(e));
  }
  const std::array<Rgba, 2> target_colour{Rgba{0.15, 0.45, 1.0, 1.0}, Rgba{0.85, 0.20, 0.85, 1.0}};
  for (std::size_t arm = 0; arm < 2; ++arm) {
    json e = entityJson(scene, input.stamp_ns, "target/" + scene.arm_names[arm]);
    const HandTargetState& t = input.targets[arm];
    if (t.given && finite(t.p_B)) {
      e["spheres"].push_back(sphereJson(t.p_B, 0.04, target_colour[arm]));
      e["texts"].push_back(textJson(t.p_B + Eigen::Vector3d(0, 0, 0.04),
                                    scene.arm_names[arm] + " target" + (t.object.empty() ? "" : ": " + t.object),
                                    target_colour[arm]));
    }
    entities.push_back(std::move(e));
  }
  json objects = entityJson(scene, input.stamp_ns, "objects");
  std::vector<std::string> object_names;
  for (const ObjectState& o : input.objects)
    if (finite(o.p_B)) object_names.push_back(o.name.empty() ? "?" : o.name);
  const std::vector<Rgba> object_colours = objectColours(object_names);
  std::size_t k = 0;
  for (const ObjectState& o : input.objects) {
    if (!finite(o.p_B)) continue;
    const Rgba& c = object_colours[k];
    objects["spheres"].push_back(sphereJson(o.p_B, 0.06, c));
    objects["texts"].push_back(textJson(o.p_B + Eigen::Vector3d(0, 0, 0.05), object_names[k], {c.r, c.g, c.b, 1.0}));
    ++k;
  }
  entities.push_back(std::move(objects));
  for (const SchemaSegmentState& b : input.schema_segments) {
    const int link = model.linkIndex(b.parent_link);
    if (!b.enabled || link < 0 || !(b.radius > 0.0) || !std::isfinite(b.radius) || !finite(b.a_L) || !finite(b.b_L))
      continue;
    json e = entityJson(scene, input.stamp_ns, "schema/" + b.name);
    const Eigen::Isometry3d& X_B_L = data.kin.X_B_L[static_cast<std::size_t>(link)];
    const Eigen::Vector3d a_B = X_B_L * b.a_L, b_B = X_B_L * b.b_L;
    const Rgba c = b.virtual_segment ? Rgba{0.45, 0.75, 1.0, 0.30} : Rgba{0.80, 0.60, 0.35, 0.85};
    appendCapsule(e, a_B, b_B, b.radius, !b.capsule || !((b_B - a_B).norm() > 0.0), c);
    e["metadata"].push_back(keyValue("body_schema", b.virtual_segment ? "virtual" : "physical"));
    e["metadata"].push_back(keyValue("parent_link", b.parent_link));
    entities.push_back(std::move(e));
  }
  // Delete-all first (stamped 1 ns before the entities: only older ones go), so that an entity not in
  // this update (a detached body-schema segment) disappears in every viewer.
  json deletions = json::array({json{{"timestamp", stampJson(input.stamp_ns - 1)}, {"type", 1}, {"id", ""}}});
  return json{{"deletions", std::move(deletions)}, {"entities", std::move(entities)}};
}

nlohmann::json buildViewStatus(const SceneModel& scene, const SceneInput& input, const std::string& protection) {
  json arms = json::array();
  for (std::size_t arm = 0; arm < 2; ++arm) {
    const ArmState& a = input.arms[arm];
    const HandTargetState& t = input.targets[arm];
    // JSON has no Inf/NaN: a distance that is not finite (no pair in range, no status yet) is null.
    arms.push_back(json{{"name", scene.arm_names[arm]},
                        {"valid", a.valid},
                        {"distance", std::isfinite(a.distance) ? json(a.distance) : json(nullptr)},
                        {"blend_f", std::isfinite(a.blend_f) ? json(a.blend_f) : json(nullptr)},
                        {"zone", zoneName(a.zone)},
                        {"estop_latched", a.estop_latched},
                        {"closest_a", a.closest_a},
                        {"closest_b", a.closest_b},
                        {"target_given", t.given},
                        {"target", t.given && finite(t.p_B) ? vec3Json(t.p_B) : json(nullptr)},
                        {"target_object", t.object}});
  }
  return json{{"timestamp", stampJson(input.stamp_ns)},
              {"d_a", scene.d_a},
              {"d_b", scene.d_b},
              {"d_r", scene.d_r},
              {"arms", std::move(arms)},
              {"objects", static_cast<int>(input.objects.size())},
              {"protection", protection}};
}

CollisionCounts countCollisionPrimitives(const SceneModel& scene) {
  CollisionCounts c;
  const control::Model& model = scene.model;
  for (int s = 0; s < model.num_robot_segments; ++s) {
    const control::Segment& seg = model.segments[static_cast<std::size_t>(s)];
    for (int k = 0; k < seg.num_primitives; ++k)
      (model.primitives[static_cast<std::size_t>(seg.first_primitive + k)].sphere ? c.spheres : c.capsules) += 1;
  }
  return c;
}

}  // namespace reflex::view
