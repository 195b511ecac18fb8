// reflex_test_robot: a TEST robot driver, the smallest thing that implements the
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
//
// A LYING robot, for the robot-port attack tests (tests/bad_input/robot_port_attack_test.cpp): with
// --lie KIND the published state differs from the true plant during a window (--lie-from s after the
// first applied command, for --lie-for s) for joint --lie-joint:
//   beyond_limit  the joint reported at its upper limit + --lie-amount
//   duplicate     the joint's name listed a second time, at the end, with true + --lie-amount
//   absurd        the joint reported at --lie-amount (e.g. 1e300)
//   offset        the joint reported at true + --lie-amount (what no controller can detect)
// The truth is measured on the plant every tick and printed in the exit line: the smallest distance
// of any checked pair (computeSegmentDistances, every pair exact), the largest |commanded velocity| /
// v_max and the farthest commanded position beyond a limit of any applied command, and how far any
// joint the controller does not drive as an arm joint (legs, heel, body) moved from where it started.
#include "reflex/control/controller.hpp"
#include "reflex/control/distance.hpp"
#include "reflex/control/kinematics.hpp"
#include "reflex/control/scenarios.hpp"
#include "reflex/control/urdf_loader.hpp"

#include <reflex/bus/bus.hpp>

#include <CLI/CLI.hpp>

#include <cmath>
#include <cstdio>
#include <ctime>

namespace {
/// 1 if q index i is an arm joint of the controller configuration `cm`.
int isArmJoint(const reflex::control::ControllerModel& cm, int i) {
  for (const auto& arm : cm.arms)
    for (int k = 0; k < arm.n; ++k)
      if (arm.q[k] == i) return 1;
  return 0;
}
}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"reflex_test_robot: a kinematic test robot on reflex/robot_state and reflex/joint_command (tests only)"};
  std::string urdf = std::string(REFLEX_SOURCE_DIR) + "/bringup/robots/asimo_like.urdf";
  int domain = 0;
  double period = 0.001, duration = 0.0;
  app.add_option("--urdf", urdf, "robot URDF")->capture_default_str();
  app.add_option("--domain", domain, "DDS domain id")->required()->check(CLI::Range(0, reflex::bus::kMaxDomainId));
  app.add_option("--period", period, "state period [s]")->capture_default_str()->check(CLI::Range(0.0001, 0.1));
  app.add_option("--duration", duration, "seconds to run (0: until SIGTERM)")->check(CLI::NonNegativeNumber);
  std::string lie = "none", lie_joint = "l_elbow";
  double lie_from = 1.0, lie_for = 0.3, lie_amount = 0.05;
  app.add_option("--lie", lie, "what the published state lies about (see the file's header)")
      ->check(CLI::IsMember({"none", "beyond_limit", "duplicate", "absurd", "offset"}));
  app.add_option("--lie-joint", lie_joint, "the joint lied about")->capture_default_str();
  app.add_option("--lie-from", lie_from, "s after the first applied command")->capture_default_str();
  app.add_option("--lie-for", lie_for, "s the lie lasts")->capture_default_str();
  app.add_option("--lie-amount", lie_amount, "rad or m (see the file's header)")->capture_default_str();
  CLI11_PARSE(app, argc, argv);
  using namespace reflex;
  try {
    const control::Model model = control::loadModel(urdf, control::loadCollisionConfigFor(urdf, ""));
    const control::ControllerModel cm = control::makeControllerModel(model, control::defaultControllerConfig());
    Eigen::VectorXd q = control::restConfiguration(model, cm), qdot = Eigen::VectorXd::Zero(model.nq);
    const Eigen::VectorXd q_start = q;
    const int lie_index = model.qIndex(lie_joint);
    if (lie != "none" && lie_index < 0)
      throw std::runtime_error("--lie-joint '" + lie_joint + "' is not a joint of " + urdf);
    control::KinematicsData kin(model);
    control::DistanceData dist(model);
    double truth_min = 1e9, truth_speed_ratio = 0.0, truth_beyond_limit = 0.0, truth_other_motion = 0.0;
    std::string truth_pair = "-";
    std::int64_t first_applied_ns = 0;
    unsigned long long lied = 0;
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
        if (first_applied_ns == 0) first_applied_ns = now;
        for (std::size_t k = 0; k < map.size(); ++k) {  // the command itself, against the URDF
          const int i = map[k];
          truth_speed_ratio = std::max(truth_speed_ratio, std::abs(cmd.velocities()[k]) / model.v_max[i]);
          truth_beyond_limit = std::max(
              {truth_beyond_limit, cmd.positions()[k] - model.q_upper[i], model.q_lower[i] - cmd.positions()[k]});
        }
      } else {
        ++hold_ticks;
      }
      // The truth, on the plant.
      if (control::computeForwardKinematics(model, kin, q)) {
        control::computeSegmentDistances(model, kin, dist);
        if (dist.closest >= 0 && dist.pairs[dist.closest].distance < truth_min) {
          truth_min = dist.pairs[dist.closest].distance;
          const auto& pd = dist.pairs[static_cast<std::size_t>(dist.closest)];
          truth_pair = model.segments[static_cast<std::size_t>(pd.seg_a)].name + "-" +
                       model.segments[static_cast<std::size_t>(pd.seg_b)].name;
        }
      }
      for (int i = 0; i < model.nq; ++i)
        if (isArmJoint(cm, i) == 0) truth_other_motion = std::max(truth_other_motion, std::abs(q[i] - q_start[i]));
      const double since = first_applied_ns > 0 ? 1e-9 * static_cast<double>(now - first_applied_ns) : -1.0;
      const bool lying = lie != "none" && since >= lie_from && since < lie_from + lie_for;
      if (state.names().size() != model.q_names.size()) state.names(model.q_names);  // undo a duplicate
      state.positions().resize(static_cast<std::size_t>(model.nq));
      state.velocities().resize(static_cast<std::size_t>(model.nq));
      for (int i = 0; i < model.nq; ++i) {
        state.positions()[i] = q[i];
        state.velocities()[i] = qdot[i];
      }
      if (lying) {
        ++lied;
        const auto j = static_cast<std::size_t>(lie_index);
        if (lie == "beyond_limit") state.positions()[j] = model.q_upper[lie_index] + lie_amount;
        if (lie == "absurd") state.positions()[j] = lie_amount;
        if (lie == "offset") state.positions()[j] = q[lie_index] + lie_amount;
        if (lie == "duplicate") {
          state.names().push_back(lie_joint);
          state.positions().push_back(q[lie_index] + lie_amount);
          state.velocities().push_back(0.0);
        }
      }
      state.applied_command_seq(valid ? cmd.header().seq() : 0);
      state.holding(!valid);
      state_writer.publish(state);
    }
    std::fprintf(stderr, "reflex_test_robot: commands %llu (refused %llu), ticks applying %llu, holding %llu\n",
                 commands, refused, applied_ticks, hold_ticks);
    std::fprintf(stderr,
                 "reflex_test_robot: truth: min distance %.6f m (%s), max command speed / v_max %.6f, max command "
                 "beyond a limit %.6g, max motion of a non-arm joint %.6g, states lied %llu\n",
                 truth_min, truth_pair.c_str(), truth_speed_ratio, truth_beyond_limit, truth_other_motion, lied);
    return 0;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "reflex_test_robot: error: %s\n", e.what());
    return 1;
  }
}
