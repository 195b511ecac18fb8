// The onboard controller process (paper Sec. 7, Fig. 4): the reactive controller and the robot, one
// cycle per controller period (5 ms by default), fed by the behavior layer over DDS, publishing joint
// state and controller status.
//
// Refused inputs are counted per cause (NodeStats::rejected, the causes of
// control::RejectCause and of DdsRobotPort), listed by cause in the exit line, and published every
// cycle in ControlStatus (rejected_* per topic, last_rejection the latest cause), so a module of any
// vendor sees that its sample was refused.
//
// Safety never depends on another process (DESIGN.md): distances are computed here; if the module
// that sends hand targets goes silent (no sample and no heartbeat for `input_timeout`), both hands
// get "no target" and retract to rest on their own; a NaN or out-of-frame target is dropped and
// counted. The loop runs on its own clock (absolute deadlines), polling the readers each cycle; with
// --trigger state a robot state starts each cycle instead, the period the longest wait (run()).
//
// With a robot state file (NodeConfig::robot_state) the simulated robot behaves like hardware across
// a controller crash: its joint positions are written every cycle and a new controller starts from
// them (robot_state_file.hpp). Resumed that way, the hands hold where they are until the target
// source speaks, for at most input_timeout (the grace any silence gets), then retract as usual.
//
// Protection: collision avoidance and the red-zone e-stop are separate switches.
// Avoidance may be switched off by --no-avoidance or by `avoidance: off` in the controller YAML
// (comparison runs); the e-stop only by NodeConfig::estop = false, i.e. the loudly named
// --disable-estop option, never by a file. What is on is published on reflex/controller_protection
// (late joiners get it), printed in the banner and in the exit line.
//
// Liveliness of the target source is tied to the DDS participant that wrote the
// last hand targets: only a heartbeat from that same participant counts as a sign of life, whatever
// module name it or any other participant claims.
//
// One controller per domain: the constructor publishes this controller's
// protection sample and then looks, for NodeConfig::peer_probe seconds, for the sample of another
// controller (a different participant). The one that published first keeps the domain: a later one
// throws (refuses to start), naming the first; if discovery was slower than the probe (measured here:
// 0.5 to 3 s), the later one leaves its loop as soon as it sees the first (peerRefusal(), exit 1), and
// the behavior side follows one joint-state writer only. The first one reports the later one.
//
// The --log file is streamed by a writer thread from a preallocated ring (timeseries_log.hpp): opened
// before the loop, every write checked; it survives any stop but SIGKILL.
//
// The bus writes of the loop (joint state, status, heartbeats, and with --robot dds the joint
// commands) are made by another thread too (bus::Outbox, reflex/bus/outbox.hpp): a DDS write can block for a
// second (a dead reader on shared memory) and the loop never waits for one. Samples are stamped in
// the cycle; what a stuck writer cannot take is dropped, counted and named in the exit line.
//
// The cycle itself (staleness, priority, body schema by name, walking, computeControl, the plant) is
// reflex::control::OnboardController (control/include/reflex/control/onboard.hpp): this node is the
// thin adapter between DDS samples and that object.
//
// The robot side (NodeConfig::robot): "kinematic" (default) is the in-process
// kinematic plant; "dds" is a robot driver on the bus (DdsRobotPort, dds_robot_port.hpp): the
// controller computes from the measured reflex/robot_state and answers each cycle with one
// reflex/joint_command; "unitree_hg" is a robot on Unitree's hg interface (UnitreeHgPort,
// unitree_hg_port.hpp: rt/lowstate in, rt/arm_sdk out, the weight ramped in and, after the loop, out). Without a state newer than robot_timeout it computes and commands nothing
// (the robot holds once the last command's deadline passed) and says so at once: a line on stderr,
// the heartbeat's `detail` ("robot state stale: ..."; "" again when fresh state returns), the exit
// line; joint state is not published meanwhile.
#pragma once

#include "reflex/control/controller.hpp"
#include "reflex/control/onboard.hpp"
#include "reflex/control/scenarios.hpp"
#include "reflex/control/simulation.hpp"
#include "reflex/control_node/bus_robot_port.hpp"
#include <reflex/msg/control.h>

#include <array>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

namespace reflex::bus {
class Participant;
}
namespace reflex::msg {
class ControllerProtection;
}

