#include "reflex/common/yaml_reader.hpp"

#include "reflex/common/files.hpp"

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <functional>
#include <limits>
#include <sstream>

namespace reflex::common {

std::string yamlText(const YAML::Node& node) {
  if (!node.IsDefined() || node.IsNull()) return "";
  std::string s;
  if (node.IsScalar()) {
    s = node.Scalar();
  } else {
    // Flow style all the way down (a block list inside a flow map would break the one line).
    const std::function<void(YAML::Node)> flow = [&](YAML::Node n) {
      n.SetStyle(YAML::EmitterStyle::Flow);
      if (n.IsSequence())
        for (auto e : n) flow(e);
      else if (n.IsMap())
        for (auto kv : n) flow(kv.second);
    };
    YAML::Node copy = YAML::Clone(node);
    flow(copy);
    YAML::Emitter out;
    out << YAML::Flow << copy;
    s = out.c_str();
  }
  if (s.size() > 60) s = s.substr(0, 57) + "...";
  return s;
}

std::string numberText(double v) {
  for (int precision = 6; precision <= 17; ++precision) {
    char buf[40];
    std::snprintf(buf, sizeof buf, "%.*g", precision, v);
    if (std::strtod(buf, nullptr) == v || !std::isfinite(v)) return buf;
  }
  return std::to_string(v);
}

namespace {
/// What a number getter accepts: "a number in [lo, hi] unit", or "a finite number" when unbounded.
std::string numberExpected(double lo, double hi, const std::string& unit) {
  const double kMax = std::numeric_limits<double>::max();
  if (lo <= -kMax && hi >= kMax) return unit.empty() ? "a finite number" : "a finite number (" + unit + ")";
  return "a number in " + rangeText(lo, hi, unit);
}
}  // namespace

std::string rangeText(double lo, double hi, const std::string& unit) {
  return "[" + numberText(lo) + ", " + numberText(hi) + "]" + (unit.empty() ? "" : " " + unit);
}

namespace {

std::string markText(const YAML::Mark& m) {
  if (m.is_null() || m.line < 0) return "";
  return ":" + std::to_string(m.line + 1) + ":" + std::to_string(m.column + 1);
}

bool parseDouble(const YAML::Node& n, double& out) {
  if (!n.IsScalar()) return false;
  try {
    out = n.as<double>();
  } catch (const YAML::Exception&) {
    return false;
  }
  return true;
}

std::string joined(const std::vector<std::string>& names) {
  std::string list;
  for (const auto& a : names) list += (list.empty() ? "" : ", ") + a;
  return list;
}

ConfigNode parsed(const std::function<YAML::Node()>& load, const std::string& origin, ConfigNode::Raise raise,
                  bool allow_empty) {
  YAML::Node root;
  try {
    root = load();
  } catch (const YAML::ParserException& e) {
    raise(origin + markText(e.mark) + ": YAML syntax error: " + e.msg);
  } catch (const YAML::Exception& e) {
    raise(origin + ": YAML syntax error: " + e.what());
  }
  ConfigNode doc(root, origin, "", raise);
  if (allow_empty && (!root.IsDefined() || root.IsNull())) return doc;
  if (!root.IsMap()) doc.failHere("not a map of keys", "a map of keys at the top level");
  return doc;
}

}  // namespace

void ConfigNode::raiseConfigError(const std::string& message) { throw ConfigError(message); }

ConfigNode::ConfigNode(YAML::Node node, std::string file, std::string path, Raise raise)
    : node_(std::move(node)), file_(std::move(file)), path_(std::move(path)), raise_(raise) {}

ConfigNode ConfigNode::loadFile(const std::string& path, const std::string& what, Raise raise, bool allow_empty) {
  // A path the system refuses (a FIFO or device would block or never end, a name longer than NAME_MAX)
  // is the same set-up error as a missing file.
  if (const std::string why = inputFileProblem(path); !why.empty()) raise(what + " " + why);
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec))
    raise(path + ": cannot open " + what + " (" + (ec ? ec.message() : "not a regular file") + ")");
  return parsed([&] { return YAML::LoadFile(path); }, path, raise, allow_empty);
}

ConfigNode ConfigNode::loadString(const std::string& text, const std::string& origin, Raise raise, bool allow_empty) {
  return parsed([&] { return YAML::Load(text); }, origin, raise, allow_empty);
}

void ConfigNode::raise(const std::string& message) const {
  raise_(message);
  std::abort();  // a Raise that returns is a programming error
}

// ---- messages

std::string ConfigNode::keyPath(const std::string& key) const { return path_.empty() ? key : path_ + "." + key; }

