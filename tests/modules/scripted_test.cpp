// Scripted-target module: events at their times (within one step period), loops, CSV = YAML,
// claims from the timeline, stop removes the targets.
#include "modules_test_support.hpp"

#include <reflex/modules/scripted.hpp>

#include <fstream>

namespace reflex::modules {
namespace {

using testing::at;
using testing::TestHost;

const char* kInline =
    "modules:\n"
    "  - name: s\n"
    "    type: scripted\n"
    "    config:\n"
    "      step_period: 0.02\n"
    "      timeline:\n"
    "        - {t: 0.0, right: [0.35, -0.15, 0.95], priority: right}\n"
    "        - {t: 1.0, left: [0.35, 0.15, 0.95]}\n"
    "        - {t: 2.5, right: [0.32, 0.10, 1.00], left: none, priority: equal}\n";

struct Change {
  double t;
  Hand hand;
  HandTarget target;
};

std::vector<Change> run(TestHost& h, double until) {
  std::vector<Change> out;
  h->start(at(0.0));
  HandTarget last[2];
  auto record = [&](double t) {
    for (Hand hd : kBothHands) {
      if (h->hand(hd) != last[handIndex(hd)]) {
        last[handIndex(hd)] = h->hand(hd);
        out.push_back({t, hd, h->hand(hd)});
      }
    }
  };
  record(0.0);
  for (int k = 1; k * 0.01 <= until + 1e-9; ++k) {
    h->tick(at(k * 0.01));
    record(k * 0.01);
  }
  return out;
}

TEST(Scripted, EventsHappenAtTheirTimes) {
  TestHost h(kInline);
  EXPECT_TRUE(h->claims().hands[0] && h->claims().hands[1] && h->claims().priority);
  const auto changes = run(h, 4.0);
  ASSERT_EQ(changes.size(), 4u);
  EXPECT_EQ(changes[0].hand, Hand::kRight);
  EXPECT_DOUBLE_EQ(changes[0].t, 0.0);
  EXPECT_EQ(changes[0].target.p_B, Eigen::Vector3d(0.35, -0.15, 0.95));
  EXPECT_EQ(changes[1].hand, Hand::kLeft);
  EXPECT_GE(changes[1].t, 1.0 - 1e-9);
  EXPECT_LE(changes[1].t, 1.0 + 0.02 + 1e-9);
  EXPECT_GE(changes[2].t, 2.5 - 1e-9);
  EXPECT_LE(changes[2].t, 2.5 + 0.02 + 1e-9);
  EXPECT_FALSE(h->hand(Hand::kLeft).given);
  EXPECT_EQ(h->hand(Hand::kRight).p_B, Eigen::Vector3d(0.32, 0.10, 1.00));
  EXPECT_EQ(h->priority(), ArmPriority::kEqual);
  ASSERT_GE(h.sink.priorities.size(), 2u);
  EXPECT_EQ(h.sink.priorities[h.sink.priorities.size() - 2], ArmPriority::kRightHigher);
}

TEST(Scripted, CsvAndYamlTimelinesGiveTheSameOutputs) {
  const std::string csv = ::testing::TempDir() + "scripted_same.csv";
  std::ofstream(csv) << "t,hand,x,y,z\n0,right,0.35,-0.15,0.95\n0,priority,right,,\n1,left,0.35,0.15,0.95\n"
                        "2.5,right,0.32,0.10,1.00\n2.5,left,none,,\n2.5,priority,equal,,\n";
  TestHost a(kInline);
  TestHost b("modules:\n  - {name: s, type: scripted, config: {step_period: 0.02, file: " + csv + "}}\n");
  run(a, 4.0);
  run(b, 4.0);
  ASSERT_EQ(a.sink.hands.size(), b.sink.hands.size());
  for (std::size_t i = 0; i < a.sink.hands.size(); ++i) {
    EXPECT_EQ(a.sink.hands[i].left, b.sink.hands[i].left);
    EXPECT_EQ(a.sink.hands[i].right, b.sink.hands[i].right);
  }
  EXPECT_EQ(a.sink.priorities, b.sink.priorities);
}

TEST(Scripted, LoopsRestartTheTimeline) {
  TestHost h(
      "modules:\n  - {name: s, type: scripted, config: {loop_period: 2.0, timeline: "
      "[{t: 0, left: [0.3, 0.2, 1.0]}, {t: 1, left: none}]}}\n");
  const auto changes = run(h, 5.5);
  // given at 0, none at 1, given at 2, none at 3, given at 4, none at 5.
  ASSERT_EQ(changes.size(), 6u);
  for (std::size_t i = 0; i < changes.size(); ++i) {
    EXPECT_EQ(changes[i].target.given, i % 2 == 0) << i;
    EXPECT_NEAR(changes[i].t, static_cast<double>(i), 0.021) << i;
  }
  EXPECT_FALSE(h->claims().hands[1]);  // the right hand is not in the timeline: not claimed
  EXPECT_FALSE(h->claims().priority);
}

TEST(Scripted, StopRemovesItsTargets) {
  TestHost h(kInline);
  run(h, 1.5);
  ASSERT_TRUE(h->hand(Hand::kLeft).given && h->hand(Hand::kRight).given);
  h->stop(at(2.0));
  EXPECT_FALSE(h.sink.hands.back().left.given);
  EXPECT_FALSE(h.sink.hands.back().right.given);
  EXPECT_EQ(h.sink.priorities.back(), ArmPriority::kEqual);
  EXPECT_EQ(h->stats().forced_cleanups, 0u);
}

TEST(Scripted, ShippedTimelineIsTheCsvFile) {
  // The shipped scripted configuration reads bringup/behavior/scripted_timeline.csv.
  const auto events = readTimelineCsv(std::string(REFLEX_SOURCE_DIR) + "/bringup/behavior/scripted_timeline.csv");
  ASSERT_FALSE(events.empty());
  for (std::size_t i = 1; i < events.size(); ++i) EXPECT_GE(events[i].t, events[i - 1].t);
}

}  // namespace
}  // namespace reflex::modules
