// The robot port under attack, with the truth measured on the plant: the real reflex_controller
// --robot dds drives reflex_test_robot (tests/system/test_robot_driver.cpp: a kinematic plant that
// moves every commanded joint towards its commanded position at the commanded speed, and computes the
// TRUE distances of every checked pair from its own positions at every 1 ms tick). The hands are
// sent to reflex_sim's crossing_arms targets (the forearms collide without avoidance), so the arms
// work in the yellow zone when the attack comes. One case per class of lie:
//   beyond_limit   the driver reports l_elbow 0.05 rad past its upper limit for 0.3 s (4 cycles of
//                  v_max: past the tolerance); absurd: 1e300 for 0.3 s; duplicate: l_elbow listed a
//                  second time with a value 0.05 rad off for 0.3 s (the first value is the truth);
//   second_writer  a second participant publishes a constant state (legs bent, arms at rest) at
//                  500 Hz for 1.5 s beside the real driver;
//   man_in_middle  a second participant re-sends each of the driver's states with l_shoulder_pitch
//                  and l_elbow 0.05 rad further (a writer between the robot and the controller).
// Independent answer: the plant's own truth (its exit line), never the controller's belief: the
// smallest distance of any checked pair stays >= d_r (5 mm), no applied command has a velocity above
// the URDF limit or a position beyond a limit, and no joint the controller does not drive as an arm
// joint (legs, heel, body) moves at all. Plus what the controller must say: the cause counted in its
// exit line, and the heartbeat's detail naming the rejection or the ignored writer. Domains 161..165.
#include "controller_run.hpp"

#include "reflex/control/controller.hpp"
#include "reflex/control/scenarios.hpp"
#include "reflex/control/urdf_loader.hpp"

#include <csignal>
#include <cstdio>

