// The physics-simulated robot (see mujoco_robot.hpp for the per-period contract).
#include "reflex/common/error.hpp"
#include "reflex/mujoco/mujoco_robot.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>

namespace reflex::mujoco {
namespace {

constexpr const char* kVfsName = "reflex_robot.xml";

// Frees a VFS (its file buffers) on every path out of compileMjcf.
struct VfsGuard {
  mjVFS* vfs;
  ~VfsGuard() { mj_deleteVFS(vfs); }
};

// MuJoCo's run-time warnings (an unstable simulation, a full contact list) go to stderr, counted by the
// caller from mjData.warning; without a handler MuJoCo also appends them to MUJOCO_LOG.TXT in the
// working directory.
extern "C" void warnToStderr(const char* message) { std::fprintf(stderr, "MuJoCo warning: %s\n", message); }

}  // namespace

MjModelPtr compileMjcf(const std::string& mjcf) {
  mju_user_warning = warnToStderr;
  // mjVFS holds 2000 file names of 1000 bytes: on the heap, not the stack.
  auto vfs = std::make_unique<mjVFS>();
  mj_defaultVFS(vfs.get());
  VfsGuard guard{vfs.get()};
  if (mj_makeEmptyFileVFS(vfs.get(), kVfsName, static_cast<int>(mjcf.size())) != 0)
    throw reflex::Error("MuJoCo: cannot make the in-memory MJCF file");
  const int index = mj_findFileVFS(vfs.get(), kVfsName);
  std::memcpy(vfs->filedata[index], mjcf.data(), mjcf.size());
  char error[1024] = "";
  MjModelPtr m(mj_loadXML(kVfsName, vfs.get(), error, sizeof error));
  if (!m) throw reflex::Error(std::string("MuJoCo could not compile the generated MJCF: ") + error);
  return m;
}

const char* verdictName(CommandVerdict v) {
  switch (v) {
    case CommandVerdict::kAccepted: return "accepted";
    case CommandVerdict::kEmpty: return "no joint names";
    case CommandVerdict::kLengthMismatch: return "names, positions and velocities differ in length";
    case CommandVerdict::kUnknownName: return "a joint name this robot does not have";
    case CommandVerdict::kDuplicateName: return "a joint named twice";
    case CommandVerdict::kNotFinite: return "a position or velocity that is not finite";
    case CommandVerdict::kExpired: return "valid_until_ns already passed";
  }
  return "?";
}

MujocoRobot::MujocoRobot(const control::Model& model, const MjcfOptions& options, const Eigen::VectorXd& q0)
    : model_(model),
      gains_(servoGains(model, options)),
      mjcf_(makeMjcf(model, options, gains_)),
      m_(compileMjcf(mjcf_)),
      d_(mj_makeData(m_.get())) {
  if (!d_) throw reflex::Error("MuJoCo: mj_makeData failed");
  const int nq = model.nq;
  if (q0.size() != 0 && q0.size() != nq)
    throw std::invalid_argument("MujocoRobot: initial configuration has " + std::to_string(q0.size()) + " values for " +
                                std::to_string(nq) + " joints");
  qpos_adr_.resize(nq);
  dof_adr_.resize(nq);
  actuator_.resize(nq);
  for (int qi = 0; qi < nq; ++qi) {
    const char* name = model.q_names[qi].c_str();
    const int joint = mj_name2id(m_.get(), mjOBJ_JOINT, name);
    actuator_[qi] = mj_name2id(m_.get(), mjOBJ_ACTUATOR, name);
    if (joint < 0 || actuator_[qi] < 0) throw reflex::Error(std::string("MuJoCo model lacks joint ") + name);
    qpos_adr_[qi] = m_->jnt_qposadr[joint];
    dof_adr_[qi] = m_->jnt_dofadr[joint];
    q_of_name_.emplace(model.q_names[qi], qi);
  }
  geom_segment_.assign(m_->ngeom, -1);
  for (int s = 0; s < model.num_robot_segments; ++s)
    for (int k = 0; k < model.segments[s].num_primitives; ++k)
      geom_segment_[mj_name2id(m_.get(), mjOBJ_GEOM, geomName(model, s, k).c_str())] = s;
  command_q_.reserve(nq);
  command_names_.reserve(nq);
  q_target_ = Eigen::VectorXd::Zero(nq);
  qdot_target_ = Eigen::VectorXd::Zero(nq);
  q_ref_ = Eigen::VectorXd::Zero(nq);
  qdot_ref_ = Eigen::VectorXd::Zero(nq);
  measured_.q = Eigen::VectorXd::Zero(nq);
  measured_.qdot = Eigen::VectorXd::Zero(nq);
  measured_.effort = Eigen::VectorXd::Zero(nq);
  measured_.contacts.reserve(model.pairs.size());
  Eigen::VectorXd q = q0.size() ? q0 : Eigen::VectorXd::Zero(nq);
  for (int qi = 0; qi < nq; ++qi) {
    if (!std::isfinite(q[qi]))
      throw std::invalid_argument("MujocoRobot: initial " + model.q_names[qi] + " is not finite");
    q[qi] = std::clamp(q[qi], model.q_lower[qi], model.q_upper[qi]);
  }
  setPositions(q);
  beginHold();
  counters_.holds = 0;  // holding from the start is not a hold "begun"
}

void MujocoRobot::setPositions(const Eigen::VectorXd& q) {
  mj_resetData(m_.get(), d_.get());
  for (int qi = 0; qi < model_.nq; ++qi) d_->qpos[qpos_adr_[qi]] = q[qi];
  mj_forward(m_.get(), d_.get());
  readMeasurement();
}

void MujocoRobot::beginHold() {
  if (!measured_.holding) ++counters_.holds;
  measured_.holding = true;
  measured_.applied_command_seq = 0;
  q_ref_ = measured_.q;
  q_target_ = measured_.q;
  qdot_ref_.setZero();
  qdot_target_.setZero();
}

CommandVerdict MujocoRobot::offerCommand(const CommandInput& c, std::int64_t now_ns) {
  CommandVerdict v = CommandVerdict::kAccepted;
  const std::size_t n = c.names ? c.names->size() : 0;
  if (n == 0) {
    v = CommandVerdict::kEmpty;
  } else if (!c.positions || !c.velocities || c.positions->size() != n || c.velocities->size() != n) {
    v = CommandVerdict::kLengthMismatch;
  } else if (c.valid_until_ns <= now_ns) {
    v = CommandVerdict::kExpired;
  } else {
    for (std::size_t i = 0; i < n && v == CommandVerdict::kAccepted; ++i)
      if (!std::isfinite((*c.positions)[i]) || !std::isfinite((*c.velocities)[i])) v = CommandVerdict::kNotFinite;
    // Map names to q indices (reusing the last mapping when the list is the same: no allocation).
    if (v == CommandVerdict::kAccepted && *c.names != command_names_) {
      std::vector<int> mapped;
      mapped.reserve(n);
      std::vector<bool> seen(model_.nq, false);
      for (const auto& name : *c.names) {
        const auto it = q_of_name_.find(name);
        if (it == q_of_name_.end()) {
          v = CommandVerdict::kUnknownName;
          break;
        }
        if (seen[it->second]) {
          v = CommandVerdict::kDuplicateName;
          break;
        }
        seen[it->second] = true;
        mapped.push_back(it->second);
      }
      if (v == CommandVerdict::kAccepted) {
        command_names_ = *c.names;
        command_q_ = std::move(mapped);
      }
    }
  }
  switch (v) {
    case CommandVerdict::kAccepted: ++counters_.accepted; break;
    case CommandVerdict::kEmpty: ++counters_.rejected_empty; break;
    case CommandVerdict::kLengthMismatch: ++counters_.rejected_length; break;
    case CommandVerdict::kUnknownName: ++counters_.rejected_unknown; break;
    case CommandVerdict::kDuplicateName: ++counters_.rejected_duplicate; break;
    case CommandVerdict::kNotFinite: ++counters_.rejected_not_finite; break;
    case CommandVerdict::kExpired: ++counters_.rejected_expired; break;
  }
  if (v != CommandVerdict::kAccepted) return v;

  if (measured_.holding) {
    // Leaving a hold: the joints this command does not name stay where they are held.
    measured_.holding = false;
  }
  bool clamped = false;
  for (std::size_t i = 0; i < n; ++i) {
    const int qi = command_q_[i];
    const double p = (*c.positions)[i];
    const double lim = std::clamp(p, model_.q_lower[qi], model_.q_upper[qi]);
    clamped = clamped || lim != p;
    q_target_[qi] = lim;
    qdot_target_[qi] = std::clamp((*c.velocities)[i], -model_.v_max[qi], model_.v_max[qi]);
  }
  if (clamped) ++counters_.position_clamped;
  valid_until_ns_ = c.valid_until_ns;
  measured_.applied_command_seq = c.seq;
  last_state_stamp_ns_ = c.state_stamp_ns;
  return v;
}

void MujocoRobot::step(int substeps, std::int64_t now_ns) {
  if (!measured_.holding && valid_until_ns_ <= now_ns) beginHold();
  const double dt = m_->opt.timestep;
  for (int k = 0; k < substeps; ++k) {
    mj_step1(m_.get(), d_.get());  // positions, collision detection, bias forces at the current state
    ++measured_.steps;
    if (d_->ncon > 0) ++measured_.contact_steps;
    if (measured_.holding) ++measured_.hold_steps;
    // The state and contacts published are those of the last step's start: one collision pass serves
    // the judge and the physics.
    if (k == substeps - 1) readMeasurement();
    for (int qi = 0; qi < model_.nq; ++qi) {
      // The reference approaches the target at most at the joint's velocity limit.
      const double max_move = model_.v_max[qi] * dt;
      const double move = std::clamp(q_target_[qi] - q_ref_[qi], -max_move, max_move);
      q_ref_[qi] += move;
      // The velocity feed-forward only while the reference still travels: once it has reached the
      // commanded position it stops there, and so does its velocity. A feed-forward kept after the
      // reference arrived held the joint kd qdot / kp = 2 qdot / omega past the commanded position
      // (51 mrad at 1.6 rad/s) until the next command -- up to the deadline when one was late -- and
      // carried arms 1-3 mm below d_r in reflex_sim --robot mujoco (walking_target_behind, grasped_bar).
      qdot_ref_[qi] = measured_.holding || q_ref_[qi] == q_target_[qi] ? 0.0 : qdot_target_[qi];
      const ServoGains& g = gains_[qi];
      d_->ctrl[actuator_[qi]] = g.kp * q_ref_[qi] + g.kd * qdot_ref_[qi] + d_->qfrc_bias[dof_adr_[qi]];
    }
    const int bad_before = d_->warning[mjWARN_BADQACC].number;
    mj_step2(m_.get(), d_.get());  // actuation, constraint forces, integration
    if (d_->warning[mjWARN_BADQACC].number != bad_before) ++measured_.unstable_steps;
  }
  // The drive torques applied from the published state on.
  for (int qi = 0; qi < model_.nq; ++qi)
    measured_.effort[qi] = d_->actuator_force[actuator_[qi]] - gains_[qi].kd * measured_.qdot[qi];
}

void MujocoRobot::readMeasurement() {
  for (int qi = 0; qi < model_.nq; ++qi) {
    measured_.q[qi] = d_->qpos[qpos_adr_[qi]];
    measured_.qdot[qi] = d_->qvel[dof_adr_[qi]];
    // The drive's torque: actuator (stiffness + feed-forward) plus its velocity gain (joint damping).
    measured_.effort[qi] = d_->actuator_force[actuator_[qi]] - gains_[qi].kd * measured_.qdot[qi];  // (see step)
  }
  collectContacts(measured_.contacts);
}

void MujocoRobot::collectContacts(std::vector<SegmentContact>& out) const {
  out.clear();
  for (int i = 0; i < d_->ncon; ++i) {
    const mjContact& c = d_->contact[i];
    int a = geom_segment_[c.geom1], b = geom_segment_[c.geom2];
    if (a < 0 || b < 0) continue;
    if (a > b) std::swap(a, b);
    bool merged = false;
    for (auto& known : out)
      if (known.seg_a == a && known.seg_b == b) {
        known.distance = std::min(known.distance, static_cast<double>(c.dist));
        merged = true;
      }
    if (!merged && out.size() < out.capacity()) out.push_back({a, b, c.dist});
  }
}

}  // namespace reflex::mujoco
