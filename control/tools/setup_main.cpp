// reflex_setup: from a humanoid's URDF (and SRDF, meshes) to the three configuration files Reflex needs:
// DIR/controller.yaml, DIR/collision.yaml, DIR/behavior.yaml (and DIR/<stem>.fit.yaml when the robot
// has meshes). Prints every decision with its reason, one line each; warns about stretches of an arm
// outside every collision primitive. Every file written is read back with the project's own readers.
// See control/README.md, "Setting up a new robot", and robot_setup.hpp for the rules.
#include "reflex/common/files.hpp"
#include "reflex/control/controller.hpp"
#include "reflex/control/mesh_fit.hpp"
#include "package_args.hpp"
#include "reflex/control/pair_sampling.hpp"
#include "reflex/control/robot_setup.hpp"
#include "reflex/control/simulation.hpp"
#include "reflex/control/urdf_loader.hpp"

#include <CLI/CLI.hpp>
#include <tinyxml2.h>

#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <cstdio>
#include <sys/stat.h>

#include <filesystem>
#include <fstream>
#include <iostream>
#include <map>
#include <string>
#include <vector>

namespace fs = std::filesystem;
using reflex::control::Model;

namespace {

std::string num(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.4f", v);
  std::string s = buf;
  while (s.size() > 1 && s.back() == '0') s.pop_back();
  if (s.back() == '.') s.pop_back();
  return s == "-0" ? "0" : s;
}

void writeFile(const std::string& path, const std::string& text) {
  if (const std::string why = reflex::common::outputFileProblem(path); !why.empty())
    throw std::runtime_error("output " + why);
  if (const std::string why = reflex::common::writeFileReplacing(path, text); !why.empty()) throw std::runtime_error(why);
}

// Whether any <collision> of the URDF holds a <mesh> (then the robot needs a fit overlay).
bool hasMeshCollision(const std::string& urdf) {
  tinyxml2::XMLDocument doc;
  if (doc.LoadFile(urdf.c_str()) != tinyxml2::XML_SUCCESS)
    throw std::runtime_error(urdf + ": cannot read the URDF as XML: " + std::string(doc.ErrorStr()));
  const tinyxml2::XMLElement* robot = doc.FirstChildElement("robot");
  for (auto* l = robot ? robot->FirstChildElement("link") : nullptr; l; l = l->NextSiblingElement("link"))
    for (auto* c = l->FirstChildElement("collision"); c; c = c->NextSiblingElement("collision"))
      if (const auto* g = c->FirstChildElement("geometry"); g && g->FirstChildElement("mesh")) return true;
  return false;
}

// A copy of the URDF with the gap-closing <collision> elements added to their links; relative mesh
// filenames are made absolute so they still resolve from the copy's folder.
void writeClosedUrdf(const std::string& urdf, const std::string& out, const std::vector<reflex::control::ArmGap>& gaps) {
  tinyxml2::XMLDocument doc;
  if (doc.LoadFile(urdf.c_str()) != tinyxml2::XML_SUCCESS) throw std::runtime_error(urdf + ": cannot read the URDF");
  tinyxml2::XMLElement* robot = doc.FirstChildElement("robot");
  const fs::path dir = fs::absolute(fs::path(urdf)).parent_path();
  for (auto* l = robot->FirstChildElement("link"); l; l = l->NextSiblingElement("link")) {
    for (auto* c = l->FirstChildElement("collision"); c; c = c->NextSiblingElement("collision")) {
      auto* g = c->FirstChildElement("geometry");
      auto* mesh = g ? g->FirstChildElement("mesh") : nullptr;
      const char* f = mesh ? mesh->Attribute("filename") : nullptr;
      if (f && std::string(f).find("://") == std::string::npos && f[0] != '/')
        mesh->SetAttribute("filename", (dir / f).lexically_normal().string().c_str());
    }
    for (const auto& gap : gaps) {
      if (gap.link != l->Attribute("name")) continue;
      tinyxml2::XMLDocument frag;
      frag.Parse(gap.urdf_snippet.c_str());
      l->InsertEndChild(frag.FirstChildElement("collision")->DeepClone(&doc));
    }
  }
  if (doc.SaveFile(out.c_str()) != tinyxml2::XML_SUCCESS) throw std::runtime_error(reflex::common::writeError(out, errno));
}

// `path` as written into a file in `dir`: relative to dir when that stays near it (at most two levels
// up, so the folder can move with the robot), else absolute.
std::string relativeTo(const std::string& path, const std::string& dir) {
  const fs::path abs = fs::absolute(path).lexically_normal();
  const fs::path rel = fs::relative(abs, fs::absolute(dir)).lexically_normal();
  int up = 0;
  for (const auto& part : rel) up += part == "..";
  return rel.empty() || up > 2 ? abs.string() : rel.string();
}

// A private folder inside DIR for the files being made; removed with everything in it when set-up ends.
struct Staging {
  std::string dir;
  explicit Staging(const std::string& parent) {
    std::string tmpl = (fs::path(parent) / ".reflex_setup.XXXXXX").string();
    if (!mkdtemp(tmpl.data()))
      throw std::runtime_error("--out '" + parent + "': cannot make a staging folder in it: " + std::strerror(errno));
    dir = tmpl;
  }
  ~Staging() {
    std::error_code ec;
    fs::remove_all(dir, ec);
  }
  Staging(const Staging&) = delete;
  Staging& operator=(const Staging&) = delete;
};

std::string vec3(const Eigen::Vector3d& v) { return "[" + num(v.x()) + ", " + num(v.y()) + ", " + num(v.z()) + "]"; }

}  // namespace

