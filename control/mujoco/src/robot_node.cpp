// reflex_mujoco's DDS adapter (see robot_node.hpp).
#include "reflex/common/error.hpp"
#include "reflex/mujoco/robot_node.hpp"
#include "reflex/common/files.hpp"

#include "reflex/control/urdf_loader.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <sstream>
#include <stdexcept>

namespace reflex::mujoco {
namespace {

constexpr std::size_t kMaxLatencySamples = 1000000;

constexpr std::int64_t kMaxCatchUp = 20;                  // periods run at once after a late wake-up
constexpr std::int64_t kHeartbeatPeriodNs = 500'000'000;  // as bus::HeartbeatPublisher's default

std::int64_t monotonicNs() {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * 1000000000 + ts.tv_nsec;
}

double monotonicSeconds() {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
}

std::string fixed(double v, int digits) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.*f", digits, v);
  return buf;
}

int robotPairCount(const control::Model& model) {
  int n = 0;
  for (const auto& pair : model.pairs) n += pair.b < model.num_robot_segments ? 1 : 0;
  return n;
}

double percentile(std::vector<double> v, double p) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  return v[std::min(v.size() - 1, static_cast<std::size_t>(p * static_cast<double>(v.size())))];
}

}  // namespace

Eigen::VectorXd parseInitialConfiguration(const control::Model& model, const std::vector<std::string>& entries) {
  Eigen::VectorXd q(model.nq);
  for (int qi = 0; qi < model.nq; ++qi) q[qi] = std::clamp(0.0, model.q_lower[qi], model.q_upper[qi]);
  for (const auto& entry : entries) {
    const auto eq = entry.find('=');
    if (eq == std::string::npos) throw reflex::Error("--q '" + entry + "': expected joint=value");
    const std::string name = entry.substr(0, eq), text = entry.substr(eq + 1);
    const int qi = model.qIndex(name);
    if (qi < 0) throw reflex::Error("--q '" + entry + "': unknown joint '" + name + "'");
    double v = 0.0;
    if (!common::parseFiniteNumber(text, v))
      throw reflex::Error("--q '" + entry + "': '" + text + "' is not a finite number");
    if (v < model.q_lower[qi] || v > model.q_upper[qi])
      throw reflex::Error("--q '" + entry + "': outside the joint limits [" + std::to_string(model.q_lower[qi]) + ", " +
                          std::to_string(model.q_upper[qi]) + "]");
    q[qi] = v;
  }
  return q;
}

RobotNode::RobotNode(const NodeConfig& config) : config_(config) {
  if (!(config.period > 0.0) || !std::isfinite(config.period) || config.period > 0.1)
    throw reflex::Error("--period " + std::to_string(config.period) + " s: must be in (0, 0.1]");
  if (!(config.duration >= 0.0) || !std::isfinite(config.duration))
    throw reflex::Error("--duration " + std::to_string(config.duration) + " s: must be >= 0");
  const double ratio = config.period / config.mjcf.timestep;
  substeps_ = static_cast<int>(std::lround(ratio));
  if (!(config.mjcf.timestep > 0.0) || substeps_ < 1 || std::abs(ratio - substeps_) > 1e-6)
    throw reflex::Error("--timestep " + std::to_string(config.mjcf.timestep) + " s: the period " +
                        std::to_string(config.period) + " s must be a whole multiple of it");
  if (config.interface != "reflex" && config.interface != "unitree_hg")
    throw reflex::Error("--interface '" + config.interface + "': use 'reflex' or 'unitree_hg'");
  if (config.interface == "unitree_hg" && config.period < 0.001)
    throw reflex::Error("--period " + std::to_string(config.period) +
                        " s: with --interface unitree_hg at least 1 ms (the tick counts milliseconds)");
  if (config.interface != "unitree_hg" && !config.joint_map.empty())
    throw reflex::Error("--joint-map '" + config.joint_map + "' is for --interface unitree_hg");
  model_ = control::loadModel(config.urdf, control::loadCollisionConfigFor(config.urdf, config.collision));
  const Eigen::VectorXd q0 = parseInitialConfiguration(model_, config.initial);
  robot_ = std::make_unique<MujocoRobot>(model_, config.mjcf, q0);
  bus::BusConfig bc;
  bc.module_name = config.module_name;
  bc.domain_id = config.domain_id;
  bc.profiles_file = config.profiles_file;
  bc.participant_profile = config.participant_profile;
  bus_ = std::make_unique<bus::Participant>(bc);
  if (config.interface == "unitree_hg") {
    hg_ = std::make_unique<HgDouble>(model_, unitree_hg::hgJointMapFor(config.urdf, config.joint_map), q0, *bus_);
  } else {
    state_writer_ = &bus_->makeWriter<msg::RobotState>();
    command_reader_ = &bus_->makeReader<msg::JointCommand>();
  }
  contacts_writer_ = &bus_->makeWriter<msg::RobotContacts>();
  heartbeat_ = std::make_unique<bus::HeartbeatPublisher>(*bus_);
  stats_.command_latency_us.reserve(4096);
}

