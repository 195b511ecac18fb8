#include "reflex/control_node/unitree_hg_port.hpp"

#include "reflex/control/controller.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <limits>
#include <thread>

namespace reflex::control_node {

namespace hg = reflex::unitree_hg;

UnitreeHgPort::UnitreeHgPort(const control::Model& model, const std::vector<int>& driven, const hg::HgJointMap& map,
                             bus::Participant& bus, const Options& options)
    : model_(model), options_(options), map_(hg::resolveHgJointMap(map, model)) {
  if (!(options.ramp_time > 0.0 && options.ramp_time <= 60.0))
    throw control::ConfigError("--ramp-time " + std::to_string(options.ramp_time) + " s must be in (0, 60]");
  for (const int qi : driven) {
    const int motor = map_.motor_of_q[static_cast<std::size_t>(qi)];
    if (motor < hg::kArmSdkFirst || motor > hg::kArmSdkLast) continue;  // legs: the robot's own controller
    if (!map_.has_gains[static_cast<std::size_t>(motor)])
      throw control::ConfigError(map.source + ": joint '" + model.q_names[qi] + "' (motor " + std::to_string(motor) +
                                 ") is commanded on rt/arm_sdk but has no kp / kd");
    commanded_.push_back(qi);
  }
  if (commanded_.empty())
    throw control::ConfigError(map.source +
                               ": no joint the controller drives is on a motor the arm_sdk weight blends "
                               "(12..28): nothing could be commanded");
  reader_ = &bus.makeReader<hg::LowState>();
  writer_ = &bus.makeWriter<hg::LowCmd>(options.command_topic, hg::kProfile);
  q_.setZero(model.nq);
  q_own_.setZero(model.nq);
  control::acceptedStateRange(model, options.period, lower_, upper_);
  for (int i = 0; i < model.nq; ++i)
    if (map_.motor_of_q[static_cast<std::size_t>(i)] < 0) q_[i] = map_.fixed_value[static_cast<std::size_t>(i)];
  undecodable_seen_ = hg::undecodableLowStates();
  // The command's constant part: every slot off, the arm_sdk slots with their gains.
  for (int motor = hg::kArmSdkFirst; motor <= hg::kArmSdkLast; ++motor) {
    auto& m = cmd_.motor_cmd()[static_cast<std::size_t>(motor)];
    if (map_.q_of_motor[static_cast<std::size_t>(motor)] < 0) continue;
    m.mode(1);
    m.kp(map_.kp[static_cast<std::size_t>(motor)]);
    m.kd(map_.kd[static_cast<std::size_t>(motor)]);
  }
}

namespace {

void formatGuid(const std::array<unsigned char, 16>& g, char (&out)[64]) noexcept {
  std::snprintf(out, sizeof(out), "%02x.%02x.%02x.%02x.%02x.%02x.%02x.%02x.%02x.%02x.%02x.%02x|%x.%x.%x.%x", g[0], g[1],
                g[2], g[3], g[4], g[5], g[6], g[7], g[8], g[9], g[10], g[11], g[12], g[13], g[14], g[15]);
}

}  // namespace

bool UnitreeHgPort::reject(int cause) noexcept {
  ++rejected_[static_cast<std::size_t>(cause)];
  cause_ = cause;
  texts_.keep(cause, rejection_);
  return false;
}

int UnitreeHgPort::poll() noexcept {
  int rejected = 0;
  bus::dds::SampleInfo info;
  while (reader_->takeNext(sample_, &info)) {
    Guid writer;
    const unsigned char* handle = info.publication_handle.value;
    std::copy(handle, handle + writer.size(), writer.begin());
    if (!accept(sample_, writer, bus::nowNs())) ++rejected;
  }
  // Samples of another size never come out of take(): the type support refused and counted them
  // during it (unitree_hg.hpp).
  const std::uint64_t now_undecodable = hg::undecodableLowStates();
  if (now_undecodable != undecodable_seen_) {
    const std::uint64_t n = now_undecodable - undecodable_seen_;
    undecodable_seen_ = now_undecodable;
    std::snprintf(rejection_, sizeof(rejection_),
                  "%llu %s sample(s) rejected: not the size of a LowState_ with %d motors (another motor count or "
                  "another type under the same name)",
                  static_cast<unsigned long long>(n), hg::kStateTopic, hg::kMotors);
    rejected_[kCauseMotorCount] += n - 1;
    reject(kCauseMotorCount);
    rejected += static_cast<int>(n);
  }
  return rejected;
}

bool UnitreeHgPort::accept(const hg::LowState& s, const Guid& writer, std::int64_t now_ns) noexcept {
  const auto tick = static_cast<unsigned long long>(s.tick());
  const bool bound_alive = bound_ && static_cast<double>(now_ns - writer_last_ns_) <= options_.rebind_silence * 1e9;
  const bool from_bound = bound_ && writer == robot_writer_;
  if (bound_alive && !from_bound) {
    if (writer != other_ || other_text_[0] == '\0') {
      other_ = writer;
      formatGuid(writer, other_text_);
    }
    std::snprintf(rejection_, sizeof(rejection_), "%s tick %llu ignored: written by %s, not the robot writer %s",
                  hg::kStateTopic, tick, other_text_, bound_text_);
    return reject(kRobotCauseOtherWriter);
  }
  if (from_bound) writer_last_ns_ = now_ns;
  const std::uint32_t crc = hg::lowStateCrc(s);
  if (crc != s.crc()) {
    std::snprintf(rejection_, sizeof(rejection_),
                  "%s tick %llu rejected: crc 0x%08x, expected 0x%08x (Crc32Core of the "
                  "C layout)",
                  hg::kStateTopic, tick, static_cast<unsigned>(s.crc()), static_cast<unsigned>(crc));
    return reject(kCauseBadCrc);
  }
  // The tick must advance (modulo 2^32: a wrap is an advance, a step back of up to 2^31 is not).
  if (have_state_ && from_bound) {
    const std::uint32_t step = s.tick() - tick_;
    if (step == 0 || step >= 0x80000000u) {
      std::snprintf(rejection_, sizeof(rejection_), "%s tick %llu rejected: does not advance over the held tick %u",
                    hg::kStateTopic, tick, static_cast<unsigned>(tick_));
      return reject(kCauseOldTick);
    }
  }
  for (int i = 0; i < model_.nq; ++i) {
    const int motor = map_.motor_of_q[static_cast<std::size_t>(i)];
    if (motor < 0) continue;
    const auto& m = s.motor_state()[static_cast<std::size_t>(motor)];
    const double p = m.q(), v = m.dq();
    if (!std::isfinite(p) || !std::isfinite(v)) {
      std::snprintf(rejection_, sizeof(rejection_), "%s tick %llu rejected: motor %d (joint '%s') q %g dq %g",
                    hg::kStateTopic, tick, motor, model_.q_names[i].c_str(), p, v);
      return reject(2);
    }
    if (!(lower_[i] <= p && p <= upper_[i])) {
      std::snprintf(rejection_, sizeof(rejection_),
                    "%s tick %llu rejected: motor %d (joint '%s') q %.6g outside its limits [%.6g, %.6g]",
                    hg::kStateTopic, tick, motor, model_.q_names[i].c_str(), p, model_.q_lower[i], model_.q_upper[i]);
      return reject(6);
    }
  }
  if (!from_bound) {
    if (bound_) ++writer_changes_;
    bound_ = true;
    robot_writer_ = writer;
    writer_last_ns_ = now_ns;
    formatGuid(writer, bound_text_);
  }
  for (int i = 0; i < model_.nq; ++i) {
    const int motor = map_.motor_of_q[static_cast<std::size_t>(i)];
    if (motor >= 0) q_[i] = s.motor_state()[static_cast<std::size_t>(motor)].q();
  }
  state_interval_ns_ = have_state_ && from_bound ? now_ns - state_stamp_ns_ : 0;
  have_state_ = true;
  tick_ = s.tick();
  state_stamp_ns_ = now_ns;
  ++accepted_;
  return true;
}

void UnitreeHgPort::sendThrough(bus::Outbox& outbox) {
  queue_ = &outbox.add(*writer_, cmd_, 16);
  outbox_ = &outbox;
}

bool UnitreeHgPort::waitForState(std::chrono::nanoseconds timeout) noexcept {
  try {
    return reader_->waitForData(timeout);
  } catch (...) {
    return false;
  }
}

const Eigen::VectorXd* UnitreeHgPort::measuredPositions(double /*now*/) noexcept {
  if (!have_state_) return nullptr;
  const double age = static_cast<double>(bus::nowNs() - state_stamp_ns_) * 1e-9;
  return age <= options_.timeout ? &q_ : nullptr;
}

void UnitreeHgPort::command(const Eigen::VectorXd& q_end, const Eigen::VectorXd& qdot, double dt) noexcept {
  for (int motor = hg::kArmSdkFirst; motor <= hg::kArmSdkLast; ++motor) {
    const int qi = map_.q_of_motor[static_cast<std::size_t>(motor)];
    if (qi < 0) continue;
    auto& m = cmd_.motor_cmd()[static_cast<std::size_t>(motor)];
    m.q(static_cast<float>(q_end[qi]));
    m.dq(static_cast<float>(qdot[qi]));
  }
  // The robot's own targets, as well as they can be known: where its controller held the arms before
  // the first command (weight 0).
  if (!sent_) q_own_ = q_;
  // Ramp in: the weight rises by dt / ramp_time per command, from 0 (the first command's weight is
  // that one step), to 1, never faster than weightStepLimit allows.
  const double w = std::min(1.0, weight_ + std::min(dt / options_.ramp_time, weightStepLimit(dt)));
  max_weight_step_ = std::max(max_weight_step_, w - weight_);
  weight_ = w;
  send();
}

void UnitreeHgPort::send() noexcept {
  cmd_.motor_cmd()[hg::kWeightSlot].q(static_cast<float>(weight_));
  cmd_.crc(hg::lowCmdCrc(cmd_));
  if (queue_ != nullptr) {
    if (queue_->push(cmd_)) ++commands_;
    outbox_->notify();
  } else if (writer_->write(cmd_)) {
    ++commands_;
  }
  sent_ = true;
}

double UnitreeHgPort::weightStepLimit(double dt) const noexcept {
  // A change dw of the weight moves the blended target of a joint by dw * |q_cmd - q_own|: at most
  // half of what the joint may move in dt at its velocity limit.
  double limit = 1.0;
  for (int motor = hg::kArmSdkFirst; motor <= hg::kArmSdkLast; ++motor) {
    const int qi = map_.q_of_motor[static_cast<std::size_t>(motor)];
    if (qi < 0) continue;
    const double gap =
        std::abs(static_cast<double>(cmd_.motor_cmd()[static_cast<std::size_t>(motor)].q()) - q_own_[qi]);
    if (gap > 0.0) limit = std::min(limit, kBlendSpeedShare * model_.v_max[qi] * dt / gap);
  }
  return limit;
}

bool UnitreeHgPort::rampOutStep(double dt) noexcept {
  if (!sent_ || weight_ <= 0.0) return false;
  const double w = std::max(0.0, weight_ - std::min(dt / options_.ramp_time, weightStepLimit(dt)));
  max_weight_step_ = std::max(max_weight_step_, weight_ - w);
  weight_ = w;
  // The last command's positions, no velocity: the arms hold where Reflex left them while the
  // robot's own controller takes them over.
  for (int motor = hg::kArmSdkFirst; motor <= hg::kArmSdkLast; ++motor)
    cmd_.motor_cmd()[static_cast<std::size_t>(motor)].dq(0.0f);
  send();
  return weight_ > 0.0;
}

void UnitreeHgPort::finish(double period) noexcept {
  if (!(period > 0.0)) period = options_.period;
  auto next = std::chrono::steady_clock::now();
  const auto step =
      std::chrono::duration_cast<std::chrono::steady_clock::duration>(std::chrono::duration<double>(period));
  while (rampOutStep(period)) {
    next += step;
    std::this_thread::sleep_until(next);
    poll();  // keeps the counters honest while ramping out
  }
}

}  // namespace reflex::control_node
