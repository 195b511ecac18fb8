#include "reflex/control_node/controller_node.hpp"

#include "reflex/control/kinematics.hpp"
#include "reflex/control/urdf_loader.hpp"
#include "reflex/control_node/robot_state_file.hpp"

#include <reflex/bus/bus.hpp>

#include <atomic>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <fstream>
#include <limits>
#include <map>
#include <unistd.h>

namespace reflex::control_node {

using namespace reflex::control;
namespace msg = reflex::msg;

namespace {

double nowSeconds(clockid_t clock) {
  timespec ts{};
  clock_gettime(clock, &ts);
  return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
}

msg::Zone toMsg(Zone z) {
  switch (z) {
    case Zone::kFree: return msg::ZONE_FREE;
    case Zone::kYellow: return msg::ZONE_YELLOW;
    case Zone::kOrange: return msg::ZONE_ORANGE;
    case Zone::kRed: return msg::ZONE_RED;
  }
  return msg::ZONE_RED;
}

std::string hostName() {
  char buf[256] = {0};
  gethostname(buf, sizeof(buf) - 1);
  return buf;
}

}  // namespace

struct ControllerNode::Impl {
  NodeConfig config;
  Model model;
  ControllerModel cm;
  std::unique_ptr<ControllerData> data;
  std::unique_ptr<KinematicRobot> robot;
  std::unique_ptr<RobotStateFile> state_file;  ///< null without --robot-state
  std::string state_note;
  std::unique_ptr<WalkingPattern> walking;
  std::unique_ptr<bus::Participant> participant;
  bus::Writer<msg::JointState>* joint_writer = nullptr;
  bus::Writer<msg::ControlStatus>* status_writer = nullptr;
  bus::Writer<msg::Heartbeat>* heartbeat_writer = nullptr;
  bus::Reader<msg::HandTargets>* targets_reader = nullptr;
  bus::Reader<msg::MotionPriority>* priority_reader = nullptr;
  bus::Reader<msg::BodySchemaChange>* schema_reader = nullptr;
  bus::Reader<msg::WalkCommand>* walk_reader = nullptr;
  bus::Reader<msg::Heartbeat>* heartbeat_reader = nullptr;
  std::atomic<bool> stop{false};
  std::atomic<bool> reset{false};

