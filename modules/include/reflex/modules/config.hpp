// Reading module and process configuration from YAML, with errors that say where.
//
// A ConfigNode is a YAML map plus its origin (file and key path, e.g. "modules[0].config"). Every
// getter validates type and range and throws ConfigError with "<file>:<line>: <path>.<key>: <what>
// '<value>'" so that a bad value is found without reading code. Unknown keys are errors too
// (rejectUnknown): a typo never silently falls back to a default.
#pragma once

#include <Eigen/Core>
#include <yaml-cpp/yaml.h>

#include <initializer_list>
#include <stdexcept>
#include <string>
#include <vector>

namespace reflex::modules {

/// Every set-up error of the behavior layer (configuration, unknown module, robot links).
class ConfigError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

class ConfigNode {
 public:
  /// Wraps `node` (a map, or null = empty map) read from `file` at key path `path` ("" = document root).
  ConfigNode(YAML::Node node, std::string file, std::string path);
  /// Parses a YAML file whose root is a map. Throws ConfigError naming the file (missing, syntax, not a map).
  static ConfigNode loadFile(const std::string& path);
  /// Parses YAML text; `origin` stands for the file name in messages.
  static ConfigNode loadString(const std::string& text, const std::string& origin);

  bool has(const std::string& key) const;
  /// Optional number in [lo, hi] (finite); `def` if absent.
  double number(const std::string& key, double def, double lo, double hi) const;
  /// Required number in [lo, hi].
  double requiredNumber(const std::string& key, double lo, double hi) const;
  /// Optional integer in [lo, hi].
  int integer(const std::string& key, int def, int lo, int hi) const;
  bool boolean(const std::string& key, bool def) const;
  /// Optional non-empty string.
  std::string string(const std::string& key, const std::string& def) const;
  /// Optional string that must be one of `allowed`.
  std::string choice(const std::string& key, const std::string& def,
                     std::initializer_list<const char*> allowed) const;
  /// Optional [x, y, z] of finite numbers.
  Eigen::Vector3d vec3(const std::string& key, const Eigen::Vector3d& def) const;
  /// Optional list of non-empty strings (a scalar is taken as a one-element list).
  std::vector<std::string> strings(const std::string& key, const std::vector<std::string>& def) const;
  /// A nested map (absent = empty map).
  ConfigNode child(const std::string& key) const;
  /// A list of maps (absent = empty list); each element's path is "<key>[i]".
  std::vector<ConfigNode> list(const std::string& key) const;
  /// The raw YAML value (undefined if absent), for modules with their own formats.
  YAML::Node raw(const std::string& key) const;
  /// Throws ConfigError naming the first key that is not in `allowed`.
  void rejectUnknown(std::initializer_list<const char*> allowed) const;

  /// A path given in this file, resolved against the file's folder unless absolute.
  std::string resolvePath(const std::string& relative) const;
  /// "<file>:<line>: <path>.<key>" for messages (line of the key's value if present).
  std::string where(const std::string& key) const;
  /// Throws ConfigError "<where(key)>: <what> '<value as text>'".
  [[noreturn]] void fail(const std::string& key, const std::string& what) const;

  const std::string& file() const { return file_; }
  const std::string& path() const { return path_; }
  const YAML::Node& node() const { return node_; }

 private:
  std::string keyPath(const std::string& key) const;
  std::string valueText(const std::string& key) const;

  YAML::Node node_;
  std::string file_;
  std::string path_;
};

/// The text of a YAML value for error messages (scalars as written, others in flow style).
std::string yamlText(const YAML::Node& node);

}  // namespace reflex::modules
