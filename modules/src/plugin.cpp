#include "reflex/modules/plugin.hpp"

#include "reflex/modules/module_call.hpp"

#include <dlfcn.h>

#include <algorithm>
#include <filesystem>
#include <system_error>

namespace reflex::modules {

std::vector<std::string> pluginPaths(const ConfigNode& root) {
  std::vector<std::string> out;
  for (const std::string& p : root.strings("plugins", {})) {
    if (p.empty()) root.fail("plugins", "holds an empty path", "a list of shared-library paths");
    out.push_back(root.resolvePath(p));
  }
  return out;
}

PluginInfo loadModulePlugin(const std::string& path, ModuleRegistry& registry) {
  namespace fs = std::filesystem;
  std::error_code ec;
  if (!fs::is_regular_file(path, ec)) throw ConfigError("module plugin '" + path + "': no such file");
  const std::string absolute = fs::absolute(path, ec).lexically_normal().string();
  // RTLD_NOW: an unresolved symbol is an error here, not a crash in the middle of a run. RTLD_LOCAL: two
  // plugins never see each other's symbols. dlopen runs the library's static constructors before it
  // returns: any shared library named here executes its code in this process before the checks below
  // can refuse it (plugin.hpp).
  // Marked like a module call (module_call.hpp): a crash or a hang in the library's code is named.
  const std::string loading = "dlopen of plugin " + absolute + " (its static constructors)";
  const std::string registering = "reflex_register_modules() of plugin " + absolute;
  void* handle = nullptr;
  {
    const ModuleCallMark mark(loading.c_str());
    handle = ::dlopen(absolute.c_str(), RTLD_NOW | RTLD_LOCAL);
  }
  if (handle == nullptr) {
    const char* why = ::dlerror();
    throw ConfigError("module plugin '" + path + "': cannot be loaded: " + (why ? why : "unknown dlopen error"));
  }
  using TagFn = const char* (*)();
  using RegisterFn = void (*)(ModuleRegistry&);
  auto tag_fn = reinterpret_cast<TagFn>(::dlsym(handle, "reflex_module_api_tag"));
  auto register_fn = reinterpret_cast<RegisterFn>(::dlsym(handle, "reflex_register_modules"));
  if (tag_fn == nullptr || register_fn == nullptr) {
    ::dlclose(handle);
    throw ConfigError("module plugin '" + path +
                      "': not a Reflex module plugin (no reflex_module_api_tag / reflex_register_modules; define them "
                      "with REFLEX_MODULE_PLUGIN from <reflex/modules/plugin.hpp>)");
  }
  std::string tag;
  try {
    const char* t = tag_fn();
    tag = t ? t : "";
  } catch (...) {
    ::dlclose(handle);
    throw ConfigError("module plugin '" + path + "': reflex_module_api_tag() threw");
  }
  if (tag != REFLEX_MODULE_API_TAG) {
    ::dlclose(handle);
    throw ConfigError("module plugin '" + path + "': built for '" + tag + "', this reflex_behavior is '" +
                      REFLEX_MODULE_API_TAG + "': rebuild the plugin against this Reflex");
  }
  // Register into a scratch registry first, so a failing plugin leaves `registry` as it was.
  ModuleRegistry added;
  try {
    const ModuleCallMark mark(registering.c_str());
    register_fn(added);
  } catch (const std::exception& e) {
    throw ConfigError("module plugin '" + path + "': registration failed: " + e.what());
  } catch (...) {
    throw ConfigError("module plugin '" + path +
                      "': registration failed: reflex_register_modules threw something that is not a std::exception");
  }
  PluginInfo info{absolute, added.types()};
  if (info.types.empty()) throw ConfigError("module plugin '" + path + "': registers no module type");
  for (const std::string& t : info.types) {
    if (registry.has(t))
      throw ConfigError("module plugin '" + path + "': module type '" + t +
                        "' is already registered (known: " + registry.typeList() + ")");
  }
  registry.merge(std::move(added));
  // The handle stays open for the life of the process: the registered factories are its code.
  return info;
}

std::vector<PluginInfo> loadModulePlugins(const std::string& config_path, ModuleRegistry& registry) {
  std::vector<PluginInfo> out;
  for (const std::string& p : pluginPaths(ConfigNode::loadFile(config_path)))
    out.push_back(loadModulePlugin(p, registry));
  return out;
}

}  // namespace reflex::modules
