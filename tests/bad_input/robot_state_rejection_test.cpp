// Robot states the controller must refuse, with the real reflex_controller
// --robot dds over real DDS (domain 219). This test is the robot: a participant on UDP only
// (reflex_participant_udp, like robot_port_test's driver) that publishes good states at 200 Hz and,
// one at a time, a bad one of every DdsRobotPort cause, in two or three variants each:
//   robot_state_length         velocities one short; efforts given but one short; one position too many
//   robot_state_missing_joint  l_elbow left out (lengths agree); l_elbow misspelt
//   robot_state_not_finite     a NaN position; a +Inf velocity; a -Inf position
//   robot_state_future_stamp   stamped 1 s ahead; 0.5 s ahead (tolerance 2 ms)
//   robot_state_old_stamp      a good state the controller already answered, sent again as is
//                              (repeated); a new seq stamped 1 s before it (reordered)
//   robot_state_duplicate_name l_elbow listed a second time (same value; another value)
//   robot_state_outside_limits l_elbow 0.05 rad past its upper limit; 1e300; r_elbow below its lower
//                              limit by twice the tolerance (v_max * period)
//   robot_state_other_writer   a good state from a second participant's writer while this one is bound
// A state with l_elbow past its upper limit by half the tolerance is a GOOD state (taken).
// Then three bad states of three causes back to back (one cycle usually takes them together): each is
// counted and each is named on stderr with its own seq.
// Independent answer: what this test sent. After each bad state the test waits for the controller's
// status (reflex/control_status) and asserts that rejected_robot_states rose by exactly 1 and that
// last_rejection names that cause; then, while good states keep coming for 150 ms, that the count
// stays (good states are never counted) and that the controller answers a good state sent after the
// bad one (good states are still taken). No command ever answers a bad state (state_seq /
// state_stamp_ns). At the end the exit line counts each cause exactly as often as it was sent.
// Good states carrying one joint the model lacks (a robot with a gripper) are taken on purpose.
// The robot-state topic is best effort: after a bad state the test sends no good one until the bad
// one is counted, and a bad state lost on the way would fail the "rose by exactly 1" wait (3 s)
// instead of passing silently.
#include "controller_run.hpp"

#include "reflex/control/controller.hpp"
#include "reflex/control/scenarios.hpp"
#include "reflex/control/urdf_loader.hpp"

#include <csignal>
#include <functional>
#include <set>

