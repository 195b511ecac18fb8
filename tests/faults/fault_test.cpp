// Faults with real processes: kill -9 of the process that feeds the controller,
// and of the recorder, in the middle of a run. Asserted: the controller keeps its 200 Hz (status
// rate and median cycle period across the kill), the hands retract within --input-timeout plus a
// margin, no pair goes below d_r, the system follows again within 3 s of a restart, and a recording
// cut by kill -9 stays readable; a bus write that blocks never stops the control loop. Domains 108..109, 224.
#include "support/child_process.hpp"
#include "../bus/bus_test_util.hpp"

#include <reflex/bus/bus.hpp>
#ifdef REFLEX_FAULTS_WITH_RECORDER
#include <reflex/record/record_file.hpp>
#endif

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <fstream>
#include <functional>
#include <iterator>
#include <sstream>
#include <thread>

namespace reflex {
namespace {

using namespace std::chrono_literals;
using Clock = std::chrono::steady_clock;

std::string bin(const std::string& exe) { return std::string(REFLEX_BIN_DIR) + "/" + exe; }

std::string readFile(const std::string& path) {
  std::ifstream in(path);
  return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
}

struct Stamped {
  double t;  // s since the test's t0
  msg::JointState js;
};

// The controller's own status rate over the received samples stamped in [from_ns, to_ns]: published
// samples (Header.seq difference, +1 per published sample) per second of the publisher's clock. A
// watcher that loses best-effort samples on a loaded host does not lower it; a controller that
// skips cycles does (counting received samples made the test fail at random).
double publishedRate(const std::vector<msg::ControlStatus>& statuses, std::int64_t from_ns, std::int64_t to_ns) {
  const msg::ControlStatus* first = nullptr;
  const msg::ControlStatus* last = nullptr;
  for (const auto& s : statuses) {
    if (s.header().stamp_ns() < from_ns || s.header().stamp_ns() > to_ns) continue;
    if (!first || s.header().seq() < first->header().seq()) first = &s;
    if (!last || s.header().seq() > last->header().seq()) last = &s;
  }
  if (!first || first == last || last->header().stamp_ns() <= first->header().stamp_ns()) return 0.0;
  return static_cast<double>(last->header().seq() - first->header().seq()) /
         (1e-9 * static_cast<double>(last->header().stamp_ns() - first->header().stamp_ns()));
}

double joint(const msg::JointState& js, const std::string& name) {
  const auto it = std::find(js.names().begin(), js.names().end(), name);
  return it == js.names().end() ? std::nan("") : js.positions()[static_cast<std::size_t>(it - js.names().begin())];
}

TEST(Faults, KillNineOfTheTargetSourceKeeps200HzRetractsAndRecoversAfterRestart) {
  constexpr int kDomain = 108;
  constexpr double kInputTimeout = 0.5;
  const std::string dom = std::to_string(kDomain);
  const std::string log = ::testing::TempDir() + "fault_controller.log";
  testing::ChildProcess controller(
      {bin("reflex_controller"), "--domain", dom, "--duration", "16", "--input-timeout", std::to_string(kInputTimeout)},
      log);
  auto source =
      std::make_unique<testing::ChildProcess>(std::vector<std::string>{bin("reflex_fault_source"), "--domain", dom},
                                              ::testing::TempDir() + "fault_source1.log");
  ASSERT_TRUE(controller.started() && source->started());

  bus::Participant watch(bus::test::testConfig("fault_watch", kDomain));
  auto& status = watch.makeReader<msg::ControlStatus>("reflex/control_status", bus::kProfileRecord);
  auto& joints = watch.makeReader<msg::JointState>("reflex/joint_state", bus::kProfileRecord);
  ASSERT_TRUE(status.waitForWriters(1, 15s));

  const auto t0 = Clock::now();
  auto now = [&] { return std::chrono::duration<double>(Clock::now() - t0).count(); };
  std::vector<msg::ControlStatus> statuses;
  std::vector<double> status_t;
  std::vector<Stamped> states;
  std::vector<msg::JointState> batch;
  auto pumpUntil = [&](double t_end) {
    while (now() < t_end) {
      std::this_thread::sleep_for(20ms);
      const double t = now();
      const std::size_t before = statuses.size();
      status.takeAll(statuses);
      status_t.resize(statuses.size(), t);
      (void)before;
      batch.clear();
      joints.takeAll(batch);
      for (auto& js : batch) states.push_back({t, js});
    }
  };
  // Reaching: wait until the right elbow has bent (the source is followed).
  pumpUntil(4.0);
  ASSERT_FALSE(states.empty());
  const double reaching = joint(states.back().js, "r_elbow");
  ASSERT_LT(reaching, -0.6) << "the right arm reached for the crossing target";

  // kill -9 of the source.
  const double t_kill = now();
  const std::int64_t kill_ns = bus::nowNs();
  source->signal(SIGKILL);
  EXPECT_GT(source->wait(2000ms), 128) << "killed by a signal";
  pumpUntil(t_kill + 3.0);
  double t_retract = -1.0;
  for (const auto& s : states) {
    if (s.t > t_kill && joint(s.js, "r_elbow") > reaching + 0.05) {
      t_retract = s.t - t_kill;
      break;
    }
  }
  EXPECT_GE(t_retract, 0.0) << "the right arm retracted after the kill";
  EXPECT_LT(t_retract, kInputTimeout + 0.5) << "within --input-timeout + 0.5 s";

  // The 200 Hz across the kill: statuses published in [t_kill - 1, t_kill + 3] (the controller's
  // stamps and sequence numbers; see publishedRate).
  std::vector<double> periods;
  for (std::size_t i = 0; i < statuses.size(); ++i) {
    if (status_t[i] >= t_kill - 1.0 && status_t[i] <= t_kill + 3.0) periods.push_back(statuses[i].cycle_period_us());
  }
  ASSERT_FALSE(periods.empty());
  std::sort(periods.begin(), periods.end());
  EXPECT_NEAR(periods[periods.size() / 2], 5000.0, 250.0);
  const double rate = publishedRate(statuses, kill_ns - 1'000'000'000, kill_ns + 3'000'000'000);
  EXPECT_GT(rate, 0.75 * 200.0) << "status published at 200 Hz around the kill";

  // Restart: followed again within 3 s.
  const double t_restart = now();
  source =
      std::make_unique<testing::ChildProcess>(std::vector<std::string>{bin("reflex_fault_source"), "--domain", dom},
                                              ::testing::TempDir() + "fault_source2.log");
  ASSERT_TRUE(source->started());
  pumpUntil(t_restart + 4.0);
  double t_recover = -1.0;
  for (const auto& s : states) {
    if (s.t > t_restart && std::abs(joint(s.js, "r_elbow") - reaching) < 0.05) {
      t_recover = s.t - t_restart;
      break;
    }
  }
  std::printf(
      "fault: retract %.2f s after kill -9 (input timeout %.1f s), follows again %.2f s after restart, "
      "status %.0f Hz around the kill, median cycle %.0f us\n",
      t_retract, kInputTimeout, t_recover, rate, periods[periods.size() / 2]);
  EXPECT_GE(t_recover, 0.0) << "the restarted source is followed";
  EXPECT_LT(t_recover, 3.0) << "within 3 s of the restart (process start + discovery + motion)";
  for (const auto& s : statuses) EXPECT_GE(std::min(s.left().distance(), s.right().distance()), 0.005);

  source.reset();
  EXPECT_EQ(controller.wait(20s), 0);
  const std::string out = readFile(log);
  EXPECT_NE(out.find("e-stops 0"), std::string::npos) << out;
  EXPECT_NE(out.find("stale events"), std::string::npos) << out;
  EXPECT_EQ(out.find("stale events 0"), std::string::npos) << "the kill was noticed: " << out;
}

// A bus write that blocks never stops the control loop (the controller's outbox, reflex/bus/outbox.hpp).
// What blocks a write in the field — Fast DDS 2.9's shared-memory port check after a reader's kill -9
// (about 1 s; idl/README.md) — does not come on demand, so the block is made for certain: the
// controller's state writers (joint state, status) are RELIABLE, KEEP_ALL with 4 samples and a
// 200 ms max_blocking_time, and a reader here never takes: after a few samples every write waits
// 200 ms. Written from the loop (two such writes a cycle), that would be about 2.5 cycles a second;
// asserted from the controller's own --log (its rows come from the loop, not the bus): over 180 Hz
// and no gap as long as one blocked write (bound 150 ms); the exit line names the blocked writes and
// the dropped samples. Domain 224.
TEST(Faults, ABusWriteThatBlocksNeverStopsTheControlLoop) {
  constexpr int kDomain = 224;
  const std::string tmp = ::testing::TempDir();
  const std::string xml = tmp + "fault_blocking_profiles.xml", log = tmp + "fault_blocking_controller.csv";
  {
    std::string s = readFile(std::string(REFLEX_SOURCE_DIR) + "/bringup/dds/reflex_profiles.xml");
    const std::string open = "<data_writer profile_name=\"reflex_state\">";
    const auto a = s.find(open), b = s.find("</data_writer>", a);
    ASSERT_TRUE(a != std::string::npos && b != std::string::npos) << "reflex_state writer in the profiles";
    s.replace(a, b - a, open + R"(
      <topic>
        <historyQos><kind>KEEP_ALL</kind></historyQos>
        <resourceLimitsQos><max_samples>4</max_samples><max_instances>1</max_instances><max_samples_per_instance>4</max_samples_per_instance><allocated_samples>4</allocated_samples></resourceLimitsQos>
      </topic>
      <qos>
        <reliability><kind>RELIABLE</kind><max_blocking_time><sec>0</sec><nanosec>200000000</nanosec></max_blocking_time></reliability>
      </qos>
    )");
    const std::string reader = R"(
    <data_reader profile_name="fault_stuck_reader">
      <topic>
        <historyQos><kind>KEEP_ALL</kind></historyQos>
        <resourceLimitsQos><max_samples>2</max_samples><max_instances>1</max_instances><max_samples_per_instance>2</max_samples_per_instance><allocated_samples>2</allocated_samples></resourceLimitsQos>
      </topic>
      <qos><reliability><kind>RELIABLE</kind></reliability></qos>
    </data_reader>
  </profiles>)";
    const auto e = s.rfind("</profiles>");
    ASSERT_NE(e, std::string::npos);
    s.replace(e, std::string("</profiles>").size(), reader);
    std::ofstream(xml) << s;
  }
  std::remove(log.c_str());
  testing::ChildProcess controller({bin("reflex_controller"), "--domain", std::to_string(kDomain), "--profiles", xml,
                                    "--duration", "4", "--log", log},
                                   tmp + "fault_blocking_controller.log");
  ASSERT_TRUE(controller.started());
  bus::BusConfig config;
  config.module_name = "fault_stuck";
  config.domain_id = kDomain;
  config.profiles_file = xml;
  bus::Participant stuck(config);
  auto& joints = stuck.makeReader<msg::JointState>("reflex/joint_state", "fault_stuck_reader");
  auto& status = stuck.makeReader<msg::ControlStatus>("reflex/control_status", "fault_stuck_reader");
  ASSERT_TRUE(joints.waitForWriters(1, 15s) && status.waitForWriters(1, 15s));
  EXPECT_EQ(controller.wait(30s), 0);  // never takes a sample: the controller's writes block meanwhile
  const std::string out = readFile(tmp + "fault_blocking_controller.log");

