#pragma once
// reflex_calibrate mount: the observations CSV and the robot's kinematics (URDF through
// reflex::control) -> MountObservations (tag point in the camera frame and in the head frame).
//
// CSV (header required, one row per view): view (optional, names the row), x_cam, y_cam, z_cam
// (the tag point in the left optical frame, metres: reflex_vision --dump's columns of that name), and
// one column per joint of the URDF that is not at zero (radians or metres, the URDF's joint names).
// Joints not given are 0. An unknown column, a missing x_cam/y_cam/z_cam, a value that is not a
// number or a row of the wrong length is an error naming the file, line and column.
#include "reflex/vision/stereo_calibrate.hpp"

#include <reflex/control/model.hpp>

#include <Eigen/Geometry>

#include <string>
#include <vector>

namespace reflex::vision {

struct MountKinematics {
  const control::Model* model = nullptr;
  int head_link = -1;
  int hand_link = -1;
  Eigen::Vector3d p_hand = Eigen::Vector3d::Zero();  ///< tag point in the hand link frame, metres
};

/// Reads the CSV; p_H = X_B_H(q)^-1 X_B_hand(q) p_hand per row. Throws VisionError naming the file/line.
std::vector<MountObservation> readMountObservations(const std::string& csv_path, const MountKinematics& k);

/// `text` as a finite number (the whole text); VisionError "<where>: '<text>' is not a finite number".
double parseNumber(const std::string& text, const std::string& where);

/// Pose of `link` in the model's root frame (the robot base frame B) with every joint at zero.
Eigen::Isometry3d linkPoseAtZero(const control::Model& model, int link);

}  // namespace reflex::vision
