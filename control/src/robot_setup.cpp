// Finding a humanoid's arms, hands, head, rest posture and collision gaps (robot_setup.hpp).
#include "reflex/control/robot_setup.hpp"

#include "reflex/control/distance.hpp"
#include "reflex/control/kinematics.hpp"
#include "reflex/control/mesh_fit.hpp"
#include "reflex/control/onboard.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <random>
#include <sstream>

namespace reflex::control {
namespace {

std::string fmt(const char* f, double v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, f, v);
  return buf;
}

std::string vec(const Eigen::Vector3d& v) {
  char buf[96];
  const auto r = [](double x) { return std::round(x * 1000.0) / 1000.0 + 0.0; };  // no "-0.000"
  std::snprintf(buf, sizeof buf, "(%.3f, %.3f, %.3f)", r(v.x()), r(v.y()), r(v.z()));
  return buf;
}

// A serial run of movable joints (see the header): its links (child of each joint, in order, with
// the fixed links between them), its revolute joints, the branching link above it.
struct Chain {
  int branch = -1;
  std::vector<int> links;   // every link of the run, top first
  std::vector<int> joints;  // q indices of its joints, top first
  bool prismatic = false;
  int first_link = -1;                                // link moved by the first joint
  Eigen::Vector3d start_B = Eigen::Vector3d::Zero();  // first joint's origin at the neutral configuration
  std::string describe(const Model& m) const {
    std::string s = "[";
    for (std::size_t i = 0; i < joints.size(); ++i) s += (i ? " " : "") + m.q_names[joints[i]];
    return s + "]";
  }
};

struct Tree {
  std::vector<std::vector<int>> children;
  std::vector<bool> movable_below;  // the link's subtree (its own joint included) holds a movable joint
  std::vector<int> segment_of;      // robot segment on the link, -1 none
  explicit Tree(const Model& m)
      : children(m.links.size()), movable_below(m.links.size(), false), segment_of(m.links.size(), -1) {
    for (std::size_t l = 0; l < m.links.size(); ++l)
      if (m.links[l].parent >= 0) children[m.links[l].parent].push_back(static_cast<int>(l));
    for (int l = static_cast<int>(m.links.size()) - 1; l >= 0; --l) {  // children come after parents
      if (m.links[l].q_index >= 0) movable_below[l] = true;
      if (movable_below[l] && m.links[l].parent >= 0) movable_below[m.links[l].parent] = true;
    }
    for (int s = 0; s < m.num_robot_segments; ++s) segment_of[m.segments[s].link] = s;
  }
  std::vector<int> movableChildren(int l) const {
    std::vector<int> r;
    for (int c : children[l])
      if (movable_below[c]) r.push_back(c);
    return r;
  }
  bool isBranch(int l) const { return movableChildren(l).size() >= 2; }
};

Chain walkDown(const Model& m, const Tree& t, int branch, int child) {
  Chain c;
  c.branch = branch;
  int cur = child;
  while (true) {
    c.links.push_back(cur);
    const Link& L = m.links[cur];
    if (L.q_index >= 0) {
      if (L.type == JointType::kPrismatic) c.prismatic = true;
      if (c.joints.empty()) c.first_link = cur;
      c.joints.push_back(L.q_index);
    }
    const std::vector<int> next = t.movableChildren(cur);
    if (next.size() != 1) break;
    cur = next[0];
  }
  return c;
}

std::vector<Chain> allChains(const Model& m, const Tree& t, const KinematicsData& kin) {
  std::vector<Chain> chains;
  for (std::size_t b = 0; b < m.links.size(); ++b) {
    if (!t.isBranch(static_cast<int>(b))) continue;
    for (int c : t.movableChildren(static_cast<int>(b))) {
      Chain ch = walkDown(m, t, static_cast<int>(b), c);
      if (ch.joints.empty()) continue;
      ch.start_B = kin.X_B_L[ch.first_link].translation();
      chains.push_back(ch);
    }
  }
  return chains;
}

// The arm chain that ends at a given hand link: its revolute joints up to the nearest branching link.
Chain chainToHand(const Model& m, const Tree& t, const KinematicsData& kin, int hand) {
  Chain c;
  std::vector<int> up;
  int cur = hand;
  while (cur >= 0 && !t.isBranch(cur)) {
    up.push_back(cur);
    cur = m.links[cur].parent;
  }
  c.branch = cur;
  for (auto it = up.rbegin(); it != up.rend(); ++it) {
    c.links.push_back(*it);
    const Link& L = m.links[*it];
    if (L.q_index < 0) continue;
    if (L.type == JointType::kPrismatic) c.prismatic = true;
    if (c.joints.empty()) c.first_link = *it;
    c.joints.push_back(L.q_index);
  }
  if (!c.joints.empty()) c.start_B = kin.X_B_L[c.first_link].translation();
  return c;
}

bool mirrored(const Chain& a, const Chain& b) {
  const double tol = 0.01;
  return a.joints.size() == b.joints.size() && std::abs(a.start_B.x() - b.start_B.x()) < tol &&
         std::abs(a.start_B.z() - b.start_B.z()) < tol && std::abs(a.start_B.y() + b.start_B.y()) < tol &&
         std::abs(a.start_B.y()) > tol;
}

int nameScore(const Model& m, const Chain& c) {
  static const char* const kArm[] = {"shoulder", "arm", "elbow", "wrist", "hand"};
  static const char* const kLeg[] = {"hip", "leg", "knee", "ankle", "foot", "thigh", "shin"};
  int score = 0;
  for (int l : c.links) {
    std::string names = m.links[l].name + " " + m.links[l].joint_name;
    std::transform(names.begin(), names.end(), names.begin(), [](unsigned char ch) { return std::tolower(ch); });
    for (const char* w : kArm) score += names.find(w) != std::string::npos;
    for (const char* w : kLeg) score -= names.find(w) != std::string::npos;
  }
  return score;
}

// What a chain's names say of its side: +1 left, -1 right, 0 nothing or both. A name says left when it
// starts with "l_", "left" or "L" followed by a capital ("LShoulderPitch"), or holds "_l_" / "left";
// right alike.
int sideHint(const Model& m, const Chain& c) {
  int left = 0, right = 0;
  auto says = [](const std::string& n, char side, const char* word) {
    const std::string lo = [&] {
      std::string x = n;
      std::transform(x.begin(), x.end(), x.begin(), [](unsigned char ch) { return std::tolower(ch); });
      return x;
    }();
    const std::string pre = std::string(1, side) + "_";
    return lo.rfind(pre, 0) == 0 || lo.find("_" + pre) != std::string::npos || lo.find(word) != std::string::npos ||
           (n.size() > 1 && n[0] == std::toupper(side) && std::isupper(static_cast<unsigned char>(n[1])));
  };
  for (int l : c.links)
    for (const std::string* n : {&m.links[l].name, &m.links[l].joint_name}) {
      left += says(*n, 'l', "left");
      right += says(*n, 'r', "right");
    }
  return left > right ? 1 : right > left ? -1 : 0;
}

std::string lower(std::string s) {
  std::transform(s.begin(), s.end(), s.begin(), [](unsigned char ch) { return std::tolower(ch); });
  return s;
}

// The hand link of a chain: its last link, or the first link with geometry rigidly below it.
int handOfChain(const Model& m, const Tree& t, const Chain& c) {
  const int last = c.links.back();
  if (t.segment_of[last] >= 0) return last;
  std::vector<int> stack = t.children[last];
  while (!stack.empty()) {
    const int l = stack.front();
    stack.erase(stack.begin());
    if (m.links[l].q_index >= 0) continue;
    if (t.segment_of[l] >= 0) return l;
    for (int ch : t.children[l]) stack.push_back(ch);
  }
  return last;
}

Eigen::Vector3d handPoint(const Model& m, const Tree& t, int hand, bool* has_geometry) {
  const int s = t.segment_of[hand];
  *has_geometry = s >= 0;
  if (s < 0) return Eigen::Vector3d::Zero();
  const Segment& seg = m.segments[s];
  Eigen::Vector3d best = Eigen::Vector3d::Zero();
  double best_n = -1.0;
  for (int p = seg.first_primitive; p < seg.first_primitive + seg.num_primitives; ++p) {
    if (linkOf(seg, m.primitives[p]) != hand) continue;  // a finger's (a segment of several links)
    for (const Eigen::Vector3d& e : {m.primitives[p].a_L, m.primitives[p].b_L}) {
      if (e.norm() > best_n + 1e-12) {
        best_n = e.norm();
        best = e;
      }
    }
  }
  return best;
}

int linkOrThrow(const Model& m, const std::string& name, const char* what) {
  const int l = m.linkIndex(name);
  if (l < 0) throw SetupError(std::string(what) + " '" + name + "' is not a link of robot '" + m.name + "'");
  return l;
}

}  // namespace

