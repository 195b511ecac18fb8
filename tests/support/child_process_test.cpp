// ChildProcess and runShell against /bin/sh, whose behaviour POSIX fixes: `exit N` gives code N,
// a shell that kills itself with signal N gives 128 + N, `echo` writes exactly its argument and a
// newline, `sleep` outlives a short wait. A missing executable is reported, not thrown. runInChild
// returns a forked function's result, the signal that ended it, or kStillRunning for a blocked one.
#include "support/child_process.hpp"

#include <gtest/gtest.h>

#include <unistd.h>

#include <csignal>
#include <fstream>

namespace reflex::testing {
namespace {

using namespace std::chrono_literals;

TEST(ChildProcess, ExitCodeAndSignalAndTimeout) {
  ChildProcess seven({"/bin/sh", "-c", "exit 7"});
  ASSERT_TRUE(seven.started()) << seven.error();
  EXPECT_EQ(seven.wait(10s), 7);
  EXPECT_EQ(seven.wait(0ms), 7) << "the code is kept after the exit";
  EXPECT_FALSE(seven.signaled());

  ChildProcess self_kill({"/bin/sh", "-c", "kill -USR1 $$"});
  EXPECT_EQ(self_kill.wait(10s), 128 + SIGUSR1);
  EXPECT_TRUE(self_kill.signaled());

  ChildProcess sleeper({"/bin/sleep", "30"});
  EXPECT_EQ(sleeper.wait(100ms), ChildProcess::kStillRunning);
  const pid_t pid = sleeper.pid();
  EXPECT_EQ(sleeper.terminate(), 128 + SIGTERM);
  EXPECT_NE(::kill(pid, 0), 0) << "reaped: the pid no longer exists";
}

TEST(ChildProcess, PipeAndLogFileOutput) {
  ChildProcess piped({"/bin/sh", "-c", "echo first; sleep 0.2; echo second"}, ChildOutput::pipe());
  EXPECT_NE(piped.readUntil("first", 10s).find("first\n"), std::string::npos);
  EXPECT_EQ(piped.wait(10s), 0);
  EXPECT_EQ(piped.output(), "first\nsecond\n");

  const std::string log = ::testing::TempDir() + "child_process_test.log";
  ChildProcess logged({"/bin/sh", "-c", "echo out; echo err >&2; sleep 0.2; echo late"}, log);
  EXPECT_NE(logged.readUntil("late", 10s).find("late"), std::string::npos);
  EXPECT_EQ(logged.wait(10s), 0);
  EXPECT_EQ(logged.output(), "out\nerr\nlate\n") << "stdout and stderr share the log";
}

TEST(ChildProcess, MissingExecutableIsReportedNotThrown) {
  ChildProcess missing({"/nonexistent/reflex_tool"}, ChildOutput::pipe());
  EXPECT_FALSE(missing.started());
  EXPECT_NE(missing.error().find("/nonexistent/reflex_tool"), std::string::npos) << missing.error();
  EXPECT_EQ(missing.wait(10ms), ChildProcess::kStillRunning);
}

TEST(RunShell, SeparatesStdoutStderrAndExitCode) {
  const std::string err = ::testing::TempDir() + "run_shell_err.txt";
  const ProcessResult r = runShell("echo 'a b'; echo oops >&2; exit 3", err);
  EXPECT_EQ(r.exit_code, 3);
  EXPECT_EQ(r.out, "a b\n");
  EXPECT_EQ(r.err, "oops\n");
  EXPECT_EQ(runShell("sleep 30", err, 200ms).exit_code, -1) << "killed after the timeout";
  const ProcessResult merged = runShell("echo out; echo err >&2; exit 0");
  EXPECT_EQ(merged.exit_code, 0);
  EXPECT_EQ(merged.out, "out\nerr\n") << "no stderr path: stderr joins stdout";
  EXPECT_EQ(merged.err, "");
}

TEST(RunInChild, ResultSignalAndDeadline) {
  EXPECT_EQ(runInChild(10s, [] { return 42; }), 42);
  EXPECT_EQ(runInChild(10s, [] { return ::raise(SIGABRT); }), 128 + SIGABRT);
  EXPECT_EQ(runInChild(200ms, [] { return ::pause(); }), ChildProcess::kStillRunning) << "blocked: killed";
}

}  // namespace
}  // namespace reflex::testing
