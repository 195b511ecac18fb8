// StateDriver: a kinematic robot driver on reflex/robot_state and reflex/joint_command, run inside a
// test or bench process (its own DDS participant, UDP only) against a real reflex_controller process.
// Used by trigger_state_test and reflex_trigger_bench.
//
// Two threads. The state thread publishes a RobotState every `period` (absolute deadlines on
// CLOCK_MONOTONIC; the rate can change and publishing can pause while it runs) and records each state
// it sent: seq, stamp, positions. Before each state it applies the newest command whose deadline has
// not passed (idl/README.md's hold rule): every joint the command names moves towards its position
// by at most |velocity| x the time since the last state (never past it), so the robot never moves a
// joint faster than the command's velocity. The command thread waits for joint commands and records
// each with the time it arrived here (system clock), so the latency from a state's measurement to the
// command answering it is measured both as the controller stamped it and as it reached the driver.
#pragma once

#include "reflex/control/controller.hpp"
#include "reflex/control/model.hpp"
#include "reflex/control/scenarios.hpp"

#include <reflex/bus/bus.hpp>

#include <pthread.h>
#include <sched.h>
#include <time.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdint>
#include <map>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

namespace reflex::testing {

class StateDriver {
 public:
  struct SentState {
    std::uint64_t seq = 0;
    std::int64_t stamp_ns = 0;
    Eigen::VectorXd q;  ///< positions sent (model order)
  };
  struct ReceivedCommand {
    msg::JointCommand command;
    std::int64_t arrived_ns = 0;  ///< system clock when taken here
  };

  /// `rt_priority` > 0: the participant's threads (made here) and the state and command threads run
  /// SCHED_FIFO at it (realtimeFailed() if refused); the calling thread keeps its own policy.
  StateDriver(const control::Model& model, const control::ControllerModel& cm, int domain, double period,
              const Eigen::VectorXd& q0, int rt_priority = 0)
      : model_(model), cm_(cm), q_(q0), rt_priority_(rt_priority) {
    period_ns_ = static_cast<long>(std::llround(period * 1e9));
    // Real-time while the participant and its entities are made: its receive threads (which take the
    // commands) inherit it; the calling thread gets its own policy back after (what it starts later,
    // e.g. a load generator, must not inherit SCHED_FIFO).
    int old_policy = SCHED_OTHER;
    sched_param old_param{};
    pthread_getschedparam(pthread_self(), &old_policy, &old_param);
    makeRealtime();
    bus::BusConfig bc;
    bc.module_name = "test_state_driver";
    bc.domain_id = domain;
    bc.participant_profile = "reflex_participant_udp";
    participant_ = std::make_unique<bus::Participant>(bc);
    state_writer_ = &participant_->makeWriter<msg::RobotState>();
    command_reader_ = &participant_->makeReader<msg::JointCommand>("reflex/joint_command", bus::kProfileRecord);
    pthread_setschedparam(pthread_self(), old_policy, &old_param);
    state_.names(model.q_names);
    state_.positions().assign(static_cast<std::size_t>(model.nq), 0.0);
    state_.velocities().assign(static_cast<std::size_t>(model.nq), 0.0);
    sent_.reserve(200000);
    received_.reserve(200000);
  }
  ~StateDriver() { stop(); }
  StateDriver(const StateDriver&) = delete;
  StateDriver& operator=(const StateDriver&) = delete;

  bus::Participant& bus() { return *participant_; }
  bool waitForController(std::chrono::seconds timeout) {
    return state_writer_->waitForReaders(1, timeout) && command_reader_->waitForWriters(1, timeout);
  }
  void start() {
    running_ = true;
    command_thread_ = std::thread([this] { commandLoop(); });
    state_thread_ = std::thread([this] { stateLoop(); });
  }
  void stop() {
    running_ = false;
    if (state_thread_.joinable()) state_thread_.join();
    if (command_thread_.joinable()) command_thread_.join();
  }
  void setPeriod(double period) { period_ns_ = static_cast<long>(std::llround(period * 1e9)); }
  void setPublishing(bool on) { publishing_ = on; }
  /// Copies of what was sent and received so far.
  std::vector<SentState> sent() {
    std::lock_guard<std::mutex> lock(mutex_);
    return sent_;
  }
  std::vector<ReceivedCommand> received() {
    std::lock_guard<std::mutex> lock(mutex_);
    return received_;
  }
  /// The largest |joint step| / (v_max x the time between two states) the robot made (<= 1 by construction
  /// when every command's |velocity| <= v_max; measured, for the tests to assert).
  double worstSpeedRatio() const { return worst_speed_ratio_; }
  bool realtimeFailed() const { return rt_failed_; }

