#include "reflex/control/redundancy.hpp"

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <Eigen/LU>

namespace reflex::control {

void dampedPseudoInverse(const TaskJacobian& J, double lambda, TaskJacobianInverse& J_pinv) {
  Eigen::Matrix3d M = J * J.transpose();
  M.diagonal().array() += lambda * lambda;
  J_pinv = J.transpose() * M.inverse();
}

void dampedPseudoInverse(const ArmRow& row, double lambda, ArmVector& row_pinv) {
  row_pinv = row.transpose() / (row.squaredNorm() + lambda * lambda);
}

void nullspaceProjector(const TaskJacobian& J, ArmMatrix& N, double sigma_min) {
  const Eigen::Index n = J.cols();
  N.setIdentity(n, n);
  const Eigen::Matrix3d JJt = J * J.transpose();
  // Well conditioned (the common case): N = I - J^T (J J^T)^-1 J through a Cholesky factorization.
  const Eigen::LLT<Eigen::Matrix3d> llt(JJt);
  if (llt.info() == Eigen::Success) {
    const Eigen::Vector3d diag = llt.matrixL().toDenseMatrix().diagonal();
    if (diag.minCoeff() > 1e-3 * diag.maxCoeff() && diag.minCoeff() > sigma_min) {
      N.noalias() -= J.transpose() * llt.solve(Eigen::Matrix<double, 3, Eigen::Dynamic, 0, 3, kMaxArmDof>(J));
      return;
    }
  }
  // Near a singularity: J J^T = U S^2 U^T; the row space of J is spanned by J^T u_i / s_i, s_i > sigma_min.
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(JJt);
  for (int i = 0; i < 3; ++i) {
    const double s2 = eig.eigenvalues()[i];
    if (!(s2 > sigma_min * sigma_min)) continue;
    const ArmVector v = J.transpose() * eig.eigenvectors().col(i) / std::sqrt(s2);
    N.noalias() -= v * v.transpose();
  }
}

void nullspaceProjector(const ArmRow& row, ArmMatrix& N, double sigma_min) {
  const Eigen::Index n = row.cols();
  N.setIdentity(n, n);
  const double r2 = row.squaredNorm();
  if (r2 > sigma_min * sigma_min) N.noalias() -= row.transpose() * row / r2;
}

}  // namespace reflex::control
