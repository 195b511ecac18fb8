// BehaviorHost with fake inputs: input validation (writer not a configured object source, NaN, future
// stamps, unknown frame_id, unknown objects, range, duplicates: rejected, counted, never forwarded), joint states, output ownership, merging of
// several modules, --module selection, the clean-up guarantee at stop, and the guard around every call
// into a module (marked while it runs; whatever it throws becomes a ModuleError naming the call).
#include "modules_test_support.hpp"

#include <reflex/modules/module_call.hpp>
#include <reflex/modules/pointing.hpp>

#include <cmath>
#include <limits>

namespace reflex::modules {
namespace {

using testing::at;
using testing::frameAt;
using testing::object;
using testing::TestHost;

// Records the frames it is given. Optional misbehaviour for the host's guarantees.
class ProbeModule final : public Module {
 public:
  static std::vector<ObjectsFrame>* frames;
  static int joint_callbacks;
  static std::string call_mark;  // moduleCallInProgress().what seen inside the last onObjects
  explicit ProbeModule(std::string name) : Module(std::move(name)) {}
  void configure(const ConfigNode& c, const RobotState&) override {
    c.rejectUnknown({"misbehave"});
    misbehave_ = c.choice("misbehave", "no", {"no", "unclaimed_hand", "leave_segment", "nan_target", "throw_int"});
  }
  Claims claims() const override {
    Claims c;
    c.objects = true;
    c.hands[1] = misbehave_ == "nan_target";
    if (misbehave_ == "leave_segment") c.segments = {"probe_ball"};
    return c;
  }
  void start(ModuleContext& ctx) override {
    if (misbehave_ == "leave_segment") {
      SegmentSpec s;
      s.name = "probe_ball";
      s.parent_link = "r_hand";
      s.capsule = false;
      s.radius = 0.05;
      ctx.attachSegment(s);
    }
  }
  void onObjects(const ObjectsFrame& f, ModuleContext& ctx) override {
    frames->push_back(f);
    const ModuleCallInProgress call = moduleCallInProgress();
    call_mark = call.what ? call.what : "";
    if (misbehave_ == "throw_int") throw 42;
    if (misbehave_ == "unclaimed_hand") ctx.setHand(Hand::kLeft, HandTarget::at({0.3, 0.0, 1.0}));
    if (misbehave_ == "nan_target")
      ctx.setHand(Hand::kRight, HandTarget::at({std::numeric_limits<double>::quiet_NaN(), 0.0, 1.0}));
  }
  void onJointState(ModuleContext&) override { ++joint_callbacks; }
  void stop(ModuleContext&) override {}  // removes nothing on purpose when misbehaving