 private:
  void makeRealtime() {
    if (rt_priority_ <= 0) return;
    sched_param p{};
    p.sched_priority = rt_priority_;
    if (pthread_setschedparam(pthread_self(), SCHED_FIFO, &p) != 0) rt_failed_ = true;
  }

  void commandLoop() {
    makeRealtime();
    msg::JointCommand c;
    while (running_) {
      if (!command_reader_->waitForData(std::chrono::milliseconds(20))) continue;
      while (command_reader_->takeNext(c)) {
        const std::int64_t now = bus::nowNs();
        std::lock_guard<std::mutex> lock(mutex_);
        received_.push_back({c, now});
        newest_ = c;
        have_command_ = true;
      }
    }
  }

  void stateLoop() {
    makeRealtime();
    timespec next{};
    clock_gettime(CLOCK_MONOTONIC, &next);
    std::int64_t last_stamp = 0;
    msg::JointCommand cmd;
    bool have = false;
    while (running_) {
      next.tv_nsec += period_ns_.load();
      while (next.tv_nsec >= 1000000000L) {
        next.tv_nsec -= 1000000000L;
        ++next.tv_sec;
      }
      clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &next, nullptr);
      {
        std::lock_guard<std::mutex> lock(mutex_);
        if (have_command_) {
          cmd = newest_;
          have = true;
        }
      }
      const std::int64_t now = bus::nowNs();
      const double elapsed = last_stamp > 0 ? 1e-9 * static_cast<double>(now - last_stamp) : 0.0;
      if (have && now <= cmd.valid_until_ns() && elapsed > 0.0) {
        for (std::size_t k = 0; k < cmd.names().size(); ++k) {
          const int i = model_.qIndex(cmd.names()[k]);
          if (i < 0) continue;
          const double step = std::abs(cmd.velocities()[k]) * elapsed;
          const double dq = std::clamp(cmd.positions()[k] - q_[i], -step, step);
          q_[i] += dq;
          worst_speed_ratio_ = std::max(worst_speed_ratio_, std::abs(dq) / (model_.v_max[i] * elapsed));
        }
      }
      if (!publishing_) {
        last_stamp = 0;  // the next state's step is measured from itself on
        continue;
      }
      for (int i = 0; i < model_.nq; ++i) state_.positions()[static_cast<std::size_t>(i)] = q_[i];
      state_.header().stamp_ns(now);  // measured now; publish() would stamp it again a little later
      state_.header().seq(++seq_);
      state_writer_->write(state_);
      last_stamp = now;
      std::lock_guard<std::mutex> lock(mutex_);
      sent_.push_back({seq_, now, q_});
    }
  }

  const control::Model& model_;
  const control::ControllerModel& cm_;
  Eigen::VectorXd q_;
  int rt_priority_ = 0;
  std::unique_ptr<bus::Participant> participant_;
  bus::Writer<msg::RobotState>* state_writer_ = nullptr;
  bus::Reader<msg::JointCommand>* command_reader_ = nullptr;
  msg::RobotState state_;
  std::uint64_t seq_ = 0;
  std::atomic<long> period_ns_{2000000};
  std::atomic<bool> running_{false}, publishing_{true};
  std::thread state_thread_, command_thread_;
  std::mutex mutex_;
  std::vector<SentState> sent_;
  std::vector<ReceivedCommand> received_;
  msg::JointCommand newest_;
  bool have_command_ = false;
  double worst_speed_ratio_ = 0.0;
  bool rt_failed_ = false;
};

}  // namespace reflex::testing
