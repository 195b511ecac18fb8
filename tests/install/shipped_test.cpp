// reflex/common/shipped.hpp: where executables find the shipped data. Run from the build tree (no
// build/share/reflex): the checkout's files; REFLEX_DATA_DIR: that folder. The installed case (a moved
// prefix, the checkout hidden) is install_test.sh's.
#include "reflex/common/shipped.hpp"

#include <gtest/gtest.h>

#include <cstdlib>
#include <filesystem>
#include <string>

namespace {

namespace fs = std::filesystem;
using reflex::common::shippedPath;

TEST(Shipped, TheBuildTreeReadsTheCheckoutItWasBuiltFrom) {
  ::unsetenv("REFLEX_DATA_DIR");
  EXPECT_EQ(fs::canonical(reflex::common::executableDir()), fs::canonical(REFLEX_BIN_DIR));
  EXPECT_EQ(reflex::common::installedDataDir(), "") << "no build/share/reflex: not an installed tree";
  const std::string src = REFLEX_SOURCE_DIR;
  EXPECT_EQ(reflex::common::defaultUrdf(), src + "/bringup/robots/asimo_like.urdf");
  EXPECT_EQ(reflex::common::defaultProfilesFile(), src + "/bringup/dds/reflex_profiles.xml");
  EXPECT_EQ(shippedPath("view/web/index.html"), src + "/modules/view/web/index.html");
  EXPECT_EQ(shippedPath("view/three/three.module.js"), src + "/bringup/web/node_modules/three/build/three.module.js");
  EXPECT_EQ(shippedPath("idl/control.idl"), src + "/idl/control.idl");
  // Every folder the install puts under share/reflex (CMakeLists.txt) has its file in the checkout.
  for (const char* rel :
       {"robots/asimo_like.urdf", "robots/mesh_humanoid_description", "dds/reflex_profiles.xml",
        "behavior/pointing.yaml", "vision/camera_mount.yaml", "sessions/flagship/session.yaml", "idl/control.idl",
        "view/web/index.html", "view/three/three.module.js", "view/three/three.core.js"})
    EXPECT_TRUE(fs::exists(shippedPath(rel))) << rel << " -> " << shippedPath(rel);
}

TEST(Shipped, ReflexDataDirPointsElsewhere) {
  ::setenv("REFLEX_DATA_DIR", "/opt/elsewhere/share/reflex", 1);
  EXPECT_EQ(reflex::common::installedDataDir(), "/opt/elsewhere/share/reflex");
  EXPECT_EQ(reflex::common::defaultUrdf(), "/opt/elsewhere/share/reflex/robots/asimo_like.urdf");
  EXPECT_EQ(shippedPath("view/three/three.core.js"), "/opt/elsewhere/share/reflex/view/three/three.core.js");
  ::setenv("REFLEX_DATA_DIR", "", 1);  // empty: as if unset
  EXPECT_EQ(reflex::common::defaultUrdf(), std::string(REFLEX_SOURCE_DIR) + "/bringup/robots/asimo_like.urdf");
  ::unsetenv("REFLEX_DATA_DIR");
}

}  // namespace
