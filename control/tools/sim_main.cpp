// reflex_sim: runs the paper's experiments on the kinematic robot (in process, simulated time) or on
// a robot over DDS in real time (--robot mujoco: it spawns reflex_mujoco; --robot dds: a robot already
// on the bus), through the same OnboardController and scenario scripts.
//   reflex_sim --list
//   reflex_sim SCENARIO --out DIR [--no-avoidance] [--mode one_dof|three_dof] [--robot kinematic|mujoco|dds]
// Writes DIR/timeseries.csv (one row per 5 ms cycle), DIR/postures.csv (capsules at a few instants),
// DIR/summary.txt, and PNG plots like the paper's figures (through python3-matplotlib). With a robot
// over DDS the summary adds the plant's figures (robot_summary below) and DIR/reflex_mujoco*.log holds
// the spawned robot's output.
#include "reflex/common/run_main.hpp"
#include "reflex/common/shipped.hpp"
#include "reflex/control_node/bus_plant.hpp"
#include "reflex/control/controller.hpp"
#include "reflex/control/scenarios.hpp"
#include "reflex/control/urdf_loader.hpp"
#include "reflex/common/files.hpp"

#include <CLI/CLI.hpp>

#include <cerrno>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <limits>
#include <optional>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <sstream>
#include <string>
#include <unistd.h>

namespace fs = std::filesystem;
using namespace reflex::control;

