// reflex_setup: from a humanoid's URDF (and SRDF, meshes) to the three configuration files Reflex needs:
// DIR/controller.yaml, DIR/collision.yaml, DIR/behavior.yaml (and DIR/<stem>.fit.yaml when the robot
// has meshes). Prints every decision with its reason, one line each; warns about stretches of an arm
// outside every collision primitive. Every file written is read back with the project's own readers.
// See control/README.md, "Setting up a new robot", and robot_setup.hpp for the rules.
#include "reflex/common/run_main.hpp"
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
#include <memory>
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
    throw reflex::Error("output " + why);
  if (const std::string why = reflex::common::writeFileReplacing(path, text); !why.empty()) throw reflex::Error(why);
}

// Whether any <collision> of the URDF holds a <mesh> (then the robot needs a fit overlay).
bool hasMeshCollision(const std::string& urdf) {
  tinyxml2::XMLDocument doc;
  if (doc.LoadFile(urdf.c_str()) != tinyxml2::XML_SUCCESS)
    throw reflex::Error(urdf + ": cannot read the URDF as XML: " + std::string(doc.ErrorStr()));
  const tinyxml2::XMLElement* robot = doc.FirstChildElement("robot");
  for (auto* l = robot ? robot->FirstChildElement("link") : nullptr; l; l = l->NextSiblingElement("link"))
    for (auto* c = l->FirstChildElement("collision"); c; c = c->NextSiblingElement("collision"))
      if (const auto* g = c->FirstChildElement("geometry"); g && g->FirstChildElement("mesh")) return true;
  return false;
}

