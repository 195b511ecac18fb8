// Bad input at run time against the real reflex_controller process: NaN / Inf /
// huge values in every numeric field of every message it reads, unknown links and enumerators,
// old / future / duplicate stamps and sequence numbers, and floods. Asserted: the sample is rejected
// and counted in the exit summary ("targets N (rejected M)") where the controller rejects it, the
// loop keeps 200 Hz, every pair stays above d_r, and no non-finite value is ever published.
// Domains 101..105, 107.
#include "controller_run.hpp"

#include <csignal>
#include <cstdio>
#include <limits>
#include <random>

namespace reflex::bad_input {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr double kInf = std::numeric_limits<double>::infinity();

// Each of the six target coordinates gets each bad value once, the other hand staying valid:
// 6 fields x 6 values = 36 rejected hand targets.
TEST(ControllerBadInput, NonFiniteHugeAndFarHandTargetsAreRejectedAndCounted) {
  ControllerRun run(101, 9.0, "hand_targets");
  ASSERT_TRUE(run.started());
  auto& targets = run.source->makeWriter<msg::HandTargets>();
  auto& hb = run.source->makeWriter<msg::Heartbeat>();
  ASSERT_TRUE(run.waitMatched(targets));

  const double bad_values[] = {kNaN, kInf, -kInf, 1e300, -1e300, 2.5 /* beyond max_target_distance 2 m */};
  std::vector<msg::HandTargets> samples;
  for (int field = 0; field < 6; ++field) {
    for (double v : bad_values) {
      msg::HandTargets t = reachable();
      t.left().status(msg::TARGET_GIVEN);  // left: a valid target
      t.left().position_base().x(0.35);
      t.left().position_base().y(0.20);
      t.left().position_base().z(0.95);
      msg::Vector3& p = field < 3 ? t.left().position_base() : t.right().position_base();
      if (field % 3 == 0) p.x(v);
      if (field % 3 == 1) p.y(v);
      if (field % 3 == 2) p.z(v);
      samples.push_back(t);
    }
  }
  // 1 s of valid targets, then the bad samples one at a time (the controller takes the newest each
  // 5 ms cycle; the next is sent once it counted the last), then valid ones again (70 ms apart:
  // none is overwritten unread).
  int sent = 0;
  run.pump(1000ms, 70ms, [&](int) {
    msg::HandTargets t = reachable();
    targets.publish(t);
    msg::Heartbeat h = heartbeat("bad_source");
    hb.publish(h);
    ++sent;
  });
  // The bad ones in lockstep: each once the controller has counted the one before (its status).
  const auto rejected = [](const msg::ControlStatus& st) { return st.rejected_hand_targets(); };
  for (std::size_t k = 0; k < samples.size(); ++k) {
    targets.publish(samples[k]);
    ++sent;
    if (k % 5 == 0) {
      msg::Heartbeat h = heartbeat("bad_source");
      hb.publish(h);
    }
    ASSERT_TRUE(run.waitStatusCount(rejected, k + 1)) << "bad sample " << k << " was not counted within 3 s";
  }
  run.pump(1500ms, 70ms, [&](int) {
    msg::HandTargets t = reachable();
    targets.publish(t);
    msg::Heartbeat h = heartbeat("bad_source");
    hb.publish(h);
    ++sent;
  });
  run.expectSafeAndFinite();

  ExitSummary s;
  ASSERT_EQ(run.finish(s), 0) << run.output;
  ASSERT_TRUE(s.found) << run.output;
  EXPECT_EQ(s.targets, sent) << "every sample was taken";
  EXPECT_EQ(s.rejected, 36) << run.output;
  EXPECT_EQ(s.estops, 0);
}

// Body schema: non-finite / non-positive radius, non-finite endpoints, unknown and empty parent
// links are rejected and counted (one stderr line each); walk commands with a non-finite goal or
// speed, or a speed <= 0, likewise. An unknown enumerator (priority 42, target status 7, segment
// shape 9) is treated as the safe default (equal priority, no target, capsule).
TEST(ControllerBadInput, BadBodySchemaWalkAndEnumeratorsAreRejectedOrDefaulted) {
  ControllerRun run(102, 7.0, "schema_walk");
  ASSERT_TRUE(run.started());
  auto& schema = run.source->makeWriter<msg::BodySchemaChange>();
  auto& walk = run.source->makeWriter<msg::WalkCommand>();
  auto& prio = run.source->makeWriter<msg::MotionPriority>();
  auto& targets = run.source->makeWriter<msg::HandTargets>();
  ASSERT_TRUE(run.waitMatched(schema));
  ASSERT_TRUE(walk.waitForReaders(1, 10s) && prio.waitForReaders(1, 10s) && targets.waitForReaders(1, 10s));

  auto segment = [](const std::string& name) {
    msg::BodySchemaChange c;
    c.segment_name(name);
    c.operation(msg::SCHEMA_ATTACH);
    c.parent_link("l_hand");
    c.shape(msg::SHAPE_CAPSULE);
    c.point_a().x(0.0);
    c.point_b().z(-0.1);
    c.radius(0.02);
    c.enabled(true);
    return c;
  };
  std::vector<msg::BodySchemaChange> bad;
  for (double r : {kNaN, kInf, -0.01, 0.0}) {
    bad.push_back(segment("bad_radius_" + std::to_string(bad.size())));
    bad.back().radius(r);
  }
  bad.push_back(segment("nan_a"));
  bad.back().point_a().y(kNaN);
  bad.push_back(segment("inf_b"));
  bad.back().point_b().x(-kInf);
  bad.push_back(segment("unknown_link"));
  bad.back().parent_link("no_such_link");
  bad.push_back(segment("empty_link"));
  bad.back().parent_link("");
  for (auto& c : bad) schema.publish(c);
  // A valid "stop" first: the walk reader is matched on both sides before the bad commands come
  // (a reliable keep-last-1 writer replaces a sample the reader never acknowledged).
  msg::WalkCommand stop;
  stop.stop(true);
  walk.publish(stop);
  run.pump(500ms, 50ms, [](int) {});

  std::vector<msg::WalkCommand> bad_walk;
  for (double g : {kNaN, kInf}) {
    msg::WalkCommand w;
    w.goal_x(g);
    w.speed(0.2);
    bad_walk.push_back(w);
  }
  for (double v : {kNaN, kInf, -0.2, 0.0}) {
    msg::WalkCommand w;
    w.goal_x(0.0);
    w.speed(v);
    bad_walk.push_back(w);
  }
  run.pumpCount(static_cast<int>(bad_walk.size()) + 2, 80ms, [&](int k) {
    if (k < static_cast<int>(bad_walk.size())) walk.publish(bad_walk[static_cast<std::size_t>(k)]);
    if (k == 0) {
      msg::MotionPriority p;
      p.priority(static_cast<msg::ArmPriority>(42));
      prio.publish(p);
    }
    if (k == 1) {
      msg::HandTargets t = reachable();
      t.left().status(static_cast<msg::TargetStatus>(7));
      t.left().position_base().x(kNaN);  // ignored: status 7 is not TARGET_GIVEN
      targets.publish(t);
    }
  });
  run.pump(1000ms, 50ms, [](int) {});
  run.expectSafeAndFinite();

  ExitSummary s;
  ASSERT_EQ(run.finish(s), 0) << run.output;
  ASSERT_TRUE(s.found) << run.output;
  EXPECT_EQ(s.rejected, static_cast<long>(bad.size() + bad_walk.size())) << run.output;
  for (const char* name : {"bad_radius_0", "nan_a", "inf_b", "unknown_link", "empty_link"}) {
    EXPECT_NE(run.output.find(std::string("body-schema segment '") + name + "' rejected"), std::string::npos) << name;
  }
  EXPECT_EQ(s.estops, 0);
  EXPECT_EQ(s.targets, 1);
}

// Header fields are the sender's business: the controller judges freshness by ARRIVAL time (its
// own monotonic clock), so a stamp from 1970, from the far future, INT64 extremes, seq 0, repeated
// or decreasing sequence numbers are all taken (never rejected, never a crash) — and, the safety
// point, a future stamp cannot keep a silent source alive: after the source stops the hands
// retract within --input-timeout.
TEST(ControllerBadInput, OldFutureAndDuplicateStampsAreHarmlessAndCannotKeepASilentSourceAlive) {
  ControllerRun run(103, 7.0, "stamps");
  ASSERT_TRUE(run.started());
  auto& targets = run.source->makeWriter<msg::HandTargets>();
  ASSERT_TRUE(run.waitMatched(targets));
  const std::int64_t now = bus::nowNs();
  const std::int64_t stamps[] = {0,
                                 -1,
                                 std::numeric_limits<std::int64_t>::min(),
                                 std::numeric_limits<std::int64_t>::max(),
                                 now + 3600LL * 1000000000LL,
                                 now - 3600LL * 1000000000LL,
                                 now,
                                 now};
  const std::uint64_t seqs[] = {0, 0, 5, 5, 4, 3, std::numeric_limits<std::uint64_t>::max(), 1};
  int sent = 0;
  run.pumpCount(16, 70ms, [&](int k) {
    msg::HandTargets t = reachable();
    t.header().stamp_ns(stamps[k % 8]);
    t.header().seq(seqs[k % 8]);
    t.header().source(k % 2 ? "bad_source" : "");
    targets.write(t);  // header as given
    ++sent;
  });
  const double reaching = run.latestJoint("r_elbow");
  // Silence: last sample carried a stamp from the future; the controller must still retract.
  run.pump(2500ms, 50ms, [](int) {});
  run.expectSafeAndFinite();
  const double after = run.latestJoint("r_elbow");
  EXPECT_GT(std::abs(after - reaching), 0.05) << "the right arm moved back towards rest";

  ExitSummary s;
  ASSERT_EQ(run.finish(s), 0) << run.output;
  ASSERT_TRUE(s.found) << run.output;
  EXPECT_EQ(s.targets, sent);
  EXPECT_EQ(s.rejected, 0);
  EXPECT_GE(s.stale, 1) << "the silent source was declared stale";
}

// A module that publishes hand targets (random, valid) and heartbeats at 1 kHz for 3 s: the
// controller keeps its 5 ms period (median of ControlStatus.cycle_period_us), publishes its status
// at ~200 Hz, and stays safe.
TEST(ControllerBadInput, OneKilohertzPublisherDoesNotSlowThe200HzLoop) {
  ControllerRun run(104, 7.0, "flood");
  ASSERT_TRUE(run.started());
  auto& targets = run.source->makeWriter<msg::HandTargets>();
  auto& hb = run.source->makeWriter<msg::Heartbeat>();
  ASSERT_TRUE(run.waitMatched(targets));
  std::mt19937 rng(8);
  std::uniform_real_distribution<double> dx(0.25, 0.45), dy(0.05, 0.35), dz(0.8, 1.1);
  run.drain();
  run.statuses.clear();
  const auto t0 = std::chrono::steady_clock::now();
  long published = 0;
  const auto end = t0 + 3s;
  auto next = t0;
  while (std::chrono::steady_clock::now() < end) {
    msg::HandTargets t;
    t.left().status(msg::TARGET_GIVEN);
    t.left().position_base().x(dx(rng));
    t.left().position_base().y(dy(rng));
    t.left().position_base().z(dz(rng));
    t.right().status(msg::TARGET_GIVEN);
    t.right().position_base().x(dx(rng));
    t.right().position_base().y(-dy(rng));
    t.right().position_base().z(dz(rng));
    targets.publish(t);
    msg::Heartbeat h = heartbeat("bad_source");
    hb.publish(h);
    ++published;
    if (published % 20 == 0) run.drain();
    next += 1ms;
    std::this_thread::sleep_until(next);
  }
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  run.drain();
  const double rate = static_cast<double>(published) / seconds;
  ASSERT_FALSE(run.statuses.empty());
  std::vector<double> periods;
  for (const auto& s : run.statuses) periods.push_back(s.cycle_period_us());
  std::sort(periods.begin(), periods.end());
  const double median = periods[periods.size() / 2];
  const double p99 = periods[periods.size() * 99 / 100];
  std::printf(
      "flood: %.0f samples/s published for %.2f s; controller status %.0f Hz, cycle period median %.0f us, "
      "p99 %.0f us\n",
      rate, seconds, static_cast<double>(run.statuses.size()) / seconds, median, p99);
  EXPECT_GT(rate, 700.0) << "the flood really ran near 1 kHz";
  EXPECT_NEAR(median, 5000.0, 250.0);
  EXPECT_GT(static_cast<double>(run.statuses.size()), 0.75 * 200.0 * seconds);
  run.expectSafeAndFinite();

  ExitSummary s;
  ASSERT_EQ(run.finish(s), 0) << run.output;
  ASSERT_TRUE(s.found) << run.output;
  EXPECT_EQ(s.rejected, 0);
  EXPECT_LE(s.targets, s.cycles) << "at most one target set per cycle is taken (the newest)";
  EXPECT_LE(s.overruns, s.cycles / 100) << "overruns stay below 1% of the cycles";
}

// A flood of 200 distinct body-schema segments in one burst: the reader keeps at most 64 instances
// (QoS resource limits), the controller fills its 4 slots and rejects (counts) the rest; the loop
// keeps 200 Hz. Then every segment is detached again and the arms move freely.
TEST(ControllerBadInput, BodySchemaFloodIsBoundedBySlotsAndResourceLimits) {
  ControllerRun run(105, 6.0, "schema_flood");
  ASSERT_TRUE(run.started());
  auto& schema = run.source->makeWriter<msg::BodySchemaChange>();
  ASSERT_TRUE(run.waitMatched(schema));
  run.drain();
  run.statuses.clear();
  int published = 0;
  run.pump(1500ms, 5ms, [&](int k) {
    if (k >= 200) return;
    msg::BodySchemaChange c;
    c.segment_name("flood_" + std::to_string(k));
    c.operation(msg::SCHEMA_ATTACH);
    c.parent_link(k % 2 ? "l_hand" : "r_hand");
    c.shape(msg::SHAPE_SPHERE);
    c.radius(0.01);
    c.enabled(true);
    c.virtual_segment(true);
    schema.publish(c);
    ++published;
  });
  std::vector<double> periods;
  for (const auto& s : run.statuses) periods.push_back(s.cycle_period_us());
  ASSERT_FALSE(periods.empty());
  std::sort(periods.begin(), periods.end());
  EXPECT_NEAR(periods[periods.size() / 2], 5000.0, 250.0);
  run.expectSafeAndFinite(/*status_distances=*/false);  // virtual spheres overlap the hands

  ExitSummary s;
  ASSERT_EQ(run.finish(s), 0) << run.output;
  ASSERT_TRUE(s.found) << run.output;
  // Writer keep-last 1 per instance, reader max 64 instances: the reader gets at most 64 instances
  // (others are refused by DDS). 4 fill the slots; every further one is rejected and counted.
  EXPECT_GE(s.rejected, 60) << run.output;
  EXPECT_LE(s.rejected, published - 4) << run.output;
  EXPECT_GE(s.min_distance_mm, 5.0) << "physical pairs never below d_r";
  EXPECT_EQ(s.estops, 0);
}

// Body-schema segments that are finite but absurd (a 1 km sphere on the left hand, a 3 m pole, a
// sphere 1.5 m away from the hand, a virtual segment of radius 0.6 m or reaching 10 m) are rejected
// at the boundary (BodySchemaLimits: radius <= 0.5 m; physical length and reach <= 1 m; virtual
// <= 4 m), counted, and named in a stderr line with the bad value; the robot keeps following its
// targets (no e-stop). A grasped bar of ordinary size is accepted (not counted). Then, by choice
// (tests/bad_input/README.md, row 44a), a physical segment within the bounds that overlaps the body on
// attach (a 0.3 m sphere on the left hand) is ACCEPTED: the e-stop latches and the robot freezes
// (zero velocities), never a NaN. Recovery: the segment is detached and SIGUSR1 releases the e-stop;
// the robot follows a new target again.
TEST(ControllerBadInput, AbsurdBodySchemaSegmentsAreRejectedAndAnOverlappingOneStopsTheRobot) {
  ControllerRun run(107, 13.0, "huge_segment");
  ASSERT_TRUE(run.started());
  auto& schema = run.source->makeWriter<msg::BodySchemaChange>();
  auto& targets = run.source->makeWriter<msg::HandTargets>();
  auto& hb = run.source->makeWriter<msg::Heartbeat>();
  ASSERT_TRUE(run.waitMatched(schema));
  ASSERT_TRUE(targets.waitForReaders(1, 10s));

  auto segment = [](const std::string& name, const std::string& link, double radius, bool is_virtual) {
    msg::BodySchemaChange c;
    c.segment_name(name);
    c.operation(msg::SCHEMA_ATTACH);
    c.parent_link(link);
    c.shape(msg::SHAPE_CAPSULE);
    c.radius(radius);
    c.enabled(true);
    c.virtual_segment(is_virtual);
    return c;
  };
  std::vector<msg::BodySchemaChange> bad;
  bad.push_back(segment("boulder", "l_hand", 1000.0, false));
  bad.back().shape(msg::SHAPE_SPHERE);
  bad.push_back(segment("pole", "l_hand", 0.02, false));  // 3 m long
  bad.back().point_a().y(-1.5);
  bad.back().point_b().y(1.5);
  bad.push_back(segment("far_ball", "r_hand", 0.05, false));  // 1.5 m from the hand
  bad.back().shape(msg::SHAPE_SPHERE);
  bad.back().point_a().x(1.5);
  bad.push_back(segment("fat_gaze", "head", 0.6, true));
  bad.back().point_b().x(1.0);
  bad.push_back(segment("gaze_to_the_moon", "head", 0.03, true));  // 10 m
  bad.back().point_b().x(10.0);
  msg::BodySchemaChange bar = segment("bar", "r_hand", 0.01, false);  // ordinary: accepted
  bar.point_a().y(-0.05);
  bar.point_a().z(-0.06);
  bar.point_b().y(0.05);
  bar.point_b().z(-0.06);

  // Phase 1: targets + heartbeats throughout; the bad segments go out one by one, the bar once the
  // right hand is forward (1.5 s).
  run.drain();
  const double elbow_before = run.latestJoint("r_elbow");
  ASSERT_TRUE(std::isfinite(elbow_before));
  run.pump(2500ms, 50ms, [&](int k) {
    msg::HandTargets t = reachable();
    targets.publish(t);
    msg::Heartbeat h = heartbeat("bad_source");
    hb.publish(h);
    if (k < static_cast<int>(bad.size())) schema.publish(bad[static_cast<std::size_t>(k)]);
    if (k == 30) schema.publish(bar);
  });
  run.expectSafeAndFinite();
  ASSERT_FALSE(run.statuses.empty());
  for (const auto& st : run.statuses) {
    ASSERT_FALSE(st.left().estop_latched() || st.right().estop_latched()) << "an absurd segment froze the robot";
  }
  const double elbow_after = run.latestJoint("r_elbow");
  EXPECT_GT(std::abs(elbow_after - elbow_before), 0.05) << "the right arm follows its target";
  const std::size_t phase1_joint_states = run.joint_states.size();

  // Phase 2: a plausible-size physical segment that overlaps the body at once: accepted, e-stop.
  msg::BodySchemaChange overlapping = segment("overlapping_ball", "l_hand", 0.3, false);
  overlapping.shape(msg::SHAPE_SPHERE);
  schema.publish(overlapping);
  run.pump(1500ms, 50ms, [&](int) {
    msg::HandTargets t = reachable();
    targets.publish(t);
    msg::Heartbeat h = heartbeat("bad_source");
    hb.publish(h);
  });
  run.drain();
  run.expectSafeAndFinite(/*status_distances=*/false);  // red by design after the overlap
  ASSERT_GT(run.joint_states.size(), phase1_joint_states);
  EXPECT_TRUE(run.statuses.back().left().estop_latched()) << "red zone -> e-stop latched";
  for (double v : run.joint_states.back().velocities()) EXPECT_EQ(v, 0.0) << "frozen";

  // Phase 3: the module detaches the segment, the operator sends SIGUSR1; a new target is followed.
  msg::BodySchemaChange detach = overlapping;
  detach.operation(msg::SCHEMA_DETACH);
  schema.publish(detach);
  run.pump(300ms, 50ms, [](int) {});
  run.signal(SIGUSR1);
  const std::vector<double> q_frozen = run.joint_states.back().positions();
  msg::HandTargets other = reachable();
  other.right().position_base().y(-0.30);
  other.right().position_base().z(0.80);
  run.statuses.clear();
  run.pump(1500ms, 50ms, [&](int) {
    targets.publish(other);
    msg::Heartbeat h = heartbeat("bad_source");
    hb.publish(h);
  });
  run.drain();
  ASSERT_FALSE(run.statuses.empty());
  EXPECT_FALSE(run.statuses.back().left().estop_latched()) << "released after detach + SIGUSR1";
  double moved = 0.0;
  const std::vector<double>& q_now = run.joint_states.back().positions();
  for (std::size_t i = 0; i < q_now.size() && i < q_frozen.size(); ++i) moved += std::abs(q_now[i] - q_frozen[i]);
  EXPECT_GT(moved, 0.05) << "the robot moves again";

  ExitSummary s;
  ASSERT_EQ(run.finish(s), 0) << run.output;
  ASSERT_TRUE(s.found) << run.output;
  EXPECT_EQ(s.rejected, static_cast<long>(bad.size())) << "the five absurd segments, not the bar, not the overlap\n"
                                                       << run.output;
  EXPECT_EQ(s.estops, 1) << "only the overlapping segment stopped the robot";
  const char* lines[] = {
      "body-schema segment 'boulder' rejected: radius above the limit: 1000 m > max_radius 0.5 m",
      "body-schema segment 'pole' rejected: length |point_b - point_a| above the limit: 3 m > max_length 1 m",
      "body-schema segment 'far_ball' rejected: endpoint farther from the parent link origin than the limit: 1.5 m > "
      "max_reach 1 m",
      "body-schema segment 'fat_gaze' rejected: radius above the limit: 0.6 m > max_radius 0.5 m",
      "body-schema segment 'gaze_to_the_moon' rejected: length |point_b - point_a| above the limit: 10 m > "
      "max_virtual_length 4 m"};
  for (const char* line : lines) EXPECT_NE(run.output.find(line), std::string::npos) << line << "\n" << run.output;
  EXPECT_EQ(run.output.find("'bar' rejected"), std::string::npos);
  EXPECT_EQ(run.output.find("'overlapping_ball' rejected"), std::string::npos);
}

}  // namespace
}  // namespace reflex::bad_input
