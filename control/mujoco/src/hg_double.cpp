#include "reflex/mujoco/hg_double.hpp"

#include <algorithm>
#include <cmath>
#include <sstream>

namespace reflex::mujoco {

namespace hg = reflex::unitree_hg;

HgDouble::HgDouble(const control::Model& model, const std::string& joint_map, const Eigen::VectorXd& own,
                   bus::Participant& bus)
    : model_(model), map_(hg::resolveHgJointMap(hg::loadHgJointMap(joint_map), model)), own_(own) {
  state_writer_ = &bus.makeWriter<hg::LowState>();
  cmd_reader_ = &bus.makeReader<hg::LowCmd>();
  names_ = model.q_names;
  positions_.assign(static_cast<std::size_t>(model.nq), 0.0);
  velocities_.assign(static_cast<std::size_t>(model.nq), 0.0);
  undecodable_seen_ = hg::undecodableLowCmds();
}

void HgDouble::takeCommands(MujocoRobot& robot, std::int64_t now_ns) noexcept {
  while (cmd_reader_->takeNext(cmd_)) {
    if (hg::lowCmdCrc(cmd_) != cmd_.crc()) {
      ++counts_.rejected_crc;
      continue;
    }
    const float w = cmd_.motor_cmd()[hg::kWeightSlot].q();
    if (!(w >= 0.0f && w <= 1.0f)) {
      ++counts_.rejected_weight;
      continue;
    }
    bool finite = true;
    for (int motor = hg::kArmSdkFirst; motor <= hg::kArmSdkLast; ++motor) {
      const auto& m = cmd_.motor_cmd()[static_cast<std::size_t>(motor)];
      finite = finite && std::isfinite(m.q()) && std::isfinite(m.dq()) && std::isfinite(m.kp()) &&
               std::isfinite(m.kd()) && m.kp() >= 0.0f && m.kd() >= 0.0f;
    }
    if (!finite) {
      ++counts_.rejected_not_finite;
      continue;
    }
    const double previous = have_command_ ? last_.motor_cmd()[hg::kWeightSlot].q() : 0.0;
    counts_.max_weight_step = std::max(counts_.max_weight_step, std::abs(static_cast<double>(w) - previous));
    counts_.weight = w;
    last_ = cmd_;
    have_command_ = true;
    ++counts_.accepted;
  }
  const std::uint64_t undecodable = hg::undecodableLowCmds();
  counts_.rejected_size += undecodable - undecodable_seen_;
  undecodable_seen_ = undecodable;
  // This period's targets: the robot's own, blended with the last accepted arm_sdk command.
  for (int qi = 0; qi < model_.nq; ++qi) {
    positions_[static_cast<std::size_t>(qi)] = own_[qi];
    velocities_[static_cast<std::size_t>(qi)] = 0.0;
  }
  if (have_command_) {
    const double w = last_.motor_cmd()[hg::kWeightSlot].q();
    for (int motor = hg::kArmSdkFirst; motor <= hg::kArmSdkLast; ++motor) {
      const int qi = map_.q_of_motor[static_cast<std::size_t>(motor)];
      const auto& m = last_.motor_cmd()[static_cast<std::size_t>(motor)];
      if (qi < 0 || m.mode() != 1) continue;
      positions_[static_cast<std::size_t>(qi)] = w * m.q() + (1.0 - w) * own_[qi];
      velocities_[static_cast<std::size_t>(qi)] = w * m.dq();
    }
  }
  CommandInput in;
  in.names = &names_;
  in.positions = &positions_;
  in.velocities = &velocities_;
  in.valid_until_ns = now_ns + 1'000'000'000;  // offered again every period: never expires while running
  in.seq = counts_.accepted;
  robot.offerCommand(in, now_ns);
}

void HgDouble::publishState(const RobotMeasurement& meas, std::int64_t simulated_ms) noexcept {
  tick_ = static_cast<std::uint32_t>(static_cast<std::uint64_t>(simulated_ms) & 0xFFFFFFFFu);
  state_.tick(tick_);
  for (int motor = 0; motor < hg::kMotors; ++motor) {
    const int qi = map_.q_of_motor[static_cast<std::size_t>(motor)];
    if (qi < 0) continue;
    auto& m = state_.motor_state()[static_cast<std::size_t>(motor)];
    m.mode(1);
    m.q(static_cast<float>(meas.q[qi]));
    m.dq(static_cast<float>(meas.qdot[qi]));
    m.tau_est(static_cast<float>(meas.effort[qi]));
  }
  state_.crc(hg::lowStateCrc(state_));
  if (state_writer_->write(state_)) ++counts_.states;
}

std::string HgDouble::summary() const {
  std::ostringstream os;
  os << "unitree_hg: states " << counts_.states << ", arm_sdk commands accepted " << counts_.accepted << " rejected "
     << counts_.rejected() << " (bad crc " << counts_.rejected_crc << ", weight " << counts_.rejected_weight
     << ", not finite " << counts_.rejected_not_finite << ", size " << counts_.rejected_size << "), weight at exit "
     << counts_.weight << ", largest weight step " << counts_.max_weight_step;
  return os.str();
}

}  // namespace reflex::mujoco