std::vector<std::pair<std::string, std::vector<std::string>>> handSegments(
    const Model& model, const std::vector<std::string>& hand_links, const std::vector<std::string>& driven_joints) {
  std::vector<std::pair<std::string, std::vector<std::string>>> out;
  std::vector<bool> has_geometry(model.links.size(), false);
  for (int s = 0; s < model.num_robot_segments; ++s) {
    const Segment& seg = model.segments[static_cast<std::size_t>(s)];
    for (int p = seg.first_primitive; p < seg.first_primitive + seg.num_primitives; ++p)
      has_geometry[static_cast<std::size_t>(linkOf(seg, model.primitives[static_cast<std::size_t>(p)]))] = true;
  }
  for (const std::string& name : hand_links) {
    const int hand = model.linkIndex(name);
    if (hand < 0) continue;
    // below[l]: l is below the hand with no driven joint on the way (links come parents first).
    std::vector<bool> below(model.links.size(), false);
    below[static_cast<std::size_t>(hand)] = true;
    std::vector<std::string> members;
    for (std::size_t l = static_cast<std::size_t>(hand) + 1; l < model.links.size(); ++l) {
      const Link& link = model.links[l];
      if (link.parent < 0 || !below[static_cast<std::size_t>(link.parent)]) continue;
      const bool driven =
          link.q_index >= 0 && std::find(driven_joints.begin(), driven_joints.end(),
                                         model.q_names[static_cast<std::size_t>(link.q_index)]) != driven_joints.end();
      if (driven) continue;
      below[l] = true;
      if (has_geometry[l]) members.push_back(link.name);
    }
    if (!members.empty()) out.emplace_back(name, members);
  }
  return out;
}

Eigen::VectorXd neutralConfiguration(const Model& model) {
  Eigen::VectorXd q(model.nq);
  for (int i = 0; i < model.nq; ++i) q[i] = std::min(std::max(0.0, model.q_lower[i]), model.q_upper[i]);
  return q;
}

