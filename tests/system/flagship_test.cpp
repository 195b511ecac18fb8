// The flagship experiment's outcome, asserted on real processes: the shipped session
// replayed through reflex_vision -> reflex_behavior -> reflex_controller over DDS (run_flagship.py),
// with and without avoidance. With avoidance the arms come within 15 mm while the objects cross, never
// below d_r, the e-stop never fires and the hands track reachable targets; without it they penetrate.
// The criteria of the run with avoidance are flagship_outcome.hpp's, shared with the secure run
// (tests/security/flagship_test.cpp).
#include "flagship_outcome.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <regex>
#include <string>
#include <vector>

namespace {

using reflex::flagship::field;
using reflex::flagship::fileText;

TEST(Flagship, AvoidanceKeepsTheCrossingArmsApartAndWithoutItTheyPenetrate) {
  const std::string out = ::testing::TempDir() + "reflex_flagship_test";
  const reflex::flagship::Run run = reflex::flagship::runFlagship(out, "--domain 74");
  ASSERT_EQ(run.exit_code, 0) << run.log;
  ASSERT_FALSE(run.summary.empty()) << run.log;
  const std::string& json = run.summary;

  EXPECT_EQ(reflex::flagship::flag(json, "avoidance", "secure"), 0) << "a plain run\n" << json;
  reflex::flagship::expectAvoidanceOutcome(json, out + "/avoidance");
  EXPECT_LT(field(json, "no_avoidance", "min_arm_distance_m"), 0.0) << "without avoidance the arms penetrate\n" << json;
  // The report's strip draws the robot with the live view's renderer (headless Chromium), not 2D sticks.
  EXPECT_NE(json.find("\"strip_robot\": \"3d\""), std::string::npos) << json;
  // Its panels are different moments (at least 2 s apart, so no two show the same crossing), the
  // closest approach among them.
  std::smatch m;
  ASSERT_TRUE(std::regex_search(
      json, m, std::regex(R"re("panels_s":\s*\[([^\]]*)\][^}]*"closest_approach_s":\s*([-0-9.eE]+))re")))
      << json;
  std::vector<double> panels;
  const std::string list = m[1].str();
  const std::regex number(R"([-0-9.eE]+)");
  for (std::sregex_iterator it(list.begin(), list.end(), number), end; it != end; ++it)
    panels.push_back(std::stod(it->str()));
  const double closest = std::stod(m[2].str());
  ASSERT_GE(panels.size(), 3U) << json;
  for (std::size_t i = 1; i < panels.size(); ++i) EXPECT_GE(panels[i] - panels[i - 1], 2.0 - 1e-3) << json;
  EXPECT_NE(std::find(panels.begin(), panels.end(), closest), panels.end()) << json;
}

}  // namespace

namespace {

/// A build folder whose bin/ holds the real executables (symbolic links) except reflex_behavior: a
/// script that, while `deaf_starts` > 0 (counted in a file beside it), runs without ever hearing the
/// controller (no status line; a link that does not connect), then execs the real reflex_behavior.
std::string buildWithDeafBehavior(const std::string& dir, int deaf_starts) {
  namespace fs = std::filesystem;
  fs::remove_all(dir);
  fs::create_directories(dir + "/bin");
  for (const auto& e : fs::directory_iterator(REFLEX_BIN_DIR))
    if (e.path().filename() != "reflex_behavior")
      fs::create_symlink(e.path(), dir + "/bin/" + e.path().filename().string());
  {
    std::ofstream(dir + "/deaf_starts_left") << deaf_starts << "\n";
    std::ofstream script(dir + "/bin/reflex_behavior");
    script << "#!/bin/sh\n"
           << "left=$(cat " << dir << "/deaf_starts_left)\n"
           << "if [ \"$left\" -gt 0 ]; then echo $((left - 1)) > " << dir << "/deaf_starts_left; exec sleep 600; fi\n"
           << "exec " << REFLEX_BIN_DIR << "/reflex_behavior \"$@\"\n";
  }
  fs::permissions(dir + "/bin/reflex_behavior", fs::perms::owner_all);
  return dir;
}

/// run_flagship.py --only on on domain 76 with TempDir()/`name`/build (buildWithDeafBehavior,
/// `deaf_starts`) and `args`, its output into TempDir()/`name`/out.
reflex::testing::ProcessResult runWithDeafBehavior(const std::string& name, int deaf_starts, const std::string& args,
                                                   std::chrono::milliseconds timeout) {
  const std::string base = ::testing::TempDir() + name;
  const std::string build = buildWithDeafBehavior(base + "/build", deaf_starts);
  return reflex::testing::runShell(std::string("/usr/bin/python3 ") + REFLEX_SOURCE_DIR +
                                       "/bringup/flagship/run_flagship.py --out " + base + "/out --build " + build +
                                       " --domain 76 --only on --no-report " + args,
                                   "", timeout);
}

}  // namespace

