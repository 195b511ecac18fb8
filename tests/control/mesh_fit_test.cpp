// Tests of control/include/reflex/control/mesh_fit.hpp: collision meshes to
// capsules and the fit overlay. Independent answers:
//  - the mesh vertices are read HERE (tinyxml2 for the URDF's origins, scales and filenames, assimp
//    directly for the files, the transforms applied here) and each one's distance to the fitted
//    capsules is computed here: every vertex must be inside one primitive;
//  - FCL's BVH mesh-mesh distance (the meshes as read here) at 150 random configurations of the
//    shipped mesh humanoid is never below the fitted pair distance (the fit is conservative);
//  - the ground truth of the generated robot (mesh_humanoid.truth.yaml: the primitives each mesh was
//    tessellated from): a one-primitive link's fit is no larger than the primitive it came from;
//  - a COLLADA file written here, Z_UP in centimetres, with a known vertex;
//  - real-world files of Debian's assimp-testmodels (STL, OBJ, DAE);
//  - the generator script and reflex_fit rerun: same bytes as the committed files;
//  - boxes (fitBox): every corner and a 25 x 25 grid on every face inside the fit, each radius tight
//    (0.1 mm less leaves a point outside), the volume against the one enclosing capsule boxes were
//    read as before (computed here); FCL's box distance on the small humanoid (boxes as fcl::Box) at
//    300 random configurations never below the fitted pair distance;
//  - every failure mode with its exact message.
#include "reflex/control/distance.hpp"
#include "reflex/control/kinematics.hpp"
#include "reflex/control/mesh_fit.hpp"
#include "raw_meshes.hpp"
#include "test_support.hpp"

#include <assimp/Importer.hpp>
#include <assimp/config.h>
#include <assimp/postprocess.h>
#include <assimp/scene.h>
#include <fcl/geometry/bvh/BVH_model.h>
#include <fcl/geometry/shape/box.h>
#include <fcl/geometry/shape/capsule.h>
#include <fcl/geometry/shape/sphere.h>
#include <fcl/narrowphase/collision.h>
#include <fcl/narrowphase/distance.h>
#include <gmock/gmock.h>
#include <sys/wait.h>
#include <gtest/gtest.h>
#include <tinyxml2.h>
#include <yaml-cpp/yaml.h>

#include <cstdint>
#include <cstdio>
#include <functional>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <optional>
#include <memory>
#include <regex>
#include <set>
#include <sstream>

