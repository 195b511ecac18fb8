// Loading a humanoid from URDF (urdfdom) plus its collision configuration into an immutable Model.
//
// Collision elements become primitives (README, "Collision model"):
//   sphere              -> sphere
//   cylinder (r, L)     -> capsule of radius r whose core segment is the cylinder's axis, length L,
//                          centred on the collision origin (the capsule is L + 2r long overall)
//   capsule (r, L)      -> URDF 1.1 <capsule radius length> (urdfdom 3 does not know it): the same
//                          capsule, core length L along the element's z axis
//   box (x, y, z)       -> a grid of capsules side by side enclosing it (mesh_fit.hpp, fitBox), with
//                          a warning giving their count, volume ratio and worst gap; the same
//                          primitives as a fit overlay holds for it (below)
//   mesh                -> the primitives of the fit overlay (mesh_fit.hpp, `reflex_fit URDF`):
//                          capsules and spheres enclosing every vertex of the link's mesh and box
//                          elements. A mesh link without a fit, or whose fit is stale (a mesh file,
//                          filename, scale, origin or box changed), is refused: one ModelError
//                          names every such link and the command to run.
// A link with collision elements is one segment named like the link.
//
// Which pairs are checked is configuration (a YAML file next to the robot, <robot>.collision.yaml):
//   exclude_adjacent: true     # default; pairs of segments on adjacent links are never checked:
//                              # joined by one joint or by a chain of links without collision
//                              # geometry, or siblings under a parent link without geometry
//   exclude:                   # further pairs that cannot collide or must not be checked
//     - [l_thigh, r_thigh]
//   srdf: robot.srdf           # optional, relative to this file: its <disable_collisions> pairs are
//                              # excluded too (entries naming links without geometry exclude nothing)
//   cylinder_as: capsule       # the cylinder policy (the only one until the mesh fitter exists)
//   fit: robot.fit.yaml        # optional, relative to this file: the fit overlay; default: the
//                              # URDF's <stem>.fit.yaml if it exists (loadModel)
// Segments on links joined by fixed joints form one rigid body and are never checked against each
// other, whatever the configuration says (no joint can change their distance).
// Every error names the file, the element and the bad value.
#pragma once

#include "reflex/common/error.hpp"
#include "reflex/control/model.hpp"

#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

namespace reflex::control {

/// Thrown for every set-up error of the model (URDF, collision configuration).
class ModelError : public reflex::Error {
 public:
  using reflex::Error::Error;
};

/// One <disable_collisions link1 link2 reason> entry of an SRDF.
struct SrdfPair {
  std::string link1, link2, reason;
  std::string where;  ///< "file:line", for error messages
};

struct CollisionConfig {
  bool exclude_adjacent = true;
  std::vector<std::pair<std::string, std::string>> exclude;
  std::string srdf;                     ///< SRDF path ("" if none)
  std::vector<SrdfPair> srdf_disabled;  ///< its disable_collisions entries
  std::string cylinder_as = "capsule";  ///< cylinder policy
  std::string fit;                      ///< fit overlay path ("" = loadModel's default, if present)
  /// Segments of several links (`segments:`): a segment named by its first link, with the links
  /// listed (each below it). Their link pairs are checked as before, one distance per segment pair.
  std::vector<std::pair<std::string, std::vector<std::string>>> segments;
  std::string source = "<defaults>";  ///< where it was read from, for error messages
};

/// Reads the <disable_collisions> entries of an SRDF (tinyxml2; other SRDF elements are ignored).
/// Throws ModelError naming the file (and line) for an unreadable file, a top element that is not
/// <robot>, or an entry without link1 / link2. Link names are checked against the URDF by loadModel.
std::vector<SrdfPair> loadSrdfDisabledCollisions(const std::string& srdf_path);

/// Reads a collision configuration YAML. Throws ModelError naming the file and the bad entry.
CollisionConfig loadCollisionConfig(const std::string& yaml_path);

/// "dir/robot.urdf" -> "dir/robot.collision.yaml".
std::string defaultCollisionConfigPath(const std::string& urdf_path);

/// The collision configuration of a robot as every tool chooses it: `collision_path` if given;
/// else defaultCollisionConfigPath(urdf_path) if anything exists there (read and checked like any
/// other: a FIFO or device there is a ModelError, never a blocked open); else the defaults.
CollisionConfig loadCollisionConfigFor(const std::string& urdf_path, const std::string& collision_path);

/// Loads a URDF file. Warnings (e.g. boxes fitted with capsules, and how tightly) are appended to `warnings` if given.
/// Throws ModelError for a missing or malformed file, mesh-only collision, non-positive radius,
/// zero-length cylinder, bad limits, and unknown link names in the configuration.
Model loadModel(const std::string& urdf_path, const CollisionConfig& config,
                std::vector<std::string>* warnings = nullptr);

/// Same, from URDF XML text; `origin` names the source in error messages.
Model loadModelFromString(const std::string& urdf_xml, const CollisionConfig& config, const std::string& origin,
                          std::vector<std::string>* warnings = nullptr);

}  // namespace reflex::control