int run(int argc, char** argv) {
  CLI::App app{"reflex_setup: find a humanoid's arms, hands, head, rest posture and collision pairs from its "
               "URDF and write DIR/controller.yaml, DIR/collision.yaml and DIR/behavior.yaml (and the mesh fit), "
               "printing every choice and why. See control/README.md, \"Setting up a new robot\"."};
  std::string urdf, srdf, out_dir;
  std::vector<std::string> package_args;
  reflex::control::SetupOptions o;
  reflex::control::PairSamplingOptions sampling;
  sampling.samples = 5000;
  bool close_gaps = false, force = false;
  app.add_option("urdf", urdf, "the robot's URDF")->required();
  app.add_option("--srdf", srdf, "SRDF whose <disable_collisions> pairs are excluded (written as srdf: in collision.yaml)");
  app.add_option("--package-path", package_args, "NAME=DIR: where package://NAME/... meshes are (repeatable)");
  app.add_option("--out", out_dir, "folder to write the configuration files into (created)")->required();
  app.add_option("--left-hand", o.left_hand, "left hand link (default: found by structure; give with --right-hand)");
  app.add_option("--right-hand", o.right_hand, "right hand link");
  app.add_option("--head", o.head, "head link (default: found by structure)");
  app.add_option("--camera", o.camera, "head camera link (default: a link named like a camera fixed below the head)");
  app.add_option("--samples", sampling.samples, "random configurations for the pair sampling")->check(CLI::Range(100, 1000000));
  app.add_option("--seed", sampling.seed, "random seed (pair sampling, rest search, gap check)");
  app.add_option("--gap-tolerance", o.gap_tolerance, "m: an arm skeleton point farther than this from the arm's "
                 "primitives is a gap")->check(CLI::Range(0.001, 0.5));
  app.add_option("--rest-margin", o.rest_margin, "m: the rest posture clears every arm pair by d_a + this")
      ->check(CLI::Range(0.0, 0.2));
  app.add_flag("--close-gaps", close_gaps, "write DIR/<stem>.urdf, a copy of the URDF with the capsules that close "
               "the gaps, and configure the robot from it");
  app.add_flag("--force", force, "replace files already in DIR");
  CLI11_PARSE(app, argc, argv);
  o.seed = sampling.seed;
  o.d_a = reflex::control::ControllerParams{}.d_a;
  sampling.near_distance = o.d_a;

  std::pair<std::string, std::string> staged_as;  // (staging folder, DIR)
  try {
    for (const auto& [what, path] : {std::pair<std::string, std::string>{"URDF", urdf}, {"--srdf", srdf}}) {
      if (path.empty()) continue;
      if (!fs::exists(path)) throw std::runtime_error(what + " '" + path + "' does not exist");
      if (const std::string why = reflex::common::inputFileProblem(path); !why.empty()) throw std::runtime_error(what + " " + why);
    }
    const reflex::control::PackagePaths paths = reflex::control::parsePackagePathArgs(package_args);
    if (const std::string why = reflex::common::outputFolderProblem(out_dir); !why.empty())
      throw std::runtime_error("--out: " + why);
    std::error_code ec;
    fs::create_directories(out_dir, ec);
    if (ec) throw std::runtime_error("--out '" + out_dir + "': cannot create the folder: " + ec.message());
    const std::string stem = fs::path(urdf).stem().string();
    const std::string final_dir = out_dir;
    const auto finalPath = [&](const std::string& name) { return (fs::path(final_dir) / name).string(); };
    // Every file set-up may write, checked before any work: only a regular file is ever replaced (a
    // directory, a device or a FIFO in its place is an error), and only with --force.
    std::vector<std::string> outputs = {finalPath("controller.yaml"), finalPath("collision.yaml"), finalPath("behavior.yaml")};
    if (hasMeshCollision(urdf)) outputs.push_back(finalPath(stem + ".fit.yaml"));
    if (close_gaps) outputs.push_back(finalPath(stem + ".urdf"));
    for (const std::string& p : outputs) {
      struct stat st {};
      if (::lstat(p.c_str(), &st) != 0) continue;
      if (!S_ISREG(st.st_mode))
        throw std::runtime_error("'" + p + "' exists and is " + reflex::common::fileKind(st.st_mode) +
                                 ": reflex_setup replaces only regular files; remove it or choose another --out");
      if (!force && p != finalPath(stem + ".fit.yaml"))
        throw std::runtime_error("'" + p + "' exists; give --force to replace it");
    }
    if (close_gaps && fs::exists(finalPath(stem + ".urdf")) && fs::equivalent(finalPath(stem + ".urdf"), urdf))
      throw std::runtime_error("--close-gaps would overwrite the URDF '" + urdf + "' itself; choose another --out");
    // Everything is written into a staging folder inside DIR first and read back from there; only a
    // set-up that gets to the end replaces the files in DIR. A failure leaves DIR as it was.
    const Staging staging(final_dir);
    out_dir = staging.dir;
    staged_as = {staging.dir, final_dir};
    const std::string controller_path = (fs::path(out_dir) / "controller.yaml").string();
    const std::string collision_path = (fs::path(out_dir) / "collision.yaml").string();
    const std::string behavior_path = (fs::path(out_dir) / "behavior.yaml").string();
    const std::string fit_path = (fs::path(out_dir) / (stem + ".fit.yaml")).string();
    const std::string closed_urdf = (fs::path(out_dir) / (stem + ".urdf")).string();

    // 1. The mesh fit, when the robot has meshes.
    const bool meshes = hasMeshCollision(urdf);
    std::string fit_final_text;
    auto fit = [&](const std::string& robot_urdf) {
      // A fit already in DIR for this URDF, with the default options, that the loader takes (every mesh
      // link there, no input changed since: same hashes) is reused; anything else is fitted anew.
      const std::string existing = finalPath(stem + ".fit.yaml");
      if (robot_urdf == urdf && fs::exists(existing)) {
        std::string why_not;
        try {
          const auto old = reflex::control::loadFitOverlay(existing);
          const reflex::control::FitOptions d;
          const auto& f = old.options;
          std::error_code ec;
          if (!fs::equivalent(old.urdf, urdf, ec)) why_not = "it is the fit of '" + old.urdf + "'";
          else if (f.max_primitives != d.max_primitives || f.split_ratio != d.split_ratio ||
                   f.min_split_gain != d.min_split_gain || f.quantum != d.quantum ||
                   f.max_pieces != d.max_pieces || f.piece_gap != d.piece_gap ||
                   f.max_pieces_large_gap != d.max_pieces_large_gap || f.large_gap != d.large_gap)
            why_not = "it was made with other options";
          else {
            reflex::control::CollisionConfig c;
            c.exclude_adjacent = false;
            c.fit = existing;
            (void)reflex::control::loadModel(urdf, c);  // throws for a stale or incomplete fit
            writeFile(fit_path, reflex::control::fitOverlayText(old, fit_path));
            fit_final_text = reflex::control::fitOverlayText(old, existing);
            std::printf("fit: reusing %s (the fit of this URDF with the default options; every mesh unchanged)\n",
                        existing.c_str());
            return;
          }
        } catch (const std::exception& e) {
          why_not = e.what();
        }
        std::printf("fit: not reusing %s: %s\n", existing.c_str(), why_not.c_str());
      }
      std::printf("fit: the URDF has mesh collision geometry: fitting capsules and spheres (reflex_fit) into %s\n",
                  fit_path.c_str());
      const auto overlay = reflex::control::fitRobot(robot_urdf, paths, reflex::control::FitOptions{});
      writeFile(fit_path, reflex::control::fitOverlayText(overlay, fit_path));
      auto as_final = overlay;  // as read from DIR: the URDF given, or the gap-closed copy in DIR
      if (robot_urdf != urdf) as_final.urdf = finalPath(stem + ".urdf");
      fit_final_text = reflex::control::fitOverlayText(as_final, finalPath(stem + ".fit.yaml"));
      for (const auto& l : overlay.links)
        std::printf("fit: %s: %zu primitives, %d/%d vertices enclosed, volume ratio %.3f, worst gap %.4f m\n",
                    l.link.c_str(), l.primitives.size(), l.stats.vertices_enclosed, l.stats.vertices,
                    l.stats.volume_ratio, l.stats.worst_gap);
    };
    if (meshes) fit(urdf);

    // 2. Which pairs to check: SRDF + sampling (as reflex_inspect --sample-pairs).
    reflex::control::CollisionConfig every;
    every.exclude_adjacent = false;
    if (meshes) every.fit = fit_path;
    reflex::control::CollisionConfig nonadj_config = every;
    nonadj_config.exclude_adjacent = true;
    if (!srdf.empty()) {
      nonadj_config.srdf = srdf;
      nonadj_config.srdf_disabled = reflex::control::loadSrdfDisabledCollisions(srdf);
    }
    const Model all = reflex::control::loadModel(urdf, every);
    const Model nonadj = reflex::control::loadModel(urdf, nonadj_config);
    // The structure first (it does not depend on the pair list): a robot without clear arms writes nothing.
    std::map<std::string, reflex::control::TriangleMesh> link_meshes;
    // The joints Reflex drives (both arms, the walking joints): a pair no driven joint moves is not checked.
    {
      const reflex::control::RobotSetup structure = reflex::control::findRobotStructure(nonadj, o);
      for (const auto& arm : structure.arms) {
        sampling.driven_joints.insert(sampling.driven_joints.end(), arm.joints.begin(), arm.joints.end());
        sampling.arm_joints.insert(sampling.arm_joints.end(), arm.joints.begin(), arm.joints.end());
      }
      sampling.standing = reflex::control::neutralConfiguration(all);
      const reflex::control::ControllerParams defaults;
      sampling.touch_distance = defaults.d_r + defaults.estop_release_margin;
      sampling.exclude_always_near = true;
      if (meshes) {  // "always in collision" only where the original meshes intersect
        link_meshes = reflex::control::linkCollisionMeshes(urdf, paths);
        sampling.confirm_collision = [&](int sa, int sb, const reflex::control::KinematicsData& kin) {
          const int la = nonadj.segments[static_cast<std::size_t>(sa)].link;
          const int lb = nonadj.segments[static_cast<std::size_t>(sb)].link;
          const auto ma = link_meshes.find(nonadj.links[static_cast<std::size_t>(la)].name);
          const auto mb = link_meshes.find(nonadj.links[static_cast<std::size_t>(lb)].name);
          if (ma == link_meshes.end() || mb == link_meshes.end()) return true;  // primitives: the model is exact
          return reflex::control::meshesIntersect(ma->second, kin.X_B_L[static_cast<std::size_t>(la)], mb->second,
                                                  kin.X_B_L[static_cast<std::size_t>(lb)]);
        };
      }
      const reflex::control::WalkingPattern walking(nonadj);
      for (const int qi : walking.joints())
        sampling.driven_joints.push_back(nonadj.q_names[static_cast<std::size_t>(qi)]);
    }
    std::fprintf(stderr, "reflex_setup: sampling %d configurations for the pair list\n", sampling.samples);
    const auto report = reflex::control::samplePairs(all, nonadj, sampling);
    int always = 0, never = 0, undriven = 0, near = 0, standing = 0;
    for (const auto& p : report.pairs) {
      always += p.verdict == reflex::control::PairVerdict::kAlwaysInCollision;
      never += p.verdict == reflex::control::PairVerdict::kNeverClose;
      near += p.verdict == reflex::control::PairVerdict::kAlwaysNear;
      standing += p.verdict == reflex::control::PairVerdict::kTouchingStanding;
      if (p.verdict == reflex::control::PairVerdict::kAlwaysNear && p.min_distance <= sampling.touch_distance)
        std::printf("WARNING: pair '%s'-'%s' is never farther apart than %.1f mm (inside d_a at every posture) and comes "
                    "%.1f mm close: NOT checked (the avoidance would hold the arm off every target); the joint limits "
                    "and the robot's own controller must keep it apart\n",
                    p.a.c_str(), p.b.c_str(), 1e3 * std::min(p.max_distance, p.driven_max_distance),
                    1e3 * p.min_distance);
      if (p.verdict == reflex::control::PairVerdict::kTouchingStanding)
        std::printf("WARNING: pair '%s'-'%s' is %.1f mm apart in the standing posture and no arm joint moves it: NOT "
                    "checked (the red zone would latch at start); the robot's own controller must keep it apart\n",
                    p.a.c_str(), p.b.c_str(), 1e3 * p.standing_distance);
      if (p.verdict != reflex::control::PairVerdict::kNotDriven) continue;
      ++undriven;
      if (p.min_distance < sampling.near_distance)
        std::printf("WARNING: pair '%s'-'%s' is moved by no joint Reflex drives and comes %.1f mm close (sampled over "
                    "the joints that move it): NOT checked; the robot's own controller must keep it apart\n",
                    p.a.c_str(), p.b.c_str(), 1e3 * p.min_distance);
    }
    std::string collision = "# Written by reflex_setup for " + urdf + " (keys: control/docs/configuration.md).\n" +
                            reflex::control::exclusionYaml(report);
    std::string collision_final = collision;
    if (!srdf.empty()) {
      collision += "srdf: " + relativeTo(srdf, out_dir) + "   # its <disable_collisions> pairs are excluded too\n";
      collision_final += "srdf: " + relativeTo(srdf, final_dir) + "   # its <disable_collisions> pairs are excluded too\n";
    }
    if (meshes) {
      collision += "fit: " + fs::path(fit_path).filename().string() + "   # the mesh fit (reflex_fit)\n";
      collision_final += "fit: " + fs::path(fit_path).filename().string() + "   # the mesh fit (reflex_fit)\n";
    }
    writeFile(collision_path, collision);
    std::printf("pairs: %d sampled configurations%s: %d pairs always in collision (excluded), %d never closer than "
                "d_a (listed, commented out: still checked), %zu adjacent (not checked), %d moved by no joint Reflex "
                "drives, %d never out of d_a, %d touching standing (these three not checked: listed in %s)\n",
                sampling.samples, srdf.empty() ? "" : " after the SRDF's exclusions", always, never,
                report.adjacent.size(), undriven, near, standing, finalPath("collision.yaml").c_str());

    // 3. The robot as the controller will load it, and what the setup finds on it.
    std::string robot_urdf = urdf;
    Model model = reflex::control::loadModel(urdf, reflex::control::loadCollisionConfig(collision_path));
    reflex::control::RobotSetup setup = reflex::control::findRobotStructure(model, o);
    reflex::control::findRestPosture(model, o, setup);
    reflex::control::findArmGaps(model, o, setup);
    for (const auto& g : setup.gaps) {
      std::printf("%s\n", g.message.c_str());
      std::printf("  paste into <link name=\"%s\"> of the URDF (Reflex reads a cylinder as that capsule), or rerun "
                  "with --close-gaps:\n  %s\n", g.link.c_str(), g.urdf_snippet.c_str());
    }
    std::vector<reflex::control::ArmGap> closing_gaps;
    if (close_gaps && !setup.gaps.empty()) {
      writeClosedUrdf(urdf, closed_urdf, setup.gaps);
      closing_gaps = setup.gaps;
      std::printf("gaps: wrote %s with %zu closing capsules; configuring that robot\n", finalPath(stem + ".urdf").c_str(),
                  setup.gaps.size());
      robot_urdf = closed_urdf;
      if (meshes) fit(robot_urdf);
      model = reflex::control::loadModel(robot_urdf, reflex::control::loadCollisionConfig(collision_path));
      setup = reflex::control::findRobotStructure(model, o);
      reflex::control::findRestPosture(model, o, setup);
      if (const int left = reflex::control::findArmGaps(model, o, setup); left > 0)
        std::printf("gaps: %d remain after closing\n", left);
    }

    // 4. controller.yaml, read back and resolved against the robot.
    std::string ctl = "# Controller configuration of " + model.name + ", written by reflex_setup (every key: "
                      "control/docs/configuration.md).\n# Parameters not given take their defaults (control/README.md, "
                      "\"Controller parameters\").\n";
    for (const auto& d : setup.decisions) ctl += "# " + d + "\n";
    ctl += "arms:\n";
    for (const auto& arm : setup.arms) {
      ctl += "  " + arm.side + ":\n    joints: [";
      for (std::size_t i = 0; i < arm.joints.size(); ++i) ctl += (i ? ", " : "") + arm.joints[i];
      ctl += "]\n    hand_link: " + arm.hand_link + "\n    hand_point: " + vec3(arm.hand_point_L) + "   # m, in " +
             arm.hand_link + "\n    rest: [";
      for (std::size_t i = 0; i < arm.rest.size(); ++i) ctl += (i ? ", " : "") + num(arm.rest[i]);
      ctl += "]   # rad\n";
    }
    if (!setup.camera_link.empty())
      ctl += "camera_link: " + setup.camera_link + "   # the head camera (reflex_sim's occlusion gaze line starts here)\n";
    writeFile(controller_path, ctl);
    const auto cconf = reflex::control::loadControllerConfig(controller_path);
    const auto cm = reflex::control::makeControllerModel(model, cconf);

    for (const auto& d : setup.decisions) std::printf("%s\n", d.c_str());

    // 5. A behavior that works with this robot: both hands to points 8 cm in front of (and 5 cm above) their
    // rest positions, checked here by a closed-loop run of the controller (smaller steps if not reached).
    reflex::control::KinematicsData kin(model);
    Eigen::VectorXd q = reflex::control::neutralConfiguration(model);
    for (const auto& arm : cm.arms)
      for (int i = 0; i < arm.n; ++i) q[arm.q[i]] = arm.rest[i];
    reflex::control::computeForwardKinematics(model, kin, q);
    reflex::control::ReachCheck reach;
    double offset = 0.0;
    std::string towards;
    // Forward and up first; where the arms rest inside the avoidance zone (a crowded shoulder) a move
    // that opens it (up, out, down) may be what the robot can do: the first one reached is written.
    const Eigen::Vector3d up = Eigen::Vector3d::UnitZ(), left = up.cross(setup.forward);
    const std::vector<std::pair<std::string, Eigen::Vector3d>> directions = {
        {"forward, 0.6 x up", setup.forward + 0.6 * up}, {"up", up}, {"out", left}, {"down", -up}};
    bool reached = false;
    for (const auto& [name, dir] : directions) {
      for (double off : {0.08, 0.05, 0.03}) {
        std::array<Eigen::Vector3d, 2> t;
        for (int a = 0; a < 2; ++a) {
          Eigen::Vector3d d = dir;
          if (a == 1) d = d - 2.0 * d.dot(left) * left;  // mirrored: out is to the right for the right hand
          t[a] = kin.X_B_L[cm.arms[a].hand_link] * cm.arms[a].hand_point_L + off * d;
        }
        for (auto& v : t)
          for (int i = 0; i < 3; ++i) v[i] = std::round(v[i] * 1000.0) / 1000.0;  // as written (mm)
        reach = reflex::control::checkReach(model, cm, t, 4.0, 0.01);
        offset = off;
        towards = name;
        reached = reach.reached_at >= 0 && reach.estops == 0 && reach.min_distance > cm.params.d_r;
        if (reached) break;
      }
      if (reached) break;
    }
    std::printf("behavior: both hands to %s / %s (rest + %.2f m %s): %s; closest pair during the "
                "run %.3f m (d_r %.3f m), %llu e-stops\n",
                vec3(reach.target_B[0]).c_str(), vec3(reach.target_B[1]).c_str(), offset, towards.c_str(),
                reached ? ("reached within 10 mm after " + num(reach.reached_at) + " s of a closed-loop run").c_str()
                        : ("NOT reached in 4 s (errors " + num(reach.error[0]) + " / " + num(reach.error[1]) + " m)").c_str(),
                reach.min_distance, cm.params.d_r, static_cast<unsigned long long>(reach.estops));
    std::string beh = "# Behavior configuration for " + model.name + ", written by reflex_setup: both hands reach to a\n"
                      "# point near their rest positions and stay (checked by a closed-loop run at set-up).\n"
                      "#   reflex_behavior --config " + behavior_path + "\n# Keys: modules/README.md, control/docs/configuration.md.\n"
                      "process: behavior\n\nrobot:\n";
    const std::string robot_urdf_final = robot_urdf == urdf ? urdf : finalPath(stem + ".urdf");
    beh += "  urdf: " + relativeTo(robot_urdf_final, final_dir) + "   # relative to this file\n";
    beh += "  collision: collision.yaml\n";
    beh += "  left_shoulder: " + setup.arms[0].shoulder_link + "\n  right_shoulder: " + setup.arms[1].shoulder_link + "\n";
    beh += "  left_hand: " + setup.arms[0].hand_link + "\n  right_hand: " + setup.arms[1].hand_link + "\n";
    beh += "  head: " + setup.head_link + "\n  head_camera: " + setup.camera_link + "\n";
    beh += "  hand_point: " + vec3(setup.arms[0].hand_point_L) + "   # m, in the hand link (the left hand's; "
           "the controller has one per arm)\n\n";
    beh += "modules:\n  - name: reach\n    type: scripted\n    config:\n      timeline:\n        - {t: 0.0, left: " +
           vec3(reach.target_B[0]) + ", right: " + vec3(reach.target_B[1]) + "}\n";
    writeFile(behavior_path, beh);
    // Into DIR: the texts as they read from there (the fit's and the SRDF's relative paths).
    if (meshes) writeFile(finalPath(stem + ".fit.yaml"), fit_final_text);
    writeFile(finalPath("collision.yaml"), collision_final);
    writeFile(finalPath("controller.yaml"), ctl);
    if (robot_urdf != urdf) writeClosedUrdf(urdf, robot_urdf_final, closing_gaps);
    writeFile(finalPath("behavior.yaml"), beh);
    std::printf("wrote %s, %s, %s%s%s\n", finalPath("controller.yaml").c_str(), finalPath("collision.yaml").c_str(),
                finalPath("behavior.yaml").c_str(), meshes ? ", " : "", meshes ? finalPath(stem + ".fit.yaml").c_str() : "");
    std::printf("next: reflex_sim SCENARIO --urdf %s --collision %s --controller %s --out RUN\n",
                robot_urdf_final.c_str(), finalPath("collision.yaml").c_str(), finalPath("controller.yaml").c_str());
    std::printf("next: reflex_controller --urdf %s --collision %s --controller %s; reflex_behavior --config %s\n",
                robot_urdf_final.c_str(), finalPath("collision.yaml").c_str(), finalPath("controller.yaml").c_str(),
                finalPath("behavior.yaml").c_str());
    return reached ? 0 : 2;
  } catch (const std::exception& e) {
    // Errors name the files as they would be in DIR, never the staging folder (removed by now).
    std::string what = e.what();
    if (!staged_as.first.empty())
      for (std::size_t at = what.find(staged_as.first); at != std::string::npos; at = what.find(staged_as.first, at))
        what.replace(at, staged_as.first.size(), staged_as.second);
    std::fprintf(stderr, "reflex_setup: error: %s\n", what.c_str());
    return 1;
  }
}

int main(int argc, char** argv) {
  const int status = run(argc, argv);
  if (const std::string why = reflex::common::flushStandardOutput(); !why.empty()) {
    std::fprintf(stderr, "reflex_setup: error: %s\n", why.c_str());
    return 1;
  }
  return status;
}
