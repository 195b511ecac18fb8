// The inputs of a link's fit, as the fitter and the loader both read them from urdfdom, and their
// hash: the overlay records it, the loader recomputes it, and a difference means the overlay is stale
// (a mesh file's bytes, a filename, a scale, an origin or a box size changed).
//
// Internal to reflex::control (not installed).
#pragma once

#include "reflex/control/mesh_fit.hpp"

#include <urdf_model/link.h>

#include <string>
#include <vector>

namespace reflex::control::detail {

/// One mesh or box collision element of a link.
struct FitElement {
  bool box = false;
  std::string name;                                 ///< the collision element's name (may be empty)
  std::string filename;                             ///< mesh: as written in the URDF
  Eigen::Vector3d scale = Eigen::Vector3d::Ones();  ///< mesh: scale attribute
  Eigen::Vector3d size = Eigen::Vector3d::Zero();   ///< box: size
  Eigen::Isometry3d X_L_C = Eigen::Isometry3d::Identity();
};

/// The link's mesh and box collision elements, in file order.
std::vector<FitElement> fitElementsOf(const urdf::Link& link);

/// FNV-1a 64-bit hash (16 hex digits) of every element's kind, filename, scale, size, origin, and
/// mesh file bytes. Meshes that cannot be resolved or read are appended to `problems` (one line each,
/// naming the link, the filename and why); `resolved` gets each mesh's path ("" if unresolved or
/// unreadable: already reported).
std::string fitInputsHash(const std::string& link, const std::vector<FitElement>& elements, const std::string& urdf_dir,
                          const PackagePaths& paths, std::vector<std::string>* problems,
                          std::vector<std::string>* resolved);

/// The folder of a file path ("." when it has none).
std::string folderOf(const std::string& path);

}  // namespace reflex::control::detail
