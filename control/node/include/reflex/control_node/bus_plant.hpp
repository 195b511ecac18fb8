// The scenarios on a robot over DDS: a control::ScenarioPlant whose robot is on the
// bus, for reflex_sim --robot mujoco|dds. The controller reaches the robot through DdsRobotPort
// (reflex/robot_state in, reflex/joint_command out), exactly as reflex_controller --robot dds does.
//
// Clock: real time. Cycle k of a scenario begins at start + k * period on the steady clock (start =
// the first awaitCycle); a cycle that begins a whole period late or more runs at once (counted by
// runScenario as late) and scenario time is NOT stretched: the robot's physics runs on wall time, so
// the controller must too, and a late cycle is what the real controller would see under load.
//
// Spawning (--robot mujoco): the plant starts `reflex_mujoco` (a separate process, its output to a log
// file) on its own DDS domain at the given start configuration with contact margin d_r, waits for
// its first state, holds that configuration for a warm-up while discovery settles in both
// directions, and stops it (SIGTERM, then SIGKILL after 5 s) in stop() or the destructor. Attaching
// (--robot dds): no process is started; the robot already on the domain is used from where it is.
//
// The judge: every reflex/robot_contacts sample is taken between cycles; contactSamples() counts
// those with at least one pair below the robot's margin, minContact() is the smallest distance any of
// them named (with the pair), totalContactSteps() the robot's own counter (since its start).
#pragma once

#include "reflex/control/model.hpp"
#include "reflex/control/scenarios.hpp"
#include "reflex/control_node/dds_robot_port.hpp"
#include "reflex/control_node/unitree_hg_port.hpp"

#include <reflex/bus/bus.hpp>

#include <sys/types.h>

#include <chrono>
#include <cstdint>
#include <limits>
#include <memory>
#include <string>
#include <vector>

namespace reflex::control_node {

struct BusPlantOptions {
  int domain = 0;                       ///< DDS domain id (the spawned robot's too)
  std::string robot_binary;             ///< reflex_mujoco to spawn; empty: attach to a robot already on the bus
  std::vector<std::string> robot_args;  ///< extra arguments for the spawned robot (--urdf, --collision ...)
  std::string robot_log;                ///< the spawned robot's stdout + stderr (file, truncated)
  Eigen::VectorXd q_start;              ///< the spawned robot's start configuration (nq; passed as --q joint=value)
  double margin = 0.005;                ///< the spawned robot's contact margin (d_r, m)
  double first_state_timeout = 30.0;    ///< s to wait for the robot's first state
  double warmup = 0.5;                  ///< s of holding the first measured configuration before the scenario
  DdsRobotPort::Options port;           ///< robot-state timeout, command deadline
  /// The robot's interface: "dds" (reflex/robot_state, reflex/joint_command) or "unitree_hg"
  /// (rt/lowstate, rt/arm_sdk through UnitreeHgPort with `joint_map`; a spawned reflex_mujoco gets
  /// --interface unitree_hg --joint-map too). With unitree_hg the time between two states is the
  /// difference of their ticks, taken as milliseconds (reflex_mujoco's tick; LowState_ has no stamp).
  std::string interface = "dds";
  std::string joint_map;
  double ramp_time = 3.0;  ///< s, the arm_sdk weight's ramp (unitree_hg)
};

class BusScenarioPlant final : public control::ScenarioPlant {
 public:
  /// Spawns the robot (if robot_binary is set), joins the domain, waits for the first robot state and
  /// warms up. Throws std::runtime_error naming what failed (the binary, the domain, the timeout and
  /// the log file), bus::BusError naming a DDS entity.
  BusScenarioPlant(const control::Model& model, const std::vector<int>& driven, const BusPlantOptions& options);
  ~BusScenarioPlant() override;
  BusScenarioPlant(const BusScenarioPlant&) = delete;
  BusScenarioPlant& operator=(const BusScenarioPlant&) = delete;

  control::RobotPort& port() override { return *port_; }
  bool awaitCycle(double t, double period) override;
  const Eigen::VectorXd& positions() const override { return q_; }
  double stateInterval(double period) const override;

  /// Stops the spawned robot (nothing when attached) and returns its exit status (0 when attached);
  /// its exit line is then in the log.
  int stop();

  const BusRobotPort& robotPort() const { return *port_; }
  /// After the scenario: with unitree_hg, the arm_sdk weight ramped to 0 (a command every `period`,
  /// the last positions held), watching the robot: the judge's contacts keep being counted and the
  /// largest measured joint step is rampOutSpeedRatio(). Nothing with dds.
  void rampOut(double period);
  /// max |dq_i| / (v_max_i dt) between consecutive states during rampOut() (dt from the ticks).
  double rampOutSpeedRatio() const { return ramp_out_ratio_; }
  /// max |dq_i| / (v_max_i dt) between the newest states of consecutive polls, from the first state
  /// to the last (warm-up, scenario, ramp out), dt from the states' stamps (unitree_hg: ticks): what
  /// the robot did, whatever was commanded.
  double measuredSpeedRatio() const { return measured_ratio_; }
  /// The arm_sdk weight's largest step between two commands (unitree_hg; 0 with dds).
  double maxWeightStep() const;
  std::uint64_t contactSamples() const { return contact_samples_; }
  std::uint64_t contactsReceived() const { return contacts_received_; }
  double minContact() const { return min_contact_; }
  const std::string& minContactPair() const { return min_contact_pair_; }
  std::uint64_t totalContactSteps() const { return total_contact_steps_; }
  const char* description() const {
    return options_.robot_binary.empty() ? "dds" : hg_ ? "mujoco (unitree_hg)" : "mujoco";
  }

 private:
  void poll() noexcept;

  const control::Model& model_;
  BusPlantOptions options_;
  pid_t child_ = -1;
  std::unique_ptr<bus::Participant> bus_;
  std::unique_ptr<BusRobotPort> port_;
  UnitreeHgPort* hg_ = nullptr;  ///< port_ when the interface is unitree_hg
  double ramp_out_ratio_ = 0.0;
  double measured_ratio_ = 0.0;
  Eigen::VectorXd q_previous_;
  bus::Reader<msg::RobotContacts>* contacts_ = nullptr;
  msg::RobotContacts contact_sample_;
  Eigen::VectorXd q_;
  std::int64_t stamp_ = 0, previous_stamp_ = 0;
  bool started_ = false;
  std::chrono::steady_clock::time_point start_;
  std::uint64_t contact_samples_ = 0, contacts_received_ = 0, total_contact_steps_ = 0;
  double min_contact_ = std::numeric_limits<double>::infinity();
  std::string min_contact_pair_;
};

}  // namespace reflex::control_node