std::string RobotNode::summary() const {
  const mjModel& m = robot_->mjModelRef();
  double mass = 0.0;
  for (int b = 0; b < m.nbody; ++b) mass += m.body_mass[b];
  std::ostringstream os;
  os << "robot '" << model_.name << "': " << m.nbody << " bodies, " << m.njnt << " joints, " << m.ngeom
     << " geoms (collision capsules / spheres / convex pieces), " << m.npair << " contact pairs (from "
     << robotPairCount(model_) << " checked segment pairs), " << m.nu << " actuators, mass " << fixed(mass, 2)
     << " kg, timestep " << fixed(m.opt.timestep * 1e3, 3) << " ms x " << substeps_ << " per period "
     << fixed(config_.period * 1e3, 3) << " ms, margin = gap = " << fixed(config_.mjcf.margin * 1e3, 2) << " mm\n";
  for (const auto& r : inertialRepairs(model_, config_.mjcf)) os << "REPAIRED " << r << "\n";
  os << "servos (PD + bias feed-forward): joint class kp kd effort armature damping\n";
  const auto& gains = robot_->gains();
  for (int qi = 0; qi < model_.nq; ++qi) {
    const auto& g = gains[qi];
    os << "  " << model_.q_names[qi] << (g.joint_class == JointClass::kBase ? " base " : " limb ") << fixed(g.kp, 1)
       << " " << fixed(g.kd, 2) << " " << fixed(g.effort, 0) << " " << g.armature << " " << g.damping << "\n";
  }
  return os.str();
}

