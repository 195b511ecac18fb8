// reflex_bus: what runs on the Reflex bus, like `ros2 node list` / `ros2 topic hz`.
//   reflex_bus list [--window S]            processes from their heartbeats: host, pid, modules, state
//                                           (listens up to 5 s more while discovery still goes on)
//   reflex_bus hz [TOPIC...] [--window S]    samples per second of every topic (or the ones named)
// Reads only: it publishes nothing (not even a heartbeat of its own).
#include "reflex/common/run_main.hpp"
#include "reflex/record/bus_survey.hpp"
#include "reflex/record/record_file.hpp"

#include <reflex/bus/bus.hpp>
#include <reflex/bus/cli.hpp>

#include "reflex/common/files.hpp"

#include <CLI/CLI.hpp>

#include <cstdio>
#include <string>
#include <vector>

namespace {

void printProcesses(const reflex::record::BusSurvey& s) {
  std::printf("# domain %d, %zu process(es) seen in %.1f s%s\n", s.domain, s.processes.size(), s.window_s,
              s.settled ? ""
                        : (" (INCOMPLETE? " + std::to_string(s.silent_participants) +
                           " participant(s) discovered sent no heartbeat: tools that publish none, or processes "
                           "not heard yet; list again)")
                              .c_str());
  std::printf("%-16s %8s  %-12s %-24s %8s %6s  %s\n", "HOST", "PID", "STATE", "MODULE", "AGE_S", "BEATS", "DETAIL");
  for (const auto& p : s.processes)
    for (const auto& m : p.modules)
      std::printf("%-16s %8d  %-12s %-24s %8.2f %6d  %s\n", p.host.c_str(), p.pid, m.state.c_str(),
                  m.module_name.c_str(), m.age_s, m.heartbeats, m.detail.c_str());
}

void printTopics(const reflex::record::BusSurvey& s) {
  std::printf("# domain %d, rates over %.1f s\n", s.domain, s.window_s);
  std::printf("%-32s %-36s %10s %9s %8s\n", "TOPIC", "TYPE", "HZ", "SAMPLES", "WRITERS");
  for (const auto& t : s.topics)
    std::printf("%-32s %-36s %10.1f %9llu %8d\n", t.topic.c_str(), t.type.c_str(), t.hz,
                static_cast<unsigned long long>(t.samples), t.writers);
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{
      "reflex_bus: what runs on the Reflex bus (reads only).\n"
      "  reflex_bus list [--window 3.5]                 processes and modules from their heartbeats\n"
      "  reflex_bus hz [reflex/joint_state ...] [--window 3.5]   samples per second of every topic"};
  app.require_subcommand(1);
  double window = 3.5;
  reflex::bus::BusOptions bus_options;
  std::vector<std::string> topics;
  auto* list = app.add_subcommand("list", "live processes and their modules (from reflex/heartbeat)");
  auto* hz = app.add_subcommand("hz",
                                "samples per second (over the span from the first to the last sample, as ros2 topic "
                                "hz) and matched writers of each topic");
  hz->add_option("topic", topics, "topics to measure (default: every Reflex topic); NAME or NAME:TYPE");
  for (CLI::App* sub : {list, hz}) {
    sub->add_option("-w,--window", window,
                    "seconds to listen (at least 3.5: every process announces itself at least every 3 s; "
                    "list then listens up to 5 s more while a process it found has not been heard)")
        ->check(reflex::FiniteRange(0.1, 3600.0))
        ->capture_default_str();
    bus_options.add(*sub);
  }
  const int status = reflex::runMain("reflex_bus", app, argc, argv, [&]() -> int {
    const reflex::bus::BusConfig config = bus_options.config("reflex_bus");
    const reflex::record::BusSurvey s =
        reflex::record::surveyBus(config, window, list->parsed() ? std::vector<std::string>{} : topics);
    if (list->parsed())
      printProcesses(s);
    else
      printTopics(s);
    return 0;
  });
  if (const std::string why = reflex::common::flushStandardOutput(); !why.empty()) {
    std::fprintf(stderr, "reflex_bus: error: %s\n", why.c_str());
    return 1;
  }
  return status;
}