namespace reflex::control_node {

struct NodeConfig {
  std::string urdf;           ///< robot description
  std::string collision;      ///< collision configuration ("" = next to the URDF)
  std::string controller;     ///< controller YAML ("" = <stem>.controller.yaml beside the URDF, else defaults)
  std::string profiles_file;  ///< DDS profiles ("" = bus defaults)
  /// UDP only by default: on Fast DDS 2.9's shared memory, a reader process killed at
  /// the wrong moment (a recorder, a view) stalls every write of this participant for 1-3 s (the
  /// port health check), so the robot and every module lost the controller's outputs meanwhile.
  /// Over UDP a dead reader costs nothing; the latency is the same (control/README.md).
  std::string participant_profile = "reflex_participant_udp";
  int domain_id = -1;                ///< -1 = bus default
  double duration = 0.0;             ///< seconds to run (0 = until SIGINT/SIGTERM)
  double input_timeout = 1.0;        ///< s without targets and heartbeat from their source -> retract
  double max_target_distance = 2.0;  ///< m from the base origin; farther targets are rejected
  bool avoidance = true;             ///< false: collision avoidance off (comparison runs only)
  /// The red-zone emergency stop (Sec. 7.1). false ONLY from the loudly named --disable-estop option;
  /// no configuration file can switch it off.
  bool estop = true;
  /// s to look for another controller on the domain before the loop starts (>= 0; 0: no wait, the
  /// run-time detection still reports one).
  double peer_probe = 1.0;
  std::string log_csv;  ///< stream the time series (reflex_sim's format) to this file
  /// Joint positions of the simulated robot, kept across controller restarts ("" = none: start from
  /// rest). Loaded at start, written every cycle; see robot_state_file.hpp for format and policy.
  std::string robot_state;
  std::string module_name = "controller";
  /// The robot side: "kinematic" (the in-process plant) or "dds" (reflex/robot_state in,
  /// reflex/joint_command out; idl/README.md "Writing a robot driver"). Anything else: ConfigError.
  std::string robot = "kinematic";
  /// s: with "dds", a newest robot state older than this is stale. (0, 1]. Default 50 ms (10 cycles,
  /// 50 robot states at 1 kHz): the timeout is about liveness, not about the distance judged. Every
  /// command is anchored at the state it answers (q_measured + qdot dt, the step the controller
  /// checked), so an older state pulls the robot back towards what was checked; it never lets it run
  /// on. 20 ms flapped stale/fresh in test runs on a loaded two-core host, each
  /// flap a freeze and a hold of the robot.
  double robot_timeout = 0.050;
  /// s: with "dds", JointCommand.valid_until_ns = now + this. 0 = three controller periods; else [period, 1].
  double command_deadline = 0.0;
  /// With "unitree_hg": the joint map (unitree_hg.hpp, loadHgJointMap); "" = <URDF stem>.hg.yaml beside
  /// the URDF (an error if there is none). Given with another robot side: ConfigError.
  std::string joint_map;
  /// s: with "unitree_hg", the arm_sdk weight's ramp from 0 to 1 at start and back at stop; (0, 60].
  double ramp_time = 3.0;
  /// What starts a cycle: "timer" (one every period, the default) or "state" (one per arriving robot
  /// state, the period as the longest wait; needs a robot that sends states, --robot dds). Anything
  /// else: ConfigError. See ControllerNode::run().
  std::string trigger = "timer";
  /// With "ros2" (Ros2RobotPort, ros2_port.hpp): the ROS topic of the sensor_msgs/JointState in, the
  /// command kind ("forward": std_msgs/Float64MultiArray to a forward controller, "trajectory":
  /// trajectory_msgs/JointTrajectory), the ros2_control controller's name ("" its kind's default) and
  /// its joints in its order (empty: the joints Reflex drives). Given with another robot side: ConfigError.
  std::string ros_state_topic = "joint_states";
  std::string ros_command = "forward";
  std::string ros_controller;
  std::vector<std::string> ros_joints;
};

/// Counters reported at exit and in tests.
struct NodeStats {
  std::uint64_t cycles = 0;
  std::uint64_t overruns = 0;
  double max_lateness_us = 0.0;
  double min_distance = msg::NO_PAIR_DISTANCE;  ///< physical pairs, over the run (m)
  std::uint64_t estop_count = 0;
  std::uint64_t guard_count = 0;  ///< cycles whose step the predictive guard shortened
  std::uint64_t targets_received = 0;
  std::uint64_t targets_rejected = 0;  ///< every refused hand target, body-schema change and walk command
  std::array<std::uint64_t, control::kRejectCauses> rejected{};  ///< the same per control::RejectCause
  std::uint64_t stale_events = 0;                                ///< transitions to "inputs stale"
  std::uint64_t state_write_errors = 0;                          ///< failed writes of the robot state file
  std::vector<double> lateness_us;                               ///< per cycle (for percentiles), reserved up front
  std::uint64_t peer_controller_samples = 0;  ///< protection samples of ANOTHER controller seen while running
  std::uint64_t log_rows = 0;                 ///< --log rows written
  std::uint64_t log_dropped = 0;              ///< --log rows dropped (the writer could not keep up)
  // The robot side (--robot dds; zero with the kinematic plant).
  std::uint64_t robot_stale_events = 0;  ///< transitions to "no fresh robot state" (the first missing state counts)
  std::uint64_t robot_stale_cycles = 0;  ///< cycles that computed and commanded nothing for lack of state
  bool robot_stale_at_exit = false;
  std::uint64_t robot_states_accepted = 0;
  std::uint64_t robot_states_rejected = 0;  ///< wrong lengths, a missing joint, NaN, a future or old stamp,
                                            ///< a name twice, outside the limits, another writer's
  std::array<std::uint64_t, kRobotStateCauses>
      robot_states_rejected_by_cause{};    ///< the same per cause (robotStateCauseName)
  std::uint64_t robot_writer_changes = 0;  ///< a silent robot writer replaced by a new one
  double arm_sdk_weight = -1.0;            ///< --robot unitree_hg: the arm_sdk weight last sent (-1: other robots)
  double arm_sdk_max_weight_step = 0.0;    ///< --robot unitree_hg: its largest change between two commands
  const char* last_rejection = "";         ///< the latest refusal's cause name ("" none), as in ControlStatus
  std::uint64_t robot_commands =
      0;  ///< JointCommand samples handed to the bus (queued for the outbox's writer thread; its drops are in bus_dropped)
  // The loop's bus outputs (joint state, status, heartbeat, joint commands), written by the outbox's thread
  // (reflex/bus/outbox.hpp): what reached the middleware, what it refused, what a full ring dropped, and
  // the writes that blocked (longer than 50 ms; the loop never waits for them).
  std::uint64_t bus_written = 0;
  std::uint64_t bus_write_failures = 0;
  std::uint64_t bus_dropped = 0;
  std::uint64_t bus_stalls = 0;
  double bus_longest_write_s = 0.0;
  std::string bus_longest_topic;
};

/// The name of a robot port's rejection cause (bus_robot_port.hpp: 0 lengths .. 7 another writer, 8..10
/// Unitree hg) as ControlStatus.last_rejection and the exit line print it: "robot_state_length",
/// ..._missing_joint, ..._not_finite, ..._future_stamp, ..._old_stamp, ..._duplicate_name,
/// ..._outside_limits, ..._other_writer, ..._bad_crc, ..._motor_count, ..._old_tick.
const char* robotStateCauseName(int cause) noexcept;

/// "hand_target_too_far 3, walk_bad_value 1" for the non-zero counters of `stats` ("" if none).
std::string describeRejections(const NodeStats& stats);

/// What protects the robot in this run (published on reflex/controller_protection).
struct Protection {
  bool avoidance = true;
  bool estop = true;
  std::string reason;  ///< "" when both are on; else what switched which off and from where
  double period = 0.005;
  std::string robot;
  bool full() const { return avoidance && estop; }
  /// "full (avoidance one_dof, e-stop on)" or "REDUCED: <reason>".
  std::string describe() const;
};

class ControllerNode {
 public:
  /// Loads the robot and controller and creates the DDS entities. Throws on any set-up error,
  /// naming the file / value / entity.
  explicit ControllerNode(const NodeConfig& config);
  ~ControllerNode();
  ControllerNode(const ControllerNode&) = delete;
  ControllerNode& operator=(const ControllerNode&) = delete;

