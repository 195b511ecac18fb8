// Faults with the physics robot, DDS domain 195: reflex_mujoco (the
// robot), reflex_controller --robot dds and reflex_behavior (bringup/behavior/scripted.yaml: the
// hands reach across, so the arms move) as three separate processes; this test process only watches
// the bus (reflex/robot_state, reflex/joint_command, reflex/heartbeat) and sends the signals.
//
// The sequence and its independent answers:
//   1. normal: the robot applies commands (RobotState.holding false) that answer its own states;
//   2. kill -9 of reflex_mujoco while the arms move: the controller says "robot state stale" in its
//      heartbeat's detail (idl/README.md: ControlStatus has no robot field and is a live type, so the
//      heartbeat carries it) within the robot timeout plus a few cycles, and FREEZES: no JointCommand
//      is published later than the last robot state's stamp + --robot-timeout + two controller periods
//      (the stamps of the robot and of the commands, not this process's timing, decide);
//   3. restart of reflex_mujoco: back to normal, i.e. a state of the new robot, a command answering
//      such a state (JointCommand.state_stamp_ns), the robot applying it (holding false) and the
//      heartbeat's detail empty again, all within 3 s of the new robot's first state (the time from
//      the restart, which includes MuJoCo building the robot, is printed);
//   4. kill -9 of reflex_controller while the arms are raised against gravity (a shoulder holding
//      more than 2 N m): the robot holds (holding true from one command deadline on,
//      applied_command_seq 0) and the drift of every arm joint over 2 s from the first holding state
//      is measured and bounded per joint by the servo's physics, computed here with MuJoCo on the same
//      URDF at the held configuration (not taken from the robot process):
//        - the whole drift: holding, every joint obeys M(q) e'' = -Kp e - (Kd + damping) e' (the
//          drive's bias feed-forward cancels gravity and Coriolis; e = q - the held reference, which
//          is the state the robot published just before holding), so V = 1/2 e'^T M e' + 1/2 e^T Kp e
//          never grows; from the first holding state t0, |e_j(t)| <= sqrt(2 V(t0) / kp_j), and
//          |q_j(t) - q_j(t0)| <= that + |e_j(t0)| (+0.1 mrad for the integrator);
//        - once settled (0.5 s .. 2 s), for the joints loaded by more than 0.1 N m: less than tau_g,j / kp_j, the sag of this servo without its
//          gravity feed-forward (tau_g from MuJoCo at the held configuration): the robot holds against
//          gravity, it does not sag under it;
//   5. restart of reflex_controller: back to normal (commands answered by the new controller, the
//      robot applying them, heartbeat detail empty) within 3 s of its first heartbeat (the time from
//      the restart, which includes the process's start-up, is printed).
#include "support/robot.hpp"
#include "support/child_process.hpp"

#include "reflex/mujoco/mjcf.hpp"
#include "reflex/mujoco/mujoco_robot.hpp"
#include "../bus/bus_test_util.hpp"

#include <reflex/bus/bus.hpp>

#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <fstream>
#include <functional>
#include <iterator>
#include <memory>
#include <thread>

