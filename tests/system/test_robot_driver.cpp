// reflex_test_robot: a TEST robot driver (issue 13, item 2), the smallest thing that implements the
// robot side of idl/README.md "Writing a robot driver": a kinematic integrator of
// reflex/joint_command that publishes reflex/robot_state at 1 kHz (or --period). Used by
// robot_port_test against the real reflex_controller --robot dds; not a simulator (no dynamics).
//
// Each tick: the newest JointCommand is taken; it is applied while its valid_until_ns has not passed
// (system clock): every joint it names moves towards its commanded position at its commanded speed
// |velocity| (never past the position). Without a valid command the robot HOLDS (nothing moves;
// RobotState.holding = true, applied_command_seq = 0). A command naming a joint the robot does not
// have, with lengths that differ, or with a non-finite value is refused whole (counted, never applied).
// The robot starts at the controller's rest posture (default controller configuration).
#include "reflex/control/controller.hpp"
#include "reflex/control/scenarios.hpp"
#include "reflex/control/urdf_loader.hpp"

#include <reflex/bus/bus.hpp>

#include <CLI/CLI.hpp>

#include <cmath>
#include <cstdio>
#include <ctime>

int main(int argc, char** argv) {
  CLI::App app{"reflex_test_robot: a kinematic test robot on reflex/robot_state and reflex/joint_command (tests only)"};
  std::string urdf = std::string(REFLEX_SOURCE_DIR) + "/bringup/robots/asimo_like.urdf";
  int domain = 0;
  double period = 0.001, duration = 0.0;
  app.add_option("--urdf", urdf, "robot URDF")->capture_default_str();
  app.add_option("--domain", domain, "DDS domain id")->required()->check(CLI::Range(0, reflex::bus::kMaxDomainId));
  app.add_option("--period", period, "state period [s]")->capture_default_str()->check(CLI::Range(0.0001, 0.1));
  app.add_option("--duration", duration, "seconds to run (0: until SIGTERM)")->check(CLI::NonNegativeNumber);
  CLI11_PARSE(app, argc, argv);
  using namespace reflex;
  try {
    const control::Model model = control::loadModel(urdf, control::loadCollisionConfigFor(urdf, ""));
    const control::ControllerModel cm = control::makeControllerModel(model, control::defaultControllerConfig());
    Eigen::VectorXd q = control::restConfiguration(model, cm), qdot = Eigen::VectorXd::Zero(model.nq);
    bus::BusConfig bc;
    bc.module_name = "test_robot";
    bc.domain_id = domain;
    // UDP only, no shared memory with the controller: with Fast DDS 2.9's shared-memory transport a
    // writer whose reader process was killed (kill -9 of the controller, step 4 below) stalls for the
    // port health check, about 1 s, and so would this loop (seen: holding reported after 0.98 s and no
    // state published meanwhile). A robot driver keeps its loop off that path (idl/README.md).
    bc.participant_profile = "reflex_participant_udp";
    bus::Participant participant(bc);
    bus::StopOnSignal stop_on_signal(participant, bus::stopSignals());
    auto& state_writer = participant.makeWriter<msg::RobotState>();
    auto& command_reader = participant.makeReader<msg::JointCommand>();
    msg::RobotState state;
    state.names(model.q_names);
    state.positions().assign(model.nq, 0.0);
    state.velocities().assign(model.nq, 0.0);
    msg::JointCommand cmd, incoming;
    bool have_cmd = false;
    std::vector<int> map;  // per command entry: model index
    unsigned long long applied_ticks = 0, hold_ticks = 0, refused = 0, commands = 0;
    timespec next{};
    clock_gettime(CLOCK_MONOTONIC, &next);
    const auto period_ns = static_cast<long>(std::llround(period * 1e9));
    const std::int64_t end_ns = duration > 0.0 ? bus::nowNs() + static_cast<std::int64_t>(duration * 1e9) : 0;
    std::fprintf(stderr, "reflex_test_robot: %d joints at %.0f Hz on domain %d\n", model.nq, 1.0 / period, domain);
    while (!participant.stopRequested() && (end_ns == 0 || bus::nowNs() < end_ns)) {
      next.tv_nsec += period_ns;
      while (next.tv_nsec >= 1000000000L) {
        next.tv_nsec -= 1000000000L;
        ++next.tv_sec;
      }
      clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &next, nullptr);
      while (command_reader.takeNext(incoming)) {
        ++commands;
        const std::size_t n = incoming.names().size();
        bool ok = incoming.positions().size() == n && incoming.velocities().size() == n;
        std::vector<int> m(n, -1);
        for (std::size_t k = 0; ok && k < n; ++k) {
          m[k] = model.qIndex(incoming.names()[k]);
          ok = m[k] >= 0 && std::isfinite(incoming.positions()[k]) && std::isfinite(incoming.velocities()[k]);
        }
        if (!ok) {
          ++refused;
          continue;
        }
        cmd = incoming;
        map = m;
        have_cmd = true;
      }
      const std::int64_t now = bus::nowNs();
      const bool valid = have_cmd && now <= cmd.valid_until_ns();
      qdot.setZero();
      if (valid) {
        for (std::size_t k = 0; k < map.size(); ++k) {
          const int i = map[k];
          const double step = std::abs(cmd.velocities()[k]) * period;
          const double dq = std::max(-step, std::min(step, cmd.positions()[k] - q[i]));
          q[i] += dq;
          qdot[i] = dq / period;
        }
        ++applied_ticks;
      } else {
        ++hold_ticks;
      }
      for (int i = 0; i < model.nq; ++i) {
        state.positions()[i] = q[i];
        state.velocities()[i] = qdot[i];
      }
      state.applied_command_seq(valid ? cmd.header().seq() : 0);
      state.holding(!valid);
      state_writer.publish(state);
    }
    std::fprintf(stderr, "reflex_test_robot: commands %llu (refused %llu), ticks applying %llu, holding %llu\n", commands,
                 refused, applied_ticks, hold_ticks);
    return 0;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "reflex_test_robot: error: %s\n", e.what());
    return 1;
  }
}
