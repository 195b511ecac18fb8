// Small file helpers of the tests. Header-only.
#pragma once

#include <cstdlib>
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

/// The number written right after `key` in `text` (e.g. "robot_state_bad_crc " in an exit line), -1 if
/// the key is absent.
inline double numberAfter(const std::string& text, const std::string& key) {
  const std::size_t at = text.find(key);
  if (at == std::string::npos) return -1;
  return std::atof(text.c_str() + at + key.size());
}

}  // namespace reflex::testing
