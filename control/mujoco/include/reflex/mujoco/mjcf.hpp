// MJCF for MuJoCo 2.2 from the project's robot Model: the physics-simulated
// robot is built from the SAME Model the controller uses (control::loadModel on the same URDF and
// collision YAML), never from a second reading of the URDF.
//
// What the MJCF holds (control/README.md, "The physics robot: reflex_mujoco"):
//   - a body per link (the root link is MuJoCo's world body), placed by the link's joint origin;
//     a hinge (revolute) or slide (prismatic) joint per movable joint, with the URDF limits;
//   - mass and inertia: the URDF <inertial> when the Model carries one (Link::has_inertial; a mass
//     below `min_mass` or principal inertias below `min_inertia` or breaking A + B >= C repaired,
//     inertialRepairs says how); else
//     MuJoCo's own inertia of the link's collision geoms at `density`; a link with neither gets
//     `min_mass` / `min_inertia` (virtual links, camera frames);
//   - every collision primitive as a MuJoCo capsule (fromto = the Model's core a_L..b_L in the link
//     frame, size = radius) or sphere, and every convex piece of the tight model (Primitive::piece)
//     as a MuJoCo mesh of its hull vertices (a flat piece thickened by 0.1 mm to either side: MuJoCo
//     needs a volume), named "<segment>/<k>"; no geom collides by default
//     (contype = conaffinity = 0), and one explicit <contact><pair> per primitive pair of every pair
//     of robot segments the controller checks (Model::pairs), with margin = gap = `margin` (d_r): a
//     pair closer than d_r is REPORTED in mjData.contact with MuJoCo's own distance, but produces a
//     force only when it penetrates (MuJoCo: active when dist < margin - gap = 0). Body-schema slots
//     are not modelled (they are objects the controller adds, not parts of this robot).
//   - one servo per movable joint: a <general> actuator whose force is
//       ctrl - kp q,   clamped to ±effort,
//     plus the servo's velocity gain as joint damping (- kd qdot, integrated implicitly by MuJoCo),
//     so that ctrl = kp q_ref + kd qdot_ref + feed-forward makes a PD servo with a velocity reference
//     (MujocoRobot sets ctrl); gains from servoGains(). The damping part is not clamped by effort.
// Units: SI (m, rad, kg, N, N m, s). Angles in the MJCF are radians.
#pragma once

#include "reflex/control/model.hpp"

#include <Eigen/Core>

#include <string>
#include <vector>

namespace reflex::mujoco {

/// A joint's servo class. kBase: a joint on the path from the root to the first link that carries a
/// collision segment (the virtual heel -> body chain of the shipped robot: floor position and
/// balance, which a real robot's legs provide); kLimb: every other movable joint (arms, head, legs).
enum class JointClass { kBase, kLimb };

/// The servo of one joint. kp [N m/rad or N/m], kd [N m s/rad or N s/m], effort [N m or N],
/// armature [kg m^2 or kg] (reflected rotor inertia), damping [N m s/rad or N s/m] (passive friction).
struct ServoGains {
  JointClass joint_class = JointClass::kLimb;
  double kp = 0.0, kd = 0.0, effort = 0.0, armature = 0.0, damping = 0.0;
};

/// Everything the generated MJCF depends on besides the Model. Defaults are the values stated in
/// control/README.md.
struct MjcfOptions {
  double timestep = 0.001;    ///< physics step [s]
  double margin = 0.005;      ///< contact margin = gap = d_r [m]: pairs below it are reported
  double density = 1000.0;    ///< [kg/m^3] for links without URDF inertial (about that of the human body)
  double min_mass = 0.01;     ///< [kg] for links with neither inertial nor collision geometry
  double min_inertia = 1e-5;  ///< [kg m^2] principal inertia of such links
  double gravity = 9.81;      ///< [m/s^2] along -z of the root frame (z up)
  // Servo design (servoGains): a critically damped PD servo of bandwidth `bandwidth` on the joint's
  // inertia at the zero configuration, kp = I w^2, kd = 2 I w.
  double limb_bandwidth_hz = 10.0;
  double limb_armature = 0.01;  ///< [kg m^2]: a small motor through a 100:1 gear
  double limb_damping = 0.1;    ///< [N m s/rad] passive joint friction
  double limb_effort = 100.0;   ///< [N m] torque limit (the shipped URDFs' effort attribute)
  double base_bandwidth_hz = 10.0;
  double base_effort = 5000.0;  ///< [N or N m]: must carry the whole robot (virtual joints)
};

/// The class of every q index (see JointClass).
std::vector<JointClass> classifyJoints(const control::Model& model);

/// The MJCF text. `gains` (one per q index) may be empty: actuators then get kp = kd = 0 (used by
/// servoGains to measure the joint inertias). Throws reflex::Error for bad options (a value
/// not finite and positive, naming it).
std::string makeMjcf(const control::Model& model, const MjcfOptions& options,
                     const std::vector<ServoGains>& gains = {});

/// Servo gains per q index, from the joint inertias MuJoCo computes for the gain-less MJCF at q = 0
/// (mjModel::dof_M0, armature included) and the bandwidths of `options`.
std::vector<ServoGains> servoGains(const control::Model& model, const MjcfOptions& options);

/// A URDF <inertial> MuJoCo would refuse, made one it takes: mass raised to `min_mass`, principal
/// inertias to `min_inertia`, the two smaller to half the largest where they break A + B >= C (a
/// sensor link of zero mass and inertia on a movable joint). Returns whether anything changed; `what`
/// says from which values to which.
bool repairInertial(const MjcfOptions& options, double& mass, Eigen::Matrix3d& I, std::string* what);

/// One line per link whose URDF <inertial> makeMjcf repairs (repairInertial), for reflex_mujoco to say.
std::vector<std::string> inertialRepairs(const control::Model& model, const MjcfOptions& options);

/// Name of the MuJoCo geom of primitive k of segment s ("<segment>/<k>").
std::string geomName(const control::Model& model, int segment, int k);

}  // namespace reflex::mujoco
