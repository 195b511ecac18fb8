// Setting up a new humanoid (the library behind `reflex_setup`): from a loaded Model,
// find what the controller and the behavior layer need to know about the robot, each choice with the
// reason it was made.
//
//   arms        by STRUCTURE: a chain is the serial run of movable joints below a branching link (a
//               link with two or more child subtrees that hold movable joints) down to a leaf or the
//               next branching; an arm candidate is a chain of >= 4 revolute joints (no prismatic)
//               with a mirrored partner (first joints at (x, y, z) and (x, -y, z) within 1 cm, same
//               joint count); left is the one with y > 0 at q = 0 (REP 103: x forward, y left, z up),
//               unless both chains' names say the opposite (l_/left/L... on the y < 0 one): then the
//               root frame faces -x (iCub's) and forward is -x.
//               Of several mirrored pairs the one starting highest is the arms (legs hang below the
//               arms) when it is 5 cm above the next; else joint and link names are hints (shoulder,
//               arm, elbow, wrist, hand against hip, leg, knee, ankle, foot); else SetupError naming
//               every candidate. A given hand link (SetupOptions) overrides: its arm is the chain of
//               revolute joints from it up to the nearest branching link.
//   hand link   the last link of the chain (or the first link below it, through fixed joints, that has
//               collision geometry); hand point: the farthest core end point of its primitives from
//               the link origin (the end of the hand's geometry, on its axis: inside the hand).
//   head        the end link with geometry of the highest chain below the arms' branching link that is
//               not an arm (a name with "head" wins); camera: a link rigidly fixed below the head whose
//               name holds "camera" (first in the tree), else the head link.
//   gaps        points every 5 mm along each arm's skeleton (each link's origin to the next link's
//               origin on the path from the first arm joint to the hand link, then the hand link's
//               origin to the hand point): a point farther than `gap_tolerance` from the surface of
//               every primitive of its link's rigid body (the link and the links fixed to it) is a gap.
//               Stretch and primitives are rigid in the link frame, so the check holds at every q.
//               Reported per link with the largest gap and the capsule that closes it (link frame:
//               from the nearest core end of the body's primitives to the last uncovered point, with
//               that primitive's radius).
//   rest        a posture inside the limits (the middle 80 % of each range) and clear of the body:
//               every checked pair with an arm segment > d_a + rest_margin (the others: legs,
//               trunk, head, the rest posture cannot change), searched by deterministic random sampling then
//               coordinate descent towards "hand below and in front of the shoulder, elbow bent, arm
//               slightly out"; the right arm mirrors the left where its axes mirror.
// Every function throws SetupError with a message that names the bad value or the candidates.
#pragma once

#include "reflex/common/error.hpp"
#include "reflex/control/controller.hpp"
#include "reflex/control/model.hpp"

#include <Eigen/Core>

#include <array>
#include <cstdint>
#include <stdexcept>
#include <string>
#include <vector>

namespace reflex::control {

class SetupError : public reflex::Error {
 public:
  using reflex::Error::Error;
};

struct SetupOptions {
  std::string left_hand, right_hand;  ///< hand links to use ("" = find by structure)
  std::string head, camera;           ///< head / camera links to use ("" = find)
  double d_a = 0.04;                  ///< m: the controller's avoidance distance (rest must clear it)
  double rest_margin = 0.01;          ///< m: rest clears every checked pair by d_a + this
  double gap_tolerance = 0.01;        ///< m: a skeleton point farther than this from its arm's primitives is a gap
  int rest_samples = 4000;            ///< random postures tried for rest
  std::uint64_t seed = 1;
};

/// One arm as found.
struct ArmSetup {
  std::string side;                 ///< "left" / "right"
  std::vector<std::string> joints;  ///< shoulder to wrist
  std::string shoulder_link;        ///< child link of the first joint (its origin is the shoulder)
  std::string hand_link;
  Eigen::Vector3d hand_point_L = Eigen::Vector3d::Zero();  ///< m, hand link frame
  std::vector<double> rest;                                ///< rad, one per joint
};

/// A stretch of an arm's skeleton outside every primitive of the arm.
struct ArmGap {
  std::string side;
  std::string link;  ///< the link that carries the stretch
  double gap = 0.0;  ///< m, largest distance of a skeleton point to the arm's primitives' surface
  Eigen::Vector3d point_L = Eigen::Vector3d::Zero();  ///< where (link frame)
  Primitive closing;                                  ///< capsule in the link frame that covers the stretch
  std::string message;                                ///< the warning, one line
  std::string urdf_snippet;                           ///< the <collision> element to paste into the link
};

struct RobotSetup {
  std::array<ArmSetup, 2> arms;  ///< [0] left, [1] right
  std::string head_link, camera_link;
  /// The robot's forward direction in the root frame: +x (REP 103), or -x when both arms' names say
  /// the root frame faces backward (left arm at y < 0).
  Eigen::Vector3d forward = Eigen::Vector3d::UnitX();
  std::vector<ArmGap> gaps;
  double rest_distance = 0.0;          ///< m, closest checked pair at rest
  std::string rest_pair;               ///< "a-b"
  std::vector<std::string> decisions;  ///< one line per decision, with its reason
};

/// Finds arms, hands, hand points and head/camera (not rest, not gaps). Throws SetupError.
RobotSetup findRobotStructure(const Model& model, const SetupOptions& options);

/// The segments of several links set-up writes (collision YAML `segments:`): each hand with every link
/// below it that has collision geometry and that no joint in `driven_joints` moves against it (its
/// fingers, links fixed to it), in the model's link order; a hand with none is left out. One segment
/// per hand is the paper's segment per body part: one distance per hand pair instead of one per finger.
std::vector<std::pair<std::string, std::vector<std::string>>> handSegments(
    const Model& model, const std::vector<std::string>& hand_links, const std::vector<std::string>& driven_joints);

/// The configuration every joint outside the arms takes: 0, or the nearest limit if 0 is outside.
Eigen::VectorXd neutralConfiguration(const Model& model);

/// Fills setup.arms[*].rest (and rest_distance / rest_pair, a decision line). Throws SetupError when no
/// posture clears every pair by d_a + rest_margin, naming the best one found and its closest pair.
void findRestPosture(const Model& model, const SetupOptions& options, RobotSetup& setup);

/// Fills setup.gaps. Returns the number of gaps.
int findArmGaps(const Model& model, const SetupOptions& options, RobotSetup& setup);

/// A short closed-loop run of the OnboardController (KinematicPort) from the rest posture, both hands
/// sent to target_B (root frame, m) at t = 0; `cm` from the written controller configuration.
struct ReachCheck {
  std::array<Eigen::Vector3d, 2> target_B{};
  std::array<double, 2> error{};  ///< m, hand point to target at the end
  double reached_at = -1.0;       ///< s, first time both hands were within `tolerance` (-1: never)
  double min_distance = 0.0;      ///< m, closest physical pair over the run
  std::uint64_t estops = 0;
};
ReachCheck checkReach(const Model& model, const ControllerModel& cm, const std::array<Eigen::Vector3d, 2>& target_B,
                      double duration, double tolerance);

/// The <collision> element (URDF; cylinder = capsule for Reflex's loader) for a capsule in a link frame.
std::string collisionElementForCapsule(const Primitive& capsule, const std::string& name);

}  // namespace reflex::control
