// reflex_mujoco's robot, in one process (no DDS): is MuJoCo's robot the controller's robot, and is
// MuJoCo's collision detection a faithful judge of the collision model?
//
// Independent answers:
//   - body poses: the project's forward kinematics (control/kinematics.hpp, itself checked against
//     KDL) vs MuJoCo's mj_kinematics on the generated MJCF, both robots, random configurations;
//   - capsule / sphere geoms: the Model's primitive endpoints and radii mapped by FK vs MuJoCo's
//     geom frames (centre +- half-length along the geom's z axis);
//   - mass: sum over primitives of density * capsule volume (pi r^2 L + 4/3 pi r^3) written out here;
//     a URDF <inertial> with a rotated frame: MuJoCo's principal inertia vs the eigenvalues of the
//     tensor, and its principal axes reproduce the tensor;
//   - the judge: two capsules placed by a slide joint at analytic separations (3 mm, 8 mm, -1 mm):
//     MuJoCo reports 3 mm (dist within 1e-9 m of the analytic value, in the gap: no force), not 8 mm,
//     and -1 mm with a force; the project's distance module gives the same numbers; on the shipped
//     robot at random configurations (margin widened to 60 mm to see many pairs) every pair MuJoCo
//     reports has the project's distance, and every checked pair below the margin is reported;
//   - the servo's command gate: bad commands change no reference and are counted; a far target is
//     approached no faster than the URDF velocity limit.
#include "reflex/control/distance.hpp"
#include "reflex/control/kinematics.hpp"
#include "reflex/control/urdf_loader.hpp"
#include "reflex/mujoco/mjcf.hpp"
#include "reflex/mujoco/mujoco_robot.hpp"

#include "../control/test_support.hpp"

#include <gtest/gtest.h>

#include <Eigen/Eigenvalues>

#include <cmath>
#include <cstdio>
#include <limits>
#include <map>
#include <random>
#include <set>

