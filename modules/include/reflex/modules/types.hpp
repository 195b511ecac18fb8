// Value types a behavior module sees and produces. They mirror the bus topics of idl/ (vision.idl,
// behavior.idl, control.idl) but carry no DDS: reflex::modules is testable without a middleware, and
// the DDS adapter (modules/node) converts between these and reflex::msg.
//
// Frames: "_B" is the robot base frame (the URDF root: x forward, y left, z up, on the floor); it is
// the frame of ObjectTarget::position_base and HandTarget::position_base. "_L" is a link frame.
// Units: metres, radians, seconds (nanoseconds where the name says _ns).
#pragma once

#include <Eigen/Core>

#include <array>
#include <cstdint>
#include <string>
#include <vector>

namespace reflex::modules {

enum class Hand { kLeft = 0, kRight = 1 };
inline constexpr std::array<Hand, 2> kBothHands = {Hand::kLeft, Hand::kRight};
inline int handIndex(Hand h) { return static_cast<int>(h); }
inline const char* handName(Hand h) { return h == Hand::kLeft ? "left" : "right"; }
inline Hand otherHand(Hand h) { return h == Hand::kLeft ? Hand::kRight : Hand::kLeft; }

/// One named object seen by vision (reflex::msg::ObjectTarget).
struct ObjectObservation {
  std::string name;  ///< object name; "" = unknown tag
  int tag_id = -1;
  Eigen::Vector3d p_B = Eigen::Vector3d::Zero();  ///< object (tag centre) in the base frame [m]
  double confidence = 1.0;                        ///< 0..1
};

/// Name of the robot base frame B on the bus: what reflex_vision writes into ObjectTargets.frame_id
/// (its --frame-id default) and what the behavior host accepts unless configured otherwise.
inline constexpr const char* kBaseFrameId = "base_link";

/// One image pair's objects (reflex::msg::ObjectTargets). An empty list = nothing seen.
struct ObjectsFrame {
  std::int64_t stamp_ns = 0;          ///< publication time, system clock [ns since epoch]
  std::int64_t capture_stamp_ns = 0;  ///< capture time of the image pair, system clock (0 = unknown)
  std::uint64_t image_index = 0;
  std::string frame_id = kBaseFrameId;  ///< frame the sender says p_B is in (ObjectTargets.frame_id)
  /// Identity of the participant that WROTE the frame (not Header.source, which any writer can set):
  /// under DDS-Security the authenticated identity name ("vision" for CN=reflex.vision), otherwise the
  /// name its participant announced; "" when unknown. Filled by the DDS adapter (bus::WriterIdentities).
  std::string source;
  std::vector<ObjectObservation> objects;
};

/// A joint state sample (reflex::msg::JointState): names and positions of equal length.
struct JointStateSample {
  std::int64_t stamp_ns = 0;
  /// Identity of the participant that wrote the sample, as ObjectsFrame::source ("" = unknown).
  std::string source;
  std::vector<std::string> names;
  std::vector<double> positions;  ///< [rad] or [m]
};

/// The target of one hand (reflex::msg::HandTarget). Invariant: when given, p_B is finite.
struct HandTarget {
  bool given = false;                             ///< false: "no target" (the controller retracts it)
  Eigen::Vector3d p_B = Eigen::Vector3d::Zero();  ///< hand target in the base frame [m] if given
  std::string object;                             ///< object pointed at ("" if none / scripted)

  static HandTarget none() { return {}; }
  static HandTarget at(const Eigen::Vector3d& p_B, std::string object = {}) {
    HandTarget t;
    t.given = true;
    t.p_B = p_B;
    t.object = std::move(object);
    return t;
  }
  bool operator==(const HandTarget& o) const {
    return given == o.given && object == o.object && (!given || p_B == o.p_B);
  }
  bool operator!=(const HandTarget& o) const { return !(*this == o); }
};

/// Motion priority between the arms (paper Sec. 7.2; reflex::msg::ArmPriority).
enum class ArmPriority { kEqual, kLeftHigher, kRightHigher };
const char* priorityName(ArmPriority p);
inline ArmPriority higher(Hand h) { return h == Hand::kLeft ? ArmPriority::kLeftHigher : ArmPriority::kRightHigher; }

/// An extra body-schema segment (paper Sec. 8.5; reflex::msg::BodySchemaChange with SCHEMA_ATTACH).
/// Invariants: radius > 0, endpoints finite; a sphere has a_L == b_L.
struct SegmentSpec {
  std::string name;                               ///< unique segment name (the topic's key)
  std::string parent_link;                        ///< URDF link the segment is attached to
  bool capsule = true;                            ///< false: sphere at a_L
  Eigen::Vector3d a_L = Eigen::Vector3d::Zero();  ///< first endpoint in the parent link frame [m]
  Eigen::Vector3d b_L = Eigen::Vector3d::Zero();  ///< second endpoint [m] (capsule only)
  double radius = 0.0;                            ///< [m] > 0
  int motion_priority = 0;                        ///< higher wins; the arms have 0 (Sec. 8.5.1)
  bool enabled = true;                            ///< false: kept, but ignored by the distance computation
  bool virtual_segment = false;                   ///< true: avoided but never moved (occlusion, Sec. 8.5.2)

  bool operator==(const SegmentSpec& o) const {
    return name == o.name && parent_link == o.parent_link && capsule == o.capsule && a_L == o.a_L && b_L == o.b_L &&
           radius == o.radius && motion_priority == o.motion_priority && enabled == o.enabled &&
           virtual_segment == o.virtual_segment;
  }
  bool operator!=(const SegmentSpec& o) const { return !(*this == o); }
};

/// A walking command (reflex::msg::WalkCommand), world (odometry) frame.
struct WalkGoal {
  double x = 0.0, y = 0.0, yaw = 0.0;  ///< goal [m, m, rad]
  double speed = 0.3;                  ///< [m/s] > 0
  bool stop = false;                   ///< true: stop walking now (goal ignored)
  bool operator==(const WalkGoal& o) const {
    return x == o.x && y == o.y && yaw == o.yaw && speed == o.speed && stop == o.stop;
  }
};

/// The time a module sees: `t` is monotonic seconds since the host was built (all module timing:
/// lost timeouts, timelines, hold times); `wall_ns` is the system clock (the Header.stamp_ns clock),
/// used only to judge input stamps.
struct Now {
  double t = 0.0;
  std::int64_t wall_ns = 0;
};

}  // namespace reflex::modules
