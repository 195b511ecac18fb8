#include "reflex/control_node/controller_node.hpp"

#include "reflex/control/kinematics.hpp"
#include "reflex/control/onboard.hpp"
#include "reflex/control/urdf_loader.hpp"
#include "reflex/control_node/dds_robot_port.hpp"
#include "reflex/control_node/ros2_port.hpp"
#include "reflex/control_node/unitree_hg_port.hpp"
#include "reflex/control_node/robot_state_file.hpp"
#include "reflex/control_node/timeseries_log.hpp"

#include <reflex/bus/bus.hpp>
#include <reflex/bus/outbox.hpp>

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <fstream>
#include <limits>
#include <map>
#include <thread>
#include <unistd.h>

namespace reflex::control_node {

using namespace reflex::control;
namespace msg = reflex::msg;

namespace {

// A body-schema slot holds any name the bus can carry, and the onboard controller refuses the rest.
static_assert(kBodySchemaNameBytes == bus::kMaxKeyStringBytes, "a slot name holds exactly a bus key string");

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

/// The DDS participant of a writer: the first 12 bytes (GUID prefix) of its publication handle.
using ParticipantId = std::array<unsigned char, 12>;
ParticipantId participantOf(const bus::dds::SampleInfo& info) {
  ParticipantId id{};
  const unsigned char* handle = info.publication_handle.value;  // 16 bytes: the writer GUID
  std::copy(handle, handle + id.size(), id.begin());
  return id;
}

}  // namespace

namespace {
constexpr std::size_t kDetailBytes = 640;    ///< the heartbeat's detail text, at most (reserved once)
constexpr double kRobotProblemWindow = 2.0;  ///< s a rejected robot state / ignored writer stays in the detail
}  // namespace

const char* robotStateCauseName(int cause) noexcept {
  static const char* const kNames[] = {
      "robot_state_length",    "robot_state_missing_joint",  "robot_state_not_finite",     "robot_state_future_stamp",
      "robot_state_old_stamp", "robot_state_duplicate_name", "robot_state_outside_limits", "robot_state_other_writer",
      "robot_state_bad_crc",   "robot_state_motor_count",    "robot_state_old_tick"};
  static_assert(sizeof(kNames) / sizeof(kNames[0]) == kRobotStateCauses, "one name per robot port cause");
  return cause >= 0 && cause < kRobotStateCauses ? kNames[cause] : "robot_state_?";
}

std::string describeRejections(const NodeStats& stats) {
  std::string text;
  auto add = [&](const char* name, std::uint64_t n) {
    if (n == 0) return;
    text += (text.empty() ? "" : ", ") + std::string(name) + " " + std::to_string(n);
  };
  for (int c = 0; c < kRejectCauses; ++c)
    add(rejectCauseName(static_cast<RejectCause>(c)), stats.rejected[static_cast<std::size_t>(c)]);
  for (int c = 0; c < kRobotStateCauses; ++c)
    add(robotStateCauseName(c), stats.robot_states_rejected_by_cause[static_cast<std::size_t>(c)]);
  return text;
}

std::string Protection::describe() const {
  return full() ? std::string("full (collision avoidance and e-stop on)") : "REDUCED: " + reason;
}

struct ControllerNode::Impl {
  NodeConfig config;
  Model model;
  ControllerModel cm;
  // The robot port: the in-process kinematic plant or the robot over DDS.
  std::unique_ptr<KinematicPort> kinematic;  ///< --robot kinematic
  std::unique_ptr<BusRobotPort> dds;         ///< --robot dds (DdsRobotPort) or unitree_hg (UnitreeHgPort)
  std::unique_ptr<bus::WriterIdentities> robot_identities;  ///< --robot dds: who wrote a robot state
  std::unique_ptr<OnboardController> ctl;                   ///< everything per cycle but the bus (onboard.hpp)
  std::unique_ptr<RobotStateFile> state_file;               ///< null without --robot-state
  std::string state_note;
  std::string interface_note;  ///< robotInterfaceNote()
  std::string config_note;     ///< describeControllerConfig
  Eigen::VectorXd q0;
  std::unique_ptr<bus::Participant> participant;
  bus::Writer<msg::JointState>* joint_writer = nullptr;
  bus::Writer<msg::ControlStatus>* status_writer = nullptr;
  bus::Writer<msg::Heartbeat>* heartbeat_writer = nullptr;
  bus::Reader<msg::HandTargets>* targets_reader = nullptr;
  bus::Reader<msg::MotionPriority>* priority_reader = nullptr;
  bus::Reader<msg::BodySchemaChange>* schema_reader = nullptr;
  bus::Reader<msg::WalkCommand>* walk_reader = nullptr;
  bus::Reader<msg::Heartbeat>* heartbeat_reader = nullptr;
  bus::Writer<msg::ControllerProtection>* protection_writer = nullptr;
  bus::Reader<msg::ControllerProtection>* protection_reader = nullptr;
  // The loop's joint state, status and heartbeats go through the outbox: a writer thread does the DDS
  // writes, so a write that blocks (a dead reader on shared memory) never stops the loop
  // (reflex/bus/outbox.hpp). Declared after the participant: closed before its writers go.
  std::unique_ptr<bus::Outbox> outbox;
  bus::OutboxQueue<msg::JointState>* joint_out = nullptr;
  bus::OutboxQueue<msg::ControlStatus>* status_out = nullptr;
  bus::OutboxQueue<msg::Heartbeat>* heartbeat_out = nullptr;
  msg::Heartbeat heartbeat_out_msg;  // filled in place: no allocation per heartbeat
  ParticipantId own_participant{};
  std::int64_t protection_stamp_ns = 0;  ///< when this controller claimed the domain (its protection sample)
  std::string peer_refusal;              ///< why this controller yielded to an earlier one ("" if it did not)
  Protection protection;
  std::unique_ptr<TimeseriesLog> log;  ///< null without --log
  std::string log_error;
  std::atomic<bool> stop{false};
  std::atomic<bool> reset{false};

