// Helpers of the MCAP tests: run the reference reader (mcap_check.cjs: @mcap/core +
// Foxglove's OMG IDL CDR decoder under node) and compare what it decoded with the rows of the
// project's CSV export, column by column.
#pragma once

#include "support/child_process.hpp"

#include <nlohmann/json.hpp>

#include <gtest/gtest.h>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <map>
#include <sstream>
#include <string>
#include <vector>

namespace reflex::record::mcap_check {

using nlohmann::json;

inline std::string slurp(const std::string& path) {
  std::ifstream in(path);
  return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
}

/// Runs `node mcap_check.cjs MODE FILE OUT [STEP]` and returns its JSON. A missing node or package
/// fails the test (REFLEX_NODE is empty when CMake found no node).
inline json runReference(const std::string& mode, const std::string& file, const std::string& work,
                         const std::string& step = "") {
  const std::string node = REFLEX_NODE;
  if (node.empty()) {
    ADD_FAILURE() << "node was not found at configure time: install Debian's nodejs (bringup/setup.sh)";
    return json();
  }
  const std::string out = work + "_" + mode + ".json", log = work + "_" + mode + ".log";
  std::vector<std::string> argv = {node, std::string(REFLEX_SOURCE_DIR) + "/tests/record/mcap_check.cjs", mode, file,
                                   out};
  if (!step.empty()) argv.push_back(step);
  std::remove(out.c_str());
  testing::ChildProcess p(argv, log);
  const int rc = p.wait(std::chrono::minutes(3));
  if (rc != 0) {
    ADD_FAILURE() << "mcap_check.cjs " << mode << " " << file << " exited " << rc << ":\n" << slurp(log);
    return json();
  }
  return json::parse(slurp(out));
}

/// True if the indexed reader read the footer (the last 37 bytes: footer record and magic) before any
/// message, i.e. it found the summary from the end of the file instead of scanning it.
inline bool readFooterFirst(const json& indexed) {
  const std::uint64_t size = indexed["file_size"];
  for (const json& r : indexed["reads_before_messages"])
    if (std::stoull(r[0].get<std::string>()) == size - 37) return true;
  return false;
}

/// One CSV line split into fields (quotes as csvField writes them).
inline std::vector<std::string> csvFields(const std::string& line) {
  std::vector<std::string> out(1);
  bool quoted = false;
  for (std::size_t i = 0; i < line.size(); ++i) {
    const char c = line[i];
    if (quoted) {
      if (c == '"' && i + 1 < line.size() && line[i + 1] == '"')
        out.back() += '"', ++i;
      else if (c == '"')
        quoted = false;
      else
        out.back() += c;
    } else if (c == '"')
      quoted = true;
    else if (c == ',')
      out.emplace_back();
    else
      out.back() += c;
  }
  return out;
}

/// A decoded value as the CSV export would print it: true/false -> 1/0; strings (and 64-bit integers,
/// which the reference reader gives as decimal strings) as they are; numbers as "%.9g" (what the
/// exporter uses for doubles) or, for integers, in full.
inline bool sameValue(const json& v, const std::string& field) {
  if (v.is_boolean()) return field == (v.get<bool>() ? "1" : "0");
  if (v.is_string()) return field == v.get<std::string>();
  if (v.is_number_integer() && field == std::to_string(v.get<long long>())) return true;
  if (v.is_number()) {
    char buf[40];
    std::snprintf(buf, sizeof(buf), "%.9g", v.get<double>());
    return field == buf;
  }
  return false;
}

/// The JSON pointer of a CSV column of a type's export (codecs.cpp), "" for a column derived otherwise.
inline std::string pointerOf(const std::string& type, const std::string& col) {
  static const std::map<std::string, std::string> common = {{"stamp_ns", "/msg/header/stamp_ns"},
                                                            {"seq", "/msg/header/seq"},
                                                            {"source", "/msg/header/source"},
                                                            {"receive_ns", "/log_time"},
                                                            {"source_ns", "/publish_time"}};
  if (common.count(col)) return common.at(col);
  const auto side = col.substr(0, col.find('_'));
  const auto rest = col.find('_') == std::string::npos ? std::string() : col.substr(col.find('_') + 1);
  if (type == "reflex::msg::HandTargets" && (side == "left" || side == "right")) {
    if (rest == "status") return "/msg/" + side + "/status";
    if (rest == "object") return "/msg/" + side + "/object_name";
    return "/msg/" + side + "/position_base/" + rest;
  }
  if (type == "reflex::msg::ControlStatus" && (side == "left" || side == "right")) {
    static const std::map<std::string, std::string> arm = {
        {"f", "blend_f"},           {"distance", "distance"},           {"zone", "zone"},
        {"estop", "estop_latched"}, {"closest_a", "closest_segment_a"}, {"closest_b", "closest_segment_b"}};
    return "/msg/" + side + "/" + arm.at(rest);
  }
  if (type == "reflex::msg::BodySchemaChange" && (side == "a" || side == "b") && rest.size() == 1)
    return "/msg/point_" + side + "/" + rest;
  return "/msg/" + col;
}

/// Compares the messages of `topic` decoded by the reference reader (`messages`, file order) with the
/// CSV the project exported for it, every column of every row. Returns the number of messages compared.
inline std::size_t expectCsvMatches(const json& messages, const std::string& topic, const std::string& csv_path) {
  std::ifstream in(csv_path);
  std::string line;
  if (!std::getline(in, line)) {
    ADD_FAILURE() << "no CSV header in " << csv_path;
    return 0;
  }
  const std::vector<std::string> header = csvFields(line);
  std::vector<std::vector<std::string>> rows;
  while (std::getline(in, line)) rows.push_back(csvFields(line));
  std::size_t row = 0, compared = 0;
  int failures = 0;
  for (const json& m : messages) {
    if (m["topic"] != topic) continue;
    const std::string type = m["schema"];
    const bool objects = type == "reflex::msg::ObjectTargets";
    const bool contacts = type == "reflex::msg::RobotContacts";  // one row per pair, like objects
    const std::size_t n_rows = objects    ? std::max<std::size_t>(1, m["msg"]["objects"].size())
                               : contacts ? std::max<std::size_t>(1, m["msg"]["contacts"].size())
                                          : 1;
    const bool per_joint =
        type == "reflex::msg::JointState" || type == "reflex::msg::RobotState" || type == "reflex::msg::JointCommand";
    for (std::size_t k = 0; k < n_rows; ++k, ++row) {
      if (row >= rows.size()) {
        ADD_FAILURE() << topic << ": the reference reader has more messages than " << csv_path << " has rows";
        return compared;
      }
      const auto& fields = rows[row];
      if (fields.size() != header.size()) {
        ADD_FAILURE() << csv_path << " row " << row << " has " << fields.size() << " fields";
        continue;
      }
      for (std::size_t c = 0; c < header.size(); ++c) {
        const std::string& col = header[c];
        if (col == "t") continue;  // seconds since the file's first record: receive_ns is compared instead
        json v;
        if (per_joint && (col.rfind("q_", 0) == 0 || col.rfind("qd_", 0) == 0 || col.rfind("effort_", 0) == 0)) {
          // q_<joint>, qd_<joint>, effort_<joint>: the value at that joint's index in names ("" past
          // the end of a shorter list: efforts not measured).
          const std::size_t cut = col.find('_');
          const std::string kind = col.substr(0, cut), name = col.substr(cut + 1);
          const json& list = m["msg"][kind == "q" ? "positions" : kind == "qd" ? "velocities" : "efforts"];
          const json& names = m["msg"]["names"];
          for (std::size_t i = 0; i < names.size(); ++i)
            if (names[i] == name) v = i < list.size() ? list[i] : json("");
        } else if (contacts && col == "n_contacts") {
          v = m["msg"]["contacts"].size();
        } else if (contacts && (col == "segment_a" || col == "segment_b" || col == "distance")) {
          v = m["msg"]["contacts"].empty() ? json("") : m["msg"]["contacts"][k][col];
        } else if (objects && col == "n_objects") {
          v = m["msg"]["objects"].size();
        } else if (objects && std::string(",object,tag_id,x,y,z,x_cam,y_cam,z_cam,confidence,").find("," + col + ",") !=
                                  std::string::npos) {
          if (m["msg"]["objects"].empty())
            v = "";
          else {
            const json& o = m["msg"]["objects"][k];
            static const std::map<std::string, std::string> ptr = {{"object", "/name"},
                                                                   {"tag_id", "/tag_id"},
                                                                   {"x", "/position_base/x"},
                                                                   {"y", "/position_base/y"},
                                                                   {"z", "/position_base/z"},
                                                                   {"x_cam", "/position_camera/x"},
                                                                   {"y_cam", "/position_camera/y"},
                                                                   {"z_cam", "/position_camera/z"},
                                                                   {"confidence", "/confidence"}};
            v = o.at(json::json_pointer(ptr.at(col)));
          }
        } else {
          const json::json_pointer p(pointerOf(type, col));
          if (m.contains(p)) v = m.at(p);
        }
        if (!sameValue(v, fields[c]) && ++failures <= 10)
          ADD_FAILURE() << topic << " row " << row << " column " << col << ": CSV '" << fields[c]
                        << "', reference reader " << v.dump();
      }
    }
    ++compared;
  }
  EXPECT_EQ(row, rows.size()) << topic << ": CSV rows without a message in the reference reader";
  return compared;
}

}  // namespace reflex::record::mcap_check
