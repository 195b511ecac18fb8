// reflex_mujoco's DDS side: the simulated robot (MujocoRobot) on the bus, as a humanoid's driver
// would be (idl/robot.idl). Per period (real-time paced, default 1 ms):
//   take every JointCommand that arrived (reflex/joint_command) and offer it to the robot (each is
//   accepted or rejected and counted; see MujocoRobot::offerCommand), advance the physics by
//   period / timestep steps, publish RobotState (reflex/robot_state) and RobotContacts
//   (reflex/robot_contacts) of the same instant. A heartbeat (reflex/heartbeat, module name
//   --name) every 500 ms, STATE_STOPPING at the end.
// Simulated time follows wall time: a wake-up that is late by whole periods (an overrun, counted)
// runs the missed periods' physics at once, up to 20 periods; beyond that the time is lost (counted
// as lost periods) and simulated time falls behind. States are published once per wake-up.
#pragma once

#include "reflex/control/model.hpp"
#include "reflex/mujoco/hg_double.hpp"
#include "reflex/mujoco/mjcf.hpp"
#include "reflex/mujoco/mujoco_robot.hpp"

#include <reflex/bus/bus.hpp>

#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace reflex::mujoco {

struct NodeConfig {
  std::string urdf;
  std::string collision;             ///< empty: next to the URDF
  std::vector<std::string> initial;  ///< "joint=value" (rad or m); other joints 0 (or nearest limit)
  double period = 0.001;             ///< [s] state publication and command intake period
  MjcfOptions mjcf;                  ///< timestep (period must be a whole multiple), margin (d_r), gains
  double duration = 0.0;             ///< [s] wall time to run; 0: until stopped
  std::optional<int> domain_id;
  /// UDP only by default, like reflex_controller and as idl/README.md asks of every robot driver: a
  /// dead shared-memory reader stalls a Fast DDS 2.9 writer for the port health check (about 1 s).
  std::string profiles_file, participant_profile = "reflex_participant_udp";
  std::string module_name = "reflex_mujoco";
  /// "reflex" (reflex/robot_state, reflex/joint_command) or "unitree_hg" (rt/lowstate, rt/arm_sdk:
  /// hg_double.hpp, with joint_map). reflex/robot_contacts and the heartbeat either way.
  std::string interface = "reflex";
  std::string joint_map;
};

struct NodeStats {
  std::uint64_t periods = 0, overruns = 0, lost_periods = 0, states_published = 0;
  double max_lateness_us = 0.0;
  std::uint64_t contact_periods = 0;           ///< published states with at least one contact
  std::vector<SegmentContact> worst_contacts;  ///< the smallest distance seen per pair (names via model)
  std::vector<double> command_latency_us;      ///< per accepted command: arrival - state_stamp_ns (first 1e6)
};

class RobotNode {
 public:
  /// Loads the model, builds the robot and the DDS entities. Throws reflex::Error (ModelError,
  /// BusError, ...) naming the bad value.
  explicit RobotNode(const NodeConfig& config);
  /// Runs until stop() (signals: bus::StopOnSignal on bus()) or the configured duration.
  void run();
  /// The model summary printed at start (bodies, joints, geoms, pairs, actuators, mass, gains).
  std::string summary() const;
  /// The exit summary (steps, contact steps, commands applied / rejected, hold time, latency).
  std::string exitSummary() const;

  bus::Participant& bus() { return *bus_; }
  const MujocoRobot& robot() const { return *robot_; }
  const control::Model& model() const { return model_; }
  const NodeStats& stats() const { return stats_; }

 private:
  NodeConfig config_;
  control::Model model_;
  std::unique_ptr<MujocoRobot> robot_;
  std::unique_ptr<bus::Participant> bus_;
  bus::Writer<msg::RobotState>* state_writer_ = nullptr;
  bus::Writer<msg::RobotContacts>* contacts_writer_ = nullptr;
  bus::Reader<msg::JointCommand>* command_reader_ = nullptr;
  std::unique_ptr<bus::HeartbeatPublisher> heartbeat_;
  std::unique_ptr<HgDouble> hg_;  ///< interface "unitree_hg"
  int substeps_ = 1;
  NodeStats stats_;
};

/// Parses "joint=value" initial positions for `model` (q index order, the rest 0 clamped to the
/// limits). Throws reflex::Error naming the bad entry (unknown joint, not a number, outside
/// the limits).
Eigen::VectorXd parseInitialConfiguration(const control::Model& model, const std::vector<std::string>& entries);

}  // namespace reflex::mujoco
