// Tests of control/tools/inspect_main.cpp: reflex_inspect run as a real process. Its CSV and JSON
// output must match the library's results for the same joint values; bad input must give a clear
// message and a non-zero exit.
#include "reflex/control/distance.hpp"
#include "reflex/control/kinematics.hpp"
#include "test_support.hpp"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <sys/wait.h>

#include <cctype>
#include <cstdio>
#include <fstream>
#include <map>
#include <sstream>
#include <string>
#include <vector>

namespace reflex::control {
namespace {

using ::testing::HasSubstr;

using test::ProcessResult;
using test::slurp;

ProcessResult inspect(const std::string& args) { return test::runTool("reflex_inspect", args); }

std::vector<std::string> split(const std::string& s, char sep) {
  std::vector<std::string> out;
  std::stringstream ss(s);
  std::string item;
  while (std::getline(ss, item, sep)) out.push_back(item);
  return out;
}

struct CsvRow {
  std::string a, b;
  double d;
  Eigen::Vector3d pa, pb;
};

/// Parses the CSV output: lines starting with '#' are comments; the first other line is the header.
std::vector<CsvRow> parseCsv(const std::string& out, std::string& header) {
  std::vector<CsvRow> rows;
  header.clear();
  for (const std::string& line : split(out, '\n')) {
    if (line.empty() || line[0] == '#') continue;
    if (header.empty()) {
      header = line;
      continue;
    }
    const auto f = split(line, ',');
    EXPECT_EQ(f.size(), 9u) << line;
    if (f.size() != 9) continue;
    rows.push_back({f[0],
                    f[1],
                    std::stod(f[2]),
                    {std::stod(f[3]), std::stod(f[4]), std::stod(f[5])},
                    {std::stod(f[6]), std::stod(f[7]), std::stod(f[8])}});
  }
  return rows;
}

// Minimal JSON syntax check (RFC 8259 grammar, no semantic checks): returns true if `s` is one value.
class JsonChecker {
 public:
  explicit JsonChecker(const std::string& s) : s_(s) {}
  bool valid() {
    ws();
    if (!value()) return false;
    ws();
    return i_ == s_.size();
  }

