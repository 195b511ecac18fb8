// reflex_view: the live 3D view of a running Reflex system, in the browser and in Foxglove.
//   reflex_view [--port 8765] [--bind 127.0.0.1] [--domain N] [--urdf FILE] ...
// Open http://localhost:8765, or in Foxglove: Open connection -> Foxglove WebSocket -> ws://localhost:8765.
#include "reflex/common/run_main.hpp"
#include "reflex/common/shipped.hpp"
#include "reflex/view_node/view_node.hpp"

#include <reflex/bus/bus.hpp>
#include <reflex/bus/cli.hpp>
#include <reflex/control/controller.hpp>
#include <reflex/control/urdf_loader.hpp>

#include <CLI/CLI.hpp>

#include <cstdio>

int main(int argc, char** argv) {
  using namespace reflex;
  CLI::App app{
      "reflex_view: live 3D view of a running Reflex system. Reads reflex/joint_state, control_status, hand_targets, "
      "object_targets, controller_protection and body_schema (never writes to the bus) and serves, on one port, the "
      "Foxglove "
      "WebSocket protocol (subprotocol foxglove.websocket.v1 or foxglove.sdk.v1: channels /tf, /reflex/scene, "
      "/reflex/status, JSON) and the bundled "
      "web page (three.js). Open http://localhost:PORT, or in Foxglove: Open connection -> Foxglove WebSocket -> "
      "ws://localhost:PORT. Exit: 0 ok, 1 runtime error, 2 bad option or set-up (port in use, bad --bind, missing "
      "web folder, bad robot files)."};
  view_node::ViewOptions options;
  options.urdf = reflex::common::defaultUrdf();
  options.server.web_dir = reflex::common::shippedPath("view/web");
  options.server.three_dir = reflex::common::shippedPath("view/three");
  bus::BusOptions bus_options;
  app.add_option("--port", options.server.port, "TCP port of the page and the WebSocket (0: any free port, printed)")
      ->capture_default_str();
  app.add_option("--bind", options.server.bind,
                 "address to listen on; 127.0.0.1 (this machine only) unless told otherwise, e.g. 0.0.0.0 for the LAN")
      ->capture_default_str();
  app.add_option("--urdf", options.urdf, "robot URDF (the controller's)")->capture_default_str();
  app.add_option("--collision", options.collision, "collision configuration (default: next to the URDF)");
  app.add_option("--controller", options.controller,
                 "controller YAML: arms and zone thresholds (default: <URDF stem>.controller.yaml beside the URDF if "
                 "it exists, else built-in)");
  app.add_option("--rate", options.rate, "scene messages per second at most, (0, 200]")->capture_default_str();
  app.add_option("--web", options.server.web_dir, "folder of the web page (index.html)")->capture_default_str();
  app.add_option("--three", options.server.three_dir, "folder of three.module.js and three.core.js")
      ->capture_default_str();
  bus_options.add(app);
  app.add_option("--duration", options.duration, "stop after this many seconds (0 = until SIGINT / SIGTERM)")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  app.add_option("--progress", options.progress_period, "counters on stderr every this many seconds (0 = none)")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  if (const int code = reflex::parseCommandLine(app, argc, argv); code >= 0) return code;
  try {
    options.domain_id = bus_options.domainId().value_or(-1);
    options.profiles_file = bus_options.profiles;
    options.participant_profile = bus_options.participant_profile;
    view_node::ViewNode node(options);
    bus::StopOnSignal stop_on_signal(node.bus());  // SIGINT / SIGTERM / ... -> a clean stop
    node.run();
    std::printf("reflex_view: stats %s\n", node.report().c_str());
    std::fflush(stdout);
    return 0;
  } catch (const std::exception& e) {
    return reflex::reportException("reflex_view", e);  // set-up errors (reflex::Error) 2, anything else 1
  }
}
