// Tests of reflex_setup (control/tools/setup_main.cpp, robot_setup.hpp), run as a real process on the
// three shipped robots, a variant with a gap and generated robots without clear arms. Checked against:
//   - the robots' generators (make_*.py): the arm joints, hand, shoulder, head and camera link names in
//     their URDFs (written out below);
//   - the project's own readers: loadControllerConfig + makeControllerModel, loadCollisionConfig +
//     loadModel, loadFitOverlay, and the behavior layer's loadHostConfig + BehaviorHost (robot links
//     resolved, the scripted module's targets taken from the host's outputs);
//   - the distance module at the rest posture (every pair with an arm segment above d_a, except pairs this
//     test finds can never get that far apart by sampling the arms itself) and at every cycle of a 4 s
//     closed-loop run of the OnboardController with the written files (never below d_r, both hands within
//     1 cm of the behavior's targets);
//   - the analytic gap of the variant (forearm capsule surface ending 6 cm before the wrist: 0.060 m at
//     the wrist) and exact messages for ambiguous and missing arms.
#include "reflex/control/controller.hpp"
#include "reflex/control/distance.hpp"
#include "reflex/control/kinematics.hpp"
#include "reflex/control/mesh_fit.hpp"
#include "reflex/control/onboard.hpp"
#include "reflex/modules/host.hpp"
#include "reflex/modules/registry.hpp"
#include "test_support.hpp"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <sys/wait.h>

#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

