// reflex_inspect: checks a robot's collision model. Loads a URDF (and its collision configuration),
// takes joint values, and prints the segments, the checked pairs with their distances and witness
// points, and the closest pair, as CSV or JSON.
#include "reflex/common/run_main.hpp"
#include "reflex/control/distance.hpp"
#include "reflex/control/kinematics.hpp"
#include "reflex/control/pair_sampling.hpp"
#include "reflex/control/urdf_loader.hpp"
#include "reflex/common/files.hpp"

#include <CLI/CLI.hpp>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <fstream>
#include <iostream>
#include <sstream>
#include <string>
#include <vector>

namespace {

using reflex::control::Model;

std::vector<std::string> splitCsv(const std::string& line) {
  std::vector<std::string> out;
  std::stringstream ss(line);
  std::string item;
  while (std::getline(ss, item, ',')) {
    const auto b = item.find_first_not_of(" \t\r");
    const auto e = item.find_last_not_of(" \t\r");
    out.push_back(b == std::string::npos ? "" : item.substr(b, e - b + 1));
  }
  return out;
}

double parseNumber(const std::string& text, const std::string& what) {
  try {
    std::size_t used = 0;
    const double v = std::stod(text, &used);
    if (used != text.size()) throw std::invalid_argument("trailing characters");
    if (!std::isfinite(v)) throw std::invalid_argument("not finite");
    return v;
  } catch (const std::exception&) {
    throw reflex::Error(what + ": '" + text + "' is not a finite number");
  }
}

void setJoint(const Model& model, Eigen::VectorXd& q, const std::string& name, const std::string& value,
              const std::string& where) {
  const int qi = model.qIndex(name);
  if (qi < 0) throw reflex::Error(where + ": unknown joint '" + name + "' in " + model.name);
  const double v = parseNumber(value, where + " joint '" + name + "'");
  if (v < model.q_lower[qi] - 1e-12 || v > model.q_upper[qi] + 1e-12) {
    std::ostringstream os;
    os << where << ": joint '" << name << "' value " << v << " is outside its limits [" << model.q_lower[qi] << ", "
       << model.q_upper[qi] << "]";
    throw reflex::Error(os.str());
  }
  q[qi] = v;
}

/// CSV with a header row of joint names and value rows; `row` selects the row (0 = first after header).
void readCsvRow(const Model& model, Eigen::VectorXd& q, const std::string& path, int row) {
  if (const std::string why = reflex::common::inputFileProblem(path); !why.empty())
    throw reflex::Error("joint CSV " + why);
  std::ifstream in(path);
  if (!in) throw reflex::Error(path + ": cannot open joint CSV");
  std::string header;
  if (!std::getline(in, header)) throw reflex::Error(path + ": empty joint CSV (expected a header row)");
  const auto names = splitCsv(header);
  std::string line;
  for (int i = 0; i <= row; ++i)
    if (!std::getline(in, line))
      throw reflex::Error(path + ": has no row " + std::to_string(row) + " after the header");
  const auto values = splitCsv(line);
  if (values.size() != names.size())
    throw reflex::Error(path + ": row " + std::to_string(row) + " has " + std::to_string(values.size()) +
                        " values for " + std::to_string(names.size()) + " columns");
  for (std::size_t i = 0; i < names.size(); ++i) {
    if (names[i] == "time" || names[i] == "t") continue;
    setJoint(model, q, names[i], values[i], path + " column " + std::to_string(i + 1));
  }
}

std::string jsonString(const std::string& s) {
  std::string out = "\"";
  for (const char c : s) {
    if (c == '"' || c == '\\') out += '\\';
    out += c;
  }
  return out + "\"";
}

/// --sample-pairs: a proposal of which pairs to check, from `samples` random configurations.
int proposePairs(const std::string& urdf_path, const std::string& config_path,
                 reflex::control::PairSamplingOptions sampling, int samples, const std::string& write_path,
                 bool force) {
  sampling.samples = samples;
  const reflex::control::CollisionConfig user_config = reflex::control::loadCollisionConfigFor(urdf_path, config_path);
  reflex::control::CollisionConfig every;  // the user's cylinder policy; no exclusions at all
  every.cylinder_as = user_config.cylinder_as;
  every.exclude_adjacent = false;
  reflex::control::CollisionConfig non_adjacent = every;
  non_adjacent.exclude_adjacent = true;
  const Model all = reflex::control::loadModel(urdf_path, every);
  const Model nonadj = reflex::control::loadModel(urdf_path, non_adjacent);
  if (!write_path.empty()) {  // before the sampling: only a regular file is ever replaced
    if (const std::string why = reflex::common::replaceableFileProblem(write_path); !why.empty())
      throw reflex::Error("--write: " + why);
    if (!force && ::access(write_path.c_str(), F_OK) == 0)
      throw reflex::Error("--write '" + write_path + "' exists; give --force to replace it");
  }
  int shown = -1;  // progress every 10 %
  const auto report = reflex::control::samplePairs(all, nonadj, sampling, [&shown](double f) {
    const int tenth = static_cast<int>(f * 10.0 + 1e-9);
    if (tenth == shown) return;
    shown = tenth;
    std::fprintf(stderr, "reflex_inspect: sampling %d %%\n", 10 * tenth);
  });
  const std::string yaml = reflex::control::exclusionYaml(report);
  if (write_path.empty()) {
    std::fputs(yaml.c_str(), stdout);
  } else {
    if (const std::string why = reflex::common::writeFileReplacing(write_path, yaml); !why.empty())
      throw reflex::Error(why);
  }
  int always = 0, never = 0;
  for (const auto& p : report.pairs) {
    always += p.verdict == reflex::control::PairVerdict::kAlwaysInCollision;
    never += p.verdict == reflex::control::PairVerdict::kNeverClose;
  }
  std::fprintf(stderr,
               "reflex_inspect: %s: %d samples: %d pairs always in collision (excluded), %d never "
               "closer than %.0f mm (commented out), %d checked, %zu adjacent%s%s\n",
               report.robot.c_str(), sampling.samples, always, never, sampling.near_distance * 1000.0,
               static_cast<int>(report.pairs.size()) - always - never, report.adjacent.size(),
               write_path.empty() ? "" : "; written to ", write_path.c_str());
  return 0;
}

/// The segments and their primitives (the CSV's commented head, or the JSON's "segments").
void printSegments(const Model& model, bool json) {
  for (int s = 0; s < model.num_robot_segments; ++s) {
    const auto& seg = model.segments[s];
    if (json) {
      std::printf("    {\"name\": %s, \"link\": %s, \"primitives\": [", jsonString(seg.name).c_str(),
                  jsonString(model.links[seg.link].name).c_str());
      for (int p = 0; p < seg.num_primitives; ++p) {
        const auto& prim = model.primitives[seg.first_primitive + p];
        std::printf(
            "%s{\"type\": \"%s\", \"link\": %s, \"a\": [%.6f, %.6f, %.6f], \"b\": [%.6f, %.6f, %.6f], "
            "\"radius\": %.6f}",
            p ? ", " : "", prim.sphere ? "sphere" : "capsule",
            jsonString(model.links[reflex::control::linkOf(seg, prim)].name).c_str(), prim.a_L.x(), prim.a_L.y(),
            prim.a_L.z(), prim.b_L.x(), prim.b_L.y(), prim.b_L.z(), prim.radius);
      }
      std::printf("]}%s\n", s + 1 < model.num_robot_segments ? "," : "");
    } else {
      std::printf("# %s,%s,", seg.name.c_str(), model.links[seg.link].name.c_str());
      for (int p = 0; p < seg.num_primitives; ++p) {
        const auto& prim = model.primitives[seg.first_primitive + p];
        std::printf("%s%s(r=%.4f)", p ? " " : "", prim.sphere ? "sphere" : "capsule", prim.radius);
      }
      std::printf("\n");
    }
  }
}

/// Every active pair's distance and witness points, then the closest pair.
void printDistances(const Model& model, const reflex::control::DistanceData& dist, bool json) {
  bool first = true;
  for (std::size_t i = 0; i < dist.pairs.size(); ++i) {
    const auto& pd = dist.pairs[i];
    if (!pd.active) continue;
    const char* a = model.segments[pd.seg_a].name.c_str();
    const char* b = model.segments[pd.seg_b].name.c_str();
    if (json) {
      std::printf(
          "%s    {\"a\": %s, \"b\": %s, \"distance\": %.6f, \"pa\": [%.6f, %.6f, %.6f], "
          "\"pb\": [%.6f, %.6f, %.6f]}",
          first ? "" : ",\n", jsonString(model.segments[pd.seg_a].name).c_str(),
          jsonString(model.segments[pd.seg_b].name).c_str(), pd.distance, pd.p_B_a.x(), pd.p_B_a.y(), pd.p_B_a.z(),
          pd.p_B_b.x(), pd.p_B_b.y(), pd.p_B_b.z());
    } else {
      std::printf("%s,%s,%.6f,%.6f,%.6f,%.6f,%.6f,%.6f,%.6f\n", a, b, pd.distance, pd.p_B_a.x(), pd.p_B_a.y(),
                  pd.p_B_a.z(), pd.p_B_b.x(), pd.p_B_b.y(), pd.p_B_b.z());
    }
    first = false;
  }
  if (dist.closest >= 0) {
    const auto& c = dist.pairs[dist.closest];
    if (json)
      std::printf("\n  ],\n  \"closest\": {\"a\": %s, \"b\": %s, \"distance\": %.6f}\n}\n",
                  jsonString(model.segments[c.seg_a].name).c_str(), jsonString(model.segments[c.seg_b].name).c_str(),
                  c.distance);
    else
      std::printf("# closest: %s,%s,%.6f\n", model.segments[c.seg_a].name.c_str(), model.segments[c.seg_b].name.c_str(),
                  c.distance);
  } else if (json) {
    std::printf("\n  ],\n  \"closest\": null\n}\n");
  }
}

}  // namespace

