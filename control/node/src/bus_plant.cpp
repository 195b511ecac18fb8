#include "reflex/common/error.hpp"
#include "reflex/control_node/bus_plant.hpp"

#include <fcntl.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>

#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <string>
#include <vector>
#include <stdexcept>
#include <thread>

extern char** environ;

namespace reflex::control_node {

namespace {

std::string number(double v) {
  char buf[64];
  std::snprintf(buf, sizeof(buf), "%.17g", v);
  return buf;
}

/// Waits up to `timeout` for `pid` to exit; its status (exit code, or 128 + signal), -1 if it did not.
int waitExit(pid_t pid, std::chrono::milliseconds timeout) {
  const auto end = std::chrono::steady_clock::now() + timeout;
  for (;;) {
    int status = 0;
    const pid_t r = waitpid(pid, &status, WNOHANG);
    if (r == pid) return WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
    if (r < 0) return -1;
    if (std::chrono::steady_clock::now() >= end) return -1;
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
}

// The last `n` non-empty lines of a text file, joined by " | " (at most 800 characters, the end kept).
std::string lastLines(const std::string& path, int n) {
  std::ifstream in(path);
  std::vector<std::string> lines;
  for (std::string line; std::getline(in, line);)
    if (!line.empty()) lines.push_back(line);
  std::string out;
  for (std::size_t i = lines.size() > static_cast<std::size_t>(n) ? lines.size() - n : 0; i < lines.size(); ++i)
    out += (out.empty() ? "" : " | ") + lines[i];
  if (out.size() > 800) out = "..." + out.substr(out.size() - 800);
  return out.empty() ? "(nothing)" : out;
}

}  // namespace

BusScenarioPlant::BusScenarioPlant(const control::Model& model, const std::vector<int>& driven,
                                   const BusPlantOptions& options)
    : model_(model), options_(options) {
  if (!options_.robot_binary.empty()) {
    if (options_.q_start.size() != model.nq)
      throw reflex::Error("robot plant: the start configuration has " + std::to_string(options_.q_start.size()) +
                          " entries, the model has " + std::to_string(model.nq));
    std::vector<std::string> argv = {options_.robot_binary,
                                     "--domain",
                                     std::to_string(options_.domain),
                                     "--margin",
                                     number(options_.margin),
                                     "--name",
                                     "reflex_mujoco_sim"};
    for (int i = 0; i < model.nq; ++i)
      if (options_.q_start[i] != 0.0) {
        argv.push_back("--q");
        argv.push_back(model.q_names[i] + "=" + number(options_.q_start[i]));
      }
    if (options_.interface == "unitree_hg")
      argv.insert(argv.end(), {"--interface", "unitree_hg", "--joint-map", options_.joint_map});
    argv.insert(argv.end(), options_.robot_args.begin(), options_.robot_args.end());
    std::vector<char*> args;
    for (auto& a : argv) args.push_back(a.data());
    args.push_back(nullptr);
    posix_spawn_file_actions_t fa;
    posix_spawn_file_actions_init(&fa);
    if (!options_.robot_log.empty()) {
      posix_spawn_file_actions_addopen(&fa, 1, options_.robot_log.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
      posix_spawn_file_actions_adddup2(&fa, 1, 2);
    }
    const int rc = posix_spawn(&child_, args[0], &fa, nullptr, args.data(), environ);
    posix_spawn_file_actions_destroy(&fa);
    if (rc != 0) {
      child_ = -1;
      throw reflex::Error("robot plant: cannot start '" + options_.robot_binary + "': " + std::strerror(rc));
    }
  }
  try {
    bus::BusConfig config;
    config.module_name = "reflex_sim";
    config.domain_id = options_.domain;
    bus_ = std::make_unique<bus::Participant>(config);
    if (options_.interface == "unitree_hg") {
      UnitreeHgPort::Options ho;
      ho.timeout = options_.port.timeout;
      ho.period = options_.port.period;
      ho.ramp_time = options_.ramp_time;
      auto hg =
          std::make_unique<UnitreeHgPort>(model, driven, unitree_hg::loadHgJointMap(options_.joint_map), *bus_, ho);
      hg_ = hg.get();
      port_ = std::move(hg);
    } else {
      port_ = std::make_unique<DdsRobotPort>(model, driven, *bus_, options_.port);
    }
    contacts_ = &bus_->makeReader<msg::RobotContacts>();
    q_ = options_.q_start.size() == model.nq ? options_.q_start : Eigen::VectorXd::Zero(model.nq);
    // The first state: the robot is up and its writer matched our reader.
    const auto t0 = std::chrono::steady_clock::now();
    const auto limit = std::chrono::duration<double>(options_.first_state_timeout);
    while (!port_->haveState()) {
      // A spawned robot that exits (MuJoCo refused the model, a bad option) is said at once, with the
      // end of its output, not after the whole wait.
      if (child_ > 0) {
        if (const int code = waitExit(child_, std::chrono::milliseconds(0)); code >= 0) {
          child_ = -1;
          throw reflex::Error("robot plant: the spawned robot (" + options_.robot_binary + ") exited with status " +
                              std::to_string(code) + " before its first state" +
                              (options_.robot_log.empty() ? std::string()
                                                          : "; the end of its output (" + options_.robot_log +
                                                                "): " + lastLines(options_.robot_log, 3)));
        }
      }
      if (std::chrono::steady_clock::now() - t0 > limit) {
        std::string where = options_.robot_binary.empty() ? "no robot on the bus"
                                                          : "the spawned robot (" + options_.robot_binary +
                                                                "; its output: " + options_.robot_log + ")";
        if (child_ > 0 && waitExit(child_, std::chrono::milliseconds(0)) >= 0) {
          child_ = -1;
          where += " exited";
        }
        throw reflex::Error("robot plant: no reflex/robot_state on domain " + std::to_string(options_.domain) +
                            " within " + number(options_.first_state_timeout) + " s: " + where);
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
      port_->poll();
    }
    // Warm-up: hold the measured configuration (commands of zero motion) while discovery settles the
    // other way (our command writer to the robot's reader), so the scenario's first commands arrive.
    const Eigen::VectorXd zero = Eigen::VectorXd::Zero(model.nq);
    const auto w0 = std::chrono::steady_clock::now();
    while (std::chrono::steady_clock::now() - w0 < std::chrono::duration<double>(options_.warmup)) {
      poll();
      port_->command(q_, zero, 0.005);
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
    }
    poll();
    previous_stamp_ = stamp_;
  } catch (...) {
    stop();
    throw;
  }
}

BusScenarioPlant::~BusScenarioPlant() { stop(); }

int BusScenarioPlant::stop() {
  if (child_ <= 0) return 0;
  kill(child_, SIGTERM);
  int status = waitExit(child_, std::chrono::milliseconds(5000));
  if (status < 0) {
    kill(child_, SIGKILL);
    status = waitExit(child_, std::chrono::milliseconds(2000));
  }
  child_ = -1;
  return status;
}

void BusScenarioPlant::poll() noexcept {
  port_->poll();
  if (const Eigen::VectorXd* q = port_->measuredPositions(0.0)) {
    q_ = *q;
    previous_stamp_ = stamp_;
    // unitree_hg: the tick, in ms (see BusPlantOptions::interface); the receive time would carry the
    // network's jitter into every measured speed.
    stamp_ = hg_ ? static_cast<std::int64_t>(port_->stateSeq()) * 1000000 : port_->stateStampNs();
    if (q_previous_.size() == q_.size() && previous_stamp_ > 0 && stamp_ > previous_stamp_) {
      const double dt = 1e-9 * static_cast<double>(stamp_ - previous_stamp_);
      for (int i = 0; i < model_.nq; ++i)
        measured_ratio_ = std::max(measured_ratio_, std::abs(q_[i] - q_previous_[i]) / (model_.v_max[i] * dt));
    }
    if (stamp_ != previous_stamp_) q_previous_ = q_;
  }
  while (contacts_->takeNext(contact_sample_)) {
    ++contacts_received_;
    total_contact_steps_ = contact_sample_.total_contact_steps();
    if (contact_sample_.contacts().empty()) continue;
    ++contact_samples_;
    for (const auto& c : contact_sample_.contacts())
      if (c.distance() < min_contact_) {
        min_contact_ = c.distance();
        min_contact_pair_ = c.segment_a() + "-" + c.segment_b();
      }
  }
}

bool BusScenarioPlant::awaitCycle(double t, double period) {
  const auto now = std::chrono::steady_clock::now();
  if (!started_) {
    started_ = true;
    start_ = now;
  }
  const auto due =
      start_ + std::chrono::duration_cast<std::chrono::steady_clock::duration>(std::chrono::duration<double>(t));
  const bool late = now - due >= std::chrono::duration<double>(period);
  if (now < due) std::this_thread::sleep_until(due);
  poll();
  return late;
}

void BusScenarioPlant::rampOut(double period) {
  if (hg_ == nullptr) return;
  Eigen::VectorXd q_before = q_;
  std::int64_t stamp_before = stamp_;
  auto next = std::chrono::steady_clock::now();
  const auto step =
      std::chrono::duration_cast<std::chrono::steady_clock::duration>(std::chrono::duration<double>(period));
  bool more = true;
  while (more) {
    more = hg_->rampOutStep(period);
    next += step;
    std::this_thread::sleep_until(next);
    poll();
    if (stamp_ > stamp_before) {
      const double dt = 1e-9 * static_cast<double>(stamp_ - stamp_before);
      for (int i = 0; i < model_.nq; ++i)
        ramp_out_ratio_ = std::max(ramp_out_ratio_, std::abs(q_[i] - q_before[i]) / (model_.v_max[i] * dt));
      q_before = q_;
      stamp_before = stamp_;
    }
  }
}

double BusScenarioPlant::maxWeightStep() const { return hg_ ? hg_->maxWeightStep() : 0.0; }

double BusScenarioPlant::stateInterval(double period) const {
  if (previous_stamp_ <= 0 || stamp_ <= previous_stamp_) return period;
  return static_cast<double>(stamp_ - previous_stamp_) * 1e-9;
}

}  // namespace reflex::control_node
