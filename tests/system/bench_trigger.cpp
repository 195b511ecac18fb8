// reflex_trigger_bench: robot state -> joint command latency of the real reflex_controller process,
// --trigger state against --trigger timer in one run, optionally with --realtime and under a competing
// load (stress-ng). Not a ctest: run by hand; the figures and the exact commands are in docs/speed.md.
//
// This process is the robot (StateDriver, state_driver.hpp: its own DDS participant, UDP only, the
// same transport as the controller's): it publishes reflex/robot_state at --rate (500 Hz), applies the
// commands by idl/README.md's hold rule (the arms move: the targets alternate every 0.8 s) and takes
// every reflex/joint_command as it arrives. For each state sent in the measured window, the FIRST
// command that answers it (JointCommand.state_seq) gives two latencies, both on this host's one
// system clock:
//   stamped:  the command's Header.stamp_ns (taken in the controller's cycle) - the state's stamp;
//   arrived:  when the command reached this process - the state's stamp (the whole loop a robot sees).
// A state is MISSED when its answer arrived later than one state interval after it (the robot measures
// its next state without it) or never; also counted: answers later than the control period (5 ms).
// The controller's own exit line (cycles, overruns, lateness) is printed after each run.
//
// --stress N starts `stress-ng --cpu N` for each run (N workers at 100 % CPU, SCHED_OTHER) and stops
// it after; --realtime passes the option to reflex_controller; --driver-rt runs this process's robot
// threads SCHED_FIFO (a real robot's driver is real-time; without it the load delays the robot, not the
// controller).
#include "support/files.hpp"
#include "state_driver.hpp"
#include "support/child_process.hpp"

#include "reflex/control/urdf_loader.hpp"

#include <CLI/CLI.hpp>

#include <algorithm>
#include <csignal>
#include <cstdio>
#include <fstream>
#include <map>
#include <sstream>

