// Two separate executables over real DDS on a unique domain (47): bus_pub_program publishes every
// topic type, bus_sub_program receives and verifies each one field by field and exits 0. Then the
// publisher is stopped with SIGTERM and must exit 0 through its WaitSet loop (clean shutdown). A
// second case stops a lone publisher with SIGINT (domain 48).
#include <gtest/gtest.h>

#include "support/child_process.hpp"

#include <csignal>
#include <thread>

namespace reflex::bus::test {
namespace {

using namespace std::chrono_literals;
using namespace reflex::testing;  // ChildProcess, binPath (support/child_process.hpp)
const ChildOutput kPipe = ChildOutput::pipe();  // stdout through a pipe (readUntil, output)

TEST(TwoProcess, SubscriberVerifiesEveryTypeFromAnotherProcess) {
  ChildProcess sub({binPath("bus_sub_program"), "--domain", "47", "--types", "all", "--timeout-s", "20"}, kPipe);
  ChildProcess pub({binPath("bus_pub_program"), "--domain", "47", "--types", "all", "--max-seconds", "40"}, kPipe);
  ASSERT_NE(pub.readUntil("running", 10s).find("running"), std::string::npos) << pub.output();

  const int sub_code = sub.wait(30s);
  ASSERT_NE(sub_code, ChildProcess::kStillRunning) << "subscriber did not finish; output:\n" << sub.output();
  EXPECT_EQ(sub_code, 0) << sub.output();
  for (const char* type : {"object_targets", "hand_targets", "motion_priority", "body_schema",
                           "walk_command", "joint_state", "control_status", "heartbeat"}) {
    EXPECT_NE(sub.output().find(std::string("verified ") + type), std::string::npos) << type;
  }

  pub.signal(SIGTERM);
  const int pub_code = pub.wait(10s);
  ASSERT_NE(pub_code, ChildProcess::kStillRunning) << "publisher ignored SIGTERM";
  EXPECT_EQ(pub_code, 0);
  EXPECT_NE(pub.output().find("stopped by signal " + std::to_string(SIGTERM)), std::string::npos)
      << pub.output();
}

TEST(TwoProcess, SigintStopsTheRunLoopCleanly) {
  ChildProcess pub({binPath("bus_pub_program"), "--domain", "48", "--types", "joint_state",
                    "--max-seconds", "30"}, kPipe);
  ASSERT_NE(pub.readUntil("running", 10s).find("running"), std::string::npos) << pub.output();
  std::this_thread::sleep_for(200ms);  // let it publish a while
  pub.signal(SIGINT);
  const int code = pub.wait(10s);
  ASSERT_NE(code, ChildProcess::kStillRunning) << "publisher ignored SIGINT";
  EXPECT_EQ(code, 0);
  EXPECT_NE(pub.output().find("stopped by signal " + std::to_string(SIGINT)), std::string::npos)
      << pub.output();
}

// Issue 16, item 10: StopOnSignal (shared by every DDS process) stops the loop cleanly on every
// catchable terminating signal, not only SIGINT / SIGTERM (each of these killed the process before).
TEST(TwoProcess, EveryCatchableTerminatingSignalStopsTheRunLoopCleanly) {
  for (const int sig : {SIGHUP, SIGUSR1, SIGUSR2, SIGQUIT, SIGALRM, SIGVTALRM, SIGPROF, SIGPWR, SIGRTMIN, SIGRTMAX}) {
    SCOPED_TRACE("signal " + std::to_string(sig));
    ChildProcess pub({binPath("bus_pub_program"), "--domain", "48", "--types", "joint_state",
                      "--max-seconds", "30"}, kPipe);
    ASSERT_NE(pub.readUntil("running", 10s).find("running"), std::string::npos) << pub.output();
    pub.signal(sig);
    const int code = pub.wait(10s);
    ASSERT_NE(code, ChildProcess::kStillRunning) << "publisher ignored the signal";
    EXPECT_EQ(code, 0) << "killed instead of stopped: " << pub.output();
    EXPECT_NE(pub.output().find("stopped by signal " + std::to_string(sig)), std::string::npos) << pub.output();
  }
}

TEST(TwoProcess, ProgramsRejectBadArguments) {
  ChildProcess bad_domain({binPath("bus_pub_program"), "--domain", "999"}, kPipe);
  const int domain_code = bad_domain.wait(10s);
  EXPECT_NE(domain_code, ChildProcess::kStillRunning);
  EXPECT_NE(domain_code, 0);
  ChildProcess bad_type({binPath("bus_sub_program"), "--domain", "47", "--types", "no_such_type"}, kPipe);
  const int type_code = bad_type.wait(10s);
  EXPECT_NE(type_code, ChildProcess::kStillRunning);
  EXPECT_NE(type_code, 0);
}

}  // namespace
}  // namespace reflex::bus::test
