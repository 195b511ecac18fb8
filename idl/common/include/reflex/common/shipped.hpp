// Where an executable finds the data Reflex ships (robots, DDS profiles, behavior configurations,
// recorded sessions, the live view's page and three.js), installed or not.
//
//   REFLEX_DATA_DIR set     $REFLEX_DATA_DIR/<rel>
//   installed               <the executable's folder>/../share/reflex/<rel>, found from /proc/self/exe,
//                           so a prefix copied or moved elsewhere keeps working
//   in the build tree       the source checkout it was built from (its bringup/ folder; the view's page
//                           and three.js where the checkout keeps them)
//
// The layout under share/reflex (CMakeLists.txt installs it): robots/, dds/, behavior/, vision/,
// sessions/, idl/, view/web/, view/three/ (bringup/<same> in the checkout; idl/ at the top; view/web is
// modules/view/web and view/three bringup/web/node_modules/three/build).
#pragma once

#include <string>

namespace reflex::common {

/// The folder of the running executable (from /proc/self/exe); "." when it cannot be read.
std::string executableDir();

/// The folder shipped data is read from (see the opening block): $REFLEX_DATA_DIR, else
/// <executableDir()>/../share/reflex when that folder exists, else "" (the build tree: shippedPath
/// uses each file's checkout path).
std::string installedDataDir();

/// The path of shipped data `rel` (relative to share/reflex, e.g. "robots/asimo_like.urdf"):
/// installedDataDir() + "/" + rel, or in the build tree the checkout's own path of it. Never checks
/// that the file exists (the caller's own open reports a missing file, naming the path).
std::string shippedPath(const std::string& rel);

/// The robot the tools use when none is given: shippedPath("robots/asimo_like.urdf").
std::string defaultUrdf();

/// The DDS QoS profiles every process loads by default: shippedPath("dds/reflex_profiles.xml").
std::string defaultProfilesFile();

}  // namespace reflex::common
