// reflex_mujoco as a separate process on the bus (DDS domain 151), driven by this test process as the
// stand-in controller: it reads reflex/robot_state and writes reflex/joint_command like a controller.
//
// Independent answers:
//   - tracking: the reference is an analytic sinusoid of wall-clock time on both shoulders and
//     elbows; the measured positions (RobotState, stamped by the robot) are compared with it: the
//     RMS and largest error and the servo lag (the shift of the reference that fits the measurement
//     best) are measured, printed and bounded;
//   - holding: when the commands stop, the robot says so (holding, applied_command_seq 0) once the
//     last deadline has passed, and its arms, loaded by gravity, move less than 1 mrad over 2 s;
//   - bad and late commands: expired deadlines, NaN, an unknown joint, wrong lengths and a joint named
//     twice, each aimed 0.5 rad away, never move the robot (it keeps holding; every joint within
//     2 mrad) and are counted by category in reflex_mujoco's exit summary;
//   - the judge on the bus: the robot started where the project's distance module puts the closest
//     pair 2 mm apart (l_shoulder_roll found by bisection) publishes that pair, and only pairs the
//     module puts below d_r, in RobotContacts with MuJoCo's distance (within 10 um), tied to a
//     RobotState seq, and counts contact steps; started 8 mm apart it reports none;
//   - its heartbeat is on reflex/heartbeat, RUNNING;
//   - set-up errors: the process exits with 1 and a message naming the bad value.
// The command latency (RobotState.stamp -> the JointCommand answering it, measured by reflex_mujoco)
// is printed from the exit summary, not asserted (control/README.md has the numbers).
#include "support/robot.hpp"
#include "support/child_process.hpp"

#include "reflex/control/distance.hpp"
#include "reflex/control/kinematics.hpp"

#include <reflex/bus/bus.hpp>

#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <limits>
#include <map>
#include <regex>
#include <sstream>
#include <thread>

