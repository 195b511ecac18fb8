#include "mount_kinematics.hpp"
#include "reflex/common/files.hpp"

#include "reflex/vision/error.hpp"

#include <reflex/control/kinematics.hpp>

#include <cmath>
#include <fstream>
#include <map>
#include <sstream>

namespace reflex::vision {
namespace {

std::vector<std::string> splitCsv(const std::string& line) {
  std::vector<std::string> out;
  std::stringstream ss(line);
  std::string cell;
  while (std::getline(ss, cell, ',')) {
    const auto b = cell.find_first_not_of(" \t\r"), e = cell.find_last_not_of(" \t\r");
    out.push_back(b == std::string::npos ? "" : cell.substr(b, e - b + 1));
  }
  if (!line.empty() && line.back() == ',') out.emplace_back();
  return out;
}

}  // namespace

double parseNumber(const std::string& text, const std::string& where) {
  double v = 0.0;
  if (!common::parseFiniteNumber(text, v)) throw VisionError(where + ": '" + text + "' is not a finite number");
  return v;
}

Eigen::Isometry3d linkPoseAtZero(const control::Model& model, int link) {
  control::KinematicsData data(model);
  const Eigen::VectorXd q = Eigen::VectorXd::Zero(model.nq);
  control::computeForwardKinematics(model, data, q);
  return data.X_B_L[static_cast<std::size_t>(link)];
}

std::vector<MountObservation> readMountObservations(const std::string& path, const MountKinematics& k) {
  std::ifstream in(path);
  if (!in) throw VisionError("cannot open observations file '" + path + "'");
  std::string line;
  if (!std::getline(in, line)) throw VisionError(path + ": empty (expected a header: view,x_cam,y_cam,z_cam,<joints>)");
  const std::vector<std::string> header = splitCsv(line);
  int col_view = -1, col_x = -1, col_y = -1, col_z = -1;
  std::map<int, int> q_of_col;  // column -> q index
  for (std::size_t c = 0; c < header.size(); ++c) {
    const std::string& h = header[c];
    const int ci = static_cast<int>(c);
    if (h == "view")
      col_view = ci;
    else if (h == "x_cam")
      col_x = ci;
    else if (h == "y_cam")
      col_y = ci;
    else if (h == "z_cam")
      col_z = ci;
    else if (const int qi = k.model->qIndex(h); qi >= 0)
      q_of_col[ci] = qi;
    else
      throw VisionError(path + ": line 1: column '" + h +
                        "' is neither view, x_cam, y_cam, z_cam nor a movable joint of " + k.model->name);
  }
  for (const auto& [name, col] : {std::pair<const char*, int>{"x_cam", col_x}, {"y_cam", col_y}, {"z_cam", col_z}})
    if (col < 0) throw VisionError(path + ": line 1: missing column '" + std::string(name) + "'");

  control::KinematicsData data(*k.model);
  Eigen::VectorXd q(k.model->nq);
  std::vector<MountObservation> out;
  int line_no = 1;
  while (std::getline(in, line)) {
    ++line_no;
    if (line.find_first_not_of(" \t\r") == std::string::npos) continue;
    const std::string where = path + ": line " + std::to_string(line_no);
    const std::vector<std::string> cells = splitCsv(line);
    if (cells.size() != header.size())
      throw VisionError(where + ": " + std::to_string(cells.size()) + " values, the header has " +
                        std::to_string(header.size()));
    MountObservation m;
    m.name = col_view >= 0 ? cells[static_cast<std::size_t>(col_view)] : "line " + std::to_string(line_no);
    auto cell = [&](int c) {
      return parseNumber(cells[static_cast<std::size_t>(c)], where + ", " + header[static_cast<std::size_t>(c)]);
    };
    m.p_C = cv::Vec3d(cell(col_x), cell(col_y), cell(col_z));
    q.setZero();
    for (const auto& [c, qi] : q_of_col) q[qi] = cell(c);
    if (!control::computeForwardKinematics(*k.model, data, q))
      throw VisionError(where + ": joint values refused by the kinematics");
    const Eigen::Vector3d p_B = data.X_B_L[static_cast<std::size_t>(k.hand_link)] * k.p_hand;
    const Eigen::Vector3d p_H = data.X_B_L[static_cast<std::size_t>(k.head_link)].inverse() * p_B;
    m.p_H = cv::Vec3d(p_H.x(), p_H.y(), p_H.z());
    out.push_back(m);
  }
  if (out.empty()) throw VisionError(path + ": no rows after the header");
  return out;
}

}  // namespace reflex::vision