 private:
  void ws() {
    while (i_ < s_.size() && std::isspace(static_cast<unsigned char>(s_[i_]))) ++i_;
  }
  bool lit(const char* w) {
    const std::string t(w);
    if (s_.compare(i_, t.size(), t) != 0) return false;
    i_ += t.size();
    return true;
  }
  bool str() {
    if (s_[i_] != '"') return false;
    for (++i_; i_ < s_.size(); ++i_) {
      if (s_[i_] == '\\') {
        ++i_;
      } else if (s_[i_] == '"') {
        ++i_;
        return true;
      } else if (static_cast<unsigned char>(s_[i_]) < 0x20) {
        return false;
      }
    }
    return false;
  }
  bool num() {
    const std::size_t start = i_;
    if (s_[i_] == '-') ++i_;
    if (i_ >= s_.size() || !std::isdigit(static_cast<unsigned char>(s_[i_]))) return false;
    while (i_ < s_.size() && (std::isdigit(static_cast<unsigned char>(s_[i_])) || s_[i_] == '.' || s_[i_] == 'e' ||
                              s_[i_] == 'E' || s_[i_] == '+' || s_[i_] == '-'))
      ++i_;
    try {
      std::stod(s_.substr(start, i_ - start));
    } catch (...) {
      return false;
    }
    return true;
  }
  bool value() {
    if (i_ >= s_.size()) return false;
    const char c = s_[i_];
    if (c == '{') return container('}', true);
    if (c == '[') return container(']', false);
    if (c == '"') return str();
    if (c == 't') return lit("true");
    if (c == 'f') return lit("false");
    if (c == 'n') return lit("null");
    return num();
  }
  bool container(char close, bool object) {
    ++i_;
    ws();
    if (i_ < s_.size() && s_[i_] == close) {
      ++i_;
      return true;
    }
    while (true) {
      ws();
      if (object) {
        if (i_ >= s_.size() || !str()) return false;
        ws();
        if (i_ >= s_.size() || s_[i_] != ':') return false;
        ++i_;
        ws();
      }
      if (!value()) return false;
      ws();
      if (i_ >= s_.size()) return false;
      if (s_[i_] == ',') {
        ++i_;
        continue;
      }
      if (s_[i_] == close) {
        ++i_;
        return true;
      }
      return false;
    }
  }
  const std::string& s_;
  std::size_t i_ = 0;
};

TEST(InspectJsonChecker, AcceptsAndRejects) {
  EXPECT_TRUE(JsonChecker(R"({"a": [1, -2.5e-3, "x"], "b": {"c": null}, "d": true})").valid());
  EXPECT_FALSE(JsonChecker(R"({"a": [1, 2,]})").valid());
  EXPECT_FALSE(JsonChecker(R"({"a": 1)").valid());
  EXPECT_FALSE(JsonChecker(R"({"a": nan})").valid());
}

/// The library's answer for the same robot and joint values.
struct Expected {
  Model model;
  DistanceData dist;
  explicit Expected(const std::string& robot, const std::map<std::string, double>& joints = {})
      : model(testing::loadRobot(robot)), dist(model) {
    Eigen::VectorXd q(model.nq);
    for (int i = 0; i < model.nq; ++i) q[i] = std::min(std::max(0.0, model.q_lower[i]), model.q_upper[i]);
    for (const auto& [name, v] : joints) q[model.qIndex(name)] = v;
    KinematicsData kin(model);
    EXPECT_TRUE(computeForwardKinematics(model, kin, q));
    computeSegmentDistances(model, kin, dist);
  }
};

void expectCsvMatchesLibrary(const ProcessResult& r, const Expected& e) {
  ASSERT_EQ(r.exit_code, 0) << r.err;
  std::string header;
  const auto rows = parseCsv(r.out, header);
  EXPECT_EQ(header, "segment_a,segment_b,distance_m,pa_x,pa_y,pa_z,pb_x,pb_y,pb_z");
  std::vector<const PairDistance*> active;
  for (const PairDistance& pd : e.dist.pairs)
    if (pd.active) active.push_back(&pd);
  ASSERT_EQ(rows.size(), active.size());
  for (std::size_t i = 0; i < rows.size(); ++i) {
    const PairDistance& pd = *active[i];
    EXPECT_EQ(rows[i].a, e.model.segments[pd.seg_a].name);
    EXPECT_EQ(rows[i].b, e.model.segments[pd.seg_b].name);
    // Printed with 6 decimals.
    EXPECT_NEAR(rows[i].d, pd.distance, 5.1e-7);
    EXPECT_LT((rows[i].pa - pd.p_B_a).cwiseAbs().maxCoeff(), 5.1e-7);
    EXPECT_LT((rows[i].pb - pd.p_B_b).cwiseAbs().maxCoeff(), 5.1e-7);
  }
  const PairDistance& c = e.dist.pairs[e.dist.closest];
  EXPECT_THAT(r.out, HasSubstr("# closest: " + e.model.segments[c.seg_a].name + "," + e.model.segments[c.seg_b].name));
}

TEST(Inspect, HelpExitsZero) {
  const ProcessResult r = inspect("--help");
  EXPECT_EQ(r.exit_code, 0);
  EXPECT_THAT(r.out, HasSubstr("--q"));
  EXPECT_THAT(r.out, HasSubstr("--csv"));
  EXPECT_THAT(r.out, HasSubstr("--format"));
}

TEST(Inspect, CsvOfTheShippedRobotAtZeroMatchesTheLibrary) {
  const ProcessResult r = inspect(testing::robotPath("asimo_like.urdf"));
  expectCsvMatchesLibrary(r, Expected(testing::kAsimo));
  EXPECT_THAT(r.out, HasSubstr("# robot asimo_like: 17 segments"));
  EXPECT_TRUE(r.err.empty()) << r.err;
}

TEST(Inspect, JointValuesFromTheCommandLine) {
  const std::map<std::string, double> q = {
      {"l_shoulder_pitch", -1.2}, {"l_elbow", -1.9}, {"neck_yaw", 0.4}, {"r_shoulder_roll", -0.6}};
  const ProcessResult r = inspect(testing::robotPath("asimo_like.urdf") +
                                  " --q l_shoulder_pitch=-1.2 l_elbow=-1.9 --q neck_yaw=0.4 --q r_shoulder_roll=-0.6");
  expectCsvMatchesLibrary(r, Expected(testing::kAsimo, q));
}

TEST(Inspect, JointValuesFromACsvRow) {
  const std::string csv = ::testing::TempDir() + "reflex_inspect_q.csv";
  std::ofstream(csv) << "time,l_elbow,r_elbow,body_pitch\n0.0,-0.5,-0.5,0.1\n0.1,-2.0,-1.0,0.2\n";
  const ProcessResult r = inspect(testing::robotPath("asimo_like.urdf") + " --csv " + csv + " --row 1");
  expectCsvMatchesLibrary(r, Expected(testing::kAsimo, {{"l_elbow", -2.0}, {"r_elbow", -1.0}, {"body_pitch", 0.2}}));
  // A --q after the CSV overrides it.
  const ProcessResult r2 = inspect(testing::robotPath("asimo_like.urdf") + " --csv " + csv + " --q l_elbow=-0.1");
  expectCsvMatchesLibrary(r2, Expected(testing::kAsimo, {{"l_elbow", -0.1}, {"r_elbow", -0.5}, {"body_pitch", 0.1}}));
}

TEST(Inspect, JsonParsesAndMatches) {
  const ProcessResult r = inspect(testing::robotPath("asimo_like.urdf") + " --format json --q l_elbow=-1.0");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(JsonChecker(r.out).valid()) << r.out;
  const Expected e(testing::kAsimo, {{"l_elbow", -1.0}});
  int active = 0;
  for (const PairDistance& pd : e.dist.pairs) active += pd.active;
  std::size_t pos = 0;
  int pairs = 0;
  while ((pos = r.out.find("\"distance\":", pos)) != std::string::npos) {
    ++pairs;
    ++pos;
  }
  EXPECT_EQ(pairs, active + 1);  // + the closest pair
  char closest[160];
  const PairDistance& c = e.dist.pairs[e.dist.closest];
  std::snprintf(closest, sizeof closest, "\"closest\": {\"a\": \"%s\", \"b\": \"%s\", \"distance\": %.6f}",
                e.model.segments[c.seg_a].name.c_str(), e.model.segments[c.seg_b].name.c_str(), c.distance);
  EXPECT_THAT(r.out, HasSubstr(closest));
  const ProcessResult segs = inspect(testing::robotPath("asimo_like.urdf") + " --format json --segments");
  ASSERT_EQ(segs.exit_code, 0) << segs.err;
  EXPECT_TRUE(JsonChecker(segs.out).valid()) << segs.out;
}

TEST(Inspect, SecondHumanoidWithBoxWarnings) {
  const ProcessResult r = inspect(testing::robotPath("small_humanoid.urdf") + " --q l_elbow=-1.4 --q waist_yaw=0.5");
  expectCsvMatchesLibrary(r, Expected(testing::kSmall, {{"l_elbow", -1.4}, {"waist_yaw", 0.5}}));
  EXPECT_THAT(r.err, HasSubstr("warning:"));
  EXPECT_THAT(r.err, HasSubstr("m fitted with"));
  EXPECT_THAT(r.err, HasSubstr("corners enclosed, fitted volume / box volume"));
  const ProcessResult j = inspect(testing::robotPath("small_humanoid.urdf") + " --format json");
  ASSERT_EQ(j.exit_code, 0);
  EXPECT_TRUE(JsonChecker(j.out).valid());
}

TEST(Inspect, ExplicitConfigFile) {
  const std::string yaml = ::testing::TempDir() + "reflex_inspect.collision.yaml";
  std::ofstream(yaml) << "exclude_adjacent: true\n";
  const ProcessResult r = inspect(testing::robotPath("asimo_like.urdf") + " --config " + yaml);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  std::string header;
  EXPECT_EQ(parseCsv(r.out, header).size(), 136u - 16u);
}

TEST(Inspect, BadInputGivesAClearMessageAndNonZeroExit) {
  const std::string bad_urdf = ::testing::TempDir() + "reflex_inspect_bad.urdf";
  std::ofstream(bad_urdf) << "<robot name='x'><link name='a'>";
  struct Case {
    std::string args;
    std::vector<std::string> message;
  };
  const std::string asimo = testing::robotPath("asimo_like.urdf");
  const std::vector<Case> cases = {
      {bad_urdf, {bad_urdf, "malformed URDF"}},
      {"/nonexistent/robot.urdf", {"/nonexistent/robot.urdf", "cannot open"}},
      {asimo + " --q l_elbw=0.1", {"unknown joint 'l_elbw'"}},
      {asimo + " --q l_elbow=abc", {"'abc' is not a finite number"}},
      {asimo + " --q l_elbow=nan", {"'nan' is not a finite number"}},
      {asimo + " --q l_elbow=0.5", {"l_elbow", "0.5", "outside its limits"}},
      {asimo + " --q l_elbow", {"'l_elbow'", "name=value"}},
      {asimo + " --csv /nonexistent/q.csv", {"/nonexistent/q.csv"}},
      {asimo + " --format xml", {"xml"}},
      {asimo + " --config /nonexistent/c.yaml", {"/nonexistent/c.yaml"}},
  };
  for (const Case& c : cases) {
    const ProcessResult r = inspect(c.args);
    EXPECT_NE(r.exit_code, 0) << c.args;
    for (const auto& m : c.message) EXPECT_THAT(r.err, HasSubstr(m)) << c.args;
  }
}

}  // namespace
}  // namespace reflex::control