namespace reflex::mujoco {
namespace {

using control::Model;
using reflex::testing::loadRobot;

constexpr std::int64_t kNow = 1'000'000'000'000;  // a wall-clock time for the command gate [ns]

Eigen::Matrix3d geomRotation(const mjData& d, int g) {
  Eigen::Matrix3d R;
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) R(r, c) = d.geom_xmat[9 * g + 3 * r + c];
  return R;
}

class ModelFidelity : public ::testing::TestWithParam<const char*> {};

void checkBodyPosesAndGeoms(const Model& model, const char* name) {
  MujocoRobot robot(model, MjcfOptions{});
  const mjModel& m = robot.mjModelRef();
  const mjData& d = robot.mjDataRef();
  control::KinematicsData kin(model);
  std::mt19937_64 rng(13);
  double max_pos = 0.0, max_rot = 0.0, max_geom = 0.0;
  int poses = 0, geoms = 0;
  for (int trial = 0; trial < 200; ++trial) {
    const Eigen::VectorXd q = control::test::randomConfiguration(model, rng);
    robot.setPositions(q);
    ASSERT_TRUE(control::computeForwardKinematics(model, kin, q));
    for (std::size_t l = 1; l < model.links.size(); ++l) {
      const int b = mj_name2id(&m, mjOBJ_BODY, model.links[l].name.c_str());
      ASSERT_GE(b, 0) << model.links[l].name;
      const Eigen::Vector3d p(d.xpos[3 * b], d.xpos[3 * b + 1], d.xpos[3 * b + 2]);
      const Eigen::Quaterniond quat(d.xquat[4 * b], d.xquat[4 * b + 1], d.xquat[4 * b + 2], d.xquat[4 * b + 3]);
      max_pos = std::max(max_pos, (p - kin.X_B_L[l].translation()).norm());
      max_rot = std::max(max_rot, (quat.toRotationMatrix() - kin.X_B_L[l].linear()).cwiseAbs().maxCoeff());
      ++poses;
    }
    for (int s = 0; s < model.num_robot_segments; ++s) {
      const auto& seg = model.segments[s];
      for (int k = 0; k < seg.num_primitives; ++k) {
        const auto& prim = model.primitives[seg.first_primitive + k];
        const int g = mj_name2id(&m, mjOBJ_GEOM, geomName(model, s, k).c_str());
        ASSERT_GE(g, 0);
        EXPECT_NEAR(m.geom_size[3 * g], prim.radius, 1e-12);
        const Eigen::Isometry3d& X = kin.X_B_L[static_cast<std::size_t>(control::linkOf(seg, prim))];
        const Eigen::Vector3d a = X * prim.a_L, b = X * prim.b_L;
        const Eigen::Vector3d c(d.geom_xpos[3 * g], d.geom_xpos[3 * g + 1], d.geom_xpos[3 * g + 2]);
        if (prim.sphere) {
          ASSERT_EQ(m.geom_type[g], mjGEOM_SPHERE);
          max_geom = std::max(max_geom, (c - a).norm());
        } else {
          ASSERT_EQ(m.geom_type[g], mjGEOM_CAPSULE);
          const Eigen::Vector3d half = m.geom_size[3 * g + 1] * geomRotation(d, g).col(2);
          const double err = std::min(std::max((c - half - a).norm(), (c + half - b).norm()),
                                      std::max((c + half - a).norm(), (c - half - b).norm()));
          max_geom = std::max(max_geom, err);
        }
        ++geoms;
      }
    }
  }
  std::printf(
      "[ measured ] %s: %d body poses, max position error %.2e m, max rotation error %.2e; %d geoms, "
      "max endpoint error %.2e m\n",
      name, poses, max_pos, max_rot, geoms, max_geom);
  EXPECT_LT(max_pos, 1e-9);
  EXPECT_LT(max_rot, 1e-9);
  EXPECT_LT(max_geom, 1e-9);
}

TEST_P(ModelFidelity, BodyPosesAndGeomsEqualTheProjectsKinematics) {
  checkBodyPosesAndGeoms(loadRobot(GetParam()), GetParam());
}

/// A segment of several links (collision YAML `segments:`): each primitive is a geom of its own
/// link's body, and the contact pairs are the same as with a segment per link (the same link pairs
/// are checked; the forearm-upper arm link pair stays adjacent, not a contact pair).
TEST(ModelFidelitySegments, ASegmentOfSeveralLinksHasEachGeomOnItsLinkAndTheSameContactPairs) {
  control::CollisionConfig config =
      control::loadCollisionConfig(reflex::testing::robotPath("asimo_like.collision.yaml"));
  config.segments = {{"l_forearm", {"l_hand"}}, {"r_forearm", {"r_hand"}}};
  const Model grouped = control::loadModel(reflex::testing::robotPath("asimo_like.urdf"), config);
  ASSERT_EQ(grouped.num_robot_segments, loadRobot(reflex::testing::kAsimo).num_robot_segments - 2);
  checkBodyPosesAndGeoms(grouped, "asimo_like with a segment per forearm and hand");
  MujocoRobot flat_robot(loadRobot(reflex::testing::kAsimo), MjcfOptions{});
  MujocoRobot grouped_robot(grouped, MjcfOptions{});
  const mjModel& f = flat_robot.mjModelRef();
  const mjModel& g = grouped_robot.mjModelRef();
  ASSERT_EQ(g.npair, f.npair);
  // Pair by pair, the bodies of the two geoms (links): the same set.
  auto bodies = [](const mjModel& m) {
    std::multiset<std::pair<std::string, std::string>> out;
    for (int k = 0; k < m.npair; ++k) {
      std::string a = mj_id2name(&m, mjOBJ_BODY, m.geom_bodyid[m.pair_geom1[k]]);
      std::string b = mj_id2name(&m, mjOBJ_BODY, m.geom_bodyid[m.pair_geom2[k]]);
      if (b < a) std::swap(a, b);
      out.insert({a, b});
    }
    return out;
  };
  EXPECT_EQ(bodies(g), bodies(f));
  EXPECT_GT(bodies(g).count({"l_hand", "l_upper_arm"}), 0u);
  EXPECT_EQ(bodies(g).count({"l_forearm", "l_upper_arm"}), 0u);
}

TEST_P(ModelFidelity, MassIsTheCollisionVolumeAtTheStatedDensity) {
  const Model model = loadRobot(GetParam());
  const MjcfOptions options;
  MujocoRobot robot(model, options);
  const mjModel& m = robot.mjModelRef();
  // Capsule volume pi r^2 L + 4/3 pi r^3 (a sphere: L = 0). The root link's geoms belong to the
  // world (static), not to a body's mass.
  auto volume = [](const control::Primitive& p) {
    return M_PI * p.radius * p.radius * (p.b_L - p.a_L).norm() + 4.0 / 3.0 * M_PI * std::pow(p.radius, 3);
  };
  double expected = 0.0;
  std::vector<bool> has_segment(model.links.size(), false);
  for (int s = 0; s < model.num_robot_segments; ++s) {
    has_segment[model.segments[s].link] = true;
    if (model.segments[s].link == 0) continue;
    for (int k = 0; k < model.segments[s].num_primitives; ++k)
      expected += options.density * volume(model.primitives[model.segments[s].first_primitive + k]);
  }
  for (std::size_t l = 1; l < model.links.size(); ++l)
    if (!has_segment[l]) expected += options.min_mass;
  double mass = 0.0;
  for (int b = 1; b < m.nbody; ++b) mass += m.body_mass[b];
  std::printf("[ measured ] %s: mass %.3f kg (expected %.3f kg)\n", GetParam(), mass, expected);
  EXPECT_NEAR(mass, expected, 1e-9 * expected);
}

INSTANTIATE_TEST_SUITE_P(Robots, ModelFidelity, ::testing::Values("asimo_like", "small_humanoid"));

// Two links: A (root) holds a capsule along y; B slides along x and holds a capsule along z. The
// cores cross at right angles, so the surface distance is x - rA - rB exactly.
constexpr double kRa = 0.04, kRb = 0.03;
const char* kTwoCapsules = R"(<?xml version="1.0"?>
<robot name="two_capsules">
  <link name="a">
    <collision><origin xyz="0 0 0" rpy="1.5707963267948966 0 0"/><geometry><cylinder radius="0.04" length="0.2"/></geometry></collision>
    <inertial><origin xyz="0.01 0 0" rpy="0.3 0.2 0.1"/><mass value="2.5"/>
      <inertia ixx="0.02" ixy="0.001" ixz="0.002" iyy="0.03" iyz="0.003" izz="0.04"/></inertial>
  </link>
  <link name="b">
    <collision><origin xyz="0 0 0" rpy="0 0 0"/><geometry><cylinder radius="0.03" length="0.2"/></geometry></collision>
    <inertial><origin xyz="0 0 0.01" rpy="0.4 -0.2 0.7"/><mass value="1.5"/>
      <inertia ixx="0.011" ixy="-0.001" ixz="0.0005" iyy="0.012" iyz="0.001" izz="0.013"/></inertial>
  </link>
  <joint name="slide" type="prismatic"><parent link="a"/><child link="b"/><origin xyz="0 0 0"/>
    <axis xyz="1 0 0"/><limit lower="0" upper="1" velocity="0.5" effort="100"/></joint>
</robot>)";

