#include "reflex/modules/registry.hpp"

#include "reflex/modules/body_schema.hpp"
#include "reflex/modules/pointing.hpp"
#include "reflex/modules/scripted.hpp"

namespace reflex::modules {

void ModuleRegistry::add(const std::string& type, const std::string& summary, ModuleFactory factory) {
  if (type.empty()) throw ConfigError("module registry: empty module type name");
  if (!factory) throw ConfigError("module registry: no factory for module type '" + type + "'");
  if (!entries_.emplace(type, Entry{summary, std::move(factory)}).second)
    throw ConfigError("module registry: module type '" + type + "' registered twice");
}

std::unique_ptr<Module> ModuleRegistry::create(const std::string& type, const std::string& instance_name) const {
  auto it = entries_.find(type);
  if (it == entries_.end()) throw ConfigError("unknown module type '" + type + "' (known: " + typeList() + ")");
  return it->second.factory(instance_name);
}

std::vector<std::string> ModuleRegistry::types() const {
  std::vector<std::string> out;
  for (const auto& kv : entries_) out.push_back(kv.first);
  return out;
}

std::string ModuleRegistry::summary(const std::string& type) const {
  auto it = entries_.find(type);
  return it == entries_.end() ? std::string() : it->second.summary;
}

std::string ModuleRegistry::typeList() const {
  std::string out;
  for (const auto& kv : entries_) out += (out.empty() ? "" : ", ") + kv.first;
  return out;
}

void ModuleRegistry::merge(ModuleRegistry&& other) {
  for (auto& kv : other.entries_) add(kv.first, kv.second.summary, std::move(kv.second.factory));
  other.entries_.clear();
}

namespace {
template <class M>
ModuleFactory factoryOf() {
  return [](const std::string& name) { return std::make_unique<M>(name); };
}
}  // namespace

ModuleRegistry builtinRegistry() {
  ModuleRegistry r;
  r.add("pointing", "points the hands at vision's objects, stable assignment, lost timeout, priority rule (Sec. 8.4)",
        factoryOf<PointingModule>());
  r.add("scripted", "hand targets and priorities from a timeline (YAML or CSV)", factoryOf<ScriptedModule>());
  r.add("grasped_bar", "a grasped bar attached to a hand as a body-schema segment with motion priority (Sec. 8.5.1)",
        factoryOf<GraspedBarModule>());
  r.add("occlusion", "a virtual capsule head camera -> looked-at object, off when a hand covers it (Sec. 8.5.2)",
        factoryOf<OcclusionModule>());
  r.add("walking", "a walking goal in the world frame (Sec. 8.3.2)", factoryOf<WalkingModule>());
  return r;
}

}  // namespace reflex::modules