namespace {

/// The arms from --left-hand and --right-hand: the revolute chains up to their branching links.
std::array<Chain, 2> givenArms(const Model& m, const Tree& t, const KinematicsData& kin, const SetupOptions& o,
                               RobotSetup& setup) {
  std::array<Chain, 2> arms;
  if (o.left_hand.empty() || o.right_hand.empty())
    throw SetupError(
        "give both --left-hand and --right-hand (got only " +
        std::string(o.left_hand.empty() ? "--right-hand '" + o.right_hand : "--left-hand '" + o.left_hand) + "')");
  const std::string given[2] = {o.left_hand, o.right_hand};
  for (int a = 0; a < 2; ++a) {
    const int hand = linkOrThrow(m, given[a], a == 0 ? "--left-hand" : "--right-hand");
    arms[a] = chainToHand(m, t, kin, hand);
    int revolute = 0;
    for (int qi : arms[a].joints) revolute += m.links[m.q_link[qi]].type == JointType::kRevolute;
    if (revolute < 1 || arms[a].prismatic)
      throw SetupError(std::string(a == 0 ? "--left-hand" : "--right-hand") + " '" + given[a] +
                       "': no chain of revolute joints leads to it from a branching link (found " +
                       arms[a].describe(m) + ")");
    if (static_cast<int>(arms[a].joints.size()) > 8)
      throw SetupError(std::string(a == 0 ? "--left-hand" : "--right-hand") + " '" + given[a] + "': its chain " +
                       arms[a].describe(m) + " has " + std::to_string(arms[a].joints.size()) +
                       " joints; the controller takes at most 8");
    arms[a].links.erase(std::find(arms[a].links.begin(), arms[a].links.end(), hand) + 1, arms[a].links.end());
  }
  setup.decisions.push_back("arms: the revolute joints from the given hand links up to their branching links '" +
                            m.links[arms[0].branch].name + "' / '" + m.links[arms[1].branch].name + "': left " +
                            arms[0].describe(m) + ", right " + arms[1].describe(m) + " (--left-hand, --right-hand)");
  return arms;
}

/// The arms found by structure: the mirrored pair of chains of >= 4 revolute joints that are not legs
/// (highest first, then by name); left and right by the side of the root frame the names agree with.
std::array<Chain, 2> foundArms(const Model& m, const Tree& t, const KinematicsData& kin, RobotSetup& setup) {
  std::array<Chain, 2> arms;
  const std::vector<Chain> chains = allChains(m, t, kin);
  std::vector<const Chain*> cands;
  for (const Chain& c : chains)
    if (c.joints.size() >= 4 && !c.prismatic) cands.push_back(&c);
  std::vector<std::array<const Chain*, 2>> pairs;  // [left, right]
  for (std::size_t i = 0; i < cands.size(); ++i)
    for (std::size_t j = i + 1; j < cands.size(); ++j)
      if (mirrored(*cands[i], *cands[j])) {
        const bool i_left = cands[i]->start_B.y() > 0;
        pairs.push_back({i_left ? cands[i] : cands[j], i_left ? cands[j] : cands[i]});
      }
  if (pairs.empty()) {
    std::string found;
    for (const Chain& c : chains)
      found += " " + c.describe(m) + " (" + std::to_string(c.joints.size()) + " joints" +
               (c.prismatic ? ", prismatic" : "") + ", from '" + m.links[c.branch].name + "' at y " +
               fmt("%.3f", c.start_B.y()) + ")";
    throw SetupError("no arms found in robot '" + m.name +
                     "': need two mirrored serial chains of >= 4 revolute joints branching from the trunk "
                     "(first joints at (x, y, z) and (x, -y, z)); chains found:" +
                     (found.empty() ? std::string(" none") : found) + "; give --left-hand and --right-hand");
  }
  // Arms end in hands, not feet: a pair whose names read like legs (hip/leg/knee/ankle/foot over
  // shoulder/arm/elbow/wrist/hand), or whose ends reach down to the robot's lowest link, is legs (a
  // locomotion variant with its arm joints fixed has only those).
  // "Reach down to the lowest link" counts only with a body above the chains (at least half their
  // drop): a trunk with chains hanging from it and nothing else is no standing robot.
  double lowest = std::numeric_limits<double>::infinity(), highest = -lowest;
  for (std::size_t l = 0; l < m.links.size(); ++l) {
    lowest = std::min(lowest, kin.X_B_L[l].translation().z());
    highest = std::max(highest, kin.X_B_L[l].translation().z());
  }
  std::vector<std::array<const Chain*, 2>> legs;
  for (auto it = pairs.begin(); it != pairs.end();) {
    const double end_z = std::min(kin.X_B_L[(*it)[0]->links.back()].translation().z(),
                                  kin.X_B_L[(*it)[1]->links.back()].translation().z());
    const double start_z = (*it)[0]->start_B.z();
    const bool to_the_ground = end_z < lowest + 0.05 && highest - start_z > 0.5 * (start_z - end_z);
    if (nameScore(m, *(*it)[0]) + nameScore(m, *(*it)[1]) < 0 || to_the_ground) {
      legs.push_back(*it);
      it = pairs.erase(it);
    } else {
      ++it;
    }
  }
  if (pairs.empty()) {
    std::string list;
    for (const auto& p : legs)
      list += " " + p[0]->describe(m) + " / " + p[1]->describe(m) + " (ending at z " +
              fmt("%.3f", kin.X_B_L[p[0]->links.back()].translation().z()) + " m; the lowest link is at " +
              fmt("%.3f", lowest) + " m);";
    throw SetupError("no arms found in robot '" + m.name +
                     "': the only mirrored chains of >= 4 revolute joints are "
                     "legs (named like legs, or ending at the robot's lowest link):" +
                     list +
                     " arms need movable joints and end in hands; give --left-hand and --right-hand if these are arms");
  }
  if (!legs.empty())
    setup.decisions.push_back("arms: " + std::to_string(legs.size()) +
                              " mirrored pair(s) of chains left out as legs "
                              "(named like legs, or ending at the robot's lowest link), e.g. " +
                              legs[0][0]->describe(m));
  std::sort(pairs.begin(), pairs.end(),
            [](const auto& a, const auto& b) { return a[0]->start_B.z() > b[0]->start_B.z(); });
  std::size_t pick = 0;
  std::string why;
  if (pairs.size() == 1) {
    why = "the only mirrored pair of chains with >= 4 revolute joints";
  } else if (pairs[0][0]->start_B.z() > pairs[1][0]->start_B.z() + 0.05) {
    why = "of " + std::to_string(pairs.size()) + " mirrored pairs the one starting highest (z " +
          fmt("%.3f", pairs[0][0]->start_B.z()) + " m, next " + fmt("%.3f", pairs[1][0]->start_B.z()) +
          " m: legs hang below the arms)";
  } else {
    std::vector<int> score;
    for (const auto& p : pairs) score.push_back(nameScore(m, *p[0]) + nameScore(m, *p[1]));
    const auto best = std::max_element(score.begin(), score.end());
    if (std::count(score.begin(), score.end(), *best) == 1 && *best > 0) {
      pick = static_cast<std::size_t>(best - score.begin());
      why = "of " + std::to_string(pairs.size()) +
            " mirrored pairs starting at the same height, the one whose "
            "names read like an arm (shoulder/arm/elbow/wrist/hand)";
    } else {
      std::string list;
      for (const auto& p : pairs)
        list += " " + p[0]->describe(m) + " / " + p[1]->describe(m) + " (z " + fmt("%.3f", p[0]->start_B.z()) + ");";
      throw SetupError("ambiguous arms in robot '" + m.name + "': " + std::to_string(pairs.size()) +
                       " mirrored pairs of chains start within 5 cm of the same height and their names do not "
                       "tell which are arms:" +
                       list + " give --left-hand and --right-hand");
    }
  }
  arms[0] = *pairs[pick][0];
  arms[1] = *pairs[pick][1];
  // REP 103 (x forward, y left) unless both arms' names say the opposite: a root frame that faces -x
  // (iCub's: x backward, y right) names its y < 0 arm left.
  std::string side_why = "left = y > 0 (" + fmt("%.3f", arms[0].start_B.y()) + " m)";
  if (sideHint(m, arms[0]) < 0 && sideHint(m, arms[1]) > 0) {
    std::swap(arms[0], arms[1]);
    setup.forward = -Eigen::Vector3d::UnitX();
    side_why = "the arm named left is at y " + fmt("%.3f", arms[0].start_B.y()) +
               " m: this URDF's root frame faces -x (x backward, y right), so forward is -x for the rest "
               "posture and the behavior's targets";
  }
  setup.decisions.push_back("arms: left " + arms[0].describe(m) + ", right " + arms[1].describe(m) + " from '" +
                            m.links[arms[0].branch].name + "': " + why + "; " + side_why);
  for (int a = 0; a < 2; ++a) {
    if (static_cast<int>(arms[a].joints.size()) > 8)
      throw SetupError("arm " + arms[a].describe(m) + " has " + std::to_string(arms[a].joints.size()) +
                       " joints; the controller takes at most 8: give --left-hand and --right-hand");
  }
  return arms;
}

/// Head: the highest chain end with geometry below the arms' branching link (and its ancestors) that
/// is not an arm; a name with "head" wins. Camera: "camera" in a name rigidly below the head.
void findHeadAndCamera(const Model& m, const Tree& t, const KinematicsData& kin, const SetupOptions& o,
                       const std::array<Chain, 2>& arms, RobotSetup& setup) {
  int head = -1;
  std::string head_why;
  if (!o.head.empty()) {
    head = linkOrThrow(m, o.head, "--head");
    head_why = "(--head)";
  } else {
    std::vector<int> ends;
    for (const Chain& c : allChains(m, t, kin)) {
      if (c.first_link == arms[0].first_link || c.first_link == arms[1].first_link) continue;
      const int e = handOfChain(m, t, c);
      if (t.segment_of[e] >= 0 && c.joints.size() <= 3) ends.push_back(e);
    }
    for (int e : ends)
      if (lower(m.links[e].name).find("head") != std::string::npos && head < 0) {
        head = e;
        head_why = "the end of a chain of at most 3 joints, named like a head";
      }
    if (head < 0) {
      for (int e : ends)
        if (head < 0 || kin.X_B_L[e].translation().z() > kin.X_B_L[head].translation().z()) head = e;
      head_why = "the highest end of a chain of at most 3 joints that is not an arm";
    }
    if (head < 0) {  // a robot without a head (an upper body, a two-arm manipulator): the arms' trunk
      head = arms[0].branch;
      head_why =
          "NO HEAD: no chain of 1 to 3 joints other than the arms ends in a link with collision geometry, so "
          "the arms' branching link stands in for the head (and the head camera, unless --camera); give "
          "--head and --camera for a camera elsewhere";
    }
  }
  setup.head_link = m.links[head].name;
  setup.decisions.push_back("head: link '" + setup.head_link + "', " + head_why);
  if (!o.camera.empty()) {
    setup.camera_link = m.links[linkOrThrow(m, o.camera, "--camera")].name;
    setup.decisions.push_back("camera: link '" + setup.camera_link + "' (--camera)");
  } else {
    std::vector<int> stack = {head};
    while (!stack.empty() && setup.camera_link.empty()) {
      const int l = stack.front();
      stack.erase(stack.begin());
      if (lower(m.links[l].name).find("camera") != std::string::npos) setup.camera_link = m.links[l].name;
      for (int ch : t.children[l])
        if (m.links[ch].q_index < 0) stack.push_back(ch);
    }
    if (setup.camera_link.empty()) {
      setup.camera_link = setup.head_link;
      setup.decisions.push_back("camera: the head link '" + setup.head_link +
                                "' (no link named like a camera is fixed below it; give --camera)");
    } else {
      setup.decisions.push_back("camera: link '" + setup.camera_link +
                                "', the first link named like a camera fixed below the head");
    }
  }
}

}  // namespace

