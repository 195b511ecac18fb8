// reflex_fault_source: a stand-in behavior process for the fault tests. Publishes hand targets every
// 100 ms and a heartbeat every 500 ms until SIGINT / SIGTERM (or SIGKILL in a test). The targets are
// "crossing" (each hand on the other side of the chest: the arms meet and avoid each other), "near"
// (in front of the chest, 14 cm apart: reachable, the arms about 2 cm apart, in the yellow zone) or
// "apart" (each hand on its own side, reachable), optionally swaying up and down (--sway metres,
// period 2 s, on the system clock so that a restarted source continues the same motion).
#include <reflex/bus/bus.hpp>

#include <CLI/CLI.hpp>

#include <cmath>
#include <cstdio>
#include <ctime>

int main(int argc, char** argv) {
  CLI::App app{"reflex_fault_source: publishes hand targets (10 Hz) and a heartbeat (2 Hz) for fault tests"};
  std::string domain_text, name = "fault_source";
  app.add_option("--domain", domain_text, "DDS domain id (default: $REFLEX_DOMAIN_ID, else 0)");
  app.add_option("--name", name, "module name")->capture_default_str();
  std::string kind = "crossing";
  double sway = 0.0;
  app.add_option("--targets", kind, "crossing, apart or near (in front of the chest, hands close together)")
      ->capture_default_str()
      ->check(CLI::IsMember({"crossing", "apart", "near"}));
  app.add_option("--sway", sway, "amplitude (m) of an up-and-down motion of both targets, period 2 s")
      ->capture_default_str()
      ->check(CLI::Range(0.0, 0.1));
  CLI11_PARSE(app, argc, argv);
  try {
    reflex::bus::BusConfig config;
    config.module_name = name;
    if (!domain_text.empty()) config.domain_id = reflex::bus::parseDomainId(domain_text, "--domain");
    reflex::bus::Participant bus(config);
    auto& targets = bus.makeWriter<reflex::msg::HandTargets>();
    reflex::bus::HeartbeatPublisher heartbeat(bus);
    heartbeat.setState(reflex::msg::STATE_RUNNING);
    // The left hand's y (base frame, +y = left); the right hand's is -y.
    const double y = kind == "crossing" ? -0.08 : kind == "near" ? 0.07 : 0.20;
    const double x = kind == "near" ? 0.25 : 0.30;
    bus.every(std::chrono::milliseconds(100), [&] {
      timespec ts{};
      clock_gettime(CLOCK_REALTIME, &ts);
      const double phase =
          2.0 * M_PI * std::fmod(static_cast<double>(ts.tv_sec % 1000) + 1e-9 * static_cast<double>(ts.tv_nsec), 2.0) /
          2.0;
      const double z = 0.90 + sway * std::sin(phase);
      reflex::msg::HandTargets t;
      t.left().status(reflex::msg::TARGET_GIVEN);
      t.left().position_base().x(x);
      t.left().position_base().y(y);
      t.left().position_base().z(z);
      t.right().status(reflex::msg::TARGET_GIVEN);
      t.right().position_base().x(x);
      t.right().position_base().y(-y);
      t.right().position_base().z(z);
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
