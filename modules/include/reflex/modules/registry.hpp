// Module registry: module type name -> factory. A configuration names types; the host asks the
// registry for instances. builtinRegistry() has every module of this folder; a program with its own
// modules adds them with add() before building the host (no static-initialization tricks, so a
// module in a static library is never silently dropped by the linker).
#pragma once

#include "reflex/modules/module.hpp"

#include <functional>
#include <map>
#include <memory>
#include <string>
#include <vector>

namespace reflex::modules {

using ModuleFactory = std::function<std::unique_ptr<Module>(const std::string& instance_name)>;

class ModuleRegistry {
 public:
  /// Registers `type`. Throws ConfigError if the type is empty or already registered.
  void add(const std::string& type, const std::string& summary, ModuleFactory factory);
  bool has(const std::string& type) const { return entries_.count(type) > 0; }
  /// A new, unconfigured module. Throws ConfigError "unknown module type '<type>' (known: ...)".
  std::unique_ptr<Module> create(const std::string& type, const std::string& instance_name) const;
  std::vector<std::string> types() const;
  std::string summary(const std::string& type) const;
  /// "a, b, c" for messages.
  std::string typeList() const;
  /// Moves every type of `other` into this registry. Throws ConfigError on a type registered in both.
  void merge(ModuleRegistry&& other);

 private:
  struct Entry {
    std::string summary;
    ModuleFactory factory;
  };
  std::map<std::string, Entry> entries_;
};

/// A registry with the built-in modules: pointing, scripted, grasped_bar, occlusion, walking.
ModuleRegistry builtinRegistry();

}  // namespace reflex::modules
