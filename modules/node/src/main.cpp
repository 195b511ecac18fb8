// reflex_behavior: runs the behavior modules a configuration names, on the bus.
//   reflex_behavior --config bringup/behavior/pointing.yaml [--domain N]
//   reflex_behavior --config bringup/behavior/bar_occlusion.yaml --module occlusion   # one module alone
//   reflex_behavior --list-modules [--config FILE | --plugin LIB]
//   reflex_behavior --config my.yaml --plugin build/libwave_module.so      # a module type from a shared library
// Swapping a module is a change of configuration: start it with another file.
#include "reflex/common/run_main.hpp"
#include "reflex/common/shipped.hpp"
#include "process_guard.hpp"
#include "reflex/modules/behavior_node.hpp"
#include "reflex/modules/plugin.hpp"

#include <reflex/bus/bus.hpp>
#include <reflex/bus/cli.hpp>

#include <CLI/CLI.hpp>

#include <cstdio>

int main(int argc, char** argv) {
  using namespace reflex;
  CLI::App app{
      "reflex_behavior: the behavior layer (paper Sec. 8.4, 8.5): runs the modules named in a YAML configuration "
      "(pointing, scripted, grasped_bar, occlusion, walking), reading reflex/object_targets and reflex/joint_state "
      "and publishing hand targets, motion priority, body schema and walking commands. Exit: 0 ok, 1 runtime "
      "error (a module that threw: named), 2 bad configuration or arguments, 3 a module call still running 2 s "
      "after SIGINT / SIGTERM (named; the process ends within 6 s of the request whatever runs); a crash inside "
      "a module keeps its signal's status (139 for SIGSEGV), the module named on stderr."};
  modules::NodeOptions options;
  bus::BusOptions bus_options;
  bool list = false;
  std::vector<std::string> plugin_files;
  app.add_option("--config", options.config, "behavior configuration YAML (see bringup/behavior/)");
  app.add_option("--module", options.module, "run only the module of this name from the configuration");
  app.add_option("--object-source", options.object_sources,
                 "identity whose reflex/object_targets are accepted, replacing the configuration's "
                 "inputs.object_sources (repeatable; default there: vision). Replaying a recording with reflex_play "
                 "in place of reflex_vision: --object-source player. Under DDS-Security the identity is the writer's "
                 "certificate (CN=reflex.<name>); without it, the name its participant announces (not authenticated)");
  app.add_option("--joint-state-source", options.joint_state_sources,
                 "identity whose reflex/joint_state samples are accepted, replacing the configuration's "
                 "inputs.joint_state_sources (repeatable; default there: controller). A recording replayed without a "
                 "live controller: --joint-state-source player");
  bus_options.add(app);
  app.add_option("--duration", options.duration, "stop after this many seconds (0 = until SIGINT / SIGTERM)")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  app.add_option("--progress", options.progress_period, "status line on stderr every this many seconds (0 = none)")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  app.add_flag("--quiet", options.quiet, "no log lines on stderr");
  app.add_option("--plugin", plugin_files,
                 "shared library adding module types (REFLEX_MODULE_PLUGIN, modules/README.md), loaded before the "
                 "configuration's own `plugins:` list (repeatable). Its code runs in this process: load only files you "
                 "trust");
  app.add_flag("--list-modules", list, "list the module types (built-in and from plugins) and exit");
  if (const int code = reflex::parseCommandLine(app, argc, argv); code >= 0) return code;

  // From here on a crash names the module (or plugin) whose code was running, and a call into one that
  // does not return is named. The watchdog outlives the node: the modules' stop() and destructors are
  // within the stop bound too.
  modules::installFatalSignalReport();
  modules::StopWatchdog watchdog(modules::StopBounds{}, 3);
  modules::ModuleRegistry registry = modules::builtinRegistry();
  try {
    std::vector<modules::PluginInfo> loaded;
    for (const auto& p : plugin_files) loaded.push_back(modules::loadModulePlugin(p, registry));
    if (!options.config.empty())
      for (auto& info : modules::loadModulePlugins(options.config, registry)) loaded.push_back(std::move(info));
    for (const auto& info : loaded) {
      std::string types;
      for (const auto& t : info.types) types += (types.empty() ? "" : ", ") + t;
      std::fprintf(stderr, "reflex_behavior: plugin %s: module types %s\n", info.path.c_str(), types.c_str());
      for (const auto& t : info.types) options.type_plugins[t] = info.path;
    }
  } catch (const std::exception& e) {
    return reflex::reportException("reflex_behavior", e);
  }
  if (list) {
    for (const auto& t : registry.types()) std::printf("%-12s %s\n", t.c_str(), registry.summary(t).c_str());
    return 0;
  }
  if (options.config.empty()) {
    std::fprintf(stderr, "reflex_behavior: error: --config FILE is required (see --help)\n");
    return reflex::kExitRefused;
  }
  try {
    options.domain_id = bus_options.domainId();
    options.profiles_file = bus_options.profiles;
    options.participant_profile = bus_options.participant_profile;
    modules::BehaviorNode node(options, registry);
    watchdog.watch([&node] { return node.bus().stopRequested(); });
    // Before the node goes (return or exception): stop watching its bus, and start the stop clock.
    struct Stopping {
      modules::StopWatchdog& w;
      ~Stopping() {
        w.unwatch();
        w.arm();
      }
    } stopping{watchdog};
    bus::StopOnSignal stop_on_signal(node.bus());  // SIGINT / SIGTERM / ... -> a clean stop
    node.run();
    std::printf("reflex_behavior: stats %s\n", node.report().c_str());
    std::fflush(stdout);
    return 0;
  } catch (const std::exception& e) {
    return reflex::reportException("reflex_behavior", e);
  } catch (...) {
    // The host turns whatever a module throws into a ModuleError; this is for anything else.
    std::fprintf(stderr,
                 "reflex_behavior: error: an exception that is not a std::exception, outside any module call\n");
    return 1;
  }
}
