#pragma once
// Internal helpers for vision's YAML set-up files: they read through the project's one YAML reader
// (reflex/common/yaml_reader.hpp), so every error has its format "FILE:LINE:COL: KEY.PATH: PROBLEM
// (value 'V', expected E)" and is thrown as a VisionError.
#include "reflex/common/files.hpp"
#include "reflex/common/yaml_reader.hpp"
#include "reflex/vision/calibration.hpp"
#include "reflex/vision/error.hpp"

#include <fstream>
#include <limits>
#include <sstream>
#include <string>
#include <vector>

namespace reflex::vision::detail {

using common::ConfigNode;

/// Any finite number (the range checks that follow say what is wrong in the file's terms).
constexpr double kAnyNumber = std::numeric_limits<double>::max();

[[noreturn]] inline void raiseVisionError(const std::string& message) { throw VisionError(message); }

inline std::string readTextFile(const std::string& path, const std::string& what) {
  if (const std::string why = common::inputFileProblem(path); !why.empty())
    throw VisionError(what + " file " + why);  // a FIFO or device would block or never end
  std::ifstream in(path, std::ios::binary);
  if (!in) throw VisionError("cannot open " + what + " file '" + path + "'");
  std::ostringstream os;
  os << in.rdbuf();
  return os.str();
}

/// The document of `text` (a map at the top level), read from `source`.
inline ConfigNode parseYaml(const std::string& text, const std::string& source) {
  return ConfigNode::loadString(text, source, &raiseVisionError);
}

/// A camera mount ({translation, rotation_matrix}, the format of camera_mount.yaml) at `node`.
CameraMount readCameraMount(const ConfigNode& node);

inline std::string fmt(double v) {
  std::ostringstream os;
  os.precision(10);
  os << v;
  return os.str();
}

}  // namespace reflex::vision::detail