namespace reflex::control {
namespace {

namespace fs = std::filesystem;
using Eigen::Vector3d;

const std::string kUrdf = testing::robotPath("mesh_humanoid.urdf");
const std::string kPackageDir = testing::robotPath("mesh_humanoid_description");

std::string readFile(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

/// A temporary folder removed at the end of the test.
struct TempDir {
  fs::path path;
  TempDir() {
    char tmpl[] = "/tmp/reflex_mesh_fit_XXXXXX";
    path = ::mkdtemp(tmpl);
  }
  ~TempDir() { fs::remove_all(path); }
  std::string operator/(const std::string& name) const { return (path / name).string(); }
};

using test::linkMeshes;
using test::parse3;
using test::RawMesh;
using test::readWithAssimp;

/// Distance from p to the capsule a-b of radius r, minus r (computed here, not by the fitter).
double outside(const Primitive& prim, const Vector3d& p) {
  const Vector3d ab = prim.b_L - prim.a_L;
  const double l2 = ab.squaredNorm();
  const double s = l2 > 0 ? std::clamp((p - prim.a_L).dot(ab) / l2, 0.0, 1.0) : 0.0;
  return (prim.a_L + s * ab - p).norm() - prim.radius;
}

int countOutside(const std::vector<Primitive>& prims, const std::vector<Vector3d>& vertices, double* worst = nullptr) {
  int n = 0;
  double w = -1.0;
  for (const auto& v : vertices) {
    double best = std::numeric_limits<double>::infinity();
    for (const auto& p : prims) best = std::min(best, outside(p, v));
    n += best > 0.0 ? 1 : 0;
    w = std::max(w, best);
  }
  if (worst) *worst = w;
  return n;
}

double capsuleVolume(const Primitive& p) {
  const double len = (p.b_L - p.a_L).norm();
  return M_PI * p.radius * p.radius * len + 4.0 / 3.0 * M_PI * std::pow(p.radius, 3);
}

std::vector<Primitive> segmentPrimitives(const Model& m, const std::string& link) {
  const Segment& s = m.segments.at(m.segmentIndex(link));
  return {m.primitives.begin() + s.first_primitive, m.primitives.begin() + s.first_primitive + s.num_primitives};
}

TEST(MeshFit, ShippedMeshHumanoidEnclosesEveryVertexOfEveryLink) {
  const Model model = testing::loadRobot("mesh_humanoid");
  const auto meshes = linkMeshes(kUrdf, {{"mesh_humanoid_description", kPackageDir}});
  ASSERT_EQ(meshes.size(), 16u);  // 14 links with meshes (the torso also a box), 2 feet with boxes
  for (const auto& [link, mesh] : meshes) {
    ASSERT_GE(model.segmentIndex(link), 0) << link;
    double worst = 0.0;
    EXPECT_EQ(countOutside(segmentPrimitives(model, link), mesh.v, &worst), 0)
        << link << ": a vertex is " << worst << " m outside every fitted primitive";
    EXPECT_GT(mesh.v.size(), 7u) << link;
  }
}

/// What an oracle says of one pair of links: whether the true shapes intersect, else how far apart they are.
struct TrueDistance {
  bool touching = false;
  double distance = 0.0;
};
struct OracleTally {
  int checked = 0, colliding = 0;
  double closest_margin = std::numeric_limits<double>::infinity();  ///< min (true - fitted) over pairs apart
};

/// The loop of both FCL checks: at `samples` random configurations (seed `seed`), every robot pair
/// (body-schema slots skipped) that `oracle(pair index, X_B_La, X_B_Lb)` answers (std::nullopt: not
/// asked) must have Reflex's fitted distance <= the true one (+ tol), and <= 0 where the shapes touch.
template <class Oracle>
void expectFittedNeverFartherThanOracle(const Model& model, int samples, unsigned seed, double tol, Oracle oracle,
                                        OracleTally& tally) {
  KinematicsData kin(model);
  DistanceData dist(model);
  std::mt19937_64 rng(seed);
  for (int sample = 0; sample < samples; ++sample) {
    ASSERT_TRUE(computeForwardKinematics(model, kin, test::randomConfiguration(model, rng)));
    computeSegmentDistances(model, kin, dist);
    for (std::size_t i = 0; i < model.pairs.size(); ++i) {
      const SegmentPair& p = model.pairs[i];
      if (model.segments[p.b].body_schema_slot) continue;
      const std::optional<TrueDistance> truth =
          oracle(i, kin.X_B_L[model.segments[p.a].link], kin.X_B_L[model.segments[p.b].link]);
      if (!truth) continue;
      const double fitted = dist.pairs[i].distance;
      const std::string what = model.segments[p.a].name + "-" + model.segments[p.b].name;
      if (truth->touching) {
        ++tally.colliding;
        EXPECT_LE(fitted, 0.0) << what << ": the true shapes intersect, fitted primitives apart";
        continue;
      }
      EXPECT_GE(truth->distance, fitted - tol) << what << " sample " << sample;
      tally.closest_margin = std::min(tally.closest_margin, truth->distance - fitted);
      ++tally.checked;
    }
  }
}

TEST(MeshFit, FittedDistanceNeverExceedsFclMeshDistance) {
  const Model model = testing::loadRobot("mesh_humanoid");
  const auto meshes = linkMeshes(kUrdf, {{"mesh_humanoid_description", kPackageDir}});
  std::map<int, std::shared_ptr<fcl::BVHModel<fcl::OBBRSSd>>> bvh;  // by segment
  for (const auto& [link, mesh] : meshes) {
    auto m = std::make_shared<fcl::BVHModel<fcl::OBBRSSd>>();
    std::vector<fcl::Triangle> tris;
    for (const auto& t : mesh.t) tris.emplace_back(t[0], t[1], t[2]);
    m->beginModel();
    m->addSubModel(mesh.v, tris);
    m->endModel();
    bvh[model.segmentIndex(link)] = m;
  }
  OracleTally t;
  expectFittedNeverFartherThanOracle(
      model, 150, 7, 1e-9,
      [&](std::size_t i, const Eigen::Isometry3d& X_B_La, const Eigen::Isometry3d& X_B_Lb) {
        const SegmentPair& p = model.pairs[i];
        const fcl::Transform3d Xa(X_B_La.matrix()), Xb(X_B_Lb.matrix());
        fcl::CollisionRequestd creq;
        fcl::CollisionResultd cres;
        fcl::collide(bvh.at(p.a).get(), Xa, bvh.at(p.b).get(), Xb, creq, cres);
        if (cres.isCollision()) return std::optional<TrueDistance>(TrueDistance{true, 0.0});
        fcl::DistanceRequestd dreq;
        dreq.enable_nearest_points = false;
        fcl::DistanceResultd dres;
        fcl::distance(bvh.at(p.a).get(), Xa, bvh.at(p.b).get(), Xb, dreq, dres);
        return std::optional<TrueDistance>(TrueDistance{false, dres.min_distance});
      },
      t);
  const int checked = t.checked, colliding = t.colliding;
  const double closest_margin = t.closest_margin;
  EXPECT_GT(checked, 10000);
  std::cout << "mesh pairs checked against FCL: " << checked << " apart, " << colliding
            << " intersecting; smallest (mesh - fitted) distance " << closest_margin << " m\n";
}

/// The fit of a link built from one capsule or sphere is no larger than that primitive and close to
/// it (its vertices lie on it); every link's numbers stay within the bounds README states.
TEST(MeshFit, GroundTruthVolumesAndStatedBounds) {
  const Model model = testing::loadRobot("mesh_humanoid");
  const YAML::Node truth = YAML::LoadFile(testing::robotPath("mesh_humanoid.truth.yaml"))["links"];
  const FitOverlay overlay = loadFitOverlay(testing::robotPath("mesh_humanoid.fit.yaml"));
  int single = 0;
  for (const auto& l : overlay.links) {
    const YAML::Node t = truth[l.link];
    ASSERT_TRUE(t) << l.link;
    EXPECT_EQ(l.stats.vertices_enclosed, l.stats.vertices) << l.link;
    EXPECT_LE(l.stats.volume_ratio, 2.0) << l.link;
    EXPECT_LE(l.stats.worst_gap, 0.12) << l.link;
    if (t.size() != 1 || t[0]["box"]) continue;
    ++single;
    Primitive gt;
    gt.radius = t[0]["radius"].as<double>();
    if (t[0]["sphere"]) {
      gt.a_L = gt.b_L =
          Vector3d(t[0]["sphere"][0].as<double>(), t[0]["sphere"][1].as<double>(), t[0]["sphere"][2].as<double>());
    } else {
      for (int k = 0; k < 3; ++k)
        gt.a_L[k] = t[0]["capsule"][0][k].as<double>(), gt.b_L[k] = t[0]["capsule"][1][k].as<double>();
    }
    const auto prims = segmentPrimitives(model, l.link);
    ASSERT_EQ(prims.size(), 1u) << l.link << " is one primitive in truth";
    const double fitted = capsuleVolume(prims[0]), ideal = capsuleVolume(gt);
    EXPECT_LE(fitted, ideal * 1.001 + 1e-8) << l.link;
    EXPECT_GE(fitted, ideal * 0.9) << l.link;
    EXPECT_LE(l.stats.worst_gap, 0.025) << l.link;  // tessellation: 16 around, 4 rings per hemisphere
  }
  EXPECT_EQ(single, 9);  // pelvis, head, imu, and per side the upper arm, forearm and shin
}

TEST(MeshFit, ColladaZUpInCentimetresComesOutInTheUrdfFrameInMetres) {
  TempDir dir;
  const std::string dae = dir / "tri.dae";
  std::ofstream(dae) << R"(<?xml version="1.0" encoding="utf-8"?>
<COLLADA xmlns="http://www.collada.org/2005/11/COLLADASchema" version="1.4.1">
  <asset><unit name="centimeter" meter="0.01"/><up_axis>Z_UP</up_axis></asset>
  <library_geometries><geometry id="g"><mesh>
    <source id="p"><float_array id="pa" count="9">1 2 3 0 0 0 4 0 0</float_array>
      <technique_common><accessor source="#pa" count="3" stride="3">
        <param name="X" type="float"/><param name="Y" type="float"/><param name="Z" type="float"/>
      </accessor></technique_common></source>
    <vertices id="v"><input semantic="POSITION" source="#p"/></vertices>
    <triangles count="1"><input semantic="VERTEX" source="#v" offset="0"/><p>0 1 2</p></triangles>
  </mesh></geometry></library_geometries>
  <library_visual_scenes><visual_scene id="s"><node id="n"><instance_geometry url="#g"/></node></visual_scene></library_visual_scenes>
  <scene><instance_visual_scene url="#s"/></scene>
</COLLADA>
)";
  const TriangleMesh mesh = loadMeshFile(dae, Vector3d(1, 1, 2));
  ASSERT_EQ(mesh.triangles.size(), 1u);
  bool found = false;
  for (const auto& v : mesh.vertices) found = found || (v - Vector3d(0.01, 0.02, 0.06)).norm() < 1e-8;  // floats
  EXPECT_TRUE(found) << "the vertex (1, 2, 3) cm with scale (1, 1, 2) must be (0.01, 0.02, 0.06) m, unrotated";
}

TEST(MeshFit, RealWorldAssimpTestModelsFitWithEveryVertexEnclosed) {
  const std::string base = "/usr/share/assimp/models/";
  int fitted = 0;
  for (const std::string f : {"OBJ/box.obj", "OBJ/concave_polygon.obj", "Collada/duck.dae", "STL/Spider_binary.stl",
                              "STL/sphereWithHole.stl"}) {
    if (!fs::exists(base + f)) {
      ADD_FAILURE() << base + f << " is missing: install assimp-testmodels (bringup/setup.sh)";
      continue;
    }
    // At 1/100 (a URDF <mesh scale>): the duck and the spider are ~100 units across, beyond the 10 m
    // any mesh vertex may be (kMaxMeshCoordinate); at scale 1 they are refused.
    const Vector3d scale = Vector3d::Constant(0.01);
    const TriangleMesh mesh = loadMeshFile(base + f, scale);
    FitStats stats;
    FitOptions options;
    options.gap_samples_per_primitive = 100;
    const auto prims = fitPrimitives(mesh, options, &stats);
    const RawMesh raw = readWithAssimp(base + f, scale, Eigen::Isometry3d::Identity());
    double worst = 0.0;
    EXPECT_EQ(countOutside(prims, raw.v, &worst), 0) << f << ": worst " << worst;
    EXPECT_EQ(stats.vertices_enclosed, stats.vertices) << f;
    EXPECT_GE(prims.size(), 1u);
    std::cout << f << ": " << raw.v.size() << " vertices, " << prims.size() << " primitives, volume ratio "
              << stats.volume_ratio << ", worst gap " << stats.worst_gap << "\n";
    ++fitted;
  }
  EXPECT_EQ(fitted, 5);
}

TEST(MeshFit, GeneratorAndReflexFitReproduceTheCommittedFilesByteForByte) {
  TempDir dir;
  const std::string script = testing::robotPath("make_mesh_humanoid.py");
  ASSERT_EQ(std::system((std::string(REFLEX_PYTHON) + " " + script + " " + dir.path.string() + " > /dev/null").c_str()),
            0);
  int compared = 0;
  for (const auto& e : fs::recursive_directory_iterator(dir.path)) {
    if (!e.is_regular_file()) continue;
    const std::string rel = fs::relative(e.path(), dir.path).string();
    EXPECT_EQ(readFile(e.path().string()), readFile(testing::robotPath(rel)))
        << rel << " differs from the committed file";
    ++compared;
  }
  EXPECT_EQ(compared, 5 + 16);  // urdf, srdf, collision, truth, package.xml; 16 meshes
  const std::string out = dir / "mesh_humanoid.fit.yaml";
  const std::string cmd = std::string(REFLEX_FIT) + " " + dir / "mesh_humanoid.urdf" +
                          " --package-path mesh_humanoid_description=" + dir / "mesh_humanoid_description" +
                          " -q > /dev/null";
  ASSERT_EQ(std::system(cmd.c_str()), 0);
  EXPECT_EQ(readFile(out), readFile(testing::robotPath("mesh_humanoid.fit.yaml")));
}

/// Every number option of reflex_fit refuses what is out of range or not a number (exit 2, the
/// value named, nothing written): CLI11's Range alone let `nan` through to the fit.
TEST(MeshFit, ReflexFitRefusesANumberOptionOutOfRangeOrNotFinite) {
  TempDir dir;
  const std::string out = dir / "out.fit.yaml";
  for (const std::string arg : {"--piece-gap nan", "--piece-gap 0", "--piece-gap inf", "--split-ratio nan",
                                "--split-ratio 0.5", "--max-pieces 0", "--piece-gap x"}) {
    const std::string cmd =
        std::string(REFLEX_FIT) + " " + testing::robotPath("mesh_humanoid.urdf") + " " + arg + " -o " + out + " 2>&1";
    FILE* pipe = popen(cmd.c_str(), "r");
    ASSERT_NE(pipe, nullptr);
    std::string text;
    char buf[512];
    while (std::fgets(buf, sizeof buf, pipe)) text += buf;
    const int status = pclose(pipe);
    EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 2) << arg << ": " << text;
    const std::string value = arg.substr(arg.find(' ') + 1);
    EXPECT_NE(text.find(arg.substr(0, arg.find(' '))), std::string::npos) << arg << ": " << text;
    EXPECT_NE(text.find("Value " + value), std::string::npos) << arg << ": " << text;
    EXPECT_FALSE(fs::exists(out)) << arg;
  }
}

/// A one-link robot with the given collision XML, in `dir`.
std::string writeRobot(const TempDir& dir, const std::string& collisions) {
  const std::string path = dir / "r.urdf";
  std::ofstream(path)
      << "<robot name=\"r\"><link name=\"base\"/>\n<link name=\"a\">" << collisions
      << "</link>\n<link name=\"b\"><collision><geometry><sphere radius=\"0.1\"/></geometry></collision></link>\n"
      << "<joint name=\"j1\" type=\"revolute\"><parent link=\"base\"/><child link=\"a\"/><axis xyz=\"0 0 1\"/>"
      << "<limit lower=\"-1\" upper=\"1\" velocity=\"1\" effort=\"1\"/></joint>\n"
      << "<joint name=\"j2\" type=\"revolute\"><parent link=\"base\"/><child link=\"b\"/><origin xyz=\"1 0 0\"/>"
      << "<axis xyz=\"0 0 1\"/><limit lower=\"-1\" upper=\"1\" velocity=\"1\" effort=\"1\"/></joint></robot>\n";
  return path;
}

std::string messageOf(const std::function<void()>& f) {
  try {
    f();
  } catch (const ModelError& e) {
    return e.what();
  }
  return "(no error)";
}

TEST(MeshFitErrors, UnresolvedPackagesAndUnreadableMeshesAreNamedInOneMessage) {
  TempDir dir;
  ::unsetenv("ROS_PACKAGE_PATH");
  std::ofstream(dir / "bad.stl") << "this is not a mesh";
  const std::string urdf =
      writeRobot(dir,
                 "<collision><geometry><mesh filename=\"package://nopkg/a.stl\"/></geometry></collision>"
                 "<collision><geometry><mesh filename=\"missing.obj\"/></geometry></collision>"
                 "<collision><geometry><mesh filename=\"bad.stl\"/></geometry></collision>");
  const std::string msg = messageOf([&] { fitRobot(urdf, {}, {}); });
  const std::regex expected(
      std::regex_replace(urdf, std::regex("[.]"), "[.]") +
      ": cannot fit: 3 meshes not resolved or not readable:\n"
      "  link 'a': mesh 'package://nopkg/a[.]stl': package 'nopkg' not found \\(give --package-path nopkg=DIR, or add "
      "its parent folder to ROS_PACKAGE_PATH, unset now\\)\n"
      "  link 'a': mesh 'missing[.]obj': cannot read '" +
      std::regex_replace(dir / "missing.obj", std::regex("[.]"), "[.]") +
      "' \\(no such file\\)\n"
      "  link 'a': mesh 'bad[.]stl': " +
      std::regex_replace(dir / "bad.stl", std::regex("[.]"), "[.]") + ": cannot read mesh: .+");
  EXPECT_TRUE(std::regex_match(msg, expected)) << msg;
}

TEST(MeshFitErrors, MissingFitNamesEveryMeshLinkAndTheCommand) {
  TempDir dir;
  std::ofstream(dir / "m.obj") << "v 0 0 0\nv 0.1 0 0\nv 0 0.1 0\nf 1 2 3\n";
  const std::string urdf = dir / "r.urdf";
  std::ofstream(urdf)
      << "<robot name=\"r\"><link name=\"base\"><collision><geometry><mesh "
         "filename=\"m.obj\"/></geometry></collision></link>"
      << "<link name=\"arm\"><collision><geometry><mesh filename=\"m.obj\"/></geometry></collision></link>"
      << "<joint name=\"j\" type=\"revolute\"><parent link=\"base\"/><child link=\"arm\"/><axis xyz=\"0 0 1\"/>"
      << "<limit lower=\"-1\" upper=\"1\" velocity=\"1\" effort=\"1\"/></joint></robot>\n";
  EXPECT_EQ(messageOf([&] { loadModel(urdf, {}); }),
            urdf + ": 2 links have mesh collision geometry and no fit: 'base' 'arm'; run: reflex_fit " + urdf +
                " (it writes " + dir / "r.fit.yaml" +
                ", which the loader reads; or name an overlay with 'fit:' in the collision YAML)");
  // After reflex_fit's library call, the same robot loads, with the fit read from the default place.
  const FitOverlay overlay = fitRobot(urdf, {}, {});
  std::ofstream(dir / "r.fit.yaml") << fitOverlayText(overlay, dir / "r.fit.yaml");
  const Model m = loadModel(urdf, {});
  EXPECT_EQ(m.num_robot_segments, 2);
}

TEST(MeshFitErrors, StaleOverlayNamesTheLink) {
  TempDir dir;
  std::ofstream(dir / "m.obj") << "v 0 0 0\nv 0.1 0 0\nv 0 0.1 0\nf 1 2 3\n";
  const std::string urdf =
      writeRobot(dir,
                 "<collision><geometry><mesh filename=\"m.obj\"/></geometry></collision>"
                 "<collision><origin xyz=\"0 0 0.3\"/><geometry><box size=\"0.1 0.1 0.1\"/></geometry></collision>");
  const std::string fit = dir / "r.fit.yaml";
  std::ofstream(fit) << fitOverlayText(fitRobot(urdf, {}, {}), fit);
  const Model fresh = loadModel(urdf, {});
  EXPECT_EQ(fresh.segments[fresh.segmentIndex("a")].num_primitives,
            static_cast<int>(loadFitOverlay(fit).links[0].primitives.size()));
  const std::string old_inputs = loadFitOverlay(fit).links[0].inputs;
  std::ofstream(dir / "m.obj", std::ios::app) << "v 0 0 0.2\nf 1 2 4\n";  // the mesh changed
  const std::string msg = messageOf([&] { loadModel(urdf, {}); });
  const std::regex expected(std::regex_replace(fit, std::regex("[.]"), "[.]") +
                            ": the fit is stale or cannot be checked for 1 link \\(rerun: reflex_fit " +
                            std::regex_replace(urdf, std::regex("[.]"), "[.]") + " -o " +
                            std::regex_replace(fit, std::regex("[.]"), "[.]") +
                            "\\):\n  link 'a': its meshes, filenames, scales, origins or boxes changed since the fit "
                            "\\(inputs [0-9a-f]{16}, fitted " +
                            old_inputs + "\\)");
  EXPECT_TRUE(std::regex_match(msg, expected)) << msg;
}

TEST(MeshFit, OverlayTextRoundTripsNamesAndNumbers) {
  TempDir dir;
  FitOverlay o;
  o.urdf = dir / "odd: #robot.urdf";
  o.packages["pkg"] = dir / "pkg dir";
  LinkFit l;
  l.link = "arm: #1 \"left\"\\x";
  l.inputs = "0123456789abcdef";
  Primitive cap;
  cap.a_L = Vector3d(0.123456, -0.5, 1e-6);
  cap.b_L = Vector3d(0.2, 0.3, -0.000001);
  cap.radius = 0.050001;
  cap.sphere = false;
  Primitive ball;
  ball.a_L = ball.b_L = Vector3d(-0.25, 0, 0.75);
  ball.radius = 0.1;
  l.primitives = {cap, ball};
  o.links.push_back(l);
  const std::string path = dir / "o.fit.yaml";
  std::ofstream(path) << fitOverlayText(o, path);
  const FitOverlay back = loadFitOverlay(path);
  ASSERT_EQ(back.links.size(), 1u);
  EXPECT_EQ(back.links[0].link, l.link);
  EXPECT_EQ(back.links[0].inputs, l.inputs);
  EXPECT_EQ(back.urdf, o.urdf);
  EXPECT_EQ(back.packages.at("pkg"), o.packages.at("pkg"));
  ASSERT_EQ(back.links[0].primitives.size(), 2u);
  for (int i = 0; i < 2; ++i) {
    EXPECT_EQ(back.links[0].primitives[i].a_L, l.primitives[i].a_L);
    EXPECT_EQ(back.links[0].primitives[i].b_L, l.primitives[i].b_L);
    EXPECT_EQ(back.links[0].primitives[i].radius, l.primitives[i].radius);
    EXPECT_EQ(back.links[0].primitives[i].sphere, l.primitives[i].sphere);
  }
}

// Format 2 (the tight model): a box piece round-trips bit for bit (vertices at %.17g); a piece whose
// capsule does not enclose a vertex, or a triangle naming no vertex, is refused naming the entry.
TEST(MeshFitOverlay, PiecesRoundTripAndABadPieceIsRefused) {
  TempDir dir;
  FitOverlay o;
  o.urdf = dir / "r.urdf";
  LinkFit l;
  l.link = "box_link";
  l.inputs = "0123456789abcdef";
  const Eigen::Isometry3d X(Eigen::Translation3d(0.1, -0.2, 0.3) *
                            Eigen::AngleAxisd(0.3, Vector3d(1, 2, 3).normalized()));
  l.pieces = {boxPiece(Vector3d(0.1, 0.2, 0.3), X, FitOptions{})};
  l.primitives = {l.pieces[0].capsule};
  o.links.push_back(l);
  const std::string path = dir / "o.fit.yaml";
  std::ofstream(path) << fitOverlayText(o, path);
  const FitOverlay back = loadFitOverlay(path);
  ASSERT_EQ(back.links.size(), 1u);
  ASSERT_EQ(back.links[0].pieces.size(), 1u);
  EXPECT_EQ(back.links[0].pieces[0].vertices, l.pieces[0].vertices);
  EXPECT_EQ(back.links[0].pieces[0].triangles, l.pieces[0].triangles);
  EXPECT_EQ(back.links[0].primitives[0].radius, l.pieces[0].capsule.radius);
  const std::string text = readFile(path);
  auto refused = [&](const std::string& edited, const std::string& expected) {
    std::ofstream(path) << edited;
    try {
      loadFitOverlay(path);
      ADD_FAILURE() << "accepted: " << expected;
    } catch (const ModelError& e) {
      EXPECT_NE(std::string(e.what()).find(expected), std::string::npos) << e.what();
    }
  };
  std::string small = text;
  const std::size_t r = small.find("radius: ");
  ASSERT_NE(r, std::string::npos);
  small.replace(r, small.find('}', r) - r, "radius: 0.001");
  refused(small, "does not enclose the vertex");
  std::string bad_index = text;
  const std::size_t t = bad_index.find("triangles: [[");
  ASSERT_NE(t, std::string::npos);
  bad_index.replace(t + 13, 1, "9");
  refused(bad_index, "is not a vertex index");
}

// The overlay's options are read back (reflex_setup reuses a fit only with today's defaults): an
// unknown option or a negative one is refused naming the key, like any other key of the overlay.
TEST(MeshFitOverlay, OptionsAreReadBackAndABadOptionIsRefused) {
  TempDir dir;
  const std::string path = dir / "o.fit.yaml";
  const std::string text = fitOverlayText(loadFitOverlay(testing::robotPath("mesh_humanoid.fit.yaml")), path);
  std::ofstream(path) << text;
  const FitOverlay back = loadFitOverlay(path);
  EXPECT_EQ(back.options.max_pieces, FitOptions{}.max_pieces);
  EXPECT_EQ(back.options.max_pieces_large_gap, FitOptions{}.max_pieces_large_gap);
  EXPECT_EQ(back.options.large_gap, FitOptions{}.large_gap);
  const std::string key = ", large_gap: 0.02}";
  for (const auto& [replacement, want] : std::vector<std::pair<std::string, std::string>>{
           {", large_gap: 0.02, bogus: 1}", "options.bogus"}, {", large_gap: -0.02}", "options.large_gap"}}) {
    std::string bad = text;
    ASSERT_NE(bad.find(key), std::string::npos);
    bad.replace(bad.find(key), key.size(), replacement);
    std::ofstream(path) << bad;
    EXPECT_THAT(messageOf([&] { (void)loadFitOverlay(path); }), ::testing::HasSubstr(want)) << replacement;
  }
}

TEST(MeshFitResolve, PackageFileAndRelativePaths) {
  TempDir dir;
  fs::create_directories(dir.path / "src" / "folder_name");
  std::ofstream(dir / "src/folder_name/package.xml") << "<package format=\"3\"><name>real_name</name></package>";
  ::setenv("ROS_PACKAGE_PATH", (dir / "src").c_str(), 1);
  std::string why;
  EXPECT_EQ(resolveMeshFilename("package://real_name/m/x.stl", "/u", {}, &why), dir / "src/folder_name" + "/m/x.stl")
      << why;
  EXPECT_EQ(resolveMeshFilename("package://folder_name/x.stl", "/u", {}, &why), "") << "package.xml names it real_name";
  PackagePaths explicit_paths;
  explicit_paths.packages["real_name"] = "/elsewhere";
  EXPECT_EQ(resolveMeshFilename("package://real_name/x.stl", "/u", explicit_paths, &why), "/elsewhere/x.stl");
  EXPECT_EQ(resolveMeshFilename("file:///abs/x.dae", "/u", {}, &why), "/abs/x.dae");
  EXPECT_EQ(resolveMeshFilename("meshes/x.obj", "/u", {}, &why), "/u/meshes/x.obj");
  EXPECT_EQ(resolveMeshFilename("http://host/x.obj", "/u", {}, &why), "");
  EXPECT_EQ(why, "unsupported URI scheme (package://, file:// or a path)");
  ::unsetenv("ROS_PACKAGE_PATH");
}

// ---------------------------------------------------------------- boxes (fitBox)
/// The one capsule the loader read a box as before fitBox (sessions 1-5): core along the longest
/// edge and as long, radius half the diagonal of the other two edges. Computed here.
double enclosingCapsuleVolume(const Vector3d& size) {
  int axis = 0;
  size.maxCoeff(&axis);
  const double r = 0.5 * std::sqrt(size.squaredNorm() - size[axis] * size[axis]);
  return M_PI * r * r * size[axis] + 4.0 / 3.0 * M_PI * r * r * r;
}

/// Points on the surface of a box (edge lengths `size`, pose X): an n x n grid on each face, its
/// edges and corners included.
std::vector<Vector3d> boxSurface(const Vector3d& size, const Eigen::Isometry3d& X, int n) {
  std::vector<Vector3d> out;
  for (int axis = 0; axis < 3; ++axis)
    for (const double side : {-0.5, 0.5})
      for (int i = 0; i < n; ++i)
        for (int j = 0; j < n; ++j) {
          Vector3d p;
          p[axis] = side * size[axis];
          p[(axis + 1) % 3] = (-0.5 + double(i) / (n - 1)) * size[(axis + 1) % 3];
          p[(axis + 2) % 3] = (-0.5 + double(j) / (n - 1)) * size[(axis + 2) % 3];
          out.push_back(X * p);
        }
  return out;
}

Eigen::Isometry3d pose(const Vector3d& xyz, const Vector3d& rpy) {
  Eigen::Isometry3d X = Eigen::Isometry3d::Identity();
  X.translation() = xyz;
  X.linear() = (Eigen::AngleAxisd(rpy.z(), Vector3d::UnitZ()) * Eigen::AngleAxisd(rpy.y(), Vector3d::UnitY()) *
                Eigen::AngleAxisd(rpy.x(), Vector3d::UnitX()))
                   .toRotationMatrix();
  return X;
}

TEST(MeshFitBox, EverySurfacePointInsideAndFlatBoxesFarTighterThanTheOldCapsule) {
  struct Case {
    const char* what;
    Vector3d size;
    Eigen::Isometry3d X_L_B;
    double factor;  ///< the old capsule's volume is at least this many times the fit's
  };
  const std::vector<Case> cases{
      {"mesh humanoid foot sole", {0.22, 0.1, 0.04}, pose({0.04, 0, -0.05}, {0, 0, 0}), 1.5},
      {"small humanoid foot sole", {0.16, 0.08, 0.02}, pose({0.03, 0, -0.04}, {0, 0, 0}), 2.5},
      {"torso plate, tilted", {0.3, 0.25, 0.03}, pose({0.1, -0.2, 0.3}, {0.3, -0.7, 1.1}), 3.0},
      {"small humanoid torso", {0.08, 0.1, 0.18}, pose({0, 0, 0.1}, {0, 0, 0}), 1.15},
      {"mesh humanoid backpack", {0.08, 0.2, 0.2}, pose({-0.15, 0, 0.3}, {0, 0, 0}), 1.4},
      {"cube", {0.1, 0.1, 0.1}, pose({0, 0, 0}, {0.2, 0.4, 0.6}), 1.1},
      {"bar (one capsule is already tight)", {0.4, 0.02, 0.02}, pose({0, 0, 0}, {0, 0, 0}), 1.0},
  };
  const FitOptions options;
  for (const Case& c : cases) {
    SCOPED_TRACE(c.what);
    const std::vector<Primitive> prims = fitBox(c.size, c.X_L_B, options);
    ASSERT_FALSE(prims.empty());
    EXPECT_LE(static_cast<int>(prims.size()), options.max_primitives);
    const std::vector<Vector3d> surface = boxSurface(c.size, c.X_L_B, 25);  // corners included
    double worst = 0.0;
    EXPECT_EQ(countOutside(prims, surface, &worst), 0) << "worst " << worst << " m outside";
    // Tight at the corners: every radius 0.1 mm less leaves surface points outside (so the check
    // above can fail).
    std::vector<Primitive> shrunk = prims;
    for (auto& p : shrunk) p.radius -= 1e-4;
    EXPECT_GT(countOutside(shrunk, surface), 0) << "the fit has slack";
    double fitted = 0.0;
    for (const auto& p : prims) fitted += capsuleVolume(p);
    const double box = c.size.prod(), old = enclosingCapsuleVolume(c.size);
    EXPECT_GE(old / fitted, c.factor) << "fitted / box " << fitted / box << ", old capsule / box " << old / box;
    // The library's own numbers agree with the ones computed here.
    const FitStats st = measureFit(boxMesh(c.size, c.X_L_B), prims, options, box);
    EXPECT_EQ(st.vertices_enclosed, 8);
    EXPECT_NEAR(st.volume_ratio, fitted / box, 1e-9);
    std::printf("%-44s %d primitive(s): fitted / box %.2f (old capsule %.2f, %.2fx), worst gap %.4f m\n", c.what,
                static_cast<int>(prims.size()), fitted / box, old / box, old / fitted, st.worst_gap);
  }
  EXPECT_THROW(fitBox({0.1, 0.0, 0.1}, Eigen::Isometry3d::Identity(), options), ModelError);
  EXPECT_THROW(fitBox({0.1, NAN, 0.1}, Eigen::Isometry3d::Identity(), options), ModelError);
}

/// Every collision shape of every link of a URDF as FCL shapes in the link frame, read here with
/// tinyxml2: boxes as boxes, spheres as spheres, cylinders as the capsules Reflex reads them as.
std::map<std::string, std::vector<std::pair<std::shared_ptr<fcl::CollisionGeometryd>, Eigen::Isometry3d>>> fclShapes(
    const std::string& urdf_path, std::set<std::string>* box_links) {
  tinyxml2::XMLDocument doc;
  EXPECT_EQ(doc.LoadFile(urdf_path.c_str()), tinyxml2::XML_SUCCESS);
  std::map<std::string, std::vector<std::pair<std::shared_ptr<fcl::CollisionGeometryd>, Eigen::Isometry3d>>> out;
  for (auto* link = doc.RootElement()->FirstChildElement("link"); link; link = link->NextSiblingElement("link")) {
    for (auto* c = link->FirstChildElement("collision"); c; c = c->NextSiblingElement("collision")) {
      Eigen::Isometry3d X = Eigen::Isometry3d::Identity();
      if (auto* o = c->FirstChildElement("origin"))
        X = pose(parse3(o->Attribute("xyz"), Vector3d::Zero()), parse3(o->Attribute("rpy"), Vector3d::Zero()));
      auto* g = c->FirstChildElement("geometry");
      std::shared_ptr<fcl::CollisionGeometryd> shape;
      if (auto* b = g->FirstChildElement("box")) {
        shape = std::make_shared<fcl::Boxd>(parse3(b->Attribute("size"), Vector3d::Zero()));
        box_links->insert(link->Attribute("name"));
      } else if (auto* sp = g->FirstChildElement("sphere")) {
        shape = std::make_shared<fcl::Sphered>(sp->DoubleAttribute("radius"));
      } else if (auto* cy = g->FirstChildElement("cylinder")) {
        shape = std::make_shared<fcl::Capsuled>(cy->DoubleAttribute("radius"), cy->DoubleAttribute("length"));
      } else {
        ADD_FAILURE() << "unexpected geometry in " << link->Attribute("name");
        continue;
      }
      out[link->Attribute("name")].push_back({shape, X});
    }
  }
  return out;
}

TEST(MeshFitBox, SmallHumanoidBoxesFittedWithoutAnOverlayAndNeverCloserThanFclSays) {
  // The shipped small humanoid has six boxes (pelvis, torso, hands, feet) and no overlay: the loader
  // fits each with fitBox, reports the numbers, and a flat box gets several capsules.
  std::vector<std::string> warnings;
  const Model model = testing::loadRobot(testing::kSmall, &warnings);
  EXPECT_EQ(warnings.size(), 6u);
  for (const auto& w : warnings)
    EXPECT_THAT(w, ::testing::MatchesRegex(".*box .* m fitted with [1-6] primitives? \\(8/8 corners enclosed.*"));
  EXPECT_GE(segmentPrimitives(model, "l_foot").size(), 2u);  // 0.16 x 0.08 x 0.02 m
  EXPECT_GE(segmentPrimitives(model, "r_foot").size(), 2u);

  // The oracle: FCL's distance between the true shapes (boxes as boxes) is never below the pair
  // distance Reflex computes on the fitted primitives, and where FCL finds the shapes touching,
  // Reflex's pair distance is <= 0.
  std::set<std::string> box_links;
  const auto shapes = fclShapes(testing::robotPath("small_humanoid.urdf"), &box_links);
  ASSERT_EQ(box_links.size(), 6u);
  OracleTally t;
  expectFittedNeverFartherThanOracle(
      model, 300, 11, 1e-6,
      [&](std::size_t i, const Eigen::Isometry3d& X_B_La, const Eigen::Isometry3d& X_B_Lb) {
        const std::string& la = model.segments[model.pairs[i].a].name;
        const std::string& lb = model.segments[model.pairs[i].b].name;
        if (!box_links.count(la) && !box_links.count(lb)) return std::optional<TrueDistance>();
        TrueDistance truth{false, std::numeric_limits<double>::infinity()};
        for (const auto& [ga, X_La_shape] : shapes.at(la))
          for (const auto& [gb, X_Lb_shape] : shapes.at(lb)) {
            const fcl::Transform3d Xa((X_B_La * X_La_shape).matrix()), Xb((X_B_Lb * X_Lb_shape).matrix());
            fcl::CollisionRequestd creq;
            fcl::CollisionResultd cres;
            fcl::collide(ga.get(), Xa, gb.get(), Xb, creq, cres);
            truth.touching = truth.touching || cres.isCollision();
            fcl::DistanceRequestd dreq;
            dreq.gjk_solver_type = fcl::GST_INDEP;
            fcl::DistanceResultd dres;
            fcl::distance(ga.get(), Xa, gb.get(), Xb, dreq, dres);
            truth.distance = std::min(truth.distance, dres.min_distance);
          }
        return std::optional<TrueDistance>(truth);
      },
      t);
  const int checked = t.checked, colliding = t.colliding;
  const double closest_margin = t.closest_margin;
  EXPECT_GT(checked, 5000);
  std::cout << "box pairs checked against FCL: " << checked << " apart, " << colliding
            << " intersecting; smallest (true - fitted) distance " << closest_margin << " m\n";
}

}  // namespace
}  // namespace reflex::control