Model twoCapsules() {
  control::CollisionConfig config;
  config.exclude_adjacent = false;  // A and B are joined by one joint; check them anyway
  return control::loadModelFromString(kTwoCapsules, config, "two_capsules");
}

TEST(Judge, ReportsPairsBelowTheMarginWithItsOwnDistanceAndNoForceUntilPenetration) {
  const Model model = twoCapsules();
  ASSERT_EQ(model.num_robot_segments, 2);
  MjcfOptions options;
  options.margin = 0.005;
  options.gravity = 0.0;
  MujocoRobot robot(model, options);
  const mjModel& m = robot.mjModelRef();
  mjData& d = robot.mjDataRef();
  control::KinematicsData kin(model);
  control::DistanceData dist(model);
  struct Case {
    double separation;
    bool reported;
  };
  for (const Case c :
       {Case{0.003, true}, Case{0.008, false}, Case{0.0049, true}, Case{0.0051, false}, Case{-0.001, true}}) {
    Eigen::VectorXd q(1);
    q << kRa + kRb + c.separation;
    robot.setPositions(q);
    ASSERT_TRUE(control::computeForwardKinematics(model, kin, q));
    control::computeSegmentDistances(model, kin, dist);
    EXPECT_NEAR(dist.pairs[0].distance, c.separation, 1e-12) << "the project's distance module";
    const auto& contacts = robot.measurement().contacts;
    ASSERT_EQ(contacts.size(), c.reported ? 1u : 0u) << "separation " << c.separation;
    if (!c.reported) continue;
    EXPECT_NEAR(contacts[0].distance, c.separation, 1e-9);
    EXPECT_EQ(model.segments[contacts[0].seg_a].name, "a");
    EXPECT_EQ(model.segments[contacts[0].seg_b].name, "b");
    ASSERT_EQ(d.ncon, 1);
    mjtNum force[6];
    mj_contactForce(&m, &d, 0, force);
    std::printf(
        "[ measured ] separation %+.4f m: MuJoCo dist %+.9f m, project %+.9f m, exclude %d, normal force %.3f N\n",
        c.separation, d.contact[0].dist, dist.pairs[0].distance, d.contact[0].exclude, force[0]);
    if (c.separation > 0.0) {
      EXPECT_EQ(d.contact[0].exclude, 1) << "in the gap: reported, not in the solver";
      EXPECT_EQ(force[0], 0.0);
    } else {
      EXPECT_EQ(d.contact[0].exclude, 0);
      EXPECT_GT(force[0], 0.0) << "a penetrating pair is pushed apart";
    }
  }
}

