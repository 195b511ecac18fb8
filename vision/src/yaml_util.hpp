#pragma once
// Internal helpers for reading YAML setup files with errors that name the file and field.
#include "reflex/vision/error.hpp"
#include "reflex/common/files.hpp"

#include <yaml-cpp/yaml.h>

#include <cmath>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

namespace reflex::vision::detail {

inline std::string readTextFile(const std::string& path, const std::string& what) {
  if (const std::string why = common::inputFileProblem(path); !why.empty())
    throw VisionError(what + " file " + why);  // a FIFO or device would block or never end
  std::ifstream in(path, std::ios::binary);
  if (!in) throw VisionError("cannot open " + what + " file '" + path + "'");
  std::ostringstream os;
  os << in.rdbuf();
  return os.str();
}

inline YAML::Node parseYaml(const std::string& text, const std::string& source) {
  try {
    YAML::Node root = YAML::Load(text);
    if (!root.IsMap()) throw VisionError(source + ": expected a YAML mapping at the top level");
    return root;
  } catch (const YAML::Exception& e) {
    throw VisionError(source + ": YAML syntax error: " + e.what());
  }
}

inline YAML::Node require(const YAML::Node& parent, const std::string& key, const std::string& where) {
  if (!parent.IsMap())  // indexing a scalar or a list throws a raw YAML::BadSubscript (fuzz finding)
    throw VisionError(where + ": expected a mapping with the field '" + key + "', got '" + YAML::Dump(parent) + "'");
  const YAML::Node n = parent[key];
  if (!n || n.IsNull()) throw VisionError(where + ": missing field '" + key + "'");
  return n;
}

inline std::string dumpShort(const YAML::Node& n) {
  std::string s = YAML::Dump(n);
  if (s.size() > 60) s = s.substr(0, 57) + "...";
  return s;
}

inline double asDouble(const YAML::Node& n, const std::string& where) {
  double v = 0.0;
  try {
    v = n.as<double>();
  } catch (const YAML::Exception&) {
    throw VisionError(where + ": expected a number, got '" + dumpShort(n) + "'");
  }
  if (!std::isfinite(v)) throw VisionError(where + ": value '" + dumpShort(n) + "' is not finite");
  return v;
}

inline int asInt(const YAML::Node& n, const std::string& where) {
  try {
    return n.as<int>();
  } catch (const YAML::Exception&) {
    throw VisionError(where + ": expected an integer, got '" + dumpShort(n) + "'");
  }
}

inline std::string asString(const YAML::Node& n, const std::string& where) {
  if (!n.IsScalar()) throw VisionError(where + ": expected a string, got '" + dumpShort(n) + "'");
  return n.as<std::string>();
}

inline bool asBool(const YAML::Node& n, const std::string& where) {
  try {
    return n.as<bool>();
  } catch (const YAML::Exception&) {
    throw VisionError(where + ": expected true/false, got '" + dumpShort(n) + "'");
  }
}

inline std::vector<double> asDoubles(const YAML::Node& n, const std::string& where) {
  if (!n.IsSequence()) throw VisionError(where + ": expected a list of numbers, got '" + dumpShort(n) + "'");
  std::vector<double> out;
  for (std::size_t i = 0; i < n.size(); ++i) out.push_back(asDouble(n[i], where + "[" + std::to_string(i) + "]"));
  return out;
}

inline std::vector<double> asDoublesN(const YAML::Node& n, std::size_t count, const std::string& where) {
  std::vector<double> v = asDoubles(n, where);
  if (v.size() != count)
    throw VisionError(where + ": expected " + std::to_string(count) + " numbers, got " + std::to_string(v.size()));
  return v;
}

inline std::string fmt(double v) {
  std::ostringstream os;
  os.precision(10);
  os << v;
  return os.str();
}

}  // namespace reflex::vision::detail