namespace reflex::control {
namespace {

// meshesIntersect against analytic placements of two boxes (boxMesh): crossing surfaces, apart by
// 1 mm along each axis, one wholly inside the other (no surface crossing: the winding number), and a
// rotated box whose corner pokes 1 mm into the other.
TEST(MeshesIntersect, CrossingApartContainedAndACornerPokingIn) {
  const TriangleMesh a = boxMesh(Eigen::Vector3d(0.2, 0.2, 0.2), Eigen::Isometry3d::Identity());
  const TriangleMesh small = boxMesh(Eigen::Vector3d(0.05, 0.05, 0.05), Eigen::Isometry3d::Identity());
  const Eigen::Isometry3d I = Eigen::Isometry3d::Identity();
  auto at = [](double x, double y, double z) {
    Eigen::Isometry3d X = Eigen::Isometry3d::Identity();
    X.translation() = Eigen::Vector3d(x, y, z);
    return X;
  };
  EXPECT_TRUE(meshesIntersect(a, I, a, at(0.15, 0.0, 0.0)));  // overlap 0.05 m
  for (int k = 0; k < 3; ++k) {
    Eigen::Vector3d d = Eigen::Vector3d::Zero();
    d[k] = 0.2 + 0.001;
    EXPECT_FALSE(meshesIntersect(a, I, a, at(d.x(), d.y(), d.z()))) << "apart by 1 mm along axis " << k;
    d[k] = 0.2 - 0.001;
    EXPECT_TRUE(meshesIntersect(a, I, a, at(d.x(), d.y(), d.z()))) << "1 mm deep along axis " << k;
  }
  EXPECT_TRUE(meshesIntersect(a, I, small, at(0.01, -0.02, 0.03)));  // inside: no triangle crosses
  EXPECT_TRUE(meshesIntersect(small, at(0.01, -0.02, 0.03), a, I));  // the same, the other way round
  EXPECT_FALSE(meshesIntersect(a, I, small, at(0.5, 0.0, 0.0)));
  // A box turned 45 degrees about z and about x: its lowest corner 1 mm below the top face of a.
  Eigen::Isometry3d X = Eigen::Isometry3d::Identity();
  X.linear() = (Eigen::AngleAxisd(M_PI / 4, Eigen::Vector3d::UnitX()) *
                Eigen::AngleAxisd(std::atan(1.0 / std::sqrt(2.0)), Eigen::Vector3d::UnitY()))
                   .toRotationMatrix();
  // Lowest point of the turned small box, below its centre:
  double low = 0.0;
  for (const auto& v : small.vertices) low = std::min(low, (X.linear() * v).z());
  X.translation() = Eigen::Vector3d(0.0, 0.0, 0.1 - low - 0.001);
  EXPECT_TRUE(meshesIntersect(a, I, small, X)) << "a corner 1 mm in";
  X.translation().z() += 0.002;
  EXPECT_FALSE(meshesIntersect(a, I, small, X)) << "a corner 1 mm above";
}

}  // namespace
}  // namespace reflex::control

