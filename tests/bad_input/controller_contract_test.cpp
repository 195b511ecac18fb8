// The controller process's contract under the second-round attack, with the real
// reflex_controller over real DDS. Domains 182..188.
//  item 3:  protection. `avoidance: off` in the controller YAML switches avoidance off but never the
//           e-stop: crossing targets latch it (the exit line counts e-stops), and the banner, the exit
//           line and reflex/controller_protection (read here as a late joiner would) say the run is not
//           fully protected; only --disable-estop switches the e-stop off, loudly. The banner's rate
//           is computed from the configured period (100 Hz for period 0.01).
//  item 4:  liveliness of the target source is tied to the participant that wrote the targets:
//           heartbeats named like the source from ANOTHER participant, or the controller's own
//           heartbeats when the targets claim to come from "controller", keep nothing alive (the
//           right elbow goes back towards rest within --input-timeout); the source's own heartbeats do.
//  item 10: SIGHUP, SIGUSR2, SIGALRM and a real-time signal stop the controller like SIGTERM (exit 0,
//           summary, every cycle in the --log file); a stderr without a reader (SIGPIPE) does not end it.
//  item 14: the --log file is written while the controller runs; a write error during the run (file
//           size limit) is exit code 3 naming the file and the reason.
//  item 16: a second controller on the same domain refuses to start, naming the first one; the first
//           one reports it; the protection sample names the robot.
#include "controller_run.hpp"

#include <csignal>
#include <cstdio>