namespace {

using namespace std::chrono_literals;
using reflex::testing::ChildProcess;
namespace msg = reflex::msg;
namespace bus = reflex::bus;

constexpr int kDomain = 151;
const std::vector<std::string> kArm = {"l_shoulder_pitch", "r_shoulder_pitch", "l_elbow", "r_elbow"};

std::string binary() { return std::string(REFLEX_BIN_DIR) + "/reflex_mujoco"; }

std::string readFile(const std::string& path) {
  std::ifstream in(path);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

std::string logPath(const std::string& name) { return ::testing::TempDir() + "/mujoco_process_" + name + ".log"; }

// Arms forward and bent, so that gravity loads the shoulders and elbows.
std::vector<std::string> robotArgs(const std::string& name) {
  return {binary(),
          "--domain",
          std::to_string(kDomain),
          "--name",
          "mujoco_" + name,
          "--q",
          "l_shoulder_pitch=-0.6",
          "--q",
          "r_shoulder_pitch=-0.6",
          "--q",
          "l_elbow=-0.8",
          "--q",
          "r_elbow=-0.8"};
}

double seconds(std::int64_t ns) { return 1e-9 * static_cast<double>(ns); }

struct Commander {
  bus::Participant participant;
  bus::Reader<msg::RobotState>& states;
  bus::Writer<msg::JointCommand>& commands;
  msg::RobotState latest;
  std::vector<msg::RobotState> received;
  explicit Commander(const std::string& name)
      : participant([&] {
          bus::BusConfig c;
          c.module_name = "commander_" + name;
          c.domain_id = kDomain;
          return c;
        }()),
        states(participant.makeReader<msg::RobotState>()),
        commands(participant.makeWriter<msg::JointCommand>()) {}

  /// Waits for the first state (robot started, matched); false on timeout.
  bool waitForState(std::chrono::seconds timeout) {
    const auto end = std::chrono::steady_clock::now() + timeout;
    while (std::chrono::steady_clock::now() < end) {
      if (poll()) return true;
      std::this_thread::sleep_for(5ms);
    }
    return false;
  }
  /// Takes every new state (kept in `received`); true if there was one.
  bool poll() {
    bool got = false;
    msg::RobotState s;
    while (states.takeNext(s)) {
      received.push_back(s);
      latest = s;
      got = true;
    }
    return got;
  }
  int index(const std::string& joint) const {
    for (std::size_t i = 0; i < latest.names().size(); ++i)
      if (latest.names()[i] == joint) return static_cast<int>(i);
    return -1;
  }
  void send(std::vector<std::string> names, std::vector<double> positions, std::vector<double> velocities,
            std::int64_t valid_until_ns) {
    msg::JointCommand c;
    c.names(std::move(names));
    c.positions(std::move(positions));
    c.velocities(std::move(velocities));
    c.valid_until_ns(valid_until_ns);
    c.state_seq(latest.header().seq());
    c.state_stamp_ns(latest.header().stamp_ns());
    commands.publish(c);
  }
};

// The reference of arm joint j at time t [s] from the start of commanding: a 0.5 Hz sinusoid of
// 0.3 rad around the initial position.
constexpr double kAmp = 0.3, kFreq = 0.5;
double reference(double q0, double t) { return q0 + kAmp * std::sin(2.0 * M_PI * kFreq * t); }
double referenceRate(double t) { return kAmp * 2.0 * M_PI * kFreq * std::cos(2.0 * M_PI * kFreq * t); }

TEST(MujocoProcess, TracksCommandsThenHoldsAgainstGravityWhenTheyStop) {
  ChildProcess robot(robotArgs("track"), logPath("track"));
  ASSERT_TRUE(robot.started());
  Commander cmd("track");
  ASSERT_TRUE(cmd.waitForState(30s)) << readFile(logPath("track"));
  const msg::RobotState first = cmd.latest;
  ASSERT_TRUE(first.holding()) << "no command yet: the robot holds";
  std::vector<int> arm;
  for (const auto& j : kArm) arm.push_back(cmd.index(j));
  for (int i : arm) ASSERT_GE(i, 0);
  const std::vector<double> q0 = first.positions();

  // 4 s of commands at 200 Hz: every joint held at q0, the four arm joints on the sinusoid; each
  // command is the reference 5 ms ahead (the end of the cycle), valid for 20 ms.
  const std::int64_t t0 = bus::nowNs();
  cmd.received.clear();
  std::int64_t now = t0;
  while ((now = bus::nowNs()) - t0 < 4'000'000'000) {
    cmd.poll();
    const double t = seconds(now - t0) + 0.005;
    std::vector<double> pos = q0, vel(q0.size(), 0.0);
    for (int i : arm) {
      pos[i] = reference(q0[i], t);
      vel[i] = referenceRate(t);
    }
    cmd.send(first.names(), pos, vel, now + 20'000'000);
    std::this_thread::sleep_for(5ms);
  }
  const std::int64_t t_stop = bus::nowNs();
  cmd.poll();

  // Tracking error and lag over the last 3 s (the first second includes the start from rest).
  std::vector<std::pair<double, std::vector<double>>> samples;  // (t, arm positions)
  for (const auto& s : cmd.received) {
    const double t = seconds(s.header().stamp_ns() - t0);
    if (t < 1.0 || s.header().stamp_ns() > t_stop) continue;
    std::vector<double> p;
    for (int i : arm) p.push_back(s.positions()[i]);
    samples.emplace_back(t, p);
  }
  ASSERT_GT(samples.size(), 300u) << "states received in 3 s (keep-last-1 reader polled every 5 ms: <= 200 per s)";
  auto rmsAtLag = [&](double lag, double* max_err) {
    double sum = 0.0;
    int n = 0;
    *max_err = 0.0;
    for (const auto& [t, p] : samples)
      for (std::size_t k = 0; k < arm.size(); ++k) {
        const double e = p[k] - reference(q0[arm[k]], t - lag);
        sum += e * e;
        ++n;
        *max_err = std::max(*max_err, std::abs(e));
      }
    return std::sqrt(sum / n);
  };
  double max_err = 0.0;
  const double rms = rmsAtLag(0.0, &max_err);
  std::vector<double> abs_err;
  for (const auto& [t, p] : samples)
    for (std::size_t k = 0; k < arm.size(); ++k) abs_err.push_back(std::abs(p[k] - reference(q0[arm[k]], t)));
  std::sort(abs_err.begin(), abs_err.end());
  const double median = abs_err[abs_err.size() / 2], p95 = abs_err[abs_err.size() * 95 / 100];
  double best_lag = 0.0, best_rms = rms, best_max = max_err;
  for (double lag = 0.0; lag <= 0.2; lag += 0.001) {
    double m = 0.0;
    const double r = rmsAtLag(lag, &m);
    if (r < best_rms) {
      best_rms = r;
      best_lag = lag;
      best_max = m;
    }
  }
  std::printf(
      "[ measured ] tracking a %.1f rad %.1f Hz sinusoid (peak %.2f rad/s) on 4 arm joints over %zu states: "
      "error median %.4f rad, p95 %.4f, RMS %.4f, max %.4f; servo lag %.0f ms (residual RMS %.4f rad, max %.4f)\n",
      kAmp, kFreq, kAmp * 2 * M_PI * kFreq, samples.size(), median, p95, rms, max_err, best_lag * 1e3, best_rms,
      best_max);
  // Bounds: the servo (10 Hz, critically damped) follows its reference with a lag of about 25 ms: its
  // velocity feed-forward acts only while the reference travels to a commanded position, never past
  // it (measured on a loaded run: median 15.5 mrad, RMS 15.9, lag 24 ms, residual after the lag 2.5
  // mrad). An earlier servo kept the feed-forward on after the reference
  // arrived, which held the joint 2 qdot / omega PAST the command (a lead that hid the lag here:
  // median 1.3 mrad, lag 0-1 ms) and carried arms below d_r when a command was late. The tail is this
  // loaded machine: a commander stalled beyond the 20 ms deadline makes the robot hold, a robot
  // stalled beyond 20 periods loses time. So the shape (the residual once the lag is removed) is
  // bounded as the RMS was before (30 mrad), the median and lag to the servo's, max loosely (a 200 ms stall).
  EXPECT_LT(median, 0.03);
  EXPECT_LT(rms, 0.05);
  EXPECT_LT(max_err, 0.2);
  EXPECT_LT(best_lag, 0.05);
  EXPECT_LT(best_rms, 0.03);

  // Commands stop: after the last deadline (20 ms) the robot holds; the drift is measured from 0.5 s
  // on (the servo has settled from the motion it was stopped in).
  std::this_thread::sleep_for(500ms);
  cmd.received.clear();
  std::this_thread::sleep_for(20ms);
  ASSERT_TRUE(cmd.waitForState(5s));
  EXPECT_TRUE(cmd.latest.holding());
  EXPECT_EQ(cmd.latest.applied_command_seq(), 0u);
  const msg::RobotState hold_start = cmd.latest;
  std::this_thread::sleep_for(2s);
  cmd.received.clear();
  ASSERT_TRUE(cmd.waitForState(5s));
  const msg::RobotState hold_end = cmd.latest;
  EXPECT_TRUE(hold_end.holding());
  double drift = 0.0;
  for (int i : arm) drift = std::max(drift, std::abs(hold_end.positions()[i] - hold_start.positions()[i]));
  double gravity_torque = 0.0;
  for (int i : arm) gravity_torque = std::max(gravity_torque, std::abs(hold_end.efforts()[i]));
  std::printf(
      "[ measured ] holding over %.2f s (robot clock): arm drift %.2e rad, largest arm holding torque %.2f N m\n",
      seconds(hold_end.header().stamp_ns() - hold_start.header().stamp_ns()), drift, gravity_torque);
  EXPECT_LT(drift, 1e-4);  // measured: 1.5e-9 rad (PD hold with gravity feed-forward)
  EXPECT_GT(gravity_torque, 1.0) << "the arms are loaded by gravity";

  // Its heartbeat (reliable, transient local: this late reader gets the newest).
  auto& heartbeats = cmd.participant.makeReader<msg::Heartbeat>();
  bool running = false;
  const auto hb_end = std::chrono::steady_clock::now() + 5s;
  msg::Heartbeat hb;
  while (!running && std::chrono::steady_clock::now() < hb_end) {
    while (heartbeats.takeNext(hb))
      running = running || (hb.module_name() == "mujoco_track" && hb.state() == msg::STATE_RUNNING);
    std::this_thread::sleep_for(10ms);
  }
  EXPECT_TRUE(running) << "reflex/heartbeat of mujoco_track, RUNNING";

  EXPECT_EQ(robot.terminate(), 0);
  const std::string log = readFile(logPath("track"));
  std::smatch m;
  ASSERT_TRUE(std::regex_search(log, m, std::regex("command latency p50 (\\d+) us p99 (\\d+) us over (\\d+)"))) << log;
  std::printf(
      "[ measured ] command latency (RobotState.stamp -> JointCommand arrival, this test as the controller): "
      "p50 %s us, p99 %s us over %s commands\n",
      m[1].str().c_str(), m[2].str().c_str(), m[3].str().c_str());
  ASSERT_TRUE(
      std::regex_search(log, m, std::regex("overruns (\\d+) \\(periods lost (\\d+)\\), max lateness (\\d+) us")));
  std::printf("[ measured ] robot loop: %s overruns, %s periods lost, max lateness %s us\n", m[1].str().c_str(),
              m[2].str().c_str(), m[3].str().c_str());
  EXPECT_NE(log.find("unstable steps 0"), std::string::npos) << log;
}

TEST(MujocoProcess, LateAndMalformedCommandsAreCountedAndNeverApplied) {
  ChildProcess robot(robotArgs("bad"), logPath("bad"));
  ASSERT_TRUE(robot.started());
  Commander cmd("bad");
  ASSERT_TRUE(cmd.waitForState(30s)) << readFile(logPath("bad"));
  std::this_thread::sleep_for(300ms);  // settle the hold
  cmd.poll();
  const msg::RobotState first = cmd.latest;
  const std::vector<double> q0 = first.positions();
  const std::vector<std::string> names = first.names();
  const std::size_t n = names.size();
  std::vector<double> away = q0;
  for (const auto& j : kArm) away[cmd.index(j)] += (j.find("elbow") != std::string::npos ? 0.5 : -0.5);
  const std::vector<double> zero(n, 0.0);
  const double nan = std::numeric_limits<double>::quiet_NaN();

  std::map<std::string, int> sent;
  cmd.received.clear();
  const auto end = std::chrono::steady_clock::now() + 1500ms;
  for (int k = 0; std::chrono::steady_clock::now() < end; ++k) {
    const std::int64_t now = bus::nowNs();
    // The other bad commands' deadlines far ahead: the robot checks the deadline before the values,
    // so one that arrived 20 ms late (a loaded machine; a fresh-clone .ci/run) was
    // counted as expired.
    const std::int64_t later = now + 2'000'000'000;
    switch (k % 5) {
      case 0:  // deadline already passed
        cmd.send(names, away, zero, now - 1'000'000);
        ++sent["expired"];
        break;
      case 1: {  // NaN position
        auto p = away;
        p[cmd.index("l_elbow")] = nan;
        cmd.send(names, p, zero, later);
        ++sent["not finite"];
        break;
      }
      case 2: {  // a joint this robot does not have
        auto nm = names;
        nm.back() = "tail";
        cmd.send(nm, away, zero, later);
        ++sent["unknown name"];
        break;
      }
      case 3: {  // one position short
        auto p = away;
        p.pop_back();
        cmd.send(names, p, zero, later);
        ++sent["length"];
        break;
      }
      case 4: {  // a joint named twice
        auto nm = names;
        nm[0] = nm[1];
        cmd.send(nm, away, zero, later);
        ++sent["duplicate"];
        break;
      }
    }
    cmd.poll();
    std::this_thread::sleep_for(6ms);
  }
  std::this_thread::sleep_for(100ms);
  cmd.poll();
  ASSERT_GT(cmd.received.size(), 100u);
  double moved = 0.0;
  bool always_holding = true;
  for (const auto& s : cmd.received) {
    always_holding = always_holding && s.holding() && s.applied_command_seq() == 0;
    for (std::size_t i = 0; i < n; ++i) moved = std::max(moved, std::abs(s.positions()[i] - q0[i]));
  }
  std::printf("[ measured ] %zu states during bad commands: largest joint motion %.2e rad\n", cmd.received.size(),
              moved);
  EXPECT_TRUE(always_holding);
  EXPECT_LT(moved, 2e-3);

  EXPECT_EQ(robot.terminate(), 0);
  const std::string log = readFile(logPath("bad"));
  std::smatch m;
  ASSERT_TRUE(std::regex_search(log, m, std::regex("commands applied (\\d+) rejected (\\d+)"))) << log;
  EXPECT_EQ(m[1].str(), "0");
  for (const auto& [category, count] : sent) {
    ASSERT_TRUE(std::regex_search(log, m, std::regex(category + " (\\d+)"))) << category << "\n" << log;
    const int counted = std::stoi(m[1].str());
    std::printf("[ measured ] %s: sent %d, counted %d\n", category.c_str(), count, counted);
    EXPECT_GE(counted, 1) << category;
    EXPECT_LE(counted, count) << category;
  }
}

// The l_shoulder_roll at which the closest checked pair of the robot (arms otherwise at 0) is
// `distance` apart, by bisection on the project's distance module; also returns that pair's names.
double rollAtClosestDistance(double distance, std::string* a, std::string* b) {
  namespace control = reflex::control;
  const control::Model model = reflex::testing::loadRobot("asimo_like");
  control::KinematicsData kin(model);
  control::DistanceData dist(model);
  const int roll = model.qIndex("l_shoulder_roll");
  auto closest = [&](double r) {
    Eigen::VectorXd q = Eigen::VectorXd::Zero(model.nq);
    for (int i = 0; i < model.nq; ++i) q[i] = std::clamp(0.0, model.q_lower[i], model.q_upper[i]);
    q[roll] = r;
    control::computeForwardKinematics(model, kin, q);
    control::computeSegmentDistances(model, kin, dist);
    const auto& p = dist.pairs[dist.closest];
    *a = model.segments[p.seg_a].name;
    *b = model.segments[p.seg_b].name;
    return p.distance;
  };
  double lo = -0.1, hi = 0.0;  // closest(lo) < 0 < distance < closest(hi) = 40 mm
  for (int k = 0; k < 60; ++k) {
    const double mid = 0.5 * (lo + hi);
    (closest(mid) < distance ? lo : hi) = mid;
  }
  closest(hi);
  return hi;
}

TEST(MujocoProcess, TheJudgeReportsPairsBelowTheMarginOnTheBus) {
  for (const double target : {0.002, 0.008}) {
    std::string a, b;
    const double roll = rollAtClosestDistance(target, &a, &b);
    char arg[64];
    std::snprintf(arg, sizeof arg, "l_shoulder_roll=%.17g", roll);
    const std::string name = target < 0.005 ? "judge2" : "judge8";
    ChildProcess robot({binary(), "--domain", std::to_string(kDomain), "--name", name, "--q", arg}, logPath(name));
    Commander cmd(name);
    auto& contacts = cmd.participant.makeReader<msg::RobotContacts>();
    ASSERT_TRUE(cmd.waitForState(30s)) << readFile(logPath(name));
    std::this_thread::sleep_for(1s);
    msg::RobotContacts c;
    ASSERT_TRUE(contacts.takeLatest(c)) << "RobotContacts are published with every state";
    std::printf(
        "[ measured ] %s,%s at %.1f mm by the distance module (l_shoulder_roll %.6f): %zu pairs reported, "
        "total contact steps %llu\n",
        a.c_str(), b.c_str(), target * 1e3, roll, c.contacts().size(),
        static_cast<unsigned long long>(c.total_contact_steps()));
    EXPECT_GT(c.state_seq(), 0u);
    if (target < 0.005) {
      ASSERT_EQ(c.contacts().size(), 1u);
      EXPECT_EQ(c.contacts()[0].segment_a() + "," + c.contacts()[0].segment_b(), a + "," + b);
      EXPECT_NEAR(c.contacts()[0].distance(), target, 1e-5);
      std::printf("[ measured ] MuJoCo's distance %.6f mm\n", c.contacts()[0].distance() * 1e3);
      EXPECT_GT(c.total_contact_steps(), 500u) << "every step of the last second had the pair";
    } else {
      EXPECT_TRUE(c.contacts().empty());
      EXPECT_EQ(c.total_contact_steps(), 0u);
    }
    EXPECT_EQ(robot.terminate(), 0);
    const std::string log = readFile(logPath(name));
    EXPECT_NE(log.find(target < 0.005 ? "contact " + a + "," + b + " min distance" : "contact steps 0"),
              std::string::npos)
        << log;
  }
}

TEST(MujocoProcess, SetupErrorsNameTheBadValue) {
  struct Case {
    std::vector<std::string> args;
    std::string message;
  };
  const std::vector<Case> cases = {
      {{"--q", "tail=1"}, "unknown joint 'tail'"},
      {{"--q", "l_elbow=abc"}, "'abc' is not a finite number"},
      {{"--q", "l_elbow=1"}, "outside the joint limits"},
      {{"--period", "0.0007"}, "whole multiple"},
      {{"--margin", "-1"}, "margin = -1"},
      {{"--urdf", "/nonexistent/robot.urdf"}, "/nonexistent/robot.urdf"},
  };
  for (const auto& c : cases) {
    std::vector<std::string> argv = {binary(), "--domain", std::to_string(kDomain)};
    argv.insert(argv.end(), c.args.begin(), c.args.end());
    ChildProcess bad(argv, logPath("setup"));
    EXPECT_EQ(bad.wait(60s), 2) << c.args[1];
    const std::string log = readFile(logPath("setup"));
    EXPECT_NE(log.find("reflex_mujoco: error:"), std::string::npos) << log;
    EXPECT_NE(log.find(c.message), std::string::npos) << log;
  }
}

}  // namespace
