#include "reflex/view/log_scene.hpp"

#include <reflex/common/files.hpp>
#include <reflex/control/controller.hpp>

#include <array>
#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <sstream>

namespace reflex::view {
namespace {

using control::ConfigError;

std::vector<std::string> splitCsvLine(const std::string& line) {
  std::vector<std::string> fields;
  std::stringstream ss(line);
  std::string field;
  while (std::getline(ss, field, ',')) fields.push_back(field);
  if (!line.empty() && line.back() == ',') fields.emplace_back();  // a trailing empty field
  return fields;
}

/// Column index of `name`, or -1.
int column(const std::vector<std::string>& header, const std::string& name) {
  for (std::size_t i = 0; i < header.size(); ++i)
    if (header[i] == name) return static_cast<int>(i);
  return -1;
}

/// The whole text as a number; nan / inf allowed (targets are "nan" when none is given).
double parseAnyNumber(const std::string& text, const std::string& where) {
  const char* begin = text.c_str();
  char* end = nullptr;
  errno = 0;
  const double v = std::strtod(begin, &end);
  if (text.empty() || end != begin + text.size()) throw ConfigError(where + ": '" + text + "' is not a number");
  return v;
}

Zone parseZone(const std::string& text, const std::string& where) {
  if (text == "free") return Zone::kFree;
  if (text == "yellow") return Zone::kYellow;
  if (text == "orange") return Zone::kOrange;
  if (text == "red") return Zone::kRed;
  throw ConfigError(where + ": zone '" + text + "' is none of free, yellow, orange, red");
}

/// Where each input of a SceneInput comes from in the header (-1: column absent).
struct LogColumns {
  int time = -1, wall_time = -1, estop = -1;
  std::vector<int> q;  // model q order
  struct Arm {
    int f = -1, distance = -1, pair = -1, zone = -1, status = -1, target[3] = {-1, -1, -1};
  };
  std::array<Arm, 2> arms;
};

LogColumns findColumns(const SceneModel& scene, const std::vector<std::string>& header, const std::string& path) {
  LogColumns c;
  c.time = column(header, "time");
  if (c.time < 0) throw ConfigError(path + ": no 'time' column (not a reflex_controller --log time series?)");
  c.wall_time = column(header, "wall_time");
  c.estop = column(header, "estop");
  const control::Model& model = scene.model;
  c.q.resize(static_cast<std::size_t>(model.nq));
  for (int qi = 0; qi < model.nq; ++qi) {
    const std::string name = "q_" + model.q_names[static_cast<std::size_t>(qi)];
    c.q[static_cast<std::size_t>(qi)] = column(header, name);
    if (c.q[static_cast<std::size_t>(qi)] < 0)
      throw ConfigError(path + ": no column " + name + " (joint of the robot model; another robot's log?)");
  }
  for (std::size_t arm = 0; arm < 2; ++arm) {
    const std::string p = scene.arm_names[arm] + "_";
    LogColumns::Arm& a = c.arms[arm];
    a.f = column(header, p + "f");
    a.distance = column(header, p + "distance");
    a.pair = column(header, p + "pair");
    a.zone = column(header, p + "zone");
    a.status = column(header, p + "status");
    for (int k = 0; k < 3; ++k) a.target[k] = column(header, p + "target_" + "xyz"[k]);
  }
  return c;
}

LogScene parseRow(const SceneModel& scene, const LogColumns& c, const std::vector<std::string>& v, std::size_t row,
                  const std::string& path) {
  const std::string where = path + " row " + std::to_string(row);
  auto at = [&](int col) -> const std::string& { return v[static_cast<std::size_t>(col)]; };
  LogScene s;
  s.row = row;
  s.t = parseAnyNumber(at(c.time), where + " column time");
  if (c.wall_time >= 0) {
    const double wall = parseAnyNumber(at(c.wall_time), where + " column wall_time");
    if (std::isfinite(wall)) s.input.stamp_ns = static_cast<std::int64_t>(std::llround(wall * 1e9));
  }
  s.input.q.resize(scene.model.nq);
  for (int qi = 0; qi < scene.model.nq; ++qi) {
    const std::string& text = at(c.q[static_cast<std::size_t>(qi)]);
    double value = 0.0;
    if (!common::parseFiniteNumber(text, value))
      throw ConfigError(where + " column q_" + scene.model.q_names[static_cast<std::size_t>(qi)] + ": '" + text +
                        "' is not a finite joint position");
    s.input.q[qi] = value;
  }
  const bool estop = c.estop >= 0 && parseAnyNumber(at(c.estop), where + " column estop") != 0.0;
  for (std::size_t arm = 0; arm < 2; ++arm) {
    const LogColumns::Arm& a = c.arms[arm];
    const std::string p = where + " column " + scene.arm_names[arm] + "_";
    ArmState& out = s.input.arms[arm];
    if (a.zone >= 0) {
      out.valid = true;
      out.zone = parseZone(at(a.zone), p + "zone");
      out.estop_latched = estop;
      if (a.f >= 0) out.blend_f = parseAnyNumber(at(a.f), p + "f");
      if (a.distance >= 0) out.distance = parseAnyNumber(at(a.distance), p + "distance");
      if (a.pair >= 0) {
        const std::string& pair = at(a.pair);
        const std::size_t bar = pair.find('|');
        if (bar != std::string::npos) {
          out.closest_a = pair.substr(0, bar);
          out.closest_b = pair.substr(bar + 1);
        }
      }
    }
    if (a.status >= 0 && at(a.status) == "given" && a.target[0] >= 0 && a.target[1] >= 0 && a.target[2] >= 0) {
      HandTargetState& target = s.input.targets[arm];
      for (int k = 0; k < 3; ++k) target.p_B[k] = parseAnyNumber(at(a.target[k]), p + "target_" + "xyz"[k]);
      target.given = target.p_B.allFinite();
    }
  }
  return s;
}

}  // namespace

std::vector<LogScene> readLogScenes(const SceneModel& scene, const std::string& path, const std::vector<double>& at) {
  if (const std::string why = common::inputFileProblem(path); !why.empty()) throw ConfigError("time series " + why);
  for (const double t : at)
    if (!std::isfinite(t)) throw ConfigError("time series " + path + ": a requested time is not finite");
  std::ifstream in(path);
  if (!in) throw ConfigError(path + ": cannot open the time series");
  std::string line;
  if (!std::getline(in, line)) throw ConfigError(path + ": empty time series (no header)");
  const std::vector<std::string> header = splitCsvLine(line);
  const LogColumns columns = findColumns(scene, header, path);

  // One pass: keep the raw lines (a 60 s run at 200 Hz is ~12 000 rows) and their times.
  std::vector<std::string> lines;
  std::vector<double> times;
  while (std::getline(in, line)) {
    if (line.empty()) continue;
    const std::size_t row = lines.size() + 1;
    std::vector<std::string> v = splitCsvLine(line);
    if (v.size() < header.size())
      throw ConfigError(path + " row " + std::to_string(row) + ": " + std::to_string(v.size()) +
                        " values, the header has " + std::to_string(header.size()));
    const std::string where = path + " row " + std::to_string(row) + " column time";
    const double t = parseAnyNumber(v[static_cast<std::size_t>(columns.time)], where);
    if (!std::isfinite(t))
      throw ConfigError(where + ": '" + v[static_cast<std::size_t>(columns.time)] + "' is not finite");
    times.push_back(t);
    lines.push_back(std::move(line));
  }
  if (lines.empty()) throw ConfigError(path + ": no rows");

  std::vector<LogScene> scenes;
  for (const double t : at) {
    std::size_t best = 0;
    for (std::size_t k = 1; k < times.size(); ++k)
      if (std::abs(times[k] - t) < std::abs(times[best] - t)) best = k;
    scenes.push_back(parseRow(scene, columns, splitCsvLine(lines[best]), best + 1, path));
  }
  return scenes;
}

}  // namespace reflex::view