 private:
  std::string misbehave_;
};
std::vector<ObjectsFrame>* ProbeModule::frames = nullptr;
int ProbeModule::joint_callbacks = 0;
std::string ProbeModule::call_mark;

ModuleRegistry probeRegistry() {
  ModuleRegistry r = builtinRegistry();
  r.add("probe", "test probe", [](const std::string& n) { return std::make_unique<ProbeModule>(n); });
  return r;
}

class HostTest : public ::testing::Test {
 protected:
  void SetUp() override {
    ProbeModule::frames = &frames_;
    ProbeModule::joint_callbacks = 0;
  }
  std::vector<ObjectsFrame> frames_;
};

const char* kProbe =
    "inputs: {known_objects: [cup, can], future_tolerance: 0.5, max_range: 3.0}\n"
    "modules:\n"
    "  - {name: probe, type: probe}\n";

TEST_F(HostTest, NonFiniteObjectsAreRejectedCountedAndNotForwarded) {
  TestHost h(kProbe, probeRegistry());
  h->start(at(0.0));
  const double nan = std::numeric_limits<double>::quiet_NaN(), inf = std::numeric_limits<double>::infinity();
  h->onObjects(frameAt(0.0, {object("cup", {nan, 0.0, 1.0}), object("can", {0.4, inf, 1.0}),
                             object("cup", {0.4, 0.1, 1.0}, nan), object("can", {0.4, 0.1, 1.0}, 1.5),
                             object("can", {0.4, 0.1, 1.0}, -0.1), object("cup", {0.45, -0.1, 0.95})}),
               at(0.0));
  ASSERT_EQ(frames_.size(), 1u);
  ASSERT_EQ(frames_[0].objects.size(), 1u);
  EXPECT_EQ(frames_[0].objects[0].name, "cup");
  EXPECT_EQ(frames_[0].objects[0].p_B, Eigen::Vector3d(0.45, -0.1, 0.95));
  EXPECT_EQ(h->stats().objects_rejected_invalid, 5u);
  EXPECT_EQ(h->stats().objects_accepted, 1u);
}

TEST_F(HostTest, FramesFromTheFutureAreRejectedWhole) {
  TestHost h(kProbe, probeRegistry());
  h->start(at(0.0));
  ObjectsFrame ahead = frameAt(1.0, {object("cup", {0.45, -0.1, 0.95})});  // stamped 1 s ahead of now
  h->onObjects(ahead, at(0.0));
  ObjectsFrame capture_ahead = frameAt(0.0, {object("cup", {0.45, -0.1, 0.95})});
  capture_ahead.capture_stamp_ns = at(0.8).wall_ns;
  h->onObjects(capture_ahead, at(0.0));
  EXPECT_TRUE(frames_.empty());
  EXPECT_EQ(h->stats().frames_rejected_future, 2u);
  h->onObjects(frameAt(0.4, {object("cup", {0.45, -0.1, 0.95})}), at(0.0));  // within the tolerance
  EXPECT_EQ(frames_.size(), 1u);
  EXPECT_EQ(h->stats().frames_received, 3u);
}

// ObjectTargets.frame_id: positions are only used when the sender says they are in the base frame
// (default name "base_link", what reflex_vision writes). Any other name, "" and a different case
// are rejected whole, counted and logged with the bad name; the accepted list is configurable.
TEST_F(HostTest, FramesInAnUnknownFrameAreRejectedWhole) {
  TestHost h(kProbe, probeRegistry());
  h->start(at(0.0));
  for (const char* bad : {"odom", "", "head_camera", "BASE_LINK", "base_link "}) {
    ObjectsFrame f = frameAt(0.0, {object("cup", {0.45, -0.1, 0.95})});
    f.frame_id = bad;
    h->onObjects(f, at(0.0));
  }
  EXPECT_TRUE(frames_.empty()) << "no frame in an unknown frame reached the module";
  EXPECT_EQ(h->stats().frames_rejected_frame, 5u);
  EXPECT_EQ(h->stats().objects_accepted, 0u);
  EXPECT_EQ(h->stats().frames_received, 5u);
  ASSERT_FALSE(h.log.empty());
  bool named = false;
  for (const auto& line : h.log) named |= line.find("unknown frame_id 'odom'") != std::string::npos;
  EXPECT_TRUE(named) << "the log names the bad frame";
  ObjectsFrame good = frameAt(0.0, {object("cup", {0.45, -0.1, 0.95})});
  good.frame_id = "base_link";
  h->onObjects(good, at(0.0));
  ASSERT_EQ(frames_.size(), 1u);
  EXPECT_EQ(frames_[0].objects.size(), 1u);
  EXPECT_EQ(h->stats().frames_rejected_frame, 5u);

  // Configured: only "torso_frame" is B; "base_link" is then unknown.
  frames_.clear();
  TestHost t("inputs: {frames: [torso_frame]}\nmodules:\n  - {name: probe, type: probe}\n", probeRegistry());
  t->start(at(0.0));
  ObjectsFrame torso = frameAt(0.0, {object("cup", {0.45, -0.1, 0.95})});
  torso.frame_id = "torso_frame";
  t->onObjects(torso, at(0.0));
  t->onObjects(good, at(0.0));
  EXPECT_EQ(frames_.size(), 1u);
  EXPECT_EQ(t->stats().frames_rejected_frame, 1u);
  try {
    TestHost empty("inputs: {frames: []}\nmodules:\n  - {name: probe, type: probe}\n", probeRegistry());
    FAIL() << "expected ConfigError";
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("frames"), std::string::npos) << e.what();
  }
}

// Object targets are accepted only from the identities inputs.object_sources names
// (default: vision), judged by ObjectsFrame::source — the identity of the participant that WROTE the
// frame (filled by the DDS adapter from the writer's GUID, authenticated under DDS-Security), never
// by a name inside the message. Every other writer ("player": a replayed recording; another module;
// an unknown participant "": not yet discovered; near-misses in case or spacing) is rejected whole,
// counted, logged naming the writer, and never reaches a module. Naming the player accepts it (the
// replay set-up) and then vision is refused.
TEST_F(HostTest, ObjectsAreAcceptedOnlyFromTheConfiguredWriters) {
  TestHost h(kProbe, probeRegistry());
  h->start(at(0.0));
  for (const char* bad :
       {"player", "", "behavior", "recorder", "Vision", "vision ", "reflex.vision", "CN=reflex.vision"}) {
    ObjectsFrame f = frameAt(0.0, {object("cup", {0.45, -0.1, 0.95})});
    f.source = bad;
    h->onObjects(f, at(0.0));
  }
  EXPECT_TRUE(frames_.empty()) << "no frame of an unnamed writer reached the module";
  EXPECT_EQ(h->stats().frames_rejected_source, 8u);
  EXPECT_EQ(h->stats().objects_accepted, 0u);
  EXPECT_EQ(h->stats().frames_received, 8u);
  bool named = false, unknown = false;
  for (const auto& line : h.log) {
    named |= line.find("written by 'player', not one of inputs.object_sources ('vision')") != std::string::npos;
    unknown |= line.find("written by an unknown participant") != std::string::npos;
  }
  EXPECT_TRUE(named && unknown) << "the log names the writer";
  ObjectsFrame good = frameAt(0.0, {object("cup", {0.45, -0.1, 0.95})});
  ASSERT_EQ(good.source, "vision");
  h->onObjects(good, at(0.0));
  ASSERT_EQ(frames_.size(), 1u);
  EXPECT_EQ(h->stats().frames_rejected_source, 8u);

  // A replay configuration: the player is named, vision is not.
  frames_.clear();
  TestHost replay("inputs: {object_sources: [player]}\nmodules:\n  - {name: probe, type: probe}\n", probeRegistry());
  replay->start(at(0.0));
  ObjectsFrame played = good;
  played.source = "player";
  replay->onObjects(played, at(0.0));
  replay->onObjects(good, at(0.0));
  ASSERT_EQ(frames_.size(), 1u);
  EXPECT_EQ(frames_[0].source, "player");
  EXPECT_EQ(replay->stats().frames_rejected_source, 1u);

  for (const char* yaml : {"inputs: {object_sources: []}\n", "inputs: {object_sources: ['']}\n"}) {
    try {
      TestHost bad(std::string(yaml) + "modules:\n  - {name: probe, type: probe}\n", probeRegistry());
      ADD_FAILURE() << "expected ConfigError for " << yaml;
    } catch (const ConfigError& e) {
      EXPECT_NE(std::string(e.what()).find("object_sources"), std::string::npos) << e.what();
    }
  }
}

TEST_F(HostTest, UnknownOutOfRangeAndDuplicateObjectsAreRejected) {
  TestHost h(kProbe, probeRegistry());
  h->start(at(0.0));
  h->onObjects(
      frameAt(0.0, {object("", {0.4, 0.0, 1.0}), object("ghost", {0.4, 0.0, 1.0}), object("cup", {3.5, 0.0, 0.0}),
                    object("can", {0.4, 0.1, 1.0}), object("can", {0.4, 0.2, 1.0})}),
      at(0.0));
  ASSERT_EQ(frames_.size(), 1u);
  ASSERT_EQ(frames_[0].objects.size(), 1u);
  EXPECT_EQ(frames_[0].objects[0].p_B, Eigen::Vector3d(0.4, 0.1, 1.0));
  EXPECT_EQ(h->stats().objects_rejected_unknown, 2u);
  EXPECT_EQ(h->stats().objects_rejected_range, 1u);
  EXPECT_EQ(h->stats().objects_rejected_duplicate, 1u);
  EXPECT_EQ(h->stats().rejectedObjects(), 4u);
}

TEST_F(HostTest, WithoutAKnownListAnyNamedObjectIsKnown) {
  TestHost h("modules:\n  - {name: probe, type: probe}\n", probeRegistry());
  h->start(at(0.0));
  h->onObjects(frameAt(0.0, {object("ghost", {0.4, 0.0, 1.0}), object("", {0.4, 0.0, 1.0})}), at(0.0));
  ASSERT_EQ(frames_[0].objects.size(), 1u);
  EXPECT_EQ(frames_[0].objects[0].name, "ghost");
  EXPECT_EQ(h->stats().objects_rejected_unknown, 1u);
}

TEST_F(HostTest, BadSamplesNeverReachTheHandTargets) {
  TestHost h("inputs: {known_objects: [cup, can]}\nmodules:\n  - {name: pointing, type: pointing}\n");
  h->start(at(0.0));
  const double nan = std::numeric_limits<double>::quiet_NaN();
  for (int k = 0; k < 30; ++k) {
    const double t = 0.1 * k;
    h->onObjects(frameAt(t, {object("cup", {nan, nan, nan}), object("ghost", {0.4, 0.0, 1.0}),
                             object("can", {0.46, 0.13, 0.96})}),
                 at(t));
    h->onObjects(frameAt(t + 5.0, {object("cup", {0.3, 0.3, 0.5})}), at(t));  // future
  }
  for (const auto& hs : h.sink.hands) {
    for (const HandTarget* t : {&hs.left, &hs.right}) {
      EXPECT_TRUE(t->p_B.allFinite());
      EXPECT_NE(t->object, "ghost");
      EXPECT_NE(t->object, "cup");  // only ever seen as NaN or from the future
    }
  }
  EXPECT_EQ(h->hand(Hand::kLeft).object, "can");
  EXPECT_EQ(h->stats().objects_rejected_invalid, 30u);
  EXPECT_EQ(h->stats().objects_rejected_unknown, 30u);
  EXPECT_EQ(h->stats().frames_rejected_future, 30u);
}

TEST_F(HostTest, JointStatesMoveTheRobotAndBadOnesAreRejected) {
  TestHost h(kProbe, probeRegistry());
  h->start(at(0.0));
  const Eigen::Vector3d s0 = h->robot().shoulder_B(Hand::kRight);
  JointStateSample js;
  js.source = "controller";  // the default joint_state_sources
  js.names = {"heel_x", "no_such_joint"};
  js.positions = {0.5, 3.0};
  h->onJointState(js, at(0.0));
  EXPECT_NEAR((h->robot().shoulder_B(Hand::kRight) - (s0 + Eigen::Vector3d(0.5, 0.0, 0.0))).norm(), 0.0, 1e-12);
  EXPECT_TRUE(h->robot().fromJointState());
  JointStateSample bad = js;
  bad.positions = {std::numeric_limits<double>::quiet_NaN(), 0.0};
  h->onJointState(bad, at(0.01));
  JointStateSample mismatch = js;
  mismatch.positions = {0.1};
  h->onJointState(mismatch, at(0.02));
  EXPECT_EQ(h->stats().joint_states_rejected, 2u);
  EXPECT_NEAR(h->robot().shoulder_B(Hand::kRight).x(), s0.x() + 0.5, 1e-12);  // kept
  // Joint states only from the configured writers (default: the controller).
  for (const char* bad_writer : {"player", "", "behavior", "Controller"}) {
    JointStateSample forged = js;
    forged.source = bad_writer;
    forged.positions = {1.5, 0.0};
    h->onJointState(forged, at(0.03));
  }
  EXPECT_EQ(h->stats().joint_states_rejected_source, 4u);
  EXPECT_NEAR(h->robot().shoulder_B(Hand::kRight).x(), s0.x() + 0.5, 1e-12) << "a forged joint state moved the robot";
  // Modules hear of joint states at most every joint_state_period (0.1 s).
  for (int k = 0; k < 100; ++k) h->onJointState(js, at(0.2 + 0.005 * k));  // 0.5 s at 200 Hz
  EXPECT_GE(ProbeModule::joint_callbacks, 5);
  EXPECT_LE(ProbeModule::joint_callbacks, 7);
}

TEST_F(HostTest, TwoModulesClaimingOneOutputAreRefused) {
  try {
    TestHost h(
        "modules:\n  - {name: a, type: pointing}\n  - {name: b, type: scripted, config: {timeline: [{t: 0, right: "
        "none}]}}\n");
    FAIL() << "expected ConfigError";
  } catch (const ConfigError& e) {
    const std::string m = e.what();
    EXPECT_NE(m.find("'a' and 'b' both write the right hand target"), std::string::npos) << m;
  }
}

TEST_F(HostTest, ModulesOfOneProcessMergeIntoOneHandTargets) {
  TestHost h(
      "inputs: {known_objects: [cup]}\n"
      "modules:\n"
      "  - {name: point_right, type: pointing, config: {hands: [right], priority_rule: none}}\n"
      "  - {name: left_script, type: scripted, config: {timeline: [{t: 0, left: [0.3, 0.2, 1.0]}]}}\n");
  h->start(at(0.0));
  h->onObjects(frameAt(0.0, {object("cup", {0.46, -0.13, 0.95})}), at(0.0));
  const auto& last = h.sink.hands.back();
  EXPECT_TRUE(last.left.given);
  EXPECT_EQ(last.left.p_B, Eigen::Vector3d(0.3, 0.2, 1.0));
  EXPECT_EQ(last.right.object, "cup");
}

TEST_F(HostTest, WritingAnUnclaimedOutputIsAProgrammingError) {
  TestHost h("modules:\n  - {name: probe, type: probe, config: {misbehave: unclaimed_hand}}\n", probeRegistry());
  h->start(at(0.0));
  // The context's std::logic_error, named by the host's guard around the module's call.
  try {
    h->onObjects(frameAt(0.0, {object("cup", {0.4, 0.0, 1.0})}), at(0.0));
    FAIL() << "expected ModuleError";
  } catch (const ModuleError& e) {
    EXPECT_EQ(std::string(e.what()),
              "onObjects() of module 'probe' (type probe, built in) threw: module 'probe' wrote the left hand "
              "without claiming it");
  }
}

TEST_F(HostTest, EveryCallIsMarkedAndWhateverItThrowsIsAModuleErrorNamingCallModuleAndPlugin) {
  const ModuleRegistry registry = probeRegistry();
  HostConfig config = parseHostConfig(
      ConfigNode::loadString("modules:\n  - {name: p1, type: probe, config: {misbehave: throw_int}}\n", "test.yaml"),
      registry);
  config.type_plugins["probe"] = "/plugins/libprobe.so";
  testing::RecordingSink sink;
  BehaviorHost host(config, registry, sink, [](const std::string&) {});
  EXPECT_EQ(moduleCallInProgress().what, nullptr);
  host.start(at(0.0));
  try {
    host.onObjects(frameAt(0.0, {object("cup", {0.4, 0.0, 1.0})}), at(0.0));
    FAIL() << "expected ModuleError";
  } catch (const ModuleError& e) {
    EXPECT_EQ(std::string(e.what()),
              "onObjects() of module 'p1' (type probe, plugin /plugins/libprobe.so) threw something that is not a "
              "std::exception (an int, a string literal, ...)");
  }
  EXPECT_EQ(ProbeModule::call_mark, "onObjects() of module 'p1' (type probe, plugin /plugins/libprobe.so)");
  EXPECT_EQ(moduleCallInProgress().what, nullptr) << "the mark outlived the call that threw";
}

TEST_F(HostTest, NonFiniteHandTargetFromAModuleBecomesNoTarget) {
  TestHost h("modules:\n  - {name: probe, type: probe, config: {misbehave: nan_target}}\n", probeRegistry());
  h->start(at(0.0));
  h->onObjects(frameAt(0.0, {object("cup", {0.4, 0.0, 1.0})}), at(0.0));
  EXPECT_FALSE(h->hand(Hand::kRight).given);
  EXPECT_EQ(h->stats().outputs_rejected, 1u);
}

TEST_F(HostTest, WhatAModuleLeavesBehindIsRemovedAtStopAndReported) {
  TestHost h("modules:\n  - {name: probe, type: probe, config: {misbehave: leave_segment}}\n", probeRegistry());
  h->start(at(0.0));
  ASSERT_EQ(h->segments().count("probe_ball"), 1u);
  h->stop(at(1.0));
  EXPECT_EQ(h->segments().count("probe_ball"), 0u);
  ASSERT_FALSE(h.sink.detached.empty());
  EXPECT_EQ(h.sink.detached.back(), "probe_ball");
  EXPECT_EQ(h->stats().forced_cleanups, 1u);
}

TEST_F(HostTest, OnlyModuleRunsOneModuleUnderItsOwnName) {
  const std::string yaml =
      "modules:\n"
      "  - {name: pointing, type: pointing}\n"
      "  - {name: eyes, type: occlusion, config: {point: [0.5, 0.0, 0.9]}}\n";
  TestHost h(yaml, builtinRegistry(), "eyes");
  EXPECT_EQ(h->moduleNames(), std::vector<std::string>{"eyes"});
  EXPECT_EQ(h->processName(), "eyes");
  EXPECT_FALSE(h->claims().hands[0] || h->claims().hands[1]);
  try {
    TestHost bad(yaml, builtinRegistry(), "nosuch");
    FAIL() << "expected ConfigError";
  } catch (const ConfigError& e) {
    const std::string m = e.what();
    EXPECT_NE(m.find("no module named 'nosuch'"), std::string::npos) << m;
    EXPECT_NE(m.find("pointing, eyes"), std::string::npos) << m;
  }
}

TEST_F(HostTest, StartTwiceIsRefused) {
  TestHost h(kProbe, probeRegistry());
  h->start(at(0.0));
  EXPECT_THROW(h->start(at(0.1)), std::logic_error);
}

}  // namespace
}  // namespace reflex::modules
