// `--package-path NAME=DIR` of the tools that read robot descriptions (reflex_fit, reflex_setup).
#pragma once

#include "reflex/common/error.hpp"
#include "reflex/control/mesh_fit.hpp"

#include <string>
#include <vector>

namespace reflex::control {

/// The NAME=DIR arguments as package paths; reflex::Error naming the first malformed one.
inline PackagePaths parsePackagePathArgs(const std::vector<std::string>& args) {
  PackagePaths paths;
  for (const auto& arg : args) {
    const auto eq = arg.find('=');
    if (eq == std::string::npos || eq == 0 || eq + 1 == arg.size())
      throw reflex::Error("--package-path '" + arg + "' must be NAME=DIR");
    paths.packages[arg.substr(0, eq)] = arg.substr(eq + 1);
  }
  return paths;
}

}  // namespace reflex::control
