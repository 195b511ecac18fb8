// The sweep's inner loop (computeSegmentDistances, distance.cpp): the core closest points of a batch
// of primitive pairs. Two kernels give the same bits: the scalar one (geometry.hpp's
// closestParametersSegmentSegment, then the core distance) and an AVX2 one that runs four pairs per
// instruction with every operation of the scalar one, in the same order, on the same operands
// (IEEE add, multiply, divide and square root are correctly rounded; no FMA, which would round
// differently; max/min with the scalar clamp's NaN rule). Chosen at run time: the AVX2 one only on a
// CPU that has it, so the library runs on every x86-64 (and elsewhere, scalar).
#pragma once

#include "reflex/control/geometry.hpp"

#include <cmath>

namespace reflex::control::detail {

/// For j in [0, n): the closest-point parameters s[j], t[j] of primitives prim[a[j]], prim[b[j]]
/// and their core distance core[j]. Allocation-free, never throws.
void coreDistancesScalar(const SegmentB* prim, const int* a, const int* b, int n, double* core, double* s, double* t);

/// The same, four pairs at a time with AVX2 (the rest scalar). Only call when avx2Available().
void coreDistancesAvx2(const SegmentB* prim, const int* a, const int* b, int n, double* core, double* s, double* t);

/// The broad phase's bounds: for r in [0, n), gap[r] = |c[a[r]] - c[b[r]]| - rsum[r], where c holds
/// 4 doubles per segment (x, y, z, 0) and the norm is sqrt((x^2 + y^2) + z^2).
void boundGapsScalar(const double* c4, const int* a, const int* b, const double* rsum, int n, double* gap);

/// The same, four pairs at a time with AVX2. Only call when avx2Available().
void boundGapsAvx2(const double* c4, const int* a, const int* b, const double* rsum, int n, double* gap);

/// Whether this CPU (and build) runs coreDistancesAvx2.
bool avx2Available();

/// One pair's core distance and parameters, the scalar kernel's arithmetic.
inline double coreDistance(const SegmentB& A, const SegmentB& B, double& s, double& t) {
  closestParametersSegmentSegment(A, B, s, t);
  const double dx = (A.start.x() + s * A.d.x()) - (B.start.x() + t * B.d.x());
  const double dy = (A.start.y() + s * A.d.y()) - (B.start.y() + t * B.d.y());
  const double dz = (A.start.z() + s * A.d.z()) - (B.start.z() + t * B.d.z());
  return std::sqrt(dx * dx + dy * dy + dz * dz);
}

}  // namespace reflex::control::detail
