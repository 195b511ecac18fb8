// Shipped data, installed or in the checkout (shipped.hpp).
#include "reflex/common/shipped.hpp"

#include <climits>
#include <cstdlib>
#include <sys/stat.h>
#include <unistd.h>

#ifndef REFLEX_CHECKOUT_DIR
#error "REFLEX_CHECKOUT_DIR (the source checkout, for the build tree) must be defined by idl/common/CMakeLists.txt"
#endif

namespace reflex::common {

namespace {

bool isDirectory(const std::string& path) {
  struct stat st {};
  return stat(path.c_str(), &st) == 0 && S_ISDIR(st.st_mode);
}

/// Where `rel` lives in the checkout: bringup/<rel>, except the view's page and three.js.
std::string checkoutPath(const std::string& rel) {
  const std::string root = REFLEX_CHECKOUT_DIR;
  const std::string web = "view/web", three = "view/three";
  if (rel.compare(0, three.size(), three) == 0)
    return root + "/bringup/web/node_modules/three/build" + rel.substr(three.size());
  if (rel.compare(0, web.size(), web) == 0) return root + "/modules/view/web" + rel.substr(web.size());
  if (rel.compare(0, 4, "idl/") == 0 || rel == "idl") return root + "/" + rel;
  return root + "/bringup/" + rel;
}

}  // namespace

std::string executableDir() {
  char buf[4096];
  const ssize_t n = readlink("/proc/self/exe", buf, sizeof(buf) - 1);
  if (n <= 0) return ".";
  buf[n] = 0;
  std::string path(buf);
  const std::size_t slash = path.rfind('/');
  return slash == std::string::npos ? "." : (slash == 0 ? "/" : path.substr(0, slash));
}

std::string installedDataDir() {
  if (const char* env = std::getenv("REFLEX_DATA_DIR"); env != nullptr && *env != '\0') return env;
  const std::string installed = executableDir() + "/../share/reflex";
  if (!isDirectory(installed)) return std::string();
  char buf[PATH_MAX];
  return realpath(installed.c_str(), buf) != nullptr ? std::string(buf) : installed;  // PREFIX/share/reflex
}

std::string shippedPath(const std::string& rel) {
  const std::string dir = installedDataDir();
  return dir.empty() ? checkoutPath(rel) : dir + "/" + rel;
}

std::string defaultUrdf() { return shippedPath("robots/asimo_like.urdf"); }

std::string defaultProfilesFile() { return shippedPath("dds/reflex_profiles.xml"); }

}  // namespace reflex::common