namespace {

/// Writes the capsules of the robot at the given samples (frame = position in `picks`).
void writePostures(const Model& model, const SimResult& result, const std::string& path,
                   const std::vector<std::size_t>& picks) {
  errno = 0;
  std::ofstream out(path);
  if (!out) throw ConfigError("postures: " + reflex::common::writeError(path, errno ? errno : EIO));
  out << "frame,time,segment,ax,ay,az,bx,by,bz,radius\n";
  KinematicsData kin(model);
  for (std::size_t f = 0; f < picks.size(); ++f) {
    const SimSample& s = result.samples[picks[f]];
    computeForwardKinematics(model, kin, s.q);
    for (int seg = 0; seg < model.num_robot_segments; ++seg) {
      const Segment& sg = model.segments[seg];
      for (int p = sg.first_primitive; p < sg.first_primitive + sg.num_primitives; ++p) {
        const Eigen::Isometry3d& X = kin.X_B_L[static_cast<std::size_t>(linkOf(sg, model.primitives[p]))];
        const Eigen::Vector3d a = X * model.primitives[p].a_L;
        const Eigen::Vector3d b = X * model.primitives[p].b_L;
        out << f << ',' << s.t << ',' << sg.name << ',' << a.x() << ',' << a.y() << ',' << a.z() << ',' << b.x() << ','
            << b.y() << ',' << b.z() << ',' << model.primitives[p].radius << '\n';
      }
    }
  }
  errno = 0;
  out.close();  // flushes: ENOSPC is an error here
  if (!out) throw ConfigError("postures: " + reflex::common::writeError(path, errno ? errno : EIO));
}

/// Closes a text output and throws naming it if anything written to it was lost.
void closeChecked(std::ofstream& out, const std::string& path) {
  errno = 0;
  out.close();
  if (!out) throw ConfigError(reflex::common::writeError(path, errno ? errno : EIO));
}

/// The exit status after the work: `status`, or 1 with a message if standard output was lost.
int finish(int status) {
  if (const std::string why = reflex::common::flushStandardOutput(); !why.empty()) {
    std::fprintf(stderr, "reflex_sim: error: %s\n", why.c_str());
    return 1;
  }
  return status;
}

std::vector<std::size_t> evenPicks(std::size_t n, int frames) {
  std::vector<std::size_t> picks;
  for (int f = 0; f < frames && n > 0; ++f)
    picks.push_back((n - 1) * static_cast<std::size_t>(f) / static_cast<std::size_t>(std::max(1, frames - 1)));
  return picks;
}

/// Reads the joint columns (q_<name>) and the time column of a time-series CSV (reflex_sim or
/// reflex_controller --log) into samples.
SimResult readTimeseries(const Model& model, const std::string& path) {
  if (const std::string why = reflex::common::inputFileProblem(path); !why.empty())
    throw ConfigError("time series " + why);
  std::ifstream in(path);
  if (!in) throw ConfigError(path + ": cannot open time series");
  std::string line;
  if (!std::getline(in, line)) throw ConfigError(path + ": empty time series");
  std::vector<std::string> cols;
  {
    std::stringstream ss(line);
    std::string c;
    while (std::getline(ss, c, ',')) cols.push_back(c);
  }
  std::vector<int> qcol(model.nq, -1);
  int tcol = -1;
  for (std::size_t i = 0; i < cols.size(); ++i) {
    if (cols[i] == "time") tcol = static_cast<int>(i);
    if (cols[i].rfind("q_", 0) == 0) {
      const int qi = model.qIndex(cols[i].substr(2));
      if (qi >= 0) qcol[qi] = static_cast<int>(i);
    }
  }
  if (tcol < 0) throw ConfigError(path + ": no 'time' column");
  for (int qi = 0; qi < model.nq; ++qi)
    if (qcol[qi] < 0) throw ConfigError(path + ": no column q_" + model.q_names[qi]);
  SimResult r;
  int row = 1;
  while (std::getline(in, line)) {
    ++row;
    std::vector<std::string> v;
    std::stringstream ss(line);
    std::string c;
    while (std::getline(ss, c, ',')) v.push_back(c);
    if (v.size() < cols.size()) throw ConfigError(path + ": row " + std::to_string(row) + " has too few values");
    SimSample s;
    s.t = std::stod(v[tcol]);
    s.q.resize(model.nq);
    for (int qi = 0; qi < model.nq; ++qi) s.q[qi] = std::stod(v[qcol[qi]]);
    r.samples.push_back(std::move(s));
  }
  return r;
}

std::string pairName(const Model& model, int pair) {
  if (pair < 0) return "none";
  return model.segments[model.pairs[pair].a].name + "-" + model.segments[model.pairs[pair].b].name;
}

/// The robot's landmarks the scenarios are placed by (ScenarioFrame), one line.
// "-x", "+y", or the direction's components when it is along no axis.
std::string direction(const Eigen::Vector3d& d) {
  for (int k = 0; k < 3; ++k)
    if (std::abs(std::abs(d[k]) - 1.0) < 1e-6) return std::string(d[k] > 0 ? "+" : "-") + "xyz"[k];
  std::ostringstream s;
  s << std::fixed << std::setprecision(3) << '(' << d.x() << ", " << d.y() << ", " << d.z() << ')';
  return s.str();
}

void printScenarioFrame(std::ostream& os, const Model& model, const ScenarioFrame& f) {
  auto mm = [](const Eigen::Vector3d& p) {
    std::ostringstream s;
    s << std::fixed << std::setprecision(0) << '(' << p.x() * 1000 << ", " << p.y() * 1000 << ", " << p.z() * 1000
      << ')';
    return s.str();
  };
  os << "robot " << model.name << ": chest " << mm(f.chest) << " mm, shoulders " << std::fixed << std::setprecision(0)
     << 2000 * f.half_width << " mm apart, arm " << f.arm_length * 1000 << " mm; scenarios "
     << (f.reference ? std::string("as written (the reference robot)")
                     : "scaled x " + std::to_string(f.scale.x()).substr(0, 5) + ", y " +
                           std::to_string(f.scale.y()).substr(0, 5) + ", z " +
                           std::to_string(f.scale.z()).substr(0, 5) + " about the chest")
     << (f.axes.isIdentity(1e-9) ? std::string() : "; forward is " + direction(f.axes.col(0)) + " in its root frame")
     << '\n'
     << std::defaultfloat << std::setprecision(6);
}

void summarize(std::ostream& os, const Model& model, const Scenario& sc, const SimResult& r, const char* label,
               double wall, const std::string& robot = "kinematic") {
  os << "scenario " << sc.name << " (" << sc.paper << "), " << label << "\n";
  if (robot == "kinematic")
    os << "  robot                 kinematic (in-process plant, OnboardController + KinematicPort)\n";
  else
    os << "  robot                 " << robot << " (a robot over DDS, OnboardController + "
       << (robot == "unitree_hg" ? "UnitreeHgPort" : "DdsRobotPort") << ")\n";
  os << "  min distance          " << r.min_distance * 1000.0 << " mm at t = " << r.min_time << " s ("
     << pairName(model, r.min_pair) << ")\n";
  if (std::isfinite(r.min_virtual_distance))
    os << "  min virtual distance  " << r.min_virtual_distance * 1000.0 << " mm\n";
  os << "  e-stop fired          " << (r.estop_fired ? "yes" : "no") << "\n";
  os << "  guard shortened       " << r.guard_cycles << " steps (predictive guard)\n";
  const char* side[2] = {"left", "right"};
  for (int a = 0; a < 2; ++a) {
    if (r.final_error[a] == 0.0 && r.reach_time[a] < 0.0) continue;
    os << "  " << side[a] << " hand: final error " << r.final_error[a] * 1000.0 << " mm, within 1 cm "
       << (r.reach_time[a] >= 0.0 ? "from t = " + std::to_string(r.reach_time[a]) + " s" : std::string("never"))
       << "\n";
  }
  if (robot == "kinematic")
    os << "  max |qdot|/v_max      " << r.max_joint_speed_ratio << "\n";
  else  // the measured speed is over the robot's state stamps: a robot catching up late periods inflates it
    os << "  max |qdot|/v_max      " << r.max_command_speed_ratio << " commanded; " << r.max_joint_speed_ratio
       << " measured (between the states' stamps)\n";
  os << "  non-finite output     " << (r.non_finite ? "YES" : "no") << "\n";
  if (robot == "kinematic")
    os << "  cycles " << r.cycles << ", simulated " << r.cycles * 0.005 << " s in " << wall * 1000.0 << " ms wall ("
       << (wall > 0 ? r.cycles * 0.005 / wall : 0.0) << "x real time)\n";
  else
    os << "  cycles " << r.cycles << ", " << r.cycles * 0.005 << " s of scenario in " << wall * 1000.0
       << " ms wall (real time)\n";
}

/// What a run on a robot over DDS measured besides the scenario's own figures.
struct PlantFigures {
  std::string robot;  ///< "mujoco" / "dds"
  int domain = 0;
  std::array<ArmTracking, 2> tracking;
  std::uint64_t below_d_r = 0;  ///< cycles whose measured state had a physical pair below d_r
  std::uint64_t contact_samples = 0, contacts_received = 0, total_contact_steps = 0;
  double min_contact = std::numeric_limits<double>::infinity();
  std::string min_contact_pair;
  int robot_exit = 0;
  std::string log;
  double ramp_out_ratio = -1.0;  ///< unitree_hg: max |dq| / (v_max dt) while the arm_sdk weight ramped out
  double measured_ratio = 0.0;   ///< max |dq| / (v_max dt) between consecutive states, the whole run
  double max_weight_step = 0.0;  ///< unitree_hg: the weight's largest step between two commands
  double ramp_time = 0.0;
  // The same scenario on the kinematic plant, for comparison.
  double kin_min_distance = 0.0;
  std::array<ArmTracking, 2> kin_tracking;
  bool kin_estop = false;
};

/// The lines a run over DDS adds to the summary (after summarize's). Every figure in mm / mrad / ms.
void summarizePlant(std::ostream& os, const SimResult& r, const PlantFigures& p, double d_r) {
  os << "  plant                 " << p.robot << " over DDS on domain " << p.domain << " (OnboardController + "
     << (p.robot == "unitree_hg" ? "UnitreeHgPort" : "DdsRobotPort")
     << ", real time; the distances above are our distance module on the MEASURED "
        "joint positions)\n";
  os << "  measured below d_r    " << p.below_d_r << " cycles (d_r = " << d_r * 1000.0 << " mm)\n";
  os << "  MuJoCo contacts       " << p.contact_samples << " of " << p.contacts_received
     << " RobotContacts samples name a pair closer than d_r; robot's contact steps " << p.total_contact_steps;
  if (std::isfinite(p.min_contact))
    os << "; smallest " << p.min_contact * 1000.0 << " mm (" << p.min_contact_pair << ")";
  os << "\n";
  const char* side[2] = {"left", "right"};
  for (int a = 0; a < 2; ++a)
    os << "  " << side[a] << " arm tracking     max " << p.tracking[a].max_error * 1000.0 << " mrad, RMS "
       << p.tracking[a].rms_error * 1000.0 << " mrad, lag " << p.tracking[a].lag * 1000.0 << " ms ("
       << p.tracking[a].cycles << " cycles); kinematic plant: max " << p.kin_tracking[a].max_error * 1000.0
       << " mrad, RMS " << p.kin_tracking[a].rms_error * 1000.0 << " mrad, lag " << p.kin_tracking[a].lag * 1000.0
       << " ms\n";
  os << "  kinematic plant       min distance " << p.kin_min_distance * 1000.0 << " mm, e-stop fired "
     << (p.kin_estop ? "yes" : "no") << " (the same scenario in process, for comparison)\n";
  os << "  robot state stale     " << r.robot_stale_cycles << " cycles (nothing commanded), late cycles "
     << r.late_cycles << "\n";
  if (p.ramp_out_ratio >= 0.0)
    os << "  arm_sdk weight        ramped in and out over " << p.ramp_time << " s, largest step " << p.max_weight_step
       << " per command; max |qdot|/v_max while ramping out " << p.ramp_out_ratio << " (measured, between ticks)\n";
  os << "  measured joint steps  max |dq|/(v_max dt) " << p.measured_ratio
     << " between consecutive states of the whole run (warm-up, scenario, ramp out; dt from the "
     << (p.ramp_out_ratio >= 0.0 ? "ticks" : "stamps") << ")\n";
  if (!p.log.empty()) os << "  robot log             " << p.log << " (exit status " << p.robot_exit << ")\n";
}

}  // namespace