YAML::Mark ConfigNode::mark() const {
  return node_.IsDefined() && !node_.Mark().is_null() ? node_.Mark() : absent_mark_;
}

std::string ConfigNode::where() const {
  return file_ + markText(mark()) + ": " + (path_.empty() ? "(document)" : path_);
}

std::string ConfigNode::where(const std::string& key) const {
  YAML::Mark m = mark();
  if (has(key)) m = node_[key].Mark();
  return file_ + markText(m) + ": " + keyPath(key);
}

void ConfigNode::fail(const std::string& key, const std::string& problem, const std::string& expected) const {
  std::vector<std::string> detail;
  if (has(key)) detail.push_back("value '" + yamlText(node_[key]) + "'");
  if (!expected.empty()) detail.push_back("expected " + expected);
  raise(where(key) + ": " + problem + (detail.empty() ? "" : " (" + joined(detail) + ")"));
}

void ConfigNode::failHere(const std::string& problem, const std::string& expected) const {
  std::string detail = "value '" + yamlText(node_) + "'";
  if (!expected.empty()) detail += ", expected " + expected;
  raise(where() + ": " + problem + " (" + detail + ")");
}

void ConfigNode::failAt(const std::string& key, const std::string& problem) const {
  raise(where(key) + ": " + problem);
}

// ---- this value

double ConfigNode::asNumber(double lo, double hi, const std::string& unit) const {
  double v = 0.0;
  const std::string expected = numberExpected(lo, hi, unit);
  if (!parseDouble(node_, v) || !std::isfinite(v)) failHere("not a finite number", expected);
  if (v < lo || v > hi) failHere("out of range", expected);
  return v;
}

int ConfigNode::asInteger(int lo, int hi) const {
  const std::string expected = "an integer in " + rangeText(lo, hi);
  int v = 0;
  bool ok = node_.IsScalar();
  if (ok) {
    try {
      v = node_.as<int>();
    } catch (const YAML::Exception&) {
      ok = false;
    }
  }
  if (!ok) failHere("not an integer", expected);
  if (v < lo || v > hi) failHere("out of range", expected);
  return v;
}

bool ConfigNode::asBoolean() const {
  bool ok = node_.IsScalar();
  bool v = false;
  if (ok) {
    try {
      v = node_.as<bool>();
    } catch (const YAML::Exception&) {
      ok = false;
    }
  }
  if (!ok) failHere("not true or false", "true or false");
  return v;
}

std::string ConfigNode::asString() const {
  if (!node_.IsScalar() || node_.Scalar().empty()) failHere("not a name", "a non-empty string");
  return node_.Scalar();
}

std::vector<double> ConfigNode::asNumbers(std::size_t count, const std::string& shape) const {
  const std::string expected = !shape.empty() ? shape
                               : count == 0   ? "a list of finite numbers"
                                              : "a list of " + std::to_string(count) + " finite numbers";
  if (!node_.IsSequence()) failHere("not a list of numbers", expected);
  if (count != 0 && node_.size() != count) failHere("has " + std::to_string(node_.size()) + " numbers", expected);
  std::vector<double> out(node_.size());
  for (std::size_t i = 0; i < node_.size(); ++i)
    if (!parseDouble(node_[i], out[i]) || !std::isfinite(out[i]))
      ConfigNode(node_[i], file_, path_ + "[" + std::to_string(i) + "]", raise_)
          .failHere("not a finite number", expected);
  return out;
}

std::vector<ConfigNode> ConfigNode::elements() const {
  if (!node_.IsSequence()) failHere("not a list", "a list");
  std::vector<ConfigNode> out;
  for (std::size_t i = 0; i < node_.size(); ++i)
    out.emplace_back(node_[i], file_, path_ + "[" + std::to_string(i) + "]", raise_);
  return out;
}

std::vector<std::pair<std::string, ConfigNode>> ConfigNode::entries() const {
  std::vector<std::pair<std::string, ConfigNode>> out;
  if (!node_.IsDefined() || node_.IsNull()) return out;
  requireMap();
  for (const auto& kv : node_) {
    if (!kv.first.IsScalar() || kv.first.Scalar().empty())
      raise(file_ + markText(kv.first.Mark()) + ": " + keyPath(yamlText(kv.first)) + ": a key must be a name (value '" +
            yamlText(kv.first) + "', expected a non-empty string)");
    out.emplace_back(kv.first.Scalar(), ConfigNode(kv.second, file_, keyPath(kv.first.Scalar()), raise_));
  }
  return out;
}

void ConfigNode::requireMap(const std::string& expected) const {
  if (!node_.IsMap()) failHere("not a map", expected);
}

// ---- keys of this map

bool ConfigNode::has(const std::string& key) const {
  return node_.IsMap() && node_[key].IsDefined() && !node_[key].IsNull();
}