  // The target source is the DDS participant that wrote the last hand targets; only ITS heartbeats
  // (state RUNNING) count as a sign of life, never a module name in a message.
  bool have_target_writer = false;
  ParticipantId target_writer{};
  // Preallocated messages.
  msg::JointState joint_msg;
  msg::ControlStatus status_msg;
  msg::HandTargets targets_msg;
  msg::Heartbeat heartbeat_msg;
  msg::ControllerProtection peer_msg;
  std::vector<msg::BodySchemaChange> schema_scratch;
  // One per-sample log line (a rejected body-schema segment): rate-limited.
  bus::LogLimiter schema_log;
  /// Rejected robot states (--robot dds), one limiter per cause: a flood of one kind never hides another.
  std::array<bus::LogLimiter, kRobotStateCauses> robot_log;
  BusRobotPort::CauseCounts robot_named{};  ///< rejections per cause when they were last named
  /// Robot state stale / fresh lines: a robot (or a loaded host) that flaps around --robot-timeout
  /// is counted (exit line) but cannot flood stderr.
  bus::LogLimiter robot_state_log{4};
  char schema_line[512] = {};
  SimSample log_row;                  ///< q / qdot sized once: filling it does not allocate
  std::uint64_t rejections_seen = 0;  ///< OnboardCounts::targets_rejected when last_rejection was last set

  // The heartbeat's detail says what the controller cannot do or refuses: "" when it runs normally;
  // with --robot dds "robot state stale ..." while it has no fresh robot state (it commands nothing),
  // then, for kRobotProblemWindow after each, the latest robot state it rejected and the latest
  // robot_state writer it ignored (another driver, a replay, a man in the middle).
  struct Loop {
    std::string detail;  ///< reserved kDetailBytes at the start of run()
    char robot_stale_text[200] = {};
    double last_robot_reject_t = -1e9, last_other_writer_t = -1e9, last_heartbeat = -1.0;
    std::uint64_t other_writer_seen = 0, bad_seen = 0;
    char detail_buf[kDetailBytes] = {};
    bool robot_ok = true;  ///< as last said (log, heartbeat)
    bool said_robot = false;
  } loop;

