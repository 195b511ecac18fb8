// The onboard controller process (paper Sec. 7, Fig. 4): the reactive controller and the robot at
// 200 Hz, fed by the behavior layer over DDS, publishing joint state and controller status.
//
// Safety never depends on another process (DESIGN.md): distances are computed here; if the module
// that sends hand targets goes silent (no sample and no heartbeat for `input_timeout`), both hands
// get "no target" and retract to rest on their own; a NaN or out-of-frame target is dropped and
// counted. The loop runs on its own clock (absolute deadlines), polling the readers each cycle.
//
// With a robot state file (NodeConfig::robot_state) the simulated robot behaves like hardware across
// a controller crash: its joint positions are written every cycle and a new controller starts from
// them (robot_state_file.hpp). Resumed that way, the hands hold where they are until the target
// source speaks, for at most input_timeout (the grace any silence gets), then retract as usual.
//
// Extending: another robot driver implements reflex::control::RobotInterface and is passed in.
#pragma once

#include "reflex/control/controller.hpp"
#include "reflex/control/scenarios.hpp"
#include "reflex/control/simulation.hpp"

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

namespace reflex::bus {
class Participant;
}

namespace reflex::control_node {

struct NodeConfig {
  std::string urdf;                  ///< robot description
  std::string collision;             ///< collision configuration ("" = next to the URDF)
  std::string controller;            ///< controller YAML ("" = defaults)
  std::string profiles_file;         ///< DDS profiles ("" = bus defaults)
  std::string participant_profile = "reflex_participant";
  int domain_id = -1;                ///< -1 = bus default
  double duration = 0.0;             ///< seconds to run (0 = until SIGINT/SIGTERM)
  double input_timeout = 1.0;        ///< s without targets and heartbeat from their source -> retract
  double max_target_distance = 2.0;  ///< m from the base origin; farther targets are rejected
  bool avoidance = true;             ///< false: collision avoidance off (comparison runs only)
  std::string log_csv;               ///< write the time series (reflex_sim's format) here at exit
  /// Joint positions of the simulated robot, kept across controller restarts ("" = none: start from
  /// rest). Loaded at start, written every cycle; see robot_state_file.hpp for format and policy.
  std::string robot_state;
  std::string module_name = "controller";
};

/// Counters reported at exit and in tests.
struct NodeStats {
  std::uint64_t cycles = 0;
  std::uint64_t overruns = 0;
  double max_lateness_us = 0.0;
  double min_distance = 1e9;          ///< physical pairs, over the run (m)
  std::uint64_t estop_count = 0;
  std::uint64_t guard_count = 0;      ///< cycles whose step the predictive guard shortened
  std::uint64_t targets_received = 0;
  std::uint64_t targets_rejected = 0;
  std::uint64_t stale_events = 0;     ///< transitions to "inputs stale"
  std::uint64_t state_write_errors = 0;  ///< failed writes of the robot state file
  std::vector<double> lateness_us;    ///< per cycle (for percentiles), reserved up front
};

class ControllerNode {
 public:
  /// Loads the robot and controller and creates the DDS entities. Throws on any set-up error,
  /// naming the file / value / entity.
  explicit ControllerNode(const NodeConfig& config);
  ~ControllerNode();
  ControllerNode(const ControllerNode&) = delete;
  ControllerNode& operator=(const ControllerNode&) = delete;

  /// Runs the 200 Hz loop until stop(), a signal, or the configured duration.
  void run();
  void stop() noexcept;
  /// Asks the controller to leave a latched e-stop (only separating motion, Sec. 7.1).
  void requestEstopReset() noexcept;

  const NodeStats& stats() const { return stats_; }
  /// What the start-up did about the robot state ("" without a robot state file).
  const std::string& robotStateNote() const;
  bus::Participant& bus();

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
  NodeStats stats_;
};

}  // namespace reflex::control_node
