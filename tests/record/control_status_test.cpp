// What reflex/control_status tells a reader, with the real
// reflex_controller and reflex_record processes over real DDS. Domains 210, 211, 213.
//  - Fig. 13 from a recording alone: reflex_record records joint state and control status while the
//    arms cross; every recorded ControlStatus.arm_distance equals the left-arm/right-arm distance
//    recomputed here from the recorded joint positions the controller computed that cycle from (the
//    robot after the previous cycle: the JointState sample of seq - 1, kinematic plant) with the
//    distance module (FK + computeSegmentDistances, the closest pair of a segment of the left arm and
//    one of the right arm, by the arms' own segment masks), to 1e-9 m.
//  - the --log CSV of the same run: min_pair is filled in every row and names the closest physical
//    pair recomputed from the previous row's q_ columns (the positions the cycle computed from), whose
//    distance is min_distance (to 1e-6 m: the CSV has 9 significant digits).
//  - refusals: a hand target just beyond max_target_distance (2 m from the base origin) and a walk command with goal_y = 0.3 m
//    (the robot walks along x only) are refused; control_status counts each on its topic and names
//    the latest cause, the exit line lists them by cause, and the heel does not move.
//  - closest segment names: with a collision configuration where the right arm's only pairs are with
//    the left arm, right-arm priority leaves the right arm without any pair: its names are "" exactly
//    when its distance is 1e9, in every status sample, also after they were set under equal priority
//    (the previous names must not stay); under equal priority the names are the right arm's
//    segment first, then the left arm's.
#include "../bad_input/controller_run.hpp"

#include "reflex/control/controller.hpp"
#include "reflex/control/distance.hpp"
#include "reflex/control/kinematics.hpp"
#include "reflex/control/scenarios.hpp"
#include "reflex/control/urdf_loader.hpp"
#include "reflex/record/recording.hpp"
#include "record_support.hpp"

#include <map>
#include <sstream>