  // run()'s steps (allocation-free, like the loop).
  void publishHeartbeat(msg::ModuleState state);
  /// 1. This cycle's inputs (poll, never block) handed to the onboard controller; `last_rejection`
  /// the latest refusal among them (or nullptr). False: another controller owns the domain (stop).
  bool takeInputs(ControllerNode& node, double t_now, const char*& last_rejection);
  void sayRobotState(bool ok, double t_now);
  void recordStats(const CycleReport& rep, NodeStats& stats);
  void recordPortStats(NodeStats& stats) const;
  void publishCycle(const CycleReport& rep, const char* last_rejection, double t, double t_now, double last_start,
                    double lateness_us, NodeStats& stats);
  void finishRun(NodeStats& stats);
  // The constructor's steps.
  void claimDomain(ControllerNode& node);
  RobotPort* makeRobotPort(const Eigen::VectorXd& q0, double deadline);
  void makeTopics();
};

namespace {
/// The options that need no file: refused naming the value (before anything is loaded).
void checkNodeOptions(const NodeConfig& config) {
  if (!(config.input_timeout > 0.0))
    throw ConfigError("--input-timeout " + std::to_string(config.input_timeout) + " must be positive");
  if (config.robot != "kinematic" && config.robot != "dds" && config.robot != "unitree_hg" && config.robot != "ros2")
    throw ConfigError("--robot '" + config.robot +
                      "' is not a robot side: use 'kinematic' (the in-process plant), 'dds' "
                      "(a robot driver on reflex/robot_state and reflex/joint_command), 'unitree_hg' (Unitree's "
                      "rt/lowstate and rt/arm_sdk, with --joint-map) or 'ros2' (sensor_msgs/JointState in, a "
                      "ros2_control controller's command out)");
  if (config.robot != "ros2" && (!config.ros_controller.empty() || !config.ros_joints.empty() ||
                                 config.ros_command != "forward" || config.ros_state_topic != "joint_states"))
    throw ConfigError(
        "--ros-state-topic / --ros-command / --ros-controller / --ros-joints are for --robot ros2, not '" +
        config.robot + "'");
  if (config.robot != "unitree_hg" && !config.joint_map.empty())
    throw ConfigError("--joint-map '" + config.joint_map + "' is for --robot unitree_hg, not '" + config.robot + "'");
  if (config.trigger != "timer" && config.trigger != "state")
    throw ConfigError("--trigger '" + config.trigger +
                      "' is not a cycle trigger: use 'timer' (a cycle every period) or "
                      "'state' (a cycle per arriving robot state, with --robot dds, unitree_hg or ros2)");
  if (config.trigger == "state" && config.robot == "kinematic")
    throw ConfigError("--trigger state runs a cycle per arriving robot state, but --robot '" + config.robot +
                      "' sends none: use --robot dds, unitree_hg or ros2, or --trigger timer");
  if (!(config.robot_timeout > 0.0 && config.robot_timeout <= 1.0))
    throw ConfigError("--robot-timeout " + std::to_string(config.robot_timeout) + " must be in (0, 1] s");
  if (config.robot != "kinematic" && !config.robot_state.empty())
    throw ConfigError("--robot-state '" + config.robot_state +
                      "' keeps the simulated robot's joints across restarts; "
                      "with --robot " +
                      config.robot + " the robot measures its own: drop one of the two options");
}
}  // namespace

/// The participant, and this controller's claim on the domain: it publishes who protects the robot,
/// then looks for another controller for --peer-probe seconds (ConfigError if one keeps the domain).
void ControllerNode::Impl::claimDomain(ControllerNode& node) {
  bus::BusConfig bc;
  bc.module_name = config.module_name;
  if (config.domain_id >= 0) bc.domain_id = config.domain_id;
  bc.profiles_file = config.profiles_file;
  bc.participant_profile = config.participant_profile;
  participant = std::make_unique<bus::Participant>(bc);
  protection_writer = &participant->makeWriter<msg::ControllerProtection>();
  protection_reader = &participant->makeReader<msg::ControllerProtection>();
  const auto& prefix = participant->native().guid().guidPrefix;
  std::copy(prefix.value, prefix.value + 12, own_participant.begin());

  // Who protects the robot, for late joiners; then one controller per domain.
  // Every controller publishes this sample first and then looks for others' for peer_probe seconds;
  // the one that published EARLIER (Header.stamp_ns; equal stamps: the smaller participant id) keeps
  // the domain and every later one refuses to start, so two controllers started at the same instant
  // leave exactly one running. The robot's output writers (joint state, status, heartbeat) are made
  // only after the probe: nothing of a refused controller ever reaches the robot's topics.
  msg::ControllerProtection mine;
  mine.avoidance(protection.avoidance);
  mine.estop(protection.estop);
  mine.reason(protection.reason);
  mine.period(protection.period);
  mine.robot(protection.robot);
  protection_writer->publish(mine);
  protection_stamp_ns = mine.header().stamp_ns();
  const auto probe_end = std::chrono::steady_clock::now() + std::chrono::duration<double>(config.peer_probe);
  for (;;) {
    msg::ControllerProtection other;
    bus::dds::SampleInfo info;
    while (protection_reader->takeNext(other, &info)) {
      const ParticipantId them = participantOf(info);
      if (them == own_participant) continue;
      if (node.notePeerController(other, them)) {
        // Before leaving, let this controller's own sample reach the running one (its reader may
        // not have matched this writer yet), so it can say that a second controller showed up:
        // this participant's reader and one other, then their acknowledgements, 1 s at most each.
        protection_writer->waitForReaders(2, std::chrono::seconds(1));
        protection_writer->native().wait_for_acknowledgments(eprosima::fastrtps::Duration_t(1, 0));
        throw ConfigError(peer_refusal);
      }
    }
    if (std::chrono::steady_clock::now() >= probe_end) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
}

/// The robot port --robot names: the in-process kinematic plant, or a robot over DDS (reflex/robot_state,
/// ROS 2, Unitree hg) whose commands go through the outbox.
RobotPort* ControllerNode::Impl::makeRobotPort(const Eigen::VectorXd& q0, double deadline) {
  if (config.robot == "dds") {
    DdsRobotPort::Options po;
    po.timeout = config.robot_timeout;
    po.deadline = deadline;
    po.period = cm.params.period;
    // Under DDS-Security only the identity "robot" can be bound (plain DDS: the first writer).
    robot_identities = std::make_unique<bus::WriterIdentities>(*participant, std::vector<std::string>{"robot"});
    if (robot_identities->authenticated()) po.identities = robot_identities.get();
    dds = std::make_unique<DdsRobotPort>(model, drivenJoints(model, cm), *participant, po);
    dds->sendThrough(*outbox);  // the commands too: a blocked write must not stop the loop
    return dds.get();
  } else if (config.robot == "ros2") {
    Ros2RobotPort::Options ro;
    ro.timeout = config.robot_timeout;
    ro.period = cm.params.period;
    ro.state_topic = config.ros_state_topic;
    ro.command = config.ros_command;
    ro.controller = config.ros_controller;
    ro.joints = config.ros_joints;
    auto ros = std::make_unique<Ros2RobotPort>(model, drivenJoints(model, cm), *participant, ro);
    interface_note = ros->describe();
    dds = std::move(ros);
    dds->sendThrough(*outbox);
    return dds.get();
  } else if (config.robot == "unitree_hg") {
    UnitreeHgPort::Options ho;
    ho.timeout = config.robot_timeout;
    ho.period = cm.params.period;
    ho.ramp_time = config.ramp_time;
    dds = std::make_unique<UnitreeHgPort>(
        model, drivenJoints(model, cm),
        unitree_hg::loadHgJointMap(unitree_hg::hgJointMapFor(config.urdf, config.joint_map)), *participant, ho);
    dds->sendThrough(*outbox);  // LowCmd_ too: a DDS write allocates and can block
    return dds.get();
  } else {
    kinematic = std::make_unique<KinematicPort>(q0);
    return kinematic.get();
  }
}

/// The writers and readers of the loop, its preallocated messages and the outbox's queues (every
/// string reserved: copying a sample into a slot never allocates), the outbox started.
void ControllerNode::Impl::makeTopics() {
  joint_writer = &participant->makeWriter<msg::JointState>();
  status_writer = &participant->makeWriter<msg::ControlStatus>();
  heartbeat_writer = &participant->makeWriter<msg::Heartbeat>();
  targets_reader = &participant->makeReader<msg::HandTargets>();
  priority_reader = &participant->makeReader<msg::MotionPriority>();
  schema_reader = &participant->makeReader<msg::BodySchemaChange>();
  walk_reader = &participant->makeReader<msg::WalkCommand>();
  heartbeat_reader = &participant->makeReader<msg::Heartbeat>();

  status_msg.last_rejection().reserve(64);  // every cause name fits: assigning it never allocates
  joint_msg.names(model.q_names);
  joint_msg.positions().assign(model.nq, 0.0);
  joint_msg.velocities().assign(model.nq, 0.0);
  schema_scratch.reserve(64);
  // The outbox's slots are copies of these prototypes with every string reserved for the longest
  // value it can take (a segment name: the model's longest, or an attached segment's, a DDS key
  // string of at most bus::kMaxKeyStringBytes; the rejection is a cause name; the heartbeat's detail
  // one of run()'s texts, < 200 bytes), so copying a sample into a slot never allocates.
  std::size_t longest_name = bus::kMaxKeyStringBytes;
  for (const auto& seg : model.segments) longest_name = std::max(longest_name, seg.name.size());
  const auto reserveStatus = [longest_name](msg::ControlStatus& st) {
    for (msg::ArmStatus* arm : {&st.left(), &st.right()}) {
      arm->closest_segment_a().reserve(longest_name);
      arm->closest_segment_b().reserve(longest_name);
    }
    st.last_rejection().reserve(64);
    st.header().source().reserve(bus::kMaxKeyStringBytes);
  };
  reserveStatus(status_msg);
  heartbeat_out_msg.module_name(config.module_name);
  heartbeat_out_msg.host(hostName());
  heartbeat_out_msg.pid(static_cast<std::int32_t>(getpid()));
  heartbeat_out_msg.period_ms(500);
  const auto reserveHeartbeat = [](msg::Heartbeat& hb) { hb.detail().reserve(kDetailBytes); };
  reserveHeartbeat(heartbeat_out_msg);
  for (auto* h : {&joint_msg.header(), &status_msg.header(), &heartbeat_out_msg.header()})
    h->source(config.module_name);
  // Written in this order each pass (the robot's commands, added by the port, first; then the
  // heartbeat, so that the STOPPING one goes out even if a stuck status writer uses up close()'s time).
  heartbeat_out = &outbox->add<msg::Heartbeat>(*heartbeat_writer, heartbeat_out_msg, 16, reserveHeartbeat);
  joint_out = &outbox->add(*joint_writer, joint_msg);
  status_out = &outbox->add<msg::ControlStatus>(*status_writer, status_msg, 64, reserveStatus);
  outbox->start();
}

ControllerNode::ControllerNode(const NodeConfig& config) : impl_(std::make_unique<Impl>()) {
  Impl& m = *impl_;
  m.config = config;
  checkNodeOptions(config);
  const CollisionConfig cc = loadCollisionConfigFor(config.urdf, config.collision);
  m.model = loadModel(config.urdf, cc);
  if (!(config.peer_probe >= 0.0 && config.peer_probe <= 60.0))
    throw ConfigError("--peer-probe " + std::to_string(config.peer_probe) + " must be in [0, 60] s");
  // The same rule as every process with --urdf: --controller, else <stem>.controller.yaml beside the URDF.
  ControllerConfig ctl = loadControllerConfigFor(config.urdf, config.controller);
  m.config_note = describeControllerConfig(ctl, config.urdf);
  // Protection: avoidance off by the option or the file; the e-stop only by the option.
  std::string reason;
  if (!config.avoidance) {
    reason = "collision avoidance OFF by --no-avoidance";
  } else if (ctl.params.mode == AvoidanceMode::kOff) {
    reason = "collision avoidance OFF by 'avoidance: off' in " + ctl.source;
  }
  if (!config.avoidance) ctl.params.mode = AvoidanceMode::kOff;
  ctl.params.estop = config.estop;
  if (!config.estop) reason += std::string(reason.empty() ? "" : "; ") + "E-STOP OFF by --disable-estop";
  m.protection.avoidance = ctl.params.mode != AvoidanceMode::kOff;
  m.protection.estop = ctl.params.estop;
  m.protection.reason = reason;
  m.protection.period = ctl.params.period;
  m.cm = makeControllerModel(m.model, ctl);
  m.protection.robot = m.model.name;
  const double deadline = config.command_deadline > 0.0 ? config.command_deadline : 3.0 * m.cm.params.period;
  if (!(deadline >= m.cm.params.period && deadline <= 1.0))
    throw ConfigError("--command-deadline " + std::to_string(config.command_deadline) +
                      " must be in [period = " + std::to_string(m.cm.params.period) + ", 1] s (0: three periods)");
  Eigen::VectorXd q0 = restConfiguration(m.model, m.cm);
  if (!config.robot_state.empty()) {
    m.state_file =
        std::make_unique<RobotStateFile>(config.robot_state, m.model.q_names, m.model.q_lower, m.model.q_upper);
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
  m.q0 = q0;

  m.claimDomain(*this);
  // Opened before the loop (an unwritable --log is an error at start, LogError) but after the probe:
  // a refused second controller never truncates the log of the one that runs.
  if (!config.log_csv.empty()) {
    m.log = std::make_unique<TimeseriesLog>(m.model, config.log_csv);
    m.log_row.q.setZero(m.model.nq);
    m.log_row.qdot.setZero(m.model.nq);
  }
  // The robot port and the onboard controller, after the probe too (a refused controller never
  // commands the robot), and before the readers: the first cycle follows their creation at once, as
  // it always did (a late-joiner sample is not yet there when a resumed controller starts holding).
  OnboardOptions oo;
  oo.input_timeout = config.input_timeout;
  oo.max_target_distance = config.max_target_distance;
  m.outbox = std::make_unique<bus::Outbox>("reflex_controller");
  RobotPort* port = m.makeRobotPort(q0, deadline);
  m.ctl = std::make_unique<OnboardController>(m.model, m.cm, *port, q0, oo);
  m.makeTopics();
  // Lateness percentiles: at most the first 10 minutes (or the whole run) are kept.
  const double expected_cycles =
      (config.duration > 0.0 ? std::min(config.duration, 600.0) : 600.0) / m.cm.params.period + 10.0;
  stats_.lateness_us.reserve(static_cast<std::size_t>(expected_cycles));
}

ControllerNode::~ControllerNode() = default;

bus::Participant& ControllerNode::bus() { return *impl_->participant; }
const std::string& ControllerNode::robotStateNote() const { return impl_->state_note; }
const std::string& ControllerNode::robotInterfaceNote() const { return impl_->interface_note; }
const std::string& ControllerNode::controllerConfigNote() const { return impl_->config_note; }
const Protection& ControllerNode::protection() const { return impl_->protection; }
std::string ControllerNode::logFailure() const { return impl_->log_error; }
const std::string& ControllerNode::peerRefusal() const { return impl_->peer_refusal; }

void ControllerNode::stop() noexcept { impl_->stop = true; }

bool ControllerNode::notePeerController(const msg::ControllerProtection& other,
                                        const std::array<unsigned char, 12>& them) {
  Impl& m = *impl_;
  const std::int64_t stamp = other.header().stamp_ns();
  const bool they_were_first =
      stamp < m.protection_stamp_ns || (stamp == m.protection_stamp_ns && them < m.own_participant);
  if (they_were_first) {
    m.peer_refusal = "another controller ('" + other.header().source() + "', robot '" + other.robot() +
                     "') already runs on DDS domain " + std::to_string(m.participant->domainId()) +
                     "; refusing to run a second one (two controllers would both publish the robot's joint "
                     "states): stop it, or use another --domain";
    return true;
  }
  // A later one: it refuses as soon as it sees this one. Said once (stderr), counted always.
  if (stats_.peer_controller_samples++ == 0) {
    std::fprintf(stderr,
                 "reflex_controller: WARNING: another controller ('%s', robot '%s') appeared on this DDS domain "
                 "(it refuses to start if it saw this one in time; else two controllers publish joint states)\n",
                 other.header().source().c_str(), other.robot().c_str());
  }
  return false;
}
void ControllerNode::requestEstopReset() noexcept { impl_->reset = true; }

void ControllerNode::Impl::publishHeartbeat(msg::ModuleState state) {
  const double t = nowSeconds(CLOCK_MONOTONIC);
  int used = std::snprintf(loop.detail_buf, sizeof(loop.detail_buf), "%s", loop.robot_stale_text);
  auto append = [&](const char* fmt, auto... args) {
    if (used < 0 || static_cast<std::size_t>(used) >= sizeof(loop.detail_buf)) return;
    const int k = std::snprintf(loop.detail_buf + used, sizeof(loop.detail_buf) - static_cast<std::size_t>(used), fmt,
                                used > 0 ? "; " : "", args...);
    if (k > 0) used += k;
  };
  if (dds && t - loop.last_other_writer_t <= kRobotProblemWindow)
    append("%sIGNORING a second %s writer %s (%llu samples; the robot writer is %s)", dds->stateTopic(),
           dds->otherWriter(), static_cast<unsigned long long>(dds->rejectedByCause()[kRobotCauseOtherWriter]),
           dds->boundWriter());
  if (dds && t - loop.last_robot_reject_t <= kRobotProblemWindow)
    append("%s%llu robot states rejected, the latest: %s", static_cast<unsigned long long>(loop.bad_seen),
           dds->lastBadRejection());
  loop.detail.assign(loop.detail_buf);  // within the reserved capacity
  msg::Heartbeat& hb = heartbeat_out_msg;
  hb.state(state);
  hb.detail().assign(loop.detail);  // within the reserved capacity
  heartbeat_out->push(hb);
  outbox->notify();
}

bool ControllerNode::Impl::takeInputs(ControllerNode& node, double t_now, const char*& last_rejection) {
  // 1. Inputs (poll; never block), handed to the onboard controller by value.
  msg::HandTargets& targets = targets_msg;
  bus::dds::SampleInfo targets_info;
  if (targets_reader->takeLatest(targets, &targets_info)) {
    const ParticipantId writer = participantOf(targets_info);
    if (!have_target_writer || writer != target_writer) ctl->newTargetSource();
    target_writer = writer;
    have_target_writer = true;
    const msg::HandTarget* hands[2] = {&targets.left(), &targets.right()};
    std::array<HandCommand, 2> commands;
    for (int a = 0; a < 2; ++a) {
      const auto& p = hands[a]->position_base();
      commands[a].status = hands[a]->status() == msg::TARGET_GIVEN ? HandStatus::kGiven : HandStatus::kNoTarget;
      commands[a].target_B = Eigen::Vector3d(p.x(), p.y(), p.z());
    }
    ctl->setHandTargets(commands, t_now);
  }
  msg::MotionPriority prio;
  if (priority_reader->takeLatest(prio)) {
    ctl->setPriority(prio.priority() == msg::PRIORITY_LEFT_HIGHER    ? MotionPriority::kLeftHigher
                     : prio.priority() == msg::PRIORITY_RIGHT_HIGHER ? MotionPriority::kRightHigher
                                                                     : MotionPriority::kEqual);
  }
  // A heartbeat is a sign of life of the target source only if the participant that wrote the
  // targets wrote it too, in state RUNNING; the name it carries is not looked at.
  bus::dds::SampleInfo hb_info;
  while (heartbeat_reader->takeNext(heartbeat_msg, &hb_info)) {
    if (have_target_writer && heartbeat_msg.state() == msg::STATE_RUNNING && participantOf(hb_info) == target_writer)
      ctl->noteSourceHeartbeat(t_now);
  }
  // Another controller on the domain (both started at the same instant, so neither saw the
  // other at start): loud once, counted.
  bus::dds::SampleInfo peer_info;
  bool yield_to_peer = false;
  while (protection_reader->takeNext(peer_msg, &peer_info)) {
    const ParticipantId them = participantOf(peer_info);
    if (them != own_participant) yield_to_peer |= node.notePeerController(peer_msg, them);
  }
  if (yield_to_peer) return false;  // discovered late: the earlier controller keeps the domain (peerRefusal())
  schema_scratch.clear();
  schema_reader->takeAll(schema_scratch);
  for (const auto& change : schema_scratch) {
    BodySchemaRequest rq;
    rq.operation = change.operation() == msg::SCHEMA_DETACH ? BodySchemaRequest::Operation::kDetach
                                                            : BodySchemaRequest::Operation::kAttach;
    rq.enabled = change.enabled();
    rq.name = &change.segment_name();
    rq.parent_link = &change.parent_link();
    rq.a_L = Eigen::Vector3d(change.point_a().x(), change.point_a().y(), change.point_a().z());
    rq.b_L = change.shape() == msg::SHAPE_SPHERE
                 ? rq.a_L
                 : Eigen::Vector3d(change.point_b().x(), change.point_b().y(), change.point_b().z());
    rq.radius = change.radius();
    rq.is_virtual = change.virtual_segment();
    rq.motion_priority = change.motion_priority();
    const BodySchemaOutcome& outcome = ctl->changeBodySchema(rq);
    if (outcome.rejected()) {
      // Formatted into a fixed buffer and printed at most LogLimiter's rate: a flood of bad
      // segments is counted (targets_rejected) but cannot flood stderr.
      std::snprintf(schema_line, sizeof(schema_line), "controller: %s", outcome.text);
      schema_log.print(stderr, schema_line);
    }
  }
  msg::WalkCommand walk;
  if (walk_reader->takeLatest(walk))
    ctl->walkCommand(walk.stop(), walk.goal_x(), walk.goal_y(), walk.goal_yaw(), walk.speed());
  if (reset.exchange(false)) ctl->requestEstopReset();
  // The latest refusal among this cycle's inputs (ControlStatus.last_rejection): robot states are
  // taken after the behavior inputs above, so a refused one is the latest.
  last_rejection = nullptr;
  if (const OnboardCounts& c = ctl->report().counts; c.targets_rejected != rejections_seen) {
    rejections_seen = c.targets_rejected;
    last_rejection = rejectCauseName(static_cast<RejectCause>(c.last_rejection));
  }
  if (dds && dds->poll() > 0) {
    // Every cause that rejected a state since the last poll is named (its latest sample): one cycle
    // can take several bad states when the robot's samples queue up behind a late cycle.
    const BusRobotPort::CauseCounts by_cause = dds->rejectedByCause();
    for (std::size_t c = 0; c < by_cause.size(); ++c) {
      if (by_cause[c] == robot_named[c]) continue;
      robot_named[c] = by_cause[c];
      std::snprintf(schema_line, sizeof(schema_line), "controller: %s", dds->rejectionOf(static_cast<int>(c)));
      robot_log[c].print(stderr, schema_line);
    }
    last_rejection = robotStateCauseName(dds->lastCause());
    const std::uint64_t other = dds->rejectedByCause()[kRobotCauseOtherWriter];
    const std::uint64_t bad = dds->rejectedTotal() - other;
    if (bad != loop.bad_seen) loop.last_robot_reject_t = t_now;
    loop.bad_seen = bad;
    if (other != loop.other_writer_seen) {
      loop.last_other_writer_t = t_now;
      const bool first = loop.other_writer_seen == 0;
      loop.other_writer_seen = other;
      if (first) {  // a second writer is said at once (stderr above, heartbeat now), not at 2 Hz
        publishHeartbeat(msg::STATE_RUNNING);
        loop.last_heartbeat = t_now;
      }
    }
  }

  return true;
}

/// The robot state turned fresh or stale (or the first cycle): said at once (stderr, heartbeat), not
/// at the next 2 Hz heartbeat.
void ControllerNode::Impl::sayRobotState(bool ok, double t_now) {
  // Said at once (stderr, heartbeat), not at the next 2 Hz heartbeat.
  loop.robot_ok = ok;
  loop.said_robot = true;
  if (ok) {
    loop.robot_stale_text[0] = '\0';
    if (dds) {
      std::snprintf(schema_line, sizeof(schema_line),
                    "reflex_controller: robot state fresh (seq %llu): commanding the robot",
                    static_cast<unsigned long long>(dds->stateSeq()));
      robot_state_log.print(stderr, schema_line);
    }
  } else {
    char text[200];
    std::snprintf(text, sizeof(text), "robot state stale: %s on %s (timeout %.0f ms); command frozen, the robot holds",
                  dds && dds->haveState() ? "no fresh state" : "no state yet", dds ? dds->stateTopic() : "",
                  config.robot_timeout * 1e3);
    std::snprintf(loop.robot_stale_text, sizeof(loop.robot_stale_text), "%s", text);
    std::snprintf(schema_line, sizeof(schema_line), "reflex_controller: %s", text);
    robot_state_log.print(stderr, schema_line);
  }
  publishHeartbeat(msg::STATE_RUNNING);
  loop.last_heartbeat = t_now;
}

/// The exit line's figures after a step.
void ControllerNode::Impl::recordStats(const CycleReport& rep, NodeStats& stats_) {
  const OnboardCounts& counts = rep.counts;
  if (rep.robot_state_ok) stats_.min_distance = std::min(stats_.min_distance, rep.min_distance);
  stats_.estop_count = counts.estop_count;
  stats_.guard_count = counts.guard_count;
  stats_.targets_received = counts.targets_received;
  stats_.targets_rejected = counts.targets_rejected;
  stats_.rejected = counts.rejected;
  stats_.stale_events = counts.stale_events;
  stats_.robot_stale_events = counts.robot_stale_events;
  stats_.robot_stale_cycles = counts.robot_stale_cycles;
  stats_.robot_stale_at_exit = !rep.robot_state_ok;
  if (dds) recordPortStats(stats_);
}

/// The robot port's counts (--robot dds, ros2, unitree_hg) for the exit line.
void ControllerNode::Impl::recordPortStats(NodeStats& stats_) const {
  stats_.robot_states_accepted = dds->acceptedStates();
  stats_.robot_states_rejected_by_cause = dds->rejectedByCause();
  stats_.robot_states_rejected = dds->rejectedTotal();
  stats_.robot_writer_changes = dds->writerChanges();
  stats_.robot_commands = dds->commandsSent();
}

/// 4. The cycle's outputs (joint state, status, the --log row) and figures. Joint state: the
/// kinematic robot after the step, or the robot's measured state the step answered (nothing while
/// the robot state is stale).
void ControllerNode::Impl::publishCycle(const CycleReport& rep, const char* last_rejection, double t, double t_now,
                                        double last_start, double lateness_us, NodeStats& stats_) {
  const ControlResult cr = rep.result;
  const OnboardCounts& counts = rep.counts;
  const ControllerData& data = ctl->data();
  const double period = cm.params.period;
  if (rep.robot_state_ok) {
    const Eigen::VectorXd& q = kinematic ? kinematic->positions() : ctl->measuredPositions();
    for (int i = 0; i < model.nq; ++i) {
      joint_msg.positions()[i] = q[i];
      joint_msg.velocities()[i] = cr == ControlResult::kFrozen ? 0.0 : data.qdot[i];
    }
    joint_out->push(joint_msg);
  }
  msg::ArmStatus* arms[2] = {&status_msg.left(), &status_msg.right()};
  for (int a = 0; a < 2; ++a) {
    const ArmReport& s = rep.arms[a];
    arms[a]->blend_f(s.f);
    arms[a]->distance(std::isfinite(s.distance) ? s.distance : msg::NO_PAIR_DISTANCE);
    arms[a]->zone(toMsg(s.zone));
    arms[a]->estop_latched(rep.estop != EstopState::kClear);
    // Cleared when the arm has no pair this cycle (control.idl): never a previous cycle's names.
    // Assigned in place (no temporary string): no allocation once the longest name was held.
    arms[a]->closest_segment_a().assign(s.segment_a != nullptr ? s.segment_a : "");
    arms[a]->closest_segment_b().assign(s.segment_b != nullptr ? s.segment_b : "");
  }
  status_msg.arm_distance(std::isfinite(rep.arm_distance) ? rep.arm_distance : msg::NO_PAIR_DISTANCE);
  status_msg.rejected_hand_targets(counts.hand_targets_rejected);
  status_msg.rejected_body_schema(counts.schema_rejected);
  status_msg.rejected_walk_commands(counts.walk_rejected);
  status_msg.rejected_robot_states(stats_.robot_states_rejected);
  if (last_rejection != nullptr) {
    status_msg.last_rejection().assign(last_rejection);  // fits the reserved capacity
    stats_.last_rejection = last_rejection;
  }
  const double compute_us = (nowSeconds(CLOCK_MONOTONIC) - t_now) * 1e6;
  if (compute_us > period * 1e6) ++stats_.overruns;
  status_msg.cycle_period_us((t_now - last_start) * 1e6);
  status_msg.compute_time_us(compute_us);
  status_msg.lateness_us(lateness_us);
  status_msg.overrun_count(stats_.overruns);
  status_out->push(status_msg);
  outbox->notify();
  ++stats_.cycles;
  stats_.max_lateness_us = std::max(stats_.max_lateness_us, lateness_us);
  if (stats_.lateness_us.size() < stats_.lateness_us.capacity()) stats_.lateness_us.push_back(lateness_us);
  if (log && rep.robot_state_ok) {  // a copy into the ring: no allocation, no I/O; a full ring is counted
    SimSample& s = log_row;
    recordCycle(s, t, data, rep);
    s.commands = rep.commands;
    if (!std::isfinite(rep.min_distance)) s.min_distance = msg::NO_PAIR_DISTANCE;
    s.wall_time = nowSeconds(CLOCK_REALTIME);
    s.q = kinematic ? kinematic->positions() : ctl->measuredPositions();
    log->push(s);
  }
}

/// After the loop: the robot left (unitree_hg: the arm_sdk weight ramped out), the last heartbeat,
/// the outbox and the log closed, their figures kept.
void ControllerNode::Impl::finishRun(NodeStats& stats_) {
  const double period = cm.params.period;
  // Leaving the robot: with unitree_hg the arm_sdk weight ramps out (finish() blocks for the ramp time).
  if (dds) {
    dds->finish(period);
    if (const auto* hg = dynamic_cast<const UnitreeHgPort*>(dds.get())) {
      stats_.arm_sdk_weight = hg->weight();
      stats_.arm_sdk_max_weight_step = hg->maxWeightStep();
    }
    recordPortStats(stats_);  // the commands of the ramp out too
  }
  publishHeartbeat(msg::STATE_STOPPING);
  outbox->close();  // writes what is queued (heartbeats first: the STOPPING one goes out), 1 s at most
  const bus::OutboxStats ob = outbox->stats();
  stats_.bus_written = ob.written;
  stats_.bus_write_failures = ob.write_failures;
  stats_.bus_dropped = ob.dropped;
  stats_.bus_stalls = ob.stalls;
  stats_.bus_longest_write_s = ob.longest_write_s;
  stats_.bus_longest_topic = ob.longest_topic;
  if (log) {
    log->close();
    log_error = log->error();
    stats_.log_rows = log->writtenRows();
    stats_.log_dropped = log->droppedRows();
  }
}

void ControllerNode::run() {
  Impl& m = *impl_;
  OnboardController& ctl = *m.ctl;
  const double period = m.cm.params.period;
  const auto period_ns = static_cast<long>(std::llround(period * 1e9));
  timespec next{};
  clock_gettime(CLOCK_MONOTONIC, &next);
  const double t_start = nowSeconds(CLOCK_MONOTONIC);
  double last_start = t_start;
  if (m.state_file && m.state_file->loaded()) {
    // Resumed from a saved robot state (a restart after a crash): the hands hold where they are
    // (targets at their current positions, avoidance active) until the target source speaks, and the
    // source gets the same grace as silence during a run: after input_timeout without a sign of it
    // the hands retract as usual. Without this the first cycle would already retract at full speed.
    ctl.holdHandsHere(t_start);
  }

  m.loop = Impl::Loop{};
  m.loop.detail.reserve(kDetailBytes);
  m.publishHeartbeat(msg::STATE_RUNNING);

  const bool on_state = m.config.trigger == "state";  // one cycle per arriving robot state (run()'s contract)
  while (!m.stop && !m.participant->stopRequested()) {
    next.tv_nsec += period_ns;
    while (next.tv_nsec >= 1000000000L) {
      next.tv_nsec -= 1000000000L;
      ++next.tv_sec;
    }
    bool state_woke = false;
    if (on_state) {
      // The next robot state, or the period's end (the deadline `next`): whichever comes first.
      for (;;) {
        timespec ts{};
        clock_gettime(CLOCK_MONOTONIC, &ts);
        const long long left_ns =
            (static_cast<long long>(next.tv_sec) - ts.tv_sec) * 1000000000LL + (next.tv_nsec - ts.tv_nsec);
        if (left_ns <= 0) break;
        if (m.dds->waitForState(std::chrono::nanoseconds(left_ns))) {
          state_woke = true;
          break;
        }
      }
    } else {
      clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &next, nullptr);
    }
    const double t_now = nowSeconds(CLOCK_MONOTONIC);
    const double scheduled = static_cast<double>(next.tv_sec) + 1e-9 * static_cast<double>(next.tv_nsec);
    const double lateness_us = state_woke ? 0.0 : std::max(0.0, (t_now - scheduled) * 1e6);
    if (on_state) clock_gettime(CLOCK_MONOTONIC, &next);  // the longest wait counts from this cycle's start
    const double t = t_now - t_start;
    if (m.config.duration > 0.0 && t >= m.config.duration) break;

    // 1. Inputs (poll; never block), handed to the onboard controller by value.
    const char* last_rejection = nullptr;
    if (!m.takeInputs(*this, t_now, last_rejection)) break;

    // 2.-3. Staleness, priority, control (allocation-free) and the robot port: one step.
    // A cycle started by a sample on the state topic spans the time since the previous cycle, at most
    // the robot's state interval (and, in step(), one period): a robot that reaches `positions` by its
    // next state never moves faster than v_max, and a flood of samples (another writer, rejected
    // states) advances walking and the trajectory no faster than real time. One started by the
    // period's end spans the period, as the timer's.
    double span = period;
    if (state_woke) {
      span = std::max(t_now - last_start, 1e-6);
      if (m.dds->stateInterval() > 0.0) span = std::min(span, m.dds->stateInterval());
    }
    const CycleReport& rep = ctl.step(t_now, span);
    if (rep.robot_state_ok != m.loop.robot_ok || !m.loop.said_robot) m.sayRobotState(rep.robot_state_ok, t_now);
    // The robot state is persisted before it is published: what any reader saw survives a crash.
    if (m.state_file && !m.state_file->save(m.kinematic->positions())) ++stats_.state_write_errors;
    m.recordStats(rep, stats_);

    m.publishCycle(rep, last_rejection, t, t_now, last_start, lateness_us, stats_);
    last_start = t_now;
    if (t_now - m.loop.last_heartbeat >= 0.5) {
      m.publishHeartbeat(msg::STATE_RUNNING);
      m.loop.last_heartbeat = t_now;
    }
    // Fell behind by more than a period: re-anchor the schedule instead of bursting.
    if (lateness_us > period * 1e6) clock_gettime(CLOCK_MONOTONIC, &next);
  }
  m.finishRun(stats_);
}

}  // namespace reflex::control_node