  std::ifstream in(log);
  std::string line;
  std::getline(in, line);
  std::size_t wall_col = 0;
  {
    std::stringstream hs(line);
    std::string f;
    for (std::size_t k = 0; std::getline(hs, f, ','); ++k)
      if (f == "wall_time") wall_col = k;
  }
  std::vector<double> wall;
  while (std::getline(in, line)) {
    std::stringstream ls(line);
    std::string f;
    for (std::size_t k = 0; std::getline(ls, f, ','); ++k)
      if (k == wall_col) wall.push_back(std::stod(f));
  }
  ASSERT_GT(wall.size(), 100U) << out;
  double gap = 0.0;
  for (std::size_t k = 1; k < wall.size(); ++k) gap = std::max(gap, wall[k] - wall[k - 1]);
  const double rate = static_cast<double>(wall.size() - 1) / (wall.back() - wall.front());
  unsigned long long written = 0, dropped = 0, refused = 0, blocked = 0;
  double longest_ms = 0.0;
  const auto at = out.find("bus writes ");
  ASSERT_NE(at, std::string::npos) << out;
  ASSERT_EQ(
      std::sscanf(out.c_str() + at, "bus writes %llu (dropped %llu, refused %llu, blocked > 50 ms %llu, longest %lf ms",
                  &written, &dropped, &refused, &blocked, &longest_ms),
      5)
      << out;
  std::printf(
      "fault: blocked bus writes: %zu loop cycles at %.1f Hz, largest gap %.1f ms; bus writes %llu, dropped %llu, "
      "refused %llu, blocked > 50 ms %llu, longest %.0f ms\n",
      wall.size(), rate, 1e3 * gap, written, dropped, refused, blocked, longest_ms);
  EXPECT_GT(blocked, 3U) << "the writes did block (the test can fail)";
  EXPECT_GT(longest_ms, 150.0);
  EXPECT_GT(dropped, 100U) << "what the blocked writer could not take is counted";
  // A cycle that waited for one write would leave a gap of 200 ms; scheduling on a loaded 2-core
  // machine leaves up to ~30 ms (measured 5.8-26.6 ms).
  EXPECT_GT(rate, 180.0) << "the loop's rate while its writes block (2.5 Hz if it waited for them)";
  EXPECT_LT(gap, 0.15) << "no cycle waited for a write";
  EXPECT_GT(wall.size(), 700U) << "4 s at 200 Hz";
}

#ifdef REFLEX_FAULTS_WITH_RECORDER
TEST(Faults, KillNineOfTheRecorderLeavesTheControllerAndAReadableRecording) {
  constexpr int kDomain = 109;
  const std::string dom = std::to_string(kDomain);
  const std::string file = ::testing::TempDir() + "fault_recording.rfx";
  std::remove(file.c_str());
  testing::ChildProcess controller({bin("reflex_controller"), "--domain", dom, "--duration", "7"},
                                   ::testing::TempDir() + "fault_rec_controller.log");
  testing::ChildProcess recorder({bin("reflex_record"), "record", "-o", file, "--domain", dom},
                                 ::testing::TempDir() + "fault_recorder.log");
  ASSERT_TRUE(controller.started() && recorder.started());
  bus::Participant watch(bus::test::testConfig("fault_watch", kDomain));
  auto& status = watch.makeReader<msg::ControlStatus>("reflex/control_status", bus::kProfileRecord);
  ASSERT_TRUE(status.waitForWriters(1, 15s));
  // The controller writes over UDP only: no Fast DDS shared-memory segment is mapped in
  // it, so the recorder's kill cannot stall its writes in the port health check (with shared memory
  // they stalled 1.0 s and 2.0 s after this kill in a ctest run, and this test saw 1 status in 2 s).
  // The recorder, on the default profile, maps them: the check can fail.
  const auto shmMappings = [](pid_t pid) {
    std::ifstream maps("/proc/" + std::to_string(pid) + "/maps");
    std::string line;
    int n = 0;
    while (std::getline(maps, line)) n += line.find("/dev/shm/fastrtps_") != std::string::npos ? 1 : 0;
    return n;
  };
  EXPECT_EQ(shmMappings(controller.pid()), 0) << "the controller must not use Fast DDS's shared memory";
  EXPECT_GT(shmMappings(recorder.pid()), 0) << "the recorder (default profile) does: the check can fail";
  std::vector<msg::ControlStatus> statuses;
  const auto pump = [&](std::chrono::milliseconds d) {
    const auto end = Clock::now() + d;
    while (Clock::now() < end) {
      std::this_thread::sleep_for(20ms);
      status.takeAll(statuses);
    }
  };
  pump(3000ms);
  recorder.signal(SIGKILL);
  EXPECT_GT(recorder.wait(2000ms), 128);
  statuses.clear();
  pump(2000ms);
  EXPECT_GT(statuses.size(), 300U) << "the controller keeps publishing at 200 Hz";
  EXPECT_EQ(controller.wait(15s), 0);

  record::RecordReader reader(file);
  record::RecordEntry e;
  std::size_t n_status = 0;
  while (reader.next(e)) n_status += e.topic == "reflex/control_status";
  std::printf("fault: recording cut by kill -9: %zu control_status records, tail '%s'\n", n_status,
              record::toString(reader.tailState()));
  EXPECT_GT(n_status, 200U) << "at least ~1 s of the 200 Hz status reached the file before the kill";
  EXPECT_NE(reader.tailState(), record::TailState::kCorrupt);
}
#endif

#ifdef REFLEX_FAULTS_WITH_CHAIN
// The real chain reflex_vision (flagship session, looped) -> reflex_behavior (pointing) ->
// reflex_controller. kill -9 of vision: the pointing module loses its objects and sends "no target"
// within lost_timeout (1 s) + margin, the controller keeps 200 Hz; vision restarted: targets again
// within 3 s of its first frame on the bus. kill -9 of behavior: the controller declares its source
// stale (retract) and keeps 200 Hz; behavior restarted: targets again within 3 s of its first
// heartbeat or sample. Times are the publishers' stamps (one host), rates the controller's own.
// (The restarted process's own start-up — opening the videos, loading the robot — is printed too;
// on a loaded 2-core machine it adds 0.2..1 s.) Domain 108 (after the test above).
TEST(Faults, KillNineOfVisionAndOfBehaviorInTheRealChainAndRestart) {
  constexpr int kDomain = 108;
  const std::string d = std::to_string(kDomain);
  const std::string src = REFLEX_SOURCE_DIR;
  const std::string tmp = ::testing::TempDir();
  auto visionArgs = [&] {
    return std::vector<std::string>{
        bin("reflex_vision"), "--session", src + "/bringup/sessions/flagship", "--loop", "--quiet", "--domain", d};
  };
  // Behavior on UDP: with Fast DDS 2.9's shared memory, a kill -9 of a reader process stalls its
  // peers' writers (the port health check), seen here once as the controller's status stream at
  // 0.67 Hz for 3 s after behavior's kill -9 (the same stall robot_port_test and
  // mujoco_faults_test avoid the same way). The controller's loop no longer waits for its writes
  // (its bus outbox, ABusWriteThatBlocksNeverStopsTheControlLoop above), but its published stream
  // would still pause for the check; this test checks the chain's restart.
  auto behaviorArgs = [&] {
    return std::vector<std::string>{bin("reflex_behavior"),
                                    "--config",
                                    src + "/bringup/behavior/pointing.yaml",
                                    "--domain",
                                    d,
                                    "--participant-profile",
                                    "reflex_participant_udp"};
  };
  testing::ChildProcess controller(
      {bin("reflex_controller"), "--domain", d, "--duration", "45", "--input-timeout", "0.5"},
      tmp + "chain_controller.log");
  auto behavior = std::make_unique<testing::ChildProcess>(behaviorArgs(), tmp + "chain_behavior1.log");
  auto vision = std::make_unique<testing::ChildProcess>(visionArgs(), tmp + "chain_vision1.log");
  ASSERT_TRUE(controller.started() && behavior->started() && vision->started());

  bus::Participant watch(bus::test::testConfig("fault_watch", kDomain));
  auto& status = watch.makeReader<msg::ControlStatus>("reflex/control_status", bus::kProfileRecord);
  auto& targets = watch.makeReader<msg::HandTargets>("reflex/hand_targets", bus::kProfileRecord);
  auto& objects = watch.makeReader<msg::ObjectTargets>("reflex/object_targets", bus::kProfileRecord);
  // The heartbeat profile (reliable, transient local): the restarted behavior's FIRST heartbeat is
  // delivered even if it was written before this reader matched the new writer.
  auto& beats = watch.makeReader<msg::Heartbeat>("reflex/heartbeat", bus::kProfileHeartbeat);
  ASSERT_TRUE(status.waitForWriters(1, 15s));
  const auto t0 = Clock::now();
  // Recovery is measured on the publishers' own stamps (Header.stamp_ns, CLOCK_REALTIME, one host):
  // DDS orders samples per writer only, so this watcher may take a restarted process's first frame
  // after the hand targets it caused; arrival order across topics proves nothing.
  std::vector<std::int64_t> object_stamps;         // every vision frame's stamp
  std::vector<std::int64_t> behavior_beat_stamps;  // every heartbeat of the behavior process
  std::vector<msg::ObjectTargets> obj_batch;
  std::vector<msg::Heartbeat> beat_batch;
  auto now = [&] { return std::chrono::duration<double>(Clock::now() - t0).count(); };
  std::vector<msg::ControlStatus> statuses;
  struct Given {
    double t;            // arrival at the watcher (s since t0)
    std::int64_t stamp;  // the behavior's publication stamp (ns, system clock)
    bool any;            // some hand has a target
  };
  std::vector<Given> given;
  std::vector<msg::HandTargets> batch;
  auto pumpUntil = [&](double t_end, const std::function<bool()>& done = {}) {
    while (now() < t_end) {
      std::this_thread::sleep_for(20ms);
      status.takeAll(statuses);
      batch.clear();
      targets.takeAll(batch);
      for (const auto& t : batch) {
        given.push_back({now(), t.header().stamp_ns(),
                         t.left().status() == msg::TARGET_GIVEN || t.right().status() == msg::TARGET_GIVEN});
      }
      obj_batch.clear();
      objects.takeAll(obj_batch);
      for (const auto& o : obj_batch) object_stamps.push_back(o.header().stamp_ns());
      beat_batch.clear();
      beats.takeAll(beat_batch);
      for (const auto& b : beat_batch) {
        if (b.module_name() == "behavior") behavior_beat_stamps.push_back(b.header().stamp_ns());
      }
      if (done && done()) return;
    }
  };
  auto lastGiven = [&] { return !given.empty() && given.back().any; };
  auto lastNone = [&] { return !given.empty() && !given.back().any; };
  // The first stamp at or after `since` (ns), or -1.
  auto firstAfter = [](const std::vector<std::int64_t>& stamps, std::int64_t since) {
    std::int64_t first = -1;
    for (const std::int64_t s : stamps)
      if (s >= since && (first < 0 || s < first)) first = s;
    return first;
  };
  // The first hand targets with a target stamped at or after `since` (ns), or -1.
  auto firstGivenAfter = [&](std::int64_t since) {
    std::int64_t first = -1;
    for (const Given& g : given)
      if (g.any && g.stamp >= since && (first < 0 || g.stamp < first)) first = g.stamp;
    return first;
  };

  pumpUntil(20.0, lastGiven);
  ASSERT_TRUE(lastGiven()) << "the chain points at an object";
  pumpUntil(now() + 2.0);

  // kill -9 of vision.
  const double t_kill_vision = now();
  vision->signal(SIGKILL);
  vision->wait(2000ms);
  pumpUntil(t_kill_vision + 4.0, lastNone);
  ASSERT_TRUE(lastNone()) << "pointing gave up the objects";
  const double lost = given.back().t - t_kill_vision;
  EXPECT_LT(lost, 1.0 + 0.6) << "within lost_timeout + margin";
  const double t_restart_vision = now();
  const std::int64_t restart_vision_ns = bus::nowNs();
  vision = std::make_unique<testing::ChildProcess>(visionArgs(), tmp + "chain_vision2.log");
  // Until targets are given again AND this watcher holds the restarted vision's first frame. The
  // wait covers the process's own start-up (opening the videos: 0.2 s idle, above 6 s seen under a
  // load of 7 on 2 cores); what is asserted is measured from its first frame.
  // And a target stamped after that frame: a frame published before this watcher's best-effort reader
  // matched the restarted writer is never seen here, so a target it caused may come first (seen once).
  pumpUntil(t_restart_vision + 15.0, [&] {
    const std::int64_t seen = firstAfter(object_stamps, restart_vision_ns);
    return lastGiven() && seen >= 0 && firstGivenAfter(seen) >= 0;
  });
  ASSERT_TRUE(lastGiven());
  const std::int64_t first_frame_ns = firstAfter(object_stamps, restart_vision_ns);
  ASSERT_GE(first_frame_ns, 0) << "the restarted vision publishes";
  const std::int64_t vision_target_ns = firstGivenAfter(first_frame_ns);
  ASSERT_GE(vision_target_ns, 0) << "targets follow the restarted vision's frames";
  const double vision_recovery = 1e-9 * static_cast<double>(vision_target_ns - restart_vision_ns);
  const double vision_back = 1e-9 * static_cast<double>(vision_target_ns - first_frame_ns);
  EXPECT_LT(vision_back, 3.0) << "targets again within 3 s of the restarted vision's first frame";
  pumpUntil(now() + 1.0);

  // kill -9 of behavior.
  const double t_kill_behavior = now();
  const std::int64_t kill_behavior_ns = bus::nowNs();
  behavior->signal(SIGKILL);
  behavior->wait(2000ms);
  pumpUntil(t_kill_behavior + 3.0);
  const double during_rate = publishedRate(statuses, kill_behavior_ns, bus::nowNs());
  EXPECT_GT(during_rate, 0.75 * 200.0) << "200 Hz while behavior is dead";
  const double t_restart_behavior = now();
  const std::int64_t restart_behavior_ns = bus::nowNs();
  behavior = std::make_unique<testing::ChildProcess>(behaviorArgs(), tmp + "chain_behavior2.log");
  pumpUntil(t_restart_behavior + 15.0, [&] {  // start-up included, as for vision
    return lastGiven() && firstGivenAfter(restart_behavior_ns) >= 0 &&
           firstAfter(behavior_beat_stamps, restart_behavior_ns) >= 0;
  });
  const std::int64_t first_beat_ns = firstAfter(behavior_beat_stamps, restart_behavior_ns);
  ASSERT_GE(first_beat_ns, 0) << "the restarted behavior sends its heartbeat";
  const std::int64_t behavior_target_ns = firstGivenAfter(restart_behavior_ns);
  ASSERT_GE(behavior_target_ns, 0) << "the restarted behavior gives targets";
  ASSERT_TRUE(lastGiven());
  const double behavior_recovery = 1e-9 * static_cast<double>(behavior_target_ns - restart_behavior_ns);
  // Its first sign of life: the first heartbeat or the first hand targets sample (it may publish
  // targets before its first heartbeat).
  std::int64_t alive_ns = first_beat_ns;
  for (const Given& g : given)
    if (g.stamp >= restart_behavior_ns) alive_ns = std::min(alive_ns, g.stamp);
  const double behavior_back = 1e-9 * static_cast<double>(behavior_target_ns - alive_ns);
  EXPECT_LT(behavior_back, 3.0) << "targets again within 3 s of the restarted behavior's first sign of life";

  std::vector<double> periods;
  for (const auto& s : statuses) periods.push_back(s.cycle_period_us());
  std::sort(periods.begin(), periods.end());
  for (const auto& s : statuses) EXPECT_GE(std::min(s.left().distance(), s.right().distance()), 0.005);
  std::printf(
      "fault chain: kill -9 vision -> no target after %.2f s; vision restart -> target after %.2f s "
      "(%.2f s after its first frame); kill -9 behavior -> %.0f status/s; behavior restart -> target after "
      "%.2f s (%.2f s after its first sign of life); median cycle %.0f us\n",
      lost, vision_recovery, vision_back, during_rate, behavior_recovery, behavior_back, periods[periods.size() / 2]);
  EXPECT_NEAR(periods[periods.size() / 2], 5000.0, 250.0);
  vision.reset();
  behavior.reset();
  controller.signal(SIGTERM);
  EXPECT_EQ(controller.wait(10s), 0);
  const std::string out = readFile(tmp + "chain_controller.log");
  EXPECT_NE(out.find("e-stops 0"), std::string::npos) << out;
  EXPECT_EQ(out.find("stale events 0"), std::string::npos) << "behavior's death was noticed: " << out;
}
#endif

}  // namespace
}  // namespace reflex