// A copy of the URDF with the gap-closing <collision> elements added to their links; relative mesh
// filenames are made absolute so they still resolve from the copy's folder.
void writeClosedUrdf(const std::string& urdf, const std::string& out,
                     const std::vector<reflex::control::ArmGap>& gaps) {
  tinyxml2::XMLDocument doc;
  if (doc.LoadFile(urdf.c_str()) != tinyxml2::XML_SUCCESS) throw reflex::Error(urdf + ": cannot read the URDF");
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
  if (doc.SaveFile(out.c_str()) != tinyxml2::XML_SUCCESS) throw reflex::Error(reflex::common::writeError(out, errno));
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
      throw reflex::Error("--out '" + parent + "': cannot make a staging folder in it: " + std::strerror(errno));
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

/// Exit code: the files are written, but the closed-loop check did not reach the rest posture.
constexpr int kExitNotReached = 3;

/// What the command line asks for.
struct Args {
  std::string urdf, srdf, out_dir;
  std::vector<std::string> package_args;
  reflex::control::SetupOptions o;
  reflex::control::PairSamplingOptions sampling;
  bool close_gaps = false, force = false;
};

void addOptions(CLI::App& app, Args& a) {
  a.sampling.samples = 5000;
  app.add_option("urdf", a.urdf, "the robot's URDF")->required();
  app.add_option("--srdf", a.srdf,
                 "SRDF whose <disable_collisions> pairs are excluded (written as srdf: in collision.yaml)");
  app.add_option("--package-path", a.package_args, "NAME=DIR: where package://NAME/... meshes are (repeatable)");
  app.add_option("--out", a.out_dir, "folder to write the configuration files into (created)")->required();
  app.add_option("--left-hand", a.o.left_hand, "left hand link (default: found by structure; give with --right-hand)");
  app.add_option("--right-hand", a.o.right_hand, "right hand link");
  app.add_option("--head", a.o.head, "head link (default: found by structure)");
  app.add_option("--camera", a.o.camera, "head camera link (default: a link named like a camera fixed below the head)");
  app.add_option("--samples", a.sampling.samples, "random configurations for the pair sampling")
      ->check(CLI::Range(100, 1000000));
  app.add_option("--seed", a.sampling.seed, "random seed (pair sampling, rest search, gap check)");
  app.add_option("--gap-tolerance", a.o.gap_tolerance,
                 "m: an arm skeleton point farther than this from the arm's "
                 "primitives is a gap")
      ->check(reflex::FiniteRange(0.001, 0.5));
  app.add_option("--rest-margin", a.o.rest_margin, "m: the rest posture clears every arm pair by d_a + this")
      ->check(reflex::FiniteRange(0.0, 0.2));
  app.add_flag("--close-gaps", a.close_gaps,
               "write DIR/<stem>.urdf, a copy of the URDF with the capsules that close "
               "the gaps, and configure the robot from it");
  app.add_flag("--force", a.force, "replace files already in DIR");
}

/// One set-up, step by step: the members are what the steps hand on. Every file goes into a staging
/// folder inside DIR first and is read back from there; only a set-up that gets to the end writes DIR.
class Setup {
 public:
  explicit Setup(Args args) : a_(std::move(args)), final_dir_(a_.out_dir) {
    a_.o.seed = a_.sampling.seed;
    a_.o.d_a = reflex::control::ControllerParams{}.d_a;
    a_.sampling.near_distance = a_.o.d_a;
    stem_ = fs::path(a_.urdf).stem().string();
  }

  /// The exit code (0, or kExitNotReached); throws naming what failed.
  int run() {
    checkFiles();
    const Staging staging(final_dir_);
    out_dir_ = staging.dir;
    staged_as_ = {staging.dir, final_dir_};
    meshes_ = hasMeshCollision(a_.urdf);
    if (meshes_) fit(a_.urdf);
    choosePairs();
    configureRobot();
    writeControllerConfig();
    const bool reached = checkReach();
    writeBehaviorConfig();
    writeFinal();
    return reached ? reflex::kExitOk : kExitNotReached;
  }

  /// `what` with the staging folder named as DIR (errors name the files as they would be in DIR).
  std::string inFinalTerms(std::string what) const {
    if (!staged_as_.first.empty())
      for (std::size_t at = what.find(staged_as_.first); at != std::string::npos; at = what.find(staged_as_.first, at))
        what.replace(at, staged_as_.first.size(), staged_as_.second);
    return what;
  }

 private:
  std::string finalPath(const std::string& name) const { return (fs::path(final_dir_) / name).string(); }
  std::string stagedPath(const std::string& name) const { return (fs::path(out_dir_) / name).string(); }

  /// The inputs exist and are files; DIR can be made; every file set-up may write, checked before any
  /// work: only a regular file is ever replaced (a directory, a device or a FIFO in its place is an
  /// error), and only with --force.
  void checkFiles() {
    for (const auto& [what, path] : {std::pair<std::string, std::string>{"URDF", a_.urdf}, {"--srdf", a_.srdf}}) {
      if (path.empty()) continue;
      if (!fs::exists(path)) throw reflex::Error(what + " '" + path + "' does not exist");
      if (const std::string why = reflex::common::inputFileProblem(path); !why.empty())
        throw reflex::Error(what + " " + why);
    }
    paths_ = reflex::control::parsePackagePathArgs(a_.package_args);
    if (const std::string why = reflex::common::outputFolderProblem(final_dir_); !why.empty())
      throw reflex::Error("--out: " + why);
    std::error_code ec;
    fs::create_directories(final_dir_, ec);
    if (ec) throw reflex::Error("--out '" + final_dir_ + "': cannot create the folder: " + ec.message());
    std::vector<std::string> outputs = {finalPath("controller.yaml"), finalPath("collision.yaml"),
                                        finalPath("behavior.yaml")};
    if (hasMeshCollision(a_.urdf)) outputs.push_back(finalPath(stem_ + ".fit.yaml"));
    if (a_.close_gaps) outputs.push_back(finalPath(stem_ + ".urdf"));
    for (const std::string& p : outputs) {
      struct stat st {};
      if (::lstat(p.c_str(), &st) != 0) continue;
      if (!S_ISREG(st.st_mode))
        throw reflex::Error("'" + p + "' exists and is " + reflex::common::fileKind(st.st_mode) +
                            ": reflex_setup replaces only regular files; remove it or choose another --out");
      if (!a_.force && p != finalPath(stem_ + ".fit.yaml"))
        throw reflex::Error("'" + p + "' exists; give --force to replace it");
    }
    if (a_.close_gaps && fs::exists(finalPath(stem_ + ".urdf")) && fs::equivalent(finalPath(stem_ + ".urdf"), a_.urdf))
      throw reflex::Error("--close-gaps would overwrite the URDF '" + a_.urdf + "' itself; choose another --out");
  }

  /// 1. The mesh fit of `robot_urdf` into the staging folder (the URDF given, or its gap-closed copy).
  void fit(const std::string& robot_urdf) {
    const std::string fit_path = stagedPath(stem_ + ".fit.yaml");
    if (robot_urdf == a_.urdf && reuseFit(fit_path)) return;
    std::printf("fit: the URDF has mesh collision geometry: fitting capsules and spheres (reflex_fit) into %s\n",
                fit_path.c_str());
    const auto overlay = reflex::control::fitRobot(robot_urdf, paths_, reflex::control::FitOptions{});
    writeFile(fit_path, reflex::control::fitOverlayText(overlay, fit_path));
    auto as_final = overlay;  // as read from DIR: the URDF given, or the gap-closed copy in DIR
    if (robot_urdf != a_.urdf) as_final.urdf = finalPath(stem_ + ".urdf");
    fit_final_text_ = reflex::control::fitOverlayText(as_final, finalPath(stem_ + ".fit.yaml"));
    for (const auto& l : overlay.links)
      std::printf("fit: %s: %zu primitives, %d/%d vertices enclosed, volume ratio %.3f, worst gap %.4f m\n",
                  l.link.c_str(), l.primitives.size(), l.stats.vertices_enclosed, l.stats.vertices,
                  l.stats.volume_ratio, l.stats.worst_gap);
  }

  /// A fit already in DIR for this URDF, with the default options, that the loader takes (every mesh
  /// link there, no input changed since: same hashes) is reused (true); anything else is fitted anew.
  bool reuseFit(const std::string& fit_path) {
    const std::string existing = finalPath(stem_ + ".fit.yaml");
    if (!fs::exists(existing)) return false;
    std::string why_not;
    try {
      const auto old = reflex::control::loadFitOverlay(existing);
      const reflex::control::FitOptions d;
      const auto& f = old.options;
      std::error_code ec;
      if (!fs::equivalent(old.urdf, a_.urdf, ec))
        why_not = "it is the fit of '" + old.urdf + "'";
      else if (f.max_primitives != d.max_primitives || f.split_ratio != d.split_ratio ||
               f.min_split_gain != d.min_split_gain || f.quantum != d.quantum || f.max_pieces != d.max_pieces ||
               f.piece_gap != d.piece_gap || f.max_pieces_large_gap != d.max_pieces_large_gap ||
               f.large_gap != d.large_gap)
        why_not = "it was made with other options";
      else {
        reflex::control::CollisionConfig c;
        c.exclude_adjacent = false;
        c.fit = existing;
        (void)reflex::control::loadModel(a_.urdf, c);  // throws for a stale or incomplete fit
        writeFile(fit_path, reflex::control::fitOverlayText(old, fit_path));
        fit_final_text_ = reflex::control::fitOverlayText(old, existing);
        std::printf("fit: reusing %s (the fit of this URDF with the default options; every mesh unchanged)\n",
                    existing.c_str());
        return true;
      }
    } catch (const std::exception& e) {
      why_not = e.what();
    }
    std::printf("fit: not reusing %s: %s\n", existing.c_str(), why_not.c_str());
    return false;
  }

  /// 2. Which pairs to check: SRDF + sampling (as reflex_inspect --sample-pairs); collision.yaml.
  void choosePairs() {
    reflex::control::PairSamplingOptions& sampling = a_.sampling;
    const std::string fit_path = stagedPath(stem_ + ".fit.yaml");
    reflex::control::CollisionConfig every;
    every.exclude_adjacent = false;
    if (meshes_) every.fit = fit_path;
    reflex::control::CollisionConfig nonadj_config = every;
    nonadj_config.exclude_adjacent = true;
    if (!a_.srdf.empty()) {
      nonadj_config.srdf = a_.srdf;
      nonadj_config.srdf_disabled = reflex::control::loadSrdfDisabledCollisions(a_.srdf);
    }
    const Model all = reflex::control::loadModel(a_.urdf, every);
    const Model nonadj = reflex::control::loadModel(a_.urdf, nonadj_config);
    std::map<std::string, reflex::control::TriangleMesh> link_meshes;
    setSamplingJoints(all, nonadj, link_meshes);
    std::fprintf(stderr, "reflex_setup: sampling %d configurations for the pair list\n", sampling.samples);
    const auto report = reflex::control::samplePairs(all, nonadj, sampling);
    int always = 0, never = 0, undriven = 0, near = 0, standing = 0;
    for (const auto& p : report.pairs) {
      always += p.verdict == reflex::control::PairVerdict::kAlwaysInCollision;
      never += p.verdict == reflex::control::PairVerdict::kNeverClose;
      near += p.verdict == reflex::control::PairVerdict::kAlwaysNear;
      standing += p.verdict == reflex::control::PairVerdict::kTouchingStanding;
      undriven += p.verdict == reflex::control::PairVerdict::kNotDriven;
      warnUnchecked(p);
    }
    std::string collision = "# Written by reflex_setup for " + a_.urdf + " (keys: control/docs/configuration.md).\n" +
                            reflex::control::exclusionYaml(report) + handSegmentsYaml(nonadj);
    collision_final_ = collision;
    if (!a_.srdf.empty()) {
      collision += "srdf: " + relativeTo(a_.srdf, out_dir_) + "   # its <disable_collisions> pairs are excluded too\n";
      collision_final_ +=
          "srdf: " + relativeTo(a_.srdf, final_dir_) + "   # its <disable_collisions> pairs are excluded too\n";
    }
    if (meshes_) {
      collision += "fit: " + fs::path(fit_path).filename().string() + "   # the mesh fit (reflex_fit)\n";
      collision_final_ += "fit: " + fs::path(fit_path).filename().string() + "   # the mesh fit (reflex_fit)\n";
    }
    writeFile(stagedPath("collision.yaml"), collision);
    std::printf(
        "pairs: %d sampled configurations%s: %d pairs always in collision (excluded), %d never closer than "
        "d_a (listed, commented out: still checked), %zu adjacent (not checked), %d moved by no joint Reflex "
        "drives, %d never out of d_a, %d touching standing (these three not checked: listed in %s)\n",
        sampling.samples, a_.srdf.empty() ? "" : " after the SRDF's exclusions", always, never, report.adjacent.size(),
        undriven, near, standing, finalPath("collision.yaml").c_str());
  }

  /// The joints Reflex drives (both arms, the walking joints; a pair no driven joint moves is not
  /// checked), the standing posture, and with meshes the confirmation of "always in collision" on the
  /// original meshes. The structure comes first (it does not depend on the pair list): a robot without
  /// clear arms writes nothing.
  void setSamplingJoints(const Model& all, const Model& nonadj,
                         std::map<std::string, reflex::control::TriangleMesh>& link_meshes) {
    reflex::control::PairSamplingOptions& sampling = a_.sampling;
    const reflex::control::RobotSetup structure = reflex::control::findRobotStructure(nonadj, a_.o);
    hand_links_.clear();
    for (const auto& arm : structure.arms) {
      hand_links_.push_back(arm.hand_link);
      sampling.driven_joints.insert(sampling.driven_joints.end(), arm.joints.begin(), arm.joints.end());
      sampling.arm_joints.insert(sampling.arm_joints.end(), arm.joints.begin(), arm.joints.end());
    }
    sampling.standing = reflex::control::neutralConfiguration(all);
    const reflex::control::ControllerParams defaults;
    sampling.touch_distance = defaults.d_r + defaults.estop_release_margin;
    sampling.exclude_always_near = true;
    if (meshes_) {  // "always in collision" only where the original meshes intersect
      link_meshes = reflex::control::linkCollisionMeshes(a_.urdf, paths_);
      sampling.confirm_collision = [&link_meshes, &nonadj](int sa, int sb, const reflex::control::KinematicsData& kin) {
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

  /// One segment per hand: the hand with the links below it that no joint Reflex drives moves (every
  /// pair inside it is then one the pair list does not check: moved by no driven joint, or adjacent).
  std::string handSegmentsYaml(const Model& nonadj) {
    hand_segments_ = reflex::control::handSegments(nonadj, hand_links_, a_.sampling.driven_joints);
    if (hand_segments_.empty()) return "";
    std::string y =
        "# One segment per hand: the hand with every link below it that no joint Reflex drives moves (its\n"
        "# fingers). Each link keeps its own geometry and its own pairs above; the hand's distance to another\n"
        "# segment is the closest of them, and the avoidance moves the hand as one body.\n"
        "segments:\n";
    for (const auto& [hand, links] : hand_segments_) {
      y += "  " + hand + ": [";
      for (std::size_t i = 0; i < links.size(); ++i) y += (i ? ", " : "") + links[i];
      y += "]\n";
    }
    return y;
  }

  /// A warning for a pair that is not checked although it comes close.
  void warnUnchecked(const reflex::control::SampledPair& p) const {
    if (p.verdict == reflex::control::PairVerdict::kAlwaysNear && p.min_distance <= a_.sampling.touch_distance)
      std::printf(
          "WARNING: pair '%s'-'%s' is never farther apart than %.1f mm (inside d_a at every posture) and comes "
          "%.1f mm close: NOT checked (the avoidance would hold the arm off every target); the joint limits "
          "and the robot's own controller must keep it apart\n",
          p.a.c_str(), p.b.c_str(), 1e3 * std::min(p.max_distance, p.driven_max_distance), 1e3 * p.min_distance);
    if (p.verdict == reflex::control::PairVerdict::kTouchingStanding)
      std::printf(
          "WARNING: pair '%s'-'%s' is %.1f mm apart in the standing posture and no arm joint moves it: NOT "
          "checked (the red zone would latch at start); the robot's own controller must keep it apart\n",
          p.a.c_str(), p.b.c_str(), 1e3 * p.standing_distance);
    if (p.verdict == reflex::control::PairVerdict::kNotDriven && p.min_distance < a_.sampling.near_distance)
      std::printf(
          "WARNING: pair '%s'-'%s' is moved by no joint Reflex drives and comes %.1f mm close (sampled over "
          "the joints that move it): NOT checked; the robot's own controller must keep it apart\n",
          p.a.c_str(), p.b.c_str(), 1e3 * p.min_distance);
  }

  /// The collision configuration at `path` with a segment per link: the structure, rest and reach are
  /// found link by link (the same link pairs are checked as with the hands' segments, so the same
  /// distances count).
  static reflex::control::CollisionConfig perLinkConfig(const std::string& path) {
    reflex::control::CollisionConfig c = reflex::control::loadCollisionConfig(path);
    c.segments.clear();
    return c;
  }

  /// 3. The robot as the controller will load it, and what the setup finds on it (closing the arm
  /// gaps in a copy of the URDF with --close-gaps).
  void configureRobot() {
    const std::string collision_path = stagedPath("collision.yaml");
    robot_urdf_ = a_.urdf;
    model_ = reflex::control::loadModel(a_.urdf, perLinkConfig(collision_path));
    setup_ = reflex::control::findRobotStructure(model_, a_.o);
    reflex::control::findRestPosture(model_, a_.o, setup_);
    reflex::control::findArmGaps(model_, a_.o, setup_);
    for (const auto& g : setup_.gaps) {
      std::printf("%s\n", g.message.c_str());
      std::printf(
          "  paste into <link name=\"%s\"> of the URDF (Reflex reads a cylinder as that capsule), or rerun "
          "with --close-gaps:\n  %s\n",
          g.link.c_str(), g.urdf_snippet.c_str());
    }
    if (!a_.close_gaps || setup_.gaps.empty()) return;
    const std::string closed_urdf = stagedPath(stem_ + ".urdf");
    writeClosedUrdf(a_.urdf, closed_urdf, setup_.gaps);
    closing_gaps_ = setup_.gaps;
    std::printf("gaps: wrote %s with %zu closing capsules; configuring that robot\n",
                finalPath(stem_ + ".urdf").c_str(), setup_.gaps.size());
    robot_urdf_ = closed_urdf;
    if (meshes_) fit(robot_urdf_);
    model_ = reflex::control::loadModel(robot_urdf_, perLinkConfig(collision_path));
    setup_ = reflex::control::findRobotStructure(model_, a_.o);
    reflex::control::findRestPosture(model_, a_.o, setup_);
    if (const int left = reflex::control::findArmGaps(model_, a_.o, setup_); left > 0)
      std::printf("gaps: %d remain after closing\n", left);
  }

  /// 4. controller.yaml, read back and resolved against the robot.
  void writeControllerConfig() {
    std::string& ctl = controller_text_;
    ctl = "# Controller configuration of " + model_.name +
          ", written by reflex_setup (every key: "
          "control/docs/configuration.md).\n# Parameters not given take their defaults (control/README.md, "
          "\"Controller parameters\").\n";
    for (const auto& d : setup_.decisions) ctl += "# " + d + "\n";
    ctl += "arms:\n";
    for (const auto& arm : setup_.arms) {
      ctl += "  " + arm.side + ":\n    joints: [";
      for (std::size_t i = 0; i < arm.joints.size(); ++i) ctl += (i ? ", " : "") + arm.joints[i];
      ctl += "]\n    hand_link: " + arm.hand_link + "\n    hand_point: " + vec3(arm.hand_point_L) + "   # m, in " +
             arm.hand_link + "\n    rest: [";
      for (std::size_t i = 0; i < arm.rest.size(); ++i) ctl += (i ? ", " : "") + num(arm.rest[i]);
      ctl += "]   # rad\n";
    }
    if (!setup_.camera_link.empty())
      ctl += "camera_link: " + setup_.camera_link +
             "   # the head camera (reflex_sim's occlusion gaze line starts here)\n";
    writeFile(stagedPath("controller.yaml"), ctl);
    const auto cconf = reflex::control::loadControllerConfig(stagedPath("controller.yaml"));
    cm_ = std::make_unique<reflex::control::ControllerModel>(reflex::control::makeControllerModel(model_, cconf));
    // The robot as the controller loads it, with the hands' segments: it must load and take this
    // configuration (no arm joint inside a segment).
    const Model as_loaded =
        reflex::control::loadModel(robot_urdf_, reflex::control::loadCollisionConfig(stagedPath("collision.yaml")));
    (void)reflex::control::makeControllerModel(as_loaded, cconf);
    for (const auto& d : setup_.decisions) std::printf("%s\n", d.c_str());
    for (const auto& [hand, links] : hand_segments_)
      std::printf(
          "segments: '%s' is one segment with the %zu link%s below it that no joint Reflex drives moves "
          "(%s%s): %d robot segments in all\n",
          hand.c_str(), links.size(), links.size() == 1 ? "" : "s", links.front().c_str(),
          links.size() > 1 ? ", ..." : "", as_loaded.num_robot_segments);
  }

  /// 5. A behavior that works with this robot: both hands to points 8 cm in front of (and 5 cm above)
  /// their rest positions, checked here by a closed-loop run of the controller (smaller steps if not
  /// reached). Forward and up first; where the arms rest inside the avoidance zone (a crowded
  /// shoulder) a move that opens it (up, out, down) may be what the robot can do: the first one
  /// reached is written. Whether one was reached.
  bool checkReach() {
    const reflex::control::ControllerModel& cm = *cm_;
    reflex::control::KinematicsData kin(model_);
    Eigen::VectorXd q = reflex::control::neutralConfiguration(model_);
    for (const auto& arm : cm.arms)
      for (int i = 0; i < arm.n; ++i) q[arm.q[i]] = arm.rest[i];
    reflex::control::computeForwardKinematics(model_, kin, q);
    double offset = 0.0;
    std::string towards;
    const Eigen::Vector3d up = Eigen::Vector3d::UnitZ(), left = up.cross(setup_.forward);
    const std::vector<std::pair<std::string, Eigen::Vector3d>> directions = {
        {"forward, 0.6 x up", setup_.forward + 0.6 * up}, {"up", up}, {"out", left}, {"down", -up}};
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
        reach_ = reflex::control::checkReach(model_, cm, t, 4.0, 0.01);
        offset = off;
        towards = name;
        reached = reach_.reached_at >= 0 && reach_.estops == 0 && reach_.min_distance > cm.params.d_r;
        if (reached) break;
      }
      if (reached) break;
    }
    std::printf(
        "behavior: both hands to %s / %s (rest + %.2f m %s): %s; closest pair during the "
        "run %.3f m (d_r %.3f m), %llu e-stops\n",
        vec3(reach_.target_B[0]).c_str(), vec3(reach_.target_B[1]).c_str(), offset, towards.c_str(),
        reached ? ("reached within 10 mm after " + num(reach_.reached_at) + " s of a closed-loop run").c_str()
                : ("NOT reached in 4 s (errors " + num(reach_.error[0]) + " / " + num(reach_.error[1]) + " m)").c_str(),
        reach_.min_distance, cm.params.d_r, static_cast<unsigned long long>(reach_.estops));
    return reached;
  }

  /// behavior.yaml: the targets checkReach found.
  void writeBehaviorConfig() {
    const std::string behavior_path = stagedPath("behavior.yaml");
    std::string& beh = behavior_text_;
    beh = "# Behavior configuration for " + model_.name +
          ", written by reflex_setup: both hands reach to a\n"
          "# point near their rest positions and stay (checked by a closed-loop run at set-up).\n"
          "#   reflex_behavior --config " +
          finalPath("behavior.yaml") +
          "\n# Keys: modules/README.md, control/docs/configuration.md.\n"
          "process: behavior\n\nrobot:\n";
    beh += "  urdf: " + relativeTo(robotUrdfFinal(), final_dir_) + "   # relative to this file\n";
    beh += "  collision: collision.yaml\n";
    beh += "  left_shoulder: " + setup_.arms[0].shoulder_link + "\n  right_shoulder: " + setup_.arms[1].shoulder_link +
           "\n";
    beh += "  left_hand: " + setup_.arms[0].hand_link + "\n  right_hand: " + setup_.arms[1].hand_link + "\n";
    beh += "  head: " + setup_.head_link + "\n  head_camera: " + setup_.camera_link + "\n";
    beh += "  hand_point: " + vec3(setup_.arms[0].hand_point_L) +
           "   # m, in the hand link (the left hand's; "
           "the controller has one per arm)\n\n";
    beh += "modules:\n  - name: reach\n    type: scripted\n    config:\n      timeline:\n        - {t: 0.0, left: " +
           vec3(reach_.target_B[0]) + ", right: " + vec3(reach_.target_B[1]) + "}\n";
    writeFile(behavior_path, beh);
  }

  std::string robotUrdfFinal() const { return robot_urdf_ == a_.urdf ? a_.urdf : finalPath(stem_ + ".urdf"); }

  /// Into DIR: the texts as they read from there (the fit's and the SRDF's relative paths).
  void writeFinal() {
    if (meshes_) writeFile(finalPath(stem_ + ".fit.yaml"), fit_final_text_);
    writeFile(finalPath("collision.yaml"), collision_final_);
    writeFile(finalPath("controller.yaml"), controller_text_);
    if (robot_urdf_ != a_.urdf) writeClosedUrdf(a_.urdf, robotUrdfFinal(), closing_gaps_);
    writeFile(finalPath("behavior.yaml"), behavior_text_);
    std::printf("wrote %s, %s, %s%s%s\n", finalPath("controller.yaml").c_str(), finalPath("collision.yaml").c_str(),
                finalPath("behavior.yaml").c_str(), meshes_ ? ", " : "",
                meshes_ ? finalPath(stem_ + ".fit.yaml").c_str() : "");
    std::printf("next: reflex_sim SCENARIO --urdf %s --collision %s --controller %s --out RUN\n",
                robotUrdfFinal().c_str(), finalPath("collision.yaml").c_str(), finalPath("controller.yaml").c_str());
    std::printf("next: reflex_controller --urdf %s --collision %s --controller %s; reflex_behavior --config %s\n",
                robotUrdfFinal().c_str(), finalPath("collision.yaml").c_str(), finalPath("controller.yaml").c_str(),
                finalPath("behavior.yaml").c_str());
  }

  Args a_;
  std::string final_dir_, out_dir_, stem_;
  std::pair<std::string, std::string> staged_as_;  // (staging folder, DIR)
  reflex::control::PackagePaths paths_;
  bool meshes_ = false;
  std::string fit_final_text_, collision_final_, controller_text_, behavior_text_;
  std::string robot_urdf_;
  Model model_;
  reflex::control::RobotSetup setup_;
  std::vector<reflex::control::ArmGap> closing_gaps_;
  std::unique_ptr<reflex::control::ControllerModel> cm_;
  std::vector<std::string> hand_links_;  ///< the arms' hand links (structure, before the pair list)
  std::vector<std::pair<std::string, std::vector<std::string>>> hand_segments_;  ///< written in collision.yaml
  reflex::control::ReachCheck reach_;
};

int run(int argc, char** argv) {
  CLI::App app{
      "reflex_setup: find a humanoid's arms, hands, head, rest posture and collision pairs from its "
      "URDF and write DIR/controller.yaml, DIR/collision.yaml and DIR/behavior.yaml (and the mesh fit), "
      "printing every choice and why. See control/README.md, \"Setting up a new robot\". Exit: 0 written, "
      "2 refused (named; nothing written), 3 written but the closed-loop check did not reach the rest "
      "posture."};
  Args args;
  addOptions(app, args);
  if (const int code = reflex::parseCommandLine(app, argc, argv); code >= 0) return code;
  std::unique_ptr<Setup> setup;
  try {
    setup = std::make_unique<Setup>(std::move(args));
    return setup->run();
  } catch (const std::exception& e) {
    // Errors name the files as they would be in DIR, never the staging folder (removed by now).
    const std::string what = setup ? setup->inFinalTerms(e.what()) : std::string(e.what());
    const bool refused = dynamic_cast<const reflex::Error*>(&e) != nullptr;
    std::fprintf(stderr, "reflex_setup: %s: %s\n", refused ? "error" : "internal error", what.c_str());
    return refused ? reflex::kExitRefused : reflex::kExitFailed;
  }
}

}  // namespace

int main(int argc, char** argv) {
  const int status = run(argc, argv);
  if (const std::string why = reflex::common::flushStandardOutput(); !why.empty()) {
    std::fprintf(stderr, "reflex_setup: error: %s\n", why.c_str());
    return 1;
  }
  return status;
}