/// What the command line asks for (robot_domain: resolved from --domain and the robot side).
struct SimArgs {
  std::string robot_side = "kinematic";
  std::string scenario_name, out_dir = "out/sim", urdf, collision, controller_cfg, mode = "one_dof";
  bool list = false, no_avoidance = false, no_plots = false;
  std::string postures_from;
  std::vector<double> at;
  std::optional<int> domain;
  double robot_timeout = 0.020, command_deadline = 0.015, robot_wait = 30.0;
  std::string joint_map;
  double ramp_time = 3.0;
  int robot_domain = 0;
};

void addOptions(CLI::App& app, SimArgs& a) {
  app.add_option("scenario", a.scenario_name, "scenario name (see --list) or 'all'");
  app.add_flag("--list", a.list, "list the scenarios");
  app.add_option("--out", a.out_dir, "output folder (created)");
  app.add_flag("--no-avoidance", a.no_avoidance,
               "run with collision avoidance AND the e-stop off (the paper's comparison; simulation only)");
  app.add_option("--mode", a.mode, "avoidance variant")->check(CLI::IsMember({"one_dof", "three_dof"}));
  app.add_option("--urdf", a.urdf, "robot URDF")->default_str(reflex::common::defaultUrdf());
  app.add_option("--collision", a.collision, "collision configuration YAML (default: next to the URDF)");
  app.add_option("--controller", a.controller_cfg,
                 "controller configuration YAML (default: <URDF stem>.controller.yaml next to the URDF if it exists, "
                 "else the built-in asimo_like arms)");
  app.add_flag("--no-plots", a.no_plots, "do not render PNG plots");
  app.add_option("--postures-from", a.postures_from,
                 "instead of simulating: write OUT/postures.csv (the robot's capsules) for rows of this time-series "
                 "CSV (reflex_sim or reflex_controller --log)");
  app.add_option("--at", a.at, "times (s) of the rows for --postures-from (nearest row each)")->delimiter(',');
  app.add_option("--robot", a.robot_side,
                 "the robot side: 'kinematic' (the in-process plant, simulated time), 'mujoco' (spawns reflex_mujoco "
                 "on --domain and drives it over DDS in real time), 'dds' (a robot already on the bus, real time) or "
                 "'unitree_hg' (spawns reflex_mujoco --interface unitree_hg and drives it as reflex_controller --robot "
                 "unitree_hg does: rt/lowstate in, rt/arm_sdk out, the weight ramped in and out; judged like mujoco)")
      ->capture_default_str()
      ->check(CLI::IsMember({"kinematic", "mujoco", "dds", "unitree_hg"}));
  app.add_option("--joint-map", a.joint_map,
                 "--robot unitree_hg: the joint map YAML (default: <URDF stem>.hg.yaml beside the URDF)");
  app.add_option("--ramp-time", a.ramp_time, "--robot unitree_hg: seconds of the arm_sdk weight's ramp in and out")
      ->capture_default_str()
      ->check(reflex::FiniteRange(1e-3, 60.0));
  app.add_option("--domain", a.domain,
                 "DDS domain id of the robot (--robot mujoco: default 197; dds: $REFLEX_DOMAIN_ID or 0)")
      ->check(CLI::Range(0, reflex::bus::kMaxDomainId));
  app.add_option("--robot-timeout", a.robot_timeout,
                 "seconds after which the newest robot state is stale (mujoco, dds): nothing is commanded; (0, 1]")
      ->capture_default_str()
      ->check(reflex::FiniteRange(1e-4, 1.0));
  app.add_option("--command-deadline", a.command_deadline,
                 "seconds each joint command stays valid (mujoco, dds); (0, 1]")
      ->capture_default_str()
      ->check(reflex::FiniteRange(1e-4, 1.0));
  app.add_option("--robot-wait", a.robot_wait, "seconds to wait for the robot's first state (mujoco, dds); (0, 600]")
      ->capture_default_str()
      ->check(reflex::FiniteRange(1e-3, 600.0));
}

