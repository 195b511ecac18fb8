#include "reflex/control/scenarios.hpp"

#include "reflex/common/files.hpp"
#include "reflex/control/onboard.hpp"

#include <cerrno>
#include <algorithm>
#include <cmath>
#include <fstream>
#include <iomanip>
#include <limits>

namespace reflex::control {

bool ScenarioContext::attach(int slot, const std::string& link, const Eigen::Vector3d& a_L, const Eigen::Vector3d& b_L,
                             double radius, bool is_virtual, const std::vector<std::string>& ignore) {
  // A scenario that needs a link or segment this robot lacks is an error naming it, never a silent
  // skip (a missing l_hand used to drop the bar without a word).
  const int l = model.linkIndex(link);
  if (l < 0)
    throw ConfigError("the scenario attaches a segment to link '" + link + "', which robot '" + model.name +
                      "' does not have");
  std::uint64_t mask = 0;
  for (const auto& name : ignore) {
    const int s = model.segmentIndex(name);
    if (s < 0 || s >= model.num_robot_segments)
      throw ConfigError("the scenario's segment on '" + link + "' ignores segment '" + name + "', which robot '" +
                        model.name + "' does not have");
    mask |= std::uint64_t{1} << s;
  }
  return attachControllerSegment(model, cm, data, slot, l, a_L, b_L, radius, mask, is_virtual, q).attached;
}

void ScenarioContext::detach(int slot) {
  if (detachBodySchemaSegment(data.dist, slot)) data.dist.slots[static_cast<std::size_t>(slot)].is_virtual = false;
}

SimResult runScenario(const Model& model, const ControllerModel& cm, const Scenario& scenario,
                      const SimOptions& options) {
  KinematicScenarioPlant plant(restConfiguration(model, cm));
  return runScenario(model, cm, scenario, options, plant);
}

SimResult runScenario(const Model& model, const ControllerModel& cm_in, const Scenario& scenario,
                      const SimOptions& options, ScenarioPlant& plant) {
  ControllerModel cm = cm_in;
  cm.params.mode = options.mode;
  cm.params.estop = options.estop;
  // The same onboard controller as reflex_controller (onboard.hpp), on the plant's robot.
  const Eigen::VectorXd q0 = plant.positions();
  OnboardController controller(model, cm, plant.port(), q0);
  ControllerData& data = controller.data();
  Eigen::VectorXd q_before = q0;
  ScenarioContext ctx{model, data, cm, plant.positions()};
  ctx.camera_link = options.camera_link;
  ControlInput input;
  SimResult result;
  result.min_distance = std::numeric_limits<double>::infinity();
  result.min_virtual_distance = std::numeric_limits<double>::infinity();
  const double dt = cm.params.period;
  const auto steps = static_cast<std::uint64_t>(std::llround(scenario.duration / dt));
  if (options.record) result.samples.reserve(steps + 1);
  bool walk_started = false;
  for (std::uint64_t k = 0; k <= steps; ++k) {
    const double t = static_cast<double>(k) * dt;
    if (plant.awaitCycle(t, dt)) ++result.late_cycles;
    // What the plant did since the last cycle, every joint (the walking joints too): |dq| / (v_max dt)
    // over the interval between the two states.
    if (k > 0) {
      const double interval = plant.stateInterval(dt);
      for (int i = 0; i < model.nq; ++i)
        result.max_joint_speed_ratio = std::max(
            result.max_joint_speed_ratio, std::abs(plant.positions()[i] - q_before[i]) / (model.v_max[i] * interval));
    }
    if (scenario.script) scenario.script(t, input, ctx);
    controller.setControlInput(input, t);  // the script owns the whole input: never stale
    input.reset_estop = false;
    // Walking starts with the plant step of the cycle at walk_start (it does not change the control).
    const bool walk_now = scenario.walk_distance > 0.0 && t >= scenario.walk_start && k < steps;
    if (walk_now && !walk_started) {
      controller.startWalking(scenario.walk_distance, scenario.walk_speed);
      walk_started = true;
    }
    q_before = plant.positions();
    // One cycle: computeControl at the robot's q, then stepPlant (arms from the controller; legs,
    // heel and body from walking, which holds while the e-stop is latched or recovering and never
    // closes a pair that no arm can move).
    const CycleReport& rep = controller.step(t);
    if (!data.qdot.allFinite()) result.non_finite = true;
    if (rep.min_distance < result.min_distance) {
      result.min_distance = rep.min_distance;
      result.min_time = t;
      result.min_pair = rep.min_pair;
    }
    result.min_virtual_distance = std::min(result.min_virtual_distance, rep.virtual_distance);
    if (data.estop != EstopState::kClear) result.estop_fired = true;
    for (int i = 0; i < model.nq; ++i)
      result.max_command_speed_ratio =
          std::max(result.max_command_speed_ratio, std::abs(data.qdot[i]) / model.v_max[i]);
    result.max_joint_speed_ratio = std::max(result.max_joint_speed_ratio, result.max_command_speed_ratio);
    for (int a = 0; a < 2; ++a) {
      if (input.hands[a].status != HandStatus::kGiven) continue;
      const double err = (data.arms[a].hand_B - input.hands[a].target_B).norm();
      result.final_error[a] = err;
      if (err < 0.01 && result.reach_time[a] < 0.0) result.reach_time[a] = t;
      if (err >= 0.01) result.reach_time[a] = -1.0;  // must stay reached
    }
    if (options.record) {
      SimSample s;
      recordCycle(s, t, data, rep);
      s.commands = input.hands;
      s.q = q_before;  // the configuration this cycle computed from
      s.commanded = rep.robot_state_ok;
      s.q_command = controller.commandedPositions();
      result.samples.push_back(std::move(s));
    }
    ++result.cycles;
    result.guard_cycles = data.guard_count;
    result.robot_stale_cycles = rep.counts.robot_stale_cycles;
    if (k == steps) break;
    result.walking_holds = data.walking_hold_count;
  }
  return result;
}

std::array<ArmTracking, 2> computeTracking(const ControllerModel& cm, const SimResult& result) {
  std::array<ArmTracking, 2> out;
  const double dt = cm.params.period;
  constexpr int kMaxShift = 40;  // cycles: 0.2 s at 5 ms
  const auto& s = result.samples;
  for (int a = 0; a < 2; ++a) {
    const auto& arm = cm.arms[a];
    // Sum of squared errors of measured(k) against command(k - 1 - shift), per shift.
    std::array<double, kMaxShift + 1> sse{};
    std::array<std::uint64_t, kMaxShift + 1> count{};
    for (std::size_t k = 1; k < s.size(); ++k) {
      if (!s[k].commanded) continue;
      for (int shift = 0; shift <= kMaxShift; ++shift) {
        if (k < static_cast<std::size_t>(shift) + 1) break;
        const SimSample& c = s[k - 1 - static_cast<std::size_t>(shift)];
        if (!c.commanded || c.q_command.size() != s[k].q.size()) continue;
        for (int i = 0; i < arm.n; ++i) {
          const double e = s[k].q[arm.q[i]] - c.q_command[arm.q[i]];
          sse[shift] += e * e;
          ++count[shift];
          if (shift == 0) out[a].max_error = std::max(out[a].max_error, std::abs(e));
        }
      }
    }
    if (count[0] == 0) continue;
    out[a].cycles = count[0] / static_cast<std::uint64_t>(std::max(1, arm.n));
    out[a].rms_error = std::sqrt(sse[0] / static_cast<double>(count[0]));
    int best = 0;
    auto mean = [&](int shift) { return count[shift] ? sse[shift] / static_cast<double>(count[shift]) : 1e300; };
    for (int shift = 1; shift <= kMaxShift; ++shift)
      if (mean(shift) < mean(best)) best = shift;
    double frac = 0.0;
    if (best > 0 && best < kMaxShift) {
      const double y0 = mean(best - 1), y1 = mean(best), y2 = mean(best + 1);
      const double den = y0 - 2.0 * y1 + y2;
      if (den > 0.0) frac = std::clamp(0.5 * (y0 - y2) / den, -0.5, 0.5);
    }
    out[a].lag = (static_cast<double>(best) + frac) * dt;
  }
  return out;
}

namespace {

const char* zoneName(Zone z) {
  switch (z) {
    case Zone::kFree: return "free";
    case Zone::kYellow: return "yellow";
    case Zone::kOrange: return "orange";
    case Zone::kRed: return "red";
  }
  return "?";
}

std::string pairName(const Model& model, int pair) {
  if (pair < 0) return "";
  return model.segments[model.pairs[pair].a].name + "|" + model.segments[model.pairs[pair].b].name;
}

}  // namespace

void writeTimeseriesCsvHeader(const Model& model, std::ostream& out) {
  out << "time";
  const char* side[2] = {"left", "right"};
  for (const char* s : side)
    out << ',' << s << "_f," << s << "_distance," << s << "_pair," << s << "_zone," << s << "_force";
  out << ",estop,min_distance,min_pair,virtual_distance,arm_distance,wall_time";
  for (const char* s : side)
    out << ',' << s << "_status," << s << "_hand_x," << s << "_hand_y," << s << "_hand_z," << s << "_target_x," << s
        << "_target_y," << s << "_target_z," << s << "_ref_x," << s << "_ref_y," << s << "_ref_z";
  for (int i = 0; i < model.nq; ++i) out << ",q_" << model.q_names[i];
  out << '\n';
}

void writeTimeseriesCsvRow(const Model& model, const SimSample& s, std::ostream& out) {
  auto num = [](double v) { return std::isfinite(v) ? v : kNoPairDistance; };
  out << std::setprecision(9);
  out << s.t;
  for (int a = 0; a < 2; ++a)
    out << ',' << s.arms[a].f << ',' << num(s.arms[a].distance) << ',' << pairName(model, s.arms[a].closest_pair) << ','
        << zoneName(s.arms[a].zone) << ',' << s.arms[a].force;
  out << ',' << static_cast<int>(s.estop) << ',' << num(s.min_distance) << ',' << pairName(model, s.min_pair) << ','
      << num(s.virtual_distance) << ',' << num(s.arm_distance) << ',' << std::setprecision(16) << s.wall_time
      << std::setprecision(9);
  for (int a = 0; a < 2; ++a) {
    const bool given = s.commands[a].status == HandStatus::kGiven;
    out << ',' << (given ? "given" : "no_target");
    for (int i = 0; i < 3; ++i) out << ',' << s.arms[a].hand_B[i];
    for (int i = 0; i < 3; ++i) out << ',' << (given ? s.commands[a].target_B[i] : std::nan(""));
    for (int i = 0; i < 3; ++i) out << ',' << s.arms[a].reference_B[i];
  }
  for (int i = 0; i < model.nq; ++i) out << ',' << s.q[i];
  out << '\n';
}

void writeTimeseriesCsv(const Model& model, const ControllerModel& cm, const SimResult& result,
                        const std::string& path) {
  errno = 0;
  std::ofstream out(path);
  if (!out) throw ConfigError("time series: " + common::writeError(path, errno ? errno : EIO));
  writeTimeseriesCsvHeader(model, out);
  for (const auto& s : result.samples) writeTimeseriesCsvRow(model, s, out);
  errno = 0;
  out.close();  // flushes: a full disk (ENOSPC) is an error here, never a silently short file
  if (!out) throw ConfigError("time series: " + common::writeError(path, errno ? errno : EIO));
  (void)cm;
}

}  // namespace reflex::control
