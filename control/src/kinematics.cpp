#include "reflex/control/kinematics.hpp"

#include <cassert>
#include <cmath>
#include <limits>

namespace reflex::control {
namespace {

/// R_out = R * Rot(axis, angle) for a unit axis. Coordinate axes (the usual URDF case) take the
/// short path: two columns of R mixed by cos / sin instead of building and multiplying a matrix.
template <typename Out>
void rotateAbout(const Eigen::Matrix3d& R, const Eigen::Vector3d& axis, double angle, Out&& R_out) {
  const double c = std::cos(angle);
  const double s = std::sin(angle);
  // Column indices (i, j) mixed by a positive rotation about axis k, and the sign of the axis.
  int k = -1;
  for (int a = 0; a < 3; ++a)
    if ((axis[a] == 1.0 || axis[a] == -1.0) && axis[(a + 1) % 3] == 0.0 && axis[(a + 2) % 3] == 0.0) k = a;
  if (k < 0) {
    R_out = R * Eigen::AngleAxisd(angle, axis).toRotationMatrix();
    return;
  }
  const int i = (k + 1) % 3;
  const int j = (k + 2) % 3;
  const double ss = axis[k] > 0.0 ? s : -s;
  // Rot about e_k: e_i -> c e_i + s e_j, e_j -> -s e_i + c e_j.
  const Eigen::Vector3d col_i = c * R.col(i) + ss * R.col(j);
  const Eigen::Vector3d col_j = c * R.col(j) - ss * R.col(i);
  R_out.col(k) = R.col(k);
  R_out.col(i) = col_i;
  R_out.col(j) = col_j;
}

/// Sets a small matrix to zero column by column: Eigen's setZero() on a whole dynamic matrix becomes
/// a memset call, whose start-up cost dominated these few-hundred-byte Jacobians in bench_distance.
template <typename Matrix>
void zeroColumns(Matrix&& M) {
  for (Eigen::Index c = 0; c < M.cols(); ++c)
    for (Eigen::Index r = 0; r < M.rows(); ++r) M(r, c) = 0.0;
}

}  // namespace

KinematicsData::KinematicsData(const Model& model)
    : X_B_L(model.links.size(), Eigen::Isometry3d::Identity()),
      axis_B(model.links.size(), Eigen::Vector3d::UnitZ()),
      q(Eigen::VectorXd::Zero(model.nq)),
      twist_B(Eigen::Matrix<double, 6, Eigen::Dynamic>::Zero(6, model.nq)),
      moved(model.links.size(), 1) {
  // Every pose computed (none kept: `moved` starts set and the joint values are compared with NaN).
  q.setConstant(std::numeric_limits<double>::quiet_NaN());
  computeForwardKinematics(model, *this, Eigen::VectorXd::Zero(model.nq));
}

bool computeForwardKinematics(const Model& model, KinematicsData& data, const Eigen::Ref<const Eigen::VectorXd>& q,
                              const KinematicsData* near) {
  if (q.size() != model.nq || !q.allFinite()) return false;
  assert(data.X_B_L.size() == model.links.size());
  assert(near != &data);
  assert(data.moved.size() == model.links.size());
  const std::size_t n = model.links.size();
  // data.q still holds the joint values of the poses in data; NaN: none computed yet (construction),
  // and a model without joints has nothing worth keeping.
  const unsigned char root_moved = data.q.size() == 0 || data.q[0] != data.q[0] ? 1 : 0;
  for (std::size_t i = 0; i < n; ++i) {
    const Link& link = model.links[i];
    if (link.parent < 0) {
      data.X_B_L[i].setIdentity();
      data.axis_B[i] = link.axis_J;
      data.moved[i] = root_moved;
      continue;
    }
    // A link whose parent kept its pose and whose joint value is the one of its pose keeps it; one
    // whose parent pose and joint value are those of `near` has near's: the same operations on the
    // same values (links come after their parent).
    const std::size_t parent = static_cast<std::size_t>(link.parent);
    if (!data.moved[parent] && (link.q_index < 0 || q[link.q_index] == data.q[link.q_index])) {
      data.moved[i] = 0;
      continue;
    }
    data.moved[i] = 1;
    if (near && (link.q_index < 0 || q[link.q_index] == near->q[link.q_index]) &&
        data.X_B_L[parent].matrix() == near->X_B_L[parent].matrix()) {
      data.X_B_L[i] = near->X_B_L[i];
      data.axis_B[i] = near->axis_B[i];
      continue;
    }
    const Eigen::Isometry3d X_B_J = data.X_B_L[link.parent] * link.X_P_J;
    data.axis_B[i] = X_B_J.linear() * link.axis_J;
    switch (link.type) {
      case JointType::kFixed: data.X_B_L[i] = X_B_J; break;
      case JointType::kRevolute:
        rotateAbout(X_B_J.linear(), link.axis_J, q[link.q_index], data.X_B_L[i].linear());
        data.X_B_L[i].translation() = X_B_J.translation();
        break;
      case JointType::kPrismatic:
        data.X_B_L[i].linear() = X_B_J.linear();
        data.X_B_L[i].translation() = X_B_J.translation() + data.axis_B[i] * q[link.q_index];
        break;
    }
  }
  data.q = q;
  for (int j = 0; j < model.nq; ++j) {
    const int l = model.q_link[j];
    if (!data.moved[static_cast<std::size_t>(l)]) continue;  // its twist is the one computed with its pose
    const Eigen::Vector3d& axis = data.axis_B[l];
    if (model.links[l].type == JointType::kRevolute) {
      data.twist_B.col(j).head<3>() = axis;
      data.twist_B.col(j).tail<3>() = data.X_B_L[l].translation().cross(axis);
    } else {
      data.twist_B.col(j).head<3>().setZero();
      data.twist_B.col(j).tail<3>() = axis;
    }
  }
  return true;
}

void computePointJacobian(const Model& model, const KinematicsData& data, int link, const Eigen::Vector3d& p_B,
                          Eigen::Ref<Eigen::MatrixXd> J_B) {
  assert(J_B.rows() == 3 && J_B.cols() == model.nq);
  zeroColumns(J_B);
  for (const int qi : model.link_support[link]) {
    const auto t = data.twist_B.col(qi);
    J_B.col(qi) = t.head<3>().cross(p_B) + t.tail<3>();
  }
}

void computeRelativeJacobian(const Model& model, const KinematicsData& data, int link1, const Eigen::Vector3d& p1_B,
                             int link2, const Eigen::Vector3d& p2_B, Eigen::Ref<Eigen::MatrixXd> J_B) {
  assert(J_B.rows() == 3 && J_B.cols() == model.nq);
  zeroColumns(J_B);
  for (const int qi : model.link_support[link1]) {
    const auto t = data.twist_B.col(qi);
    J_B.col(qi) += t.head<3>().cross(p1_B) + t.tail<3>();
  }
  for (const int qi : model.link_support[link2]) {
    const auto t = data.twist_B.col(qi);
    J_B.col(qi) -= t.head<3>().cross(p2_B) + t.tail<3>();
  }
}

std::size_t commonSupport(const Model& model, int link1, int link2) {
  const std::vector<int>& s1 = model.link_support[static_cast<std::size_t>(link1)];
  const std::vector<int>& s2 = model.link_support[static_cast<std::size_t>(link2)];
  std::size_t common = 0;
  while (common < s1.size() && common < s2.size() && s1[common] == s2[common]) ++common;
  return common;
}

void computeDirectionalRowOnSupport(const Model& model, const KinematicsData& data, int link1,
                                    const Eigen::Vector3d& p1_B, int link2, const Eigen::Vector3d& p2_B,
                                    const Eigen::Vector3d& n_B, std::size_t common, double* row) {
  const std::vector<int>& s1 = model.link_support[static_cast<std::size_t>(link1)];
  const std::vector<int>& s2 = model.link_support[static_cast<std::size_t>(link2)];
  // n . (w x p + v) = w . (p x n) + v . n for a joint with twist (w, v). Joints on the common path
  // from the root move p1 and p2 as one rigid body: their entry is w . ((p1 - p2) x n) (0 when n is
  // along p1 - p2, as for a PairDistance; the v terms cancel). Below the common path the two paths
  // share no joint (a tree), so every column is written once.
  const Eigen::Vector3d w = (p1_B - p2_B).cross(n_B);
  for (std::size_t k = 0; k < common; ++k) row[s1[k]] = data.twist_B.col(s1[k]).head<3>().dot(w);
  Eigen::Matrix<double, 6, 1> x1, x2;
  x1 << p1_B.cross(n_B), n_B;
  x2 << p2_B.cross(n_B), n_B;
  for (std::size_t k = common; k < s1.size(); ++k) row[s1[k]] = data.twist_B.col(s1[k]).dot(x1);
  for (std::size_t k = common; k < s2.size(); ++k) row[s2[k]] = -data.twist_B.col(s2[k]).dot(x2);
}

void computeDirectionalRow(const Model& model, const KinematicsData& data, int link1, const Eigen::Vector3d& p1_B,
                           int link2, const Eigen::Vector3d& p2_B, const Eigen::Vector3d& n_B,
                           Eigen::Ref<Eigen::RowVectorXd> row) {
  assert(row.cols() == model.nq);
  zeroColumns(row);
  computeDirectionalRowOnSupport(model, data, link1, p1_B, link2, p2_B, n_B, commonSupport(model, link1, link2),
                                 row.data());
}

}  // namespace reflex::control
