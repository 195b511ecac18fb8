#include "reflex/modules/config.hpp"

#include "reflex/common/files.hpp"
#include <cmath>
#include <filesystem>
#include <sstream>

namespace reflex::modules {

std::string yamlText(const YAML::Node& node) {
  if (!node.IsDefined() || node.IsNull()) return "";
  if (node.IsScalar()) return node.Scalar();
  YAML::Emitter out;
  out << YAML::Flow << node;
  return out.c_str();
}

ConfigNode::ConfigNode(YAML::Node node, std::string file, std::string path)
    : node_(std::move(node)), file_(std::move(file)), path_(std::move(path)) {
  if (node_.IsDefined() && !node_.IsNull() && !node_.IsMap()) {
    std::ostringstream m;
    m << file_ << ":" << node_.Mark().line + 1 << ": " << (path_.empty() ? "<document>" : path_)
      << ": expected a map of keys, got '" << yamlText(node_) << "'";
    throw ConfigError(m.str());
  }
}

ConfigNode ConfigNode::loadFile(const std::string& path) {
  // The error_code overload: a path the system refuses (a name longer than NAME_MAX, ...) is the
  // same set-up error as a missing file, not a std::filesystem_error without the key's context.
  if (const std::string why = common::inputFileProblem(path); !why.empty())
    throw ConfigError("configuration file " + why);  // a FIFO or device would block or never end
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec))
    throw ConfigError("configuration file '" + path + "' does not exist" + (ec ? " (" + ec.message() + ")" : ""));
  YAML::Node root;
  try {
    root = YAML::LoadFile(path);
  } catch (const YAML::Exception& e) {
    throw ConfigError(path + ":" + std::to_string(e.mark.line + 1) + ": YAML syntax error: " + e.msg);
  }
  if (!root.IsMap()) throw ConfigError(path + ": the configuration must be a map of keys, got '" + yamlText(root) + "'");
  return ConfigNode(root, path, "");
}

ConfigNode ConfigNode::loadString(const std::string& text, const std::string& origin) {
  YAML::Node root;
  try {
    root = YAML::Load(text);
  } catch (const YAML::Exception& e) {
    throw ConfigError(origin + ":" + std::to_string(e.mark.line + 1) + ": YAML syntax error: " + e.msg);
  }
  if (!root.IsMap()) throw ConfigError(origin + ": the configuration must be a map of keys, got '" + yamlText(root) + "'");
  return ConfigNode(root, origin, "");
}

bool ConfigNode::has(const std::string& key) const {
  return node_.IsMap() && node_[key].IsDefined() && !node_[key].IsNull();
}

std::string ConfigNode::keyPath(const std::string& key) const { return path_.empty() ? key : path_ + "." + key; }

std::string ConfigNode::valueText(const std::string& key) const { return has(key) ? yamlText(node_[key]) : ""; }

std::string ConfigNode::where(const std::string& key) const {
  int line = node_.IsDefined() ? node_.Mark().line + 1 : 0;
  if (has(key)) line = node_[key].Mark().line + 1;
  std::ostringstream m;
  m << file_;
  if (line > 0) m << ":" << line;
  m << ": " << keyPath(key);
  return m.str();
}

void ConfigNode::fail(const std::string& key, const std::string& what) const {
  throw ConfigError(where(key) + ": " + what + " '" + valueText(key) + "'");
}

