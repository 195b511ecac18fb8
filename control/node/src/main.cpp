// reflex_controller: the onboard controller process (200 Hz) over DDS. See controller_node.hpp.
#include "reflex/control_node/controller_node.hpp"

#include <reflex/bus/bus.hpp>

#include <CLI/CLI.hpp>

#include <algorithm>
#include <csignal>
#include <cstdio>

namespace {
reflex::control_node::ControllerNode* g_node = nullptr;
extern "C" void onUsr1(int) {
  if (g_node) g_node->requestEstopReset();  // only sets an atomic flag
}
}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"reflex_controller: onboard reactive controller (200 Hz) with the simulated robot, over DDS.\n"
               "Subscribes hand targets, motion priority, body schema, walk commands; publishes joint state,\n"
               "controller status and a heartbeat. SIGUSR1 asks to leave a latched e-stop."};
  reflex::control_node::NodeConfig config;
  config.urdf = REFLEX_DEFAULT_URDF;
  bool no_avoidance = false;
  app.add_option("--urdf", config.urdf, "robot URDF")->capture_default_str();
  app.add_option("--collision", config.collision, "collision configuration (default: next to the URDF)");
  app.add_option("--controller", config.controller, "controller configuration YAML (default: built-in)");
  app.add_option("--domain", config.domain_id, "DDS domain id (default: $REFLEX_DOMAIN_ID or 0)")
      ->check(CLI::Range(0, reflex::bus::kMaxDomainId));
  app.add_option("--profiles", config.profiles_file, "DDS QoS profiles XML (default: bringup/dds/reflex_profiles.xml)");
  app.add_option("--participant-profile", config.participant_profile, "participant profile in the XML")->capture_default_str();
  app.add_option("--duration", config.duration, "seconds to run (0: until Ctrl-C)")->check(CLI::NonNegativeNumber);
  app.add_option("--input-timeout", config.input_timeout, "seconds of silence from the target source before the hands retract")
      ->capture_default_str()->check(CLI::PositiveNumber);
  app.add_flag("--no-avoidance", no_avoidance, "collision avoidance off (comparison runs only; never on a robot)");
  app.add_option("--log", config.log_csv, "write the per-cycle time series CSV here at exit");
  app.add_option("--robot-state", config.robot_state,
                 "keep the simulated robot's joint positions in this file across restarts (loaded at start, "
                 "written every cycle; refused if it holds another robot or is damaged)");
  app.add_option("--name", config.module_name, "module name on the bus")->capture_default_str();
  CLI11_PARSE(app, argc, argv);
  config.avoidance = !no_avoidance;
  try {
    reflex::control_node::ControllerNode node(config);
    g_node = &node;
    std::signal(SIGUSR1, onUsr1);
    reflex::bus::StopOnSignal stop_on_signal(node.bus());
    if (!node.robotStateNote().empty()) std::fprintf(stderr, "reflex_controller: %s\n", node.robotStateNote().c_str());
    std::fprintf(stderr, "reflex_controller: running at %.0f Hz on domain %d%s\n", 200.0, node.bus().domainId(),
                 config.avoidance ? "" : " (AVOIDANCE OFF)");
    node.run();
    g_node = nullptr;
    const auto& s = node.stats();
    std::vector<double> lat = s.lateness_us;
    std::sort(lat.begin(), lat.end());
    auto pct = [&](double p) { return lat.empty() ? 0.0 : lat[std::min(lat.size() - 1, static_cast<std::size_t>(p * lat.size()))]; };
    std::fprintf(stderr,
                 "reflex_controller: %llu cycles, lateness p50 %.0f us p99 %.0f us max %.0f us, overruns %llu, "
                 "min distance %.1f mm, e-stops %llu, targets %llu (rejected %llu), stale events %llu, "
                 "guard-shortened steps %llu%s\n",
                 static_cast<unsigned long long>(s.cycles), pct(0.5), pct(0.99), s.max_lateness_us,
                 static_cast<unsigned long long>(s.overruns), s.min_distance * 1000.0,
                 static_cast<unsigned long long>(s.estop_count), static_cast<unsigned long long>(s.targets_received),
                 static_cast<unsigned long long>(s.targets_rejected), static_cast<unsigned long long>(s.stale_events),
                 static_cast<unsigned long long>(s.guard_count),
                 s.state_write_errors > 0 ? (", robot-state writes FAILED " + std::to_string(s.state_write_errors)).c_str() : "");
    // DDS-Security material that expired during the run stopped the loop (bus::Participant): not success.
    if (node.bus().credentialsExpired()) return 1;
    return 0;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "reflex_controller: error: %s\n", e.what());
    return 1;
  }
}
