// reflex_mujoco --interface unitree_hg: the simulated robot speaking Unitree's hg low-level interface
// (control/node: unitree_hg.hpp), a test double for reflex_controller --robot unitree_hg.
//
// What it plays (our choices where Unitree documents nothing; idl/README.md "Robots that already have
// an interface"):
//  - State: rt/lowstate every period: motor_state[slot].q / dq / tau_est of each joint the joint map
//    puts on a motor, tick = simulated milliseconds since the double started (uint32, wraps; it
//    advances by the periods each publication covers, so it never stands still), a correct crc.
//  - The robot's own controller: it holds every joint at the start configuration ("own" targets).
//  - rt/arm_sdk: a LowCmd_ whose crc is right, whose weight motor_cmd[29].q is finite and in [0, 1]
//    and whose q / dq of the arm_sdk slots are finite is accepted; the others are rejected and counted
//    by cause. For every mapped slot in 12..28 with mode 1 the servo target becomes
//    w * q + (1 - w) * own (velocity feed-forward w * dq); every other joint keeps its own target.
//    The last accepted command stays in force (a position target, never extrapolated) until another
//    arrives. kp / kd are checked (finite, >= 0) but the simulated servos keep their own gains.
//  - The weight's largest step between two accepted commands is measured (a ramp, never a jump).
#pragma once

#include "reflex/control/model.hpp"
#include "reflex/control_node/unitree_hg.hpp"
#include "reflex/mujoco/mujoco_robot.hpp"

#include <reflex/bus/bus.hpp>

#include <cstdint>
#include <string>
#include <vector>

namespace reflex::mujoco {

struct HgDoubleCounts {
  std::uint64_t states = 0;
  std::uint64_t accepted = 0;
  std::uint64_t rejected_crc = 0, rejected_weight = 0, rejected_not_finite = 0, rejected_size = 0;
  double max_weight_step = 0.0;  ///< between two accepted commands
  double weight = 0.0;           ///< of the last accepted command
  std::uint64_t rejected() const { return rejected_crc + rejected_weight + rejected_not_finite + rejected_size; }
};

class HgDouble {
 public:
  /// Reads and resolves the joint map against `model` (throws control::ConfigError naming it), makes
  /// the writer of rt/lowstate and the reader of rt/arm_sdk on `bus`. own: the start configuration.
  HgDouble(const control::Model& model, const std::string& joint_map, const Eigen::VectorXd& own,
           bus::Participant& bus);

  /// Takes every rt/arm_sdk sample and offers the robot this period's servo targets. No allocation
  /// once the first offer was made.
  void takeCommands(MujocoRobot& robot, std::int64_t now_ns) noexcept;
  /// Publishes rt/lowstate from the measurement with tick = simulated_ms (mod 2^32).
  void publishState(const RobotMeasurement& meas, std::int64_t simulated_ms) noexcept;
  std::uint32_t tick() const { return tick_; }
  const HgDoubleCounts& counts() const { return counts_; }
  std::string summary() const;

 private:
  const control::Model& model_;
  unitree_hg::HgResolvedMap map_;
  Eigen::VectorXd own_;
  bus::Writer<unitree_hg::LowState>* state_writer_ = nullptr;
  bus::Reader<unitree_hg::LowCmd>* cmd_reader_ = nullptr;
  unitree_hg::LowState state_;
  unitree_hg::LowCmd cmd_, last_;
  bool have_command_ = false;
  std::vector<std::string> names_;
  std::vector<double> positions_, velocities_;
  std::uint32_t tick_ = 0;
  std::uint64_t undecodable_seen_ = 0;
  HgDoubleCounts counts_;
};

}  // namespace reflex::mujoco