TEST(Judge, UrdfInertialIsUsedWithItsRotatedFrame) {
  const Model model = twoCapsules();
  ASSERT_TRUE(model.links[1].has_inertial);
  MujocoRobot robot(model, MjcfOptions{});
  const mjModel& m = robot.mjModelRef();
  const int b = mj_name2id(&m, mjOBJ_BODY, "b");
  EXPECT_NEAR(m.body_mass[b], 1.5, 1e-12);
  // The URDF tensor (in its rpy frame), rotated into the link frame by the loader, equals MuJoCo's
  // principal inertia in its principal axes.
  Eigen::Matrix3d I_urdf;
  I_urdf << 0.011, -0.001, 0.0005, -0.001, 0.012, 0.001, 0.0005, 0.001, 0.013;
  const Eigen::Matrix3d R_rpy =
      (Eigen::AngleAxisd(0.7, Eigen::Vector3d::UnitZ()) * Eigen::AngleAxisd(-0.2, Eigen::Vector3d::UnitY()) *
       Eigen::AngleAxisd(0.4, Eigen::Vector3d::UnitX()))
          .toRotationMatrix();
  const Eigen::Matrix3d I_L = R_rpy * I_urdf * R_rpy.transpose();
  const Eigen::Quaterniond iq(m.body_iquat[4 * b], m.body_iquat[4 * b + 1], m.body_iquat[4 * b + 2],
                              m.body_iquat[4 * b + 3]);
  const Eigen::Vector3d principal(m.body_inertia[3 * b], m.body_inertia[3 * b + 1], m.body_inertia[3 * b + 2]);
  const Eigen::Matrix3d I_mujoco = iq.toRotationMatrix() * principal.asDiagonal() * iq.toRotationMatrix().transpose();
  // MuJoCo diagonalizes the tensor iteratively (mju_eig3): agreement to 1e-6 of its size.
  EXPECT_LT((I_mujoco - I_L).cwiseAbs().maxCoeff(), 1e-8);
  EXPECT_NEAR(m.body_ipos[3 * b + 2], 0.01, 1e-12);
}

