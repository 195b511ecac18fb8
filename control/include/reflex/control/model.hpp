// Robot model: the immutable description of a humanoid's kinematic tree and collision segments
// (paper Sec. 4, Fig. 1). Loaded once from URDF (see loadModel in urdf_loader.hpp); never mutated
// afterwards. Everything that changes per cycle lives in the Data structs of kinematics.hpp and
// distance.hpp, sized from this model.
//
// Frames: B is the URDF root link frame ("base frame"; for the shipped robot: on the floor, x forward,
// y left, z up). L is a link frame (URDF convention: it coincides with the frame of its parent joint).
// Units: metres, radians.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "reflex/control/convex.hpp"

#include <array>
#include <string>
#include <utility>
#include <vector>

namespace reflex::control {

enum class JointType { kFixed, kRevolute, kPrismatic };

/// One link and the joint that connects it to its parent (every non-root link has exactly one).
struct Link {
  std::string name;
  int parent = -1;                                          ///< parent link index, -1 for the root
  Eigen::Isometry3d X_P_J = Eigen::Isometry3d::Identity();  ///< joint origin in the parent link frame
  JointType type = JointType::kFixed;
  Eigen::Vector3d axis_J = Eigen::Vector3d::UnitZ();  ///< unit joint axis in the joint frame
  int q_index = -1;                                   ///< index into q, -1 if fixed
  std::string joint_name;                             ///< empty for the root
  /// The URDF <inertial>, if the link has one (the controller does not use it; the physics robot
  /// reflex_mujoco does): mass [kg], centre of mass in L [m], inertia about the centre of mass in
  /// L's axes [kg m^2] (the URDF's inertial-frame tensor rotated into L).
  bool has_inertial = false;
  double mass = 0.0;
  Eigen::Vector3d com_L = Eigen::Vector3d::Zero();
  Eigen::Matrix3d inertia_L = Eigen::Matrix3d::Zero();
};

/// A sphere-swept line (capsule) in a link frame; a sphere when a_L == b_L (`sphere` is then true).
/// Invariants: radius > 0; a capsule has |b_L - a_L| > 0.
/// With `piece` >= 0 the capsule is only the ENCLOSING BOUND of the convex piece Model::pieces[piece]
/// (a piece of a mesh or a box, convex.hpp), which is the real shape: distances are computed on the
/// piece, the capsule serves the broad phase (its distance is a lower bound of the piece's).
struct Primitive {
  Eigen::Vector3d a_L = Eigen::Vector3d::Zero();
  Eigen::Vector3d b_L = Eigen::Vector3d::Zero();
  double radius = 0.0;
  bool sphere = true;
  int piece = -1;  ///< index into Model::pieces, -1: the capsule (or sphere) is the shape itself
  /// The link the primitive is expressed in and moves with, when it is not its segment's (a segment of
  /// several links: a hand with its fingers); -1: the segment's link. See linkOf.
  int link = -1;
};

/// A collision segment (paper Fig. 1): one or several primitives of one body part. Usually one link; a
/// segment of several links (collision YAML `segments:`, e.g. a hand with its fingers) is its first
/// link and links below it that no joint the controller drives moves: each primitive then moves with
/// its own link (Primitive::link), the pair's distance is the least over its primitives, and its
/// Jacobian row is that of the winning primitives' links (a finger's own joints included: the fingers'
/// motion counts as motion the arm does not command; the controller acts on the arm's columns).
/// Primitives are stored flat in Model::primitives[first_primitive, first_primitive + num_primitives).
struct Segment {
  std::string name;  ///< the link name for robot segments; the slot name for body-schema slots
  int link = -1;     ///< the segment's link (its primitives' unless they name theirs; slots: set at run time)
  int first_primitive = 0;
  int num_primitives = 0;
  bool body_schema_slot = false;  ///< a run-time slot (grasped object / virtual segment), Sec. 8.5
};

/// A pair of segments whose distance is computed every cycle. Invariant: a < b.
struct SegmentPair {
  SegmentPair() = default;
  SegmentPair(int a_, int b_, std::vector<std::array<int, 2>> unchecked = {})
      : a(a_), b(b_), unchecked_links(std::move(unchecked)) {}
  int a = -1;
  int b = -1;
  /// Link pairs {link of a, link of b} of this pair that are not checked (excluded, adjacent or on
  /// one rigid body as links): only where a segment has several links, sorted. Their primitive pairs
  /// are never computed.
  std::vector<std::array<int, 2>> unchecked_links;
};

/// The immutable robot model. Build it with loadModel(); do not edit it after loading.
struct Model {
  std::string name;
  std::vector<Link> links;           ///< topological order: a parent always comes before its children
  int nq = 0;                        ///< number of movable (revolute / prismatic) joints
  std::vector<std::string> q_names;  ///< joint name per q index
  Eigen::VectorXd q_lower, q_upper;  ///< position limits per q index (rad or m)
  Eigen::VectorXd v_max;             ///< velocity limits per q index (rad/s or m/s), > 0
  std::vector<int> q_link;           ///< link moved by each q index
  /// For each link, the q indices of the movable joints on the path from the root to it,
  /// root first (its own joint last if movable). Used by every Jacobian.
  std::vector<std::vector<int>> link_support;

  std::vector<Primitive> primitives;
  /// The convex pieces of fitted meshes and boxes (link frame of the primitive that refers to them).
  std::vector<ConvexPiece> pieces;
  std::vector<Segment> segments;  ///< robot segments first, then the body-schema slots
  int num_robot_segments = 0;
  std::vector<SegmentPair> pairs;  ///< checked pairs (configuration), including slot pairs

  /// Index lookups; return -1 when the name is unknown. segmentIndex also finds a segment by the
  /// name of any link it has (a finger link names its hand's segment).
  int linkIndex(const std::string& link_name) const;
  int qIndex(const std::string& joint_name) const;
  int segmentIndex(const std::string& segment_name) const;
};

/// The link primitive `prim` of segment `seg` moves with.
inline int linkOf(const Segment& seg, const Primitive& prim) { return prim.link >= 0 ? prim.link : seg.link; }

/// The file of a robot's set that lies beside its URDF: the URDF's path without its extension, then
/// `suffix` (".collision.yaml", ".controller.yaml", ".fit.yaml", ...). One rule for every such file.
std::string robotFileBeside(const std::string& urdf_path, const std::string& suffix);

/// Capacity of a body-schema slot (one capsule each) and the number of slots every model has.
inline constexpr int kBodySchemaSlots = 4;

/// Most segments a model may have, robot segments and body-schema slots together: segment sets are
/// 64-bit masks (BodySchemaSlot::ignore_mask, ControllerModel::Arm::segment_mask). loadModel refuses
/// a robot with more than kMaxSegments - kBodySchemaSlots collision segments, naming the count and
/// the limit; makeControllerModel checks it again for models built by hand.
inline constexpr int kMaxSegments = 64;

}  // namespace reflex::control