namespace reflex::bad_input {
namespace {

/// Rows of a CSV file without its header (0 if missing).
long csvRows(const std::string& path) {
  const std::string text = readFile(path);
  const long lines = static_cast<long>(std::count(text.begin(), text.end(), '\n'));
  return lines > 0 ? lines - 1 : 0;
}

/// Waits for the controller's protection sample (reliable, transient local: a late joiner gets it).
bool takeProtection(bus::Reader<msg::ControllerProtection>& reader, msg::ControllerProtection& out) {
  if (!reader.waitForData(10s)) return false;
  return reader.takeNext(out);
}

// Item 3: avoidance off in the file, the e-stop stays on and the run says it is not protected.
TEST(ControllerContract, AvoidanceOffInTheYamlKeepsTheEstopAndEveryOutputSaysSo) {
  const std::string yaml = ::testing::TempDir() + "contract_avoidance_off.yaml";
  writeFile(yaml, "avoidance: off\nperiod: 0.01\n");
  ControllerRun run(182, 6.0, "avoidance_off", {"--controller", yaml});
  ASSERT_TRUE(run.started());
  auto& protection = run.watch->makeReader<msg::ControllerProtection>();
  auto& targets = run.source->makeWriter<msg::HandTargets>();
  auto& hb = run.source->makeWriter<msg::Heartbeat>();
  ASSERT_TRUE(run.waitMatched(targets));
  msg::ControllerProtection p;
  ASSERT_TRUE(takeProtection(protection, p));
  EXPECT_FALSE(p.avoidance());
  EXPECT_TRUE(p.estop()) << "a file never switches the e-stop off";
  EXPECT_NE(p.reason().find("'avoidance: off' in " + yaml), std::string::npos) << p.reason();
  EXPECT_DOUBLE_EQ(p.period(), 0.01);
  run.pump(3500ms, 50ms, [&](int) {
    msg::HandTargets t = crossingTargets();
    targets.publish(t);
    msg::Heartbeat h = heartbeat("bad_source");
    hb.publish(h);
  });
  run.drain();
  ASSERT_FALSE(run.statuses.empty());
  EXPECT_TRUE(run.statuses.back().left().estop_latched()) << "the colliding arms latched the e-stop";

  ExitSummary s;
  ASSERT_EQ(run.finish(s), 0) << run.output;
  ASSERT_TRUE(s.found) << run.output;
  EXPECT_GE(s.estops, 1) << run.output;
  EXPECT_GT(s.min_distance_mm, 0.0) << "stopped before the arms went through each other";
  EXPECT_NE(run.output.find("running at 100.0 Hz (period 10.000 ms)"), std::string::npos) << run.output;
  EXPECT_NE(
      run.output.find("WARNING: THIS RUN IS NOT PROTECTED: collision avoidance OFF by 'avoidance: off' in " + yaml),
      std::string::npos)
      << run.output;
  EXPECT_NE(run.output.find("protection REDUCED: collision avoidance OFF"), std::string::npos) << "exit line\n"
                                                                                               << run.output;
}

// Item 3: the e-stop goes off only by its own loud option, and the run says so everywhere.
TEST(ControllerContract, OnlyDisableEstopSwitchesTheEstopOffAndItIsLoud) {
  ControllerRun run(183, 5.0, "estop_off", {"--no-avoidance", "--disable-estop"});
  ASSERT_TRUE(run.started());
  auto& protection = run.watch->makeReader<msg::ControllerProtection>();
  auto& targets = run.source->makeWriter<msg::HandTargets>();
  auto& hb = run.source->makeWriter<msg::Heartbeat>();
  ASSERT_TRUE(run.waitMatched(targets));
  msg::ControllerProtection p;
  ASSERT_TRUE(takeProtection(protection, p));
  EXPECT_FALSE(p.avoidance());
  EXPECT_FALSE(p.estop());
  EXPECT_NE(p.reason().find("E-STOP OFF by --disable-estop"), std::string::npos) << p.reason();
  run.pump(3000ms, 50ms, [&](int) {
    msg::HandTargets t = crossingTargets();
    targets.publish(t);
    msg::Heartbeat h = heartbeat("bad_source");
    hb.publish(h);
  });
  ExitSummary s;
  ASSERT_EQ(run.finish(s), 0) << run.output;
  ASSERT_TRUE(s.found) << run.output;
  EXPECT_EQ(s.estops, 0) << "switched off on purpose";
  EXPECT_NE(run.output.find("THIS RUN IS NOT PROTECTED: collision avoidance OFF by --no-avoidance; E-STOP OFF by "
                            "--disable-estop"),
            std::string::npos)
      << run.output;
  EXPECT_NE(run.output.find("protection REDUCED"), std::string::npos) << run.output;
}

// Item 4: the source is killed; another participant keeps sending heartbeats with its name (and with
// the controller's). The hands must retract within --input-timeout.
TEST(ControllerContract, HeartbeatsFromAnotherParticipantDoNotKeepAKilledSourceAlive) {
  ControllerRun run(184, 10.0, "liveliness_fake");
  ASSERT_TRUE(run.started());
  auto& targets = run.source->makeWriter<msg::HandTargets>();
  auto& hb = run.source->makeWriter<msg::Heartbeat>();
  ASSERT_TRUE(run.waitMatched(targets));
  run.drain();
  const double rest = run.latestJoint("r_elbow");
  ASSERT_TRUE(std::isfinite(rest));
  run.pump(2000ms, 100ms, [&](int) {
    msg::HandTargets t = reachable();
    targets.publish(t);
    msg::Heartbeat h = heartbeat("bad_source");
    hb.publish(h);
  });
  const double reaching = run.latestJoint("r_elbow");
  ASSERT_GT(std::abs(reaching - rest), 0.1) << "the right arm reached forward";
  // Targets stop, the source's own heartbeats go on: alive (no retraction) for 2 s > input timeout.
  run.pump(2000ms, 100ms, [&](int) {
    msg::Heartbeat h = heartbeat("bad_source");
    hb.publish(h);
  });
  EXPECT_LT(std::abs(run.latestJoint("r_elbow") - reaching), 0.02) << "the genuine heartbeats keep the source alive";

  // The source dies; a faker (another participant) claims its name and the controller's.
  run.source.reset();
  bus::BusConfig config;
  config.module_name = "faker";
  config.domain_id = 184;
  bus::Participant faker(config);
  auto& fake_hb = faker.makeWriter<msg::Heartbeat>();
  run.pump(3000ms, 100ms, [&](int) {
    for (const char* name : {"bad_source", "controller"}) {
      msg::Heartbeat h = heartbeat(name);
      fake_hb.publish(h);
    }
  });
  const double after = run.latestJoint("r_elbow");
  EXPECT_GT(std::abs(after - reaching), 0.05) << "the arm retracts although heartbeats named 'bad_source' go on";
  run.expectSafeAndFinite();

  ExitSummary s;
  ASSERT_EQ(run.finish(s), 0) << run.output;
  ASSERT_TRUE(s.found) << run.output;
  EXPECT_EQ(s.stale, 1) << "declared stale once: after the kill, not before";
}

// Item 4: targets whose Header.source is "controller" (the controller's own heartbeat name) and no
// heartbeat from their writer: stale after --input-timeout.
TEST(ControllerContract, ASourceNamedLikeTheControllerGoesStaleWhenSilent) {
  ControllerRun run(185, 6.0, "liveliness_name");
  ASSERT_TRUE(run.started());
  auto& targets = run.source->makeWriter<msg::HandTargets>();
  ASSERT_TRUE(run.waitMatched(targets));
  run.pumpCount(15, 100ms, [&](int) {
    msg::HandTargets t = reachable();
    t.header().source("controller");
    t.header().stamp_ns(bus::nowNs());
    targets.write(t);  // header as given
  });
  const double reaching = run.latestJoint("r_elbow");
  run.pump(2500ms, 50ms, [](int) {});
  EXPECT_GT(std::abs(run.latestJoint("r_elbow") - reaching), 0.05) << "the right arm moved back towards rest";
  ExitSummary s;
  ASSERT_EQ(run.finish(s), 0) << run.output;
  ASSERT_TRUE(s.found) << run.output;
  EXPECT_GE(s.stale, 1) << run.output;
}

// Items 10 and 14: catchable signals stop the controller cleanly; its log is streamed and complete.
TEST(ControllerContract, HangUpUser2AlarmAndRealTimeSignalsStopCleanlyWithTheWholeLog) {
  const int signals[] = {SIGHUP, SIGUSR2, SIGALRM, SIGRTMIN + 2};
  for (const int sig : signals) {
    SCOPED_TRACE("signal " + std::to_string(sig));
    const std::string csv = ::testing::TempDir() + "contract_signal_" + std::to_string(sig) + ".csv";
    std::remove(csv.c_str());
    ControllerRun run(186, 20.0, "signal_" + std::to_string(sig), {"--log", csv});
    ASSERT_TRUE(run.started());
    ASSERT_TRUE(run.status->waitForWriters(1, 15s));
    run.pump(1500ms, 50ms, [](int) {});
    EXPECT_GT(csvRows(csv), 50) << "rows reach the file while the controller runs";
    run.signal(sig);
    ExitSummary s;
    ASSERT_EQ(run.finish(s), 0) << "not killed by the signal:\n" << run.output;
    ASSERT_TRUE(s.found) << run.output;
    EXPECT_GT(s.cycles, 100) << "ran about 1.5 s (fewer cycles on a loaded host: the loop re-anchors when late)";
    EXPECT_EQ(csvRows(csv), s.cycles) << "one row per cycle, none lost";
    EXPECT_NE(run.output.find("(dropped 0)"), std::string::npos) << run.output;
  }
}

// Item 10: stderr is a pipe whose reader is gone before the first line; the controller runs on,
// exits 0 and its log holds every cycle.
TEST(ControllerContract, AStderrWithoutReaderDoesNotEndTheController) {
  std::signal(SIGPIPE, SIG_DFL);  // the child must not inherit an ignored SIGPIPE from this test
  const std::string csv = ::testing::TempDir() + "contract_sigpipe.csv";
  const std::string rc_file = ::testing::TempDir() + "contract_sigpipe.rc";
  std::remove(csv.c_str());
  std::remove(rc_file.c_str());
  const std::string script = "'" + controllerExe() + "' --domain 187 --duration 3 --log '" + csv +
                             "' 2>&1 | (exit 0); echo ${PIPESTATUS[0]} > '" + rc_file + "'";
  testing::ChildProcess shell({"/bin/bash", "-c", script});
  ASSERT_TRUE(shell.started());
  ASSERT_EQ(shell.wait(30s), 0);
  const std::string rc = readFile(rc_file);
  EXPECT_EQ(rc, "0\n") << "exit status of reflex_controller (141 = SIGPIPE)";
  EXPECT_GT(csvRows(csv), 300) << "about 3 s at 200 Hz";
}

// Item 14: a write error during the run (the file size limit) is not success.
TEST(ControllerContract, ALogWriteErrorDuringTheRunIsExitCode3NamingTheFile) {
  const std::string csv = ::testing::TempDir() + "contract_fsize.csv";
  const std::string out = ::testing::TempDir() + "contract_fsize.log";
  std::remove(csv.c_str());
  // ulimit -f counts 1024-byte blocks in bash: 16 KB hold the header and a few dozen rows.
  // UDP only: Fast DDS's shared-memory segments would exceed the limit themselves.
  const std::string script = "ulimit -f 16; exec '" + controllerExe() +
                             "' --domain 187 --participant-profile reflex_participant_udp --duration 2 --log '" + csv +
                             "'";
  testing::ChildProcess shell({"/bin/bash", "-c", script}, out);
  ASSERT_TRUE(shell.started());
  const int rc = shell.wait(30s);
  const std::string text = readFile(out);
  EXPECT_EQ(rc, 3) << text;
  EXPECT_NE(text.find("cannot write the --log file '" + csv + "': File too large"), std::string::npos) << text;
  EXPECT_TRUE(parseSummary(text).found) << "the summary is printed anyway\n" << text;
}

// Item 16: one controller per domain.
TEST(ControllerContract, ASecondControllerOnTheDomainRefusesToStart) {
  ControllerRun first(188, 10.0, "first_controller");
  ASSERT_TRUE(first.started());
  auto& protection = first.watch->makeReader<msg::ControllerProtection>();
  ASSERT_TRUE(first.status->waitForWriters(1, 15s));
  msg::ControllerProtection p;
  ASSERT_TRUE(takeProtection(protection, p));
  EXPECT_TRUE(p.avoidance() && p.estop()) << "default: fully protected";
  EXPECT_EQ(p.reason(), "");
  EXPECT_EQ(p.robot(), "asimo_like");
  EXPECT_EQ(p.header().source(), "controller");

  const std::string log = ::testing::TempDir() + "contract_second_controller.log";
  // The second one refuses at start if discovery is faster than its 1 s probe, else it leaves its
  // loop as soon as it discovers the first (measured: 0.5 to 3 s); either way refused: exit 2, naming it.
  const auto t0 = std::chrono::steady_clock::now();
  testing::ChildProcess second({controllerExe(), "--domain", "188", "--duration", "30", "--name", "controller_b"}, log);
  ASSERT_TRUE(second.started());
  const int rc = second.wait(20s);
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  const std::string text = readFile(log);
  EXPECT_EQ(rc, 2) << text;
  EXPECT_NE(text.find("another controller ('controller', robot 'asimo_like') already runs on DDS domain 188"),
            std::string::npos)
      << text;
  EXPECT_LT(seconds, 10.0) << "stopped long before its 30 s";
  std::printf("second controller: exit %d after %.2f s, %s\n", rc, seconds,
              text.find("running at") == std::string::npos ? "refused at start" : "left its loop on discovery");

  ExitSummary s;
  ASSERT_EQ(first.finish(s), 0) << first.output;
  ASSERT_TRUE(s.found) << first.output;
  EXPECT_NE(first.output.find("another controller ('controller_b', robot 'asimo_like')"), std::string::npos)
      << "the first one says a second one showed up\n"
      << first.output;
}

}  // namespace
}  // namespace reflex::bad_input