// A sensor link of zero mass and inertia on a movable joint, and a link whose inertia breaks MuJoCo's
// triangle inequality: MuJoCo refuses both as written; the MJCF carries the repaired values (MuJoCo
// compiles it and reports them), and inertialRepairs names each link with what it changed.
TEST(Judge, DegenerateUrdfInertialsAreRepairedAndSaid) {
  std::string urdf = kTwoCapsules;
  const std::string b_inertial = R"(<mass value="1.5"/>
      <inertia ixx="0.011" ixy="-0.001" ixz="0.0005" iyy="0.012" iyz="0.001" izz="0.013"/>)";
  const auto at = urdf.find(b_inertial);
  ASSERT_NE(at, std::string::npos);
  urdf.replace(at, b_inertial.size(), R"(<mass value="0"/><inertia ixx="0" ixy="0" ixz="0" iyy="0" iyz="0" izz="0"/>)");
  control::CollisionConfig config;
  config.exclude_adjacent = false;
  const Model model = control::loadModelFromString(urdf, config, "degenerate");
  const MjcfOptions options;
  const auto repairs = inertialRepairs(model, options);
  ASSERT_EQ(repairs.size(), 1u);
  EXPECT_EQ(
      repairs[0].rfind(
          "link 'b': URDF <inertial> mass 0 -> 0.01 kg, principal inertia [0 0 0] -> [1e-05 1e-05 1e-05] kg m^2", 0),
      0u)
      << repairs[0];
  // A tensor breaking A + B >= C (principal 0.001, 0.001, 0.01, turned): the two smaller raised to 0.005
  // and 2e-6 of it (a margin MuJoCo's own rounding cannot undo), the axes kept; a valid tensor and mass
  // left exactly as they are.
  const Eigen::Matrix3d R = Eigen::AngleAxisd(0.3, Eigen::Vector3d(1, 2, 3).normalized()).toRotationMatrix();
  Eigen::Matrix3d I = R * Eigen::Vector3d(0.001, 0.001, 0.01).asDiagonal() * R.transpose();
  double mass = 2.0;
  std::string what;
  EXPECT_TRUE(repairInertial(options, mass, I, &what));
  EXPECT_LT((I - R * Eigen::Vector3d(0.005 * (1 + 2e-6), 0.005 * (1 + 2e-6), 0.01).asDiagonal() * R.transpose())
                .cwiseAbs()
                .maxCoeff(),
            1e-12)
      << what;
  // Exactly on the inequality (A + B = C): raised by the margin too (Romeo's RElbowYawLink: MuJoCo
  // refused the model when the repair stopped at equality).
  Eigen::Matrix3d edge = R * Eigen::Vector3d(0.004, 0.006, 0.01).asDiagonal() * R.transpose();
  EXPECT_TRUE(repairInertial(options, mass, edge, &what));
  const Eigen::Vector3d l = Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(edge).eigenvalues();
  EXPECT_GT(l[0] + l[1], l[2] * (1 + 1e-6)) << what;
  EXPECT_EQ(mass, 2.0);
  Eigen::Matrix3d good = R * Eigen::Vector3d(0.02, 0.03, 0.04).asDiagonal() * R.transpose();
  const Eigen::Matrix3d good0 = good;
  EXPECT_FALSE(repairInertial(options, mass, good, &what)) << what;
  EXPECT_EQ(good, good0);
  MujocoRobot robot(model, options);  // throws if MuJoCo refuses the MJCF
  const mjModel& m = robot.mjModelRef();
  const int b = mj_name2id(&m, mjOBJ_BODY, "b");
  EXPECT_NEAR(m.body_mass[b], 0.01, 1e-12);
  for (int k = 0; k < 3; ++k) EXPECT_NEAR(m.body_inertia[3 * b + k], 1e-5, 1e-12);
}

TEST(Judge, AgreesWithTheProjectsDistancesOnTheRobotAtRandomConfigurations) {
  const Model model = loadRobot("asimo_like");
  MjcfOptions options;
  options.margin = 0.06;  // wide, so that many pairs are compared
  MujocoRobot robot(model, options);
  control::KinematicsData kin(model);
  control::DistanceData dist(model);
  std::map<std::pair<int, int>, int> pair_index;
  for (std::size_t i = 0; i < model.pairs.size(); ++i)
    pair_index[{model.pairs[i].a, model.pairs[i].b}] = static_cast<int>(i);
  std::mt19937_64 rng(7);
  int compared = 0, penetrating = 0, below = 0;
  double max_err = 0.0;
  for (int trial = 0; trial < 400; ++trial) {
    const Eigen::VectorXd q = control::test::randomConfiguration(model, rng);
    robot.setPositions(q);
    ASSERT_TRUE(control::computeForwardKinematics(model, kin, q));
    control::computeSegmentDistances(model, kin, dist);
    const auto& contacts = robot.measurement().contacts;
    for (const auto& c : contacts) {
      const auto it = pair_index.find({c.seg_a, c.seg_b});
      ASSERT_NE(it, pair_index.end()) << "MuJoCo reported a pair the controller does not check";
      const double err = std::abs(c.distance - dist.pairs[it->second].distance);
      max_err = std::max(max_err, err);
      EXPECT_LT(err, 1e-9) << model.segments[c.seg_a].name << "," << model.segments[c.seg_b].name;
      ++compared;
      if (c.distance < 0) ++penetrating;
    }
    for (std::size_t i = 0; i < model.pairs.size(); ++i) {
      if (model.pairs[i].b >= model.num_robot_segments) continue;
      if (dist.pairs[i].distance < options.margin - 1e-9) {
        ++below;
        bool found = false;
        for (const auto& c : contacts) found = found || (c.seg_a == model.pairs[i].a && c.seg_b == model.pairs[i].b);
        EXPECT_TRUE(found) << "not reported: " << model.segments[model.pairs[i].a].name << ","
                           << model.segments[model.pairs[i].b].name << " at " << dist.pairs[i].distance;
      }
    }
  }
  std::printf(
      "[ measured ] %d reported pairs compared (%d penetrating), %d project pairs below the margin; "
      "max distance difference %.2e m\n",
      compared, penetrating, below, max_err);
  EXPECT_GT(compared, 200);
  EXPECT_GT(penetrating, 20);
  EXPECT_EQ(compared, below);
}

