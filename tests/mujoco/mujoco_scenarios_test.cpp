// The paper's seven scenarios on the physics robot:
// `reflex_sim all --robot mujoco` spawns reflex_mujoco (a separate process, MuJoCo) per run on its own
// DDS domain (190..194 here) and drives it over DDS through OnboardController + DdsRobotPort in real
// time, with the same scenario scripts as the kinematic plant.
//
// Independent answers:
//   - MuJoCo's own collision detection on the same capsules, with contact margin d_r (RobotContacts,
//     published by the robot process with each state): with avoidance no sample names a pair, and
//     the judge was heard (at least one RobotContacts sample per cycle or so);
//   - our distance module on the MEASURED joint positions (what the robot reported, not what was
//     commanded): no cycle has a physical pair below d_r, and no e-stop fired;
//   - without avoidance (target_inside_body drives the right hand into the body) MuJoCo reports
//     contacts and the measured state goes below d_r: the judge can fail; MuJoCo's smallest distance
//     (the robot's exit summary, over every state it published) and ours on the measured state name
//     the same pair and agree within 1 mm (MuJoCo's <= ours);
//   - --robot dds attaches to a reflex_mujoco this test started itself (no spawn by reflex_sim);
//   - bad values are named: an unknown --robot, a domain out of range, no robot on the bus.
// The tracking error and servo lag are printed (the summaries), bounded loosely (the machine is loaded).
//
// All seven pass since reflex_mujoco's servo stops its velocity feed-forward once the
// reference reaches the commanded position (before, walking_target_behind and grasped_bar, whose pair
// sits at the guard's floor of 6.0 mm on the kinematic plant, went 1-3 mm below d_r and fired the e-stop).
#include "support/child_process.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <regex>
#include <sstream>
#include <string>
#include <vector>

