// The flagship experiment's outcome (issue 7, item 4), asserted on real processes: the shipped session
// replayed through reflex_vision -> reflex_behavior -> reflex_controller over DDS (run_flagship.py),
// with and without avoidance. With avoidance the arms come within 15 mm while the objects cross, never
// below d_r, the e-stop never fires and the hands track reachable targets; without it they penetrate.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <fstream>
#include <regex>
#include <sstream>
#include <string>
#include <sys/wait.h>

namespace {

/// The number after "key": inside the object of `section` in summary.json.
double field(const std::string& json, const std::string& section, const std::string& key) {
  const auto start = json.find("\"" + section + "\"");
  if (start == std::string::npos) return std::nan("");
  const auto end = json.find('}', start);
  const std::string obj = json.substr(start, end - start);
  std::smatch m;
  if (!std::regex_search(obj, m, std::regex("\"" + key + "\": (-?[0-9.eE+-]+|NaN)"))) return std::nan("");
  return m[1] == "NaN" ? std::nan("") : std::stod(m[1]);
}

TEST(Flagship, AvoidanceKeepsTheCrossingArmsApartAndWithoutItTheyPenetrate) {
  const std::string out = ::testing::TempDir() + "reflex_flagship_test";
  const std::string cmd = std::string("/usr/bin/python3 ") + REFLEX_SOURCE_DIR + "/bringup/flagship/run_flagship.py --out " +
                          out + " --build " + REFLEX_BIN_DIR + "/.. --domain 74 2>&1";
  FILE* p = popen(cmd.c_str(), "r");
  ASSERT_NE(p, nullptr);
  std::string log;
  char buf[4096];
  while (fgets(buf, sizeof buf, p)) log += buf;
  const int status = pclose(p);
  ASSERT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << log;
  std::ifstream in(out + "/summary.json");
  ASSERT_TRUE(in.good()) << log;
  std::stringstream ss;
  ss << in.rdbuf();
  const std::string json = ss.str();

  const double d_on = field(json, "avoidance", "min_arm_distance_m");
  EXPECT_LT(d_on, 0.015) << "the arms come within the orange zone while the objects cross\n" << json;
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
  EXPECT_LT(field(json, "no_avoidance", "min_arm_distance_m"), 0.0) << "without avoidance the arms penetrate";
}

}  // namespace
