// A real reflex_controller process for the bad-input tests, plus a plain participant that feeds it
// and watches its output. The process's exit summary line
//   "reflex_controller: N cycles, ..., e-stops E, targets T (rejected R), stale events S"
// is parsed into ExitSummary.
#pragma once

#include "support/child_process.hpp"

#include <reflex/bus/bus.hpp>

#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <fstream>
#include <iterator>
#include <memory>
#include <regex>
#include <string>
#include <thread>
#include <vector>

namespace reflex::bad_input {

using namespace std::chrono_literals;

inline std::string controllerExe() { return std::string(REFLEX_BIN_DIR) + "/reflex_controller"; }

inline std::string readFile(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
}

inline void writeFile(const std::string& path, const std::string& text) {
  std::ofstream(path, std::ios::binary | std::ios::trunc) << text;
}

struct ExitSummary {
  bool found = false;
  long cycles = 0, overruns = 0, estops = 0, targets = 0, rejected = 0, stale = 0;
  double min_distance_mm = 0.0;
};

inline ExitSummary parseSummary(const std::string& text) {
  ExitSummary s;
  std::smatch m;
  const std::regex re(
      R"(reflex_controller: (\d+) cycles, .* overruns (\d+), min distance ([-0-9.e+]+) mm, e-stops (\d+), )"
      R"(targets (\d+) \(rejected (\d+)\), stale events (\d+))");
  if (std::regex_search(text, m, re)) {
    s.found = true;
    s.cycles = std::stol(m[1]);
    s.overruns = std::stol(m[2]);
    s.min_distance_mm = std::stod(m[3]);
    s.estops = std::stol(m[4]);
    s.targets = std::stol(m[5]);
    s.rejected = std::stol(m[6]);
    s.stale = std::stol(m[7]);
  }
  return s;
}

/// reflex_sim's crossing_arms targets: without avoidance the forearms collide in front of the chest.
inline msg::HandTargets crossingTargets() {
  msg::HandTargets t;
  t.left().status(msg::TARGET_GIVEN);
  t.left().position_base().x(0.30);
  t.left().position_base().y(-0.08);
  t.left().position_base().z(0.90);
  t.right().status(msg::TARGET_GIVEN);
  t.right().position_base().x(0.30);
  t.right().position_base().y(0.08);
  t.right().position_base().z(0.90);
  return t;
}

/// The controller process + a feeding participant ("bad_source") + a watching one.
class ControllerRun {
 public:
  ControllerRun(int domain, double duration_s, const std::string& name, std::vector<std::string> extra = {})
      : log_(::testing::TempDir() + "bad_input_" + name + ".log") {
    std::vector<std::string> argv = {
        controllerExe(),   "--domain", std::to_string(domain), "--duration", std::to_string(duration_s),
        "--input-timeout", "1.0"};
    argv.insert(argv.end(), extra.begin(), extra.end());
    process_ = std::make_unique<testing::ChildProcess>(argv, log_);
    bus::BusConfig config;
    config.module_name = "bad_source";
    config.domain_id = domain;
    source = std::make_unique<bus::Participant>(config);
    config.module_name = "bad_watch";
    watch = std::make_unique<bus::Participant>(config);
    status = &watch->makeReader<msg::ControlStatus>("reflex/control_status", bus::kProfileRecord);
    joints = &watch->makeReader<msg::JointState>("reflex/joint_state", bus::kProfileRecord);
  }

