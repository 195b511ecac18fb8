// reflex::scene (modules/view/include/reflex/view/scene.hpp) against independent answers:
//   - FrameTransforms: composing the JSON parent -> child transforms from the root (quaternions and
//     translations parsed back from the JSON text) equals computeForwardKinematics for every link, on
//     both shipped robots at 60 random configurations each (FK itself is checked against KDL in
//     control_kinematics_test);
//   - capsules: every cylinder's axis ends and every end sphere equal the distance module's core
//     segments (DistanceData::prim_B after computeSegmentDistances), diameters = 2 radius; counts equal
//     the model's primitives;
//   - the closest-pair line: its ends equal the witness points of the named pair recomputed here by
//     brute force over the two segments' primitive pairs with capsuleCapsuleDistance;
//   - colours: arm segments and the partner of the closest pair by the arm's zone, the rest neutral;
//   - JSON: every message checked key by key against its schema (every key a schema property with the
//     schema's type, oneOf consts, time bounds); the schemas name the foxglove fields of the published
//     definitions (written out again here);
//   - bad input: NaN joints, unknown joint names, NaN targets / objects, unknown pair names;
//   - vision objects: each its own colour (pairwise distinct within a scene, the same name the same
//     colour in another scene), its label the object's name in the sphere's colour.
#include "../control/test_support.hpp"

#include <reflex/control/geometry.hpp>
#include <reflex/control/urdf_loader.hpp>
#include <reflex/view/scene.hpp>

#include <gtest/gtest.h>

#include <Eigen/Geometry>

#include <cmath>
#include <map>
#include <random>
#include <set>