namespace {

using namespace std::chrono_literals;
using reflex::testing::ChildProcess;
namespace fs = std::filesystem;

const std::vector<std::string> kScenarios = {"target_inside_body", "through_body",          "one_vs_three_dof",
                                             "crossing_arms",      "walking_target_behind", "grasped_bar",
                                             "occlusion"};

std::string bin(const std::string& name) { return std::string(REFLEX_BIN_DIR) + "/" + name; }

std::string readFile(const fs::path& path) {
  std::ifstream in(path);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

fs::path outDir(const std::string& name) {
  const fs::path dir = fs::path(::testing::TempDir()) / ("mujoco_scenarios_" + name);
  fs::remove_all(dir);
  return dir;
}

/// Runs reflex_sim with `args` (its output in dir/reflex_sim.log); its exit code.
int runSim(const std::vector<std::string>& args, const fs::path& dir, std::chrono::seconds timeout) {
  fs::create_directories(dir);
  std::vector<std::string> argv = {bin("reflex_sim")};
  argv.insert(argv.end(), args.begin(), args.end());
  ChildProcess sim(argv, (dir / "reflex_sim.log").string());
  EXPECT_TRUE(sim.started());
  return sim.wait(std::chrono::duration_cast<std::chrono::milliseconds>(timeout));
}

/// The figures one run's block of summary.txt states.
struct Figures {
  bool found = false;
  std::string robot;
  double min_distance_mm = -1e9;
  bool estop = true, non_finite = true;
  long below_d_r = -1, contact_samples = -1, contacts_received = -1, contact_steps = -1;
  double rms_mrad[2] = {-1, -1}, max_mrad[2] = {-1, -1}, lag_ms[2] = {-1, -1};
  double mujoco_min_mm = 1e9;  ///< MuJoCo's smallest contact distance (1e9: none reported)
  std::string mujoco_pair, min_pair;
  long cycles = -1, late_cycles = -1;  ///< the controller's cycles, and those that began a period late or more
  double lateFraction() const {
    return cycles > 0 ? static_cast<double>(late_cycles) / static_cast<double>(cycles) : 1.0;
  }
};

Figures parse(const std::string& block) {
  Figures f;
  std::smatch m;
  if (std::regex_search(block, m, std::regex(R"(robot\s+(\w+))"))) f.robot = m[1];
  if (std::regex_search(block, m, std::regex(R"(min distance\s+(-?[0-9.e+-]+) mm at t = \S+ s \(([^)]*)\))"))) {
    f.min_distance_mm = std::stod(m[1]);
    f.min_pair = m[2];
  }
  if (std::regex_search(block, m, std::regex(R"(smallest (-?[0-9.e+-]+) mm \(([^)]*)\))"))) {
    f.mujoco_min_mm = std::stod(m[1]);
    f.mujoco_pair = m[2];
  }
  if (std::regex_search(block, m, std::regex(R"(e-stop fired\s+(\w+))"))) f.estop = m[1] != "no";
  if (std::regex_search(block, m, std::regex(R"(non-finite output\s+(\w+))"))) f.non_finite = m[1] != "no";
  if (std::regex_search(block, m, std::regex(R"(measured below d_r\s+(\d+) cycles)"))) f.below_d_r = std::stol(m[1]);
  if (std::regex_search(block, m,
                        std::regex(R"(MuJoCo contacts\s+(\d+) of (\d+) RobotContacts samples.*contact steps (\d+))"))) {
    f.contact_samples = std::stol(m[1]);
    f.contacts_received = std::stol(m[2]);
    f.contact_steps = std::stol(m[3]);
    f.found = true;
  }
  if (std::regex_search(block, m, std::regex(R"(\n\s*cycles (\d+), )"))) f.cycles = std::stol(m[1]);
  if (std::regex_search(block, m, std::regex(R"(late cycles (\d+))"))) f.late_cycles = std::stol(m[1]);
  const char* side[2] = {"left", "right"};
  for (int a = 0; a < 2; ++a)
    if (std::regex_search(
            block, m,
            std::regex(std::string(side[a]) +
                       R"( arm tracking\s+max ([0-9.e+-]+) mrad, RMS ([0-9.e+-]+) mrad, lag ([0-9.e+-]+) ms)"))) {
      f.max_mrad[a] = std::stod(m[1]);
      f.rms_mrad[a] = std::stod(m[2]);
      f.lag_ms[a] = std::stod(m[3]);
    }
  return f;
}

/// Every run's block in a summary.txt (one_vs_three_dof has two).
std::vector<Figures> parseSummary(const fs::path& path) {
  const std::string text = readFile(path);
  std::vector<Figures> out;
  std::size_t pos = text.find("scenario ");
  while (pos != std::string::npos) {
    const std::size_t next = text.find("\nscenario ", pos + 1);
    out.push_back(parse(text.substr(pos, next == std::string::npos ? std::string::npos : next - pos)));
    pos = next == std::string::npos ? next : next + 1;
  }
  return out;
}

/// The smallest distance reflex_mujoco's exit summary names (lines "contact A,B min distance X mm": per
/// pair, over every state it published) and its pair as "A-B".
struct RobotMinimum {
  bool found = false;
  double mm = 1e9;
  std::string pair;
};

RobotMinimum robotMinimum(const std::string& log) {
  RobotMinimum out;
  const std::regex line(R"(contact (\S+),(\S+) min distance (-?[0-9.]+) mm)");
  for (std::sregex_iterator it(log.begin(), log.end(), line), end; it != end; ++it) {
    const double mm = std::stod((*it)[3]);
    if (mm < out.mm) out = {true, mm, (*it)[1].str() + "-" + (*it)[2].str()};
  }
  return out;
}

/// What in a run is not the avoidance outcome asserted on the physics robot ("" when all is).
std::string avoidanceFailure(const Figures& f) {
  std::ostringstream o;
  if (f.robot != "mujoco") o << "robot '" << f.robot << "'; ";
  if (f.contacts_received <= 500) o << "the judge was not heard (" << f.contacts_received << " samples); ";
  if (f.non_finite) o << "non-finite output; ";
  if (f.contact_samples != 0) o << "MuJoCo reported a pair closer than d_r in " << f.contact_samples << " samples; ";
  if (f.contact_steps != 0) o << f.contact_steps << " MuJoCo contact steps; ";
  if (f.below_d_r != 0) o << f.below_d_r << " measured cycles below d_r; ";
  if (!(f.min_distance_mm >= 5.0)) o << "min distance " << f.min_distance_mm << " mm; ";
  if (f.estop) o << "e-stop fired; ";
  for (int a = 0; a < 2; ++a) {
    // loose: a loaded machine makes the robot hold now and then
    if (!(f.rms_mrad[a] >= 0.0 && f.rms_mrad[a] < 30.0)) o << "tracking RMS " << f.rms_mrad[a] << " mrad; ";
    if (!(f.lag_ms[a] <= 100.0)) o << "servo lag " << f.lag_ms[a] << " ms; ";
  }
  std::string out = o.str();
  if (!out.empty()) out.resize(out.size() - 2);  // the last "; "
  return out;
}

// The controller runs in real time beside the robot: a machine that stalls the controller process
// (not the robot) lets the robot go on with the last command while no new one comes. Reproduced by
// hand (SIGSTOP of reflex_sim for 25 ms every 100 ms, the robot left running): grasped_bar, whose
// hands sit 1 mm above d_r by design (the guard's floor, 6.0 mm on the kinematic plant), went to
// 4.5 mm and the e-stop fired; that is what a fresh-clone .ci/run on a loaded VM met (robot loop
// overruns in the same minute). So a run whose controller began more than kDisturbedLate of its cycles a period late or
// more is not judged: it is run again (at most 3 runs), each retry named. A failure in a run the
// machine did not disturb fails at once.
constexpr double kDisturbedLate = 0.02;

TEST(MujocoScenarios, AllSevenAvoidOnThePhysicsRobot) {
  const fs::path dir = outDir("all");
  const int rc =
      runSim({"all", "--robot", "mujoco", "--domain", "190", "--no-plots", "--out", dir.string()}, dir, 240s);
  ASSERT_EQ(rc, 0) << readFile(dir / "reflex_sim.log");
  for (const auto& name : kScenarios) {
    fs::path summary = dir / name / "summary.txt";
    std::string disturbed_failures;
    for (int attempt = 1;; ++attempt) {
      const auto runs = parseSummary(summary);
      ASSERT_EQ(runs.size(), name == "one_vs_three_dof" ? 2U : 1U) << name << "\n" << readFile(summary);
      std::string failure;
      double late = 0.0;
      for (const Figures& f : runs) {
        ASSERT_TRUE(f.found) << name << ": no MuJoCo contact line\n" << readFile(summary);
        std::printf(
            "%-22s robot %s: min distance %.2f mm, MuJoCo contacts %ld of %ld samples, below d_r %ld, "
            "tracking L max %.2f RMS %.3f mrad lag %.1f ms, R max %.2f RMS %.3f mrad lag %.1f ms, late cycles "
            "%ld of %ld\n",
            name.c_str(), f.robot.c_str(), f.min_distance_mm, f.contact_samples, f.contacts_received, f.below_d_r,
            f.max_mrad[0], f.rms_mrad[0], f.lag_ms[0], f.max_mrad[1], f.rms_mrad[1], f.lag_ms[1], f.late_cycles,
            f.cycles);
        const std::string run_failure = avoidanceFailure(f);
        failure += (failure.empty() || run_failure.empty() ? "" : "; ") + run_failure;
        late = std::max(late, f.lateFraction());
      }
      if (failure.empty()) break;
      char why[160];
      std::snprintf(why, sizeof why, "the controller began %.1f %% of its cycles a period late or more", 100.0 * late);
      if (!(late > kDisturbedLate)) {
        ADD_FAILURE() << name << ": " << failure << " in a run the machine did not disturb (" << why << ")\n"
                      << disturbed_failures << readFile(summary);
        break;
      }
      disturbed_failures += "  attempt " + std::to_string(attempt) + ": " + failure + "; " + why + "\n";
      if (attempt == 3) {
        ADD_FAILURE() << name << ": every run was disturbed by the machine and failed:\n" << disturbed_failures;
        break;
      }
      std::printf("%s: %s and the outcome failed (%s); running it again (attempt %d of 3)\n", name.c_str(), why,
                  failure.c_str(), attempt + 1);
      const fs::path again = dir / (name + "_again" + std::to_string(attempt));
      ASSERT_EQ(
          runSim({name, "--robot", "mujoco", "--domain", "190", "--no-plots", "--out", again.string()}, again, 90s), 0)
          << readFile(again / "reflex_sim.log");
      summary = again / "summary.txt";
    }
  }
}

TEST(MujocoScenarios, WithoutAvoidanceMujocoReportsContacts) {
  const fs::path dir = outDir("no_avoidance");
  const int rc = runSim({"target_inside_body", "--robot", "mujoco", "--domain", "191", "--no-avoidance", "--no-plots",
                         "--out", dir.string()},
                        dir, 90s);
  ASSERT_EQ(rc, 0) << readFile(dir / "reflex_sim.log");
  const auto runs = parseSummary(dir / "summary.txt");
  ASSERT_EQ(runs.size(), 1U);
  const Figures& f = runs[0];
  ASSERT_TRUE(f.found) << readFile(dir / "summary.txt");
  std::printf(
      "without avoidance: min distance %.2f mm, MuJoCo contacts %ld of %ld samples (%ld steps), below d_r %ld\n",
      f.min_distance_mm, f.contact_samples, f.contacts_received, f.contact_steps, f.below_d_r);
  EXPECT_GT(f.contact_samples, 10);
  EXPECT_GT(f.contact_steps, 10);
  EXPECT_GT(f.below_d_r, 10);
  EXPECT_LT(f.min_distance_mm, 5.0);
  // Two independent distance measurements of the same contact: MuJoCo's collision detection on every
  // state the robot published (1 kHz; its exit summary keeps the smallest per pair) and our distance
  // module on the measured state of each 5 ms cycle, one of those published states. So MuJoCo's
  // smallest is at most ours; the pushed-back hand rests, so they meet (seen: equal to 1e-3 mm, the
  // robot's printed precision). The summary's "smallest" cannot serve here: it is over the
  // RobotContacts samples reflex_sim took (KEEP_LAST 1, one per cycle), and the sample of the state a
  // cycle measured may still be in flight when the cycle polls (CI, stop 24: ours 1.3 um below it).
  const RobotMinimum robot = robotMinimum(readFile(dir / "reflex_mujoco.log"));
  ASSERT_TRUE(robot.found) << readFile(dir / "reflex_mujoco.log");
  std::printf("robot's own smallest: %.3f mm (%s); ours %.4f mm (%s)\n", robot.mm, robot.pair.c_str(),
              f.min_distance_mm, f.min_pair.c_str());
  EXPECT_EQ(robot.pair, f.min_pair);
  EXPECT_LE(robot.mm, f.min_distance_mm + 1e-3);
  EXPECT_LT(f.min_distance_mm - robot.mm, 1.0);
  // The summary's sampled smallest is never below the robot's own (it is over a subset of its states).
  EXPECT_GE(f.mujoco_min_mm, robot.mm - 1e-3);
}

TEST(MujocoScenarios, AttachesToARobotAlreadyOnTheBus) {
  const fs::path dir = outDir("attach");
  fs::create_directories(dir);
  // A robot already running, at its own start posture (all joints 0): the scenario starts from where it is.
  ChildProcess robot({bin("reflex_mujoco"), "--domain", "192", "--name", "attached_robot"},
                     (dir / "robot.log").string());
  ASSERT_TRUE(robot.started());
  const int rc = runSim(
      {"target_inside_body", "--robot", "dds", "--domain", "192", "--no-plots", "--out", dir.string()}, dir, 90s);
  ASSERT_EQ(rc, 0) << readFile(dir / "reflex_sim.log");
  const auto runs = parseSummary(dir / "summary.txt");
  ASSERT_EQ(runs.size(), 1U);
  EXPECT_EQ(runs[0].robot, "dds");
  EXPECT_GT(runs[0].contacts_received, 500);
  EXPECT_EQ(runs[0].contact_samples, 0);
  EXPECT_EQ(runs[0].below_d_r, 0);
  EXPECT_FALSE(runs[0].estop);
  EXPECT_NE(readFile(dir / "reflex_sim.log").find("joining on domain 192"), std::string::npos);
}

TEST(MujocoScenarios, BadValuesAreNamed) {
  const fs::path dir = outDir("bad");
  EXPECT_NE(runSim({"through_body", "--robot", "gazebo", "--out", dir.string()}, dir, 30s), 0);
  EXPECT_NE(readFile(dir / "reflex_sim.log").find("gazebo"), std::string::npos) << readFile(dir / "reflex_sim.log");
  EXPECT_NE(runSim({"through_body", "--robot", "mujoco", "--domain", "300", "--out", dir.string()}, dir, 30s), 0);
  EXPECT_NE(readFile(dir / "reflex_sim.log").find("300"), std::string::npos) << readFile(dir / "reflex_sim.log");
  // No robot on domain 193: named, with the domain and the wait.
  EXPECT_EQ(runSim({"through_body", "--robot", "dds", "--domain", "193", "--robot-wait", "1", "--no-plots", "--out",
                    dir.string()},
                   dir, 30s),
            2);  // a robot that cannot be set up: refused (docs/tools.md, "Exit codes")
  const std::string log = readFile(dir / "reflex_sim.log");
  EXPECT_NE(log.find("no reflex/robot_state on domain 193 within 1 s"), std::string::npos) << log;
}

}  // namespace