RobotSetup findRobotStructure(const Model& m, const SetupOptions& o) {
  RobotSetup setup;
  const Tree t(m);
  KinematicsData kin(m);
  computeForwardKinematics(m, kin, neutralConfiguration(m));
  std::array<Chain, 2> arms;
  if (!o.left_hand.empty() || !o.right_hand.empty())
    arms = givenArms(m, t, kin, o, setup);
  else
    arms = foundArms(m, t, kin, setup);
  for (int a = 0; a < 2; ++a) {
    ArmSetup& arm = setup.arms[a];
    const Chain& c = arms[a];
    arm.side = a == 0 ? "left" : "right";
    for (int qi : c.joints) arm.joints.push_back(m.q_names[qi]);
    arm.shoulder_link = m.links[c.first_link].name;
    const int hand = (a == 0 ? o.left_hand : o.right_hand).empty() ? handOfChain(m, t, c)
                                                                   : m.linkIndex(a == 0 ? o.left_hand : o.right_hand);
    arm.hand_link = m.links[hand].name;
    bool geometry = false;
    arm.hand_point_L = handPoint(m, t, hand, &geometry);
    setup.decisions.push_back(
        arm.side + " hand: link '" + arm.hand_link + "' (" +
        (hand == c.links.back() ? "the last link of the chain" : "the link with geometry at the chain's end") +
        "); hand point " + vec(arm.hand_point_L) + " m in it: " +
        (geometry ? "the farthest end of its collision geometry's core from the wrist"
                  : "its origin (the link has no collision geometry)"));
  }
  findHeadAndCamera(m, t, kin, o, arms, setup);
  return setup;
}

namespace {

struct ArmIndex {
  std::array<std::vector<int>, 2> q;  // q indices per arm
  std::vector<double> mirror;         // per left joint: right = mirror * left (0: not mirrored)
};

ArmIndex armIndex(const Model& m, const RobotSetup& s) {
  ArmIndex ix;
  for (int a = 0; a < 2; ++a)
    for (const std::string& j : s.arms[a].joints) ix.q[a].push_back(m.qIndex(j));
  KinematicsData kin(m);
  computeForwardKinematics(m, kin, neutralConfiguration(m));
  // URDFs round their angles (3.14159, 1.5708: a few micro-radians off, compounding along the chain), so
  // two axes are taken as mirror images within 2 mrad; an axis that is not is tenths of a radian off.
  constexpr double kMirrorAxisTolerance = 2e-3;
  for (std::size_t i = 0; i < ix.q[0].size(); ++i) {
    double sign = 0.0;
    if (i < ix.q[1].size()) {
      // A rotation about axis u mirrored through the x-z plane is a rotation by -angle about M u.
      Eigen::Vector3d mu = kin.axis_B[m.q_link[ix.q[0][i]]];
      mu.y() = -mu.y();
      const Eigen::Vector3d ur = kin.axis_B[m.q_link[ix.q[1][i]]];
      if ((ur - mu).norm() < kMirrorAxisTolerance)
        sign = -1.0;
      else if ((ur + mu).norm() < kMirrorAxisTolerance)
        sign = 1.0;
    }
    ix.mirror.push_back(sign);
  }
  return ix;
}

double lo80(const Model& m, int qi) {
  const double lo = std::isfinite(m.q_lower[qi]) ? m.q_lower[qi] : -M_PI;
  const double hi = std::isfinite(m.q_upper[qi]) ? m.q_upper[qi] : M_PI;
  return lo + 0.1 * (hi - lo);
}
double hi80(const Model& m, int qi) {
  const double lo = std::isfinite(m.q_lower[qi]) ? m.q_lower[qi] : -M_PI;
  const double hi = std::isfinite(m.q_upper[qi]) ? m.q_upper[qi] : M_PI;
  return hi - 0.1 * (hi - lo);
}

}  // namespace