TEST(CommandGate, BadCommandsAreRejectedCountedAndChangeNothing) {
  const Model model = loadRobot("asimo_like");
  MujocoRobot robot(model, MjcfOptions{});
  const Eigen::VectorXd ref0 = robot.reference();
  const std::vector<std::string> names = {"l_elbow", "r_elbow"};
  const std::vector<double> good = {-0.5, -0.5}, zero = {0.0, 0.0};
  const std::vector<double> nan = {std::numeric_limits<double>::quiet_NaN(), -0.5};
  const std::vector<double> inf = {0.0, std::numeric_limits<double>::infinity()};
  const std::vector<double> one = {-0.5};
  const std::vector<std::string> unknown = {"l_elbow", "tail"}, twice = {"l_elbow", "l_elbow"}, none = {};
  auto offer = [&](const std::vector<std::string>& n, const std::vector<double>& p, const std::vector<double>& v,
                   std::int64_t valid_until) {
    CommandInput in;
    in.names = &n;
    in.positions = &p;
    in.velocities = &v;
    in.valid_until_ns = valid_until;
    in.seq = 1;
    return robot.offerCommand(in, kNow);
  };
  const std::int64_t later = kNow + 10'000'000;
  EXPECT_EQ(offer(names, nan, zero, later), CommandVerdict::kNotFinite);
  EXPECT_EQ(offer(names, good, inf, later), CommandVerdict::kNotFinite);
  EXPECT_EQ(offer(unknown, good, zero, later), CommandVerdict::kUnknownName);
  EXPECT_EQ(offer(twice, good, zero, later), CommandVerdict::kDuplicateName);
  EXPECT_EQ(offer(names, one, zero, later), CommandVerdict::kLengthMismatch);
  EXPECT_EQ(offer(none, {}, {}, later), CommandVerdict::kEmpty);
  EXPECT_EQ(offer(names, good, zero, kNow - 1), CommandVerdict::kExpired);
  robot.step(100, kNow);
  EXPECT_TRUE(robot.measurement().holding);
  EXPECT_EQ(robot.measurement().applied_command_seq, 0u);
  EXPECT_LT((robot.reference() - ref0).cwiseAbs().maxCoeff(), 1e-3) << "no bad command moved a reference";
  const auto& c = robot.counters();
  EXPECT_EQ(c.rejected_not_finite, 2u);
  EXPECT_EQ(c.rejected_unknown, 1u);
  EXPECT_EQ(c.rejected_duplicate, 1u);
  EXPECT_EQ(c.rejected_length, 1u);
  EXPECT_EQ(c.rejected_empty, 1u);
  EXPECT_EQ(c.rejected_expired, 1u);
  EXPECT_EQ(c.accepted, 0u);

  // A valid command far away: the reference moves at the URDF velocity limit, no faster.
  const int qi = model.qIndex("l_elbow");
  const double v_max = model.v_max[qi];
  const double start = robot.reference()[qi];
  EXPECT_EQ(offer(names, {-2.0, -2.0}, zero, later), CommandVerdict::kAccepted);
  double max_speed = 0.0;
  for (int k = 0; k < 100; ++k) {
    robot.step(1, kNow);
    max_speed = std::max(max_speed, std::abs(robot.measurement().qdot[qi]));
  }
  EXPECT_NEAR(robot.reference()[qi], start - v_max * 100 * robot.timestep(), 1e-9);
  EXPECT_FALSE(robot.measurement().holding);
  for (int k = 0; k < 900; ++k) {  // on to the target (-2 rad, 0.8 s at the limit) and settled
    robot.step(1, kNow);
    max_speed = std::max(max_speed, std::abs(robot.measurement().qdot[qi]));
  }
  std::printf(
      "[ measured ] l_elbow to a target 2 rad away: largest speed %.4f rad/s (limit %.2f), at %.4f rad after 1 s\n",
      max_speed, v_max, robot.measurement().q[qi]);
  EXPECT_LT(max_speed, 1.02 * v_max) << "the joint follows the rate-limited reference";
  EXPECT_NEAR(robot.measurement().q[qi], -2.0, 1e-3);
  // Its deadline passes: the robot holds where it is measured.
  ASSERT_FALSE(robot.measurement().holding);
  robot.step(1, later + 1);
  EXPECT_TRUE(robot.measurement().holding);
  EXPECT_EQ(robot.counters().holds, 1u);
}

}  // namespace
}  // namespace reflex::mujoco