/// --postures-from: OUT/postures.csv for rows of a time series, instead of simulating.
int writePosturesFrom(SimArgs& a) {
  if (a.urdf.empty()) a.urdf = reflex::common::defaultUrdf();
  const Model model = loadModel(a.urdf, loadCollisionConfigFor(a.urdf, a.collision));
  const SimResult r = readTimeseries(model, a.postures_from);
  if (r.samples.empty()) throw ConfigError(a.postures_from + ": no rows");
  std::vector<std::size_t> picks;
  if (a.at.empty()) picks = evenPicks(r.samples.size(), 6);
  for (const double t : a.at) {
    std::size_t best = 0;
    for (std::size_t k = 0; k < r.samples.size(); ++k)
      if (std::abs(r.samples[k].t - t) < std::abs(r.samples[best].t - t)) best = k;
    picks.push_back(best);
  }
  fs::create_directories(a.out_dir);
  writePostures(model, r, (fs::path(a.out_dir) / "postures.csv").string(), picks);
  std::cout << "wrote " << (fs::path(a.out_dir) / "postures.csv").string() << "\n";
  return finish(0);
}

/// One run of a scenario on a robot over DDS: a fresh reflex_mujoco per run (mujoco, unitree_hg), or
/// the robot already on the bus (dds), started at the rest configuration; judged by the robot's own
/// measurements, and compared with the same run on the kinematic robot.
SimResult runOnBus(const SimArgs& a, const Model& model, const ControllerModel& cm, const Scenario& scenario,
                   const SimOptions& opt, const fs::path& dir, const std::string& csv, const char* label, int run_index,
                   std::ostream& summary) {
  const Scenario* sc = &scenario;
  const int robot_domain = a.robot_domain;
  // A robot over DDS: a fresh reflex_mujoco per run (mujoco), started at the rest configuration.
  reflex::control_node::BusPlantOptions po;
  po.domain = robot_domain;
  po.q_start = restConfiguration(model, cm);
  po.margin = cm.params.d_r;
  po.port.timeout = a.robot_timeout;
  po.port.deadline = a.command_deadline;
  po.first_state_timeout = a.robot_wait;
  PlantFigures fig;
  fig.robot = a.robot_side;
  fig.domain = robot_domain;
  if (a.robot_side == "unitree_hg") {
    po.interface = "unitree_hg";
    po.joint_map = !a.joint_map.empty()
                       ? a.joint_map
                       : (fs::path(a.urdf).parent_path() / (fs::path(a.urdf).stem().string() + ".hg.yaml")).string();
    po.ramp_time = a.ramp_time;
    fig.ramp_time = a.ramp_time;
  }
  if (a.robot_side == "mujoco" || a.robot_side == "unitree_hg") {
    po.robot_binary = reflex::common::executableDir() + "/reflex_mujoco";
    po.robot_args = {"--urdf", a.urdf};
    if (!a.collision.empty()) po.robot_args.insert(po.robot_args.end(), {"--collision", a.collision});
    fig.log =
        (dir / (run_index == 0 ? "reflex_mujoco.log" : "reflex_mujoco_" + std::to_string(run_index) + ".log")).string();
    po.robot_log = fig.log;
  }
  std::cout << "  " << sc->name << " (" << label
            << "): " << (a.robot_side != "dds" ? "starting reflex_mujoco" : "joining") << " on domain " << robot_domain
            << ", then " << sc->duration << " s in real time ..." << std::endl;
  SimResult r;
  double wall = 0.0;
  {
    reflex::control_node::BusScenarioPlant plant(model, drivenJoints(model, cm), po);
    const auto t0 = std::chrono::steady_clock::now();
    r = runScenario(model, cm, *sc, opt, plant);
    wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    // unitree_hg: the arm_sdk weight back to 0, watched like the scenario (contacts, joint steps).
    if (a.robot_side == "unitree_hg") {
      plant.rampOut(cm.params.period);
      fig.ramp_out_ratio = plant.rampOutSpeedRatio();
      fig.max_weight_step = plant.maxWeightStep();
    }
    fig.measured_ratio = plant.measuredSpeedRatio();
    // The judge's last words: contacts published after the last cycle.
    plant.awaitCycle(static_cast<double>(r.cycles) * cm.params.period, cm.params.period);
    fig.robot_exit = plant.stop();
    fig.contact_samples = plant.contactSamples();
    fig.contacts_received = plant.contactsReceived();
    fig.total_contact_steps = plant.totalContactSteps();
    fig.min_contact = plant.minContact();
    fig.min_contact_pair = plant.minContactPair();
  }
  fig.tracking = computeTracking(cm, r);
  for (const auto& s : r.samples)
    if (s.commanded && s.min_distance < cm.params.d_r) ++fig.below_d_r;
  const SimResult kin = runScenario(model, cm, *sc, opt);
  fig.kin_min_distance = kin.min_distance;
  fig.kin_tracking = computeTracking(cm, kin);
  fig.kin_estop = kin.estop_fired;
  writeTimeseriesCsv(model, cm, r, (dir / csv).string());
  for (std::ostream* os : {static_cast<std::ostream*>(&std::cout), static_cast<std::ostream*>(&summary)}) {
    summarize(*os, model, *sc, r, label, wall, a.robot_side);
    summarizePlant(*os, r, fig, cm.params.d_r);
  }
  return r;
}