namespace {

using namespace std::chrono_literals;
using reflex::testing::ChildProcess;
namespace msg = reflex::msg;
namespace bus = reflex::bus;

constexpr int kDomain = 195;
constexpr double kRobotTimeout = 0.050;  // s: reflex_controller's default --robot-timeout
constexpr double kPeriod = 0.005;        // s: the controller's period (controller.hpp default)
constexpr double kBackWithin = 3.0;      // s: "back to normal within 3 s"
const std::vector<std::string> kArmJoints = {
    "l_shoulder_pitch", "l_shoulder_roll", "l_shoulder_yaw", "l_elbow", "l_wrist",
    "r_shoulder_pitch", "r_shoulder_roll", "r_shoulder_yaw", "r_elbow", "r_wrist"};

std::string bin(const std::string& exe) { return std::string(REFLEX_BIN_DIR) + "/" + exe; }
std::string logPath(const std::string& name) { return ::testing::TempDir() + "/mujoco_faults_" + name + ".log"; }
std::string readFile(const std::string& path) {
  std::ifstream in(path);
  return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
}
double sec(std::int64_t ns) { return 1e-9 * static_cast<double>(ns); }

std::vector<std::string> robotArgs() {
  // UDP only (idl/README.md, Writing a robot driver): on Fast DDS 2.9's shared memory the controller's
  // writers stall ~1 s for the port health check after the robot's kill -9 (seen: "stale" after 1.5 s).
  return {
      bin("reflex_mujoco"),    "--domain", std::to_string(kDomain), "--name", "mujoco_faults", "--participant-profile",
      "reflex_participant_udp"};
}
std::vector<std::string> controllerArgs() {
  // UDP only too: a controller restarted after kill -9 takes its predecessor's participant id, and
  // over Fast DDS 2.9's shared memory the peers that knew the dead one (behavior, this watch) found
  // the new one only after 3 s typically and once not within 29 s (the robot, on UDP, was commanded
  // at once; bringup/README.md, "A controller restart"). Over UDP the new controller is found at
  // once. This test is about the robot and the controller recovering, not that transport defect.
  return {bin("reflex_controller"),
          "--domain",
          std::to_string(kDomain),
          "--robot",
          "dds",
          "--name",
          "ctl_faults",
          "--participant-profile",
          "reflex_participant_udp"};
}

// What this process saw on the bus, each with its arrival time (system clock, ns).
struct Seen {
  std::int64_t at = 0;
  msg::RobotState state;
};
struct SeenCommand {
  std::int64_t at = 0;
  std::int64_t stamp = 0, state_stamp = 0;
  std::uint64_t state_seq = 0;
};
struct SeenBeat {
  std::int64_t at = 0;
  std::int32_t pid = 0;
  std::string detail;
};

struct Watch {
  bus::Participant participant;
  bus::Reader<msg::RobotState>& states;
  bus::Reader<msg::JointCommand>& commands;
  bus::Reader<msg::Heartbeat>& beats;
  std::vector<Seen> seen_states;
  std::vector<SeenCommand> seen_commands;
  std::vector<SeenBeat> seen_beats;  // of the controller only
  Watch()
      : participant(bus::test::testConfig("mujoco_faults_watch", kDomain)),
        // The recorders' reader profile (keep last 256): every state and command, also when this
        // process is late to poll.
        states(participant.makeReader<msg::RobotState>("reflex/robot_state", bus::kProfileRecord)),
        commands(participant.makeReader<msg::JointCommand>("reflex/joint_command", bus::kProfileRecord)),
        beats(participant.makeReader<msg::Heartbeat>("reflex/heartbeat", bus::kProfileHeartbeat)) {}