namespace reflex::control {
namespace {

// The fit accounts for every collision element as the loader does: a value urdfdom cannot read (it
// then drops every collision element of the link) is an error naming the link and the value, not a
// link silently left out of the fit.
TEST(MeshFit, ACollisionElementUrdfdomDropsIsAnErrorNamingTheLink) {
  std::ifstream in(kUrdf);
  std::stringstream ss;
  ss << in.rdbuf();
  std::string xml = ss.str();
  const std::string good = "<collision name=\"torso_0\">\n      <origin xyz=\"0 0 0\"";
  const auto at = xml.find(good);
  ASSERT_NE(at, std::string::npos);
  xml.replace(at, good.size(), "<collision name=\"torso_0\">\n      <origin xyz=\"nan 0 0\"");
  const std::string path = ::testing::TempDir() + "mesh_humanoid_nan.urdf";
  std::ofstream(path) << xml;
  PackagePaths paths;
  paths.packages["mesh_humanoid_description"] = kPackageDir;
  paths.use_ros_package_path = false;
  try {
    (void)fitRobot(path, paths, FitOptions{});
    FAIL() << "fitted a URDF whose torso urdfdom cannot read";
  } catch (const ModelError& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find(path + ": cannot fit: collision geometry would be left out or is out of range (1 problem):\n"
                               "  link 'torso': urdfdom read 0 of its 2 collision elements"),
              std::string::npos)
        << what;
    EXPECT_NE(what.find("'nan' is not a finite number"), std::string::npos) << what;
  }
}

}  // namespace
}  // namespace reflex::control

