// bench_mujoco_latency: the latency from a robot's measured state to the command that answers it,
// with this program as the stand-in controller (not a CTest test; numbers go into
// control/README.md). It starts reflex_mujoco (or uses one already running: --no-spawn), reads
// reflex/robot_state and answers with reflex/joint_command (hold the measured positions, state_seq and
// state_stamp_ns of the state answered):
//   --mode immediate  answer every state as soon as it arrives (the bus round trip);
//   --mode cycle      answer the newest state once per 5 ms cycle, as reflex_controller does.
// Reported: this side's state age when answered (now - RobotState.stamp), and the robot's
// measurement (reflex_mujoco's exit line: RobotState.stamp -> the answering JointCommand's arrival,
// both on the robot's clock), p50 / p99. Run the robot against reflex_controller --robot dds instead
// by starting both and reading reflex_mujoco's exit line.
#include "support/child_process.hpp"

#include <reflex/bus/bus.hpp>

#include <CLI/CLI.hpp>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <ctime>
#include <fstream>
#include <regex>
#include <sstream>
#include <thread>

namespace {

double percentile(std::vector<double> v, double p) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  return v[std::min(v.size() - 1, static_cast<std::size_t>(p * static_cast<double>(v.size())))];
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{
      "bench_mujoco_latency: RobotState.stamp -> answering JointCommand latency, this program as the controller"};
  double duration = 10.0;
  int domain = 159;
  std::string mode = "cycle", participant_profile = "reflex_participant", log = "/tmp/bench_mujoco_latency_robot.log";
  bool no_spawn = false;
  app.add_option("--duration", duration, "seconds to measure")->capture_default_str()->check(CLI::PositiveNumber);
  app.add_option("--domain", domain, "DDS domain id")->capture_default_str()->check(CLI::Range(0, 232));
  app.add_option("--mode", mode, "immediate | cycle")
      ->capture_default_str()
      ->check(CLI::IsMember({"immediate", "cycle"}));
  app.add_option("--participant-profile", participant_profile, "participant profile (reflex_participant_udp: UDP only)")
      ->capture_default_str();
  app.add_option("--robot-log", log, "where reflex_mujoco's output goes")->capture_default_str();
  app.add_flag("--no-spawn", no_spawn,
               "use a reflex_mujoco already running on the domain (its exit line has its side)");
  CLI11_PARSE(app, argc, argv);

  std::unique_ptr<reflex::testing::ChildProcess> robot;
  if (!no_spawn) {
    robot = std::make_unique<reflex::testing::ChildProcess>(
        std::vector<std::string>{std::string(REFLEX_BIN_DIR) + "/reflex_mujoco", "--domain", std::to_string(domain),
                                 "--participant-profile", participant_profile},
        log);
    if (!robot->started()) {
      std::fprintf(stderr, "bench_mujoco_latency: error: cannot start reflex_mujoco\n");
      return 1;
    }
  }
  reflex::bus::BusConfig config;
  config.module_name = "bench_mujoco_latency";
  config.domain_id = domain;
  config.participant_profile = participant_profile;
  reflex::bus::Participant bus(config);
  auto& states = bus.makeReader<reflex::msg::RobotState>();
  auto& commands = bus.makeWriter<reflex::msg::JointCommand>();
  reflex::msg::RobotState state;
  reflex::msg::JointCommand command;
  std::fprintf(stderr, "bench_mujoco_latency: waiting for reflex/robot_state on domain %d\n", domain);
  const auto give_up = std::chrono::steady_clock::now() + std::chrono::seconds(60);
  while (!states.takeLatest(state)) {
    if (std::chrono::steady_clock::now() > give_up) {
      std::fprintf(stderr, "bench_mujoco_latency: error: no robot state within 60 s\n");
      return 1;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  std::vector<double> age_us;
  age_us.reserve(static_cast<std::size_t>(duration * 1100));
  const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(duration);
  timespec next{};
  clock_gettime(CLOCK_MONOTONIC, &next);
  while (std::chrono::steady_clock::now() < end) {
    bool got = false;
    if (mode == "immediate") {
      if (states.waitForData(std::chrono::milliseconds(10))) got = states.takeLatest(state);
    } else {
      next.tv_nsec += 5'000'000;
      if (next.tv_nsec >= 1'000'000'000) {
        next.tv_nsec -= 1'000'000'000;
        ++next.tv_sec;
      }
      clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &next, nullptr);
      got = states.takeLatest(state);
    }
    if (!got) continue;
    const std::int64_t now = reflex::bus::nowNs();
    age_us.push_back(1e-3 * static_cast<double>(now - state.header().stamp_ns()));
    command.names(state.names());
    command.positions(state.positions());
    command.velocities(std::vector<double>(state.positions().size(), 0.0));
    command.valid_until_ns(now + 20'000'000);
    command.state_seq(state.header().seq());
    command.state_stamp_ns(state.header().stamp_ns());
    commands.publish(command);
  }
  std::printf("mode %s, profile %s, %zu answers: state age when answered p50 %.0f us p99 %.0f us\n", mode.c_str(),
              participant_profile.c_str(), age_us.size(), percentile(age_us, 0.5), percentile(age_us, 0.99));
  if (robot) {
    robot->terminate();
    std::ifstream in(log);
    std::stringstream ss;
    ss << in.rdbuf();
    std::smatch m;
    const std::string text = ss.str();
    if (std::regex_search(text, m, std::regex("command latency p50 (\\d+) us p99 (\\d+) us over (\\d+) commands")))
      std::printf("robot side (RobotState.stamp -> JointCommand arrival): p50 %s us p99 %s us over %s commands\n",
                  m[1].str().c_str(), m[2].str().c_str(), m[3].str().c_str());
    if (std::regex_search(text, m, std::regex("overruns (\\d+) \\(periods lost (\\d+)\\), max lateness (\\d+) us")))
      std::printf("robot loop: %s overruns, %s periods lost, max lateness %s us\n", m[1].str().c_str(),
                  m[2].str().c_str(), m[3].str().c_str());
  }
  return 0;
}