namespace {

/// The rest posture search of findRestPosture: one object, its steps the methods.
class RestSearch {
 public:
  RestSearch(const Model& model, const SetupOptions& options, RobotSetup& setup)
      : m(model),
        o(options),
        s(setup),
        ix(armIndex(m, s)),
        q0(neutralConfiguration(m)),
        kin(m),
        dist(m),
        q(m.nq),
        required(m.pairs.size(), o.d_a + o.rest_margin) {
    dopt.row_threshold = -std::numeric_limits<double>::infinity();
    // Exact up to 0.1 m (above every requirement, d_a + margin); farther pairs get a lower bound.
    dopt.prune_distance = std::max(0.1, o.d_a + o.rest_margin + 0.01);
    computeForwardKinematics(m, kin, q0);
    for (int a = 0; a < 2; ++a) {
      hand[a] = m.linkIndex(s.arms[a].hand_link);
      shoulder[a] = m.q_link[ix.q[a][0]];
      S[a] = kin.X_B_L[shoulder[a]].translation();
    }
    {  // arm length: shoulder to hand point with every arm joint at 0 (stretched, as RobotState measures it)
      Eigen::VectorXd qz = q0;
      for (int a = 0; a < 2; ++a)
        for (int qi : ix.q[a]) qz[qi] = std::min(std::max(0.0, m.q_lower[qi]), m.q_upper[qi]);
      computeForwardKinematics(m, kin, qz);
      reach = (kin.X_B_L[hand[0]] * s.arms[0].hand_point_L - S[0]).norm();
    }
    // Hand below and in front of the shoulder, slightly out: elbow bent, arm not touching the body.
    fwd = s.forward;
    lft = Eigen::Vector3d::UnitZ().cross(s.forward);
    for (int a = 0; a < 2; ++a)
      goal[a] = S[a] + reach * (0.35 * fwd + (a == 0 ? 0.2 : -0.2) * lft - 0.7 * Eigen::Vector3d::UnitZ());
    // Only pairs with an arm segment: the rest posture cannot change the others (legs, head, trunk).
    std::vector<bool> moved(m.links.size(), false);
    for (int a = 0; a < 2; ++a) moved[m.q_link[ix.q[a][0]]] = true;
    for (std::size_t l = 0; l < m.links.size(); ++l)
      if (m.links[l].parent >= 0 && moved[m.links[l].parent]) moved[l] = true;
    arm_pair.assign(m.pairs.size(), false);
    for (std::size_t i = 0; i < m.pairs.size(); ++i)
      arm_pair[i] = !m.segments[m.pairs[i].b].body_schema_slot &&
                    (moved[m.segments[m.pairs[i].a].link] || moved[m.segments[m.pairs[i].b].link]);
  }

  void run() {
    setRequirements();
    search();
    // No sample clears every pair: the clearest one climbs (a crowded shoulder leaves a narrow region
    // that random postures rarely hit, mirrored arms in 7 joints even less). Clear now, it is the start
    // of the refinement; else the requirements are scaled to what it keeps.
    if (!best.clear && closest.ratio > 0.0) {
      climbClearest();
      if (closest.clear) {
        best = closest;
        best_l = closest_l;
        best_r = closest_r;
      }
    }
    if (!best.clear && closest.ratio > 0.0) {
      const std::vector<double> climbed_l = closest_l, climbed_r = closest_r;
      const double floor = latch_floor + 0.004;
      const double first_ratio = closest.ratio;
      const double scale = 0.95 * first_ratio;
      int lowered = 0;
      for (std::size_t i = 0; i < required.size(); ++i) {
        if (!arm_pair[i]) continue;
        const double r_new = std::max(scale * required[i], std::min(required[i], floor));
        if (r_new < required[i]) ++lowered;
        required[i] = r_new;
      }
      search();
      if (!best.clear) {  // the climbed posture keeps more than the scaled requirements
        const Eval e = evaluate(climbed_l, climbed_r);
        if (e.clear) {
          best = e;
          best_l = climbed_l;
          best_r = climbed_r;
        }
      }
      if (best.clear)
        s.decisions.push_back(
            "rest: WARNING: no posture clears every arm pair by d_a + margin (or 90 % of its reach); "
            "the clearest keeps " +
            fmt("%.0f", 100.0 * first_ratio) + " % of it: " + std::to_string(lowered) + " requirements scaled to " +
            fmt("%.0f", 100.0 * scale) + " % (never below " + fmt("%.3f", floor) +
            " m): avoidance acts at rest on the pairs "
            "listed below d_a");
    }
    if (!best.clear) throwNoPosture();
    refine();
    describe();
  }

 private:
  struct Eval {
    bool clear = false;
    double cost = std::numeric_limits<double>::infinity();
    double dmin = -std::numeric_limits<double>::infinity();
    double ratio = -std::numeric_limits<double>::infinity();  // smallest distance / requirement
    int pair = -1;
  };

  void place(const std::vector<double>& left, const std::vector<double>& right, Eigen::VectorXd& q) const {
    q = q0;
    for (std::size_t i = 0; i < ix.q[0].size(); ++i) q[ix.q[0][i]] = left[i];
    for (std::size_t i = 0; i < ix.q[1].size(); ++i) q[ix.q[1][i]] = right[i];
  }

  std::vector<double> mirrorOf(const std::vector<double>& left, const std::vector<double>& right_free) const {
    std::vector<double> r = right_free;
    for (std::size_t i = 0; i < ix.q[1].size() && i < left.size(); ++i)
      if (ix.mirror[i] != 0.0) r[i] = std::clamp(ix.mirror[i] * left[i], lo80(m, ix.q[1][i]), hi80(m, ix.q[1][i]));
    return r;
  }

  // What each arm pair can reach: its distance range over random arm postures drawn as the search draws
  // them (the middle 80 % of the limits, the right arm mirrored). A pair the arms cannot move (a shoulder
  // sphere turning about its centre) is not asked to clear anything; a pair never farther apart than
  // d_a + margin there (a short arm's upper arm and hand, a shoulder link and the upper arm) is asked for
  // 90 % of its maximum.
  void setRequirements() {
    std::vector<double> lo_d(m.pairs.size(), std::numeric_limits<double>::infinity());
    std::vector<double> hi_d(m.pairs.size(), -std::numeric_limits<double>::infinity());
    std::mt19937_64 pre(o.seed + 5);
    std::vector<double> pl(ix.q[0].size()), pr(ix.q[1].size());
    for (int k = 0; k < std::max(200, o.rest_samples / 2); ++k) {
      for (std::size_t i = 0; i < pl.size(); ++i)
        pl[i] = std::uniform_real_distribution<double>(lo80(m, ix.q[0][i]), hi80(m, ix.q[0][i]))(pre);
      for (std::size_t i = 0; i < pr.size(); ++i)
        pr[i] = std::uniform_real_distribution<double>(lo80(m, ix.q[1][i]), hi80(m, ix.q[1][i]))(pre);
      place(pl, mirrorOf(pl, pr), q);
      computeForwardKinematics(m, kin, q);
      computeSegmentDistances(m, kin, dist, dopt);
      for (std::size_t i = 0; i < m.pairs.size(); ++i) {
        if (!arm_pair[i]) continue;
        lo_d[i] = std::min(lo_d[i], dist.pairs[i].distance);
        hi_d[i] = std::max(hi_d[i], dist.pairs[i].distance);
      }
    }
    int fixed_pairs = 0;
    std::string fixed_example;
    for (std::size_t i = 0; i < m.pairs.size(); ++i) {
      if (!arm_pair[i]) continue;
      const std::string name = "'" + m.segments[m.pairs[i].a].name + "'-'" + m.segments[m.pairs[i].b].name + "'";
      if (hi_d[i] - lo_d[i] < 1e-6) {
        arm_pair[i] = false;
        ++fixed_pairs;
        if (fixed_example.empty()) fixed_example = name + " " + fmt("%.3f", hi_d[i]) + " m";
      } else if (hi_d[i] < required[i]) {
        // Never below the e-stop's release (+ 1 mm): resting there would latch the red zone.
        required[i] = std::max(0.9 * hi_d[i], std::min(required[i], latch_floor));
        s.decisions.push_back(
            "rest: pair " + name + " is never farther apart than " + fmt("%.3f", hi_d[i]) +
            " m (sampled in the rest search's range): rest keeps it at >= " + fmt("%.3f", required[i]) +
            " m, inside the avoidance zone d_a " + fmt("%.3f", o.d_a) + " m");
      }
    }
    if (fixed_pairs > 0)
      s.decisions.push_back("rest: " + std::to_string(fixed_pairs) +
                            " arm pairs keep their distance whatever the arm "
                            "joints do (e.g. " +
                            fixed_example +
                            ": a shoulder sphere turning about its centre): "
                            "not part of the rest search");
  }

