// The one YAML configuration reader of the project: controller.yaml, collision.yaml, the fit overlay,
// behavior.yaml (every module type's config), and vision's session manifest, camera calibration,
// camera mount, object map and session spec all read through ConfigNode.
//
// A ConfigNode is a YAML value (map, list or scalar) plus where it came from: the file and its key
// path from the document root ("arms.left.rest", "modules[0].config.gain", "links.l_hand.primitives[1]").
// Every getter checks kind and range and throws, through the layer's own error type (`Raise`:
// control::ConfigError, control::ModelError, vision::VisionError, common::ConfigError), ONE format:
//
//   FILE:LINE:COL: KEY.PATH: PROBLEM (value 'TEXT', expected EXPECTED)
//
//   LINE:COL   1-based position of the value in the file; of the enclosing map when the key is missing
//   KEY.PATH   the full key path ("(document)" for the root)
//   TEXT       the value as written (a scalar verbatim, anything else in flow style, cut at 60 chars)
//   EXPECTED   what would have been accepted (a range with its unit, a list of names, a shape)
//
// A missing required key reads "... KEY.PATH: missing (expected EXPECTED)"; an unknown key reads
// "... KEY.PATH: unknown key (expected one of a, b, c)" (a typo never falls back to a default).
// File-level errors: "FILE: <why it cannot be read>" and "FILE:LINE:COL: YAML syntax error: <msg>".
// control/docs/configuration.md ("Error messages") is the reference for users.
#pragma once

#include "reflex/common/error.hpp"
#include <Eigen/Core>
#include <yaml-cpp/yaml.h>

#include <initializer_list>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

namespace reflex::common {

/// The text of a YAML value for error messages: a scalar as written, anything else in flow style,
/// cut at 60 characters ("..."); "" for an absent or null value.
std::string yamlText(const YAML::Node& node);

/// `v` as the shortest text that reads back to it ("0.05", "1e-06").
std::string numberText(double v);

class ConfigNode {
 public:
  /// Throws the layer's error with `message`; must not return (ConfigNode aborts if it does).
  using Raise = void (*)(const std::string& message);
  [[noreturn]] static void raiseConfigError(const std::string& message);

  /// Wraps `node` read from `file` at key path `path` ("" = the document root).
  ConfigNode(YAML::Node node, std::string file, std::string path, Raise raise = &raiseConfigError);
  /// Parses a YAML file whose root is a map (an empty file is an empty map if `allow_empty`).
  /// `what` names the file's kind in the messages of a file that cannot be read ("controller configuration").
  static ConfigNode loadFile(const std::string& path, const std::string& what = "configuration file",
                             Raise raise = &raiseConfigError, bool allow_empty = false);
  /// Parses YAML text; `origin` stands for the file name in messages.
  static ConfigNode loadString(const std::string& text, const std::string& origin, Raise raise = &raiseConfigError,
                               bool allow_empty = false);

  // ---- this value (a list element, a free-named map entry, a document)
  bool isMap() const { return node_.IsMap(); }
  bool isList() const { return node_.IsSequence(); }
  bool isScalar() const { return node_.IsScalar(); }
  /// A finite number in [lo, hi] (`unit` is printed after the range in messages).
  double asNumber(double lo, double hi, const std::string& unit = "") const;
  int asInteger(int lo, int hi) const;
  bool asBoolean() const;
  /// A non-empty scalar.
  std::string asString() const;
  /// A list of finite numbers; exactly `count` of them unless count == 0 (`shape` names it in messages,
  /// e.g. "[x, y, z] of finite numbers"; default "a list of N finite numbers").
  std::vector<double> asNumbers(std::size_t count = 0, const std::string& shape = "") const;
  /// The elements of a list (any kind); each element's path is "<path>[i]".
  std::vector<ConfigNode> elements() const;
  /// The entries of a map (any kind) with their keys, in file order; each entry's path is "<path>.<key>".
  std::vector<std::pair<std::string, ConfigNode>> entries() const;
  /// Throws unless this value is a map ("not a map", expected `expected`).
  void requireMap(const std::string& expected = "a map of keys") const;

  // ---- keys of this map (absent or null = not given)
  bool has(const std::string& key) const;
  /// The value under `key` (any kind); a missing key is an error naming `expected`.
  ConfigNode at(const std::string& key, const std::string& expected) const;
  /// Optional number in [lo, hi] (finite); `def` if absent.
  double number(const std::string& key, double def, double lo, double hi, const std::string& unit = "") const;
  /// Required number in [lo, hi].
  double requiredNumber(const std::string& key, double lo, double hi, const std::string& unit = "") const;
  /// Optional integer in [lo, hi].
  int integer(const std::string& key, int def, int lo, int hi) const;
  bool boolean(const std::string& key, bool def) const;
  /// Optional non-empty string.
  std::string string(const std::string& key, const std::string& def) const;
  /// Required non-empty string.
  std::string requiredString(const std::string& key, const std::string& expected = "a non-empty string") const;
  /// Optional string that must be one of `allowed`.
  std::string choice(const std::string& key, const std::string& def, std::initializer_list<const char*> allowed) const;
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
  /// Throws naming the first key that is not in `allowed` ("unknown key (expected one of ...)").
  void rejectUnknown(std::initializer_list<const char*> allowed) const;
  void rejectUnknown(const std::vector<std::string>& allowed) const;

  /// A path given in this file, resolved against the file's folder unless absolute.
  std::string resolvePath(const std::string& relative) const;
  /// "FILE:LINE:COL: KEY.PATH" of `key` (the key's value if present, else this map).
  std::string where(const std::string& key) const;
  /// "FILE:LINE:COL: PATH" of this value.
  std::string where() const;
  /// Throws "<where(key)>: <problem> (value 'V', expected <expected>)" (no value part when the key is
  /// absent, no expected part when `expected` is empty).
  [[noreturn]] void fail(const std::string& key, const std::string& problem, const std::string& expected = "") const;
  /// The same for this value.
  [[noreturn]] void failHere(const std::string& problem, const std::string& expected = "") const;
  /// Throws "<where(key)>: <problem>" (a message that is not about one value, e.g. "give exactly one of a, b").
  [[noreturn]] void failAt(const std::string& key, const std::string& problem) const;
  /// Throws `message` through this reader's error type.
  [[noreturn]] void raise(const std::string& message) const;

  const std::string& file() const { return file_; }
  const std::string& path() const { return path_; }
  const YAML::Node& node() const { return node_; }
  Raise raiser() const { return raise_; }

 private:
  ConfigNode item(const std::string& key) const;
  /// The value's position; for an absent map (child of a missing key), the parent's.
  YAML::Mark mark() const;
  std::string keyPath(const std::string& key) const;

  YAML::Node node_;
  std::string file_;
  std::string path_;
  Raise raise_;
  YAML::Mark absent_mark_ = YAML::Mark::null_mark();
};

/// "[lo, hi]" (with " unit" if given) for messages.
std::string rangeText(double lo, double hi, const std::string& unit = "");

}  // namespace reflex::common