int main(int argc, char** argv) {
  CLI::App app{
      "reflex_sim: the paper's experiments on the kinematic robot (in process, no DDS), or on a robot over DDS\n"
      "in real time (--robot mujoco spawns reflex_mujoco on its own domain; --robot dds joins a robot already\n"
      "on the bus), through the same onboard controller and scenario scripts"};
  SimArgs args;
  addOptions(app, args);
  if (const int code = reflex::parseCommandLine(app, argc, argv); code >= 0) return code;
  const bool over_bus = args.robot_side != "kinematic";
  if (over_bus) {
    try {
      args.robot_domain =
          args.robot_side != "dds" ? args.domain.value_or(197) : reflex::bus::resolveDomainId(args.domain);
    } catch (const std::exception& e) {
      return reflex::reportException("reflex_sim", e);
    }
  }

  // A folder that cannot be made is an error now, before any simulation (not after the first one).
  if (!args.list && !args.out_dir.empty()) {
    if (const std::string why = reflex::common::outputFolderProblem(args.out_dir); !why.empty()) {
      std::fprintf(stderr, "reflex_sim: error: %s\n", why.c_str());
      return reflex::kExitRefused;
    }
  }
  if (!args.postures_from.empty()) return reflex::runGuarded("reflex_sim", [&] { return writePosturesFrom(args); });

  if (args.list) {
    for (const auto& s : builtinScenarios())
      std::printf("%-22s %-22s %s\n", s.name.c_str(), s.paper.c_str(), s.description.c_str());
    return finish(0);
  }
  if (args.scenario_name.empty()) {
    std::fprintf(stderr, "reflex_sim: error: name a scenario (reflex_sim --list) or 'all'\n");
    return 2;
  }
  std::vector<const Scenario*> chosen;
  if (args.scenario_name == "all") {
    for (const auto& s : builtinScenarios()) chosen.push_back(&s);
  } else if (const Scenario* s = findScenario(args.scenario_name)) {
    chosen.push_back(s);
  } else {
    std::fprintf(stderr, "reflex_sim: error: unknown scenario '%s' (reflex_sim --list names them)\n",
                 args.scenario_name.c_str());
    return 2;
  }
  try {
    if (args.urdf.empty()) args.urdf = reflex::common::defaultUrdf();
    const Model model = loadModel(args.urdf, loadCollisionConfigFor(args.urdf, args.collision));
    const ControllerConfig config = loadControllerConfigFor(args.urdf, args.controller_cfg);
    const ControllerModel cm = makeControllerModel(model, config);
    std::cout << "reflex_sim: " << describeControllerConfig(config, args.urdf) << "\n";
    printScenarioFrame(std::cout, model, scenarioFrame(model, cm));
    int failures = 0;
    for (const Scenario* sc : chosen) {
      const fs::path dir = chosen.size() > 1 ? fs::path(args.out_dir) / sc->name : fs::path(args.out_dir);
      fs::create_directories(dir);
      const std::string summary_path = (dir / "summary.txt").string();
      std::ofstream summary(summary_path);
      if (!summary) throw ConfigError("summary: " + reflex::common::writeError(summary_path, errno ? errno : EIO));
      int run_index = 0;
      auto run = [&](AvoidanceMode m, const std::string& csv, const char* label) {
        SimOptions opt;
        opt.mode = m;
        opt.estop = !args.no_avoidance;  // the paper's comparison: neither avoidance nor the e-stop
        opt.camera_link = config.camera_link;
        if (!over_bus) {
          const auto t0 = std::chrono::steady_clock::now();
          SimResult r = runScenario(model, cm, *sc, opt);
          const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
          writeTimeseriesCsv(model, cm, r, (dir / csv).string());
          summarize(std::cout, model, *sc, r, label, wall);
          summarize(summary, model, *sc, r, label, wall);
          return r;
        }
        return runOnBus(args, model, cm, *sc, opt, dir, csv, label, run_index++, summary);
      };
      const AvoidanceMode m = args.no_avoidance
                                  ? AvoidanceMode::kOff
                                  : (args.mode == "three_dof" ? AvoidanceMode::kThreeDof : AvoidanceMode::kOneDof);
      const SimResult main =
          run(m, "timeseries.csv", args.no_avoidance ? "avoidance off, e-stop off" : args.mode.c_str());
      writePostures(model, main, (dir / "postures.csv").string(), evenPicks(main.samples.size(), 6));
      if (sc->name == "one_vs_three_dof" && !args.no_avoidance)
        run(AvoidanceMode::kThreeDof, "timeseries_3dof.csv", "three_dof");
      closeChecked(summary, summary_path);
      if (!args.no_plots) {
        const std::string script = reflex::common::executableDir() + "/reflex_plot_sim.py";
        const std::string cmd =
            std::string(REFLEX_PYTHON) + " '" + script + "' '" + dir.string() + "' '" + sc->name + "'";
        if (std::system(cmd.c_str()) != 0) {
          std::fprintf(stderr, "reflex_sim: warning: plotting failed (%s)\n", cmd.c_str());
          ++failures;
        }
      }
      std::cout << "  wrote " << dir.string() << "/\n";
    }
    return finish(failures ? 1 : 0);
  } catch (const std::exception& e) {
    return reflex::reportException("reflex_sim", e);
  }
}
