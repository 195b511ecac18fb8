// The flagship experiment's outcome, shared by flagship_test (plain DDS) and
// security_flagship_test (DDS-Security): run bringup/flagship/run_flagship.py, read the summary.json
// that bringup/flagship/report.py writes, and check the criteria of the run with avoidance.
#pragma once

#include "support/child_process.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <regex>
#include <sstream>
#include <string>
#include <vector>

namespace reflex::flagship {

/// The text of a JSON object `"section": { ... }` in summary.json (report.py writes flat objects), or "".
inline std::string section(const std::string& json, const std::string& name) {
  const auto start = json.find("\"" + name + "\"");
  if (start == std::string::npos) return "";
  const auto end = json.find('}', start);
  return json.substr(start, end == std::string::npos ? std::string::npos : end - start);
}

/// The number after "key": inside the object `section` of summary.json; NaN if absent or NaN.
inline double field(const std::string& json, const std::string& name, const std::string& key) {
  const std::string obj = section(json, name);
  std::smatch m;
  if (!std::regex_search(obj, m, std::regex("\"" + key + "\": (-?[0-9.eE+-]+|NaN)"))) return std::nan("");
  return m[1] == "NaN" ? std::nan("") : std::stod(m[1]);
}

/// The boolean after "key": inside the object `section`: 1 true, 0 false, -1 absent.
inline int flag(const std::string& json, const std::string& name, const std::string& key) {
  const std::string obj = section(json, name);
  std::smatch m;
  if (!std::regex_search(obj, m, std::regex("\"" + key + "\": (true|false)"))) return -1;
  return m[1] == "true" ? 1 : 0;
}

struct Run {
  int exit_code = -1;   ///< run_flagship.py's exit code (-1: did not exit normally)
  std::string log;      ///< its stdout + stderr
  std::string summary;  ///< OUT/summary.json, "" if not written
};

/// The whole text of the file at `path` ("" if it cannot be read).
inline std::string fileText(const std::string& path) {
  std::ifstream in(path);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

/// Runs run_flagship.py --out `out` --build <build dir> `args` and reads its summary.json (any old one
/// is removed first, so a summary is always this run's).
inline Run runFlagship(const std::string& out, const std::string& args) {
  std::filesystem::remove(out + "/summary.json");
  const std::string cmd = std::string("/usr/bin/python3 ") + REFLEX_SOURCE_DIR +
                          "/bringup/flagship/run_flagship.py --out " + out + " --build " + REFLEX_BIN_DIR + "/.. " +
                          args;
  Run run;
  const reflex::testing::ProcessResult r = reflex::testing::runShell(cmd, "", std::chrono::minutes(15));
  run.log = r.out;
  run.exit_code = r.exit_code;
  run.summary = fileText(out + "/summary.json");
  return run;
}

/// run.json and the last `lines` lines of every *.log in `dir` (a run's folder), for a failure's output:
/// which link of the chain did not connect, what each process said when it ended.
inline std::string logTails(const std::string& dir, std::size_t lines = 12) {
  std::string text;
  std::error_code ec;
  std::vector<std::filesystem::path> files;
  for (const auto& e : std::filesystem::directory_iterator(dir, ec))
    if (e.path().extension() == ".log" || e.path().filename() == "run.json") files.push_back(e.path());
  std::sort(files.begin(), files.end());
  for (const auto& f : files) {
    std::ifstream in(f);
    std::vector<std::string> all;
    for (std::string line; std::getline(in, line);) all.push_back(line);
    text += "--- " + f.string() + " (last " + std::to_string(std::min(lines, all.size())) + " of " +
            std::to_string(all.size()) + " lines)\n";
    for (std::size_t i = all.size() > lines ? all.size() - lines : 0; i < all.size(); ++i) text += all[i] + "\n";
  }
  return text;
}

/// The run with avoidance (summary section "avoidance"): the arms come within the orange-zone bound of
/// 15 mm while the objects cross, no pair ever below d_r = 5 mm, no e-stop, the collision controller
/// took over (f > 0.5), both hands had a target most of the time and tracked reachable targets within
/// 20 mm (median), and the left target was lost at least once (the session hides the can). On a failure
/// (this or an earlier one of the test) prints logTails(run_dir).
inline void expectAvoidanceOutcome(const std::string& json, const std::string& run_dir) {
  SCOPED_TRACE("summary.json:\n" + json);
  const double d_on = field(json, "avoidance", "min_arm_distance_m");
  EXPECT_LT(d_on, 0.015) << "the arms come within the orange zone while the objects cross";
  EXPECT_GE(field(json, "avoidance", "min_distance_all_pairs_m"), 0.005) << "never below d_r";
  EXPECT_EQ(field(json, "avoidance", "estop_cycles"), 0.0);
  EXPECT_GT(field(json, "avoidance", "max_f"), 0.5) << "the collision controller took over";
  for (const char* side : {"left", "right"}) {
    const std::string s(side);
    EXPECT_GT(field(json, "avoidance", s + "_tracking_samples"), 1000.0) << side;
    EXPECT_LT(field(json, "avoidance", s + "_tracking_error_median_m"), 0.02) << side << " hand tracks its target";
    EXPECT_GT(field(json, "avoidance", s + "_given_fraction"), 0.6) << side << " hand had a target most of the time";
  }
  EXPECT_GE(field(json, "avoidance", "left_lost_events"), 1.0) << "the session hides the can for a while";
  if (::testing::Test::HasFailure()) std::printf("the run's logs:\n%s", logTails(run_dir).c_str());
}

}  // namespace reflex::flagship