namespace reflex::control {
namespace {

// A binary STL of `n` triangles (each a small triangle at x = i mm), `patch` changing any vertex.
void writeBinaryStl(const std::string& path, std::uint32_t n,
                    const std::function<void(std::uint32_t, int, float*)>& patch = {}) {
  std::ofstream out(path, std::ios::binary);
  const std::string header(80, ' ');
  out.write(header.data(), 80);
  out.write(reinterpret_cast<const char*>(&n), 4);
  for (std::uint32_t i = 0; i < n; ++i) {
    float f[12] = {0,     0, 1, 0.001f * (i % 1000), 0, 0, 0.001f * (i % 1000) + 0.01f, 0, 0, 0.001f * (i % 1000),
                   0.01f, 0};
    for (int k = 0; k < 3 && patch; ++k) patch(i, k, f + 3 + 3 * k);
    out.write(reinterpret_cast<const char*>(f), sizeof f);
    const std::uint16_t attr = 0;
    out.write(reinterpret_cast<const char*>(&attr), 2);
  }
}

// Mesh values obey the ranges of URDF values, and a mesh beyond the stated size is refused before any
// work: a NaN in the second triangle (it used to be merged away: a NaN map key), a vertex at 1e30 m (it
// became a 1e30 m capsule), one 10 m out only at scale 2, and 200,001 triangles (1 M took 358 s and
// 8.1 GB to fit).
TEST(MeshFit, MeshValuesBeyondTheRangesAndMeshesBeyondTheSizeAreRefused) {
  const std::string dir = ::testing::TempDir();
  auto message = [](const std::string& path, const Vector3d& scale) {
    try {
      (void)loadMeshFile(path, scale);
    } catch (const ModelError& e) {
      return std::string(e.what());
    }
    return std::string("(loaded)");
  };
  writeBinaryStl(dir + "nan.stl", 2, [](std::uint32_t i, int k, float* v) {
    if (i == 1 && k == 2) v[1] = std::nanf("");
  });
  EXPECT_THAT(message(dir + "nan.stl", Vector3d::Ones()), ::testing::HasSubstr("nan.stl: mesh vertex "));
  EXPECT_THAT(message(dir + "nan.stl", Vector3d::Ones()), ::testing::HasSubstr(" is not finite"));
  writeBinaryStl(dir + "far.stl", 2, [](std::uint32_t i, int k, float* v) {
    if (i == 1 && k == 1) v[0] = 1e30f;
  });
  EXPECT_THAT(message(dir + "far.stl", Vector3d::Ones()),
              ::testing::HasSubstr("is out of range (|coordinate| <= 10 m after scale)"));
  writeBinaryStl(dir + "six.stl", 2, [](std::uint32_t i, int k, float* v) {
    if (i == 1 && k == 1) v[2] = 6.0f;
  });
  EXPECT_EQ(message(dir + "six.stl", Vector3d::Ones()), "(loaded)");
  EXPECT_THAT(message(dir + "six.stl", Vector3d::Constant(2.0)), ::testing::HasSubstr(", 0, 12) m is out of range"));
  writeBinaryStl(dir + "big.stl", 200001);
  EXPECT_EQ(message(dir + "big.stl", Vector3d::Ones()),
            dir +
                "big.stl: mesh has 200001 triangles, more than the 200000 a collision mesh may have: decimate it (a "
                "collision mesh needs the shape, not the detail)");
  writeBinaryStl(dir + "ok.stl", 200000);
  EXPECT_EQ(message(dir + "ok.stl", Vector3d::Ones()), "(loaded)");
}

}  // namespace
}  // namespace reflex::control