  bool started() const { return process_->started(); }
  /// Sends a signal to the controller process (SIGUSR1: leave a latched e-stop).
  void signal(int sig) { process_->signal(sig); }
  /// Waits until the controller's status stream and the given writer are matched, then 0.5 s more:
  /// the writer sees the match before the controller's reader has matched back, and a reliable
  /// keep-last-1 writer replaces a first sample that was never acknowledged.
  /// On failure: which side did not match, whether the process still runs, and its output so far.
  template <class W>
  ::testing::AssertionResult waitMatched(W& writer) {
    const char* missing = nullptr;
    if (!status->waitForWriters(1, 30s)) {
      missing = "the controller's reflex/control_status writer never matched the watching reader";
    } else if (!writer.waitForReaders(1, 30s)) {
      missing = "the controller's reader never matched the feeding writer";
    }
    if (missing == nullptr) {
      std::this_thread::sleep_for(500ms);
      return ::testing::AssertionSuccess();
    }
    const int rc = process_->wait(0ms);
    return ::testing::AssertionFailure() << missing << " within 30 s; the controller "
                                         << (rc == testing::ChildProcess::kStillRunning
                                                 ? std::string("still runs")
                                                 : "exited with " + std::to_string(rc))
                                         << "; its output so far:\n"
                                         << process_->output();
  }
  /// Keeps draining the watch readers for `d` while calling `tick(k)` every `period`.
  template <class Fn>
  void pump(std::chrono::milliseconds d, std::chrono::milliseconds period, Fn tick) {
    const auto end = std::chrono::steady_clock::now() + d;
    int k = 0;
    while (std::chrono::steady_clock::now() < end) {
      tick(k++);
      std::this_thread::sleep_for(period);
      drain();
    }
  }
  /// Calls `tick(k)` exactly `n` times, at least `period` apart, draining the watch readers in
  /// between. Never faster: after a stall of this process the next ticks do not catch up back to
  /// back (the controller's keep-last-1 readers would replace a sample it had not read yet).
  template <class Fn>
  void pumpCount(int n, std::chrono::milliseconds period, Fn tick) {
    for (int k = 0; k < n; ++k) {
      tick(k);
      std::this_thread::sleep_for(period);
      drain();
    }
  }
  /// Drains the watch readers until the latest status's `counter` (e.g. rejected_hand_targets) is at
  /// least `value`, at most `limit`; whether it got there. For lockstep: the next bad sample is
  /// sent only once the controller has counted the last one, so none is replaced unread.
  template <class Counter>
  bool waitStatusCount(Counter counter, std::uint64_t value,
                       std::chrono::milliseconds limit = std::chrono::seconds(3)) {
    const auto end = std::chrono::steady_clock::now() + limit;
    do {
      drain();
      if (!statuses.empty() && counter(statuses.back()) >= value) return true;
      std::this_thread::sleep_for(std::chrono::milliseconds(2));
    } while (std::chrono::steady_clock::now() < end);
    return false;
  }
  void drain() {
    status->takeAll(statuses);
    joints->takeAll(joint_states);
  }
  /// Waits for the process to exit and returns its exit code and summary.
  int finish(ExitSummary& summary, std::chrono::seconds timeout = 20s) {
    const int rc = process_->wait(timeout);
    output = process_->output();  // the log file
    summary = parseSummary(output);
    return rc;
  }
  /// Every published joint position / velocity finite, every distance finite and (if
  /// `status_distances`) >= d_r. ArmStatus.distance includes virtual body-schema segments (e.g. a
  /// gaze line), which may legitimately overlap the body: tests that attach virtual segments check
  /// the physical minimum of the exit summary instead.
  void expectSafeAndFinite(bool status_distances = true) const {
    ASSERT_FALSE(joint_states.empty());
    for (const auto& js : joint_states) {
      for (double v : js.positions()) ASSERT_TRUE(std::isfinite(v)) << "a non-finite joint position was published";
      for (double v : js.velocities()) ASSERT_TRUE(std::isfinite(v)) << "a non-finite joint velocity was published";
    }
    for (const auto& s : statuses) {
      ASSERT_TRUE(std::isfinite(s.left().distance()) && std::isfinite(s.right().distance()));
      if (status_distances) {
        EXPECT_GE(std::min(s.left().distance(), s.right().distance()), 0.005) << "below d_r";
      }
    }
  }
  /// Position of joint `name` in the newest joint state (NaN if absent).
  double latestJoint(const std::string& name) const {
    if (joint_states.empty()) return std::nan("");
    const auto& js = joint_states.back();
    const auto it = std::find(js.names().begin(), js.names().end(), name);
    return it == js.names().end() ? std::nan("") : js.positions()[static_cast<std::size_t>(it - js.names().begin())];
  }

  std::unique_ptr<bus::Participant> source;
  std::unique_ptr<bus::Participant> watch;
  bus::Reader<msg::ControlStatus>* status = nullptr;
  bus::Reader<msg::JointState>* joints = nullptr;
  std::vector<msg::ControlStatus> statuses;
  std::vector<msg::JointState> joint_states;
  std::string output;

 private:
  std::string log_;
  std::unique_ptr<testing::ChildProcess> process_;
};

/// A valid target pair the shipped robot reaches without a collision (right hand forward).
inline msg::HandTargets reachable() {
  msg::HandTargets t;
  t.left().status(msg::TARGET_NONE);
  t.right().status(msg::TARGET_GIVEN);
  t.right().position_base().x(0.35);
  t.right().position_base().y(-0.20);
  t.right().position_base().z(0.95);
  return t;
}

inline msg::Heartbeat heartbeat(const std::string& module) {
  msg::Heartbeat hb;
  hb.module_name(module);
  hb.state(msg::STATE_RUNNING);
  hb.period_ms(500);
  return hb;
}

}  // namespace reflex::bad_input
