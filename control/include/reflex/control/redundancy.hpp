// Redundancy resolution for one arm (Eq. 2-3, 8-9): the singularity-robust inverse used for the
// task terms and the exact nullspace projector used for the gradient terms, so that nullspace
// criteria never disturb the primary task (J N = 0 to rounding), even near singularities.
// Arm-sized types have a fixed maximum size: nothing here allocates.
#pragma once

#include <Eigen/Core>

namespace reflex::control {

inline constexpr int kMaxArmDof = 8;

using ArmVector = Eigen::Matrix<double, Eigen::Dynamic, 1, 0, kMaxArmDof, 1>;
using ArmRow = Eigen::Matrix<double, 1, Eigen::Dynamic, Eigen::RowMajor, 1, kMaxArmDof>;
using ArmMatrix = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, 0, kMaxArmDof, kMaxArmDof>;
using TaskJacobian = Eigen::Matrix<double, 3, Eigen::Dynamic, 0, 3, kMaxArmDof>;         ///< 3 x n
using TaskJacobianInverse = Eigen::Matrix<double, Eigen::Dynamic, 3, 0, kMaxArmDof, 3>;  ///< n x 3

/// Singularity-robust (damped least-squares) inverse J^T (J J^T + lambda^2 I)^-1 (Nakamura; Wampler).
void dampedPseudoInverse(const TaskJacobian& J, double lambda, TaskJacobianInverse& J_pinv);

/// Damped inverse of a row: row^T / (row row^T + lambda^2).
void dampedPseudoInverse(const ArmRow& row, double lambda, ArmVector& row_pinv);

/// Exact projector onto the nullspace of J: I - J^+ J, with J^+ the Moore-Penrose inverse over the
/// singular directions whose singular value exceeds `sigma_min` (m/rad).
void nullspaceProjector(const TaskJacobian& J, ArmMatrix& N, double sigma_min = 1e-6);

/// Exact projector onto the nullspace of a row: I - row^T row / |row|^2 (identity if |row| <= sigma_min).
void nullspaceProjector(const ArmRow& row, ArmMatrix& N, double sigma_min = 1e-6);

}  // namespace reflex::control