  void pollOnce() {
    Seen s;
    while (states.takeNext(s.state)) {
      s.at = bus::nowNs();
      seen_states.push_back(s);
    }
    msg::JointCommand c;
    while (commands.takeNext(c))
      seen_commands.push_back({bus::nowNs(), c.header().stamp_ns(), c.state_stamp_ns(), c.state_seq()});
    msg::Heartbeat hb;
    while (beats.takeNext(hb))
      if (hb.module_name() == "ctl_faults") seen_beats.push_back({bus::nowNs(), hb.pid(), hb.detail()});
  }
  /// Polls every ms for `seconds`.
  void pumpFor(double seconds) {
    const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(seconds);
    while (std::chrono::steady_clock::now() < end) {
      pollOnce();
      std::this_thread::sleep_for(1ms);
    }
  }
  /// Polls until `done()` or `seconds` passed; true if done.
  bool pumpUntil(double seconds, const std::function<bool()>& done) {
    const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(seconds);
    while (std::chrono::steady_clock::now() < end) {
      pollOnce();
      if (done()) return true;
      std::this_thread::sleep_for(1ms);
    }
    return false;
  }
};

// The first arrival time (ns) at or after `from` of an element matching `pred`; -1 if none.
template <typename T, typename P>
std::int64_t firstAfter(const std::vector<T>& seen, std::int64_t from, P pred) {
  for (const T& e : seen)
    if (e.at >= from && pred(e)) return e.at;
  return -1;
}

// "Back to normal" after a restart at `from`: a fresh robot state (stamp after `fresh_after`), a
// command answering such a state, the robot applying commands (not holding), the controller's
// heartbeat without detail (from `pid` if non-zero). Returns the latest of the four arrivals, -1 if
// one is missing.
std::int64_t backToNormal(const Watch& w, std::int64_t from, std::int64_t fresh_after, std::int32_t pid) {
  const std::int64_t state =
      firstAfter(w.seen_states, from, [&](const Seen& s) { return s.state.header().stamp_ns() > fresh_after; });
  const std::int64_t command =
      firstAfter(w.seen_commands, from, [&](const SeenCommand& c) { return c.state_stamp > fresh_after; });
  const std::int64_t applied = firstAfter(w.seen_states, from, [&](const Seen& s) {
    return s.state.header().stamp_ns() > fresh_after && !s.state.holding() && s.state.applied_command_seq() > 0;
  });
  const std::int64_t ok =
      firstAfter(w.seen_beats, from, [&](const SeenBeat& b) { return b.detail.empty() && (pid == 0 || b.pid == pid); });
  if (state < 0 || command < 0 || applied < 0 || ok < 0) return -1;
  return std::max({state, command, applied, ok});
}

double largestShoulderEffort(const msg::RobotState& s) {
  double e = 0.0;
  for (std::size_t i = 0; i < s.names().size() && i < s.efforts().size(); ++i)
    if (s.names()[i].find("shoulder") != std::string::npos) e = std::max(e, std::abs(s.efforts()[i]));
  return e;
}

double largestArmSpeed(const msg::RobotState& s) {
  double v = 0.0;
  for (std::size_t i = 0; i < s.names().size(); ++i)
    if (std::find(kArmJoints.begin(), kArmJoints.end(), s.names()[i]) != kArmJoints.end())
      v = std::max(v, std::abs(s.velocities()[i]));
  return v;
}

TEST(MujocoFaults, KillAndRestartTheRobotAndTheController) {
  auto robot = std::make_unique<ChildProcess>(robotArgs(), logPath("robot1"));
  auto controller = std::make_unique<ChildProcess>(controllerArgs(), logPath("controller1"));
  ChildProcess behavior(
      {bin("reflex_behavior"), "--config", std::string(REFLEX_SOURCE_DIR) + "/bringup/behavior/scripted.yaml",
       "--domain", std::to_string(kDomain)},
      logPath("behavior"));
  ASSERT_TRUE(robot->started() && controller->started() && behavior.started());
  Watch w;

  // 1. Normal operation, arms moving.
  const std::int64_t t_start = bus::nowNs();
  ASSERT_TRUE(w.pumpUntil(60.0, [&] { return backToNormal(w, t_start, 0, 0) >= 0; }))
      << "robot:\n"
      << readFile(logPath("robot1")) << "controller:\n"
      << readFile(logPath("controller1"));
  ASSERT_TRUE(w.pumpUntil(15.0, [&] {
    return !w.seen_states.empty() && largestArmSpeed(w.seen_states.back().state) > 0.05;
  })) << "the scripted hands move the arms";
  std::printf("[ measured ] normal operation %.1f s after the start; the arms move\n", sec(bus::nowNs() - t_start));

  // 2. kill -9 of the robot while the arms move.
  w.pumpFor(0.3);
  const std::int64_t t_kill_robot = bus::nowNs();
  robot->signal(SIGKILL);
  EXPECT_EQ(robot->wait(2000ms), 128 + SIGKILL);
  robot.reset();
  w.pumpFor(1.5);
  std::int64_t last_state_stamp = 0;
  std::uint64_t last_state_seq = 0;
  for (const Seen& s : w.seen_states)
    if (s.state.header().stamp_ns() > last_state_stamp) {
      last_state_stamp = s.state.header().stamp_ns();
      last_state_seq = s.state.header().seq();
    }
  ASSERT_GT(last_state_stamp, 0);
  EXPECT_LE(last_state_stamp, t_kill_robot + 1'000'000) << "no robot state after the kill";
  const std::int64_t stale_at =
      firstAfter(w.seen_beats, t_kill_robot, [](const SeenBeat& b) { return b.detail.find("robot state stale") == 0; });
  ASSERT_GE(stale_at, 0) << "the controller's heartbeat says 'robot state stale'\n" << readFile(logPath("controller1"));
  std::printf(
      "[ measured ] robot killed: the controller said 'robot state stale' %.0f ms after the robot's last state "
      "(timeout %.0f ms)\n",
      1e-6 * static_cast<double>(stale_at - last_state_stamp), kRobotTimeout * 1e3);
  EXPECT_LT(sec(stale_at - last_state_stamp), kRobotTimeout + 0.5)
      << "said within the timeout and a loaded host's delay";
  // Frozen: no command stamped after the last state's stamp + timeout + two periods, none answering
  // a later state; and nothing at all during the last second.
  std::int64_t last_command_stamp = 0;
  std::uint64_t max_answered = 0;
  int late_commands = 0;
  for (const SeenCommand& c : w.seen_commands) {
    if (c.at < t_kill_robot - 1'000'000'000) continue;
    last_command_stamp = std::max(last_command_stamp, c.stamp);
    if (c.at >= t_kill_robot) max_answered = std::max(max_answered, c.state_seq);
    if (c.at >= stale_at + 500'000'000) ++late_commands;
  }
  std::printf(
      "[ measured ] last command stamped %.1f ms after the robot's last state (bound %.0f ms); commands in the "
      "last second: %d\n",
      1e-6 * static_cast<double>(last_command_stamp - last_state_stamp), (kRobotTimeout + 2 * kPeriod) * 1e3,
      late_commands);
  EXPECT_LE(sec(last_command_stamp - last_state_stamp), kRobotTimeout + 2 * kPeriod) << "the command is frozen";
  EXPECT_LE(max_answered, last_state_seq) << "no command answers a state that never was";
  EXPECT_EQ(late_commands, 0);
  const std::string detail = w.seen_beats.back().detail;
  EXPECT_EQ(detail.find("robot state stale"), 0u) << "still stale: " << detail;

  // 3. Restart of the robot: back to normal.
  const std::int64_t t_restart_robot = bus::nowNs();
  robot = std::make_unique<ChildProcess>(robotArgs(), logPath("robot2"));
  ASSERT_TRUE(robot->started());
  ASSERT_TRUE(w.pumpUntil(60.0, [&] { return backToNormal(w, t_restart_robot, t_restart_robot, 0) >= 0; }))
      << readFile(logPath("robot2"));
  {
    const std::int64_t back = backToNormal(w, t_restart_robot, t_restart_robot, 0);
    const std::int64_t first_state = firstAfter(
        w.seen_states, t_restart_robot, [&](const Seen& s) { return s.state.header().stamp_ns() > t_restart_robot; });
    std::int64_t first_stamp = 0;
    for (const Seen& s : w.seen_states)
      if (s.at == first_state) first_stamp = s.state.header().stamp_ns();
    // Asserted from the new robot's first state: what comes before is the robot booting (MuJoCo
    // building it: 0.3-5.3 s measured on a loaded two-core host), not the system recovering.
    std::printf(
        "[ measured ] robot restarted: back to normal %.0f ms after its first state (%.2f s after the restart, "
        "which includes building the robot in MuJoCo and discovery)\n",
        1e-6 * static_cast<double>(back - first_stamp), sec(back - t_restart_robot));
    EXPECT_LT(sec(back - first_stamp), kBackWithin);
  }

  // 4. kill -9 of the controller while a shoulder holds the raised arm against gravity: MuJoCo on the
  // same URDF in this process (the "twin") gives the gravity torque at each measured configuration.
  const reflex::control::Model model = reflex::testing::loadRobot("asimo_like");
  const reflex::mujoco::MjcfOptions options;
  reflex::mujoco::MujocoRobot twin(model, options);
  const mjModel& mm = twin.mjModelRef();
  mjData& md = twin.mjDataRef();
  auto toModelOrder = [&](const msg::RobotState& s) {
    Eigen::VectorXd q = Eigen::VectorXd::Zero(model.nq);
    for (std::size_t i = 0; i < s.names().size(); ++i) q[model.qIndex(s.names()[i])] = s.positions()[i];
    return q;
  };
  auto shoulderGravity = [&](const msg::RobotState& s) {  // largest |gravity torque| on a shoulder joint [N m]
    twin.setPositions(toModelOrder(s));
    double g = 0.0;
    for (const std::string& joint : kArmJoints)
      if (joint.find("shoulder") != std::string::npos)
        g = std::max(g, std::abs(md.qfrc_bias[mm.jnt_dofadr[mj_name2id(&mm, mjOBJ_JOINT, joint.c_str())]]));
    return g;
  };
  double gravity_seen = 0.0;
  ASSERT_TRUE(w.pumpUntil(20.0,
                          [&] {
                            gravity_seen = std::max(gravity_seen, shoulderGravity(w.seen_states.back().state));
                            return gravity_seen > 2.0;
                          }))
      << "the arms are raised (scripted targets in front of the chest): largest shoulder gravity torque seen "
      << gravity_seen << " N m";
  const std::int64_t t_kill_ctl = bus::nowNs();
  controller->signal(SIGKILL);
  EXPECT_EQ(controller->wait(2000ms), 128 + SIGKILL);
  controller.reset();
  w.pumpFor(2.6);
  // The first holding state h0 and the hold's reference: the robot holds at the measurement it
  // published last before holding (MujocoRobot::beginHold), i.e. the state with seq h0.seq - 1. If
  // that state was lost on the way here, the reference is the settled position 2 s later (with the
  // gravity feed-forward the servo settles on its reference: see the settled drift below).
  const Seen* hold_start = nullptr;
  const Seen* before_hold = nullptr;
  for (const Seen& s : w.seen_states) {
    if (s.at >= t_kill_ctl && s.state.holding()) {
      hold_start = &s;
      break;
    }
    before_hold = &s;
  }
  ASSERT_NE(hold_start, nullptr) << "the robot holds once the commands stop";
  const msg::RobotState h0 = hold_start->state;
  std::printf("[ measured ] controller killed: the robot holds %.1f ms after the kill (arm speed then %.3f rad/s)\n",
              1e-6 * static_cast<double>(h0.header().stamp_ns() - t_kill_ctl), largestArmSpeed(h0));
  const msg::RobotState* reference = nullptr;
  const bool contiguous = before_hold && before_hold->state.header().seq() + 1 == h0.header().seq();
  if (contiguous) {
    reference = &before_hold->state;
  } else {
    for (const Seen& s : w.seen_states)
      if (s.state.header().stamp_ns() - h0.header().stamp_ns() <= 2'000'000'000) reference = &s.state;
  }
  ASSERT_NE(reference, nullptr);

  // The bound per arm joint: the servo's energy at h0, V = 1/2 v^T M v + 1/2 sum kp_i e_i^2 over every
  // joint (e = h0 - reference), with M and kp of the twin at h0 (not from the robot process); while
  // holding V never grows, so |e_j(t)| <= sqrt(2 V / kp_j) and the drift from h0 is at most that plus
  // |e_j(h0)|. 0.1 mrad is left for the integrator.
  twin.setPositions(toModelOrder(h0));
  std::vector<mjtNum> v0(static_cast<std::size_t>(mm.nv), 0.0), Mv0(static_cast<std::size_t>(mm.nv), 0.0);
  std::vector<double> e0(h0.names().size(), 0.0);
  double energy2 = 0.0;  // 2 V [J]
  for (std::size_t k = 0; k < h0.names().size(); ++k) {
    const int qi = model.qIndex(h0.names()[k]);
    v0[static_cast<std::size_t>(mm.jnt_dofadr[mj_name2id(&mm, mjOBJ_JOINT, h0.names()[k].c_str())])] =
        h0.velocities()[k];
    e0[k] = h0.positions()[k] - reference->positions()[k];
    energy2 += twin.gains()[qi].kp * e0[k] * e0[k];
  }
  mj_mulM(&mm, &md, Mv0.data(), v0.data());
  for (int d = 0; d < mm.nv; ++d) energy2 += v0[static_cast<std::size_t>(d)] * Mv0[static_cast<std::size_t>(d)];
  std::printf(
      "[ measured ] at the hold: 2V = %.3e J (largest arm speed %.3f rad/s, largest shoulder torque %.2f N m); "
      "reference: %s\n",
      energy2, largestArmSpeed(h0), largestShoulderEffort(h0),
      contiguous ? "the state before the hold" : "the settled position (the state before the hold was lost)");
  double worst_ratio = 0.0;
  bool held_throughout = true;
  for (const std::string& joint : kArmJoints) {
    int i = -1;
    for (std::size_t k = 0; k < h0.names().size(); ++k)
      if (h0.names()[k] == joint) i = static_cast<int>(k);
    ASSERT_GE(i, 0) << joint;
    const int qi = model.qIndex(joint);
    const int dof = mm.jnt_dofadr[mj_name2id(&mm, mjOBJ_JOINT, joint.c_str())];
    const double tau_g = md.qfrc_bias[dof];  // at rest (setPositions: zero velocities): gravity only [N m]
    const double kp = twin.gains()[qi].kp;
    const double bound = std::sqrt(energy2 / kp) + std::abs(e0[static_cast<std::size_t>(i)]) + 1e-4;
    const double settled_bound = std::abs(tau_g) / kp;
    double drift = 0.0, settled = 0.0;
    const msg::RobotState* at_half = nullptr;
    for (const Seen& s : w.seen_states) {
      const std::int64_t dt = s.state.header().stamp_ns() - h0.header().stamp_ns();
      if (dt < 0 || dt > 2'000'000'000) continue;
      held_throughout = held_throughout && s.state.holding() && s.state.applied_command_seq() == 0;
      drift = std::max(drift, std::abs(s.state.positions()[i] - h0.positions()[i]));
      if (dt >= 500'000'000 && !at_half) at_half = &s.state;
      if (at_half) settled = std::max(settled, std::abs(s.state.positions()[i] - at_half->positions()[i]));
    }
    ASSERT_NE(at_half, nullptr);
    std::printf(
        "[ measured ] %-16s drift over 2 s %.2e rad (bound %.2e, kp %.1f N m/rad); settled 0.5-2 s %.2e rad "
        "(bound tau_g/kp = %.2e, gravity %.2f N m)\n",
        joint.c_str(), drift, bound, kp, settled, settled_bound, tau_g);
    EXPECT_LT(drift, bound) << joint;
    if (std::abs(tau_g) > 0.1) {
      EXPECT_LT(settled, settled_bound) << joint << " (loaded by gravity)";
    }
    worst_ratio = std::max(worst_ratio, drift / bound);
  }
  EXPECT_TRUE(held_throughout) << "holding, applied_command_seq 0, for the whole 2 s";
  EXPECT_GT(w.seen_states.back().state.header().stamp_ns() - h0.header().stamp_ns(), 1'900'000'000)
      << "states over the whole 2 s";
  std::printf("[ measured ] largest drift / bound over the arm joints: %.2f\n", worst_ratio);

  // 5. Restart of the controller: back to normal.
  const std::int64_t t_restart_ctl = bus::nowNs();
  controller = std::make_unique<ChildProcess>(controllerArgs(), logPath("controller2"));
  ASSERT_TRUE(controller->started());
  const std::int32_t pid2 = controller->pid();
  ASSERT_TRUE(w.pumpUntil(30.0, [&] { return backToNormal(w, t_restart_ctl, t_restart_ctl, pid2) >= 0; }))
      << readFile(logPath("controller2"));
  // Asserted from the new controller's first heartbeat (its loop runs): what comes before is the
  // process starting (the URDF, the DDS participant, the 1 s --peer-probe for another controller:
  // 1.2-3.1 s measured on a loaded two-core host), not the system recovering.
  const std::int64_t back = backToNormal(w, t_restart_ctl, t_restart_ctl, pid2);
  const std::int64_t first_beat =
      firstAfter(w.seen_beats, t_restart_ctl, [&](const SeenBeat& b) { return b.pid == pid2; });
  ASSERT_GE(first_beat, 0);
  std::printf(
      "[ measured ] controller restarted: back to normal %.0f ms after its first heartbeat (%.2f s after the "
      "restart, which includes its start-up and the 1 s peer probe)\n",
      1e-6 * static_cast<double>(back - first_beat), sec(back - t_restart_ctl));
  EXPECT_LT(sec(back - first_beat), kBackWithin);

  w.pumpFor(1.0);
  EXPECT_EQ(controller->terminate(), 0);
  EXPECT_EQ(robot->terminate(), 0);
  const std::string robot_log = readFile(logPath("robot2"));
  EXPECT_NE(robot_log.find("unstable steps 0"), std::string::npos) << robot_log;
}

}  // namespace