namespace {

using namespace reflex;

std::string slurp(const std::string& path) { return testing::readFile(path); }

struct Percentiles {
  double p50 = 0, p99 = 0, p999 = 0, max = 0;
};
Percentiles percentiles(std::vector<double> v) {
  Percentiles p;
  if (v.empty()) return p;
  std::sort(v.begin(), v.end());
  auto at = [&](double q) {
    return v[std::min(v.size() - 1, static_cast<std::size_t>(q * static_cast<double>(v.size())))];
  };
  p.p50 = at(0.5);
  p.p99 = at(0.99);
  p.p999 = at(0.999);
  p.max = v.back();
  return p;
}

struct Options {
  std::string bin_dir = REFLEX_BIN_DIR;
  std::string urdf = std::string(REFLEX_SOURCE_DIR) + "/bringup/robots/asimo_like.urdf";
  int domain = 23;
  double rate = 500.0;
  double seconds = 20.0;
  std::vector<std::string> modes = {"state", "timer"};
  std::string realtime;
  int driver_rt = 0;
  int stress = 0;
  std::string work = "/tmp";
};

int runOne(const Options& o, const control::Model& model, const control::ControllerModel& cm, const std::string& mode) {
  const std::string log = o.work + "/reflex_trigger_bench." + mode + ".log";
  std::vector<std::string> argv = {o.bin_dir + "/reflex_controller",
                                   "--domain",
                                   std::to_string(o.domain),
                                   "--robot",
                                   "dds",
                                   "--trigger",
                                   mode,
                                   "--peer-probe",
                                   "0",
                                   "--input-timeout",
                                   "5",
                                   "--urdf",
                                   o.urdf,
                                   "--duration",
                                   std::to_string(o.seconds + 8.0)};
  if (!o.realtime.empty()) {
    argv.push_back("--realtime");
    argv.push_back(o.realtime);
  }
  std::unique_ptr<testing::ChildProcess> stress;
  if (o.stress > 0) {
    stress = std::make_unique<testing::ChildProcess>(
        // Normal scheduling, whatever this process runs at (chrt --other 0).
        std::vector<std::string>{"/usr/bin/chrt", "--other", "0", "/usr/bin/stress-ng", "--cpu",
                                 std::to_string(o.stress), "--quiet"},
        o.work + "/reflex_trigger_bench.stress.log");
    if (!stress->started()) {
      std::fprintf(stderr, "reflex_trigger_bench: cannot start stress-ng: %s\n", stress->error().c_str());
      return 1;
    }
  }
  testing::ChildProcess controller(argv, log);
  testing::StateDriver driver(model, cm, o.domain, 1.0 / o.rate, control::restConfiguration(model, cm), o.driver_rt);
  auto& targets = driver.bus().makeWriter<msg::HandTargets>();
  if (!driver.waitForController(std::chrono::seconds(30)) || !targets.waitForReaders(1, std::chrono::seconds(30))) {
    std::fprintf(stderr, "reflex_trigger_bench: the controller did not match:\n%s\n", slurp(log).c_str());
    return 1;
  }
  driver.start();
  std::int64_t from = 0;
  const std::int64_t t0 = bus::nowNs();
  const std::int64_t end = t0 + static_cast<std::int64_t>((2.0 + o.seconds) * 1e9);
  int tick = 0;
  while (bus::nowNs() < end) {
    if (from == 0 && bus::nowNs() >= t0 + 2'000'000'000) from = bus::nowNs();  // 2 s of warm-up
    msg::HandTargets t;
    const bool high = (tick++ / 16) % 2 == 0;
    msg::HandTarget* h[2] = {&t.left(), &t.right()};
    for (int a = 0; a < 2; ++a) {
      h[a]->status(msg::TARGET_GIVEN);
      h[a]->position_base().x(high ? 0.30 : 0.25);
      h[a]->position_base().y(a == 0 ? 0.20 : -0.20);
      h[a]->position_base().z(high ? 0.85 : 0.65);
    }
    targets.publish(t);
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  const std::int64_t to = bus::nowNs() - 20'000'000;  // the last states' answers are still on their way
  std::this_thread::sleep_for(std::chrono::milliseconds(30));
  driver.stop();
  controller.signal(SIGTERM);
  controller.wait(std::chrono::seconds(20));
  if (stress) stress->terminate(std::chrono::seconds(5));
  if (driver.realtimeFailed())
    std::fprintf(stderr, "reflex_trigger_bench: WARNING: --driver-rt refused (not permitted)\n");

  const auto sent = driver.sent();
  const auto got = driver.received();
  std::map<std::uint64_t, std::pair<std::int64_t, std::int64_t>> first;  // state seq -> (stamped, arrived) ns
  for (const auto& r : got)
    if (first.find(r.command.state_seq()) == first.end())
      first[r.command.state_seq()] = {r.command.header().stamp_ns(), r.arrived_ns};
  std::vector<double> stamped, arrived;
  std::size_t states = 0, unanswered = 0, late_interval = 0, late_period = 0;
  const double interval_ms = 1e3 / o.rate, period_ms = cm.params.period * 1e3;
  for (const auto& s : sent) {
    if (s.stamp_ns < from || s.stamp_ns >= to) continue;
    ++states;
    const auto it = first.find(s.seq);
    if (it == first.end()) {
      ++unanswered;
      continue;
    }
    stamped.push_back(1e-6 * static_cast<double>(it->second.first - s.stamp_ns));
    arrived.push_back(1e-6 * static_cast<double>(it->second.second - s.stamp_ns));
    late_interval += arrived.back() > interval_ms;
    late_period += arrived.back() > period_ms;
  }
  const Percentiles ps = percentiles(stamped), pa = percentiles(arrived);
  std::printf(
      "--trigger %-5s %6zu states, answered %6zu (%5.1f %%), commands %6zu | stamped p50 %.3f p99 %.3f p99.9 %.3f max "
      "%.3f ms"
      " | arrived p50 %.3f p99 %.3f p99.9 %.3f max %.3f ms | missed (answer > %.1f ms or none) %zu = %.2f %%, "
      "answer > %.0f ms %zu\n",
      mode.c_str(), states, states - unanswered,
      states ? 100.0 * static_cast<double>(states - unanswered) / static_cast<double>(states) : 0.0, got.size(), ps.p50,
      ps.p99, ps.p999, ps.max, pa.p50, pa.p99, pa.p999, pa.max, interval_ms, late_interval + unanswered,
      states ? 100.0 * static_cast<double>(late_interval + unanswered) / static_cast<double>(states) : 0.0, period_ms,
      late_period);
  const std::string text = slurp(log);
  const auto pos = text.find("cycles, lateness");
  if (pos != std::string::npos) {
    const auto start = text.rfind('\n', pos);
    const auto stop = text.find(", rejected by cause", pos);
    std::printf("    controller: %s\n", text.substr(start == std::string::npos ? 0 : start + 1,
                                                    (stop == std::string::npos ? text.find('\n', pos) : stop) -
                                                        (start == std::string::npos ? 0 : start + 1))
                                            .c_str());
  } else {
    std::printf("    controller log:\n%s\n", text.c_str());
  }
  if (const auto rt = text.find("real-time:"); rt != std::string::npos)
    std::printf("    %s\n", text.substr(rt, text.find('\n', rt) - rt).c_str());
  std::fflush(stdout);
  return states > 0 ? 0 : 1;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{
      "reflex_trigger_bench: robot state -> joint command latency of reflex_controller --robot dds, --trigger "
      "state against --trigger timer (this process is the robot), optionally --realtime and under stress-ng "
      "load. Figures: docs/speed.md."};
  Options o;
  app.add_option("--bin-dir", o.bin_dir, "folder of reflex_controller")->capture_default_str();
  app.add_option("--domain", o.domain, "DDS domain id")->capture_default_str()->check(CLI::Range(0, 231));
  app.add_option("--rate", o.rate, "robot states per second")->capture_default_str()->check(CLI::Range(50.0, 2000.0));
  app.add_option("--seconds", o.seconds, "measured seconds per run (after 2 s of warm-up)")
      ->capture_default_str()
      ->check(CLI::Range(1.0, 3600.0));
  app.add_option("--modes", o.modes, "the triggers to run, in order")
      ->delimiter(',')
      ->capture_default_str()
      ->check(CLI::IsMember({"state", "timer"}));
  app.add_option("--realtime", o.realtime, "passed to reflex_controller --realtime (PRIORITY[,CPU])");
  app.add_option("--driver-rt", o.driver_rt, "SCHED_FIFO priority of this process's robot threads (0: normal)")
      ->capture_default_str()
      ->check(CLI::Range(0, 99));
  app.add_option("--stress", o.stress, "run `stress-ng --cpu N` during each run (0: none)")
      ->capture_default_str()
      ->check(CLI::Range(0, 64));
  app.add_option("--work", o.work, "folder for the controller's logs")->capture_default_str();
  CLI11_PARSE(app, argc, argv);
  try {
    const control::Model model = control::loadModel(o.urdf, control::loadCollisionConfigFor(o.urdf, ""));
    const control::ControllerModel cm =
        control::makeControllerModel(model, control::loadControllerConfigFor(o.urdf, ""));
    double load[3] = {0, 0, 0};
    if (getloadavg(load, 3) < 0) load[0] = -1;
    std::printf("reflex_trigger_bench: %.0f Hz robot states, %.0f s per run, %s, load average %.2f %.2f %.2f%s%s\n",
                o.rate, o.seconds,
                o.realtime.empty() ? "controller without --realtime" : ("controller --realtime " + o.realtime).c_str(),
                load[0], load[1], load[2],
                o.stress > 0 ? (", stress-ng --cpu " + std::to_string(o.stress)).c_str() : "",
                o.driver_rt > 0 ? (", robot threads SCHED_FIFO " + std::to_string(o.driver_rt)).c_str() : "");
    int rc = 0;
    for (const auto& mode : o.modes) rc |= runOne(o, model, cm, mode);
    return rc;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "reflex_trigger_bench: error: %s\n", e.what());
    return 1;
  }
}
