// An independent reading of a URDF's XML (tinyxml2), made to account for every collision element
//. urdfdom drops a link's collision elements without failing when anything in the
// link does not parse (a NaN, "1e999", "0.001 " with a space, "1 2" for a 3-vector, an unnamed
// <material>, an unknown geometry such as <capsule>, a bad mass), and it accepts finite absurd values
// (an origin at 1e300 m) that move geometry out of reach just as surely. It also reads URDF 1.1
// <capsule>, handing urdfdom the same document with capsules as cylinders. loadModelFromString compares
// the counts found here with what urdfdom returned and refuses the model, naming every affected link
// and the reason found, in one message.
//
// Internal to reflex::control (not installed): the contract is tested through loadModelFromString.
#pragma once

#include <map>
#include <string>
#include <vector>

namespace urdf {
class ModelInterface;
}

namespace reflex::control::detail {

/// Ranges a humanoid's URDF must respect (checked for every collision element and every joint).
inline constexpr double kMaxUrdfLength = 10.0;               ///< m: |origin xyz|, radius, length, box size
inline constexpr double kMaxUrdfAngle = 12.566370614359172;  ///< rad (4 pi): |origin rpy|
inline constexpr double kMaxJointLimit = 1000.0;             ///< rad or m: |limit lower/upper|
inline constexpr double kMaxJointVelocity = 100.0;           ///< rad/s or m/s: limit velocity

struct UrdfAudit {
  std::string xml_error;  ///< non-empty: the text is not well-formed XML (tinyxml2's message and line)
  /// Number of <collision> children of every <link> that is a direct child of <robot>.
  std::map<std::string, int> collisions;
  /// Per link: problems in its collision elements (always fatal: not finite, malformed, out of range).
  std::map<std::string, std::vector<std::string>> collision_problems;
  /// Per link: problems in its visual / inertial elements. urdfdom drops the whole link's collision
  /// elements for these; they are reported as the reason when the counts differ.
  std::map<std::string, std::vector<std::string>> other_problems;
  /// Problems outside links (joints, collision elements outside every link, nested links,
  /// duplicate or unnamed links): always fatal. Each names its element and line.
  std::vector<std::string> problems;
  /// URDF 1.1 <capsule radius length> elements (collision and visual), which urdfdom 3 does not
  /// know. When there are any, `urdfdom_xml` is the document with each of them written as a
  /// <cylinder> of the same radius and length, for urdfdom to parse; the loader reads a cylinder as
  /// the capsule around its axis, which is exactly the capsule (radius r, core length = length).
  int capsules = 0;
  std::string urdfdom_xml;
};

/// Reads `xml` and fills the audit. Never throws for bad input (only std::bad_alloc).
UrdfAudit auditUrdf(const std::string& xml);

/// Every collision element of the file accounted for against what urdfdom read (`model`, null if it
/// refused the file): one line per affected link, how many elements urdfdom kept (if not all) and
/// every reason found. Visual / inertial problems are reasons only where urdfdom dropped something
/// (or refused the file): they cost urdfdom the whole link's collision elements. The loader and the
/// fit (fitRobot) refuse a file with any.
std::vector<std::string> collisionAccounting(const UrdfAudit& audit, const urdf::ModelInterface* model);

}  // namespace reflex::control::detail
