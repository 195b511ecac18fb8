// The fit overlay: fitting a whole robot, writing `<stem>.fit.yaml`, reading it back.
#include "fit_inputs.hpp"
#include "reflex/common/files.hpp"
#include "reflex/common/yaml_reader.hpp"
#include "reflex/control/mesh_fit.hpp"
#include "reflex/control/urdf_loader.hpp"
#include "urdf_audit.hpp"

#include <urdf_model/model.h>
#include <urdf_parser/urdf_parser.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <limits>
#include <set>
#include <sstream>

namespace reflex::control {
namespace {

namespace fs = std::filesystem;

std::string num(double v, const char* format = "%.10g") {
  char buf[48];
  std::snprintf(buf, sizeof buf, format, v == 0.0 ? 0.0 : v);  // never "-0"
  return buf;
}

/// A YAML double-quoted scalar (names and paths may hold ':', '#', spaces).
std::string quoted(const std::string& text) {
  std::string out = "\"";
  for (const char ch : text) {
    if (static_cast<unsigned char>(ch) < 0x20) {  // control characters as \xHH
      char buf[8];
      std::snprintf(buf, sizeof buf, "\\x%02x", static_cast<unsigned>(static_cast<unsigned char>(ch)));
      out += buf;
      continue;
    }
    if (ch == '"' || ch == '\\') out += '\\';
    out += ch;
  }
  return out + "\"";
}

std::string vec(const Eigen::Vector3d& v) { return "[" + num(v.x()) + ", " + num(v.y()) + ", " + num(v.z()) + "]"; }

/// `path` relative to `dir` (both made absolute first), for paths written into the overlay.
std::string relativeTo(const std::string& path, const std::string& dir) {
  std::error_code ec;
  const fs::path abs = fs::weakly_canonical(fs::absolute(path), ec);
  const fs::path base = fs::weakly_canonical(fs::absolute(dir), ec);
  const fs::path rel = abs.lexically_relative(base);
  return rel.empty() ? abs.string() : rel.string();
}

std::string joinPath(const std::string& dir, const std::string& path) {
  if (!path.empty() && path[0] == '/') return path;
  return (fs::path(dir) / path).lexically_normal().string();
}

void append(TriangleMesh& to, const TriangleMesh& from, const Eigen::Isometry3d& X) {
  const int base = static_cast<int>(to.vertices.size());
  for (const auto& v : from.vertices) to.vertices.push_back(X * v);
  for (const auto& t : from.triangles) to.triangles.push_back({base + t[0], base + t[1], base + t[2]});
}

}  // namespace

std::string defaultFitOverlayPath(const std::string& urdf_path) { return robotFileBeside(urdf_path, ".fit.yaml"); }

namespace {

struct Job {
  std::string link;
  std::vector<detail::FitElement> elements;
  std::vector<std::string> resolved;
  std::string hash;
};

/// The URDF's links with mesh or box collision elements, their input hashes, and their meshes (link
/// frame; with_boxes: the boxes' meshes too), every mesh read once. Throws ModelError naming every
/// unresolved or unreadable mesh in one message.
struct RobotMeshes {
  FitOverlay overlay;  // urdf, urdf_dir, packages
  std::vector<Job> jobs;
  std::vector<TriangleMesh> meshes, with_boxes;
};

RobotMeshes readRobotMeshes(const std::string& urdf_path, const PackagePaths& paths) {
  if (const std::string why = common::inputFileProblem(urdf_path); !why.empty()) throw ModelError("URDF file " + why);
  std::ifstream in(urdf_path);
  if (!in) throw ModelError(urdf_path + ": cannot open URDF file");
  std::stringstream ss;
  ss << in.rdbuf();
  const detail::UrdfAudit audit = detail::auditUrdf(ss.str());
  if (!audit.xml_error.empty()) throw ModelError(urdf_path + ": malformed URDF: " + audit.xml_error);
  urdf::ModelInterfaceSharedPtr model;
  try {
    model = urdf::parseURDF(audit.capsules > 0 ? audit.urdfdom_xml : ss.str());
  } catch (const std::exception& e) {
    throw ModelError(urdf_path + ": urdfdom: " + e.what());
  }
  // The loader's accounting (every collision element of the file read, or the link named with why):
  // a link urdfdom emptied would otherwise be left out of the fit without a word.
  std::vector<std::string> lost = audit.problems;
  for (auto& p : detail::collisionAccounting(audit, model.get())) lost.push_back(std::move(p));
  if (!lost.empty()) {
    if (model)
      for (auto& e : model->links_)
        if (e.second) e.second->child_links.clear();
    std::string msg = urdf_path + ": cannot fit: collision geometry would be left out or is out of range (" +
                      std::to_string(lost.size()) + " problem" + (lost.size() == 1 ? "" : "s") + "):";
    for (const auto& p : lost) msg += "\n  " + p;
    throw ModelError(msg);
  }
  if (!model) throw ModelError(urdf_path + ": malformed URDF (urdfdom could not parse it; reflex_inspect says why)");
  struct Release {  // urdfdom's parent/child shared_ptr cycle
    urdf::ModelInterfaceSharedPtr& m;
    ~Release() {
      for (auto& e : m->links_)
        if (e.second) e.second->child_links.clear();
    }
  } release{model};

  RobotMeshes out;
  FitOverlay& overlay = out.overlay;
  overlay.urdf = urdf_path;
  overlay.urdf_dir = detail::folderOf(urdf_path);
  std::vector<std::string> problems;
  std::vector<Job>& jobs = out.jobs;
  for (const auto& [name, link] : model->links_) {  // std::map: sorted by name
    Job job{name, detail::fitElementsOf(*link), {}, {}};
    if (job.elements.empty()) continue;
    job.hash = detail::fitInputsHash(name, job.elements, overlay.urdf_dir, paths, &problems, &job.resolved);
    jobs.push_back(std::move(job));
  }
  // The packages used, as found (recorded so the loader finds the same files).
  for (const auto& job : jobs)
    for (std::size_t i = 0, m = 0; i < job.elements.size(); ++i) {
      if (job.elements[i].box) continue;
      const std::string& f = job.elements[i].filename;
      const std::string& r = job.resolved[m++];
      if (r.empty() || f.compare(0, 10, "package://") != 0) continue;
      const std::string rest = f.substr(10);
      const std::string pkg = rest.substr(0, rest.find('/'));
      const std::string rel = rest.substr(pkg.size() + 1);
      overlay.packages[pkg] = r.substr(0, r.size() - rel.size() - 1);
    }
  // Read every mesh once; unreadable ones are problems too, all named in one message. Boxes are
  // fitted on their own (fitBox) and join the meshes only for the link's numbers.
  std::vector<TriangleMesh>& meshes = out.meshes;
  std::vector<TriangleMesh>& with_boxes = out.with_boxes;
  meshes.resize(jobs.size());
  with_boxes.resize(jobs.size());
  for (std::size_t j = 0; j < jobs.size(); ++j) {
    const Job& job = jobs[j];
    for (std::size_t i = 0, m = 0; i < job.elements.size(); ++i) {
      const auto& e = job.elements[i];
      if (e.box) {
        if (!(e.size.minCoeff() > 0.0) || !e.size.allFinite())
          problems.push_back("link '" + job.link + "': box size must be positive");
        else
          append(with_boxes[j], boxMesh(e.size, e.X_L_C), Eigen::Isometry3d::Identity());
        continue;
      }
      const std::string& path = job.resolved[m++];
      if (path.empty()) continue;  // already a problem
      try {
        const TriangleMesh mesh = loadMeshFile(path, e.scale);
        append(meshes[j], mesh, e.X_L_C);
        append(with_boxes[j], mesh, e.X_L_C);
      } catch (const ModelError& err) {
        problems.push_back("link '" + job.link + "': mesh '" + e.filename + "': " + err.what());
      }
    }
  }
  if (!problems.empty()) {
    std::string msg = urdf_path + ": cannot fit: " + std::to_string(problems.size()) + " mesh" +
                      (problems.size() == 1 ? "" : "es") + " not resolved or not readable:";
    for (const auto& p : problems) msg += "\n  " + p;
    throw ModelError(msg);
  }
  return out;
}

}  // namespace

std::map<std::string, TriangleMesh> linkCollisionMeshes(const std::string& urdf_path, const PackagePaths& paths) {
  RobotMeshes r = readRobotMeshes(urdf_path, paths);
  std::map<std::string, TriangleMesh> out;
  for (std::size_t j = 0; j < r.jobs.size(); ++j) out[r.jobs[j].link] = std::move(r.with_boxes[j]);
  return out;
}

FitOverlay fitRobot(const std::string& urdf_path, const PackagePaths& paths, const FitOptions& options,
                    const std::function<void(const std::string&)>& progress) {
  RobotMeshes r = readRobotMeshes(urdf_path, paths);
  FitOverlay overlay = std::move(r.overlay);
  overlay.options = options;
  const std::vector<Job>& jobs = r.jobs;
  const std::vector<TriangleMesh>& meshes = r.meshes;
  const std::vector<TriangleMesh>& with_boxes = r.with_boxes;
  for (std::size_t j = 0; j < jobs.size(); ++j) {
    LinkFit fit;
    fit.link = jobs[j].link;
    fit.inputs = jobs[j].hash;
    fit.elements = static_cast<int>(jobs[j].elements.size());
    // The tight model: the meshes together cut into convex pieces (fitConvexPieces), each box one
    // exact piece; every piece with the capsule that encloses it.
    double gap = 0.0;
    if (!meshes[j].vertices.empty()) fit.pieces = fitConvexPieces(meshes[j], options, &gap);
    for (const auto& e : jobs[j].elements)
      if (e.box) fit.pieces.push_back(boxPiece(e.size, e.X_L_C, options));
    for (const PieceFit& piece : fit.pieces) fit.primitives.push_back(piece.capsule);
    fit.stats = measurePieces(with_boxes[j], fit.pieces, gap);
    if (progress) {
      std::ostringstream os;
      std::size_t hull_vertices = 0;
      for (const PieceFit& piece : fit.pieces) hull_vertices += piece.vertices.size();
      os << "fitted " << fit.link << ": " << fit.pieces.size() << " convex piece(s) (" << hull_vertices
         << " hull vertices), " << fit.stats.vertices_enclosed << "/" << fit.stats.vertices
         << " vertices enclosed, volume ratio " << num(fit.stats.volume_ratio, "%.3f") << ", worst gap "
         << num(fit.stats.worst_gap, "%.4f") << " m (" << j + 1 << "/" << jobs.size() << ")";
      progress(os.str());
    }
    overlay.links.push_back(std::move(fit));
  }
  return overlay;
}

std::string fitOverlayText(const FitOverlay& overlay, const std::string& overlay_path) {
  const std::string dir = detail::folderOf(overlay_path);
  std::ostringstream os;
  os << "# Collision fit of " << fs::path(overlay.urdf).filename().string()
     << ", written by reflex_fit: do not edit, rerun reflex_fit.\n"
     << "# The URDF is never edited: the loader reads the pieces below instead of the links' mesh and\n"
     << "# box elements. Link frame (m). inputs: hash of the mesh bytes, filenames,\n"
     << "# scales, origins and box sizes; a link whose inputs changed is refused as stale.\n"
     << "# fitted_volume: sum of the pieces' volumes; volume_ratio: that / the link's convex-hull volume;\n"
     << "# worst_gap: largest distance from the pieces' outer surface (sampled) to the mesh.\n"
     << "# pieces: the tight model: each the convex hull of a cluster of the link's mesh triangles (or a\n"
     << "# box), exact vertices; the capsule encloses it (the broad phase). Distances are computed on\n"
     << "# the pieces: never above the distance between the meshes.\n"
     << "format: " << (overlay.links.empty() || !overlay.links.front().pieces.empty() ? 2 : 1) << "\n"
     << "urdf: " << quoted(relativeTo(overlay.urdf, dir)) << "\n";
  if (!overlay.packages.empty()) {
    os << "packages:\n";
    for (const auto& [name, path] : overlay.packages)
      os << "  " << quoted(name) << ": " << quoted(relativeTo(path, dir)) << "\n";
  }
  const FitOptions& o = overlay.options;
  os << "options: {max_primitives: " << o.max_primitives << ", split_ratio: " << num(o.split_ratio)
     << ", min_split_gain: " << num(o.min_split_gain) << ", quantum: " << num(o.quantum)
     << ", max_pieces: " << o.max_pieces << ", piece_gap: " << num(o.piece_gap)
     << ", max_pieces_large_gap: " << o.max_pieces_large_gap << ", large_gap: " << num(o.large_gap) << "}\n"
     << "links:\n";
  for (const auto& l : overlay.links) {
    const FitStats& s = l.stats;
    os << "  " << quoted(l.link) << ":\n"
       << "    inputs: \"" << l.inputs << "\"\n"
       << "    elements: " << l.elements << "\n"
       << "    vertices: " << s.vertices << "\n"
       << "    vertices_enclosed: " << s.vertices_enclosed << "\n"
       << "    triangles: " << s.triangles << "\n"
       << "    hull_volume: " << num(s.hull_volume, "%.6g") << "\n"
       << "    fitted_volume: " << num(s.fitted_volume, "%.6g") << "\n"
       << "    volume_ratio: " << num(s.volume_ratio, "%.4f") << "\n"
       << "    worst_gap: " << num(s.worst_gap, "%.6f") << "\n";
    auto capsule = [&](const Primitive& p) {
      if (p.sphere) return "{sphere: " + vec(p.a_L) + ", radius: " + num(p.radius) + "}";
      return "{a: " + vec(p.a_L) + ", b: " + vec(p.b_L) + ", radius: " + num(p.radius) + "}";
    };
    if (l.pieces.empty()) {
      os << "    primitives:\n";
      for (const auto& p : l.primitives) os << "      - " << capsule(p) << "\n";
      continue;
    }
    os << "    pieces:\n";
    for (const PieceFit& piece : l.pieces) {
      os << "      - capsule: " << capsule(piece.capsule) << "\n        vertices: [";
      for (std::size_t v = 0; v < piece.vertices.size(); ++v) {
        const Eigen::Vector3d& x = piece.vertices[v];
        os << (v ? ", " : "") << "[" << num(x.x(), "%.17g") << ", " << num(x.y(), "%.17g") << ", "
           << num(x.z(), "%.17g") << "]";
      }
      os << "]\n        triangles: [";
      for (std::size_t t = 0; t < piece.triangles.size(); ++t) {
        const auto& tri = piece.triangles[t];
        os << (t ? ", " : "") << "[" << tri[0] << ", " << tri[1] << ", " << tri[2] << "]";
      }
      os << "]\n";
    }
  }
  return os.str();
}

FitOverlay loadFitOverlay(const std::string& path) {
  constexpr double kAnyOption = std::numeric_limits<double>::max();
  // Every error names FILE:LINE:COL: KEY.PATH and ends with "(rerun reflex_fit)": the file is written by
  // reflex_fit, so a bad one is stale or hand-edited.
  const common::ConfigNode::Raise raise = [](const std::string& m) { throw ModelError(m + " (rerun reflex_fit)"); };
  const common::ConfigNode root = common::ConfigNode::loadFile(path, "fit overlay", raise);
  const std::string format = root.string("format", "");
  if (format != "1" && format != "2") root.fail("format", "not a reflex_fit overlay of format 1 or 2", "1 or 2");
  root.rejectUnknown({"format", "urdf", "packages", "options", "links"});
  const std::string dir = detail::folderOf(path);
  FitOverlay o;
  o.source = path;
  o.urdf = joinPath(dir, root.requiredString("urdf", "the URDF's path"));
  o.urdf_dir = detail::folderOf(o.urdf);
  for (const auto& [name, value] : root.child("packages").entries()) o.packages[name] = joinPath(dir, value.asString());
  // The options the fit was made with (reflex_setup reuses a fit only if they are today's defaults);
  // a key an older reflex_fit did not write is taken as 0, never as today's default.
  const common::ConfigNode opts = root.child("options");
  opts.rejectUnknown({"max_primitives", "split_ratio", "min_split_gain", "quantum", "max_pieces", "piece_gap",
                      "max_pieces_large_gap", "large_gap"});
  o.options.max_primitives = opts.integer("max_primitives", 0, 0, std::numeric_limits<int>::max());
  o.options.split_ratio = opts.number("split_ratio", 0.0, 0.0, kAnyOption);
  o.options.min_split_gain = opts.number("min_split_gain", 0.0, 0.0, kAnyOption);
  o.options.quantum = opts.number("quantum", 0.0, 0.0, kAnyOption, "m");
  o.options.max_pieces = opts.integer("max_pieces", 0, 0, std::numeric_limits<int>::max());
  o.options.piece_gap = opts.number("piece_gap", 0.0, 0.0, kAnyOption, "m");
  o.options.max_pieces_large_gap = opts.integer("max_pieces_large_gap", 0, 0, std::numeric_limits<int>::max());
  o.options.large_gap = opts.number("large_gap", 0.0, 0.0, kAnyOption, "m");
  const common::ConfigNode links = root.at("links", "a map of links");
  links.requireMap("a map of links");
  constexpr double kAny = std::numeric_limits<double>::max();
  for (const auto& [name, n] : links.entries()) {
    LinkFit l;
    l.link = name;
    n.requireMap("a map with inputs and primitives");
    n.rejectUnknown({"inputs", "elements", "vertices", "vertices_enclosed", "triangles", "hull_volume", "fitted_volume",
                     "volume_ratio", "worst_gap", format == "1" ? "primitives" : "pieces"});
    l.inputs = n.requiredString("inputs", "the hash of the link's fit inputs");
    l.elements = n.integer("elements", 0, 0, std::numeric_limits<int>::max());
    l.stats.vertices = n.integer("vertices", 0, 0, std::numeric_limits<int>::max());
    l.stats.vertices_enclosed = n.integer("vertices_enclosed", 0, 0, std::numeric_limits<int>::max());
    l.stats.triangles = n.integer("triangles", 0, 0, std::numeric_limits<int>::max());
    l.stats.hull_volume = n.number("hull_volume", 0.0, -kAny, kAny);
    l.stats.fitted_volume = n.number("fitted_volume", 0.0, -kAny, kAny);
    l.stats.volume_ratio = n.number("volume_ratio", 0.0, -kAny, kAny);
    l.stats.worst_gap = n.number("worst_gap", 0.0, -kAny, kAny);
    auto readCapsule = [&](const common::ConfigNode& pn) {
      Primitive p;
      pn.requireMap("{sphere: [x, y, z], radius: r} or {a: [x, y, z], b: [x, y, z], radius: r}");
      pn.rejectUnknown({"sphere", "a", "b", "radius"});
      p.radius = pn.requiredNumber("radius", -kAny, kAny, "m");
      if (!(p.radius > 0.0)) pn.fail("radius", "not positive", "a radius > 0 m");
      auto point = [&](const char* key, const char* what) {
        const std::vector<double> v = pn.at(key, what).asNumbers(3);
        return Eigen::Vector3d(v[0], v[1], v[2]);
      };
      if (pn.has("sphere")) {
        p.a_L = p.b_L = point("sphere", "[x, y, z] (the sphere's centre)");
        p.sphere = true;
      } else {
        p.a_L = point("a", "[x, y, z] (a capsule's first end; a sphere is written 'sphere')");
        p.b_L = point("b", "[x, y, z] (a capsule's second end)");
        p.sphere = false;
        if (!((p.b_L - p.a_L).norm() > 0.0)) pn.fail("b", "equals a", "a != b (write a sphere)");
      }
      return p;
    };
    if (format == "1") {
      const std::vector<common::ConfigNode> primitives =
          n.at("primitives", "a non-empty list of primitives").elements();
      if (primitives.empty()) n.fail("primitives", "empty", "a non-empty list of primitives");
      for (const common::ConfigNode& pn : primitives) l.primitives.push_back(readCapsule(pn));
    } else {
      const std::vector<common::ConfigNode> pieces = n.at("pieces", "a non-empty list of convex pieces").elements();
      if (pieces.empty()) n.fail("pieces", "empty", "a non-empty list of convex pieces");
      for (const common::ConfigNode& pn : pieces) {
        pn.requireMap("{capsule: {...}, vertices: [[x, y, z], ...], triangles: [[i, j, k], ...]}");
        pn.rejectUnknown({"capsule", "vertices", "triangles"});
        PieceFit piece;
        piece.capsule = readCapsule(pn.at("capsule", "the capsule enclosing the piece"));
        const std::vector<common::ConfigNode> vs = pn.at("vertices", "a non-empty list of [x, y, z]").elements();
        if (vs.empty()) pn.fail("vertices", "empty", "a non-empty list of [x, y, z]");
        for (const common::ConfigNode& v : vs) {
          const std::vector<double> x = v.asNumbers(3, "[x, y, z]");
          piece.vertices.emplace_back(x[0], x[1], x[2]);
          // The capsule must enclose the piece (the broad phase's bound): checked, not trusted.
          if (!(signedDistanceToPrimitive(piece.capsule, piece.vertices.back()) <= 1e-9))
            pn.fail("capsule", "does not enclose the vertex [" + num(x[0]) + ", " + num(x[1]) + ", " + num(x[2]) + "]",
                    "a capsule enclosing every vertex");
        }
        const int nv = static_cast<int>(piece.vertices.size());
        for (const common::ConfigNode& t : pn.at("triangles", "a list of [i, j, k]").elements()) {
          const std::vector<double> x = t.asNumbers(3, "[i, j, k]");
          std::array<int, 3> tri{};
          for (int k = 0; k < 3; ++k) {
            if (!(x[k] >= 0 && x[k] < nv) || x[k] != std::floor(x[k]))
              pn.fail("triangles", "index " + num(x[k]) + " is not a vertex index",
                      "integers in [0, " + std::to_string(nv) + ")");
            tri[k] = static_cast<int>(x[k]);
          }
          piece.triangles.push_back(tri);
        }
        l.primitives.push_back(piece.capsule);
        l.pieces.push_back(std::move(piece));
      }
    }
    o.links.push_back(std::move(l));
  }
  return o;
}

}  // namespace reflex::control
