// reflex_fault_source: a stand-in behavior process for the fault tests. Publishes crossing hand
// targets every 100 ms and a heartbeat every 500 ms until SIGINT / SIGTERM (or SIGKILL in a test).
#include <reflex/bus/bus.hpp>

#include <CLI/CLI.hpp>

#include <cstdio>

int main(int argc, char** argv) {
  CLI::App app{"reflex_fault_source: publishes crossing hand targets (10 Hz) and a heartbeat (2 Hz) for fault tests"};
  std::string domain_text, name = "fault_source";
  app.add_option("--domain", domain_text, "DDS domain id (default: $REFLEX_DOMAIN_ID, else 0)");
  app.add_option("--name", name, "module name")->capture_default_str();
  CLI11_PARSE(app, argc, argv);
  try {
    reflex::bus::BusConfig config;
    config.module_name = name;
    if (!domain_text.empty()) config.domain_id = reflex::bus::parseDomainId(domain_text, "--domain");
    reflex::bus::Participant bus(config);
    auto& targets = bus.makeWriter<reflex::msg::HandTargets>();
    reflex::bus::HeartbeatPublisher heartbeat(bus);
    heartbeat.setState(reflex::msg::STATE_RUNNING);
    bus.every(std::chrono::milliseconds(100), [&] {
      reflex::msg::HandTargets t;
      t.left().status(reflex::msg::TARGET_GIVEN);
      t.left().position_base().x(0.30);
      t.left().position_base().y(-0.08);
      t.left().position_base().z(0.90);
      t.right().status(reflex::msg::TARGET_GIVEN);
      t.right().position_base().x(0.30);
      t.right().position_base().y(0.08);
      t.right().position_base().z(0.90);
      targets.publish(t);
    });
    reflex::bus::StopOnSignal stop_on_signal(bus);
    bus.run();
    return 0;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "reflex_fault_source: error: %s\n", e.what());
    return 1;
  }
}
