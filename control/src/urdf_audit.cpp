#include "urdf_audit.hpp"

#include <tinyxml2.h>
#include <urdf_model/model.h>

#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <sstream>

namespace reflex::control::detail {
namespace {

using tinyxml2::XMLElement;

std::string fmt(double v) {
  std::ostringstream os;
  os << v;
  return os.str();
}

std::string lineOf(const XMLElement& e) { return "line " + std::to_string(e.GetLineNum()); }

bool isName(const XMLElement& e, const char* name) { return std::strcmp(e.Name(), name) == 0; }

/// What is wrong with one number token ("" if nothing): the whole token must be a number in the C
/// locale's syntax, finite, and |value| <= max_abs.
std::string numberProblem(const std::string& token, double max_abs, const char* unit, double& value) {
  if (token.empty()) return "empty number";
  errno = 0;
  char* end = nullptr;
  value = std::strtod(token.c_str(), &end);
  if (end == token.c_str() || *end != '\0') return "'" + token + "' is not a number";
  if (!std::isfinite(value) || errno == ERANGE) {
    if (errno == ERANGE && std::isfinite(value)) return "";  // underflow to (almost) zero is harmless
    return "'" + token + "' is not a finite number";
  }
  if (std::abs(value) > max_abs)
    return fmt(value) + " is out of range (|value| <= " + fmt(max_abs) + (*unit ? " " : "") + unit + ")";
  return "";
}

/// The text of attribute `attr` of `e`, or null; a missing required attribute is appended to `out`
/// as "<where>: missing (line N)". `where` becomes "<prefix><element> <attr>".
const char* attributeText(const XMLElement& e, const char* attr, bool required, const std::string& prefix,
                          std::string& where, std::vector<std::string>& out) {
  const char* text = e.Attribute(attr);
  where = prefix + "<" + e.Name() + "> " + attr;
  if (!text && required) out.push_back(where + ": missing (" + lineOf(e) + ")");
  return text;
}

/// Checks attribute `attr` of `e`: a single number written without spaces (urdfdom refuses
/// "0.001 "). Appends "<prefix><element> <attr> '<text>': <reason>" to `out`.
void checkScalar(const XMLElement& e, const char* attr, bool required, double max_abs, const char* unit,
                 const std::string& prefix, std::vector<std::string>& out) {
  std::string where;
  const char* text = attributeText(e, attr, required, prefix, where, out);
  if (!text) return;
  double v = 0.0;
  const std::string why = numberProblem(text, max_abs, unit, v);
  if (!why.empty()) out.push_back(where + " '" + text + "' (" + lineOf(e) + "): " + why);
}

/// Checks a vector attribute of `n` numbers separated by white space (urdfdom tolerates white space
/// around the numbers, so this does too).
void checkVector(const XMLElement& e, const char* attr, int n, bool required, double max_abs, const char* unit,
                 const std::string& prefix, std::vector<std::string>& out) {
  std::string where;
  const char* text = attributeText(e, attr, required, prefix, where, out);
  if (!text) return;
  std::istringstream is{std::string(text)};
  std::vector<std::string> tokens;
  for (std::string t; is >> t;) tokens.push_back(t);
  const std::string head = where + " '" + text + "' (" + lineOf(e) + "): ";
  if (static_cast<int>(tokens.size()) != n) {
    out.push_back(head + std::to_string(tokens.size()) + " values, " + std::to_string(n) + " expected");
    return;
  }
  for (const auto& t : tokens) {
    double v = 0.0;
    const std::string why = numberProblem(t, max_abs, unit, v);
    if (!why.empty()) {
      out.push_back(head + why);
      return;
    }
  }
}

/// <origin xyz rpy>: `limited` applies the ranges of collision elements and joints, else only
/// "finite and well-formed" (what urdfdom itself needs).
void checkOrigin(const XMLElement& parent, bool limited, const std::string& prefix, std::vector<std::string>& out) {
  for (const XMLElement* o = parent.FirstChildElement("origin"); o; o = o->NextSiblingElement("origin")) {
    checkVector(*o, "xyz", 3, false, limited ? kMaxUrdfLength : HUGE_VAL, "m", prefix, out);
    checkVector(*o, "rpy", 3, false, limited ? kMaxUrdfAngle : HUGE_VAL, "rad", prefix, out);
  }
}

/// <geometry>: exactly one shape of URDF (urdfdom's four and URDF 1.1's capsule), with well-formed sizes (collision: also in range).
/// Signs are left to the loader, which names them ("radius -0.25 must be positive").
void checkGeometry(const XMLElement& owner, bool limited, const std::string& prefix, std::vector<std::string>& out) {
  const XMLElement* g = owner.FirstChildElement("geometry");
  if (!g) {
    out.push_back(prefix + "no <geometry> (" + lineOf(owner) + ")");
    return;
  }
  const XMLElement* shape = g->FirstChildElement();
  if (!shape) {
    out.push_back(prefix + "<geometry> (" + lineOf(*g) + ") holds no shape");
    return;
  }
  if (shape->NextSiblingElement())
    out.push_back(prefix + "<geometry> (" + lineOf(*g) + ") holds more than one shape (<" + shape->Name() + ">, <" +
                  shape->NextSiblingElement()->Name() + ">): urdfdom reads only the first");
  const double max = limited ? kMaxUrdfLength : HUGE_VAL;
  if (isName(*shape, "sphere")) {
    checkScalar(*shape, "radius", true, max, "m", prefix, out);
  } else if (isName(*shape, "cylinder") || isName(*shape, "capsule")) {
    checkScalar(*shape, "radius", true, max, "m", prefix, out);
    checkScalar(*shape, "length", true, max, "m", prefix, out);
  } else if (isName(*shape, "box")) {
    checkVector(*shape, "size", 3, true, max, "m", prefix, out);
  } else if (isName(*shape, "mesh")) {
    if (!shape->Attribute("filename")) out.push_back(prefix + "<mesh> (" + lineOf(*shape) + ") has no filename");
    checkVector(*shape, "scale", 3, false, HUGE_VAL, "", prefix, out);
  } else {
    out.push_back(prefix + "unknown geometry <" + std::string(shape->Name()) + "> (" + lineOf(*shape) +
                  "); a URDF geometry is a sphere, cylinder, capsule, box or mesh");
  }
}

void checkLink(const XMLElement& link, const std::string& name, UrdfAudit& audit) {
  int count = 0;
  std::vector<std::string>& cp = audit.collision_problems[name];
  std::vector<std::string>& op = audit.other_problems[name];
  for (const XMLElement* c = link.FirstChildElement("collision"); c; c = c->NextSiblingElement("collision")) {
    ++count;
    const std::string prefix = "collision " + std::to_string(count) + " (" + lineOf(*c) + "): ";
    checkOrigin(*c, true, prefix, cp);
    checkGeometry(*c, true, prefix, cp);
  }
  audit.collisions[name] = count;
  int nv = 0;
  for (const XMLElement* v = link.FirstChildElement("visual"); v; v = v->NextSiblingElement("visual")) {
    const std::string prefix = "visual " + std::to_string(++nv) + " (" + lineOf(*v) + "): ";
    checkOrigin(*v, false, prefix, op);
    checkGeometry(*v, false, prefix, op);
    for (const XMLElement* m = v->FirstChildElement("material"); m; m = m->NextSiblingElement("material")) {
      if (!m->Attribute("name")) op.push_back(prefix + "<material> (" + lineOf(*m) + ") has no name");
      if (const XMLElement* color = m->FirstChildElement("color"))
        checkVector(*color, "rgba", 4, true, HUGE_VAL, "", prefix, op);
    }
  }
  for (const XMLElement* in = link.FirstChildElement("inertial"); in; in = in->NextSiblingElement("inertial")) {
    const std::string prefix = "inertial (" + lineOf(*in) + "): ";
    checkOrigin(*in, false, prefix, op);
    if (const XMLElement* mass = in->FirstChildElement("mass"))
      checkScalar(*mass, "value", true, HUGE_VAL, "kg", prefix, op);
    else
      op.push_back(prefix + "no <mass>");
    if (const XMLElement* inertia = in->FirstChildElement("inertia")) {
      for (const char* a : {"ixx", "ixy", "ixz", "iyy", "iyz", "izz"})
        checkScalar(*inertia, a, true, HUGE_VAL, "", prefix, op);
    } else {
      op.push_back(prefix + "no <inertia>");
    }
  }
}

void checkJoint(const XMLElement& joint, std::vector<std::string>& out) {
  const char* name = joint.Attribute("name");
  const std::string prefix = std::string("joint '") + (name ? name : "<unnamed>") + "' (" + lineOf(joint) + "): ";
  if (!name) out.push_back(prefix + "has no name");
  checkOrigin(joint, true, prefix, out);
  if (const XMLElement* axis = joint.FirstChildElement("axis"))
    checkVector(*axis, "xyz", 3, false, HUGE_VAL, "", prefix, out);
  if (const XMLElement* limit = joint.FirstChildElement("limit")) {
    checkScalar(*limit, "lower", false, kMaxJointLimit, "", prefix, out);
    checkScalar(*limit, "upper", false, kMaxJointLimit, "", prefix, out);
    checkScalar(*limit, "effort", false, HUGE_VAL, "", prefix, out);
    checkScalar(*limit, "velocity", false, kMaxJointVelocity, "rad/s or m/s", prefix, out);
  }
  // Other joint elements urdfdom parses as numbers: a bad one fails the whole file there.
  for (const char* child : {"dynamics", "calibration", "safety_controller", "mimic"}) {
    for (const XMLElement* e = joint.FirstChildElement(child); e; e = e->NextSiblingElement(child))
      for (const tinyxml2::XMLAttribute* a = e->FirstAttribute(); a; a = a->Next())
        if (std::strcmp(a->Name(), "joint") != 0) checkScalar(*e, a->Name(), false, HUGE_VAL, "", prefix, out);
  }
}

/// Collision elements and links anywhere but where urdfdom looks (<robot><link><collision>). Inside
/// <gazebo> extension blocks, <collision> carries simulator surface parameters, not geometry.
/// Recursive: the depth is bounded by tinyxml2, which refuses documents nested deeper than
/// TINYXML2_MAX_ELEMENT_DEPTH (100) with a parse error.
void findStrays(const XMLElement& e, const XMLElement& robot, bool in_gazebo, std::vector<std::string>& out) {
  for (const XMLElement* c = e.FirstChildElement(); c; c = c->NextSiblingElement()) {
    const bool gazebo = in_gazebo || isName(*c, "gazebo");
    if (!gazebo) {
      const bool link_of_robot = &e == &robot && isName(*c, "link");
      if (isName(*c, "collision") && !(isName(e, "link") && e.Parent() == &robot))
        out.push_back("a <collision> element (" + lineOf(*c) + ") inside <" + e.Name() +
                      ">, outside every <link> of <robot>: urdfdom ignores it");
      if (isName(*c, "link") && !link_of_robot && c->FirstChildElement("collision")) {
        const char* name = c->Attribute("name");
        out.push_back(std::string("link '") + (name ? name : "<unnamed>") + "' (" + lineOf(*c) + ") inside <" +
                      e.Name() + ">, not directly inside <robot>: urdfdom ignores it and its collision elements");
      }
    }
    findStrays(*c, robot, gazebo, out);
  }
}

}  // namespace

UrdfAudit auditUrdf(const std::string& xml) {
  UrdfAudit audit;
  tinyxml2::XMLDocument doc;
  if (doc.Parse(xml.data(), xml.size()) != tinyxml2::XML_SUCCESS) {
    const char* s = doc.ErrorStr();
    audit.xml_error = s ? s : "XML error";
    return audit;
  }
  const XMLElement* robot = doc.RootElement();
  if (!robot) {
    audit.xml_error = "no XML element";
    return audit;
  }
  if (!isName(*robot, "robot")) {
    audit.problems.push_back(std::string("the top element is <") + robot->Name() + ">, not <robot>");
    return audit;
  }
  std::map<std::string, int> first_line;
  for (const XMLElement* link = robot->FirstChildElement("link"); link; link = link->NextSiblingElement("link")) {
    const char* name = link->Attribute("name");
    if (!name) {
      audit.problems.push_back("a <link> without a name (" + lineOf(*link) + ")");
      continue;
    }
    if (const auto it = first_line.find(name); it != first_line.end()) {
      audit.problems.push_back(std::string("link '") + name + "' is defined twice (lines " +
                               std::to_string(it->second) + " and " + std::to_string(link->GetLineNum()) + ")");
      continue;
    }
    first_line[name] = link->GetLineNum();
    checkLink(*link, name, audit);
  }
  for (const XMLElement* joint = robot->FirstChildElement("joint"); joint; joint = joint->NextSiblingElement("joint"))
    checkJoint(*joint, audit.problems);
  for (const XMLElement* m = robot->FirstChildElement("material"); m; m = m->NextSiblingElement("material"))
    if (!m->Attribute("name")) audit.problems.push_back("a <material> of <robot> without a name (" + lineOf(*m) + ")");
  findStrays(*robot, *robot, false, audit.problems);
  // URDF 1.1 capsules of links' collision and visual elements -> cylinders of the same size, for urdfdom.
  for (XMLElement* link = doc.RootElement()->FirstChildElement("link"); link; link = link->NextSiblingElement("link"))
    for (const char* kind : {"collision", "visual"})
      for (XMLElement* c = link->FirstChildElement(kind); c; c = c->NextSiblingElement(kind))
        if (XMLElement* g = c->FirstChildElement("geometry"))
          for (XMLElement* shape = g->FirstChildElement("capsule"); shape;
               shape = shape->NextSiblingElement("capsule")) {
            shape->SetName("cylinder");
            ++audit.capsules;
          }
  if (audit.capsules > 0) {
    tinyxml2::XMLPrinter printer;
    doc.Print(&printer);
    audit.urdfdom_xml.assign(printer.CStr(),
                             static_cast<std::size_t>(printer.CStrSize() > 0 ? printer.CStrSize() - 1 : 0));
  }
  return audit;
}

std::vector<std::string> collisionAccounting(const UrdfAudit& audit, const urdf::ModelInterface* model) {
  std::vector<std::string> problems;
  for (const auto& [link, expected] : audit.collisions) {
    int read = expected;
    if (model) {
      const auto ulink = model->getLink(link);
      read = !ulink                            ? 0
             : !ulink->collision_array.empty() ? static_cast<int>(ulink->collision_array.size())
                                               : (ulink->collision ? 1 : 0);
    }
    const bool dropped = read != expected;
    std::string line;
    if (dropped)
      line = "; urdfdom read " + std::to_string(read) + " of its " + std::to_string(expected) + " collision elements";
    for (const auto& p : audit.collision_problems.at(link)) line += "; " + p;
    if (dropped || !model)
      for (const auto& p : audit.other_problems.at(link)) line += "; " + p;
    if (dropped && line.find("; ", 2) == std::string::npos)
      line += "; no reason found here (urdfdom's message above says why)";
    if (!line.empty()) problems.push_back("link '" + link + "'" + line.replace(0, 1, ":"));
  }
  return problems;
}

}  // namespace reflex::control::detail
