// bus_pub_program: publishes the distinctive test sample (samples.hpp, variant 7) of the selected
// topic types on their default topics and profiles, every --period-ms, until SIGINT / SIGTERM (exit
// 0, prints "stopped by signal N") or --max-seconds (exit 2). Prints "running (participant id N)" once
// set up.
// Used by bus_two_process_test and the Cyclone DDS interoperability tests.
#include <CLI/CLI.hpp>

#include <reflex/bus/bus.hpp>

#include <cstdio>
#include <iostream>

#include "bus_test_util.hpp"
#include "program_types.hpp"

int main(int argc, char** argv) {
  using namespace reflex::bus;
  CLI::App app("Publish the Reflex bus test samples until SIGINT/SIGTERM.");
  int domain = 0;
  std::string types = "all";
  std::string participant_profile = "reflex_participant";
  std::string module = "two_process_pub";
  int period_ms = 20;
  double max_seconds = 30.0;
  app.add_option("--domain", domain, "DDS domain id")->required()->check(CLI::Range(0, kMaxDomainId));
  app.add_option("--types", types, "comma-separated type names, or 'all'");
  app.add_option("--participant-profile", participant_profile, "participant profile in the profiles file");
  app.add_option("--module", module, "module name (Header.source)");
  app.add_option("--period-ms", period_ms, "publishing period [ms]")->check(CLI::Range(1, 10000));
  app.add_option("--max-seconds", max_seconds, "give up (exit 2) after this long")->check(CLI::PositiveNumber);
  CLI11_PARSE(app, argc, argv);

  try {
    Participant bus(test::testConfig(module, domain, participant_profile));
    std::vector<std::function<void()>> publishers;
    for (const auto& name : test::splitTypes(types)) {
      const bool known = test::forTypeName(name, [&](auto* tag) {
        using T = std::remove_pointer_t<decltype(tag)>;
        auto& writer = bus.makeWriter<T>();
        publishers.push_back([&writer, sample = test::sampleOf<T>(7)]() mutable { writer.publish(sample); });
      });
      if (!known) {
        std::cerr << "bus_pub_program: unknown type '" << name << "' in --types (known: all, "
                  << "object_targets, hand_targets, ...)\n";
        return 1;
      }
    }
    bus.every(std::chrono::milliseconds(period_ms), [&] {
      for (auto& p : publishers) p();
    });
    bool timed_out = false;
    bus.every(std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::duration<double>(max_seconds)), [&] {
      timed_out = true;
      bus.stop();
    });
    StopOnSignal stop_on_signal(bus);
    std::cout << "running (participant id " << bus.participantId() << ")" << std::endl;
    bus.run();
    if (timed_out) {
      std::cerr << "bus_pub_program: not stopped by a signal within --max-seconds " << max_seconds << "\n";
      return 2;
    }
    std::cout << "stopped by signal " << stop_on_signal.lastSignal() << std::endl;
    return 0;
  } catch (const BusError& e) {
    std::cerr << "bus_pub_program: " << e.what() << "\n";
    return 1;
  }
}
