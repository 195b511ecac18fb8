// reflex::record over real DDS, in one process: every Reflex topic type is recorded, read back,
// played and exported unchanged (compared field by field with what was published, through the
// types' own Fast DDS type support); the player keeps the recorded timing scaled by the rate, starts
// at the offset and loops; bad options are clear errors. Domain 80.
#include "reflex/record/recorder.hpp"

#include <reflex/bus/bus.hpp>

#include "record_support.hpp"
#include "samples.hpp"

#include <gtest/gtest.h>

#include <fstream>
#include <sstream>
#include <thread>

namespace reflex::record {
namespace {

constexpr int kDomain = 80;
using namespace std::chrono_literals;

std::string tempPath(const std::string& name) { return ::testing::TempDir() + "record_bus_test_" + name; }

bus::BusConfig busConfig(const std::string& name) {
  bus::BusConfig c;
  c.module_name = name;
  c.domain_id = kDomain;
  return c;
}

// Independent decoding: the generated PubSubType directly, not the recorder's codec.
template <class T>
T decode(const RecordEntry& e) {
  T out;
  EXPECT_TRUE(test::decodeEntry(e, out)) << e.topic << " (" << e.type << ")";
  return out;
}
using test::encodeEntry;

std::vector<std::vector<std::string>> readCsv(const std::string& path) {
  std::ifstream in(path);
  std::vector<std::vector<std::string>> rows;
  std::string line;
  while (std::getline(in, line)) {
    std::vector<std::string> cells;
    std::stringstream ss(line);
    std::string c;
    while (std::getline(ss, c, ',')) cells.push_back(c);
    if (!line.empty() && line.back() == ',') cells.emplace_back();
    rows.push_back(cells);
  }
  return rows;
}
std::size_t col(const std::vector<std::string>& header, const std::string& name) {
  for (std::size_t i = 0; i < header.size(); ++i)
    if (header[i] == name) return i;
  ADD_FAILURE() << "no column " << name;
  return 0;
}

struct Sent {
  std::vector<msg::ObjectTargets> objects;
  std::vector<msg::HandTargets> hands;
  std::vector<msg::MotionPriority> prio;
  std::vector<msg::BodySchemaChange> schema;
  std::vector<msg::WalkCommand> walk;
  std::vector<msg::JointState> joints;
  std::vector<msg::ControlStatus> status;
  std::vector<msg::Heartbeat> beats;
  std::vector<msg::ControllerProtection> protection;
  std::vector<msg::RobotState> robot;  // the robot boundary
  std::vector<msg::JointCommand> command;
  std::vector<msg::RobotContacts> contacts;
  std::vector<msg::CameraImage> camera;
};

template <class T>
void expectRecorded(const std::vector<RecordEntry>& all, const std::vector<T>& sent) {
  std::vector<T> got;
  for (const auto& e : all)
    if (e.topic == bus::TopicTraits<T>::kTopicName) got.push_back(decode<T>(e));
  ASSERT_EQ(got.size(), sent.size()) << bus::TopicTraits<T>::kTopicName;
  for (std::size_t k = 0; k < got.size(); ++k) {
    const auto d = bus::test::diffSample(sent[k], got[k]);
    EXPECT_TRUE(d.empty()) << bus::TopicTraits<T>::kTopicName << " #" << k << "\n" << bus::test::join(d);
  }
}

TEST(RecordBus, EveryTopicTypeIsRecordedPlayedAndExportedUnchanged) {
  const std::string file = tempPath("all.rfx");
  RecorderOptions ro;
  ro.output = file;
  ro.bus = busConfig("recorder");
  Recorder recorder(ro);
  EXPECT_EQ(recorder.counts().size(), 13u) << "all Reflex topics by default";
  std::thread rec_thread([&] { recorder.run(); });

  Sent sent;
  {
    bus::Participant src(busConfig("source"));
    auto& w_obj = src.makeWriter<msg::ObjectTargets>();
    auto& w_hand = src.makeWriter<msg::HandTargets>();
    auto& w_prio = src.makeWriter<msg::MotionPriority>();
    auto& w_schema = src.makeWriter<msg::BodySchemaChange>();
    auto& w_walk = src.makeWriter<msg::WalkCommand>();
    auto& w_joint = src.makeWriter<msg::JointState>();
    auto& w_status = src.makeWriter<msg::ControlStatus>();
    auto& w_beat = src.makeWriter<msg::Heartbeat>();
    auto& w_protection = src.makeWriter<msg::ControllerProtection>();
    auto& w_robot = src.makeWriter<msg::RobotState>();
    auto& w_command = src.makeWriter<msg::JointCommand>();
    auto& w_contacts = src.makeWriter<msg::RobotContacts>();
    auto& w_camera = src.makeWriter<msg::CameraImage>();
    for (bus::detail::WriterBase* w : std::initializer_list<bus::detail::WriterBase*>{
             &w_obj, &w_hand, &w_prio, &w_schema, &w_walk, &w_joint, &w_status, &w_beat, &w_protection, &w_robot,
             &w_command, &w_contacts, &w_camera})
      ASSERT_TRUE(w->waitForReaders(1, 10s)) << w->topicName();
    // Both sides: a writer that matched the recorder may still be unknown to the recorder's reader,
    // which then drops a best-effort sample (on a loaded host that window lasted long enough to lose
    // 24 of 40 samples). Once both sides matched, every sample here is delivered:
    // the reliable topics are read reliably (repaired if dropped), and 65 samples in 150 ms never
    // fill a best-effort transport queue on one host.
    ASSERT_TRUE(recorder.waitForWriters(10s)) << "the recorder matched every writer";
    for (int k = 0; k < 5; ++k) {
      sent.objects.push_back(bus::test::objectTargets(k));
      sent.hands.push_back(bus::test::handTargets(k));
      sent.prio.push_back(bus::test::motionPriority(k));
      sent.schema.push_back(bus::test::bodySchemaChange(k));
      sent.walk.push_back(bus::test::walkCommand(k));
      sent.joints.push_back(bus::test::jointState(k));
      sent.status.push_back(bus::test::controlStatus(k));
      sent.beats.push_back(bus::test::heartbeat(k));
      sent.protection.push_back(bus::test::controllerProtection(k));
      sent.robot.push_back(bus::test::robotState(k));
      sent.command.push_back(bus::test::jointCommand(k));
      sent.contacts.push_back(bus::test::robotContacts(k));
      sent.camera.push_back(bus::test::cameraImage(k));
      sent.camera.back().data().resize(20'000);  // a small JPEG's size: 5 in 150 ms stay in the queue
      w_obj.write(sent.objects.back());
      w_hand.write(sent.hands.back());
      w_prio.write(sent.prio.back());
      w_schema.write(sent.schema.back());
      w_walk.write(sent.walk.back());
      w_joint.write(sent.joints.back());
      w_status.write(sent.status.back());
      w_beat.write(sent.beats.back());
      w_protection.write(sent.protection.back());
      w_robot.write(sent.robot.back());
      w_command.write(sent.command.back());
      w_contacts.write(sent.contacts.back());
      w_camera.write(sent.camera.back());
      std::this_thread::sleep_for(30ms);
    }
    std::this_thread::sleep_for(500ms);
  }
  recorder.stop();
  rec_thread.join();
  EXPECT_EQ(recorder.totalSamples(), 65u);

  // Read back: every sample, unchanged, receive times ordered, DDS source times set.
  std::vector<RecordEntry> all;
  {
    RecordReader r(file);
    RecordEntry e;
    while (r.next(e)) all.push_back(e);
    EXPECT_EQ(r.tailState(), TailState::kClean);
  }
  ASSERT_EQ(all.size(), 65u);
  for (std::size_t i = 1; i < all.size(); ++i) EXPECT_GE(all[i].receive_ns, all[i - 1].receive_ns);
  for (const auto& e : all) {
    EXPECT_GT(e.source_ns, 0);
    EXPECT_LE(e.source_ns, e.receive_ns);
  }
  expectRecorded(all, sent.objects);
  expectRecorded(all, sent.hands);
  expectRecorded(all, sent.prio);
  expectRecorded(all, sent.schema);
  expectRecorded(all, sent.walk);
  expectRecorded(all, sent.joints);
  expectRecorded(all, sent.status);
  expectRecorded(all, sent.beats);
  expectRecorded(all, sent.protection);
  expectRecorded(all, sent.robot);
  expectRecorded(all, sent.command);
  expectRecorded(all, sent.contacts);
  expectRecorded(all, sent.camera);

  std::vector<std::int64_t> status_rx;  // recorded receive times of the control status samples
  for (const auto& e : all)
    if (e.topic == "reflex/control_status") status_rx.push_back(e.receive_ns);

  // CSV export: values as published.
  const std::string csv = tempPath("status.csv");
  EXPECT_EQ(exportCsv(file, "reflex/control_status", csv), 5u);
  auto rows = readCsv(csv);
  ASSERT_EQ(rows.size(), 6u);
  const auto& h = rows[0];
  for (int k = 0; k < 5; ++k) {
    const auto& r = rows[static_cast<std::size_t>(k) + 1];
    ASSERT_EQ(r.size(), h.size());
    EXPECT_EQ(std::stoull(r[col(h, "seq")]), 1000u + static_cast<unsigned>(k));
    EXPECT_EQ(r[col(h, "source")], "test-source");
    EXPECT_DOUBLE_EQ(std::stod(r[col(h, "compute_time_us")]), 812.5 + k);
    EXPECT_DOUBLE_EQ(std::stod(r[col(h, "left_distance")]), 0.0125);
    EXPECT_EQ(r[col(h, "right_zone")], "3");  // ZONE_RED
    EXPECT_EQ(r[col(h, "right_estop")], "1");
    EXPECT_EQ(r[col(h, "left_closest_a")], "left_forearm");
    EXPECT_EQ(std::stoull(r[col(h, "overrun_count")]), 0xFFFF'FFFF'FFFF'FFF0ULL);
    EXPECT_DOUBLE_EQ(std::stod(r[col(h, "arm_distance")]), 0.0375 + k);
    EXPECT_EQ(std::stoull(r[col(h, "rejected_body_schema")]), 0xFFFF'FFFF'FFFF'FFFEULL);
    EXPECT_EQ(r[col(h, "last_rejection")], "walk_goal_y_or_yaw_not_zero");
  }
  const std::string csv_obj = tempPath("objects.csv");
  EXPECT_EQ(exportCsv(file, "reflex/object_targets", csv_obj), 5u);
  rows = readCsv(csv_obj);
  ASSERT_EQ(rows.size(), 1u + 5u * 3u) << "one row per object";
  EXPECT_DOUBLE_EQ(std::stod(rows[2][col(rows[0], "x")]), 1.25);
  EXPECT_EQ(rows[2][col(rows[0], "object")], "");
  EXPECT_EQ(rows[3][col(rows[0], "tag_id")], "13");
  const std::string csv_js = tempPath("joints.csv");
  EXPECT_EQ(exportCsv(file, "reflex/joint_state", csv_js), 5u);
  rows = readCsv(csv_js);
  EXPECT_DOUBLE_EQ(std::stod(rows[3][col(rows[0], "q_joint_20")]), 0.2 - 1.0 + 2e-3);
  EXPECT_DOUBLE_EQ(std::stod(rows[3][col(rows[0], "qd_joint_4")]), -2.0);
  // The robot boundary: one row per state / command, one per reported pair (samples.hpp's values).
  const std::string csv_robot = tempPath("robot.csv");
  EXPECT_EQ(exportCsv(file, "reflex/robot_state", csv_robot), 5u);
  rows = readCsv(csv_robot);
  ASSERT_EQ(rows.size(), 6u);
  ASSERT_EQ(rows[3].size(), rows[0].size()) << "a short efforts list keeps the row's width";
  EXPECT_DOUBLE_EQ(std::stod(rows[3][col(rows[0], "q_l_shoulder_pitch")]), -3.0 + 0.5 + 2e-6);
  EXPECT_DOUBLE_EQ(std::stod(rows[3][col(rows[0], "effort_joint_2")]), -93.0);
  EXPECT_EQ(rows[3][col(rows[0], "effort_joint_63")], "") << "not measured";
  EXPECT_EQ(rows[3][col(rows[0], "applied_command_seq")], "18446744073709551612");
  EXPECT_EQ(rows[3][col(rows[0], "holding")], "0");
  const std::string csv_cmd = tempPath("command.csv");
  EXPECT_EQ(exportCsv(file, "reflex/joint_command", csv_cmd), 5u);
  rows = readCsv(csv_cmd);
  EXPECT_EQ(rows[2][col(rows[0], "valid_until_ns")], "-2");
  EXPECT_EQ(rows[2][col(rows[0], "state_seq")], "78");
  EXPECT_DOUBLE_EQ(std::stod(rows[2][col(rows[0], "qd_r_9")]), 2.5 + 1e-3);
  const std::string csv_contacts = tempPath("contacts.csv");
  EXPECT_EQ(exportCsv(file, "reflex/robot_contacts", csv_contacts), 5u);
  rows = readCsv(csv_contacts);
  ASSERT_EQ(rows.size(), 1u + 5u * 3u) << "one row per pair";
  EXPECT_EQ(rows[1][col(rows[0], "segment_a")], "l_forearm_0");
  EXPECT_DOUBLE_EQ(std::stod(rows[1][col(rows[0], "distance")]), -0.0015);
  EXPECT_EQ(rows[3][col(rows[0], "segment_a")], "");
  EXPECT_EQ(rows[3][col(rows[0], "n_contacts")], "3");
  const std::string csv_camera = tempPath("camera.csv");
  EXPECT_EQ(exportCsv(file, "reflex/camera_left", csv_camera), 5u);
  rows = readCsv(csv_camera);
  ASSERT_EQ(rows.size(), 6u);
  EXPECT_EQ(rows[2][col(rows[0], "format")], "png");
  EXPECT_EQ(rows[2][col(rows[0], "width")], "641");
  EXPECT_EQ(rows[2][col(rows[0], "bytes")], "20000");
  EXPECT_EQ(rows[2][col(rows[0], "capture_stamp_ns")], "-8");
  EXPECT_THROW(exportCsv(file, "reflex/nothing", csv), RecordError);

  // Play back two topics: the same samples arrive, headers untouched; with --restamp the stamps move.
  for (bool restamp : {false, true}) {
    bus::Participant sink(busConfig("sink"));
    auto& r_status = sink.makeReader<msg::ControlStatus>("reflex/control_status", bus::kProfileRecord);
    auto& r_hand = sink.makeReader<msg::HandTargets>();
    PlayerOptions po;
    po.input = file;
    po.topics = {"reflex/control_status", "reflex/hand_targets"};
    po.commands = true;  // hand targets are a command topic: played only when asked
    po.bus = busConfig("player");
    po.delay = 1.0;
    po.restamp = restamp;
    Player player(po);
    const std::int64_t before = bus::nowNs();
    player.run();
    EXPECT_EQ(player.stats().published, 10u);
    EXPECT_EQ(player.stats().loops, 1u);
    std::this_thread::sleep_for(200ms);
    std::vector<msg::ControlStatus> st;
    r_status.takeAll(st);
    ASSERT_EQ(st.size(), 5u) << (restamp ? "restamp" : "as recorded");
    for (int k = 0; k < 5; ++k) {
      msg::ControlStatus expected = sent.status[static_cast<std::size_t>(k)];
      if (restamp) {
        // Moved by (publish time - recorded receive time): the sample's age is what it was when recorded.
        const std::int64_t shift = st[static_cast<std::size_t>(k)].header().stamp_ns() - expected.header().stamp_ns();
        EXPECT_GE(shift, before - status_rx[static_cast<std::size_t>(k)]) << "moved to the playing time";
        EXPECT_LE(shift, bus::nowNs() - status_rx[static_cast<std::size_t>(k)]);
        expected.header().stamp_ns(st[static_cast<std::size_t>(k)].header().stamp_ns());
      }
      const auto d = bus::test::diffSample(expected, st[static_cast<std::size_t>(k)]);
      EXPECT_TRUE(d.empty()) << bus::test::join(d);
    }
    msg::HandTargets hand;
    ASSERT_TRUE(r_hand.takeLatest(hand));
    EXPECT_EQ(hand.left().position_base().y(), sent.hands.back().left().position_base().y());
  }

  // Play everything (no --topic): every recorded sample but the controller's protection state, a
  // live controller's claim that a replay must not make beside a live controller;
  // named with --topic it is played. By default observations only: the six command topics of this
  // recording (hand targets, priority, body schema, walk command, joint command, and the robot state a
  // controller over DDS computes from; 5 samples each) only with `commands`.
  // 13 types x 5 samples were recorded (the camera image is an observation: played by default).
  enum class Mode { kDefault, kCommands, kProtectionNamed };
  for (const Mode mode : {Mode::kDefault, Mode::kCommands, Mode::kProtectionNamed}) {
    PlayerOptions po;
    po.input = file;
    if (mode == Mode::kProtectionNamed) po.topics = {"reflex/controller_protection"};
    po.commands = mode == Mode::kCommands;
    po.bus = busConfig("player");
    po.delay = 0.2;
    po.rate = 0.0;  // as fast as possible
    Player player(po);
    player.run();
    const std::uint64_t expected = mode == Mode::kProtectionNamed ? 5u : mode == Mode::kCommands ? 60u : 30u;
    EXPECT_EQ(player.stats().published, expected) << static_cast<int>(mode);
    if (mode == Mode::kDefault) {
      EXPECT_EQ(player.commandsSkipped().size(), 6u);
    }
  }

  // A replayed command, restamped, keeps its age: its deadline and the answered state's stamp move
  // with its header (else a robot would get a command with a deadline in the past, or a forever one).
  {
    bus::Participant sink(busConfig("sink"));
    auto& r_cmd = sink.makeReader<msg::JointCommand>("reflex/joint_command", bus::kProfileRecord);
    PlayerOptions po;
    po.input = file;
    po.topics = {"reflex/joint_command"};
    po.commands = true;  // a command topic: played only when asked for
    po.bus = busConfig("player");
    po.delay = 1.0;
    po.restamp = true;
    Player player(po);
    player.run();
    std::this_thread::sleep_for(200ms);
    std::vector<msg::JointCommand> got;
    r_cmd.takeAll(got);
    ASSERT_FALSE(got.empty());
    for (const msg::JointCommand& c : got) {
      ASSERT_GE(c.header().seq(), 1000u);
      const msg::JointCommand& was = sent.command.at(c.header().seq() - 1000u);
      EXPECT_GT(c.header().stamp_ns(), was.header().stamp_ns()) << "restamped";
      EXPECT_EQ(c.valid_until_ns() - c.header().stamp_ns(), was.valid_until_ns() - was.header().stamp_ns())
          << "deadline moved with the stamp";
      EXPECT_EQ(c.state_stamp_ns() - c.header().stamp_ns(), was.state_stamp_ns() - was.header().stamp_ns());
    }
  }
}

// The controller's protection state is published once, before most recorders start: it is recorded
// by default (before: only with --late-joiner-state, so no recording said whether avoidance was on).
TEST(RecordBus, TheControllerProtectionPublishedBeforeTheRecorderStartedIsRecordedByDefault) {
  bus::Participant src(busConfig("controller"));
  auto& w = src.makeWriter<msg::ControllerProtection>();
  msg::ControllerProtection p;
  p.avoidance(false);
  p.estop(true);
  p.reason("--no-avoidance");
  p.period(0.005);
  p.robot("asimo_like");
  w.write(p);  // nobody listens yet; the writer keeps it (transient local)
  RecorderOptions ro;
  ro.output = tempPath("protection.rfx");
  ro.topics = {"reflex/controller_protection"};
  ro.duration = 4.0;
  ro.bus = busConfig("recorder");
  Recorder recorder(ro);
  recorder.run();
  RecordReader r(ro.output);
  RecordEntry e;
  ASSERT_TRUE(r.next(e)) << "the protection state is in the recording";
  const auto got = decode<msg::ControllerProtection>(e);
  EXPECT_FALSE(got.avoidance());
  EXPECT_TRUE(got.estop());
  EXPECT_EQ(got.reason(), "--no-avoidance");
  EXPECT_EQ(got.robot(), "asimo_like");
}

TEST(RecordBus, LateJoinerStateRecordsTheStatePublishedBeforeTheRecorderStarted) {
  bus::Participant src(busConfig("source"));
  auto& w = src.makeWriter<msg::HandTargets>();
  msg::HandTargets before = bus::test::handTargets(7);
  w.write(before);  // nobody listens yet; the writer keeps it (transient local)
  for (bool late : {false, true}) {
    RecorderOptions ro;
    ro.output = tempPath(late ? "late.rfx" : "not_late.rfx");
    ro.topics = {"reflex/hand_targets"};
    ro.late_joiner_state = late;
    ro.duration = 4.0;  // discovery + the transient-local resend take seconds on a loaded 2-core CI machine
    ro.bus = busConfig("recorder");
    Recorder recorder(ro);
    recorder.run();
    const RecordingInfo info = scanRecording(ro.output);
    EXPECT_EQ(info.records, late ? 1u : 0u) << (late ? "with" : "without") << " --late-joiner-state";
    if (late) {
      RecordReader r(ro.output);
      RecordEntry e;
      ASSERT_TRUE(r.next(e));
      const auto d = bus::test::diffSample(before, decode<msg::HandTargets>(e));
      EXPECT_TRUE(d.empty()) << bus::test::join(d);
    }
  }
}

// A recording made here: ControlStatus k = 0..20 received every 100 ms (2 s long).
std::string syntheticRecording() {
  const std::string file = tempPath("synthetic.rfx");
  RecordWriter w(file);
  const std::int64_t t0 = 1'700'000'000'000'000'000LL;
  for (int k = 0; k <= 20; ++k) {
    msg::ControlStatus s = bus::test::controlStatus(k);
    w.append(encodeEntry(s, t0 + k * 100'000'000LL));
  }
  return file;
}

struct Received {
  std::vector<std::uint64_t> seq;
  std::vector<double> t;  // steady seconds
};

Received playAndCollect(PlayerOptions po, std::chrono::milliseconds stop_after = 0ms) {
  bus::Participant sink(busConfig("sink"));
  auto& reader = sink.makeReader<msg::ControlStatus>("reflex/control_status", bus::kProfileRecord);
  Received got;
  po.bus = busConfig("player");
  po.delay = 1.0;
  Player player(po);
  std::atomic<bool> done{false};
  std::thread t([&] {
    player.run();
    done = true;
  });
  const auto start = std::chrono::steady_clock::now();
  while (!done) {
    msg::ControlStatus s;
    if (reader.waitForData(20ms)) {
      const double now = std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
      while (reader.takeNext(s)) {
        got.seq.push_back(s.header().seq());
        got.t.push_back(now);
      }
    }
    if (stop_after.count() > 0 && std::chrono::steady_clock::now() - start > stop_after) player.stop();
  }
  t.join();
  msg::ControlStatus s;
  std::this_thread::sleep_for(50ms);
  while (reader.takeNext(s)) got.seq.push_back(s.header().seq());
  return got;
}

TEST(RecordBus, PlayerKeepsTheTimingScaledByTheRateFromTheStartOffsetAndLoops) {
  const std::string file = syntheticRecording();
  {  // rate 2: 2 s of recording in 1 s
    PlayerOptions po;
    po.input = file;
    po.rate = 2.0;
    const Received r = playAndCollect(po);
    ASSERT_EQ(r.seq.size(), 21u);
    for (std::size_t k = 0; k < r.seq.size(); ++k) EXPECT_EQ(r.seq[k], 1000u + k);
    EXPECT_NEAR(r.t.back() - r.t.front(), 1.0, 0.1);
  }
  {  // start 1.2 s, rate 1: samples 12..20 over 0.8 s
    PlayerOptions po;
    po.input = file;
    po.start = 1.2;
    const Received r = playAndCollect(po);
    ASSERT_EQ(r.seq.size(), 9u);
    EXPECT_EQ(r.seq.front(), 1012u);
    EXPECT_EQ(r.seq.back(), 1020u);
    EXPECT_NEAR(r.t.back() - r.t.front(), 0.8, 0.1);
  }
  {  // loop a 0.3 s window (samples 5..8) at rate 1 for ~1.4 s of playing: several passes
    PlayerOptions po;
    po.input = file;
    po.start = 0.5;
    po.duration = 0.3;
    po.loop = true;
    const Received r = playAndCollect(po, 2400ms);
    ASSERT_GE(r.seq.size(), 12u);
    for (std::size_t k = 0; k < 12; ++k) EXPECT_EQ(r.seq[k], 1005u + k % 4) << k;
  }
}

TEST(RecordBus, BadOptionsAreClearErrors) {
  const std::string file = syntheticRecording();
  auto expectError = [](auto&& make, const std::string& needle) {
    try {
      make();
      ADD_FAILURE() << "no error for " << needle;
    } catch (const std::exception& e) {
      EXPECT_NE(std::string(e.what()).find(needle), std::string::npos) << e.what();
    }
  };
  PlayerOptions po;
  po.input = file;
  po.bus = busConfig("player");
  expectError(
      [&] {
        PlayerOptions o = po;
        o.rate = -2;
        Player p(o);
      },
      "-2");
  expectError(
      [&] {
        PlayerOptions o = po;
        o.start = 5.0;
        Player p(o);
      },
      "beyond the end");
  expectError(
      [&] {
        PlayerOptions o = po;
        o.topics = {"reflex/joint_state"};
        Player p(o);
      },
      "reflex/control_status");
  expectError(
      [&] {
        PlayerOptions o = po;
        o.input = tempPath("missing.rfx");
        Player p(o);
      },
      "missing.rfx");
  RecorderOptions ro;
  ro.output = tempPath("bad.rfx");
  ro.bus = busConfig("recorder");
  expectError(
      [&] {
        RecorderOptions o = ro;
        o.topics = {"reflex/jointstate"};
        Recorder r(o);
      },
      "reflex/jointstate");
  expectError(
      [&] {
        RecorderOptions o = ro;
        o.topics = {"my/topic:Joints"};
        Recorder r(o);
      },
      "Joints");
  expectError(
      [&] {
        RecorderOptions o = ro;
        o.exclude = {"x/y"};
        Recorder r(o);
      },
      "x/y");
  expectError(
      [&] {
        RecorderOptions o = ro;
        o.output = "/nonexistent_dir/r.rfx";
        Recorder r(o);
      },
      "/nonexistent_dir/r.rfx");
  const TopicSpec custom = parseTopicSpec("test/targets:HandTargets");
  EXPECT_EQ(custom.topic, "test/targets");
  ASSERT_NE(custom.codec, nullptr);
  EXPECT_EQ(custom.codec->typeName(), "reflex::msg::HandTargets");
  EXPECT_EQ(parseTopicSpec("x:reflex::msg::JointState").codec->shortName(), "JointState");
}

}  // namespace
}  // namespace reflex::record
