// reflex_controller: the onboard controller process over DDS. See controller_node.hpp.
#include "reflex/common/run_main.hpp"
#include "reflex/common/shipped.hpp"
#include "reflex/control_node/controller_node.hpp"
#include "reflex/control_node/realtime.hpp"

#include <reflex/bus/bus.hpp>
#include <reflex/bus/cli.hpp>

#include <CLI/CLI.hpp>

#include <algorithm>
#include <csignal>
#include <cstdio>

namespace {
reflex::control_node::ControllerNode* g_node = nullptr;
extern "C" void onUsr1(int) {
  if (g_node) g_node->requestEstopReset();  // only sets an atomic flag
}
/// What the command line sets.
struct Options {
  reflex::control_node::NodeConfig config;
  bool no_avoidance = false, disable_estop = false;
  std::string realtime;
  /// The controller's participant is UDP only by default: a killed shared-memory reader cannot stall
  /// its writes.
  reflex::bus::BusOptions bus{"", "", "reflex_participant_udp"};
};

void addOptions(CLI::App& app, Options& o) {
  reflex::control_node::NodeConfig& config = o.config;
  bool& no_avoidance = o.no_avoidance;
  bool& disable_estop = o.disable_estop;
  std::string& realtime = o.realtime;
  config.urdf = reflex::common::defaultUrdf();
  app.add_option("--urdf", config.urdf, "robot URDF")->capture_default_str();
  app.add_option("--collision", config.collision, "collision configuration (default: next to the URDF)");
  app.add_option("--controller", config.controller,
                 "controller configuration YAML (default: <URDF stem>.controller.yaml beside the URDF if it exists, "
                 "else built-in, the asimo_like robot's arms; the banner names the one used); 'avoidance: off' there "
                 "switches avoidance off but never the e-stop");
  o.bus.add(app, "UDP only by default: a killed shared-memory reader cannot stall the controller's writes");
  app.add_option("--duration", config.duration, "seconds to run (0: until Ctrl-C)")->check(CLI::NonNegativeNumber);
  app.add_option("--input-timeout", config.input_timeout,
                 "seconds of silence from the target source before the hands retract")
      ->capture_default_str()
      ->check(CLI::PositiveNumber);
  app.add_flag("--no-avoidance", no_avoidance,
               "collision avoidance off (comparison runs only; never on a robot); the e-stop stays on");
  app.add_flag("--disable-estop", disable_estop,
               "DANGER: switch the red-zone emergency stop off (comparison runs in simulation only; never on a "
               "robot). Printed in the banner, the exit line and on reflex/controller_protection");
  app.add_option("--peer-probe", config.peer_probe,
                 "seconds to look for another controller on the domain before starting (refuses to start if one "
                 "runs; 0: no wait)")
      ->capture_default_str();
  app.add_option("--log", config.log_csv,
                 "stream the per-cycle time series CSV to this file (opened at start; a write error is exit code 3)");
  app.add_option("--robot-state", config.robot_state,
                 "keep the simulated robot's joint positions in this file across restarts (loaded at start, "
                 "written every cycle; refused if it holds another robot or is damaged)");
  app.add_option("--robot", config.robot,
                 "the robot side: 'kinematic' (the in-process plant), 'dds' (a robot driver on reflex/robot_state "
                 "and reflex/joint_command), 'unitree_hg' (Unitree's low-level interface: every joint read from "
                 "rt/lowstate, the arms commanded on rt/arm_sdk beside the robot's walking controller, with "
                 "--joint-map) or 'ros2' (ROS 2 on the wire, no ROS 2 needed here: sensor_msgs/JointState in, "
                 "a ros2_control controller's command out; idl/README.md 'Robots that already have an interface')")
      ->capture_default_str();
  app.add_option("--ros-state-topic", config.ros_state_topic,
                 "--robot ros2: the ROS topic of the robot's sensor_msgs/JointState (DDS topic rt/<topic>)")
      ->capture_default_str();
  app.add_option("--ros-command", config.ros_command,
                 "--robot ros2: 'forward' (std_msgs/Float64MultiArray on rt/<controller>/commands, a ros2_control "
                 "forward_command_controller) or 'trajectory' (trajectory_msgs/JointTrajectory on "
                 "rt/<controller>/joint_trajectory)")
      ->capture_default_str();
  app.add_option("--ros-controller", config.ros_controller,
                 "--robot ros2: the ros2_control controller's name (default forward_position_controller, or "
                 "joint_trajectory_controller with --ros-command trajectory)");
  app.add_option("--ros-joints", config.ros_joints,
                 "--robot ros2: the controller's joints in its order (its `joints:` parameter; a joint Reflex does "
                 "not drive gets its measured position); default: the joints Reflex drives")
      ->delimiter(',');
  app.add_option(
      "--joint-map", config.joint_map,
      "--robot unitree_hg: the joint map YAML (motor index <-> URDF joint, kp / kd of the commanded "
      "motors, joints held fixed), e.g. bringup/robots/unitree_g1_29dof.hg.yaml (default: <URDF stem>.hg.yaml "
      "beside the URDF)");
  app.add_option("--ramp-time", config.ramp_time,
                 "--robot unitree_hg: seconds for the arm_sdk weight to rise from 0 to 1 after the first command "
                 "and to fall back to 0 after the last cycle (the exit waits for it); (0, 60]")
      ->capture_default_str()
      ->check(reflex::FiniteRange(1e-3, 60.0));
  app.add_option(
         "--robot-timeout", config.robot_timeout,
         "seconds (system clock, against the state's stamp) after which the newest robot state is stale "
         "(--robot dds; with unitree_hg since the state was taken, LowState_ has no stamp): the controller then "
         "commands nothing until fresh state returns; (0, 1]. Commands "
         "are anchored at the state they answer, so the timeout is about liveness: 50 ms rides out a loaded "
         "host's scheduling stalls")
      ->capture_default_str();
  app.add_option("--command-deadline", config.command_deadline,
                 "seconds each joint command stays valid (--robot dds; JointCommand.valid_until_ns = now + this); "
                 "0: three controller periods; else [period, 1]")
      ->capture_default_str();
  app.add_option("--trigger", config.trigger,
                 "what starts a control cycle: 'timer' (one every controller period, 5 ms by default) or 'state' (with "
                 "--robot dds: one per arriving reflex/robot_state, with unitree_hg per rt/lowstate, so each command "
                 "answers its state at once; the "
                 "driver sets the rate, e.g. 500 Hz). With 'state' a cycle spans the time since the previous one, at "
                 "most the robot's state interval and one period (no joint is commanded more than v_max times it), and "
                 "the period is the longest wait: "
                 "when no state arrives within it the cycle runs as the timer's (stale after --robot-timeout: "
                 "nothing commanded). Cycles started by a state report lateness 0")
      ->capture_default_str();
  app.add_option("--realtime", realtime,
                 "PRIORITY[,CPU]: run real-time: pin the process to CPU (if given), SCHED_FIFO at PRIORITY (1..99), "
                 "lock all memory (mlockall) and pre-fault the stack, before any thread starts (the DDS threads "
                 "inherit it). Refused with exit 2, naming the value and the reason, where not permitted (needs "
                 "root, or CAP_SYS_NICE and CAP_IPC_LOCK, or rtprio/memlock limits) or not possible (a CPU this "
                 "process may not use): it never runs without what was asked. E.g. --realtime 80,1");
  app.add_option("--name", config.module_name,
                 "module name on the bus (1.." + std::to_string(reflex::bus::kMaxKeyStringBytes) + " bytes)")
      ->capture_default_str();
}

/// The banner: the configuration, the robot, the rate and what protects the run.
void printBanner(reflex::control_node::ControllerNode& node, const reflex::control_node::NodeConfig& config) {
  std::fprintf(stderr, "reflex_controller: %s\n", node.controllerConfigNote().c_str());
  if (!node.robotStateNote().empty()) std::fprintf(stderr, "reflex_controller: %s\n", node.robotStateNote().c_str());
  if (!node.robotInterfaceNote().empty())
    std::fprintf(stderr, "reflex_controller: %s\n", node.robotInterfaceNote().c_str());
  const auto& protection = node.protection();
  if (config.trigger == "state")
    std::fprintf(stderr,
                 "reflex_controller: a cycle per arriving robot state, at least every %.3f ms (--trigger state) "
                 "on domain %d, robot '%s' (robot over DDS); protection %s\n",
                 protection.period * 1e3, node.bus().domainId(), protection.robot.c_str(),
                 protection.describe().c_str());
  else
    std::fprintf(
        stderr, "reflex_controller: running at %.1f Hz (period %.3f ms) on domain %d, robot '%s' (%s); protection %s\n",
        1.0 / protection.period, protection.period * 1e3, node.bus().domainId(), protection.robot.c_str(),
        config.robot == "dds"          ? "robot over DDS"
        : config.robot == "unitree_hg" ? "Unitree hg: rt/lowstate in, rt/arm_sdk out"
        : config.robot == "ros2"       ? "ROS 2: sensor_msgs/JointState in, ros2_control command out"
                                       : "kinematic plant",
        protection.describe().c_str());
  if (!protection.full())
    std::fprintf(stderr, "reflex_controller: WARNING: THIS RUN IS NOT PROTECTED: %s\n", protection.reason.c_str());
}

/// The exit line: cycles, lateness, distances, e-stops, what was rejected and why, the bus writes.
void printExitLine(reflex::control_node::ControllerNode& node, const reflex::control_node::NodeConfig& config) {
  const auto& protection = node.protection();
  const auto& s = node.stats();
  std::vector<double> lat = s.lateness_us;
  std::sort(lat.begin(), lat.end());
  auto pct = [&](double p) {
    return lat.empty() ? 0.0 : lat[std::min(lat.size() - 1, static_cast<std::size_t>(p * lat.size()))];
  };
  std::string extra;
  if (lat.size() < s.cycles) extra += " (percentiles over the first " + std::to_string(lat.size()) + " cycles)";
  if (s.state_write_errors > 0) extra += ", robot-state writes FAILED " + std::to_string(s.state_write_errors);
  if (!config.log_csv.empty())
    extra += ", log rows " + std::to_string(s.log_rows) + " (dropped " + std::to_string(s.log_dropped) + ")";
  if (s.peer_controller_samples > 0)
    extra += ", ANOTHER CONTROLLER seen " + std::to_string(s.peer_controller_samples) + " times";
  if (config.robot != "kinematic") {
    extra += ", robot " + config.robot + ": states " + std::to_string(s.robot_states_accepted) + " (rejected " +
             std::to_string(s.robot_states_rejected) + "), commands " + std::to_string(s.robot_commands) +
             ", robot stale events " + std::to_string(s.robot_stale_events) + " (" +
             std::to_string(s.robot_stale_cycles) + " cycles without state)";
    if (s.robot_stale_at_exit) extra += ", ROBOT STATE STALE at exit";
    if (s.arm_sdk_weight >= 0.0) {
      char w[128];
      std::snprintf(w, sizeof(w), ", arm_sdk weight at exit %.3f (largest step %.5f)", s.arm_sdk_weight,
                    s.arm_sdk_max_weight_step);
      extra += w;
    }
    if (s.robot_writer_changes > 0)
      extra += ", robot writer replaced " + std::to_string(s.robot_writer_changes) + " times";
    if (s.robot_states_rejected_by_cause[7] > 0)
      extra += ", SECOND ROBOT WRITER ignored (" + std::to_string(s.robot_states_rejected_by_cause[7]) + " samples)";
  }
  if (s.targets_rejected + s.robot_states_rejected > 0)
    extra += ", rejected by cause: " + reflex::control_node::describeRejections(s) + " (last " + s.last_rejection + ")";
  {  // the loop's bus outputs (reflex/bus/outbox.hpp): a blocked write never stopped the loop; it is named here
    char bus_line[256];
    std::snprintf(bus_line, sizeof(bus_line),
                  ", bus writes %llu (dropped %llu, refused %llu, blocked > 50 ms %llu, longest %.1f ms%s%s)",
                  static_cast<unsigned long long>(s.bus_written), static_cast<unsigned long long>(s.bus_dropped),
                  static_cast<unsigned long long>(s.bus_write_failures), static_cast<unsigned long long>(s.bus_stalls),
                  1e3 * s.bus_longest_write_s, s.bus_longest_topic.empty() ? "" : " ", s.bus_longest_topic.c_str());
    extra += bus_line;
  }
  extra += ", protection " + protection.describe();
  std::fprintf(stderr,
               "reflex_controller: %llu cycles, lateness p50 %.0f us p99 %.0f us max %.0f us, overruns %llu, "
               "min distance %.1f mm, e-stops %llu, targets %llu (rejected %llu), stale events %llu, "
               "guard-shortened steps %llu%s\n",
               static_cast<unsigned long long>(s.cycles), pct(0.5), pct(0.99), s.max_lateness_us,
               static_cast<unsigned long long>(s.overruns), s.min_distance * 1000.0,
               static_cast<unsigned long long>(s.estop_count), static_cast<unsigned long long>(s.targets_received),
               static_cast<unsigned long long>(s.targets_rejected), static_cast<unsigned long long>(s.stale_events),
               static_cast<unsigned long long>(s.guard_count), extra.c_str());
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{
      "reflex_controller: onboard reactive controller (one cycle per controller 'period', 5 ms by default)\n"
      "over DDS, with the in-process kinematic robot (--robot kinematic, default) or a robot driver on the bus\n"
      "(--robot dds: reads reflex/robot_state, writes reflex/joint_command; idl/README.md). Subscribes hand\n"
      "targets, motion priority, body schema, walk commands; publishes joint state, controller status, its\n"
      "protection state and a heartbeat (its detail says 'robot state stale ...' while --robot dds has no\n"
      "fresh robot state: the controller then commands nothing and the robot holds).\n"
      "SIGUSR1 asks to leave a latched e-stop; SIGINT, SIGTERM, SIGHUP, SIGUSR2 and every other catchable\n"
      "terminating signal stop it cleanly (summary, --log closed); SIGPIPE is ignored.\n"
      "Exit codes: 0 success; 1 failed while running (expired DDS-Security credentials); 2 refused: a bad\n"
      "option, file or set-up, named, or another controller keeps the domain; 3 the --log file could not be\n"
      "written completely."};
  Options options;
  addOptions(app, options);
  reflex::control_node::NodeConfig& config = options.config;
  const bool& no_avoidance = options.no_avoidance;
  const bool& disable_estop = options.disable_estop;
  const std::string& realtime = options.realtime;
  return reflex::runMain("reflex_controller", app, argc, argv, [&]() -> int {
    config.avoidance = !no_avoidance;
    config.domain_id = options.bus.domainId().value_or(-1);
    config.profiles_file = options.bus.profiles;
    config.participant_profile = options.bus.participant_profile;
    config.estop = !disable_estop;
    std::signal(SIGPIPE, SIG_IGN);  // from the start: a closed stderr never ends the process,
    std::signal(SIGXFSZ, SIG_IGN);  // nor a file size limit (the failed write is reported instead)
    std::signal(SIGUSR1, onUsr1);   // ignored until the node exists (g_node)
    if (!realtime.empty()) {        // before the node: every thread it starts inherits the policy and the CPU
      const std::string applied =
          reflex::control_node::applyRealtime(reflex::control_node::parseRealtime(realtime), realtime);
      std::fprintf(stderr, "reflex_controller: real-time: %s\n", applied.c_str());
    }
    reflex::control_node::ControllerNode node(config);
    // Every catchable terminating signal stops the loop (the log is closed, the summary printed);
    // SIGUSR1 is the e-stop reset, handled here.
    std::vector<int> stop_signals = reflex::bus::stopSignals();
    stop_signals.erase(std::remove(stop_signals.begin(), stop_signals.end(), SIGUSR1), stop_signals.end());
    reflex::bus::StopOnSignal stop_on_signal(node.bus(), stop_signals);
    g_node = &node;
    printBanner(node, config);
    node.run();
    printExitLine(node, config);
    g_node = nullptr;
    if (!node.peerRefusal().empty()) {
      std::fprintf(stderr, "reflex_controller: error: %s\n", node.peerRefusal().c_str());
      return reflex::kExitRefused;  // the same refusal as at start (another controller keeps the domain)
    }
    if (const std::string log_error = node.logFailure(); !log_error.empty()) {
      std::fprintf(stderr, "reflex_controller: error: %s\n", log_error.c_str());
      return 3;
    }
    // DDS-Security material that expired during the run stopped the loop (bus::Participant): not success.
    if (node.bus().credentialsExpired()) return 1;
    return 0;
  });
}
