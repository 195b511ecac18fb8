// Scene channels for viewers: the robot's links as `foxglove.FrameTransforms` and
// its collision model, closest pairs, hand targets and vision objects as `foxglove.SceneUpdate`,
// JSON-encoded, with their JSON schemas. No DDS here: reflex_view feeds it from the bus, and a recorder
// can call the same functions on recorded samples (a JointState + ControlStatus at one instant).
//
// Frames: every scene entity is expressed in the URDF base frame B (`SceneModel::root_frame`, "world"
// for the shipped robot; frame_locked false), so a viewer needs no transform tree to draw it; the
// FrameTransforms give every link (parent -> child, one per non-root link) for viewers that show
// frames. Units: metres, seconds; colours RGBA in [0, 1].
//
// How the collision model is drawn (Foxglove has no capsule primitive): a capsule primitive (core
// segment a_B -> b_B, radius r; model.hpp) is one CylinderPrimitive (centre (a+b)/2, its z axis along
// b - a, size 2r x 2r x |b - a|) plus two SpherePrimitives of diameter 2r at a_B and b_B; a sphere
// primitive is one SpherePrimitive. One entity per segment, id "segment/<name>".
//
// Colour: a segment an arm moves takes the colour of that arm's zone (ControlStatus.zone of the arm,
// paper Sec. 8: free, yellow d_b < d < d_a, orange d_r < d <= d_b, red d <= d_r); the other segment of
// an arm's closest pair takes it too (the worse of the two arms if both name it); every other segment
// is grey. The closest pair of each arm is a line between its witness points (entity "closest/<arm>"),
// from this library's own distance computation of the pair the controller named.
//
// Extending: another primitive kind goes into appendSegmentEntity (scene.cpp) and, if it uses a new
// foxglove primitive, into sceneUpdateSchema.
#pragma once

#include <reflex/control/controller.hpp>
#include <reflex/control/distance.hpp>
#include <reflex/control/kinematics.hpp>
#include <reflex/control/model.hpp>

#include <Eigen/Core>
#include <nlohmann/json.hpp>

#include <array>
#include <cstdint>
#include <limits>
#include <string>
#include <vector>