int run(int argc, char** argv) {
  CLI::App app{"reflex_inspect: check a robot's collision model (segments, checked pairs, distances)"};
  std::string urdf_path;
  std::string config_path;
  std::vector<std::string> q_args;
  std::string csv_path;
  int csv_row = 0;
  std::string format = "csv";
  bool list_only = false;
  app.add_option("urdf", urdf_path,
                 "URDF file (collision elements: spheres, cylinders and capsules; meshes and boxes through the fit "
                 "overlay <urdf stem>.fit.yaml written by reflex_fit; boxes without one fitted here the same way)")
      ->required();
  app.add_option("--config", config_path,
                 "collision configuration YAML (default: <urdf stem>.collision.yaml if it exists)");
  app.add_option("--q", q_args,
                 "joint values, name=value (radians / metres); others stay 0 (or the nearest limit if 0 is outside)");
  app.add_option("--csv", csv_path, "joint values from a CSV file: header row of joint names, value rows");
  app.add_option("--row", csv_row, "row of --csv to use (0 = first after the header)")->check(CLI::NonNegativeNumber);
  app.add_option("--format", format, "output format")->check(CLI::IsMember({"csv", "json"}));
  app.add_flag("--segments", list_only, "print only the segments and their primitives");
  reflex::control::PairSamplingOptions sampling;
  int sample_pairs = 0;
  std::string write_path;
  bool force = false;
  app.add_option("--sample-pairs", sample_pairs,
                 "propose which pairs to check: sample N random configurations within the limits and print a "
                 "commented collision configuration (always in collision: excluded; never close: commented out)")
      ->check(CLI::PositiveNumber);
  app.add_option("--seed", sampling.seed, "random seed of --sample-pairs (same seed, same proposal)");
  app.add_option("--near", sampling.near_distance, "--sample-pairs: 'never close' means never closer than this (m)")
      ->check(CLI::NonNegativeNumber);
  app.add_option("--always-fraction", sampling.always_fraction,
                 "--sample-pairs: 'always in collision' means penetrating in at least this fraction of samples")
      ->check(reflex::FiniteRange(1e-9, 1.0));
  app.add_option("--write", write_path, "--sample-pairs: write the proposal to this file instead of standard output");
  app.add_flag("--force", force, "--write may replace an existing file");
  if (const int code = reflex::parseCommandLine(app, argc, argv); code >= 0) return code;

  return reflex::runGuarded("reflex_inspect", [&]() -> int {
    if (sample_pairs > 0) return proposePairs(urdf_path, config_path, sampling, sample_pairs, write_path, force);
    const reflex::control::CollisionConfig config = reflex::control::loadCollisionConfigFor(urdf_path, config_path);
    std::vector<std::string> warnings;
    const Model model = reflex::control::loadModel(urdf_path, config, &warnings);
    for (const auto& w : warnings) std::cerr << "warning: " << w << "\n";

    Eigen::VectorXd q = Eigen::VectorXd::Zero(model.nq);
    for (int qi = 0; qi < model.nq; ++qi)  // zero if allowed, else the nearest limit
      q[qi] = std::min(std::max(0.0, model.q_lower[qi]), model.q_upper[qi]);
    if (!csv_path.empty()) readCsvRow(model, q, csv_path, csv_row);
    for (const auto& arg : q_args) {
      const auto eq = arg.find('=');
      if (eq == std::string::npos) throw reflex::Error("--q '" + arg + "': expected name=value");
      setJoint(model, q, arg.substr(0, eq), arg.substr(eq + 1), "--q");
    }

    reflex::control::KinematicsData kin(model);
    reflex::control::computeForwardKinematics(model, kin, q);
    reflex::control::DistanceData dist(model);
    reflex::control::computeSegmentDistances(model, kin, dist);

    const bool json = format == "json";
    int robot_pairs = 0;  // pairs of two robot segments (the slot pairs are inactive here)
    for (const auto& p : model.pairs) robot_pairs += model.segments[p.b].body_schema_slot ? 0 : 1;
    if (json)
      std::printf("{\n  \"robot\": %s,\n  \"segments\": [\n", jsonString(model.name).c_str());
    else
      std::printf(
          "# robot %s: %d segments, %d checked pairs (+%d with body-schema slots), %d joints\n"
          "# segment,link,primitives\n",
          model.name.c_str(), model.num_robot_segments, robot_pairs, static_cast<int>(model.pairs.size()) - robot_pairs,
          model.nq);
    printSegments(model, json);
    if (list_only) {
      if (json) std::printf("  ]\n}\n");
      return 0;
    }
    if (json)
      std::printf("  ],\n  \"pairs\": [\n");
    else
      std::printf("segment_a,segment_b,distance_m,pa_x,pa_y,pa_z,pb_x,pb_y,pb_z\n");
    printDistances(model, dist, json);
    return 0;
  });
}

int main(int argc, char** argv) {
  const int status = run(argc, argv);
  // Output that could not be written (reflex_inspect robot.urdf > /dev/full) is not success.
  if (const std::string why = reflex::common::flushStandardOutput(); !why.empty()) {
    std::fprintf(stderr, "reflex_inspect: error: %s\n", why.c_str());
    return 1;
  }
  return status;
}
