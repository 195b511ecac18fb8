// reflex_mujoco: the physics-simulated humanoid on the bus. See robot_node.hpp and control/README.md
// ("The physics robot: reflex_mujoco").
#include "reflex/common/run_main.hpp"
#include "reflex/common/shipped.hpp"
#include "reflex/mujoco/robot_node.hpp"
#include "reflex/control/urdf_loader.hpp"

#include <reflex/bus/bus.hpp>
#include <reflex/bus/cli.hpp>

#include <CLI/CLI.hpp>

#include <csignal>
#include <cstdio>

int main(int argc, char** argv) {
  CLI::App app{
      "reflex_mujoco: the robot on the bus, simulated by MuJoCo from the same URDF and collision model as the\n"
      "controller (capsules as capsules, gravity, armature, PD servos with torque limits on every joint).\n"
      "Publishes reflex/robot_state and reflex/robot_contacts every --period; applies the newest\n"
      "reflex/joint_command whose valid_until_ns has not passed and whose joint names it knows, and holds the\n"
      "measured position when there is none. MuJoCo reports every checked segment pair closer than --margin\n"
      "(d_r) with its own distance, without force until the pair penetrates (RobotContacts).\n"
      "SIGINT / SIGTERM stop it; the summary (steps, contact steps, commands applied / rejected, hold time,\n"
      "command latency) is printed at exit. Exit codes: 0 success, 1 failed while running, 2 refused: a bad\n"
      "option, file or set-up, named."};
  reflex::mujoco::NodeConfig config;
  config.urdf = reflex::common::defaultUrdf();
  bool print_mjcf = false;
  app.add_option("--urdf", config.urdf, "robot URDF")->capture_default_str();
  app.add_option("--collision", config.collision, "collision configuration (default: next to the URDF)");
  app.add_option("--q", config.initial, "initial joint position joint=value (rad or m), repeatable; others 0");
  app.add_option("--period", config.period, "state publication period [s]")->capture_default_str();
  app.add_option("--timestep", config.mjcf.timestep, "physics step [s]; the period must be a whole multiple")
      ->capture_default_str();
  app.add_option("--margin", config.mjcf.margin, "contact margin = gap = d_r [m]: pairs closer are reported")
      ->capture_default_str();
  app.add_option("--limb-bandwidth", config.mjcf.limb_bandwidth_hz, "servo bandwidth of arm, head, leg joints [Hz]")
      ->capture_default_str();
  app.add_option("--limb-effort", config.mjcf.limb_effort, "torque limit of arm, head, leg joints [N m]")
      ->capture_default_str();
  app.add_option("--duration", config.duration, "seconds to run (0: until stopped)")->capture_default_str();
  reflex::bus::BusOptions bus_options{"", "", config.participant_profile};
  bus_options.add(app);
  app.add_option("--name", config.module_name, "module name on the bus")->capture_default_str();
  app.add_flag("--print-mjcf", print_mjcf, "print the generated MJCF to stdout and exit");
  app.add_option("--interface", config.interface,
                 "'reflex' (reflex/robot_state out, reflex/joint_command in) or 'unitree_hg' (Unitree's rt/lowstate "
                 "out with tick and crc, rt/arm_sdk in blended by its weight with the robot's own controller, which "
                 "holds the start configuration; --joint-map)")
      ->capture_default_str();
  app.add_option("--joint-map", config.joint_map,
                 "--interface unitree_hg: the joint map YAML (motor index <-> URDF joint), e.g. "
                 "bringup/robots/asimo_like.hg.yaml (default: <URDF stem>.hg.yaml beside the URDF)");
  return reflex::runMain("reflex_mujoco", app, argc, argv, [&]() -> int {
    std::signal(SIGPIPE, SIG_IGN);
    config.domain_id = bus_options.domainId();
    config.profiles_file = bus_options.profiles;
    config.participant_profile = bus_options.participant_profile;
    if (print_mjcf) {
      const auto model = reflex::control::loadModel(
          config.urdf, reflex::control::loadCollisionConfigFor(config.urdf, config.collision));
      std::fputs(reflex::mujoco::makeMjcf(model, config.mjcf, reflex::mujoco::servoGains(model, config.mjcf)).c_str(),
                 stdout);
      return 0;
    }
    reflex::mujoco::RobotNode node(config);
    reflex::bus::StopOnSignal stop_on_signal(node.bus());
    std::fprintf(stderr, "reflex_mujoco: %s", node.summary().c_str());
    std::fprintf(stderr, "reflex_mujoco: running on domain %d\n", node.bus().domainId());
    node.run();
    std::fprintf(stderr, "reflex_mujoco: %s\n", node.exitSummary().c_str());
    return 0;
  });
}