  Eval evaluate(const std::vector<double>& left, const std::vector<double>& right) {
    Eval e;
    place(left, right, q);
    computeForwardKinematics(m, kin, q);
    computeSegmentDistances(m, kin, dist, dopt);
    e.dmin = std::numeric_limits<double>::infinity();  // the smallest clearance beyond what is required
    e.ratio = std::numeric_limits<double>::infinity();
    e.clear = true;
    for (std::size_t i = 0; i < dist.pairs.size(); ++i) {
      if (!dist.pairs[i].active || !arm_pair[i]) continue;
      if (dist.pairs[i].distance <= required[i]) e.clear = false;
      e.ratio = std::min(e.ratio, dist.pairs[i].distance / required[i]);
      if (dist.pairs[i].distance - required[i] < e.dmin) {
        e.dmin = dist.pairs[i].distance - required[i];
        e.pair = static_cast<int>(i);
      }
    }
    double c = 0.0;
    for (int a = 0; a < 2; ++a) c += (kin.X_B_L[hand[a]] * s.arms[a].hand_point_L - goal[a]).norm() / reach;
    double centre = 0.0;
    for (int a = 0; a < 2; ++a)
      for (int qi : ix.q[a]) {
        const double mid = 0.5 * (lo80(m, qi) + hi80(m, qi));
        const double half = 0.5 * (hi80(m, qi) - lo80(m, qi)) + 1e-9;
        centre += std::abs((q[qi] - mid) / half);
      }
    e.cost = c + 0.05 * centre / static_cast<double>(ix.q[0].size() + ix.q[1].size());
    return e;
  }

  void search() {
    std::mt19937_64 rng(o.seed);
    best = Eval{};
    closest = Eval{};
    for (int k = 0; k < o.rest_samples; ++k) {
      for (std::size_t i = 0; i < l.size(); ++i)
        l[i] = std::uniform_real_distribution<double>(lo80(m, ix.q[0][i]), hi80(m, ix.q[0][i]))(rng);
      for (std::size_t i = 0; i < r.size(); ++i)
        r[i] = std::uniform_real_distribution<double>(lo80(m, ix.q[1][i]), hi80(m, ix.q[1][i]))(rng);
      r = mirrorOf(l, r);
      const Eval e = evaluate(l, r);
      if (e.ratio > closest.ratio) {
        closest = e;
        closest_l = l;
        closest_r = r;
      }
      if (e.clear && e.cost < best.cost) {
        best = e;
        best_l = l;
        best_r = r;
      }
    }
  }

  /// Every pair short of what it must keep in the clearest posture, named.
  [[noreturn]] void throwNoPosture() {
    // Every pair short of what it must keep in the clearest posture.
    place(closest_l, closest_r, q);
    computeForwardKinematics(m, kin, q);
    computeSegmentDistances(m, kin, dist, dopt);
    std::string short_pairs;
    int n_short = 0;
    for (std::size_t i = 0; i < dist.pairs.size(); ++i) {
      if (!dist.pairs[i].active || !arm_pair[i] || dist.pairs[i].distance > required[i]) continue;
      ++n_short;
      short_pairs += std::string(short_pairs.empty() ? "" : ", ") + "'" + m.segments[m.pairs[i].a].name + "'-'" +
                     m.segments[m.pairs[i].b].name + "' " + fmt("%.1f", 1e3 * dist.pairs[i].distance) +
                     " mm (needs > " + fmt("%.1f", 1e3 * required[i]) + ")";
    }
    throw SetupError("no rest posture found for robot '" + m.name + "': of " + std::to_string(o.rest_samples) +
                     " postures within the middle 80 % of the arm joints' limits none keeps every checked pair of an "
                     "arm segment clear (d_a + margin, 90 % of what the pair reaches there, at least d_r + "
                     "estop_release_margin + 1 mm); the clearest leaves " +
                     std::to_string(n_short) + " short: " + short_pairs +
                     ": exclude the pairs that cannot collide (collision YAML exclude:), or lower d_r");
  }

  /// Coordinate steps from the posture (pl, pr) with evaluation pe: each left joint by +-step (the right
  /// one mirrored), then the unmirrored right joints, steps of 0.2 down to 0.01 rad, a step taken when
  /// better(its Eval, pe); until no step is taken or done(pe).
  template <class Better, class Done>
  void coordinateSteps(std::vector<double>& pl, std::vector<double>& pr, Eval& pe, Better better, Done done) {
    for (double step : {0.2, 0.1, 0.05, 0.02, 0.01}) {
      bool improved = true;
      while (improved && !done(pe)) {
        improved = false;
        for (int a = 0; a < 2; ++a)
          for (std::size_t i = 0; i < ix.q[a].size(); ++i) {
            if (a == 1 && i < ix.mirror.size() && ix.mirror[i] != 0.0) continue;
            for (double d : {step, -step}) {
              std::vector<double> tl = pl, tr = pr;
              std::vector<double>& v = a == 0 ? tl : tr;
              v[i] = std::clamp(v[i] + d, lo80(m, ix.q[a][i]), hi80(m, ix.q[a][i]));
              if (a == 0) tr = mirrorOf(tl, tr);
              const Eval e = evaluate(tl, tr);
              if (better(e, pe)) {
                pe = e;
                pl = tl;
                pr = tr;
                improved = true;
              }
            }
          }
      }
    }
  }

  /// Coordinate ascent of the clearest posture's smallest distance / requirement, until it clears.
  void climbClearest() {
    coordinateSteps(
        closest_l, closest_r, closest, [](const Eval& e, const Eval& now) { return e.ratio > now.ratio + 1e-9; },
        [](const Eval& now) { return now.clear; });
  }

  /// Coordinate descent of the best posture's cost, every pair kept clear.
  void refine() {
    coordinateSteps(
        best_l, best_r, best, [](const Eval& e, const Eval& now) { return e.clear && e.cost < now.cost - 1e-9; },
        [](const Eval&) { return false; });
  }

