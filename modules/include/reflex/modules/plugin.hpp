// Module types from shared libraries: a behavior configuration's `plugins:` list (paths relative to the
// file) or `reflex_behavior --plugin FILE` adds the module types a plugin registers, so a new module type
// is swapped in by configuration, with the stock reflex_behavior (no new executable).
//
// Writing a plugin (modules/examples/wave_module is a complete outside project):
//   #include <reflex/modules/plugin.hpp>
//   class WaveModule final : public reflex::modules::Module { ... };
//   REFLEX_MODULE_PLUGIN(registry) {
//     registry.add("wave", "waves a hand", [](const std::string& n) { return std::make_unique<WaveModule>(n); });
//   }
// built as a SHARED library linking reflex::modules from the installed package (find_package(reflex)).
//
// Contract: the plugin is built against the same Reflex version (the API tag below is compared and a
// mismatch is refused, naming both); a plugin is never unloaded (its factories live as long as the
// process). Loading a plugin is running its code: dlopen runs the library's static constructors
// before any check, so a file that turns out to be "not a Reflex module plugin" (or built for another
// API) has already executed in the behavior process when it is refused — load only files you trust.
// Once loaded, what its modules throw, a crash inside them and a call that never returns are named
// (host.hpp, modules/README.md), not prevented.
#pragma once

#include "reflex/modules/config.hpp"
#include "reflex/modules/registry.hpp"

#include <string>
#include <vector>

/// Changes whenever Module, ModuleContext, ModuleRegistry or the types they pass change layout.
#define REFLEX_MODULE_API_TAG "reflex-module-api/1"

/// Defines the two entry points reflex_behavior looks up; the body registers the plugin's module types.
#define REFLEX_MODULE_PLUGIN(registry_var)                                                \
  extern "C" __attribute__((visibility("default"))) const char* reflex_module_api_tag() { \
    return REFLEX_MODULE_API_TAG;                                                         \
  }                                                                                       \
  extern "C" __attribute__((visibility("default"))) void reflex_register_modules(         \
      ::reflex::modules::ModuleRegistry& registry_var)

namespace reflex::modules {

/// What one plugin added.
struct PluginInfo {
  std::string path;                ///< as loaded (absolute)
  std::vector<std::string> types;  ///< module types it registered (at least one)
};

/// The `plugins:` list of a behavior configuration, resolved against the file's folder ([] when absent).
/// Throws ConfigError naming the key when it is not a list of non-empty strings.
std::vector<std::string> pluginPaths(const ConfigNode& root);

/// Loads one plugin and registers its module types in `registry`. Throws ConfigError naming `path` and
/// the cause: file missing or not loadable (dlopen's message), not a Reflex plugin (entry points
/// missing), API tag mismatch (both tags), a type already registered, or no type registered.
PluginInfo loadModulePlugin(const std::string& path, ModuleRegistry& registry);

/// pluginPaths(config file) + loadModulePlugin for each, in order.
std::vector<PluginInfo> loadModulePlugins(const std::string& config_path, ModuleRegistry& registry);

}  // namespace reflex::modules
