// reflex_sim: runs the paper's experiments on the kinematic robot, without DDS.
//   reflex_sim --list
//   reflex_sim SCENARIO --out DIR [--urdf R [--controller C]] [--no-avoidance] [--mode one_dof|three_dof]
// On any robot: the scenarios' targets are placed by the robot's own landmarks (ScenarioFrame, printed
// first); its controller configuration is <R stem>.controller.yaml beside the URDF unless --controller.
// Writes DIR/timeseries.csv (one row per 5 ms cycle), DIR/postures.csv (capsules at a few instants),
// DIR/summary.txt, and PNG plots like the paper's figures (through python3-matplotlib).
#include "reflex/control/controller.hpp"
#include "reflex/control/scenarios.hpp"
#include "reflex/control/urdf_loader.hpp"
#include "reflex/common/files.hpp"

#include <CLI/CLI.hpp>

#include <cerrno>
#include <chrono>
#include <cstdio>
#include <cstdlib>
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

std::string exeDir() {
  char buf[4096];
  const ssize_t n = readlink("/proc/self/exe", buf, sizeof(buf) - 1);
  if (n <= 0) return ".";
  buf[n] = 0;
  return fs::path(buf).parent_path().string();
}

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
        const Eigen::Vector3d a = kin.X_W_L[sg.link] * model.primitives[p].a_L;
        const Eigen::Vector3d b = kin.X_W_L[sg.link] * model.primitives[p].b_L;
        out << f << ',' << s.t << ',' << sg.name << ',' << a.x() << ',' << a.y() << ',' << a.z() << ',' << b.x()
            << ',' << b.y() << ',' << b.z() << ',' << model.primitives[p].radius << '\n';
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
void printScenarioFrame(std::ostream& os, const Model& model, const ScenarioFrame& f) {
  auto mm = [](const Eigen::Vector3d& p) {
    std::ostringstream s;
    s << std::fixed << std::setprecision(0) << '(' << p.x() * 1000 << ", " << p.y() * 1000 << ", " << p.z() * 1000 << ')';
    return s.str();
  };
  os << "robot " << model.name << ": chest " << mm(f.chest) << " mm, shoulders " << std::fixed << std::setprecision(0)
     << 2000 * f.half_width << " mm apart, arm " << f.arm_length * 1000 << " mm; scenarios "
     << (f.reference ? std::string("as written (the reference robot)")
                     : "scaled x " + std::to_string(f.scale.x()).substr(0, 5) + ", y " + std::to_string(f.scale.y()).substr(0, 5) +
                           ", z " + std::to_string(f.scale.z()).substr(0, 5) + " about the chest")
     << '\n' << std::defaultfloat << std::setprecision(6);
}