  void describe() {
    s.arms[0].rest = best_l;
    s.arms[1].rest = best_r;
    const Eval e = evaluate(best_l, best_r);
    const SegmentPair& p = m.pairs[e.pair];
    s.rest_distance = e.dmin + required[e.pair];
    s.rest_pair = m.segments[p.a].name + "-" + m.segments[p.b].name;
    Eigen::Vector3d h = kin.X_B_L[hand[0]] * s.arms[0].hand_point_L - S[0];
    std::ostringstream os;
    os << "rest: left hand " << fmt("%.2f", h.dot(fwd)) << " m in front of, " << fmt("%.2f", h.dot(lft))
       << " m beside and " << fmt("%.2f", -h.z()) << " m below the shoulder (arm reach " << fmt("%.2f", reach)
       << " m): the posture nearest to 'hand below and in front of the shoulder, arm slightly out' of "
       << o.rest_samples
       << " random ones in the middle 80 % of the limits (then refined) with every checked pair of an arm above d_a + "
       << fmt("%.3f", o.rest_margin) << " m; at rest the pair with the least margin over what it must keep is '"
       << m.segments[p.a].name << "'-'" << m.segments[p.b].name << "', " << fmt("%.3f", s.rest_distance)
       << " m apart; right arm mirrored";
    std::string own;  // right joints whose axis is no mirror image of the left one's: searched on their own
    for (std::size_t i = 0; i < ix.q[1].size(); ++i)
      if (i >= ix.mirror.size() || ix.mirror[i] == 0.0) own += (own.empty() ? "" : ", ") + s.arms[1].joints[i];
    if (!own.empty())
      os << " except " << own
         << " (at the zero posture their axes are no mirror images of the left ones': each chosen on its own)";
    s.decisions.push_back(os.str());
  }

  const Model& m;
  const SetupOptions& o;
  RobotSetup& s;
  const ArmIndex ix;
  const Eigen::VectorXd q0;
  KinematicsData kin;
  DistanceData dist;
  DistanceOptions dopt;
  std::array<int, 2> hand{}, shoulder{};
  std::array<Eigen::Vector3d, 2> S, goal;
  double reach = 0.0;
  Eigen::Vector3d fwd, lft;
  std::vector<bool> arm_pair;
  Eigen::VectorXd q;
  std::vector<double> required;
  const double latch_floor = ControllerParams{}.d_r + ControllerParams{}.estop_release_margin + 0.001;
  std::vector<double> best_l, best_r, l = std::vector<double>(ix.q[0].size()), r = std::vector<double>(ix.q[1].size());
  Eval best;
  Eval closest;  // the clearest posture, for the error message
  std::vector<double> closest_l, closest_r;
};

}  // namespace

void findRestPosture(const Model& m, const SetupOptions& o, RobotSetup& s) { RestSearch(m, o, s).run(); }

namespace {

// The primitives of `link`'s rigid body in the link frame (one set); if that body has none, those of
// the nearest body above it (not above the arm's first link) with primitives, one set per combination of
// the joints in between at {lower, middle, upper} of the middle 80 % of their ranges.
std::vector<std::vector<Primitive>> bodyPrimitivesInLink(const Model& m, const Tree& t, int link, int arm_first) {
  auto bodyOf = [&](int l) {
    while (m.links[l].parent >= 0 && m.links[l].q_index < 0) l = m.links[l].parent;
    return l;
  };
  auto collect = [&](int body) {  // body's primitives in the body frame
    std::vector<Primitive> prims;
    std::vector<std::pair<int, Eigen::Isometry3d>> stack = {{body, Eigen::Isometry3d::Identity()}};
    while (!stack.empty()) {
      const auto [l, X_body_l] = stack.back();
      stack.pop_back();
      if (const int sg = t.segment_of[l]; sg >= 0) {
        const Segment& seg = m.segments[sg];
        for (int pi = seg.first_primitive; pi < seg.first_primitive + seg.num_primitives; ++pi) {
          if (linkOf(seg, m.primitives[pi]) != l) continue;  // on a link below, moved by its joint
          Primitive p = m.primitives[pi];
          p.a_L = X_body_l * p.a_L;
          p.b_L = X_body_l * p.b_L;
          prims.push_back(p);
        }
      }
      for (int ch : t.children[l])
        if (m.links[ch].q_index < 0) stack.push_back({ch, X_body_l * m.links[ch].X_P_J});
    }
    return prims;
  };
  int body = bodyOf(link);
  std::vector<int> between;  // links whose joints lie between the geometric body and `link`
  std::vector<Primitive> prims = collect(body);
  while (prims.empty() && body != arm_first && m.links[body].parent >= 0) {
    between.push_back(body);
    body = bodyOf(m.links[body].parent);
    prims = collect(body);
  }
  // X_body_link for one combination of the joint values.
  const int combos = static_cast<int>(std::pow(3.0, static_cast<double>(between.size())));
  std::vector<std::vector<Primitive>> sets;
  for (int c = 0; c < combos; ++c) {
    std::vector<double> value(m.links.size(), 0.0);
    int code = c;
    for (int l : between) {
      const int qi = m.links[l].q_index;
      const double lo = std::isfinite(m.q_lower[qi]) ? m.q_lower[qi] : -M_PI;
      const double hi = std::isfinite(m.q_upper[qi]) ? m.q_upper[qi] : M_PI;
      value[l] = lo + (0.1 + 0.4 * (code % 3)) * (hi - lo);
      code /= 3;
    }
    Eigen::Isometry3d X_body_link = Eigen::Isometry3d::Identity();
    for (int l = link; l != body; l = m.links[l].parent) {
      Eigen::Isometry3d X_J = Eigen::Isometry3d::Identity();
      if (m.links[l].q_index >= 0 && m.links[l].type == JointType::kRevolute)
        X_J.linear() = Eigen::AngleAxisd(value[l], m.links[l].axis_J).toRotationMatrix();
      else if (m.links[l].q_index >= 0)
        X_J.translation() = value[l] * m.links[l].axis_J;
      X_body_link = m.links[l].X_P_J * X_J * X_body_link;
    }
    std::vector<Primitive> in_link = prims;
    for (Primitive& p : in_link) {
      p.a_L = X_body_link.inverse() * p.a_L;
      p.b_L = X_body_link.inverse() * p.b_L;
    }
    sets.push_back(in_link);
  }
  return sets;
}

}  // namespace

ReachCheck checkReach(const Model& model, const ControllerModel& cm, const std::array<Eigen::Vector3d, 2>& target_B,
                      double duration, double tolerance) {
  ReachCheck r;
  r.target_B = target_B;
  Eigen::VectorXd q0 = neutralConfiguration(model);
  for (const auto& arm : cm.arms)
    for (int i = 0; i < arm.n; ++i) q0[arm.q[i]] = arm.rest[i];
  KinematicPort port(q0);
  OnboardOptions options;
  options.input_timeout = duration + 1.0;
  OnboardController ctl(model, cm, port, q0, options);
  std::array<HandCommand, 2> hands;
  for (int a = 0; a < 2; ++a) hands[a] = {HandStatus::kGiven, target_B[a]};
  KinematicsData kin(model);
  r.min_distance = std::numeric_limits<double>::infinity();
  const double dt = cm.params.period;
  const int cycles = static_cast<int>(std::ceil(duration / dt));
  for (int k = 0; k <= cycles; ++k) {
    const double now = k * dt;
    ctl.setHandTargets(hands, now);
    const CycleReport& rep = ctl.step(now);
    r.min_distance = std::min(r.min_distance, rep.min_distance);
    computeForwardKinematics(model, kin, port.positions());
    for (int a = 0; a < 2; ++a)
      r.error[a] = (kin.X_B_L[cm.arms[a].hand_link] * cm.arms[a].hand_point_L - target_B[a]).norm();
    if (r.reached_at < 0 && r.error[0] < tolerance && r.error[1] < tolerance) r.reached_at = now;
  }
  r.estops = ctl.report().counts.estop_count;
  return r;
}

