// Small file helpers of the tests. Header-only.
#pragma once

#include <fstream>
#include <sstream>
#include <string>

namespace reflex::testing {

/// The whole text of `path` ("" when it cannot be read: a test then fails on the content).
inline std::string readFile(const std::string& path) {
  std::ifstream in(path);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

}  // namespace reflex::testing