// run_flagship.py's start-up (a CI failure: a secure run went 64 s with no object
// reaching the controller): a chain whose behavior does not hear the controller within --ready-timeout
// is stopped and started again, the failure named in the log and run.json, the failed attempt's logs
// kept; the second chain runs the session. The session at 4x speed, avoidance only, domain 76.
// --ready-timeout 12: the deaf attempt waits that long, and the real second chain must connect
// within it on a loaded machine (4 s was tight for controller start + discovery + the 1 s stat lines).
TEST(FlagshipStartup, ALinkThatDoesNotConnectRestartsTheChainAndTheRunGoesOn) {
  const std::string dir = ::testing::TempDir() + "reflex_flagship_startup_test/out/avoidance";
  const reflex::testing::ProcessResult r =
      runWithDeafBehavior("reflex_flagship_startup_test", 1, "--rate 4 --ready-timeout 12", std::chrono::minutes(5));
  ASSERT_EQ(r.exit_code, 0) << r.out;
  const std::string failure = "start-up: reflex_behavior received no joint state from reflex_controller in 12 s (see " +
                              dir + "/behavior.attempt1.log)";
  EXPECT_NE(r.out.find("flagship: " + failure + "; stopping the chain and starting it again (attempt 2 of 3)"),
            std::string::npos)
      << r.out;
  const std::string note = fileText(dir + "/run.json");
  EXPECT_NE(note.find("\"startup_failures\": [\n    \"" + failure + "\"\n  ]"), std::string::npos) << note;
  for (const char* kept : {"behavior.attempt1.log", "controller.attempt1.log", "recorder.attempt1.log"})
    EXPECT_TRUE(std::filesystem::exists(dir + "/" + kept)) << kept;
  // The second chain connected and ran: behavior heard the controller, the controller got targets.
  std::smatch m;
  const std::string behavior = fileText(dir + "/behavior.log"), controller = fileText(dir + "/controller.log");
  ASSERT_TRUE(std::regex_search(behavior, m, std::regex(R"(reflex_behavior: stats .* joint_states=(\d+) )")))
      << behavior;
  EXPECT_GT(std::stol(m[1]), 0) << behavior;
  ASSERT_TRUE(std::regex_search(controller, m, std::regex(R"(targets (\d+) \(rejected 0\))"))) << controller;
  EXPECT_GT(std::stol(m[1]), 50) << controller;
  EXPECT_NE(fileText(dir + "/vision.log").find("reflex_vision: 2 reader(s) matched after"), std::string::npos)
      << fileText(dir + "/vision.log");
  if (::testing::Test::HasFailure()) std::printf("the run's logs:\n%s", reflex::flagship::logTails(dir).c_str());
}

// Three chains in a row that do not connect: the run ends with exit 1 naming each failure, never a run
// without targets. Domain 76.
TEST(FlagshipStartup, AChainThatNeverConnectsEndsTheRunNamingEachAttempt) {
  const std::string dir = ::testing::TempDir() + "reflex_flagship_startup_never_test/out/avoidance";
  const reflex::testing::ProcessResult r =
      runWithDeafBehavior("reflex_flagship_startup_never_test", 3, "--ready-timeout 2", std::chrono::minutes(3));
  EXPECT_EQ(r.exit_code, 1) << r.out;
  // One line naming the three attempts; each names the behavior (and, if it had not recorded within the
  // 2 s either, the recorder) and the attempt's kept log.
  const std::string head = "flagship: error: the chain did not connect in 3 attempts: ";
  const auto at = r.out.find(head);
  ASSERT_NE(at, std::string::npos) << r.out;
  std::string line = r.out.substr(at + head.size());
  line = line.substr(0, line.find('\n'));
  std::vector<std::string> attempts;
  for (std::size_t from = 0;;) {
    const auto bar = line.find(" | ", from);
    attempts.push_back(line.substr(from, bar == std::string::npos ? std::string::npos : bar - from));
    if (bar == std::string::npos) break;
    from = bar + 3;
  }
  ASSERT_EQ(attempts.size(), 3u) << line;
  for (std::size_t a = 0; a < 3; ++a) {
    EXPECT_EQ(attempts[a].rfind("start-up: reflex_behavior received no joint state from reflex_controller", 0), 0u)
        << attempts[a];
    EXPECT_NE(attempts[a].find(" in 2 s (see " + dir + "/behavior.attempt" + std::to_string(a + 1) + ".log"),
              std::string::npos)
        << attempts[a];
  }
  EXPECT_FALSE(std::filesystem::exists(dir + "/vision.log")) << "vision started on a chain that was not connected";

  const reflex::testing::ProcessResult bad =
      runWithDeafBehavior("reflex_flagship_startup_bad_test", 0, "--ready-timeout -1", std::chrono::minutes(1));
  EXPECT_EQ(bad.exit_code, 2) << bad.out;
  EXPECT_NE(bad.out.find("run_flagship.py: error: --ready-timeout -1: must be a number of seconds >= 0 "
                         "(0: the default)"),
            std::string::npos)
      << bad.out;
}
