#include "reflex/control/kinematics.hpp"

#include <cassert>

namespace reflex::control {

KinematicsData::KinematicsData(const Model& model)
    : X_W_L(model.links.size(), Eigen::Isometry3d::Identity()),
      axis_W(model.links.size(), Eigen::Vector3d::UnitZ()),
      q(Eigen::VectorXd::Zero(model.nq)) {
  computeForwardKinematics(model, *this, q);
}

bool computeForwardKinematics(const Model& model, KinematicsData& data,
                              const Eigen::Ref<const Eigen::VectorXd>& q) {
  if (q.size() != model.nq || !q.allFinite()) return false;
  assert(data.X_W_L.size() == model.links.size());
  data.q = q;
  const std::size_t n = model.links.size();
  for (std::size_t i = 0; i < n; ++i) {
    const Link& link = model.links[i];
    if (link.parent < 0) {
      data.X_W_L[i].setIdentity();
      data.axis_W[i] = link.axis_J;
      continue;
    }
    const Eigen::Isometry3d X_W_J = data.X_W_L[link.parent] * link.X_P_J;
    data.axis_W[i] = X_W_J.linear() * link.axis_J;
    switch (link.type) {
      case JointType::kFixed:
        data.X_W_L[i] = X_W_J;
        break;
      case JointType::kRevolute: {
        const Eigen::Matrix3d R = Eigen::AngleAxisd(q[link.q_index], link.axis_J).toRotationMatrix();
        data.X_W_L[i].linear() = X_W_J.linear() * R;
        data.X_W_L[i].translation() = X_W_J.translation();
        break;
      }
      case JointType::kPrismatic:
        data.X_W_L[i].linear() = X_W_J.linear();
        data.X_W_L[i].translation() = X_W_J.translation() + data.axis_W[i] * q[link.q_index];
        break;
    }
  }
  return true;
}

void computePointJacobian(const Model& model, const KinematicsData& data, int link,
                          const Eigen::Vector3d& p_W, Eigen::Ref<Eigen::MatrixXd> J_W) {
  assert(J_W.rows() == 3 && J_W.cols() == model.nq);
  J_W.setZero();
  for (const int qi : model.link_support[link]) {
    const int l = model.q_link[qi];
    if (model.links[l].type == JointType::kRevolute)
      J_W.col(qi) = data.axis_W[l].cross(p_W - data.X_W_L[l].translation());
    else
      J_W.col(qi) = data.axis_W[l];
  }
}

void computeRelativeJacobian(const Model& model, const KinematicsData& data, int link1,
                             const Eigen::Vector3d& p1_W, int link2, const Eigen::Vector3d& p2_W,
                             Eigen::Ref<Eigen::MatrixXd> J_W) {
  assert(J_W.rows() == 3 && J_W.cols() == model.nq);
  J_W.setZero();
  for (const int qi : model.link_support[link1]) {
    const int l = model.q_link[qi];
    if (model.links[l].type == JointType::kRevolute)
      J_W.col(qi) += data.axis_W[l].cross(p1_W - data.X_W_L[l].translation());
    else
      J_W.col(qi) += data.axis_W[l];
  }
  for (const int qi : model.link_support[link2]) {
    const int l = model.q_link[qi];
    if (model.links[l].type == JointType::kRevolute)
      J_W.col(qi) -= data.axis_W[l].cross(p2_W - data.X_W_L[l].translation());
    else
      J_W.col(qi) -= data.axis_W[l];
  }
}

void computeDirectionalRow(const Model& model, const KinematicsData& data, int link1,
                           const Eigen::Vector3d& p1_W, int link2, const Eigen::Vector3d& p2_W,
                           const Eigen::Vector3d& n_W, Eigen::Ref<Eigen::RowVectorXd> row) {
  assert(row.cols() == model.nq);
  row.setZero();
  // n . (axis x (p - o)) = axis . ((p - o) x n)
  for (const int qi : model.link_support[link1]) {
    const int l = model.q_link[qi];
    row[qi] += model.links[l].type == JointType::kRevolute
                   ? data.axis_W[l].dot((p1_W - data.X_W_L[l].translation()).cross(n_W))
                   : data.axis_W[l].dot(n_W);
  }
  for (const int qi : model.link_support[link2]) {
    const int l = model.q_link[qi];
    row[qi] -= model.links[l].type == JointType::kRevolute
                   ? data.axis_W[l].dot((p2_W - data.X_W_L[l].translation()).cross(n_W))
                   : data.axis_W[l].dot(n_W);
  }
}

}  // namespace reflex::control