namespace {
std::string rangeText(double lo, double hi) {
  std::ostringstream m;
  m << "[" << lo << ", " << hi << "]";
  return m.str();
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
}  // namespace

double ConfigNode::number(const std::string& key, double def, double lo, double hi) const {
  if (!has(key)) return def;
  double v = 0.0;
  if (!parseDouble(node_[key], v) || !std::isfinite(v)) fail(key, "expected a number in " + rangeText(lo, hi) + ", got");
  if (v < lo || v > hi) fail(key, "out of range " + rangeText(lo, hi) + ":");
  return v;
}

double ConfigNode::requiredNumber(const std::string& key, double lo, double hi) const {
  if (!has(key)) throw ConfigError(where(key) + ": required key missing (a number in " + rangeText(lo, hi) + ")");
  return number(key, 0.0, lo, hi);
}

int ConfigNode::integer(const std::string& key, int def, int lo, int hi) const {
  if (!has(key)) return def;
  int v = 0;
  bool ok = node_[key].IsScalar();
  if (ok) {
    try {
      v = node_[key].as<int>();
    } catch (const YAML::Exception&) {
      ok = false;
    }
  }
  if (!ok) fail(key, "expected an integer in " + rangeText(lo, hi) + ", got");
  if (v < lo || v > hi) fail(key, "out of range " + rangeText(lo, hi) + ":");
  return v;
}

bool ConfigNode::boolean(const std::string& key, bool def) const {
  if (!has(key)) return def;
  bool ok = node_[key].IsScalar();
  bool v = false;
  if (ok) {
    try {
      v = node_[key].as<bool>();
    } catch (const YAML::Exception&) {
      ok = false;
    }
  }
  if (!ok) fail(key, "expected true or false, got");
  return v;
}

std::string ConfigNode::string(const std::string& key, const std::string& def) const {
  if (!has(key)) return def;
  if (!node_[key].IsScalar() || node_[key].Scalar().empty()) fail(key, "expected a non-empty string, got");
  return node_[key].Scalar();
}

std::string ConfigNode::choice(const std::string& key, const std::string& def,
                               std::initializer_list<const char*> allowed) const {
  const std::string v = string(key, def);
  std::string list;
  for (const char* a : allowed) {
    if (v == a) return v;
    list += (list.empty() ? "" : ", ") + std::string(a);
  }
  fail(key, "expected one of {" + list + "}, got");
}

Eigen::Vector3d ConfigNode::vec3(const std::string& key, const Eigen::Vector3d& def) const {
  if (!has(key)) return def;
  const YAML::Node n = node_[key];
  Eigen::Vector3d v;
  if (!n.IsSequence() || n.size() != 3) fail(key, "expected [x, y, z] (3 numbers), got");
  for (int i = 0; i < 3; ++i) {
    if (!parseDouble(n[i], v[i]) || !std::isfinite(v[i])) fail(key, "expected [x, y, z] of finite numbers, got");
  }
  return v;
}

std::vector<std::string> ConfigNode::strings(const std::string& key, const std::vector<std::string>& def) const {
  if (!has(key)) return def;
  const YAML::Node n = node_[key];
  std::vector<std::string> out;
  if (n.IsScalar()) {
    out.push_back(n.Scalar());
  } else if (n.IsSequence()) {
    for (const auto& e : n) {
      if (!e.IsScalar()) fail(key, "expected a list of names, got");
      out.push_back(e.Scalar());
    }
  } else {
    fail(key, "expected a list of names, got");
  }
  for (const auto& s : out)
    if (s.empty()) fail(key, "empty name in");
  return out;
}

ConfigNode ConfigNode::child(const std::string& key) const {
  if (!has(key)) return ConfigNode(YAML::Node(), file_, keyPath(key));
  if (!node_[key].IsMap()) fail(key, "expected a map of keys, got");
  return ConfigNode(node_[key], file_, keyPath(key));
}

std::vector<ConfigNode> ConfigNode::list(const std::string& key) const {
  std::vector<ConfigNode> out;
  if (!has(key)) return out;
  const YAML::Node n = node_[key];
  if (!n.IsSequence()) fail(key, "expected a list, got");
  for (std::size_t i = 0; i < n.size(); ++i) {
    const std::string p = keyPath(key) + "[" + std::to_string(i) + "]";
    if (!n[i].IsMap()) {
      throw ConfigError(file_ + ":" + std::to_string(n[i].Mark().line + 1) + ": " + p +
                        ": expected a map of keys, got '" + yamlText(n[i]) + "'");
    }
    out.emplace_back(n[i], file_, p);
  }
  return out;
}

YAML::Node ConfigNode::raw(const std::string& key) const {
  if (!node_.IsMap()) return YAML::Node(YAML::NodeType::Undefined);
  return node_[key];
}

void ConfigNode::rejectUnknown(std::initializer_list<const char*> allowed) const {
  if (!node_.IsMap()) return;
  for (const auto& kv : node_) {
    const std::string k = kv.first.IsScalar() ? kv.first.Scalar() : yamlText(kv.first);
    bool ok = false;
    std::string list;
    for (const char* a : allowed) {
      ok |= k == a;
      list += (list.empty() ? "" : ", ") + std::string(a);
    }
    if (!ok) {
      throw ConfigError(file_ + ":" + std::to_string(kv.first.Mark().line + 1) + ": " + keyPath(k) +
                        ": unknown key '" + k + "' (known keys: " + list + ")");
    }
  }
}

std::string ConfigNode::resolvePath(const std::string& relative) const {
  const std::filesystem::path p(relative);
  if (p.is_absolute() || file_.empty()) return p.lexically_normal().string();
  return (std::filesystem::path(file_).parent_path() / p).lexically_normal().string();
}

}  // namespace reflex::modules