namespace reflex::view {
namespace {

using nlohmann::json;

using reflex::testing::robotPath;

SceneModel asimo() { return loadSceneModel(robotPath("asimo_like.urdf"), "", ""); }

Eigen::Vector3d vec(const json& j) {
  return {j.at("x").get<double>(), j.at("y").get<double>(), j.at("z").get<double>()};
}
Eigen::Quaterniond quat(const json& j) {
  return Eigen::Quaterniond(j.at("w").get<double>(), j.at("x").get<double>(), j.at("y").get<double>(),
                            j.at("z").get<double>());
}

/// Checks `v` against `schema` (the subset our schemas use); appends every violation to `errors`.
void validate(const json& v, const json& schema, const std::string& where, std::vector<std::string>& errors) {
  if (schema.contains("oneOf")) {
    bool any = false;
    for (const json& o : schema["oneOf"]) any |= o.at("const") == v;
    if (!any) errors.push_back(where + ": " + v.dump() + " matches no oneOf const");
    return;
  }
  std::set<std::string> types;
  if (schema.contains("type")) {
    if (schema["type"].is_array()) {
      for (const json& t : schema["type"]) types.insert(t.get<std::string>());
    } else {
      types.insert(schema["type"].get<std::string>());
    }
  }
  std::string t = v.is_null()             ? "null"
                  : v.is_boolean()        ? "boolean"
                  : v.is_number_integer() ? "integer"
                  : v.is_number()         ? "number"
                  : v.is_string()         ? "string"
                  : v.is_array()          ? "array"
                                          : "object";
  if (!types.empty() && !types.count(t) && !(t == "integer" && types.count("number"))) {
    errors.push_back(where + ": " + t + " where the schema says " + schema["type"].dump());
    return;
  }
  if (schema.contains("minimum") && v.is_number() && v.get<double>() < schema["minimum"].get<double>())
    errors.push_back(where + " below minimum");
  if (schema.contains("maximum") && v.is_number() && v.get<double>() > schema["maximum"].get<double>())
    errors.push_back(where + " above maximum");
  if (schema.contains("enum") && std::find(schema["enum"].begin(), schema["enum"].end(), v) == schema["enum"].end())
    errors.push_back(where + ": " + v.dump() + " not in enum");
  if (v.is_object() && schema.contains("properties")) {
    for (const auto& [k, x] : v.items()) {
      if (!schema["properties"].contains(k)) {
        errors.push_back(where + "." + k + ": not in the schema");
      } else {
        validate(x, schema["properties"][k], where + "." + k, errors);
      }
    }
  }
  if (v.is_array() && schema.contains("items"))
    for (std::size_t i = 0; i < v.size(); ++i)
      validate(v[i], schema["items"], where + "[" + std::to_string(i) + "]", errors);
}

std::set<std::string> keys(const json& properties) {
  std::set<std::string> k;
  for (const auto& [name, _] : properties.items()) k.insert(name);
  return k;
}

SceneInput inputAt(const SceneModel& scene, std::mt19937_64& rng) {
  SceneInput in;
  in.stamp_ns = 1'700'000'000'123'456'789;
  in.q = control::test::randomConfiguration(scene.model, rng);
  return in;
}

TEST(Scene, FrameTransformsComposeToForwardKinematicsOnBothRobots) {
  SceneModel small;
  small.model = control::loadModel(robotPath("small_humanoid.urdf"),
                                   control::loadCollisionConfig(robotPath("small_humanoid.collision.yaml")));
  small.root_frame = small.model.links.front().name;
  std::mt19937_64 rng(14);
  double worst_p = 0.0, worst_R = 0.0;
  for (const SceneModel* scene : {new SceneModel(asimo()), &small}) {
    SceneData data(*scene);
    const control::Model& model = scene->model;
    for (int trial = 0; trial < 60; ++trial) {
      const SceneInput in = inputAt(*scene, rng);
      ASSERT_TRUE(updateScene(*scene, data, in));
      // Parsed back from text: what a viewer receives.
      const json tf = json::parse(buildFrameTransforms(*scene, data, in).dump());
      ASSERT_EQ(tf["transforms"].size(), model.links.size() - 1);
      std::map<std::string, std::pair<std::string, Eigen::Isometry3d>> parent_of;
      for (const json& t : tf["transforms"]) {
        EXPECT_EQ(t["timestamp"]["sec"], 1'700'000'000);
        EXPECT_EQ(t["timestamp"]["nsec"], 123'456'789);
        Eigen::Isometry3d X = Eigen::Isometry3d::Identity();
        X.linear() = quat(t["rotation"]).normalized().toRotationMatrix();
        EXPECT_NEAR(quat(t["rotation"]).norm(), 1.0, 1e-12);
        X.translation() = vec(t["translation"]);
        ASSERT_TRUE(parent_of
                        .emplace(t["child_frame_id"].get<std::string>(),
                                 std::make_pair(t["parent_frame_id"].get<std::string>(), X))
                        .second)
            << "one transform per child";
      }
      control::KinematicsData fk(model);
      ASSERT_TRUE(control::computeForwardKinematics(model, fk, in.q));
      for (std::size_t l = 0; l < model.links.size(); ++l) {
        Eigen::Isometry3d X_B_L = Eigen::Isometry3d::Identity();
        std::string frame = model.links[l].name;
        for (int depth = 0; frame != scene->root_frame; ++depth) {
          ASSERT_LT(depth, 100) << "chain from " << model.links[l].name << " reaches the root";
          const auto& [parent, X_P_C] = parent_of.at(frame);
          X_B_L = X_P_C * X_B_L;
          frame = parent;
        }
        worst_p = std::max(worst_p, (X_B_L.translation() - fk.X_B_L[l].translation()).norm());
        worst_R = std::max(worst_R, (X_B_L.linear() - fk.X_B_L[l].linear()).norm());
      }
    }
    if (scene != &small) delete scene;
  }
  EXPECT_LT(worst_p, 1e-12);
  EXPECT_LT(worst_R, 1e-12);
  std::printf("composed transforms vs FK: max %.2e m, %.2e (rotation matrix)\n", worst_p, worst_R);
}

TEST(Scene, CapsulesAreTheDistanceModuleSegments) {
  const SceneModel scene = asimo();
  const control::Model& model = scene.model;
  SceneData data(scene);
  std::mt19937_64 rng(7);
  double worst = 0.0;
  for (int trial = 0; trial < 40; ++trial) {
    const SceneInput in = inputAt(scene, rng);
    ASSERT_TRUE(updateScene(scene, data, in));
    const json update = json::parse(buildSceneUpdate(scene, data, in).dump());
    control::KinematicsData kin(model);
    control::DistanceData ref(model);
    ASSERT_TRUE(control::computeForwardKinematics(model, kin, in.q));
    control::computeSegmentDistances(model, kin, ref);
    int capsules = 0, spheres = 0;
    for (int s = 0; s < model.num_robot_segments; ++s) {
      const control::Segment& seg = model.segments[static_cast<std::size_t>(s)];
      const json* entity = nullptr;
      for (const json& e : update["entities"])
        if (e["id"] == "segment/" + seg.name) entity = &e;
      ASSERT_NE(entity, nullptr) << seg.name;
      EXPECT_EQ((*entity)["frame_id"], "world");
      std::size_t cyl = 0, sph = 0;
      for (int k = 0; k < seg.num_primitives; ++k) {
        const int p = seg.first_primitive + k;
        const control::SegmentB& core = ref.prim_B[static_cast<std::size_t>(p)];
        const Eigen::Vector3d a = core.start, b = core.start + core.d;
        const double r = model.primitives[static_cast<std::size_t>(p)].radius;
        const json& sa = (*entity)["spheres"].at(sph++);
        worst = std::max(worst, (vec(sa["pose"]["position"]) - a).norm());
        EXPECT_NEAR(sa["size"]["x"].get<double>(), 2 * r, 1e-15);
        if (model.primitives[static_cast<std::size_t>(p)].sphere) {
          ++spheres;
          continue;
        }
        ++capsules;
        const json& sb = (*entity)["spheres"].at(sph++);
        worst = std::max(worst, (vec(sb["pose"]["position"]) - b).norm());
        const json& c = (*entity)["cylinders"].at(cyl++);
        const Eigen::Vector3d centre = vec(c["pose"]["position"]);
        const Eigen::Vector3d axis = quat(c["pose"]["orientation"]).normalized() * Eigen::Vector3d::UnitZ();
        const double length = c["size"]["z"].get<double>();
        worst = std::max(worst, (centre - 0.5 * length * axis - a).norm());
        worst = std::max(worst, (centre + 0.5 * length * axis - b).norm());
        EXPECT_NEAR(c["size"]["x"].get<double>(), 2 * r, 1e-15);
        EXPECT_NEAR(c["size"]["y"].get<double>(), 2 * r, 1e-15);
      }
      EXPECT_EQ((*entity)["cylinders"].size(), cyl) << seg.name;
      EXPECT_EQ((*entity)["spheres"].size(), sph) << seg.name;
    }
    const CollisionCounts counts = countCollisionPrimitives(scene);
    EXPECT_EQ(counts.capsules, capsules);
    EXPECT_EQ(counts.spheres, spheres);
    EXPECT_EQ(capsules, 17);
    EXPECT_EQ(spheres, 3);
  }
  EXPECT_LT(worst, 1e-12);
  std::printf("capsule ends vs distance module: max %.2e m\n", worst);
}

// When the controller names a body-schema slot as an arm's closest segment ("body_schema_0": the slot
// numbering is the controller's), the line goes from the arm's segment to the nearest enabled body-schema
// segment of the input (the grasped bar), witness points recomputed here by brute force; a disabled one
// is not used, and none enabled draws no line.
TEST(Scene, ClosestLineToABodySchemaSegment) {
  const SceneModel scene = asimo();
  const control::Model& model = scene.model;
  SceneData data(scene);
  std::mt19937_64 rng(5);
  SceneInput in = inputAt(scene, rng);
  in.arms[1].valid = true;
  in.arms[1].closest_a = "r_hand";
  in.arms[1].closest_b = "body_schema_0";
  in.arms[1].zone = Zone::kYellow;
  SchemaSegmentState bar;
  bar.name = "bar";
  bar.parent_link = "l_hand";
  bar.a_L = Eigen::Vector3d(-0.16, 0.0, -0.06);
  bar.b_L = Eigen::Vector3d(0.16, 0.0, -0.06);
  bar.radius = 0.015;
  SchemaSegmentState far = bar;  // disabled, and nearer the right hand: must not be used
  far.name = "old";
  far.parent_link = "r_hand";
  far.enabled = false;
  in.schema_segments = {far, bar};
  ASSERT_TRUE(updateScene(scene, data, in));
  control::KinematicsData kin(model);
  ASSERT_TRUE(control::computeForwardKinematics(model, kin, in.q));
  const int sa = model.segmentIndex("r_hand");
  const Eigen::Isometry3d& XA = kin.X_B_L[model.segments[sa].link];
  const Eigen::Isometry3d& XB = kin.X_B_L[model.linkIndex("l_hand")];
  double best = 1e9;
  Eigen::Vector3d pa = Eigen::Vector3d::Zero(), pb = Eigen::Vector3d::Zero();
  for (int i = 0; i < model.segments[sa].num_primitives; ++i) {
    const auto& A = model.primitives[static_cast<std::size_t>(model.segments[sa].first_primitive + i)];
    double d;
    Eigen::Vector3d a, b, n;
    control::capsuleCapsuleDistance(XA * A.a_L, XA * A.b_L, A.radius, XB * bar.a_L, XB * bar.b_L, bar.radius,
                                    Eigen::Vector3d::UnitZ(), d, a, b, n);
    if (d < best) {
      best = d;
      pa = a;
      pb = b;
    }
  }
  const json update = buildSceneUpdate(scene, data, in);
  std::map<std::string, json> by_id;
  for (const json& e : update["entities"]) by_id[e["id"].get<std::string>()] = e;
  const json& right = by_id.at("closest/right");
  ASSERT_EQ(right["lines"].size(), 1U);
  EXPECT_LT((vec(right["lines"][0]["points"][0]) - pa).norm() + (vec(right["lines"][0]["points"][1]) - pb).norm(),
            1e-12);
  in.schema_segments = {far};
  ASSERT_TRUE(updateScene(scene, data, in));
  by_id.clear();
  const json update_without = buildSceneUpdate(scene, data, in);
  for (const json& e : update_without["entities"]) by_id[e["id"].get<std::string>()] = e;
  EXPECT_TRUE(by_id.at("closest/right")["lines"].empty()) << "no enabled body-schema segment: no line";
}

TEST(Scene, ClosestPairLineAndZoneColours) {
  const SceneModel scene = asimo();
  const control::Model& model = scene.model;
  SceneData data(scene);
  std::mt19937_64 rng(3);
  SceneInput in = inputAt(scene, rng);
  in.arms[0].valid = true;
  in.arms[0].closest_a = "l_hand";
  in.arms[0].closest_b = "chest";
  in.arms[0].zone = Zone::kOrange;
  in.arms[1].valid = true;
  in.arms[1].closest_a = "r_forearm";
  in.arms[1].closest_b = "no_such_segment";
  in.arms[1].zone = Zone::kYellow;
  ASSERT_TRUE(updateScene(scene, data, in));
  const json update = buildSceneUpdate(scene, data, in);

  // Witness points of l_hand - chest by brute force over their primitive pairs.
  control::KinematicsData kin(model);
  ASSERT_TRUE(control::computeForwardKinematics(model, kin, in.q));
  const int sa = model.segmentIndex("l_hand"), sb = model.segmentIndex("chest");
  double best = 1e9;
  Eigen::Vector3d pa = Eigen::Vector3d::Zero(), pb = Eigen::Vector3d::Zero();
  for (int i = 0; i < model.segments[sa].num_primitives; ++i) {
    for (int j = 0; j < model.segments[sb].num_primitives; ++j) {
      const auto& A = model.primitives[static_cast<std::size_t>(model.segments[sa].first_primitive + i)];
      const auto& B = model.primitives[static_cast<std::size_t>(model.segments[sb].first_primitive + j)];
      const Eigen::Isometry3d& XA = kin.X_B_L[model.segments[sa].link];
      const Eigen::Isometry3d& XB = kin.X_B_L[model.segments[sb].link];
      double d;
      Eigen::Vector3d a, b, n;
      control::capsuleCapsuleDistance(XA * A.a_L, XA * A.b_L, A.radius, XB * B.a_L, XB * B.b_L, B.radius,
                                      Eigen::Vector3d::UnitZ(), d, a, b, n);
      if (d < best) {
        best = d;
        pa = a;
        pb = b;
      }
    }
  }
  std::map<std::string, json> by_id;
  for (const json& e : update["entities"]) by_id[e["id"].get<std::string>()] = e;
  const json& left = by_id.at("closest/left");
  ASSERT_EQ(left["lines"].size(), 1U);
  const json& line = left["lines"][0];
  EXPECT_EQ(line["type"], 2);
  ASSERT_EQ(line["points"].size(), 2U);
  // l_hand is the pair's second segment in the model (chest < l_hand): a line from the chest to the hand.
  const Eigen::Vector3d p0 = vec(line["points"][0]), p1 = vec(line["points"][1]);
  EXPECT_LT(std::min((p0 - pa).norm() + (p1 - pb).norm(), (p0 - pb).norm() + (p1 - pa).norm()), 1e-12);
  EXPECT_TRUE(by_id.at("closest/right")["lines"].empty()) << "an unknown segment name draws no line";

  auto colourOf = [&](const std::string& seg) {
    const json& c = by_id.at("segment/" + seg)["spheres"][0]["color"];
    return Rgba{c["r"], c["g"], c["b"], c["a"]};
  };
  auto same = [](Rgba a, Rgba b) { return a.r == b.r && a.g == b.g && a.b == b.b && a.a == b.a; };
  for (const char* s : {"l_upper_arm", "l_forearm", "l_hand"})
    EXPECT_TRUE(same(colourOf(s), zoneColour(Zone::kOrange))) << s;
  for (const char* s : {"r_upper_arm", "r_forearm", "r_hand"})
    EXPECT_TRUE(same(colourOf(s), zoneColour(Zone::kYellow))) << s;
  EXPECT_TRUE(same(colourOf("chest"), zoneColour(Zone::kOrange))) << "the partner of the left arm's closest pair";
  EXPECT_TRUE(same(colourOf("head"), neutralColour()));
  EXPECT_TRUE(same(colourOf("l_thigh"), neutralColour()));
  std::set<std::string> distinct;
  for (Zone z : {Zone::kFree, Zone::kYellow, Zone::kOrange, Zone::kRed}) {
    const Rgba c = zoneColour(z);
    distinct.insert(std::to_string(c.r) + std::to_string(c.g) + std::to_string(c.b));
  }
  EXPECT_EQ(distinct.size(), 4U) << "four distinct zone colours";
}

TEST(Scene, MessagesValidateAgainstTheirSchemasAndSchemasNameTheFoxgloveFields) {
  const SceneModel scene = asimo();
  SceneData data(scene);
  std::mt19937_64 rng(11);
  SceneInput in = inputAt(scene, rng);
  in.arms[0].valid = in.arms[1].valid = true;
  in.arms[0].closest_a = "l_hand";
  in.arms[0].closest_b = "r_hand";
  in.arms[0].distance = 0.02;
  in.arms[0].zone = Zone::kYellow;
  in.targets[0].given = true;
  in.targets[0].p_B = {0.3, 0.1, 1.0};
  in.targets[0].object = "red_cup";
  in.targets[1].given = true;
  in.targets[1].p_B = {std::nan(""), 0, 1};
  in.objects.push_back({"red_cup", {0.5, 0.1, 1.0}, 0.9});
  in.objects.push_back({"bad", {0.5, std::numeric_limits<double>::infinity(), 1.0}, 0.9});
  ASSERT_TRUE(updateScene(scene, data, in));
  std::vector<std::string> errors;
  const json tf = buildFrameTransforms(scene, data, in), su = buildSceneUpdate(scene, data, in),
             st = buildViewStatus(scene, in, "avoidance on, e-stop on");
  validate(tf, frameTransformsSchema(), "tf", errors);
  validate(su, sceneUpdateSchema(), "scene", errors);
  validate(st, viewStatusSchema(), "status", errors);
  EXPECT_TRUE(errors.empty()) << errors.size() << " errors, first: " << errors.front();
  std::map<std::string, json> by_id;
  for (const json& e : su["entities"]) by_id[e["id"].get<std::string>()] = e;
  EXPECT_EQ(by_id.at("target/left")["spheres"].size(), 1U);
  EXPECT_TRUE(by_id.at("target/right")["spheres"].empty()) << "a NaN target is not drawn";
  EXPECT_EQ(by_id.at("objects")["spheres"].size(), 1U) << "an infinite object is not drawn";
  EXPECT_TRUE(su.dump().find("null") == std::string::npos) << "no NaN in the scene";
  EXPECT_TRUE(st["arms"][1]["distance"].is_null()) << "an infinite distance is null";

  // A validator that could not fail would prove nothing: break a message three ways.
  json broken = su;
  broken["entities"][0]["spheres"][0]["size"]["x"] = "wide";
  broken["entities"][0]["colour"] = 1;
  broken["entities"][1]["lines"] = json::array({json{{"type", 7}}});
  std::vector<std::string> expected_errors;
  validate(broken, sceneUpdateSchema(), "scene", expected_errors);
  EXPECT_EQ(expected_errors.size(), 3U);

  // The foxglove field names (published schema definitions).
  const json s = sceneUpdateSchema();
  EXPECT_EQ(s["title"], "foxglove.SceneUpdate");
  EXPECT_EQ(keys(s["properties"]), (std::set<std::string>{"deletions", "entities"}));
  const json& entity = s["properties"]["entities"]["items"];
  EXPECT_EQ(entity["title"], "foxglove.SceneEntity");
  // Every field foxglove.SceneEntity has, each required (the published schema requires them all; a
  // message without `arrows` or `models` fails Foxglove's own validation: view_foxglove_ws_test and
  // record_scene_process_test check every message against it).
  const std::set<std::string> entity_fields{"timestamp", "frame_id",  "id",    "lifetime", "frame_locked",
                                            "metadata",  "arrows",    "cubes", "spheres",  "cylinders",
                                            "lines",     "triangles", "texts", "models"};
  EXPECT_EQ(keys(entity["properties"]), entity_fields);
  std::set<std::string> required;
  for (const json& k : entity["required"]) required.insert(k.get<std::string>());
  EXPECT_EQ(required, entity_fields);
  for (const json& e : su["entities"]) EXPECT_EQ(keys(e), entity_fields) << e["id"];
  EXPECT_EQ(keys(entity["properties"]["cylinders"]["items"]["properties"]),
            (std::set<std::string>{"pose", "size", "bottom_scale", "top_scale", "color"}));
  EXPECT_EQ(
      keys(entity["properties"]["lines"]["items"]["properties"]),
      (std::set<std::string>{"type", "pose", "thickness", "scale_invariant", "points", "color", "colors", "indices"}));
  EXPECT_EQ(keys(entity["properties"]["texts"]["items"]["properties"]),
            (std::set<std::string>{"pose", "billboard", "font_size", "scale_invariant", "color", "text"}));
  const json f = frameTransformsSchema();
  EXPECT_EQ(f["title"], "foxglove.FrameTransforms");
  EXPECT_EQ(keys(f["properties"]["transforms"]["items"]["properties"]),
            (std::set<std::string>{"timestamp", "parent_frame_id", "child_frame_id", "translation", "rotation"}));
}

TEST(Scene, BodySchemaSegmentsAreDrawnInTheirParentLinkFrame) {
  const SceneModel scene = asimo();
  SceneData data(scene);
  std::mt19937_64 rng(5);
  SceneInput in = inputAt(scene, rng);
  SchemaSegmentState bar;
  bar.name = "grasped_bar";
  bar.parent_link = "l_hand";
  bar.a_L = {0.0, -0.15, -0.06};
  bar.b_L = {0.0, 0.15, -0.06};
  bar.radius = 0.02;
  SchemaSegmentState gaze = bar, off = bar, unknown = bar, nan = bar;
  gaze.name = "gaze_line";
  gaze.parent_link = "head";
  gaze.virtual_segment = true;
  off.name = "off";
  off.enabled = false;
  unknown.name = "unknown";
  unknown.parent_link = "no_such_link";
  nan.name = "nan";
  nan.b_L.x() = std::nan("");
  in.schema_segments = {bar, gaze, off, unknown, nan};
  ASSERT_TRUE(updateScene(scene, data, in));
  const json su = json::parse(buildSceneUpdate(scene, data, in).dump());
  std::map<std::string, json> by_id;
  for (const json& e : su["entities"]) by_id[e["id"].get<std::string>()] = e;
  for (const char* gone : {"schema/off", "schema/unknown", "schema/nan"}) EXPECT_EQ(by_id.count(gone), 0U) << gone;
  ASSERT_EQ(by_id.count("schema/grasped_bar"), 1U);
  ASSERT_EQ(by_id.count("schema/gaze_line"), 1U);
  const Eigen::Isometry3d& X_B_hand = data.kin.X_B_L[scene.model.linkIndex("l_hand")];
  const json& e = by_id["schema/grasped_bar"];
  ASSERT_EQ(e["cylinders"].size(), 1U);
  ASSERT_EQ(e["spheres"].size(), 2U);
  EXPECT_LT((vec(e["spheres"][0]["pose"]["position"]) - X_B_hand * bar.a_L).norm(), 1e-12);
  EXPECT_LT((vec(e["spheres"][1]["pose"]["position"]) - X_B_hand * bar.b_L).norm(), 1e-12);
  EXPECT_NEAR(e["cylinders"][0]["size"]["z"].get<double>(), 0.30, 1e-12);
  EXPECT_LT(by_id["schema/gaze_line"]["spheres"][0]["color"]["a"].get<double>(), 0.5) << "virtual: translucent";
  // One delete-all, stamped before the entities, so that a detached segment disappears.
  ASSERT_EQ(su["deletions"].size(), 1U);
  EXPECT_EQ(su["deletions"][0]["type"], 1);
  const std::int64_t del = su["deletions"][0]["timestamp"]["sec"].get<std::int64_t>() * 1000000000 +
                           su["deletions"][0]["timestamp"]["nsec"].get<std::int64_t>();
  EXPECT_EQ(del, in.stamp_ns - 1);
  std::vector<std::string> errors;
  validate(su, sceneUpdateSchema(), "scene", errors);
  EXPECT_TRUE(errors.empty()) << errors.front();
}

TEST(Scene, BadJointInputIsSkippedAndCounted) {
  const SceneModel scene = asimo();
  SceneData data(scene);
  Eigen::VectorXd q;
  int unknown = 0, rejected = 0;
  const int set = jointPositionsToQ(scene, {"l_elbow", "no_such_joint", "r_elbow", "x"},
                                    {-1.0, 2.0, std::nan(""), 1.0, 5.0}, q, &unknown, &rejected);
  EXPECT_EQ(set, 1);
  EXPECT_EQ(unknown, 3) << "two unknown names and one position without a name";
  EXPECT_EQ(rejected, 1);
  ASSERT_EQ(q.size(), scene.model.nq);
  EXPECT_EQ(q[scene.model.qIndex("l_elbow")], -1.0);
  EXPECT_EQ(q[scene.model.qIndex("r_elbow")], 0.0) << "a NaN leaves the joint as it was";

  SceneInput in;
  in.q = q;
  ASSERT_TRUE(updateScene(scene, data, in));
  in.q[0] = std::nan("");
  EXPECT_FALSE(updateScene(scene, data, in)) << "a NaN configuration is refused";
  in.q = Eigen::VectorXd::Zero(3);
  EXPECT_FALSE(updateScene(scene, data, in)) << "a wrong size is refused";
  EXPECT_THROW(loadSceneModel("/nonexistent/robot.urdf", "", ""), control::ModelError);
}

// The view reads the robot's own controller configuration beside the URDF, as the controller
// does. Independent answer: the arms' segments are those of the links the test names (the small
// humanoid's hands and forearms), and the note names the file; a named file that is missing is an
// error naming it.
TEST(Scene, FindsTheRobotsControllerYamlBesideTheUrdf) {
  const SceneModel scene = loadSceneModel(robotPath("small_humanoid.urdf"), "", "");
  EXPECT_EQ(scene.controller_note.rfind("controller configuration " + robotPath("small_humanoid.controller.yaml") +
                                            " (beside the URDF): arm left to hand 'l_hand' (6 joints)",
                                        0),
            0u)
      << scene.controller_note;
  for (const char* link : {"l_hand", "l_forearm"})
    EXPECT_TRUE((scene.arm_segments[0] >> scene.model.segmentIndex(link)) & 1U) << link;
  for (const char* link : {"r_hand", "r_forearm"})
    EXPECT_TRUE((scene.arm_segments[1] >> scene.model.segmentIndex(link)) & 1U) << link;
  EXPECT_FALSE((scene.arm_segments[0] >> scene.model.segmentIndex("torso")) & 1U);
  EXPECT_EQ(asimo().controller_note.rfind("controller configuration: built-in defaults (no ", 0), 0u);
  try {
    loadSceneModel(robotPath("small_humanoid.urdf"), "", "/nonexistent/ctl.yaml");
    ADD_FAILURE() << "no error";
  } catch (const control::ConfigError& e) {
    EXPECT_EQ(
        std::string(e.what()),
        "--controller '/nonexistent/ctl.yaml': no such controller configuration file (No such file or directory)");
  }
}

// Two tracked objects must not look alike: every object of a scene its own colour, an object its
// colour whatever else is in the scene, and each object's label its name in that colour.
TEST(Scene, VisionObjectsAreDistinguishableAndLabelledWithTheirNames) {
  // Pairwise distinct for up to the palette's six, even for names that pick the same colour first.
  std::vector<std::string> names;
  for (int i = 0; i < 6; ++i) names.push_back("tag_" + std::to_string(i));
  names.insert(names.begin(), {"red_cup", "can"});
  names.resize(6);
  const std::vector<Rgba> colours = objectColours(names);
  ASSERT_EQ(colours.size(), names.size());
  for (std::size_t i = 0; i < colours.size(); ++i)
    for (std::size_t j = i + 1; j < colours.size(); ++j)
      EXPECT_GT(std::abs(colours[i].r - colours[j].r) + std::abs(colours[i].g - colours[j].g) +
                    std::abs(colours[i].b - colours[j].b),
                0.2)
          << names[i] << " and " << names[j] << " look alike";
  // The first name keeps its own colour whatever follows it; alone, every name has its own.
  EXPECT_EQ(objectColours({"can"})[0].g, objectColours({"can", "red_cup", "x"})[0].g);
  EXPECT_EQ(objectColours({"red_cup"})[0].b, objectColours({"red_cup", "can"})[0].b);
  // None is a zone colour (the segments' colours).
  for (const Rgba& c : colours)
    for (const Zone z : {Zone::kFree, Zone::kYellow, Zone::kOrange, Zone::kRed}) {
      const Rgba zc = zoneColour(z);
      EXPECT_GT(std::abs(c.r - zc.r) + std::abs(c.g - zc.g) + std::abs(c.b - zc.b), 0.2) << zoneName(z);
    }

  const SceneModel scene = asimo();
  SceneData data(scene);
  std::mt19937_64 rng(5);
  SceneInput in = inputAt(scene, rng);
  in.objects.push_back({"red_cup", {0.5, 0.1, 1.0}, 0.9});
  in.objects.push_back({"can", {0.45, -0.25, 0.9}, 0.9});
  ASSERT_TRUE(updateScene(scene, data, in));
  const json su = buildSceneUpdate(scene, data, in);
  const json* objects = nullptr;
  for (const json& e : su["entities"])
    if (e["id"] == "objects") objects = &e;
  ASSERT_NE(objects, nullptr);
  ASSERT_EQ((*objects)["spheres"].size(), 2U);
  ASSERT_EQ((*objects)["texts"].size(), 2U);
  const json &s0 = (*objects)["spheres"][0]["color"], &s1 = (*objects)["spheres"][1]["color"];
  EXPECT_NE(s0, s1) << "two objects, two colours";
  EXPECT_EQ((*objects)["texts"][0]["text"], "red_cup");
  EXPECT_EQ((*objects)["texts"][1]["text"], "can");
  for (int i = 0; i < 2; ++i) {
    const json& t = (*objects)["texts"][i];
    const json& s = (*objects)["spheres"][i];
    for (const char* k : {"r", "g", "b"}) EXPECT_EQ(t["color"][k], s["color"][k]) << "label in its object's colour";
    EXPECT_GT(t["pose"]["position"]["z"].get<double>(), s["pose"]["position"]["z"].get<double>()) << "above it";
  }
}

}  // namespace
}  // namespace reflex::view