  /// Runs the control loop until stop(), a signal, or the configured duration. Closes the --log file
  /// at the end (see logFailure()).
  ///
  /// trigger "timer": a cycle every ControllerParams::period on absolute deadlines.
  /// trigger "state": the loop waits for the next robot state (DdsRobotPort::waitForState) and runs a
  /// cycle as soon as one arrives, spanning the time since the previous cycle, at most the robot's
  /// state interval (DdsRobotPort::stateInterval()) and one period (OnboardController::step(now, dt)),
  /// so a command answers its state at once and no joint is asked to move more than v_max times the
  /// robot's interval; a flood of samples cannot run walking or the trajectory faster than real time. The period stays the longest wait:
  /// when no state arrives within it, the cycle runs exactly as the timer's would (from the newest
  /// state while it is fresh, spanning one period; nothing computed or commanded once it is stale), so
  /// staleness, the e-stop and the command deadline are those of the timer. A cycle started by a state
  /// is never late (lateness 0); one started by the wait's end is late by its wake-up delay.
  void run();
  void stop() noexcept;
  /// Asks the controller to leave a latched e-stop (only separating motion, Sec. 7.1).
  void requestEstopReset() noexcept;

  const NodeStats& stats() const { return stats_; }
  /// What the start-up did about the robot state ("" without a robot state file).
  const std::string& robotStateNote() const;
  /// With --robot ros2: the DDS topics and types it speaks and the commanded joints ("" otherwise).
  const std::string& robotInterfaceNote() const;
  /// Which controller configuration it uses and the arms it names (describeControllerConfig).
  const std::string& controllerConfigNote() const;
  const Protection& protection() const;
  /// After run(): "" if the --log file (if any) got every row and closed cleanly; else the error
  /// naming the file and the reason.
  std::string logFailure() const;
  /// After run(): "" or why the loop stopped early for another controller that claimed the domain
  /// first but was discovered only after the start-up probe (exit code 1).
  const std::string& peerRefusal() const;
  bus::Participant& bus();

 private:
  /// A protection sample of another controller (participant `them`): true if that one claimed the
  /// domain first (peerRefusal() then says so); else said once on stderr and counted.
  bool notePeerController(const reflex::msg::ControllerProtection& other, const std::array<unsigned char, 12>& them);
  struct Impl;
  std::unique_ptr<Impl> impl_;
  NodeStats stats_;
};

}  // namespace reflex::control_node