  // Inputs as last received.
  ControlInput input;
  MotionPriority topic_priority = MotionPriority::kEqual;
  std::string targets_source;
  double last_targets_rx = -1.0;
  std::map<std::string, double> heartbeat_rx;  // module -> monotonic time of its last heartbeat
  bool stale = true;
  std::map<std::string, int> schema_slots;     // segment name -> slot
  std::array<int, kBodySchemaSlots> slot_priority{};
  // Preallocated messages.
  msg::JointState joint_msg;
  msg::ControlStatus status_msg;
  std::vector<msg::BodySchemaChange> schema_scratch;
  Eigen::VectorXd q_walk;
  std::vector<SimSample> log;
};

ControllerNode::ControllerNode(const NodeConfig& config) : impl_(std::make_unique<Impl>()) {
  Impl& m = *impl_;
  m.config = config;
  if (!(config.input_timeout > 0.0))
    throw ConfigError("--input-timeout " + std::to_string(config.input_timeout) + " must be positive");
  const CollisionConfig cc = loadCollisionConfigFor(config.urdf, config.collision);
  m.model = loadModel(config.urdf, cc);
  ControllerConfig ctl = config.controller.empty() ? defaultControllerConfig() : loadControllerConfig(config.controller);
  if (!config.avoidance) ctl.params.mode = AvoidanceMode::kOff;
  m.cm = makeControllerModel(m.model, ctl);
  m.data = std::make_unique<ControllerData>(m.model, m.cm);
  Eigen::VectorXd q0 = restConfiguration(m.model, m.cm);
  if (!config.robot_state.empty()) {
    m.state_file = std::make_unique<RobotStateFile>(config.robot_state, m.model.q_names, m.model.q_lower, m.model.q_upper);
    char note[512];
    if (m.state_file->loaded()) {
      q0 = m.state_file->loadedPositions();
      const double age = nowSeconds(CLOCK_REALTIME) - 1e-9 * static_cast<double>(m.state_file->loadedWallNs());
      std::snprintf(note, sizeof(note), "robot state from '%s' (record %llu, written %.3f s ago)",
                    config.robot_state.c_str(), static_cast<unsigned long long>(m.state_file->loadedSequence()), age);
    } else {
      std::snprintf(note, sizeof(note), "no robot state in '%s' yet: starting from rest", config.robot_state.c_str());
    }
    m.state_note = note;
  }
  m.robot = std::make_unique<KinematicRobot>(m.model, q0);
  m.walking = std::make_unique<WalkingPattern>(m.model);
  m.q_walk = m.robot->jointPositions();

  bus::BusConfig bc;
  bc.module_name = config.module_name;
  if (config.domain_id >= 0) bc.domain_id = config.domain_id;
  bc.profiles_file = config.profiles_file;
  bc.participant_profile = config.participant_profile;
  m.participant = std::make_unique<bus::Participant>(bc);
  m.joint_writer = &m.participant->makeWriter<msg::JointState>();
  m.status_writer = &m.participant->makeWriter<msg::ControlStatus>();
  m.heartbeat_writer = &m.participant->makeWriter<msg::Heartbeat>();
  m.targets_reader = &m.participant->makeReader<msg::HandTargets>();
  m.priority_reader = &m.participant->makeReader<msg::MotionPriority>();
  m.schema_reader = &m.participant->makeReader<msg::BodySchemaChange>();
  m.walk_reader = &m.participant->makeReader<msg::WalkCommand>();
  m.heartbeat_reader = &m.participant->makeReader<msg::Heartbeat>();

  m.joint_msg.names(m.model.q_names);
  m.joint_msg.positions().assign(m.model.nq, 0.0);
  m.joint_msg.velocities().assign(m.model.nq, 0.0);
  m.schema_scratch.reserve(64);
  const double expected_cycles = config.duration > 0.0 ? config.duration / m.cm.params.period + 10.0 : 200.0 * 600.0;
  stats_.lateness_us.reserve(static_cast<std::size_t>(expected_cycles));
  if (!config.log_csv.empty()) m.log.reserve(static_cast<std::size_t>(expected_cycles));
}

ControllerNode::~ControllerNode() = default;

bus::Participant& ControllerNode::bus() { return *impl_->participant; }
const std::string& ControllerNode::robotStateNote() const { return impl_->state_note; }

void ControllerNode::stop() noexcept { impl_->stop = true; }
void ControllerNode::requestEstopReset() noexcept { impl_->reset = true; }

void ControllerNode::run() {
  Impl& m = *impl_;
  const double period = m.cm.params.period;
  const auto period_ns = static_cast<long>(std::llround(period * 1e9));
  timespec next{};
  clock_gettime(CLOCK_MONOTONIC, &next);
  const double t_start = nowSeconds(CLOCK_MONOTONIC);
  double last_start = t_start, last_heartbeat = -1.0;
  bool walk_active = false;
  if (m.state_file && m.state_file->loaded()) {
    // Resumed from a saved robot state (a restart after a crash): the hands hold where they are
    // (targets at their current positions, avoidance active) until the target source speaks, and the
    // source gets the same grace as silence during a run: after input_timeout without a sign of it
    // the hands retract as usual. Without this the first cycle would already retract at full speed.
    if (computeForwardKinematics(m.model, m.data->kin, m.robot->jointPositions())) {
      for (int a = 0; a < 2; ++a) {
        m.input.hands[a].status = HandStatus::kGiven;
        m.input.hands[a].target_W = m.data->kin.X_W_L[m.cm.arms[a].hand_link] * m.cm.arms[a].hand_point_L;
      }
      m.last_targets_rx = t_start;
    }
  }

  auto publishHeartbeat = [&](msg::ModuleState state) {
    msg::Heartbeat hb;
    hb.module_name(m.config.module_name);
    hb.host(hostName());
    hb.pid(static_cast<std::int32_t>(getpid()));
    hb.state(state);
    hb.period_ms(500);
    m.heartbeat_writer->publish(hb);
  };
  publishHeartbeat(msg::STATE_RUNNING);

  while (!m.stop && !m.participant->stopRequested()) {
    next.tv_nsec += period_ns;
    while (next.tv_nsec >= 1000000000L) {
      next.tv_nsec -= 1000000000L;
      ++next.tv_sec;
    }
    clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &next, nullptr);
    const double t_now = nowSeconds(CLOCK_MONOTONIC);
    const double scheduled = static_cast<double>(next.tv_sec) + 1e-9 * static_cast<double>(next.tv_nsec);
    const double lateness_us = std::max(0.0, (t_now - scheduled) * 1e6);
    const double t = t_now - t_start;
    if (m.config.duration > 0.0 && t >= m.config.duration) break;

    // 1. Inputs (poll; never block).
    msg::HandTargets targets;
    if (m.targets_reader->takeLatest(targets)) {
      ++stats_.targets_received;
      m.last_targets_rx = t_now;
      m.targets_source = targets.header().source();
      const msg::HandTarget* hands[2] = {&targets.left(), &targets.right()};
      for (int a = 0; a < 2; ++a) {
        const auto& p = hands[a]->position_base();
        const Eigen::Vector3d target(p.x(), p.y(), p.z());
        const bool given = hands[a]->status() == msg::TARGET_GIVEN;
        if (given && (!target.allFinite() || target.norm() > m.config.max_target_distance)) {
          ++stats_.targets_rejected;  // never followed; the hand keeps what it had
          continue;
        }
        m.input.hands[a].status = given ? HandStatus::kGiven : HandStatus::kNoTarget;
        if (given) m.input.hands[a].target_W = target;
      }
    }
    msg::MotionPriority prio;
    if (m.priority_reader->takeLatest(prio)) {
      m.topic_priority = prio.priority() == msg::PRIORITY_LEFT_HIGHER    ? MotionPriority::kLeftHigher
                         : prio.priority() == msg::PRIORITY_RIGHT_HIGHER ? MotionPriority::kRightHigher
                                                                         : MotionPriority::kEqual;
    }
    msg::Heartbeat hb;
    while (m.heartbeat_reader->takeNext(hb)) m.heartbeat_rx[hb.module_name()] = t_now;
    m.schema_scratch.clear();
    m.schema_reader->takeAll(m.schema_scratch);
    for (const auto& change : m.schema_scratch) {
      const std::string& name = change.segment_name();
      auto it = m.schema_slots.find(name);
      if (change.operation() == msg::SCHEMA_DETACH || !change.enabled()) {
        if (it != m.schema_slots.end()) {
          detachBodySchemaSegment(m.data->dist, it->second);
          m.data->slot_virtual[it->second] = false;
          if (change.operation() == msg::SCHEMA_DETACH) m.schema_slots.erase(it);
        }
        continue;
      }
      int slot = -1;
      if (it != m.schema_slots.end()) {
        slot = it->second;
      } else {
        for (int s = 0; s < kBodySchemaSlots && slot < 0; ++s) {
          bool used = false;
          for (const auto& kv : m.schema_slots) used |= kv.second == s;
          if (!used) slot = s;
        }
      }
      const int link = m.model.linkIndex(change.parent_link());
      const Eigen::Vector3d a(change.point_a().x(), change.point_a().y(), change.point_a().z());
      const Eigen::Vector3d b = change.shape() == msg::SHAPE_SPHERE
                                    ? a
                                    : Eigen::Vector3d(change.point_b().x(), change.point_b().y(), change.point_b().z());
      std::uint64_t ignore = 0;
      const int own = m.model.segmentIndex(change.parent_link());
      if (own >= 0) ignore |= std::uint64_t{1} << own;
      if (change.virtual_segment()) {  // the gaze line starts inside the head
        const int head = m.model.segmentIndex("head");
        if (head >= 0) ignore |= std::uint64_t{1} << head;
      } else if (link >= 0 && m.model.links[link].parent >= 0) {
        const int parent_seg = m.model.segmentIndex(m.model.links[m.model.links[link].parent].name);
        if (parent_seg >= 0) ignore |= std::uint64_t{1} << parent_seg;
      }
      // The boundary check (bounds: BodySchemaLimits): a bad sample is rejected, counted and named.
      const BodySchemaCheck check =
          checkBodySchemaSegment(m.model, link, a, b, change.radius(), change.virtual_segment(), BodySchemaLimits{});
      if (!check.ok() || slot < 0 || !attachBodySchemaSegment(m.model, m.data->dist, slot, link, a, b, change.radius(), ignore)) {
        ++stats_.targets_rejected;
        if (check.ok()) {
          std::fprintf(stderr, "controller: body-schema segment '%s' rejected: no free slot (link '%s')\n", name.c_str(),
                       change.parent_link().c_str());
        } else if (*check.key != '\0') {
          std::fprintf(stderr, "controller: body-schema segment '%s' rejected: %s: %g m > %s %g m (link '%s', %s)\n",
                       name.c_str(), describe(check.fault), check.value, check.key, check.limit,
                       change.parent_link().c_str(), change.virtual_segment() ? "virtual" : "physical");
        } else {
          std::fprintf(stderr, "controller: body-schema segment '%s' rejected: %s (value %g, link '%s')\n", name.c_str(),
                       describe(check.fault), check.value, change.parent_link().c_str());
        }
        continue;
      }
      m.data->slot_virtual[slot] = change.virtual_segment();
      m.slot_priority[slot] = change.motion_priority();
      m.schema_slots[name] = slot;
    }
    msg::WalkCommand walk;
    if (m.walk_reader->takeLatest(walk)) {
      const int heel = m.model.qIndex("heel_x");
      const double x = heel >= 0 ? m.robot->jointPositions()[heel] : 0.0;
      if (walk.stop()) {
        m.walking->stop();
      } else if (std::isfinite(walk.goal_x()) && std::isfinite(walk.speed()) && walk.speed() > 0.0) {
        m.walking->start(walk.goal_x() - x, std::min(walk.speed(), 0.5));
        walk_active = true;
      } else {
        ++stats_.targets_rejected;
      }
    }

    // 2. Staleness: the target source is silent (no sample, no heartbeat) for input_timeout -> retract.
    double last_sign = m.last_targets_rx;
    auto hb_it = m.heartbeat_rx.find(m.targets_source);
    if (hb_it != m.heartbeat_rx.end()) last_sign = std::max(last_sign, hb_it->second);
    const bool stale_now = last_sign < 0.0 || t_now - last_sign > m.config.input_timeout;
    if (stale_now && !m.stale) ++stats_.stale_events;
    m.stale = stale_now;
    ControlInput in = m.input;
    if (m.stale) in.hands[kLeft].status = in.hands[kRight].status = HandStatus::kNoTarget;
    in.priority = m.topic_priority;
    if (in.priority == MotionPriority::kEqual) {  // a grasped object with priority makes its arm higher
      for (int s = 0; s < kBodySchemaSlots; ++s) {
        if (!m.data->dist.slots[s].enabled || m.data->slot_virtual[s] || m.slot_priority[s] <= 0) continue;
        for (int a = 0; a < 2; ++a)
          if (m.cm.arms[a].link_in_arm[m.data->dist.slots[s].link])
            in.priority = a == kLeft ? MotionPriority::kLeftHigher : MotionPriority::kRightHigher;
      }
    }
    in.reset_estop = m.reset.exchange(false);

    // 3. Control (allocation-free) and the robot.
    const ControlResult cr = computeControl(m.model, m.cm, *m.data, m.robot->jointPositions(), in);
    if (cr != ControlResult::kFrozen) {
      m.robot->command(m.data->qdot, period);
      if (walk_active) {
        m.q_walk = m.robot->jointPositions();
        m.walking->step(period, m.q_walk);
        m.robot->setWalkingJoints(m.q_walk, m.walking->joints());
      }
    }
    // The robot state is persisted before it is published: what any reader saw survives a crash.
    if (m.state_file && !m.state_file->save(m.robot->jointPositions())) ++stats_.state_write_errors;
    double dmin = 1e9, dvirt = std::numeric_limits<double>::infinity();
    for (std::size_t i = 0; i < m.data->dist.pairs.size(); ++i) {
      const auto& pd = m.data->dist.pairs[i];
      if (!pd.active) continue;
      const int sb = pd.seg_b;
      if (m.model.segments[sb].body_schema_slot && m.data->slot_virtual[sb - m.model.num_robot_segments]) {
        dvirt = std::min(dvirt, pd.distance);
        continue;
      }
      dmin = std::min(dmin, pd.distance);
    }
    stats_.min_distance = std::min(stats_.min_distance, dmin);
    stats_.estop_count = m.data->estop_count;
    stats_.guard_count = m.data->guard_count;

    // 4. Outputs.
    const Eigen::VectorXd& q = m.robot->jointPositions();
    for (int i = 0; i < m.model.nq; ++i) {
      m.joint_msg.positions()[i] = q[i];
      m.joint_msg.velocities()[i] = cr == ControlResult::kFrozen ? 0.0 : m.data->qdot[i];
    }
    m.joint_writer->publish(m.joint_msg);
    msg::ArmStatus* arms[2] = {&m.status_msg.left(), &m.status_msg.right()};
    for (int a = 0; a < 2; ++a) {
      const ArmStatus& s = m.data->arms[a];
      arms[a]->blend_f(s.f);
      arms[a]->distance(std::isfinite(s.distance) ? s.distance : 1e9);
      arms[a]->zone(toMsg(s.zone));
      arms[a]->estop_latched(m.data->estop != EstopState::kClear);
      if (s.closest_pair >= 0) {
        arms[a]->closest_segment_a(m.model.segments[m.model.pairs[s.closest_pair].a].name);
        arms[a]->closest_segment_b(m.model.segments[m.model.pairs[s.closest_pair].b].name);
      }
    }
    const double compute_us = (nowSeconds(CLOCK_MONOTONIC) - t_now) * 1e6;
    if (compute_us > period * 1e6) ++stats_.overruns;
    m.status_msg.cycle_period_us((t_now - last_start) * 1e6);
    m.status_msg.compute_time_us(compute_us);
    m.status_msg.lateness_us(lateness_us);
    m.status_msg.overrun_count(stats_.overruns);
    m.status_writer->publish(m.status_msg);
    last_start = t_now;
    ++stats_.cycles;
    stats_.max_lateness_us = std::max(stats_.max_lateness_us, lateness_us);
    if (stats_.lateness_us.size() < stats_.lateness_us.capacity()) stats_.lateness_us.push_back(lateness_us);
    if (!m.config.log_csv.empty() && m.log.size() < m.log.capacity()) {
      SimSample s;
      s.t = t;
      s.arms = m.data->arms;
      s.commands = in.hands;
      s.estop = m.data->estop;
      s.min_distance = dmin;
      s.virtual_distance = dvirt;
      s.arm_distance = armToArmDistance(m.model, m.cm, *m.data);
      s.wall_time = nowSeconds(CLOCK_REALTIME);
      s.q = q;
      s.qdot = m.data->qdot;
      m.log.push_back(std::move(s));
    }
    if (t_now - last_heartbeat >= 0.5) {
      publishHeartbeat(msg::STATE_RUNNING);
      last_heartbeat = t_now;
    }
    // Fell behind by more than a period: re-anchor the schedule instead of bursting.
    if (lateness_us > period * 1e6) clock_gettime(CLOCK_MONOTONIC, &next);
  }
  publishHeartbeat(msg::STATE_STOPPING);
  if (!m.config.log_csv.empty()) {
    SimResult r;
    r.samples = std::move(m.log);
    writeTimeseriesCsv(m.model, m.cm, r, m.config.log_csv);
  }
}

}  // namespace reflex::control_node