namespace reflex {
namespace {

using namespace std::chrono_literals;
using bad_input::readFile;
using Clock = std::chrono::steady_clock;

struct Truth {
  bool found = false;
  double min_distance = 0.0, speed_ratio = 0.0, beyond_limit = 0.0, other_motion = 0.0;
  unsigned long long lied = 0;
  std::string pair;
};

Truth parseTruth(const std::string& text) {
  Truth t;
  const std::size_t at = text.find("reflex_test_robot: truth: ");
  if (at == std::string::npos) return t;
  char pair[200] = {};
  t.found = std::sscanf(text.c_str() + at,
                        "reflex_test_robot: truth: min distance %lf m (%199[^)]), max command speed / v_max %lf, max "
                        "command beyond a limit %lf, max motion of a non-arm joint %lf, states lied %llu",
                        &t.min_distance, pair, &t.speed_ratio, &t.beyond_limit, &t.other_motion, &t.lied) == 6;
  t.pair = pair;
  return t;
}

struct Attack {
  int domain;
  std::vector<std::string> lie;  ///< reflex_test_robot options
  enum class Writer { kNone, kSecond, kManInTheMiddle } writer = Writer::kNone;
};

/// Runs one attack; returns the controller's and the driver's output.
void runAttack(const Attack& attack, std::string& controller_text, std::string& driver_text,
               std::vector<std::string>& details) {
  const std::string urdf = std::string(REFLEX_SOURCE_DIR) + "/bringup/robots/asimo_like.urdf";
  const control::Model model = control::loadModel(urdf, control::loadCollisionConfigFor(urdf, ""));
  const control::ControllerModel cm = control::makeControllerModel(model, control::defaultControllerConfig());
  const std::string dir = ::testing::TempDir();
  const std::string tag = std::to_string(attack.domain);
  const std::string clog = dir + "attack_" + tag + ".controller.log", dlog = dir + "attack_" + tag + ".robot.log";
  testing::ChildProcess controller({bad_input::controllerExe(), "--domain", tag, "--robot", "dds", "--peer-probe", "0",
                                    "--participant-profile", "reflex_participant_udp", "--duration", "60"},
                                   clog);
  ASSERT_TRUE(controller.started());
  std::vector<std::string> dargs = {testing::binPath("reflex_test_robot"), "--domain", tag};
  dargs.insert(dargs.end(), attack.lie.begin(), attack.lie.end());
  testing::ChildProcess driver(dargs, dlog);
  ASSERT_TRUE(driver.started());

  bus::BusConfig config;
  config.module_name = "attack_source";
  config.domain_id = attack.domain;
  config.participant_profile = "reflex_participant_udp";
  bus::Participant source(config);
  auto& targets = source.makeWriter<msg::HandTargets>();
  auto& heartbeats = source.makeReader<msg::Heartbeat>();
  auto& commands = source.makeReader<msg::JointCommand>("reflex/joint_command", bus::kProfileRecord);
  ASSERT_TRUE(targets.waitForReaders(1, 15s)) << readFile(clog);
  ASSERT_TRUE(commands.waitForWriters(1, 15s)) << readFile(clog);
  // The attacker: its own participant (another process on a real network would be the same to DDS).
  std::unique_ptr<bus::Participant> attacker;
  bus::Writer<msg::RobotState>* forged = nullptr;
  bus::Reader<msg::RobotState>* real_states = nullptr;
  if (attack.writer != Attack::Writer::kNone) {
    bus::BusConfig ac = config;
    ac.module_name = "attacker";
    attacker = std::make_unique<bus::Participant>(ac);
    forged = &attacker->makeWriter<msg::RobotState>();
    if (attack.writer == Attack::Writer::kManInTheMiddle) real_states = &attacker->makeReader<msg::RobotState>();
  }
  // Until the robot is commanded, then 4 s of crossing targets with the attack in the middle.
  const msg::HandTargets t = bad_input::crossingTargets();
  msg::JointCommand cmd;
  const auto wait_end = Clock::now() + 20s;
  bool commanded = false;
  while (!commanded && Clock::now() < wait_end) {
    msg::HandTargets tt = t;
    targets.publish(tt);
    std::this_thread::sleep_for(20ms);
    commanded = commands.takeLatest(cmd);
  }
  ASSERT_TRUE(commanded) << readFile(clog) << readFile(dlog);
  const auto start = Clock::now();
  Eigen::VectorXd q_forged = control::restConfiguration(model, cm);
  for (const char* leg : {"l_knee", "r_knee"}) q_forged[model.qIndex(leg)] = 0.6;
  for (const char* hip : {"l_hip_pitch", "r_hip_pitch"}) q_forged[model.qIndex(hip)] = -0.3;
  msg::RobotState state;
  msg::Heartbeat hb;
  bus::dds::SampleInfo info;
  auto last_targets = Clock::now();
  while (Clock::now() - start < 4s) {
    const double since = std::chrono::duration<double>(Clock::now() - start).count();
    if (Clock::now() - last_targets > 200ms) {  // a sign of life of the source (input_timeout 1 s)
      msg::HandTargets tt = t;
      targets.publish(tt);
      last_targets = Clock::now();
    }
    if (attack.writer == Attack::Writer::kSecond && since >= 1.0 && since < 2.5) {
      msg::RobotState s;
      s.names(model.q_names);
      s.positions().assign(q_forged.data(), q_forged.data() + model.nq);
      s.velocities().assign(static_cast<std::size_t>(model.nq), 0.0);
      forged->publish(s);
    }
    if (attack.writer == Attack::Writer::kManInTheMiddle) {
      while (real_states->takeNext(state)) {
        // Only the driver's states (the forged ones, marked "relay", come back to this reader too).
        if (state.header().source() == "relay") continue;
        state.header().source("relay");
        for (std::size_t k = 0; k < state.names().size(); ++k)
          if (state.names()[k] == "l_shoulder_pitch" || state.names()[k] == "l_elbow") state.positions()[k] += 0.05;
        forged->write(state);  // stamp and seq as measured: a faithful relay but for the lie and the source
      }
    }
    while (heartbeats.takeNext(hb, &info))
      if (hb.module_name() == "controller" && !hb.detail().empty()) details.push_back(hb.detail());
    std::this_thread::sleep_for(2ms);
  }
  driver.signal(SIGTERM);
  EXPECT_EQ(driver.wait(10s), 0);
  controller.signal(SIGTERM);
  EXPECT_EQ(controller.wait(20s), 0);
  controller_text = readFile(clog);
  driver_text = readFile(dlog);
}

/// The truth on the plant: never below d_r, never a command above v_max or beyond a limit, nothing
/// but the arm joints moved.
void expectSafeTruth(const std::string& driver_text, const std::string& controller_text) {
  const Truth truth = parseTruth(driver_text);
  ASSERT_TRUE(truth.found) << driver_text;
  const double d_r = control::defaultControllerConfig().params.d_r;
  std::printf(
      "truth: min distance %.2f mm (%s), max command speed / v_max %.4f, beyond a limit %.3g, non-arm motion %.3g, "
      "lied %llu\n",
      truth.min_distance * 1e3, truth.pair.c_str(), truth.speed_ratio, truth.beyond_limit, truth.other_motion,
      truth.lied);
  EXPECT_GE(truth.min_distance, d_r) << driver_text << controller_text;
  EXPECT_LE(truth.speed_ratio, 1.0 + 1e-9) << controller_text;
  EXPECT_LE(truth.beyond_limit, 1e-12) << controller_text;
  EXPECT_EQ(truth.other_motion, 0.0) << "a leg, heel or body joint moved";
  EXPECT_NE(controller_text.find("e-stops 0,"), std::string::npos) << "an e-stop latched\n" << controller_text;
}

bool anyContains(const std::vector<std::string>& details, const std::string& what) {
  for (const auto& d : details)
    if (d.find(what) != std::string::npos) return true;
  return false;
}

/// "robot_state_outside_limits 73" in the exit line's "rejected by cause": the count, 0 if absent.
long causeCount(const std::string& text, const std::string& cause) {
  const std::size_t at = text.find("rejected by cause: ");
  if (at == std::string::npos) return 0;
  const std::size_t c = text.find(cause + " ", at);
  return c == std::string::npos ? 0 : std::stol(text.substr(c + cause.size() + 1));
}

TEST(RobotPortAttack, StateBeyondALimitIsRejectedAndNoCommandExceedsVmax) {
  std::string ctext, dtext;
  std::vector<std::string> details;
  runAttack({161,
             {"--lie", "beyond_limit", "--lie-joint", "l_elbow", "--lie-from", "1.5", "--lie-for", "0.3",
              "--lie-amount", "0.05"}},
            ctext, dtext, details);
  expectSafeTruth(dtext, ctext);
  EXPECT_GT(parseTruth(dtext).lied, 100u);
  EXPECT_GT(causeCount(ctext, "robot_state_outside_limits"), 10) << ctext;
  EXPECT_NE(ctext.find("joint 'l_elbow' position"), std::string::npos) << ctext;
  EXPECT_TRUE(anyContains(details, "outside its limits")) << "the heartbeat's detail names the rejection";
}

TEST(RobotPortAttack, AbsurdFiniteValueIsRejectedAndNeverEchoed) {
  std::string ctext, dtext;
  std::vector<std::string> details;
  runAttack(
      {162,
       {"--lie", "absurd", "--lie-joint", "l_elbow", "--lie-from", "1.5", "--lie-for", "0.3", "--lie-amount", "1e300"}},
      ctext, dtext, details);
  expectSafeTruth(dtext, ctext);
  EXPECT_GT(causeCount(ctext, "robot_state_outside_limits"), 10) << ctext;
  EXPECT_TRUE(anyContains(details, "1e+300")) << "the heartbeat's detail names the value";
}

TEST(RobotPortAttack, DuplicatedJointNameIsRejected) {
  std::string ctext, dtext;
  std::vector<std::string> details;
  runAttack({163,
             {"--lie", "duplicate", "--lie-joint", "l_elbow", "--lie-from", "1.5", "--lie-for", "0.3", "--lie-amount",
              "0.05"}},
            ctext, dtext, details);
  expectSafeTruth(dtext, ctext);
  EXPECT_GT(causeCount(ctext, "robot_state_duplicate_name"), 10) << ctext;
  EXPECT_TRUE(anyContains(details, "joint 'l_elbow' is listed twice"));
}

TEST(RobotPortAttack, SecondWriterIsIgnoredCountedAndNamed) {
  std::string ctext, dtext;
  std::vector<std::string> details;
  Attack a{164, {}};
  a.writer = Attack::Writer::kSecond;
  runAttack(a, ctext, dtext, details);
  expectSafeTruth(dtext, ctext);
  EXPECT_GT(causeCount(ctext, "robot_state_other_writer"), 100) << ctext;
  EXPECT_NE(ctext.find("SECOND ROBOT WRITER ignored"), std::string::npos) << ctext;
  EXPECT_TRUE(anyContains(details, "IGNORING a second reflex/robot_state writer"));
}

TEST(RobotPortAttack, ManInTheMiddleIsIgnoredAndNeverLatchesOnAPhantom) {
  std::string ctext, dtext;
  std::vector<std::string> details;
  Attack a{165, {}};
  a.writer = Attack::Writer::kManInTheMiddle;
  runAttack(a, ctext, dtext, details);
  expectSafeTruth(dtext, ctext);
  EXPECT_GT(causeCount(ctext, "robot_state_other_writer"), 100) << ctext;
  EXPECT_TRUE(anyContains(details, "IGNORING a second reflex/robot_state writer"));
}

}  // namespace
}  // namespace reflex