void RobotNode::run() {
  const MujocoRobot& robot = *robot_;
  const RobotMeasurement& meas = robot.measurement();
  msg::RobotState state;
  state.names(model_.q_names);
  state.positions().resize(model_.nq);
  state.velocities().resize(model_.nq);
  state.efforts().resize(model_.nq);
  msg::RobotContacts contacts;
  contacts.contacts().reserve(model_.pairs.size());
  msg::JointCommand command;
  stats_.worst_contacts.clear();

  const auto period_ns = static_cast<std::int64_t>(std::llround(config_.period * 1e9));
  const std::int64_t t_start = monotonicNs();
  std::int64_t next = t_start;         // start of the next period [ns, CLOCK_MONOTONIC]
  std::int64_t simulated_periods = 0;  // periods of physics run since t_start
  const double t_end = config_.duration > 0.0 ? monotonicSeconds() + config_.duration : 0.0;
  // The heartbeat (reflex/heartbeat) from this loop: setState publishes at once; every 500 ms.
  heartbeat_->setState(msg::STATE_RUNNING);
  std::int64_t next_heartbeat = t_start + kHeartbeatPeriodNs;
  while (!bus_->stopRequested() && (t_end == 0.0 || monotonicSeconds() < t_end)) {
    // Sleep to the start of this period. Simulated time follows wall time: a late period runs the
    // periods it missed (an overrun), up to kMaxCatchUp; time beyond that is lost (counted).
    const timespec wake{static_cast<time_t>(next / 1000000000), static_cast<long>(next % 1000000000)};
    clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &wake, nullptr);
    const std::int64_t now_mono = monotonicNs();
    const double late_us = 1e-3 * static_cast<double>(now_mono - next);
    stats_.max_lateness_us = std::max(stats_.max_lateness_us, late_us);
    const std::int64_t due = (now_mono - t_start) / period_ns + 1;  // periods that should have run by now
    std::int64_t periods = due - simulated_periods;
    if (periods > 1) ++stats_.overruns;
    if (periods > kMaxCatchUp) {
      stats_.lost_periods += static_cast<std::uint64_t>(periods - kMaxCatchUp);
      simulated_periods += periods - kMaxCatchUp;
      periods = kMaxCatchUp;
    }
    periods = std::max<std::int64_t>(periods, 1);
    simulated_periods += periods;
    next = t_start + simulated_periods * period_ns;

    // 1. Commands: every sample that arrived, oldest first (each counted); the last accepted one rules.
    std::int64_t now_ns = bus::nowNs();
    if (hg_) hg_->takeCommands(*robot_, now_ns);
    while (command_reader_ != nullptr && command_reader_->takeNext(command)) {
      CommandInput in;
      in.names = &command.names();
      in.positions = &command.positions();
      in.velocities = &command.velocities();
      in.valid_until_ns = command.valid_until_ns();
      in.seq = command.header().seq();
      in.state_stamp_ns = command.state_stamp_ns();
      if (robot_->offerCommand(in, now_ns) == CommandVerdict::kAccepted && in.state_stamp_ns > 0 &&
          stats_.command_latency_us.size() < kMaxLatencySamples)
        stats_.command_latency_us.push_back(1e-3 * static_cast<double>(now_ns - in.state_stamp_ns));
    }

    // 2. Physics.
    robot_->step(substeps_ * static_cast<int>(periods), now_ns);
    stats_.periods += static_cast<std::uint64_t>(periods);

    // 3. The measured state and the judge's contacts of the same instant.
    for (int qi = 0; qi < model_.nq; ++qi) {
      state.positions()[qi] = meas.q[qi];
      state.velocities()[qi] = meas.qdot[qi];
      state.efforts()[qi] = meas.effort[qi];
    }
    if (hg_) {
      hg_->publishState(
          meas, static_cast<std::int64_t>(std::llround(static_cast<double>(simulated_periods) * config_.period * 1e3)));
      contacts.state_seq(hg_->tick());
    } else {
      state.applied_command_seq(meas.applied_command_seq);
      state.holding(meas.holding);
      state_writer_->publish(state);
      contacts.state_seq(state_writer_->lastSeq());
    }
    ++stats_.states_published;
    contacts.contacts().clear();
    for (const auto& c : meas.contacts) {
      msg::SegmentContact sc;
      sc.segment_a(model_.segments[c.seg_a].name);
      sc.segment_b(model_.segments[c.seg_b].name);
      sc.distance(c.distance);
      contacts.contacts().push_back(sc);
      bool known = false;
      for (auto& w : stats_.worst_contacts)
        if (w.seg_a == c.seg_a && w.seg_b == c.seg_b) {
          w.distance = std::min(w.distance, c.distance);
          known = true;
        }
      if (!known) stats_.worst_contacts.push_back(c);
    }
    if (!meas.contacts.empty()) ++stats_.contact_periods;
    contacts.total_contact_steps(meas.contact_steps);
    contacts_writer_->publish(contacts);
    if (now_mono >= next_heartbeat) {
      heartbeat_->setState(msg::STATE_RUNNING);
      next_heartbeat = now_mono + kHeartbeatPeriodNs;
    }
  }
  heartbeat_->setState(msg::STATE_STOPPING);
}

std::string RobotNode::exitSummary() const {
  const RobotMeasurement& meas = robot_->measurement();
  const CommandCounters& c = robot_->counters();
  const double dt = robot_->timestep();
  std::ostringstream os;
  os << "steps " << meas.steps << " (" << fixed(meas.steps * dt, 3) << " s simulated), periods " << stats_.periods
     << ", overruns " << stats_.overruns << " (periods lost " << stats_.lost_periods << "), max lateness "
     << fixed(stats_.max_lateness_us, 0) << " us"
     << ", contact steps " << meas.contact_steps << ", contact periods " << stats_.contact_periods
     << ", commands applied " << c.accepted << " rejected " << c.rejected() << " (unknown name " << c.rejected_unknown
     << ", length " << c.rejected_length << ", not finite " << c.rejected_not_finite << ", duplicate "
     << c.rejected_duplicate << ", empty " << c.rejected_empty << ", expired " << c.rejected_expired << "), clamped "
     << c.position_clamped << ", holds begun " << c.holds << ", hold time " << fixed(meas.hold_steps * dt, 3)
     << " s, unstable steps " << meas.unstable_steps;
  os << ", command latency p50 " << fixed(percentile(stats_.command_latency_us, 0.5), 0) << " us p99 "
     << fixed(percentile(stats_.command_latency_us, 0.99), 0) << " us over " << stats_.command_latency_us.size()
     << " commands";
  if (hg_) os << ", " << hg_->summary();
  for (const auto& w : stats_.worst_contacts)
    os << "\ncontact " << model_.segments[w.seg_a].name << "," << model_.segments[w.seg_b].name << " min distance "
       << fixed(w.distance * 1e3, 3) << " mm";
  return os.str();
}

}  // namespace reflex::mujoco