namespace reflex {
namespace {

using namespace std::chrono_literals;
using bad_input::readFile;
using Clock = std::chrono::steady_clock;

constexpr int kDomain = 219;
constexpr std::uint64_t kOwnSeq = 1'000'000'000;  ///< seqs of written bad states: never one publish() gives

struct Cause {
  const char* name;  ///< robotStateCauseName
  int sent = 0;
};

TEST(RobotStateRejection, EachCauseIsCountedOnceNamedInTheStatusAndGoodStatesAreStillTaken) {
  const std::string urdf = std::string(REFLEX_SOURCE_DIR) + "/bringup/robots/asimo_like.urdf";
  const control::Model model = control::loadModel(urdf, control::loadCollisionConfigFor(urdf, ""));
  const control::ControllerModel cm = control::makeControllerModel(model, control::defaultControllerConfig());
  const Eigen::VectorXd q0 = control::restConfiguration(model, cm);
  const int elbow = model.qIndex("l_elbow");
  ASSERT_GE(elbow, 0);

  const std::string log = ::testing::TempDir() + "robot_state_rejection.controller.log";
  testing::ChildProcess controller(
      {bad_input::controllerExe(), "--domain", std::to_string(kDomain), "--robot", "dds", "--peer-probe", "0",
       "--participant-profile", "reflex_participant_udp", "--duration", "120"},
      log);
  ASSERT_TRUE(controller.started());
  bus::BusConfig config;
  config.module_name = "test_robot";
  config.domain_id = kDomain;
  config.participant_profile = "reflex_participant_udp";
  bus::Participant robot(config);
  auto& states = robot.makeWriter<msg::RobotState>();
  auto& commands = robot.makeReader<msg::JointCommand>("reflex/joint_command", bus::kProfileRecord);
  auto& status = robot.makeReader<msg::ControlStatus>("reflex/control_status", bus::kProfileRecord);
  ASSERT_TRUE(states.waitForReaders(1, 15s)) << readFile(log);
  ASSERT_TRUE(commands.waitForWriters(1, 15s)) << readFile(log);
  ASSERT_TRUE(status.waitForWriters(1, 15s)) << readFile(log);

  bool extra_joint = false;           // good states with one joint the model lacks (taken on purpose)
  double q0_override = std::nan("");  // l_elbow's position in good states, if not NaN
  auto good = [&] {
    msg::RobotState st;
    for (int i = 0; i < model.nq; ++i) {
      st.names().push_back(model.q_names[i]);
      st.positions().push_back(i == elbow && !std::isnan(q0_override) ? q0_override : q0[i]);
      st.velocities().push_back(0.0);
    }
    if (extra_joint) {
      st.names().push_back("r_gripper_finger");
      st.positions().push_back(0.01);
      st.velocities().push_back(0.0);
    }
    return st;
  };
  std::set<std::uint64_t> good_seqs, bad_seqs;
  std::set<std::int64_t> bad_stamps;
  std::uint64_t last_good_seq = 0;
  msg::ControlStatus latest;
  bool have_status = false;
  std::uint64_t answered_seq = 0;  // state_seq of the newest command
  std::vector<msg::JointCommand> cmds;
  std::vector<msg::ControlStatus> statuses;
  int bad_answers = 0;
  // One tick: a good state (unless `quiet`), 5 ms, then whatever the controller said.
  auto tick = [&](bool quiet) {
    if (!quiet) {
      msg::RobotState st = good();
      ASSERT_TRUE(states.publish(st));
      good_seqs.insert(st.header().seq());
      last_good_seq = st.header().seq();
    }
    std::this_thread::sleep_for(5ms);
    cmds.clear();
    commands.takeAll(cmds);
    for (const auto& c : cmds) {
      if (bad_seqs.count(c.state_seq()) || bad_stamps.count(c.state_stamp_ns())) ++bad_answers;
      answered_seq = std::max(answered_seq, c.state_seq());
    }
    statuses.clear();
    status.takeAll(statuses);
    if (!statuses.empty()) {
      latest = statuses.back();
      have_status = true;
    }
  };
  auto ticksUntil = [&](std::chrono::milliseconds limit, const std::function<bool()>& done, bool quiet = false) {
    const auto end = Clock::now() + limit;
    while (Clock::now() < end) {
      tick(quiet);
      if (::testing::Test::HasFatalFailure()) return false;
      if (done()) return true;
    }
    return false;
  };

  // Good states until the controller answers them.
  ASSERT_TRUE(ticksUntil(15s, [&] { return have_status && answered_seq > 0 && good_seqs.count(answered_seq); }))
      << readFile(log);
  ASSERT_EQ(latest.rejected_robot_states(), 0u);

  Cause length{"robot_state_length"}, missing{"robot_state_missing_joint"}, non_finite{"robot_state_not_finite"},
      future{"robot_state_future_stamp"}, old{"robot_state_old_stamp"};
  std::uint64_t expected = 0;
  // Sends one bad state (spoil edits a good one; `stamped`: spoil set the header, written as is),
  // then asserts the count and the cause from the bus, and that good states are taken again.
  auto sendBad = [&](Cause& cause, const char* what, const std::function<void(msg::RobotState&)>& spoil, bool stamped,
                     bus::Writer<msg::RobotState>* via = nullptr) {
    SCOPED_TRACE(what);
    if (::testing::Test::HasFatalFailure()) return;
    msg::RobotState st = good();
    spoil(st);
    bus::Writer<msg::RobotState>& w = via != nullptr ? *via : states;
    if (stamped) {
      ASSERT_TRUE(w.write(st));
    } else {
      ASSERT_TRUE(w.publish(st));
    }
    // A written state of the test's own seq range is bad through and through; the repeated state
    // carries a good state's seq and stamp, which commands may answer (they answer the original).
    if (!stamped || st.header().seq() >= kOwnSeq) {
      bad_seqs.insert(st.header().seq());
      bad_stamps.insert(st.header().stamp_ns());
    }
    ++cause.sent;
    ++expected;
    // No good state until the bad one is counted: each count is then the bad state's alone.
    const bool counted = ticksUntil(
        3s, [&] { return latest.rejected_robot_states() >= expected; }, true);
    ASSERT_TRUE(counted) << "rejected_robot_states stayed " << latest.rejected_robot_states() << "\n" << readFile(log);
    EXPECT_EQ(latest.rejected_robot_states(), expected);
    EXPECT_EQ(latest.last_rejection(), cause.name);
    const std::uint64_t after = last_good_seq;  // a good state sent after the bad one
    ASSERT_TRUE(ticksUntil(3s, [&] { return answered_seq > after; })) << "good states are taken again";
    ticksUntil(150ms, [] { return false; });
    EXPECT_EQ(latest.rejected_robot_states(), expected) << "good states are never counted";
    EXPECT_EQ(latest.last_rejection(), cause.name);
  };
  auto drop = [&](msg::RobotState& st, int i) {
    st.names().erase(st.names().begin() + i);
    st.positions().erase(st.positions().begin() + i);
    st.velocities().erase(st.velocities().begin() + i);
  };

  sendBad(
      length, "velocities one short", [](msg::RobotState& st) { st.velocities().pop_back(); }, false);
  sendBad(
      length, "efforts one short", [](msg::RobotState& st) { st.efforts().assign(st.names().size() - 1, 0.0); }, false);
  sendBad(
      length, "one position too many", [](msg::RobotState& st) { st.positions().push_back(0.0); }, false);
  sendBad(
      missing, "l_elbow left out", [&](msg::RobotState& st) { drop(st, elbow); }, false);
  sendBad(
      missing, "l_elbow misspelt", [&](msg::RobotState& st) { st.names()[static_cast<std::size_t>(elbow)] = "l_elbw"; },
      false);
  sendBad(
      non_finite, "NaN position", [](msg::RobotState& st) { st.positions()[3] = std::nan(""); }, false);
  sendBad(
      non_finite, "+Inf velocity", [](msg::RobotState& st) { st.velocities()[5] = HUGE_VAL; }, false);
  sendBad(
      non_finite, "-Inf position", [](msg::RobotState& st) { st.positions()[0] = -HUGE_VAL; }, false);
  std::uint64_t own_seq = kOwnSeq;
  sendBad(
      future, "stamped 1 s ahead",
      [&](msg::RobotState& st) {
        st.header().seq(++own_seq);
        st.header().stamp_ns(bus::nowNs() + 1'000'000'000);
      },
      true);
  // 0.5 s: far past the 2 ms tolerance even when the test or the controller stalls between the stamp
  // and the check (at 50 ms a 48 ms stall let it through, and every later count was off).
  sendBad(
      future, "stamped 0.5 s ahead",
      [&](msg::RobotState& st) {
        st.header().seq(++own_seq);
        st.header().stamp_ns(bus::nowNs() + 500'000'000);
      },
      true);
  // Old: a state the controller has answered (so it holds that one or a newer one), sent again.
  const std::uint64_t repeat_seq = answered_seq;
  ASSERT_TRUE(good_seqs.count(repeat_seq));
  msg::RobotState repeated = good();
  bool found = false;
  {
    // Its stamp: the answering command carries it (state_stamp_ns).
    ASSERT_TRUE(ticksUntil(3s, [&] {
      for (const auto& c : cmds)
        if (c.state_seq() == answered_seq) {
          repeated.header().seq(c.state_seq());
          repeated.header().stamp_ns(c.state_stamp_ns());
          found = true;
        }
      return found;
    }));
  }
  sendBad(
      old, "an answered state sent again", [&](msg::RobotState& st) { st.header() = repeated.header(); }, true);
  sendBad(
      old, "a new seq stamped 1 s before it",
      [&](msg::RobotState& st) {
        st.header().seq(++own_seq);
        st.header().stamp_ns(repeated.header().stamp_ns() - 1'000'000'000);
      },
      true);

  Cause duplicate{"robot_state_duplicate_name"}, limits{"robot_state_outside_limits"},
      other{"robot_state_other_writer"};
  sendBad(
      duplicate, "l_elbow twice, same value",
      [&](msg::RobotState& st) {
        st.names().push_back("l_elbow");
        st.positions().push_back(q0[elbow]);
        st.velocities().push_back(0.0);
      },
      false);
  sendBad(
      duplicate, "l_elbow twice, another value",
      [&](msg::RobotState& st) {
        st.names().insert(st.names().begin(), "l_elbow");
        st.positions().insert(st.positions().begin(), q0[elbow] + 0.05);
        st.velocities().insert(st.velocities().begin(), 0.0);
      },
      false);
  const int r_elbow = model.qIndex("r_elbow");
  const double period = control::defaultControllerConfig().params.period;
  sendBad(
      limits, "l_elbow 0.05 rad past its upper limit",
      [&](msg::RobotState& st) { st.positions()[static_cast<std::size_t>(elbow)] = model.q_upper[elbow] + 0.05; },
      false);
  sendBad(
      limits, "l_elbow 1e300", [&](msg::RobotState& st) { st.positions()[static_cast<std::size_t>(elbow)] = 1e300; },
      false);
  sendBad(
      limits, "r_elbow below its lower limit by twice the tolerance",
      [&](msg::RobotState& st) {
        st.positions()[static_cast<std::size_t>(r_elbow)] =
            model.q_lower[r_elbow] - 2.0 * control::stateLimitTolerance(model, r_elbow, period);
      },
      false);
  // Within the tolerance: a good state, taken and answered.
  {
    double& e = q0_override;
    e = model.q_upper[elbow] + 0.5 * control::stateLimitTolerance(model, elbow, period);
    const std::uint64_t before = last_good_seq;
    ASSERT_TRUE(ticksUntil(3s, [&] { return answered_seq > before; })) << "a state within the tolerance is taken";
    EXPECT_EQ(latest.rejected_robot_states(), expected);
    e = std::nan("");
  }
  // Three bad states of three causes back to back (microseconds apart, so one controller cycle
  // usually takes them together): each is counted and each is named with its own seq, not only the
  // last one the cycle took.
  std::vector<std::uint64_t> burst_seqs;
  {
    const int l_wrist = model.qIndex("l_wrist");
    const int r_wrist = model.qIndex("r_wrist");
    ASSERT_GE(l_wrist, 0);
    ASSERT_GE(r_wrist, 0);
    msg::RobotState two_positions_too_many = good(), wrist_left_out = good(), wrist_nan = good();
    two_positions_too_many.positions().push_back(0.0);
    two_positions_too_many.positions().push_back(0.0);
    drop(wrist_left_out, l_wrist);
    wrist_nan.positions()[static_cast<std::size_t>(r_wrist)] = std::nan("");
    for (msg::RobotState* st : {&two_positions_too_many, &wrist_left_out, &wrist_nan}) {
      ASSERT_TRUE(states.publish(*st));
      burst_seqs.push_back(st->header().seq());
      bad_seqs.insert(st->header().seq());
      bad_stamps.insert(st->header().stamp_ns());
    }
    ++length.sent;
    ++missing.sent;
    ++non_finite.sent;
    expected += 3;
    ASSERT_TRUE(ticksUntil(
        3s, [&] { return latest.rejected_robot_states() >= expected; }, true))
        << "rejected_robot_states stayed " << latest.rejected_robot_states() << "\n"
        << readFile(log);
    const std::uint64_t after = last_good_seq;
    ASSERT_TRUE(ticksUntil(3s, [&] { return answered_seq > after; })) << "good states are taken again";
    EXPECT_EQ(latest.rejected_robot_states(), expected);
  }
  {
    bus::BusConfig second = config;
    second.module_name = "second_robot";
    bus::Participant intruder(second);
    auto& intruder_states = intruder.makeWriter<msg::RobotState>();
    // The robot keeps sending while the intruder is discovered: silent for rebind_silence (1 s), its
    // writer would count as gone and the intruder's state would rebind instead of being refused. Then
    // 300 ms more, so the controller's reader has matched the intruder's writer too (best effort: a
    // sample written before that is lost).
    ASSERT_TRUE(ticksUntil(15s, [&] { return intruder_states.waitForReaders(1, 0s); }));
    ticksUntil(300ms, [] { return false; });
    sendBad(
        other, "a good state from a second writer", [](msg::RobotState&) {}, false, &intruder_states);
  }

  // A robot with one joint more than the model: its states are taken, never counted.
  extra_joint = true;
  const std::uint64_t before_extra = last_good_seq;
  ASSERT_TRUE(ticksUntil(3s, [&] { return answered_seq > before_extra; })) << "states with an extra joint are taken";
  ticksUntil(200ms, [] { return false; });
  EXPECT_EQ(latest.rejected_robot_states(), expected);
  EXPECT_EQ(latest.rejected_hand_targets() + latest.rejected_body_schema() + latest.rejected_walk_commands(), 0u);
  EXPECT_EQ(bad_answers, 0) << "a command answered a bad state";
  std::printf(
      "sent %llu bad states (length %d, missing %d, non-finite %d, future %d, old %d, duplicate %d, limits %d, "
      "other writer %d), %zu good; status counted %llu\n",
      static_cast<unsigned long long>(expected), length.sent, missing.sent, non_finite.sent, future.sent, old.sent,
      duplicate.sent, limits.sent, other.sent, good_seqs.size(),
      static_cast<unsigned long long>(latest.rejected_robot_states()));

  controller.signal(SIGTERM);
  EXPECT_EQ(controller.wait(20s), 0);
  const std::string text = readFile(log);
  unsigned long long accepted = 0, rejected = 0;
  const std::size_t at = text.find("robot dds: states ");
  ASSERT_NE(at, std::string::npos) << text;
  ASSERT_EQ(std::sscanf(text.c_str() + at, "robot dds: states %llu (rejected %llu)", &accepted, &rejected), 2) << text;
  EXPECT_EQ(rejected, expected);
  EXPECT_GT(accepted, 100u);
  char by_cause[500];
  std::snprintf(
      by_cause, sizeof(by_cause), "rejected by cause: %s %d, %s %d, %s %d, %s %d, %s %d, %s %d, %s %d, %s %d (last %s)",
      length.name, length.sent, missing.name, missing.sent, non_finite.name, non_finite.sent, future.name, future.sent,
      old.name, old.sent, duplicate.name, duplicate.sent, limits.name, limits.sent, other.name, other.sent, other.name);
  EXPECT_NE(text.find(by_cause), std::string::npos) << "expected '" << by_cause << "' in\n" << text;
  // Each refusal is named on stderr with the bad value.
  for (const char* line : {"names but", "joint 'l_elbow' is missing", "position nan", "velocity inf", "position -inf",
                           "in the future", "not newer than", "joint 'l_elbow' is listed twice",
                           "joint 'l_elbow' position 1e+300 outside its limits", "not the robot writer"})
    EXPECT_NE(text.find(line), std::string::npos) << line << "\n" << text;
  // The burst: each of the three named by its own seq with its own cause.
  ASSERT_EQ(burst_seqs.size(), 3u);
  const std::string n = std::to_string(model.nq);
  const std::vector<std::string> burst_lines = {
      " " + std::to_string(burst_seqs[0]) + " rejected: " + n + " names but " + std::to_string(model.nq + 2) +
          " positions",
      " " + std::to_string(burst_seqs[1]) + " rejected: joint 'l_wrist' is missing",
      " " + std::to_string(burst_seqs[2]) + " rejected: joint 'r_wrist' position nan"};
  for (const std::string& line : burst_lines) EXPECT_NE(text.find(line), std::string::npos) << line << "\n" << text;
}

}  // namespace
}  // namespace reflex