ConfigNode ConfigNode::item(const std::string& key) const {
  return ConfigNode(node_[key], file_, keyPath(key), raise_);
}

ConfigNode ConfigNode::at(const std::string& key, const std::string& expected) const {
  if (!node_.IsMap()) failHere("not a map", "a map with the key '" + key + "'");
  if (!has(key)) fail(key, "missing", expected);
  return item(key);
}

double ConfigNode::number(const std::string& key, double def, double lo, double hi, const std::string& unit) const {
  return has(key) ? item(key).asNumber(lo, hi, unit) : def;
}

double ConfigNode::requiredNumber(const std::string& key, double lo, double hi, const std::string& unit) const {
  return at(key, numberExpected(lo, hi, unit)).asNumber(lo, hi, unit);
}

int ConfigNode::integer(const std::string& key, int def, int lo, int hi) const {
  return has(key) ? item(key).asInteger(lo, hi) : def;
}

bool ConfigNode::boolean(const std::string& key, bool def) const { return has(key) ? item(key).asBoolean() : def; }

std::string ConfigNode::string(const std::string& key, const std::string& def) const {
  return has(key) ? item(key).asString() : def;
}

std::string ConfigNode::requiredString(const std::string& key, const std::string& expected) const {
  return at(key, expected).asString();
}

std::string ConfigNode::choice(const std::string& key, const std::string& def,
                               std::initializer_list<const char*> allowed) const {
  const std::string v = string(key, def);
  std::vector<std::string> names;
  for (const char* a : allowed) {
    if (v == a) return v;
    names.emplace_back(a);
  }
  fail(key, "unknown value", "one of " + joined(names));
}

Eigen::Vector3d ConfigNode::vec3(const std::string& key, const Eigen::Vector3d& def) const {
  if (!has(key)) return def;
  const std::vector<double> v = item(key).asNumbers(3, "[x, y, z] of finite numbers");
  return Eigen::Vector3d(v[0], v[1], v[2]);
}

std::vector<std::string> ConfigNode::strings(const std::string& key, const std::vector<std::string>& def) const {
  if (!has(key)) return def;
  const YAML::Node n = node_[key];
  std::vector<std::string> out;
  if (n.IsScalar()) {
    out.push_back(n.Scalar());
  } else if (n.IsSequence()) {
    for (const auto& e : n) {
      if (!e.IsScalar()) fail(key, "not a list of names", "a list of names");
      out.push_back(e.Scalar());
    }
  } else {
    fail(key, "not a list of names", "a list of names");
  }
  for (const auto& s : out)
    if (s.empty()) fail(key, "holds an empty name", "a list of non-empty names");
  return out;
}

ConfigNode ConfigNode::child(const std::string& key) const {
  if (!has(key)) {  // an empty map; a missing key inside it is placed at this map
    ConfigNode absent(YAML::Node(), file_, keyPath(key), raise_);
    absent.absent_mark_ = mark();
    return absent;
  }
  if (!node_[key].IsMap()) fail(key, "not a map", "a map of keys");
  return item(key);
}

std::vector<ConfigNode> ConfigNode::list(const std::string& key) const {
  if (!has(key)) return {};
  std::vector<ConfigNode> out = item(key).elements();
  for (const ConfigNode& e : out) e.requireMap();
  return out;
}

YAML::Node ConfigNode::raw(const std::string& key) const {
  if (!node_.IsMap()) return YAML::Node(YAML::NodeType::Undefined);
  return node_[key];
}

void ConfigNode::rejectUnknown(std::initializer_list<const char*> allowed) const {
  rejectUnknown(std::vector<std::string>(allowed.begin(), allowed.end()));
}

void ConfigNode::rejectUnknown(const std::vector<std::string>& allowed) const {
  for (const auto& entry : entries()) {
    const std::string& k = entry.first;  // not a structured binding: clang (C++17) cannot capture one below
    bool ok = false;
    for (const auto& a : allowed) ok |= k == a;
    if (!ok) {
      const YAML::Node key_node = [&] {
        for (const auto& kv : node_)
          if (kv.first.Scalar() == k) return kv.first;
        return YAML::Node();
      }();
      raise(file_ + markText(key_node.Mark()) + ": " + keyPath(k) + ": unknown key (expected one of " +
            joined(allowed) + ")");
    }
  }
}

std::string ConfigNode::resolvePath(const std::string& relative) const {
  const std::filesystem::path p(relative);
  if (p.is_absolute() || file_.empty()) return p.lexically_normal().string();
  return (std::filesystem::path(file_).parent_path() / p).lexically_normal().string();
}

}  // namespace reflex::common