namespace reflex::record {
namespace {

using bad_input::ControllerRun;
using bad_input::readFile;
using bad_input::writeFile;
using namespace std::chrono_literals;

std::string bin(const std::string& name) { return std::string(REFLEX_BIN_DIR) + "/" + name; }
std::string tempPath(const std::string& name) { return ::testing::TempDir() + "control_status_test_" + name; }
const std::string kUrdf = std::string(REFLEX_SOURCE_DIR) + "/bringup/robots/asimo_like.urdf";

/// The closest distance between a segment the left arm moves and one the right arm moves (m).
double armToArm(const control::Model& model, const control::ControllerModel& cm, const Eigen::VectorXd& q) {
  control::KinematicsData kin(model);
  control::DistanceData dist(model);
  EXPECT_TRUE(control::computeForwardKinematics(model, kin, q));
  control::computeSegmentDistances(model, kin, dist);
  double best = std::numeric_limits<double>::infinity();
  for (const control::PairDistance& pd : dist.pairs) {
    if (!pd.active) continue;
    const bool la = (cm.arms[control::kLeft].segment_mask >> pd.seg_a) & 1U;
    const bool lb = (cm.arms[control::kLeft].segment_mask >> pd.seg_b) & 1U;
    const bool ra = (cm.arms[control::kRight].segment_mask >> pd.seg_a) & 1U;
    const bool rb = (cm.arms[control::kRight].segment_mask >> pd.seg_b) & 1U;
    if ((la && rb) || (ra && lb)) best = std::min(best, pd.distance);
  }
  return best;
}

/// Publishes `sample` once and watches the controller's outputs for 1.5 s.
template <class W, class T>
void sendAndWatch(ControllerRun& run, W& writer, T& sample) {
  run.pump(1500ms, 100ms, [&](int k) {
    if (k == 0) writer.publish(sample);
  });
}

/// Waits for the controller's exit (expected 0) and takes what is left of its outputs.
bad_input::ExitSummary finishAndDrain(ControllerRun& run) {
  bad_input::ExitSummary summary;
  EXPECT_EQ(run.finish(summary, 30s), 0) << run.output;
  run.drain();
  return summary;
}

TEST(ControlStatusOnTheBus, TheTimeSeriesAndTheBusWriteOneNoPairValue) {
  EXPECT_EQ(reflex::control::kNoPairDistance, reflex::msg::NO_PAIR_DISTANCE);
}

TEST(ControlStatusOnTheBus, ARecordingAloneGivesFig13TheArmDistanceOfTheRecordedJointState) {
  const int domain = 210;
  const std::string file = tempPath("fig13.mcap");
  testing::ChildProcess recorder({bin("reflex_record"), "record", "-o", file, "--domain", std::to_string(domain),
                                  "--duration", "14", "-t", "reflex/joint_state", "-t", "reflex/control_status"},
                                 tempPath("recorder.log"));
  ASSERT_TRUE(recorder.started());
  const std::string csv = tempPath("fig13_log.csv");
  ControllerRun run(domain, 9.0, "fig13", {"--log", csv});
  ASSERT_TRUE(run.started());
  auto& targets = run.source->makeWriter<msg::HandTargets>();
  auto& hb = run.source->makeWriter<msg::Heartbeat>();
  ASSERT_TRUE(run.waitMatched(targets));
  msg::HandTargets cross = bad_input::crossingTargets();
  run.pump(7s, 100ms, [&](int k) {
    if (k == 0) targets.publish(cross);
    msg::Heartbeat h;
    h.module_name("bad_source");
    h.state(msg::STATE_RUNNING);
    hb.publish(h);
  });
  bad_input::ExitSummary summary;
  EXPECT_EQ(run.finish(summary, 30s), 0) << run.output;
  EXPECT_EQ(recorder.wait(30s), 0) << readFile(tempPath("recorder.log"));

  const control::Model model =
      control::loadModel(kUrdf, control::loadCollisionConfig(control::defaultCollisionConfigPath(kUrdf)));
  const control::ControllerModel cm = control::makeControllerModel(model, control::defaultControllerConfig());
  std::map<std::uint64_t, msg::JointState> joints;  // by header.seq
  std::vector<msg::ControlStatus> statuses;
  const std::unique_ptr<SampleReader> reader = openRecording(file);
  RecordEntry e;
  while (reader->next(e)) {
    if (e.topic == "reflex/joint_state") {
      msg::JointState js;
      ASSERT_TRUE(test::decodeEntry(e, js));
      joints[js.header().seq()] = js;
    } else if (e.topic == "reflex/control_status") {
      msg::ControlStatus st;
      ASSERT_TRUE(test::decodeEntry(e, st));
      statuses.push_back(st);
    }
  }
  ASSERT_GT(statuses.size(), 500u) << "several seconds of a 200 Hz stream";
  int compared = 0, close = 0;
  double min_recorded = 1e9;
  for (const msg::ControlStatus& st : statuses) {
    const auto it = joints.find(st.header().seq() - 1);  // the positions this cycle computed from
    if (it == joints.end()) continue;                    // best effort: a dropped sample
    const msg::JointState& js = it->second;
    Eigen::VectorXd q = Eigen::VectorXd::Zero(model.nq);
    ASSERT_EQ(js.names().size(), js.positions().size());
    for (std::size_t i = 0; i < js.names().size(); ++i) {
      const int qi = model.qIndex(js.names()[i]);
      ASSERT_GE(qi, 0) << js.names()[i];
      q[qi] = js.positions()[i];
    }
    const double expected = armToArm(model, cm, q);
    ASSERT_NEAR(st.arm_distance(), expected, 1e-9) << "status seq " << st.header().seq();
    ++compared;
    close += expected < 0.04;
    min_recorded = std::min(min_recorded, st.arm_distance());
  }
  std::printf("compared %d status samples with their joint state; closest arms %.2f mm (%d samples below d_a)\n",
              compared, min_recorded * 1e3, close);
  EXPECT_GT(compared, 500);
  EXPECT_GT(close, 50) << "the arms came within d_a of each other: the comparison covers Fig. 13's interesting part";
  EXPECT_GT(min_recorded, 0.005) << "and never below d_r";

  // The --log file: min_pair against the closest pair recomputed from the previous row's q.
  std::istringstream text(readFile(csv));
  std::string line;
  auto split = [](const std::string& l) {
    std::vector<std::string> f;
    std::stringstream ss(l);
    for (std::string x; std::getline(ss, x, ',');) f.push_back(x);
    return f;
  };
  ASSERT_TRUE(std::getline(text, line));
  const std::vector<std::string> header = split(line);
  auto col = [&](const std::string& name) {
    return static_cast<std::size_t>(std::find(header.begin(), header.end(), name) - header.begin());
  };
  const std::size_t c_pair = col("min_pair"), c_dist = col("min_distance");
  ASSERT_LT(c_pair, header.size());
  std::vector<std::size_t> c_q;
  for (int i = 0; i < model.nq; ++i) c_q.push_back(col("q_" + model.q_names[static_cast<std::size_t>(i)]));
  control::KinematicsData kin(model);
  control::DistanceData dist(model);
  std::vector<std::string> prev;
  int rows = 0;
  while (std::getline(text, line)) {
    const std::vector<std::string> row = split(line);
    ASSERT_EQ(row.size(), header.size());
    ASSERT_FALSE(row[c_pair].empty()) << "min_pair is filled in every row (row " << rows << ")";
    if (!prev.empty()) {
      Eigen::VectorXd q(model.nq);
      for (int i = 0; i < model.nq; ++i) q[i] = std::stod(prev[c_q[static_cast<std::size_t>(i)]]);
      ASSERT_TRUE(control::computeForwardKinematics(model, kin, q));
      control::computeSegmentDistances(model, kin, dist);
      double best = std::numeric_limits<double>::infinity(), named = best;
      for (std::size_t i = 0; i < dist.pairs.size(); ++i) {
        const control::PairDistance& pd = dist.pairs[i];
        if (!pd.active) continue;
        best = std::min(best, pd.distance);
        if (model.segments[static_cast<std::size_t>(pd.seg_a)].name + "|" +
                model.segments[static_cast<std::size_t>(pd.seg_b)].name ==
            row[c_pair])
          named = pd.distance;
      }
      ASSERT_NEAR(std::stod(row[c_dist]), best, 1e-6) << "row " << rows;
      ASSERT_NEAR(named, best, 1e-6) << "row " << rows << ": min_pair '" << row[c_pair] << "' is the closest pair";
    }
    prev = row;
    ++rows;
  }
  EXPECT_GT(rows, 1000) << "about 9 s of rows";
}

TEST(ControlStatusOnTheBus, RefusedInputsAreCountedPerTopicAndNamedInTheStatusAndTheExitLine) {
  ControllerRun run(211, 6.0, "status_refusals");
  ASSERT_TRUE(run.started());
  auto& targets = run.source->makeWriter<msg::HandTargets>();
  auto& walk = run.source->makeWriter<msg::WalkCommand>();
  ASSERT_TRUE(run.waitMatched(targets));
  ASSERT_TRUE(walk.waitForReaders(1, 15s));
  std::this_thread::sleep_for(300ms);
  msg::HandTargets far = bad_input::crossingTargets();
  far.right().position_base().x(std::nextafter(2.0, 3.0));  // |t| > 2 m = max_target_distance
  far.right().position_base().y(0.0);
  far.right().position_base().z(0.0);
  sendAndWatch(run, targets, far);
  msg::WalkCommand sideways;
  sideways.goal_x(1.0);
  sideways.goal_y(0.3);  // the walking pattern walks along x only: refused whole
  sideways.goal_yaw(0.0);
  sideways.speed(0.2);
  sideways.stop(false);
  sendAndWatch(run, walk, sideways);
  const bad_input::ExitSummary summary = finishAndDrain(run);
  ASSERT_FALSE(run.statuses.empty());
  const msg::ControlStatus& last = run.statuses.back();
  EXPECT_EQ(last.rejected_hand_targets(), 1u);
  EXPECT_EQ(last.rejected_walk_commands(), 1u);
  EXPECT_EQ(last.rejected_body_schema(), 0u);
  EXPECT_EQ(last.rejected_robot_states(), 0u);
  EXPECT_EQ(last.last_rejection(), "walk_goal_y_or_yaw_not_zero");
  // Between the two refusals the status named the hand target's cause.
  bool saw_hand_cause = false;
  for (const auto& s : run.statuses)
    saw_hand_cause |= s.rejected_hand_targets() == 1 && s.rejected_walk_commands() == 0 &&
                      s.last_rejection() == "hand_target_too_far";
  EXPECT_TRUE(saw_hand_cause);
  EXPECT_EQ(summary.rejected, 2) << run.output;
  EXPECT_NE(run.output.find("rejected by cause: hand_target_too_far 1, walk_goal_y_or_yaw_not_zero 1 "
                            "(last walk_goal_y_or_yaw_not_zero)"),
            std::string::npos)
      << run.output;
  // The heel did not move: the refused goal was not walked along x either.
  ASSERT_FALSE(run.joint_states.empty());
  const auto& names = run.joint_states.front().names();
  const auto heel = std::find(names.begin(), names.end(), "heel_x") - names.begin();
  ASSERT_LT(static_cast<std::size_t>(heel), names.size());
  for (const auto& js : run.joint_states)
    ASSERT_EQ(js.positions()[static_cast<std::size_t>(heel)],
              run.joint_states.front().positions()[static_cast<std::size_t>(heel)]);
}

TEST(ControlStatusOnTheBus, ClosestNamesAreClearedExactlyWhenTheArmHasNoPair) {
  // The shipped collision configuration plus: every pair of a right-arm segment with anything but a
  // left-arm segment excluded. Under right-arm priority the right arm ignores the left arm (Sec. 7.2)
  // and so has no pair at all.
  const control::Model model =
      control::loadModel(kUrdf, control::loadCollisionConfig(control::defaultCollisionConfigPath(kUrdf)));
  const control::ControllerModel cm = control::makeControllerModel(model, control::defaultControllerConfig());
  std::string yaml = readFile(control::defaultCollisionConfigPath(kUrdf));
  int excluded = 0;
  for (const control::SegmentPair& p : model.pairs) {
    if (model.segments[p.a].body_schema_slot || model.segments[p.b].body_schema_slot) continue;
    const auto in = [&](int arm, int s) { return ((cm.arms[arm].segment_mask >> s) & 1U) != 0; };
    const bool right_pair = in(control::kRight, p.a) || in(control::kRight, p.b);
    const bool arm_pair =
        (in(control::kRight, p.a) && in(control::kLeft, p.b)) || (in(control::kLeft, p.a) && in(control::kRight, p.b));
    if (!right_pair || arm_pair) continue;
    yaml += "  - [" + model.segments[p.a].name + ", " + model.segments[p.b].name + "]\n";
    ++excluded;
  }
  ASSERT_GT(excluded, 5);
  const std::string collision = tempPath("right_arm_only_with_left.collision.yaml");
  writeFile(collision, yaml);

  ControllerRun run(213, 7.0, "closest_cleared", {"--collision", collision});
  ASSERT_TRUE(run.started());
  auto& priority = run.source->makeWriter<msg::MotionPriority>();
  ASSERT_TRUE(run.waitMatched(priority));
  msg::MotionPriority p;
  const msg::ArmPriority phases[3] = {msg::PRIORITY_RIGHT_HIGHER, msg::PRIORITY_EQUAL, msg::PRIORITY_RIGHT_HIGHER};
  for (const msg::ArmPriority phase : phases) {
    p.priority(phase);
    sendAndWatch(run, priority, p);
  }
  finishAndDrain(run);
  // Phases seen in the stream, in order: named (a pair) and cleared (none).
  std::string phases_seen;
  for (const auto& s : run.statuses) {
    const msg::ArmStatus& r = s.right();
    const bool none = r.distance() == reflex::msg::NO_PAIR_DISTANCE;
    ASSERT_EQ(none, r.closest_segment_a().empty())
        << "seq " << s.header().seq() << " distance " << r.distance() << " names '" << r.closest_segment_a() << "'";
    ASSERT_EQ(none, r.closest_segment_b().empty()) << "seq " << s.header().seq();
    if (!none) {
      EXPECT_EQ(r.closest_segment_a().rfind("r_", 0), 0u) << "the arm's own segment first: " << r.closest_segment_a();
      EXPECT_EQ(r.closest_segment_b().rfind("l_", 0), 0u) << r.closest_segment_b();
    }
    const char c = none ? 'c' : 'n';
    if (phases_seen.empty() || phases_seen.back() != c) phases_seen += c;
  }
  EXPECT_NE(phases_seen.find("ncnc"), std::string::npos)
      << "named (equal priority, the default), cleared (right arm higher), named, cleared again (seen: " << phases_seen
      << ")";
  // The left arm always has pairs (torso, legs): always named, the left arm's segment first.
  for (const auto& s : run.statuses)
    ASSERT_EQ(s.left().closest_segment_a().rfind("l_", 0), 0u) << s.left().closest_segment_a();
}

}  // namespace
}  // namespace reflex::record