namespace reflex::control {
namespace {

using ::testing::HasSubstr;
using ::testing::Not;
namespace fs = std::filesystem;

using test::ProcessResult;
using test::slurp;

ProcessResult setupRun(const std::string& args) { return test::runTool("reflex_setup", args); }

std::string freshDir(const std::string& name) {
  const std::string dir = ::testing::TempDir() + "reflex_setup_" + name;
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir;
}

class RecordingSink final : public modules::OutputSink {
 public:
  modules::HandTarget left, right;
  void handTargets(const modules::HandTarget& l, const modules::HandTarget& r) override {
    left = l;
    right = r;
  }
  void motionPriority(modules::ArmPriority) override {}
  void segmentAttached(const modules::SegmentSpec&) override {}
  void segmentDetached(const std::string&) override {}
  void walk(const modules::WalkGoal&) override {}
};

// Ground truth: the names make_asimo_like.py, make_small_humanoid.py and make_mesh_humanoid.py write.
struct Truth {
  std::string robot;
  std::string extra_args;
  std::vector<std::string> left_joints;
  std::string left_shoulder, head, camera;
  bool meshes = false;
};

std::vector<std::string> mirror(const std::vector<std::string>& left) {
  std::vector<std::string> r;
  for (const auto& j : left) r.push_back("r" + j.substr(1));
  return r;
}

std::string str(const std::vector<std::string>& v) {
  std::string s;
  for (const auto& x : v) s += x + " ";
  return s;
}

class ShippedRobot : public ::testing::TestWithParam<Truth> {};

TEST_P(ShippedRobot, FindsTheKnownArmsHeadAndARestClearOfTheBodyAndTheFilesWorkInClosedLoop) {
  const Truth& truth = GetParam();
  const std::string urdf = testing::robotPath(truth.robot + ".urdf");
  const std::string dir = freshDir(truth.robot);
  const ProcessResult r = setupRun(urdf + " --out " + dir + " " + truth.extra_args);
  ASSERT_EQ(r.exit_code, 0) << r.out << r.err;
  EXPECT_THAT(r.out, Not(HasSubstr("warning"))) << "the shipped robots have no gaps";
  EXPECT_THAT(r.out, Not(HasSubstr("right arm mirrored except"))) << "their arms are mirror images";
  // One line per decision, each with its reason.
  for (const char* d : {"arms: left [", "left hand: link '", "right hand: link '", "head: link '", "camera: link '",
                        "rest: left hand ", "behavior: both hands to", "pairs: 5000 sampled configurations"})
    EXPECT_THAT(r.out, HasSubstr(d));

  // collision.yaml (and the fit) load with the project's readers; the model the controller will use.
  const CollisionConfig cc = loadCollisionConfig(dir + "/collision.yaml");
  if (truth.meshes) {
    EXPECT_FALSE(cc.srdf.empty());
    EXPECT_FALSE(cc.fit.empty());
    EXPECT_FALSE(loadFitOverlay(dir + "/" + truth.robot + ".fit.yaml").links.empty());
  }
  const Model model = loadModel(urdf, cc);

  // controller.yaml: the known chains and hands.
  const ControllerConfig config = loadControllerConfig(dir + "/controller.yaml");
  EXPECT_EQ(str(config.arms[kLeft].joints), str(truth.left_joints));
  EXPECT_EQ(str(config.arms[kRight].joints), str(mirror(truth.left_joints)));
  EXPECT_EQ(config.arms[kLeft].hand_link, "l_hand");
  EXPECT_EQ(config.arms[kRight].hand_link, "r_hand");
  const ControllerModel cm = makeControllerModel(model, config);

  // The rest posture: inside the limits, every arm pair above d_a at it (a pair the arms can never
  // take that far apart, found by this test's own sampling, at least 80 % of its sampled maximum).
  Eigen::VectorXd q_rest(model.nq);
  for (int i = 0; i < model.nq; ++i) q_rest[i] = std::min(std::max(0.0, model.q_lower[i]), model.q_upper[i]);
  for (const auto& arm : cm.arms)
    for (int i = 0; i < arm.n; ++i) {
      EXPECT_GE(arm.rest[i], model.q_lower[arm.q[i]]);
      EXPECT_LE(arm.rest[i], model.q_upper[arm.q[i]]);
      q_rest[arm.q[i]] = arm.rest[i];
    }
  const std::size_t npairs = model.pairs.size();
  Eigen::VectorXd max_d = Eigen::VectorXd::Zero(static_cast<Eigen::Index>(npairs));
  Eigen::VectorXd min_d = Eigen::VectorXd::Constant(static_cast<Eigen::Index>(npairs), 1e9);
  KinematicsData kin(model);
  DistanceData dist(model);
  std::mt19937_64 rng(7);
  for (int k = 0; k < 3000; ++k) {
    const Eigen::VectorXd qr = test::randomConfiguration(model, rng);
    Eigen::VectorXd q = q_rest;
    for (const auto& arm : cm.arms)
      for (int i = 0; i < arm.n; ++i) q[arm.q[i]] = qr[arm.q[i]];
    computeForwardKinematics(model, kin, q);
    computeSegmentDistances(model, kin, dist);
    for (std::size_t i = 0; i < model.pairs.size(); ++i) {
      max_d[static_cast<Eigen::Index>(i)] = std::max(max_d[static_cast<Eigen::Index>(i)], dist.pairs[i].distance);
      min_d[static_cast<Eigen::Index>(i)] = std::min(min_d[static_cast<Eigen::Index>(i)], dist.pairs[i].distance);
    }
  }
  computeForwardKinematics(model, kin, q_rest);
  computeSegmentDistances(model, kin, dist);
  const std::uint64_t arm_mask = cm.arms[0].segment_mask | cm.arms[1].segment_mask;
  int checked = 0;
  for (std::size_t i = 0; i < model.pairs.size(); ++i) {
    const SegmentPair& p = model.pairs[i];
    if (model.segments[p.b].body_schema_slot) continue;
    if (!(((arm_mask >> p.a) & 1U) || ((arm_mask >> p.b) & 1U))) continue;
    if (max_d[i] - min_d[i] < 1e-6) continue;  // no arm motion changes it
    const std::string name = model.segments[p.a].name + "-" + model.segments[p.b].name;
    if (max_d[i] > cm.params.d_a + 0.01) {
      EXPECT_GT(dist.pairs[i].distance, cm.params.d_a) << name;
    } else {
      EXPECT_GT(dist.pairs[i].distance, 0.8 * max_d[i]) << name << " (never farther than " << max_d[i] << ")";
    }
    ++checked;
  }
  EXPECT_GT(checked, 10);

  // behavior.yaml: loads with the behavior layer, its robot links are the known ones, and its targets...
  const modules::ModuleRegistry registry = modules::builtinRegistry();
  const modules::HostConfig hc = modules::loadHostConfig(dir + "/behavior.yaml", registry);
  EXPECT_EQ(hc.robot.left_hand, "l_hand");
  EXPECT_EQ(hc.robot.right_hand, "r_hand");
  EXPECT_EQ(hc.robot.left_shoulder, truth.left_shoulder);
  EXPECT_EQ(hc.robot.right_shoulder, "r" + truth.left_shoulder.substr(1));
  EXPECT_EQ(hc.robot.head, truth.head);
  EXPECT_EQ(hc.robot.head_camera, truth.camera);
  RecordingSink sink;
  modules::BehaviorHost host(hc, registry, sink, [](const std::string&) {});
  host.start(modules::Now{0.0, 0});
  for (double t = 0.02; t < 0.5; t += 0.02) host.tick(modules::Now{t, 0});
  ASSERT_TRUE(sink.left.given && sink.right.given);
  const std::array<Eigen::Vector3d, 2> target = {sink.left.p_B, sink.right.p_B};
  host.stop(modules::Now{0.5, 0});

  // ...are reached in a closed-loop run of the controller with the written files, never below d_r.
  KinematicPort port(q_rest);
  OnboardOptions options;
  options.input_timeout = 10.0;
  OnboardController ctl(model, cm, port, q_rest, options);
  std::array<HandCommand, 2> hands;
  for (int a = 0; a < 2; ++a) hands[a] = {HandStatus::kGiven, target[a]};
  double min_seen = 1e9;
  const int cycles = static_cast<int>(4.0 / cm.params.period);
  for (int k = 0; k <= cycles; ++k) {
    ctl.setHandTargets(hands, k * cm.params.period);
    ctl.step(k * cm.params.period);
    computeForwardKinematics(model, kin, port.positions());
    computeSegmentDistances(model, kin, dist);
    for (const auto& pd : dist.pairs)
      if (pd.active) min_seen = std::min(min_seen, pd.distance);
  }
  EXPECT_GT(min_seen, cm.params.d_r);
  EXPECT_EQ(ctl.report().counts.estop_count, 0u);
  for (int a = 0; a < 2; ++a) {
    const Eigen::Vector3d hand = kin.X_B_L[cm.arms[a].hand_link] * cm.arms[a].hand_point_L;
    EXPECT_LT((hand - target[a]).norm(), 0.01) << (a == 0 ? "left" : "right");
  }
}

const std::string kMeshArgs =
    "--srdf " + testing::robotPath("mesh_humanoid.srdf") +
    " --package-path mesh_humanoid_description=" + testing::robotPath("mesh_humanoid_description");

INSTANTIATE_TEST_SUITE_P(
    Robots, ShippedRobot,
    ::testing::Values(Truth{"asimo_like",
                            "",
                            {"l_shoulder_pitch", "l_shoulder_roll", "l_shoulder_yaw", "l_elbow", "l_wrist"},
                            "l_shoulder",
                            "head",
                            "head_camera",
                            false},
                      Truth{"small_humanoid",
                            "",
                            {"l_shoulder_pitch", "l_shoulder_roll", "l_arm_yaw", "l_elbow", "l_wrist_yaw",
                             "l_wrist_pitch"},
                            "l_shoulder",
                            "head",
                            "camera",
                            false},
                      Truth{"mesh_humanoid",
                            kMeshArgs,
                            {"l_shoulder_pitch", "l_shoulder_roll", "l_arm_yaw", "l_elbow", "l_wrist_pitch"},
                            "l_shoulder_link",
                            "head",
                            "camera_link",
                            true}),
    [](const auto& info) { return info.param.robot; });

// The ASIMO-like robot with its left forearm capsule shortened: core z -0.02 .. -0.095 (radius 0.045),
// so its surface ends at z = -0.14, 6 cm before the wrist at z = -0.2 (l_forearm frame).
std::string gapRobot(const std::string& dir) {
  std::string urdf = slurp(testing::robotPath("asimo_like.urdf"));
  const std::string old_el =
      "<collision name=\"l_forearm_0\">\n      <origin xyz=\"0 0 -0.1\" rpy=\"0 3.14159 0\"/>\n"
      "      <geometry><cylinder radius=\"0.045\" length=\"0.16\"/>";
  const std::string new_el =
      "<collision name=\"l_forearm_0\">\n      <origin xyz=\"0 0 -0.0575\" rpy=\"0 3.14159 0\"/>\n"
      "      <geometry><cylinder radius=\"0.045\" length=\"0.075\"/>";
  const auto at = urdf.find(old_el);
  EXPECT_NE(at, std::string::npos);
  urdf.replace(at, old_el.size(), new_el);
  const std::string path = dir + "/gap_robot.urdf";
  std::ofstream(path) << urdf;
  return path;
}

TEST(Setup, WarnsAboutAForearmGapWithTheClosingCapsuleAndClosesIt) {
  const std::string dir = freshDir("gap");
  const std::string urdf = gapRobot(dir);
  const ProcessResult r = setupRun(urdf + " --out " + dir + "/out");
  ASSERT_EQ(r.exit_code, 0) << r.out << r.err;
  // Analytic: the wrist (0, 0, -0.2) is 0.2 - 0.095 - 0.045 = 0.060 m outside the capsule; the points
  // more than 10 mm outside run from z = -0.155 (the 5 mm grid's first beyond -0.15) to the wrist.
  EXPECT_THAT(
      r.out,
      HasSubstr("warning: left arm: link 'l_forearm': the stretch between its joints lies up to 0.060 m outside every "
                "collision "
                "primitive of the link, at (0.000, 0.000, -0.200) m in 'l_forearm' (tolerance 0.010 m): a capsule from "
                "(0.000, 0.000, -0.095) to (0.000, 0.000, -0.200) m, radius 0.045 m, closes it\n"));
  EXPECT_THAT(r.out, HasSubstr("<collision name=\"l_forearm_gap\"><origin xyz=\"0.0000 0.0000 -0.1475\""));
  EXPECT_EQ(r.out.find("warning: right arm"), std::string::npos);

  // --close-gaps: the copy carries the capsule, loads, and every point of the forearm's skeleton now lies
  // within 10 mm of a primitive of l_forearm (computed here from the loaded model).
  const ProcessResult closed = setupRun(urdf + " --out " + dir + "/closed --close-gaps");
  ASSERT_EQ(closed.exit_code, 0) << closed.out << closed.err;
  EXPECT_THAT(closed.out, HasSubstr("gaps: wrote " + dir + "/closed/gap_robot.urdf with 1 closing capsules"));
  EXPECT_THAT(closed.out, Not(HasSubstr("remain after closing")));
  const Model m = loadModel(dir + "/closed/gap_robot.urdf", loadCollisionConfig(dir + "/closed/collision.yaml"));
  const Segment& fore = m.segments[m.segmentIndex("l_forearm")];
  ASSERT_EQ(fore.num_primitives, 2);
  for (double z = 0.0; z >= -0.2; z -= 0.001) {
    double d = 1e9;
    for (int p = fore.first_primitive; p < fore.first_primitive + fore.num_primitives; ++p)
      d = std::min(d, signedDistanceToPrimitive(m.primitives[p], Eigen::Vector3d(0, 0, z)));
    EXPECT_LE(d, 0.01) << "z " << z;
  }
  EXPECT_THAT(slurp(dir + "/closed/behavior.yaml"), HasSubstr("urdf: gap_robot.urdf"));
}

// Two 4-joint arms (joints within +-0.6 rad) on a trunk sphere, no head, and two thin rods fixed to
// the trunk, lying along y at x = +-rod_x beside the left arm's second link.
std::string shieldRobot(const std::string& dir, double rod_x) {
  std::ostringstream os;
  os << "<robot name=\"shield\"><link name=\"trunk\"><collision><geometry><sphere radius=\"0.05\"/></geometry>"
        "</collision></link>\n";
  for (const char* p : {"l", "r"}) {
    std::string parent = "trunk";
    for (int j = 1; j <= 4; ++j) {
      const std::string link = std::string(p) + "_l" + std::to_string(j);
      os << "<link name=\"" << link << "\"><collision><origin xyz=\"0 0 -0.06\"/><geometry><cylinder radius=\"0.02\" "
         << "length=\"0.06\"/></geometry></collision></link>\n<joint name=\"" << p << "_j" << j
         << "\" type=\"revolute\"><parent link=\"" << parent << "\"/><child link=\"" << link << "\"/><origin xyz=\""
         << (j == 1 ? (p[0] == 'l' ? "0 0.2 0" : "0 -0.2 0") : "0 0 -0.12") << "\"/><axis xyz=\""
         << (j % 2 ? "0 1 0" : "1 0 0") << "\"/><limit lower=\"-0.6\" upper=\"0.6\" velocity=\"2\" effort=\"10\"/>"
         << "</joint>\n";
      parent = link;
    }
  }
  for (int k = 0; k < 2; ++k)
    os << "<link name=\"rod" << k << "\"><collision><origin rpy=\"1.5707963267948966 0 0\"/><geometry><cylinder "
       << "radius=\"0.001\" length=\"0.2\"/></geometry></collision></link>\n<joint name=\"rod" << k
       << "_fix\" type=\"fixed\"><parent link=\"trunk\"/><child link=\"rod" << k << "\"/><origin xyz=\""
       << (k == 0 ? rod_x : -rod_x) << " 0.2 -0.18\"/></joint>\n";
  os << "</robot>\n";
  const std::string path = dir + "/shield.urdf";
  std::ofstream(path) << os.str();
  return path;
}

// What set-up may replace in DIR: only regular files, only with --force, and only once it succeeded
// (the files are made in a staging folder inside DIR, then moved). A directory where behavior.yaml
// goes is refused before any work: nothing in DIR changes, no staging folder is left.
TEST(Setup, OnlySuccessReplacesFilesAndNeverAnythingButARegularFile) {
  const std::string dir = freshDir("shield");
  const std::string urdf = shieldRobot(dir, 0.15);
  const std::string out = dir + "/out";
  fs::create_directories(out + "/behavior.yaml");
  std::ofstream(out + "/controller.yaml") << "keep\n";
  auto listing = [&] {
    std::vector<std::string> names;
    for (const auto& e : fs::directory_iterator(out)) names.push_back(e.path().filename().string());
    std::sort(names.begin(), names.end());
    return names;
  };
  const ProcessResult r = setupRun(urdf + " --out " + out + " --force");
  EXPECT_EQ(r.exit_code, 2) << r.out << r.err;
  EXPECT_EQ(r.err, "reflex_setup: error: '" + out +
                       "/behavior.yaml' exists and is a directory: reflex_setup replaces "
                       "only regular files; remove it or choose another --out\n");
  EXPECT_EQ(listing(), (std::vector<std::string>{"behavior.yaml", "controller.yaml"}));
  EXPECT_EQ(slurp(out + "/controller.yaml"), "keep\n");
  EXPECT_TRUE(fs::is_directory(out + "/behavior.yaml"));

  // The directory gone: set-up succeeds (--force replaces controller.yaml), and the robot without a
  // head is said to have none.
  fs::remove(out + "/behavior.yaml");
  const ProcessResult r2 = setupRun(urdf + " --out " + out + " --force");
  ASSERT_EQ(r2.exit_code, 0) << r2.out << r2.err;
  EXPECT_THAT(r2.out, HasSubstr("head: link 'trunk', NO HEAD: no chain of 1 to 3 joints other than the arms ends in a "
                                "link with collision geometry"));
  EXPECT_THAT(slurp(out + "/behavior.yaml"), HasSubstr("  head: trunk\n"));
  EXPECT_THAT(slurp(out + "/controller.yaml"), HasSubstr("arms:"));
  EXPECT_EQ(listing(), (std::vector<std::string>{"behavior.yaml", "collision.yaml", "controller.yaml"}));
}

// A fit in the output folder is reused only when it was made with today's default options: one
// written by an older reflex_fit (without the large-gap options) is made again, and said so.
TEST(Setup, AFitMadeWithOtherOptionsIsMadeAgainNotReused) {
  const std::string dir = freshDir("fit_options");
  const std::string fit = dir + "/mesh_humanoid.fit.yaml";
  const std::string today = fitOverlayText(loadFitOverlay(testing::robotPath("mesh_humanoid.fit.yaml")), fit);
  ASSERT_THAT(today, HasSubstr(", max_pieces_large_gap: 48, large_gap: 0.02}"));
  std::ofstream(fit) << today;
  const std::string args = testing::robotPath("mesh_humanoid.urdf") + " " + kMeshArgs + " --out " + dir + " --force";
  const ProcessResult reused = setupRun(args);
  ASSERT_EQ(reused.exit_code, 0) << reused.out << reused.err;
  EXPECT_THAT(reused.out, HasSubstr("fit: reusing " + fit));

  std::string older = today;
  older.replace(older.find(", max_pieces_large_gap: 48, large_gap: 0.02}"),
                std::string(", max_pieces_large_gap: 48, large_gap: 0.02}").size(), "}");
  std::ofstream(fit) << older;
  EXPECT_EQ(loadFitOverlay(fit).options.max_pieces_large_gap, 0) << "a key an older fit lacks reads as 0";
  const ProcessResult refit = setupRun(args);
  ASSERT_EQ(refit.exit_code, 0) << refit.out << refit.err;
  EXPECT_THAT(refit.out, HasSubstr("fit: not reusing " + fit + ": it was made with other options"));
  EXPECT_EQ(slurp(fit), today) << "made again with today's options: the shipped fit";
}

// A locomotion variant: asimo_like with every arm joint fixed. Its only mirrored chains of >= 4
// revolute joints are the legs, which are never taken for arms (before: legs configured as arms, feet
// as hands, exit 0).
TEST(Setup, ALegsOnlyRobotIsRefusedNeverConfiguredWithLegsAsArms) {
  const std::string dir = freshDir("legs_only");
  std::string urdf = slurp(testing::robotPath("asimo_like.urdf"));
  int fixed = 0;
  for (const char* side : {"l_", "r_"})
    for (const char* j : {"shoulder_pitch", "shoulder_roll", "shoulder_yaw", "elbow", "wrist"}) {
      const std::string from = "<joint name=\"" + std::string(side) + j + "\" type=\"revolute\">";
      const auto at = urdf.find(from);
      ASSERT_NE(at, std::string::npos) << from;
      urdf.replace(at, from.size(), "<joint name=\"" + std::string(side) + j + "\" type=\"fixed\">");
      ++fixed;
    }
  ASSERT_EQ(fixed, 10);
  std::ofstream(dir + "/legs_only.urdf") << urdf;
  const ProcessResult r = setupRun(dir + "/legs_only.urdf --out " + dir + "/out");
  EXPECT_EQ(r.exit_code, 2) << r.out << r.err;
  EXPECT_THAT(r.err, HasSubstr("reflex_setup: error: no arms found in robot '"));
  EXPECT_THAT(r.err, HasSubstr("the only mirrored chains of >= 4 revolute joints are legs (named like legs, or ending "
                               "at the robot's lowest link): [l_hip_yaw"));
  EXPECT_FALSE(fs::exists(dir + "/out/controller.yaml"));
}

// The right arm mirrors the left where their joint axes are mirror images at the zero posture, up to the
// rounding URDFs carry (3.14159, 1.5708: micro-radians, compounding along a chain): asimo_like with its
// right shoulder turned 0.1 mrad about z is mirrored whole (the rest's hands mirror images within 0.1
// mm); turned 50 mrad, its joints whose axes that turns are named as chosen on their own.
TEST(Setup, TheRightArmMirrorsTheLeftUpToRoundedAnglesAndNamesTheJointsItCannot) {
  const std::string base = slurp(testing::robotPath("asimo_like.urdf"));
  const std::string from = "<origin xyz=\"0 -0.23 0.16\" rpy=\"0 0 0\"/>";
  ASSERT_NE(base.find(from), std::string::npos);
  for (const char* yaw : {"0.0001", "0.05"}) {
    const std::string dir = freshDir(std::string("turned_") + yaw);
    std::string urdf = base;
    urdf.replace(urdf.find(from), from.size(), "<origin xyz=\"0 -0.23 0.16\" rpy=\"0 0 " + std::string(yaw) + "\"/>");
    std::ofstream(dir + "/turned.urdf") << urdf;
    const ProcessResult r = setupRun(dir + "/turned.urdf --out " + dir + "/out");
    ASSERT_EQ(r.exit_code, 0) << r.out << r.err;
    if (std::string(yaw) == "0.05") {
      EXPECT_THAT(r.out, HasSubstr("right arm mirrored except r_shoulder_pitch, r_shoulder_roll, "));
      continue;
    }
    EXPECT_THAT(r.out, HasSubstr("right arm mirrored\n"));
    const Model model = loadModel(dir + "/turned.urdf", loadCollisionConfig(dir + "/out/collision.yaml"));
    const ControllerConfig config = loadControllerConfig(dir + "/out/controller.yaml");
    EXPECT_LT(test::restHandsMirrorGap(model, config), 1e-4);
  }
}

// A rest search whose random postures clear no pair set climbs the clearest one instead of lowering
// every requirement: small_humanoid with 10 samples instead of 4000, 20 seeds. Without the climb 13 of
// the 20 lower them (the WARNING line); with it none does, and none fails.
TEST(Setup, TheRestSearchClimbsTheClearestPostureBeforeItLowersTheRequirements) {
  const Model m = testing::loadRobot("small_humanoid");
  int lowered = 0;
  for (int seed = 1; seed <= 20; ++seed) {
    SetupOptions o;
    o.rest_samples = 10;
    o.seed = static_cast<std::uint64_t>(seed);
    RobotSetup s = findRobotStructure(m, o);
    ASSERT_NO_THROW(findRestPosture(m, o, s)) << "seed " << seed;
    for (const auto& d : s.decisions) lowered += d.find("rest: WARNING") != std::string::npos;
  }
  EXPECT_EQ(lowered, 0);
}

// A trunk sphere and chains of revolute joints (capsule links hanging along -z) at given start points.
std::string chainXml(const std::string& p, int joints, double x, double y, double z) {
  std::ostringstream os;
  std::string parent = "trunk";
  for (int j = 1; j <= joints; ++j) {
    const std::string link = p + "_l" + std::to_string(j);
    os << "<link name=\"" << link << "\"><collision><origin xyz=\"0 0 -0.06\"/><geometry><cylinder radius=\"0.02\" "
       << "length=\"0.06\"/></geometry></collision></link>\n"
       << "<joint name=\"" << p << "_j" << j << "\" type=\"revolute\"><parent link=\"" << parent << "\"/><child link=\""
       << link << "\"/><origin xyz=\"" << (j == 1 ? x : 0.0) << " " << (j == 1 ? y : 0.0) << " " << (j == 1 ? z : -0.12)
       << "\"/><axis xyz=\"" << (j % 2 ? "0 1 0" : "1 0 0")
       << "\"/><limit lower=\"-1\" upper=\"1\" velocity=\"2\" effort=\"10\"/></joint>\n";
    parent = link;
  }
  return os.str();
}

std::string robotXml(const std::string& name, const std::string& chains) {
  return "<robot name=\"" + name +
         "\"><link name=\"trunk\"><collision><geometry><sphere radius=\"0.05\"/></geometry>"
         "</collision></link>\n" +
         chains + "</robot>\n";
}

TEST(Setup, AmbiguousAndMissingArmsAreErrorsNamingTheCandidates) {
  const std::string dir = freshDir("bad");
  // Two mirrored pairs at the same height, named neutrally.
  std::ofstream(dir + "/amb.urdf") << robotXml("amb", chainXml("a", 4, 0, 0.2, 0.5) + chainXml("b", 4, 0, -0.2, 0.5) +
                                                          chainXml("c", 4, 0, 0.4, 0.5) +
                                                          chainXml("d", 4, 0, -0.4, 0.5));
  ProcessResult r = setupRun(dir + "/amb.urdf --out " + dir + "/amb");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_EQ(r.err,
            "reflex_setup: error: ambiguous arms in robot 'amb': 2 mirrored pairs of chains start within 5 cm "
            "of the same height and their names do not tell which are arms: [a_j1 a_j2 a_j3 a_j4] / "
            "[b_j1 b_j2 b_j3 b_j4] (z 0.500); [c_j1 c_j2 c_j3 c_j4] / [d_j1 d_j2 d_j3 d_j4] (z 0.500); "
            "give --left-hand and --right-hand\n");
  // The flags resolve it.
  r = setupRun(dir + "/amb.urdf --out " + dir + "/amb --left-hand c_l4 --right-hand d_l4 --head trunk");
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_THAT(r.out, HasSubstr("arms: the revolute joints from the given hand links up to their branching links "
                               "'trunk' / 'trunk': left [c_j1 c_j2 c_j3 c_j4], right [d_j1 d_j2 d_j3 d_j4] "
                               "(--left-hand, --right-hand)"));
  // One arm-like chain and a two-joint neck: no mirrored pair.
  std::ofstream(dir + "/one.urdf") << robotXml("one", chainXml("a", 4, 0, 0.2, 0.5) + chainXml("h", 2, 0, 0, 0.6));
  r = setupRun(dir + "/one.urdf --out " + dir + "/one");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_THAT(r.err, HasSubstr("reflex_setup: error: no arms found in robot 'one': need two mirrored serial chains "
                               "of >= 4 revolute joints branching from the trunk (first joints at (x, y, z) and "
                               "(x, -y, z)); chains found: [a_j1 a_j2 a_j3 a_j4] (4 joints, from 'trunk' at y 0.200) "
                               "[h_j1 h_j2] (2 joints, from 'trunk' at y 0.000); give --left-hand and --right-hand\n"));
  // Bad flags.
  r = setupRun(dir + "/one.urdf --out " + dir + "/one --left-hand a_l4");
  EXPECT_THAT(r.err,
              HasSubstr("reflex_setup: error: give both --left-hand and --right-hand (got only --left-hand 'a_l4')\n"));
  r = setupRun(dir + "/one.urdf --out " + dir + "/one --left-hand a_l4 --right-hand nope");
  EXPECT_THAT(r.err, HasSubstr("reflex_setup: error: --right-hand 'nope' is not a link of robot 'one'\n"));
  // Bad set-up input, each named.
  r = setupRun(dir + "/nope.urdf --out " + dir + "/x");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_EQ(r.err, "reflex_setup: error: URDF '" + dir + "/nope.urdf' does not exist\n");
  r = setupRun(dir + "/one.urdf --out " + dir + "/x --srdf " + dir + "/nope.srdf");
  EXPECT_EQ(r.err, "reflex_setup: error: --srdf '" + dir + "/nope.srdf' does not exist\n");
  r = setupRun(dir + "/one.urdf --out " + dir + "/x --package-path foo");
  EXPECT_EQ(r.err, "reflex_setup: error: --package-path 'foo' must be NAME=DIR\n");
  r = setupRun(dir + "/one.urdf --out /dev/null/x");
  EXPECT_EQ(r.err,
            "reflex_setup: error: --out: output folder '/dev/null/x' cannot be created: '/dev/null' is a "
            "character device\n");
  r = setupRun("--help");
  EXPECT_EQ(r.exit_code, 0);
  EXPECT_THAT(r.out, HasSubstr("--close-gaps"));
  // Files already there are not replaced without --force.
  r = setupRun(dir + "/amb.urdf --out " + dir + "/amb --left-hand c_l4 --right-hand d_l4 --head trunk");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_THAT(r.err, HasSubstr("controller.yaml' exists; give --force to replace it"));
}

}  // namespace
}  // namespace reflex::control