std::string collisionElementForCapsule(const Primitive& c, const std::string& name) {
  const Eigen::Vector3d mid = 0.5 * (c.a_L + c.b_L);
  const Eigen::Vector3d d = c.b_L - c.a_L;
  const double len = d.norm();
  // The cylinder's axis is the origin's z: rotate z onto d by pitch then yaw (rpy = (0, pitch, yaw)).
  const double yaw = len > 0 ? std::atan2(d.y(), d.x()) : 0.0;
  const double pitch = len > 0 ? std::atan2(std::hypot(d.x(), d.y()), d.z()) : 0.0;
  char buf[400];
  if (len < 1e-9) {
    std::snprintf(buf, sizeof buf,
                  "<collision name=\"%s\"><origin xyz=\"%.4f %.4f %.4f\" rpy=\"0 0 0\"/>"
                  "<geometry><sphere radius=\"%.4f\"/></geometry></collision>",
                  name.c_str(), mid.x(), mid.y(), mid.z(), c.radius);
  } else {
    std::snprintf(buf, sizeof buf,
                  "<collision name=\"%s\"><origin xyz=\"%.4f %.4f %.4f\" rpy=\"0 %.6f %.6f\"/>"
                  "<geometry><cylinder radius=\"%.4f\" length=\"%.4f\"/></geometry></collision>",
                  name.c_str(), mid.x(), mid.y(), mid.z(), pitch, yaw, c.radius, len);
  }
  return buf;
}

int findArmGaps(const Model& m, const SetupOptions& o, RobotSetup& s) {
  s.gaps.clear();
  const Tree t(m);
  for (const ArmSetup& arm : s.arms) {
    const int hand = m.linkIndex(arm.hand_link);
    const int first = m.q_link[m.qIndex(arm.joints.front())];
    // The skeleton: the links from the first arm joint's link to the hand (each stretch runs from a
    // link's origin to its child's origin on the path), then the hand link's origin to the hand point.
    std::vector<int> path;
    for (int l = hand; l >= 0; l = m.links[l].parent) {
      path.push_back(l);
      if (l == first) break;
    }
    std::reverse(path.begin(), path.end());
    struct Stretch {
      int link;
      Eigen::Vector3d to_L;
    };
    std::vector<Stretch> stretches;
    for (std::size_t i = 0; i + 1 < path.size(); ++i)
      stretches.push_back({path[i], m.links[path[i + 1]].X_P_J.translation()});
    stretches.push_back({hand, arm.hand_point_L});
    for (std::size_t si = 0; si < stretches.size(); ++si) {
      const Stretch& st = stretches[si];
      const double len = st.to_L.norm();
      if (len < 1e-9 && si + 1 < stretches.size()) continue;
      // The primitives of the link's rigid body (the link and every link joined to it by fixed joints),
      // in the link frame: the stretch and they move together, so the gap is the same at every q. A body
      // without primitives (a bare link between two joints, e.g. an arm-yaw link) is checked against the
      // nearest body above it with primitives, with the joints in between at the ends and middle of
      // their ranges (every combination; the worst counts).
      std::vector<std::vector<Primitive>> prim_sets = bodyPrimitivesInLink(m, t, st.link, first);
      const int n = std::max(1, static_cast<int>(std::ceil(len / 0.005)));
      double worst = -std::numeric_limits<double>::infinity();
      Eigen::Vector3d worst_p = Eigen::Vector3d::Zero();
      int k_first = -1, k_last = -1;
      for (int k = 0; k <= n; ++k) {
        const Eigen::Vector3d p_L = (static_cast<double>(k) / n) * st.to_L;
        double d = -std::numeric_limits<double>::infinity();
        for (const auto& prims : prim_sets) {
          double dc = std::numeric_limits<double>::infinity();
          for (const Primitive& p : prims) dc = std::min(dc, signedDistanceToPrimitive(p, p_L));
          d = std::max(d, dc);
        }
        if (d > o.gap_tolerance) {
          if (k_first < 0) k_first = k;
          k_last = k;
        }
        if (d > worst) {
          worst = d;
          worst_p = p_L;
        }
      }
      if (k_first < 0) continue;
      ArmGap g;
      g.side = arm.side;
      g.link = m.links[st.link].name;
      g.gap = worst;
      g.point_L = worst_p;
      const Eigen::Vector3d p0 = (static_cast<double>(k_first) / n) * st.to_L;
      const Eigen::Vector3d p1 = (static_cast<double>(k_last) / n) * st.to_L;
      // From the nearest core end of the body's primitives (continuing it) to the last uncovered point.
      g.closing.a_L = p0;
      g.closing.radius = 0.0;
      double best_d = std::numeric_limits<double>::infinity();
      for (const Primitive& p : prim_sets.front())
        for (const Eigen::Vector3d& e : {p.a_L, p.b_L})
          if ((e - p0).norm() < best_d) {
            best_d = (e - p0).norm();
            g.closing.a_L = e;
            g.closing.radius = p.radius;
          }
      if (g.closing.radius <= 0.0) g.closing.radius = std::max(2.0 * o.gap_tolerance, 0.02);
      g.closing.b_L = p1;
      g.closing.sphere = (g.closing.b_L - g.closing.a_L).norm() < 1e-9;
      if (g.closing.sphere) g.closing.b_L = g.closing.a_L;
      std::ostringstream msg;
      msg << "warning: " << arm.side << " arm: link '" << g.link
          << "': " << (si + 1 == stretches.size() ? "the stretch to the hand point" : "the stretch between its joints")
          << " lies up to " << fmt("%.3f", worst) << " m outside every collision primitive of the link, at "
          << vec(worst_p) << " m in '" << g.link << "' (tolerance " << fmt("%.3f", o.gap_tolerance)
          << " m): a capsule from " << vec(g.closing.a_L) << " to " << vec(g.closing.b_L) << " m, radius "
          << fmt("%.3f", g.closing.radius) << " m, closes it";
      g.message = msg.str();
      g.urdf_snippet = collisionElementForCapsule(g.closing, g.link + "_gap");
      s.gaps.push_back(g);
    }
  }
  return static_cast<int>(s.gaps.size());
}

}  // namespace reflex::control
