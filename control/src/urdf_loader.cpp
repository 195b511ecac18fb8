#include "reflex/control/urdf_loader.hpp"

#include "reflex/common/files.hpp"
#include "reflex/common/yaml_reader.hpp"
#include "fit_inputs.hpp"
#include "reflex/control/mesh_fit.hpp"
#include "urdf_audit.hpp"

#include <urdf_model/model.h>
#include <urdf_parser/urdf_parser.h>

#include <tinyxml2.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <limits>
#include <map>
#include <set>
#include <sstream>
#include <sys/stat.h>

namespace reflex::control {
namespace {

[[noreturn]] void fail(const std::string& origin, const std::string& what) { throw ModelError(origin + ": " + what); }

/// One ModelError for all problems found, one per line, each naming its link or joint.
[[noreturn]] void failWithProblems(const std::string& origin, const std::string& what,
                                   const std::vector<std::string>& problems) {
  std::string msg = what + " (" + std::to_string(problems.size()) + " problem" + (problems.size() == 1 ? "" : "s") +
                    "; the model is refused rather than loaded without them):";
  for (const auto& p : problems) msg += "\n  " + p;
  fail(origin, msg);
}

Eigen::Isometry3d toIsometry(const urdf::Pose& pose) {
  Eigen::Isometry3d X = Eigen::Isometry3d::Identity();
  const Eigen::Quaterniond quat(pose.rotation.w, pose.rotation.x, pose.rotation.y, pose.rotation.z);
  X.linear() = quat.normalized().toRotationMatrix();
  X.translation() = Eigen::Vector3d(pose.position.x, pose.position.y, pose.position.z);
  return X;
}

std::string fmt(double v) {
  std::ostringstream os;
  os << v;
  return os.str();
}

/// Appends the primitives of one URDF collision element (in the link frame).
void addCollision(const std::string& origin, const std::string& link_name, const urdf::Collision& collision,
                  std::vector<Primitive>& out, std::vector<std::string>* warnings) {
  if (!collision.geometry) fail(origin, "link '" + link_name + "' has a collision element without geometry");
  const Eigen::Isometry3d X_L_C = toIsometry(collision.origin);
  const std::string where = "link '" + link_name + "' collision '" + collision.name + "'";
  Primitive prim;
  switch (collision.geometry->type) {
    case urdf::Geometry::SPHERE: {
      const auto& sphere = static_cast<const urdf::Sphere&>(*collision.geometry);
      if (!(sphere.radius > 0.0) || !std::isfinite(sphere.radius))
        fail(origin, where + ": sphere radius " + fmt(sphere.radius) + " must be positive");
      prim.a_L = prim.b_L = X_L_C.translation();
      prim.radius = sphere.radius;
      prim.sphere = true;
      break;
    }
    case urdf::Geometry::CYLINDER: {
      const auto& cyl = static_cast<const urdf::Cylinder&>(*collision.geometry);
      if (!(cyl.radius > 0.0) || !std::isfinite(cyl.radius))
        fail(origin, where + ": cylinder radius " + fmt(cyl.radius) + " must be positive");
      if (!(cyl.length > 0.0) || !std::isfinite(cyl.length))
        fail(origin, where + ": cylinder (capsule) length " + fmt(cyl.length) +
                         " must be positive; use a sphere for a zero-length capsule");
      const Eigen::Vector3d half = X_L_C.linear() * Eigen::Vector3d(0, 0, 0.5 * cyl.length);
      prim.a_L = X_L_C.translation() - half;
      prim.b_L = X_L_C.translation() + half;
      prim.radius = cyl.radius;
      prim.sphere = false;
      break;
    }
    case urdf::Geometry::BOX: {
      const auto& box = static_cast<const urdf::Box&>(*collision.geometry);
      const Eigen::Vector3d dim(box.dim.x, box.dim.y, box.dim.z);
      if (!(dim.minCoeff() > 0.0) || !dim.allFinite())
        fail(origin,
             where + ": box size " + fmt(dim.x()) + " " + fmt(dim.y()) + " " + fmt(dim.z()) + " must be positive");
      // The box fitted on its own (mesh_fit.hpp, fitBox): a grid of capsules that encloses it,
      // the same primitives reflex_fit writes for it, so no overlay is needed for a box.
      const FitOptions options;
      const std::vector<Primitive> fitted = fitBox(dim, X_L_C, options);
      if (warnings) {
        const FitStats st = measureFit(boxMesh(dim, X_L_C), fitted, options, dim.prod());
        char numbers[200];
        std::snprintf(
            numbers, sizeof numbers,
            " fitted with %zu primitive%s (%d/%d corners enclosed, fitted volume / box volume %.2f, worst gap %.4f m)",
            fitted.size(), fitted.size() == 1 ? "" : "s", st.vertices_enclosed, st.vertices, st.volume_ratio,
            st.worst_gap);
        warnings->push_back(origin + ": " + where + ": box " + fmt(dim.x()) + " x " + fmt(dim.y()) + " x " +
                            fmt(dim.z()) + " m" + numbers);
      }
      out.insert(out.end(), fitted.begin(), fitted.end());
      return;
    }
    case urdf::Geometry::MESH:
    default: fail(origin, where + ": mesh collision geometry needs a fit; run: reflex_fit " + origin);
  }
  out.push_back(prim);
}

/// The overlay's fit for each link that has one, checked: every link with a mesh element has a fit,
/// every fit's inputs hash matches the link's elements now, every fitted link exists and has mesh or
/// box elements. Otherwise one ModelError names every such link and the command to run.
std::map<std::string, const LinkFit*> fittedLinks(const std::string& origin,
                                                  const std::vector<urdf::LinkConstSharedPtr>& links,
                                                  const FitOverlay& overlay) {
  std::map<std::string, const LinkFit*> by_name, out;
  for (const auto& l : overlay.links) by_name[l.link] = &l;
  std::vector<std::string> missing, stale;
  std::set<std::string> seen;
  PackagePaths paths;
  paths.packages = overlay.packages;
  for (const auto& ulink : links) {
    const std::vector<detail::FitElement> elements = detail::fitElementsOf(*ulink);
    const bool has_mesh = std::any_of(elements.begin(), elements.end(), [](const auto& e) { return !e.box; });
    const auto it = by_name.find(ulink->name);
    if (it == by_name.end()) {
      if (has_mesh) missing.push_back("'" + ulink->name + "'");
      continue;
    }
    seen.insert(ulink->name);
    if (elements.empty()) {
      stale.push_back("link '" + ulink->name + "' has no mesh or box collision elements now");
      continue;
    }
    std::vector<std::string> unreadable;
    const std::string inputs =
        detail::fitInputsHash(ulink->name, elements, overlay.urdf_dir, paths, &unreadable, nullptr);
    if (!unreadable.empty())
      stale.insert(stale.end(), unreadable.begin(), unreadable.end());
    else if (inputs != it->second->inputs)
      stale.push_back("link '" + ulink->name +
                      "': its meshes, filenames, scales, origins or boxes changed since the fit (inputs " + inputs +
                      ", fitted " + it->second->inputs + ")");
    else
      out[ulink->name] = it->second;
  }
  for (const auto& l : overlay.links)
    if (!seen.count(l.link)) stale.push_back("link '" + l.link + "' is not a link of " + origin);
  if (missing.empty() && stale.empty()) return out;
  std::string msg;
  if (!missing.empty()) {
    msg = origin + ": " + std::to_string(missing.size()) + " link" + (missing.size() == 1 ? " has" : "s have") +
          " mesh collision geometry and no fit:";
    for (const auto& m : missing) msg += " " + m;
    msg += "; run: reflex_fit " + origin + " (it writes " + defaultFitOverlayPath(origin) +
           ", which the loader reads; or name an overlay with 'fit:' in the collision YAML)";
  }
  if (!stale.empty()) {
    if (!msg.empty()) msg += "\n";
    msg += overlay.source + ": the fit is stale or cannot be checked for " + std::to_string(stale.size()) + " link" +
           (stale.size() == 1 ? "" : "s") + " (rerun: reflex_fit " + overlay.urdf + " -o " + overlay.source + "):";
    for (const auto& l : stale) msg += "\n  " + l;
  }
  throw ModelError(msg);
}

}  // namespace

std::string defaultCollisionConfigPath(const std::string& urdf_path) {
  return robotFileBeside(urdf_path, ".collision.yaml");
}

CollisionConfig loadCollisionConfig(const std::string& yaml_path) {
  CollisionConfig config;
  config.source = yaml_path;
  // An empty file is the defaults; errors name FILE:LINE:COL: KEY.PATH (control/docs/configuration.md).
  const common::ConfigNode root = common::ConfigNode::loadFile(
      yaml_path, "collision configuration", [](const std::string& m) { throw ModelError(m); }, /*allow_empty=*/true);
  root.rejectUnknown({"exclude_adjacent", "exclude", "srdf", "cylinder_as", "fit", "segments"});
  config.exclude_adjacent = root.boolean("exclude_adjacent", config.exclude_adjacent);
  if (root.has("exclude")) {
    for (const common::ConfigNode& item : root.at("exclude", "a list of pairs").elements()) {
      if (!item.isList() || item.node().size() != 2 || !item.node()[0].IsScalar() || !item.node()[1].IsScalar())
        item.failHere("not a pair", "a pair [segment_a, segment_b]");
      config.exclude.emplace_back(item.node()[0].Scalar(), item.node()[1].Scalar());
    }
  }
  if (root.has("segments")) {
    const common::ConfigNode segs = root.at("segments", "a map: segment link -> the links below it it takes in");
    segs.requireMap("a map: segment link -> the links below it it takes in");
    for (const auto& entry : segs.entries()) {
      const std::string& name = entry.first;
      config.segments.emplace_back(name, segs.strings(name, {}));
      if (config.segments.back().second.empty())
        segs.fail(name, "an empty list", "the links below " + name + " it takes in");
    }
  }
  config.cylinder_as = root.string("cylinder_as", config.cylinder_as);
  if (config.cylinder_as != "capsule")
    root.fail("cylinder_as", "not a cylinder policy",
              "capsule (the capsule around the cylinder's axis: the only one until the mesh fitter reads cylinders "
              "as shapes to fit)");
  if (root.has("fit"))
    config.fit = root.resolvePath(root.requiredString("fit", "the path of a fit overlay (written by reflex_fit)"));
  if (root.has("srdf")) {
    config.srdf = root.resolvePath(root.requiredString("srdf", "the path of an SRDF file"));
    config.srdf_disabled = loadSrdfDisabledCollisions(config.srdf);
  }
  return config;
}

std::vector<SrdfPair> loadSrdfDisabledCollisions(const std::string& srdf_path) {
  if (const std::string why = common::inputFileProblem(srdf_path); !why.empty()) throw ModelError("SRDF file " + why);
  tinyxml2::XMLDocument doc;
  if (doc.LoadFile(srdf_path.c_str()) != tinyxml2::XML_SUCCESS) {
    const char* e = doc.ErrorStr();
    throw ModelError(srdf_path + ": cannot read SRDF: " + (e ? e : "XML error"));
  }
  const tinyxml2::XMLElement* robot = doc.RootElement();
  if (!robot || std::strcmp(robot->Name(), "robot") != 0)
    throw ModelError(srdf_path + ": the top element must be <robot>, found <" + (robot ? robot->Name() : "") + ">");
  std::vector<SrdfPair> pairs;
  for (const auto* d = robot->FirstChildElement("disable_collisions"); d;
       d = d->NextSiblingElement("disable_collisions")) {
    const char* l1 = d->Attribute("link1");
    const char* l2 = d->Attribute("link2");
    const std::string where = srdf_path + ":" + std::to_string(d->GetLineNum());
    if (!l1 || !l2 || !*l1 || !*l2) throw ModelError(where + ": <disable_collisions> needs link1 and link2");
    const char* reason = d->Attribute("reason");
    pairs.push_back({l1, l2, reason ? reason : "", where});
  }
  return pairs;
}

CollisionConfig loadCollisionConfigFor(const std::string& urdf_path, const std::string& collision_path) {
  if (!collision_path.empty()) return loadCollisionConfig(collision_path);
  const std::string guess = defaultCollisionConfigPath(urdf_path);
  struct stat st {};
  if (::stat(guess.c_str(), &st) != 0) return CollisionConfig{};  // nothing there: the defaults
  return loadCollisionConfig(guess);  // something there: read it (a FIFO or device is refused)
}

Model loadModel(const std::string& urdf_path, const CollisionConfig& config, std::vector<std::string>* warnings) {
  if (const std::string why = common::inputFileProblem(urdf_path); !why.empty())
    throw ModelError("URDF file " + why);  // a FIFO or device would block or never end
  std::ifstream in(urdf_path);
  if (!in) throw ModelError(urdf_path + ": cannot open URDF file");
  std::stringstream ss;
  ss << in.rdbuf();
  if (config.fit.empty()) {  // the default overlay next to the robot, if there is one
    const std::string guess = defaultFitOverlayPath(urdf_path);
    struct stat st {};
    if (::stat(guess.c_str(), &st) == 0) {
      CollisionConfig with_fit = config;
      with_fit.fit = guess;
      return loadModelFromString(ss.str(), with_fit, urdf_path, warnings);
    }
  }
  return loadModelFromString(ss.str(), config, urdf_path, warnings);
}

namespace {

/// The links in `order` (parents first) with their joints and inertials; q indices in that order.
void addLinks(Model& model, const std::vector<urdf::LinkConstSharedPtr>& order, const std::string& origin) {
  std::map<std::string, int> index_of;
  for (const auto& ulink : order) {
    Link link;
    link.name = ulink->name;
    const auto& joint = ulink->parent_joint;
    if (joint) {
      link.parent = index_of.at(ulink->getParent()->name);
      link.joint_name = joint->name;
      link.X_P_J = toIsometry(joint->parent_to_joint_origin_transform);
      const Eigen::Vector3d axis(joint->axis.x, joint->axis.y, joint->axis.z);
      const std::string jwhere = "joint '" + joint->name + "'";
      switch (joint->type) {
        case urdf::Joint::FIXED: link.type = JointType::kFixed; break;
        case urdf::Joint::REVOLUTE:
        case urdf::Joint::CONTINUOUS: link.type = JointType::kRevolute; break;
        case urdf::Joint::PRISMATIC: link.type = JointType::kPrismatic; break;
        default:
          fail(origin, jwhere +
                           ": floating and planar joints are not supported; model them as a chain "
                           "of prismatic and revolute joints");
      }
      if (link.type != JointType::kFixed) {
        // Normalised from its largest component: |axis| of "1e308 1e308 0" overflows to inf and
        // axis / inf is (0, 0, 0); axis / 1e308 is (1, 1, 0), whose direction is the axis'.
        const double big = axis.cwiseAbs().maxCoeff();
        if (!axis.allFinite() || !(big > 1e-9)) fail(origin, jwhere + ": zero or invalid axis");
        link.axis_J = (axis / big).normalized();
        link.q_index = model.nq++;
        model.q_names.push_back(joint->name);
        model.q_link.push_back(static_cast<int>(model.links.size()));
      }
    }
    if (ulink->inertial) {
      const auto& in = *ulink->inertial;
      const Eigen::Isometry3d X_L_I = toIsometry(in.origin);
      Eigen::Matrix3d I_I;
      I_I << in.ixx, in.ixy, in.ixz, in.ixy, in.iyy, in.iyz, in.ixz, in.iyz, in.izz;
      link.has_inertial = true;
      link.mass = in.mass;
      link.com_L = X_L_I.translation();
      link.inertia_L = X_L_I.linear() * I_I * X_L_I.linear().transpose();
    }
    index_of[link.name] = static_cast<int>(model.links.size());
    model.links.push_back(link);
  }
}

/// Position and velocity limits per q index (a missing velocity limit: 1.0, with a warning).
void setLimits(Model& model, const urdf::ModelInterface& urdf_model, const std::string& origin,
               std::vector<std::string>* warnings) {
  // Limits per q index.
  model.q_lower.resize(model.nq);
  model.q_upper.resize(model.nq);
  model.v_max.resize(model.nq);
  for (int qi = 0; qi < model.nq; ++qi) {
    const auto joint = urdf_model.getJoint(model.q_names[qi]);
    const std::string jwhere = "joint '" + joint->name + "'";
    double lo = -std::numeric_limits<double>::infinity();
    double hi = std::numeric_limits<double>::infinity();
    double v = 0.0;
    if (joint->limits) {
      if (joint->type != urdf::Joint::CONTINUOUS) {
        lo = joint->limits->lower;
        hi = joint->limits->upper;
      }
      v = joint->limits->velocity;
    }
    if (!(lo <= hi)) fail(origin, jwhere + ": lower limit " + fmt(lo) + " exceeds upper limit " + fmt(hi));
    if (!(v > 0.0) || !std::isfinite(v)) {
      if (warnings)
        warnings->push_back(origin + ": " + jwhere + ": no positive velocity limit (" + fmt(v) + "); using 1.0");
      v = 1.0;
    }
    model.q_lower[qi] = lo;
    model.q_upper[qi] = hi;
    model.v_max[qi] = v;
  }
}

/// One segment per link with collision elements (a fitted link's pieces and capsules first), then the
/// body-schema slots.
void addSegments(Model& model, const std::vector<urdf::LinkConstSharedPtr>& order,
                 const std::map<std::string, const LinkFit*>& fitted, const std::string& origin,
                 std::vector<std::string>* warnings) {
  // Segments: one per link with collision elements.
  for (std::size_t i = 0; i < order.size(); ++i) {
    const auto& ulink = order[i];
    std::vector<urdf::CollisionSharedPtr> collisions = ulink->collision_array;
    if (collisions.empty() && ulink->collision) collisions.push_back(ulink->collision);
    if (collisions.empty()) continue;
    Segment seg;
    seg.name = ulink->name;
    seg.link = static_cast<int>(i);
    seg.first_primitive = static_cast<int>(model.primitives.size());
    const auto fit = fitted.find(ulink->name);
    if (fit != fitted.end()) {
      // The tight model: each capsule of a format-2 fit encloses a convex piece, the real shape.
      const LinkFit& lf = *fit->second;
      for (std::size_t k = 0; k < lf.primitives.size(); ++k) {
        Primitive p = lf.primitives[k];
        if (k < lf.pieces.size()) {
          p.piece = static_cast<int>(model.pieces.size());
          model.pieces.push_back(makeConvexPiece(lf.pieces[k].vertices, lf.pieces[k].triangles));
        }
        model.primitives.push_back(p);
      }
    }
    for (const auto& c : collisions) {
      const bool replaced = fit != fitted.end() && c->geometry &&
                            (c->geometry->type == urdf::Geometry::MESH || c->geometry->type == urdf::Geometry::BOX);
      if (!replaced) addCollision(origin, ulink->name, *c, model.primitives, warnings);
    }
    seg.num_primitives = static_cast<int>(model.primitives.size()) - seg.first_primitive;
    model.segments.push_back(seg);
  }
  model.num_robot_segments = static_cast<int>(model.segments.size());
  if (model.num_robot_segments == 0)
    fail(origin, "no link has collision geometry; add spheres or cylinders (read as capsules)");
  if (model.num_robot_segments + kBodySchemaSlots > kMaxSegments)
    fail(origin, "too many collision segments (" + std::to_string(model.num_robot_segments) + "); at most " +
                     std::to_string(kMaxSegments - kBodySchemaSlots) + " are supported");
  for (int s = 0; s < kBodySchemaSlots; ++s) {
    Segment seg;
    seg.name = "body_schema_" + std::to_string(s);
    seg.link = 0;
    seg.first_primitive = static_cast<int>(model.primitives.size());
    seg.num_primitives = 1;
    seg.body_schema_slot = true;
    model.primitives.push_back(Primitive{});
    model.segments.push_back(seg);
  }
}

/// The checked pairs: every pair of segments but those the SRDF or the configuration excludes, those
/// on one rigid body, and (with exclude_adjacent) adjacent ones; slot pairs with every robot segment.
void addPairs(Model& model, const CollisionConfig& config, const std::string& origin) {
  // Segment parent: the nearest ancestor link that carries a segment.
  std::vector<int> segment_of_link(model.links.size(), -1);
  for (int s = 0; s < model.num_robot_segments; ++s) segment_of_link[model.segments[s].link] = s;
  auto segmentParent = [&](int s) {
    int l = model.links[model.segments[s].link].parent;
    while (l >= 0 && segment_of_link[l] < 0) l = model.links[l].parent;
    return l >= 0 ? segment_of_link[l] : -1;
  };

  std::set<std::pair<int, int>> excluded;
  // SRDF <disable_collisions>: both links must be links of this robot; a link without collision
  // geometry has no segment, so its entries exclude nothing (MoveIt lists every link pair).
  for (const auto& d : config.srdf_disabled) {
    for (const std::string* name : {&d.link1, &d.link2})
      if (model.linkIndex(*name) < 0)
        fail(d.where, "disable_collisions names link '" + *name + "', which " + origin + " does not have");
    const int a = model.segmentIndex(d.link1);
    const int b = model.segmentIndex(d.link2);
    if (a >= 0 && b >= 0 && a != b && a < model.num_robot_segments && b < model.num_robot_segments)
      excluded.insert({std::min(a, b), std::max(a, b)});
  }
  for (const auto& [na, nb] : config.exclude) {
    const int a = model.segmentIndex(na);
    const int b = model.segmentIndex(nb);
    if (a < 0 || a >= model.num_robot_segments)
      fail(config.source, "exclude pair [" + na + ", " + nb + "]: unknown segment '" + na + "' in " + origin);
    if (b < 0 || b >= model.num_robot_segments)
      fail(config.source, "exclude pair [" + na + ", " + nb + "]: unknown segment '" + nb + "' in " + origin);
    if (a == b) fail(config.source, "exclude pair [" + na + ", " + nb + "]: a segment is never paired with itself");
    excluded.insert({std::min(a, b), std::max(a, b)});
  }
  // Rigid bodies: links joined by fixed joints move together, so their segments keep one distance
  // that no joint can change. Never checked, whatever the configuration says.
  std::vector<int> body_of_link(model.links.size());
  for (std::size_t l = 0; l < model.links.size(); ++l) {
    const Link& link = model.links[l];
    body_of_link[l] =
        (link.parent >= 0 && link.type == JointType::kFixed) ? body_of_link[link.parent] : static_cast<int>(l);
  }
  // Adjacency, looking through links without collision geometry as the field
  // does: a segment and the nearest segment up its chain (joined by one joint, or through links
  // without geometry), and two segments whose links are children of the same link without
  // geometry (siblings, e.g. two hip links under a bare pelvis). Deliberately no further: cousins
  // through longer geometry-less chains (two arms under a bare torso) stay checked.
  auto siblingsUnderBareParent = [&](int a, int b) {
    const int pa = model.links[model.segments[a].link].parent;
    return pa >= 0 && pa == model.links[model.segments[b].link].parent && segment_of_link[pa] < 0;
  };
  auto adjacent = [&](int a, int b) {
    return segmentParent(a) == b || segmentParent(b) == a || siblingsUnderBareParent(a, b);
  };
  const int nseg = static_cast<int>(model.segments.size());
  for (int a = 0; a < nseg; ++a) {
    for (int b = a + 1; b < nseg; ++b) {
      if (model.segments[a].body_schema_slot) continue;  // slot-slot pairs are never checked
      if (!model.segments[b].body_schema_slot) {
        if (excluded.count({a, b})) continue;
        if (body_of_link[model.segments[a].link] == body_of_link[model.segments[b].link]) continue;
        if (config.exclude_adjacent && adjacent(a, b)) continue;
      }
      model.pairs.push_back({a, b});
    }
  }
}

/// The segments of several links (`segments:`): each takes in the segments of the links it lists,
/// their primitives keeping their own links; the checked pairs become pairs of the new segments, with
/// every link pair that was not checked listed in SegmentPair::unchecked_links, so exactly the same
/// link pairs are checked. A link pair inside one segment that was checked is refused (a segment is
/// never checked against itself).
void groupSegments(Model& model, const CollisionConfig& config, const std::string& origin) {
  if (config.segments.empty()) return;
  const std::string where = "segments: ";
  const int nl = static_cast<int>(model.links.size());
  std::vector<int> old_segment_of_link(static_cast<std::size_t>(nl), -1);
  for (int s = 0; s < model.num_robot_segments; ++s) old_segment_of_link[model.segments[s].link] = s;
  std::vector<int> group_of_link(static_cast<std::size_t>(nl), -1);  // key and members
  std::vector<int> group_key;
  std::vector<std::vector<int>> group_members;
  for (const auto& [key_name, members] : config.segments) {
    const int key = model.linkIndex(key_name);
    if (key < 0) fail(config.source, where + "'" + key_name + "' is not a link of " + origin);
    const int g = static_cast<int>(group_key.size());
    if (group_of_link[key] >= 0)
      fail(config.source, where + "link '" + key_name + "' is in two segments ('" +
                              model.links[group_key[group_of_link[key]]].name + "' and '" + key_name + "')");
    group_of_link[key] = g;
    group_key.push_back(key);
    group_members.emplace_back();
    for (const std::string& name : members) {
      const int l = model.linkIndex(name);
      if (l < 0) fail(config.source, where + key_name + ": '" + name + "' is not a link of " + origin);
      if (group_of_link[l] >= 0)
        fail(config.source, where + "link '" + name + "' is in two segments ('" +
                                model.links[group_key[group_of_link[l]]].name + "' and '" + key_name + "')");
      int up = model.links[l].parent;
      while (up >= 0 && up != key) up = model.links[up].parent;
      if (up != key) fail(config.source, where + key_name + ": '" + name + "' is not below '" + key_name + "'");
      if (old_segment_of_link[l] < 0)
        fail(config.source, where + key_name + ": '" + name + "' has no collision geometry (nothing to take in)");
      group_of_link[l] = g;
      group_members.back().push_back(l);
    }
  }
  // The new robot segments, in the order of their first link's segment; primitives re-laid.
  std::vector<Segment> segs;
  std::vector<Primitive> prims;
  std::vector<int> new_of_old(model.segments.size(), -1);
  std::vector<int> new_of_group(group_key.size(), -1);
  auto append = [&](Segment& seg, int old) {
    const Segment& o = model.segments[static_cast<std::size_t>(old)];
    for (int p = o.first_primitive; p < o.first_primitive + o.num_primitives; ++p) {
      Primitive prim = model.primitives[static_cast<std::size_t>(p)];
      if (o.link != seg.link) prim.link = o.link;
      prims.push_back(prim);
    }
    seg.num_primitives += o.num_primitives;
    new_of_old[static_cast<std::size_t>(old)] = static_cast<int>(segs.size());
  };
  for (int s = 0; s < model.num_robot_segments; ++s) {
    const int g = group_of_link[model.segments[s].link];
    if (g >= 0 && new_of_group[g] >= 0) continue;  // taken in with its group
    Segment seg;
    seg.first_primitive = static_cast<int>(prims.size());
    if (g < 0) {
      seg.name = model.segments[s].name;
      seg.link = model.segments[s].link;
      append(seg, s);
    } else {
      seg.name = model.links[group_key[g]].name;
      seg.link = group_key[g];
      if (const int own = old_segment_of_link[group_key[g]]; own >= 0) append(seg, own);
      for (const int l : group_members[g]) append(seg, old_segment_of_link[l]);
      new_of_group[g] = static_cast<int>(segs.size());
    }
    segs.push_back(std::move(seg));
  }
  const int nrobot = static_cast<int>(segs.size());
  for (int s = model.num_robot_segments; s < static_cast<int>(model.segments.size()); ++s) {
    Segment seg = model.segments[s];
    seg.first_primitive = static_cast<int>(prims.size());
    prims.push_back(model.primitives[static_cast<std::size_t>(model.segments[s].first_primitive)]);
    segs.push_back(seg);
  }
  // The checked link pairs, and the new segment pairs they fall in.
  std::set<std::pair<int, int>> checked_links;
  std::set<std::pair<int, int>> new_pairs;
  for (const SegmentPair& p : model.pairs) {
    if (model.segments[p.a].body_schema_slot || model.segments[p.b].body_schema_slot) continue;
    const int la = model.segments[p.a].link, lb = model.segments[p.b].link;
    const int na = new_of_old[p.a], nb = new_of_old[p.b];
    if (na == nb)
      fail(config.source,
           where + "'" + segs[na].name + "' takes in '" + model.links[la].name + "' and '" + model.links[lb].name +
               "', a pair that is checked; a segment is never checked against itself: exclude [" +
               model.links[la].name + ", " + model.links[lb].name + "] or leave one of them out of the segment");
    checked_links.insert({std::min(la, lb), std::max(la, lb)});
    new_pairs.insert({std::min(na, nb), std::max(na, nb)});
  }
  auto linksOf = [&](const Segment& seg) {
    std::vector<int> out;
    for (int p = seg.first_primitive; p < seg.first_primitive + seg.num_primitives; ++p) {
      const int l = linkOf(seg, prims[static_cast<std::size_t>(p)]);
      if (std::find(out.begin(), out.end(), l) == out.end()) out.push_back(l);
    }
    return out;
  };
  std::vector<SegmentPair> pairs;
  const int nseg = static_cast<int>(segs.size());
  for (int a = 0; a < nrobot; ++a) {
    for (int b = a + 1; b < nseg; ++b) {
      if (b >= nrobot) {  // a body-schema slot: checked against every robot segment
        pairs.push_back({a, b, {}});
        continue;
      }
      if (!new_pairs.count({a, b})) continue;
      SegmentPair pair{a, b, {}};
      for (const int la : linksOf(segs[a]))
        for (const int lb : linksOf(segs[b]))
          if (!checked_links.count({std::min(la, lb), std::max(la, lb)})) pair.unchecked_links.push_back({la, lb});
      std::sort(pair.unchecked_links.begin(), pair.unchecked_links.end());
      pairs.push_back(std::move(pair));
    }
  }
  model.segments = std::move(segs);
  model.primitives = std::move(prims);
  model.num_robot_segments = nrobot;
  model.pairs = std::move(pairs);
}

}  // namespace

Model loadModelFromString(const std::string& urdf_xml, const CollisionConfig& config, const std::string& origin,
                          std::vector<std::string>* warnings) {
  // Our own reading of the XML first: it finds what urdfdom would drop silently (urdf_audit.hpp).
  const detail::UrdfAudit audit = detail::auditUrdf(urdf_xml);
  if (!audit.xml_error.empty()) fail(origin, "malformed URDF: " + audit.xml_error);
  std::vector<std::string> problems = audit.problems;
  urdf::ModelInterfaceSharedPtr urdf_model;
  try {
    urdf_model = urdf::parseURDF(audit.capsules > 0 ? audit.urdfdom_xml : urdf_xml);
  } catch (const std::exception& e) {
    problems.push_back(std::string("urdfdom: ") + e.what());
  }
  for (auto& p : detail::collisionAccounting(audit, urdf_model.get())) problems.push_back(std::move(p));
  if (!urdf_model) {
    if (problems.empty()) fail(origin, "malformed URDF (urdfdom could not parse it; see the message above)");
    failWithProblems(origin, "malformed URDF", problems);
  }
  // Every collision element of the file is accounted for, or the load fails naming the link.
  if (!problems.empty()) {
    // Release urdfdom's child links even on this exit (the reference cycle below).
    for (auto& entry : urdf_model->links_)
      if (entry.second) entry.second->child_links.clear();
    failWithProblems(origin, "collision geometry would be left out or is out of range", problems);
  }
  // urdfdom holds children by shared_ptr: a kinematic loop in a malformed file (a link made the child
  // of its own descendant) is a reference cycle that would outlive the model. Break it on every exit.
  struct ChildLinksReleaser {
    urdf::ModelInterfaceSharedPtr& m;
    ~ChildLinksReleaser() {
      for (auto& entry : m->links_)
        if (entry.second) entry.second->child_links.clear();
    }
  } release_children{urdf_model};
  if (!urdf_model->getRoot()) fail(origin, "URDF has no root link");

  FitOverlay overlay;
  if (!config.fit.empty()) overlay = loadFitOverlay(config.fit);

  Model model;
  model.name = urdf_model->getName();

  // Breadth-first over the tree: parents before children.
  std::vector<urdf::LinkConstSharedPtr> order{urdf_model->getRoot()};
  std::set<std::string> reached{urdf_model->getRoot()->name};
  for (std::size_t i = 0; i < order.size(); ++i)
    for (const auto& child : order[i]->child_links)
      if (reached.insert(child->name).second) order.push_back(child);
  for (const auto& entry : urdf_model->links_)
    if (!reached.count(entry.first))
      fail(origin, "link '" + entry.first + "' is not connected to the root link '" + urdf_model->getRoot()->name +
                       "' (a kinematic loop: is it the child of its own descendant?)");

  addLinks(model, order, origin);

  setLimits(model, *urdf_model, origin, warnings);

  // Support (movable ancestors, root first) of every link.
  model.link_support.resize(model.links.size());
  for (std::size_t i = 0; i < model.links.size(); ++i) {
    const Link& link = model.links[i];
    if (link.parent >= 0) model.link_support[i] = model.link_support[link.parent];
    if (link.q_index >= 0) model.link_support[i].push_back(link.q_index);
  }

  // Meshes (and, on fitted links, boxes): the fit overlay's primitives, checked fresh.
  const std::map<std::string, const LinkFit*> fitted = fittedLinks(origin, order, overlay);

  addSegments(model, order, fitted, origin, warnings);

  addPairs(model, config, origin);
  groupSegments(model, config, origin);
  return model;
}

}  // namespace reflex::control