void summarize(std::ostream& os, const Model& model, const Scenario& sc, const SimResult& r, const char* label,
               double wall) {
  os << "scenario " << sc.name << " (" << sc.paper << "), " << label << "\n";
  os << "  robot                 kinematic (in-process plant, OnboardController + KinematicPort)\n";
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
  os << "  max |qdot|/v_max      " << r.max_joint_speed_ratio << "\n";
  os << "  non-finite output     " << (r.non_finite ? "YES" : "no") << "\n";
  os << "  cycles " << r.cycles << ", simulated " << r.cycles * 0.005 << " s in " << wall * 1000.0
     << " ms wall (" << (wall > 0 ? r.cycles * 0.005 / wall : 0.0) << "x real time)\n";
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"reflex_sim: the paper's experiments on the kinematic robot (no DDS)"};
  std::string robot_side = "kinematic";
  std::string scenario_name, out_dir = "out/sim", urdf, collision, controller_cfg, mode = "one_dof";
  bool list = false, no_avoidance = false, no_plots = false;
  app.add_option("scenario", scenario_name, "scenario name (see --list) or 'all'");
  app.add_flag("--list", list, "list the scenarios");
  app.add_option("--out", out_dir, "output folder (created)");
  app.add_flag("--no-avoidance", no_avoidance, "run with collision avoidance AND the e-stop off (the paper's comparison; simulation only)");
  app.add_option("--mode", mode, "avoidance variant")->check(CLI::IsMember({"one_dof", "three_dof"}));
  app.add_option("--urdf", urdf, "robot URDF")->default_str(REFLEX_DEFAULT_URDF);
  app.add_option("--collision", collision, "collision configuration YAML (default: next to the URDF)");
  app.add_option("--controller", controller_cfg,
                 "controller configuration YAML (default: <URDF stem>.controller.yaml next to the URDF if it exists, "
                 "else the built-in asimo_like arms)");
  app.add_flag("--no-plots", no_plots, "do not render PNG plots");
  std::string postures_from;
  std::vector<double> at;
  app.add_option("--postures-from", postures_from,
                 "instead of simulating: write OUT/postures.csv (the robot's capsules) for rows of this time-series "
                 "CSV (reflex_sim or reflex_controller --log)");
  app.add_option("--at", at, "times (s) of the rows for --postures-from (nearest row each)")->delimiter(',');
  app.add_option("--robot", robot_side,
                 "the robot side: 'kinematic' (the in-process plant; the only one reflex_sim runs today; a robot over "
                 "DDS is reflex_controller --robot dds)")
      ->capture_default_str();
  CLI11_PARSE(app, argc, argv);
  if (robot_side != "kinematic") {
    std::fprintf(stderr,
                 "reflex_sim: error: --robot '%s': reflex_sim runs the in-process kinematic plant only ('kinematic'); "
                 "drive a robot over DDS with reflex_controller --robot dds\n",
                 robot_side.c_str());
    return 1;
  }

  // A folder that cannot be made is an error now, before any simulation (not after the first one).
  if (!list && !out_dir.empty()) {
    if (const std::string why = reflex::common::outputFolderProblem(out_dir); !why.empty()) {
      std::fprintf(stderr, "reflex_sim: error: %s\n", why.c_str());
      return 1;
    }
  }
  if (!postures_from.empty()) {
    try {
      if (urdf.empty()) urdf = REFLEX_DEFAULT_URDF;
      const Model model = loadModel(urdf, loadCollisionConfigFor(urdf, collision));
      const SimResult r = readTimeseries(model, postures_from);
      if (r.samples.empty()) throw ConfigError(postures_from + ": no rows");
      std::vector<std::size_t> picks;
      if (at.empty()) picks = evenPicks(r.samples.size(), 6);
      for (const double t : at) {
        std::size_t best = 0;
        for (std::size_t k = 0; k < r.samples.size(); ++k)
          if (std::abs(r.samples[k].t - t) < std::abs(r.samples[best].t - t)) best = k;
        picks.push_back(best);
      }
      fs::create_directories(out_dir);
      writePostures(model, r, (fs::path(out_dir) / "postures.csv").string(), picks);
      std::cout << "wrote " << (fs::path(out_dir) / "postures.csv").string() << "\n";
      return finish(0);
    } catch (const std::exception& e) {
      std::fprintf(stderr, "reflex_sim: error: %s\n", e.what());
      return 1;
    }
  }

  if (list) {
    for (const auto& s : builtinScenarios()) std::printf("%-22s %-22s %s\n", s.name.c_str(), s.paper.c_str(), s.description.c_str());
    return finish(0);
  }
  if (scenario_name.empty()) {
    std::fprintf(stderr, "reflex_sim: error: name a scenario (reflex_sim --list) or 'all'\n");
    return 2;
  }
  std::vector<const Scenario*> chosen;
  if (scenario_name == "all") {
    for (const auto& s : builtinScenarios()) chosen.push_back(&s);
  } else if (const Scenario* s = findScenario(scenario_name)) {
    chosen.push_back(s);
  } else {
    std::fprintf(stderr, "reflex_sim: error: unknown scenario '%s' (reflex_sim --list names them)\n", scenario_name.c_str());
    return 2;
  }
  try {
    if (urdf.empty()) urdf = REFLEX_DEFAULT_URDF;
    const Model model = loadModel(urdf, loadCollisionConfigFor(urdf, collision));
    const ControllerConfig config = loadControllerConfigFor(urdf, controller_cfg);
    const ControllerModel cm = makeControllerModel(model, config);
    printScenarioFrame(std::cout, model, scenarioFrame(model, cm));
    int failures = 0;
    for (const Scenario* sc : chosen) {
      const fs::path dir = chosen.size() > 1 ? fs::path(out_dir) / sc->name : fs::path(out_dir);
      fs::create_directories(dir);
      const std::string summary_path = (dir / "summary.txt").string();
      std::ofstream summary(summary_path);
      if (!summary) throw ConfigError("summary: " + reflex::common::writeError(summary_path, errno ? errno : EIO));
      auto run = [&](AvoidanceMode m, const std::string& csv, const char* label) {
        SimOptions opt;
        opt.mode = m;
        opt.estop = !no_avoidance;  // the paper's comparison: neither avoidance nor the e-stop
        opt.camera_link = config.camera_link;
        const auto t0 = std::chrono::steady_clock::now();
        SimResult r = runScenario(model, cm, *sc, opt);
        const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
        writeTimeseriesCsv(model, cm, r, (dir / csv).string());
        summarize(std::cout, model, *sc, r, label, wall);
        summarize(summary, model, *sc, r, label, wall);
        return r;
      };
      const AvoidanceMode m = no_avoidance ? AvoidanceMode::kOff
                                           : (mode == "three_dof" ? AvoidanceMode::kThreeDof : AvoidanceMode::kOneDof);
      const SimResult main = run(m, "timeseries.csv", no_avoidance ? "avoidance off, e-stop off" : mode.c_str());
      writePostures(model, main, (dir / "postures.csv").string(), evenPicks(main.samples.size(), 6));
      if (sc->name == "one_vs_three_dof" && !no_avoidance) run(AvoidanceMode::kThreeDof, "timeseries_3dof.csv", "three_dof");
      closeChecked(summary, summary_path);
      if (!no_plots) {
        const std::string script = exeDir() + "/reflex_plot_sim.py";
        const std::string cmd = std::string(REFLEX_PYTHON) + " '" + script + "' '" + dir.string() + "' '" + sc->name + "'";
        if (std::system(cmd.c_str()) != 0) {
          std::fprintf(stderr, "reflex_sim: warning: plotting failed (%s)\n", cmd.c_str());
          ++failures;
        }
      }
      std::cout << "  wrote " << dir.string() << "/\n";
    }
    return finish(failures ? 1 : 0);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "reflex_sim: error: %s\n", e.what());
    return 1;
  }
}
