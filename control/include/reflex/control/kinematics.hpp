// Forward kinematics and Jacobians (positions only) for a Model.
//
// Frames: B = root link frame. Jacobians are 3 x nq, in B, of a point fixed to a link, given by its
// current position p_B. Columns of joints that do not move the link are zero.
// Per-cycle functions allocate nothing and never throw; sizes are asserted.
#pragma once

#include "reflex/control/model.hpp"

#include <Eigen/Core>
#include <Eigen/Geometry>

#include <vector>

namespace reflex::control {

/// Per-cycle kinematic results, sized from the model. One per thread of use.
struct KinematicsData {
  explicit KinematicsData(const Model& model);

  std::vector<Eigen::Isometry3d> X_B_L;  ///< pose of every link in B
  std::vector<Eigen::Vector3d> axis_B;   ///< joint axis of every link's parent joint, in B
  Eigen::VectorXd q;                     ///< the configuration the poses belong to
  /// Per joint (column = q index), its unit twist in B: angular part w (rows 0-2; the axis for a
  /// revolute joint, 0 for a prismatic one) and linear part v (rows 3-5; o x axis for a revolute
  /// joint at origin o, the axis for a prismatic one). A point p_B moved by joint j moves at
  /// (w x p_B + v) per unit qdot_j: the Jacobian and row functions use it, so the per-joint work
  /// (o x axis) is done once per cycle instead of once per pair.
  Eigen::Matrix<double, 6, Eigen::Dynamic> twist_B;
  /// Per link, whether the last computeForwardKinematics changed its pose (scratch of the next one).
  std::vector<unsigned char> moved;
};

/// Forward kinematics. Returns false (and leaves `data` unchanged) if q has the wrong size or a
/// non-finite value; the caller then keeps its last valid state. A link whose parent kept its pose
/// and whose joint value is the one `data` last had keeps its pose (the arms move, the legs and head
/// cost nothing). With `near` (the kinematics of a configuration that differs from q in a few joints,
/// e.g. the cycle's for a prediction one step ahead), a link whose parent pose and joint value equal
/// near's copies its pose from it. Either way the same bits as computing it.
bool computeForwardKinematics(const Model& model, KinematicsData& data, const Eigen::Ref<const Eigen::VectorXd>& q,
                              const KinematicsData* near = nullptr);

/// J_B (3 x nq) of the point p_B rigidly attached to `link` (after computeForwardKinematics).
void computePointJacobian(const Model& model, const KinematicsData& data, int link, const Eigen::Vector3d& p_B,
                          Eigen::Ref<Eigen::MatrixXd> J_B);

/// Relative Jacobian J_B_p1 - J_B_p2 (3 x nq) of two points on two links: the rate of p1 - p2.
void computeRelativeJacobian(const Model& model, const KinematicsData& data, int link1, const Eigen::Vector3d& p1_B,
                             int link2, const Eigen::Vector3d& p2_B, Eigen::Ref<Eigen::MatrixXd> J_B);

/// The directional row n^T (J_B_p1 - J_B_p2) (1 x nq): the rate of the distance along n_B.
/// With n_B = (p1 - p2)/d this is the paper's J_ca|row,y (Eq. 8): positive row velocity separates.
void computeDirectionalRow(const Model& model, const KinematicsData& data, int link1, const Eigen::Vector3d& p1_B,
                           int link2, const Eigen::Vector3d& p2_B, const Eigen::Vector3d& n_B,
                           Eigen::Ref<Eigen::RowVectorXd> row);

/// How many joints the support paths of link1 and link2 share from the root (Model::link_support).
std::size_t commonSupport(const Model& model, int link1, int link2);

/// computeDirectionalRow writing only the columns of the joints that move link1 or link2 (the
/// others keep their values: a caller whose rows always join the same two links zeroes them once).
/// common = commonSupport(model, link1, link2); row points at nq doubles.
void computeDirectionalRowOnSupport(const Model& model, const KinematicsData& data, int link1,
                                    const Eigen::Vector3d& p1_B, int link2, const Eigen::Vector3d& p2_B,
                                    const Eigen::Vector3d& n_B, std::size_t common, double* row);

}  // namespace reflex::control