namespace reflex::view {

/// Zone of an arm's closest distance, numbered as reflex::msg::Zone (control.idl).
enum class Zone : int { kFree = 0, kYellow = 1, kOrange = 2, kRed = 3 };

/// RGBA colour of a zone (and of segments no arm moves: zoneColour with `neutral` true).
struct Rgba {
  double r = 0, g = 0, b = 0, a = 1;
};
Rgba zoneColour(Zone zone);
Rgba neutralColour();
/// Colour of each vision object, in the order of `names`: each name's own colour of a fixed palette
/// (chosen from the name, so an object keeps its colour from scene to scene), or, when an earlier name
/// of the list holds it, the next colour of the palette not yet taken, so up to the palette's size
/// (6) objects of one scene never share a colour. None is a zone, target or closest-line colour.
std::vector<Rgba> objectColours(const std::vector<std::string>& names);
/// "free", "yellow", "orange", "red" (anything else: "free").
const char* zoneName(Zone zone);

/// The immutable part: robot model, which segments each arm moves, zone thresholds.
struct SceneModel {
  control::Model model;
  std::array<std::string, 2> arm_names{"left", "right"};  ///< [0] left, [1] right (controller order)
  std::array<std::uint64_t, 2> arm_segments{0, 0};        ///< bit s: robot segment s moved by that arm
  double d_a = 0.040, d_b = 0.010, d_r = 0.005;           ///< zone thresholds [m] (controller params)
  std::string root_frame;                                 ///< name of the URDF root link (frame of every entity)
  std::string controller_note;  ///< loadSceneModel: which controller configuration (describeControllerConfig)
};

/// Loads the robot as reflex_controller does (URDF, collision YAML next to it unless given, controller
/// YAML by control::loadControllerConfigFor: the given one, else <stem>.controller.yaml beside the URDF,
/// else the defaults). Throws control::ModelError / control::ConfigError naming file and value.
SceneModel loadSceneModel(const std::string& urdf, const std::string& collision, const std::string& controller);
/// From an already loaded model and controller configuration (throws like makeControllerModel).
SceneModel makeSceneModel(control::Model model, const control::ControllerConfig& config);

/// One arm's status, as ControlStatus.ArmStatus carries it.
struct ArmState {
  bool valid = false;  ///< false: no ControlStatus yet (colour neutral, no closest line)
  double blend_f = 0.0;
  std::string closest_a, closest_b;
  double distance = std::numeric_limits<double>::infinity();
  Zone zone = Zone::kFree;
  bool estop_latched = false;
};

/// A hand target in B (HandTargets.position_base: the robot base frame is the URDF root frame).
struct HandTargetState {
  bool given = false;
  Eigen::Vector3d p_B = Eigen::Vector3d::Zero();
  std::string object;
};

/// A vision object in B (ObjectTargets.position_base).
struct ObjectState {
  std::string name;
  Eigen::Vector3d p_B = Eigen::Vector3d::Zero();
  double confidence = 0.0;
};

/// A body-schema segment from reflex/body_schema (Sec. 8.5: a grasped object, or a virtual gaze-line
/// segment): a capsule (or a sphere, a_L only) in the frame of `parent_link`. Drawn as entity
/// "schema/<name>": physical ones in the schema colour, virtual ones translucent; disabled ones, an
/// unknown link or a non-finite value are not drawn. (Not part of the view's own distances: the
/// controller's pairs with a slot are not drawn as closest lines.)
struct SchemaSegmentState {
  std::string name;
  std::string parent_link;
  bool capsule = true;
  Eigen::Vector3d a_L = Eigen::Vector3d::Zero(), b_L = Eigen::Vector3d::Zero();
  double radius = 0.0;
  bool enabled = true;
  bool virtual_segment = false;
};

/// Everything one scene is built from. Non-finite positions are skipped when drawing (never emitted).
struct SceneInput {
  std::int64_t stamp_ns = 0;  ///< system clock [ns]: the joint state's Header.stamp_ns
  Eigen::VectorXd q;          ///< model.nq joint positions, model q order (see jointPositionsToQ)
  std::array<ArmState, 2> arms;
  std::array<HandTargetState, 2> targets;
  std::vector<ObjectState> objects;
  std::vector<SchemaSegmentState> schema_segments;
};

/// Per-scene results, sized from the model (one per thread of use).
struct SceneData {
  explicit SceneData(const SceneModel& scene);
  control::KinematicsData kin;
  control::DistanceData dist;
  std::array<int, 2> closest_pair{-1, -1};  ///< index into model.pairs of each arm's named pair, -1 if none
  /// The line drawn for each arm's closest pair (witness points in the world frame): the named robot
  /// pair's, or, when the controller names a body-schema slot (`body_schema_N`, whose slot numbering
  /// is the controller's own), the nearest enabled body-schema segment of the input to the arm's
  /// named segment. closest_line[arm] false: nothing to draw.
  std::array<bool, 2> closest_line{false, false};
  std::array<Eigen::Vector3d, 2> closest_a_B, closest_b_B;
  std::vector<Zone> segment_zone;    ///< per segment: the zone it is coloured with
  std::vector<bool> segment_in_arm;  ///< per segment: moved by an arm or named in a closest pair
};

/// Fills q (resized to model.nq, unset joints keep their value, or 0 on resize) from JointState names
/// and positions. Returns the number of joints set; names it does not know and non-finite values are
/// skipped (counted in `unknown`, `rejected` if given). Never throws.
int jointPositionsToQ(const SceneModel& scene, const std::vector<std::string>& names,
                      const std::vector<double>& positions, Eigen::VectorXd& q, int* unknown = nullptr,
                      int* rejected = nullptr);

/// Forward kinematics, distances, closest pairs and colours for `input`. Returns false (data keeps the
/// previous scene) if q has the wrong size or a non-finite value.
bool updateScene(const SceneModel& scene, SceneData& data, const SceneInput& input);

/// `foxglove.FrameTransforms`: one transform per non-root link, parent link -> link, at input.stamp_ns.
/// Composing them from the root gives data.kin.X_B_L. Call after updateScene.
nlohmann::json buildFrameTransforms(const SceneModel& scene, const SceneData& data, const SceneInput& input);

/// `foxglove.SceneUpdate` with the entities described at the top of this file ("segment/<name>",
/// "closest/left", "closest/right", "target/left", "target/right", "objects", "schema/<name>"); every
/// entity is sent every time, and one deletion (type ALL, stamped just before) first, so that a
/// body-schema segment that went away disappears too. Call after updateScene.
nlohmann::json buildSceneUpdate(const SceneModel& scene, const SceneData& data, const SceneInput& input);

/// The Reflex status channel the bundled page plots (`reflex.ViewStatus`): stamp, d_a/d_b/d_r, each
/// arm's distance, f(d), zone, e-stop and closest pair, the hand targets, and `protection` (free text).
nlohmann::json buildViewStatus(const SceneModel& scene, const SceneInput& input, const std::string& protection);

/// JSON schemas (draft-07 style objects) of the three messages above, written from the published
/// foxglove schema definitions (field names, types, enum values). Only the primitives Reflex emits
/// (spheres, cylinders, lines, texts) are listed in the SceneEntity schema.
nlohmann::json frameTransformsSchema();
nlohmann::json sceneUpdateSchema();
nlohmann::json viewStatusSchema();

/// `foxglove.CompressedImage` of an encoded camera image (the bus's reflex/camera_left): timestamp,
/// frame_id, format ("jpeg") and the bytes as base64 (JSON encoding of a bytes field).
nlohmann::json buildCompressedImage(std::int64_t stamp_ns, const std::string& frame_id, const std::string& format,
                                    const std::vector<std::uint8_t>& data);
/// Its JSON schema, from the published foxglove.CompressedImage definition.
nlohmann::json compressedImageSchema();
/// Standard base64 (RFC 4648, with padding) of `data`.
std::string base64(const std::vector<std::uint8_t>& data);

/// Counts of what buildSceneUpdate draws for the robot itself (for tests and the page's checks).
struct CollisionCounts {
  int capsules = 0;  ///< capsule primitives (one cylinder + two spheres each)
  int spheres = 0;   ///< sphere primitives
};
CollisionCounts countCollisionPrimitives(const SceneModel& scene);

}  // namespace reflex::view
