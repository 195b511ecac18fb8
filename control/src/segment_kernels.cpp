#include "segment_kernels.hpp"

#include <cassert>

#if defined(__x86_64__) && defined(__GNUC__)
#include <immintrin.h>
#define REFLEX_HAVE_AVX2_KERNEL 1
#endif

namespace reflex::control::detail {

// The AVX2 kernel reads a SegmentB as 8 doubles: start x y z, d x y z, dd, inv_dd.
static_assert(sizeof(SegmentB) == 8 * sizeof(double), "SegmentB must be 8 packed doubles");

void coreDistancesScalar(const SegmentB* prim, const int* a, const int* b, int n, double* core, double* s, double* t) {
  for (int j = 0; j < n; ++j) {
    double sj, tj;  // locals: writing through s / t directly would force reloads (aliasing)
    core[j] = coreDistance(prim[a[j]], prim[b[j]], sj, tj);
    s[j] = sj;
    t[j] = tj;
  }
}

void boundGapsScalar(const double* c4, const int* a, const int* b, const double* rsum, int n, double* gap) {
  for (int r = 0; r < n; ++r) {
    const double* ca = c4 + 4 * a[r];
    const double* cb = c4 + 4 * b[r];
    const double dx = ca[0] - cb[0], dy = ca[1] - cb[1], dz = ca[2] - cb[2];
    gap[r] = std::sqrt((dx * dx + dy * dy) + dz * dz) - rsum[r];
  }
}

#if defined(REFLEX_HAVE_AVX2_KERNEL)

namespace {

/// The 8 fields of four primitives, one field per register (lane k: primitive k).
struct Four {
  __m256d sx, sy, sz, dx, dy, dz, dd, inv_dd;
};

/// Transposes the 4 x 4 block whose rows are r0..r3 into its columns c0..c3.
__attribute__((target("avx2"))) inline void transpose4(__m256d r0, __m256d r1, __m256d r2, __m256d r3, __m256d& c0,
                                                       __m256d& c1, __m256d& c2, __m256d& c3) {
  const __m256d t0 = _mm256_unpacklo_pd(r0, r1);  // r0[0] r1[0] r0[2] r1[2]
  const __m256d t1 = _mm256_unpackhi_pd(r0, r1);  // r0[1] r1[1] r0[3] r1[3]
  const __m256d t2 = _mm256_unpacklo_pd(r2, r3);
  const __m256d t3 = _mm256_unpackhi_pd(r2, r3);
  c0 = _mm256_permute2f128_pd(t0, t2, 0x20);
  c2 = _mm256_permute2f128_pd(t0, t2, 0x31);
  c1 = _mm256_permute2f128_pd(t1, t3, 0x20);
  c3 = _mm256_permute2f128_pd(t1, t3, 0x31);
}

/// Loads primitives p0..p3 (8 doubles each) and transposes them: two 4 x 4 blocks.
__attribute__((target("avx2"))) inline Four loadFour(const SegmentB& p0, const SegmentB& p1, const SegmentB& p2,
                                                     const SegmentB& p3) {
  const double* q0 = p0.start.data();
  const double* q1 = p1.start.data();
  const double* q2 = p2.start.data();
  const double* q3 = p3.start.data();
  Four f;
  transpose4(_mm256_loadu_pd(q0), _mm256_loadu_pd(q1), _mm256_loadu_pd(q2), _mm256_loadu_pd(q3), f.sx, f.sy, f.sz,
             f.dx);
  transpose4(_mm256_loadu_pd(q0 + 4), _mm256_loadu_pd(q1 + 4), _mm256_loadu_pd(q2 + 4), _mm256_loadu_pd(q3 + 4), f.dy,
             f.dz, f.dd, f.inv_dd);
  return f;
}

/// clamp01 of geometry.hpp, four lanes: max(x, 0) gives 0 for NaN (maxpd returns its second operand
/// when either is NaN, as maxsd does), then min(., 1).
__attribute__((target("avx2"))) inline __m256d clamp01x4(__m256d x) {
  return _mm256_min_pd(_mm256_max_pd(x, _mm256_setzero_pd()), _mm256_set1_pd(1.0));
}

}  // namespace

__attribute__((target("avx2"))) void coreDistancesAvx2(const SegmentB* prim, const int* a, const int* b, int n,
                                                       double* core, double* s, double* t) {
  assert(prim[0].d.data() == prim[0].start.data() + 3 && &prim[0].dd == prim[0].start.data() + 6 &&
         &prim[0].inv_dd == prim[0].start.data() + 7);
  const __m256d zero = _mm256_setzero_pd();
  const __m256d parallel_eps = _mm256_set1_pd(1e-14);
  int j = 0;
  for (; j + 4 <= n; j += 4) {
    const Four A = loadFour(prim[a[j]], prim[a[j + 1]], prim[a[j + 2]], prim[a[j + 3]]);
    const Four B = loadFour(prim[b[j]], prim[b[j + 1]], prim[b[j + 2]], prim[b[j + 3]]);
    // closestParametersSegmentSegment, operation for operation.
    const __m256d rx = _mm256_sub_pd(A.sx, B.sx);
    const __m256d ry = _mm256_sub_pd(A.sy, B.sy);
    const __m256d rz = _mm256_sub_pd(A.sz, B.sz);
    const __m256d f =
        _mm256_add_pd(_mm256_add_pd(_mm256_mul_pd(B.dx, rx), _mm256_mul_pd(B.dy, ry)), _mm256_mul_pd(B.dz, rz));
    const __m256d c =
        _mm256_add_pd(_mm256_add_pd(_mm256_mul_pd(A.dx, rx), _mm256_mul_pd(A.dy, ry)), _mm256_mul_pd(A.dz, rz));
    const __m256d bb =
        _mm256_add_pd(_mm256_add_pd(_mm256_mul_pd(A.dx, B.dx), _mm256_mul_pd(A.dy, B.dy)), _mm256_mul_pd(A.dz, B.dz));
    const __m256d ae = _mm256_mul_pd(A.dd, B.dd);
    const __m256d denom = _mm256_sub_pd(ae, _mm256_mul_pd(bb, bb));
    const __m256d not_parallel = _mm256_and_pd(_mm256_cmp_pd(denom, _mm256_mul_pd(parallel_eps, ae), _CMP_GT_OQ),
                                               _mm256_cmp_pd(denom, zero, _CMP_GT_OQ));
    const __m256d s_div = _mm256_div_pd(_mm256_sub_pd(_mm256_mul_pd(bb, f), _mm256_mul_pd(c, B.dd)), denom);
    const __m256d s_line = _mm256_blendv_pd(zero, s_div, not_parallel);
    const __m256d s0 = clamp01x4(s_line);
    const __m256d t1 = clamp01x4(_mm256_mul_pd(_mm256_add_pd(_mm256_mul_pd(bb, s0), f), B.inv_dd));
    const __m256d s1 = clamp01x4(_mm256_mul_pd(_mm256_sub_pd(_mm256_mul_pd(bb, t1), c), A.inv_dd));
    // coreDistance.
    const __m256d ex =
        _mm256_sub_pd(_mm256_add_pd(A.sx, _mm256_mul_pd(s1, A.dx)), _mm256_add_pd(B.sx, _mm256_mul_pd(t1, B.dx)));
    const __m256d ey =
        _mm256_sub_pd(_mm256_add_pd(A.sy, _mm256_mul_pd(s1, A.dy)), _mm256_add_pd(B.sy, _mm256_mul_pd(t1, B.dy)));
    const __m256d ez =
        _mm256_sub_pd(_mm256_add_pd(A.sz, _mm256_mul_pd(s1, A.dz)), _mm256_add_pd(B.sz, _mm256_mul_pd(t1, B.dz)));
    const __m256d sq =
        _mm256_add_pd(_mm256_add_pd(_mm256_mul_pd(ex, ex), _mm256_mul_pd(ey, ey)), _mm256_mul_pd(ez, ez));
    _mm256_storeu_pd(core + j, _mm256_sqrt_pd(sq));
    _mm256_storeu_pd(s + j, s1);
    _mm256_storeu_pd(t + j, t1);
  }
  coreDistancesScalar(prim, a + j, b + j, n - j, core + j, s + j, t + j);
}

__attribute__((target("avx2"))) void boundGapsAvx2(const double* c4, const int* a, const int* b, const double* rsum,
                                                   int n, double* gap) {
  int r = 0;
  for (; r + 4 <= n; r += 4) {
    __m256d v[4];
    for (int k = 0; k < 4; ++k) {
      const __m256d diff = _mm256_sub_pd(_mm256_loadu_pd(c4 + 4 * a[r + k]), _mm256_loadu_pd(c4 + 4 * b[r + k]));
      v[k] = _mm256_mul_pd(diff, diff);  // x^2 y^2 z^2 0
    }
    const __m256d h01 = _mm256_hadd_pd(v[0], v[1]);  // x0+y0 x1+y1 z0+0 z1+0
    const __m256d h23 = _mm256_hadd_pd(v[2], v[3]);
    const __m256d sq = _mm256_add_pd(_mm256_permute2f128_pd(h01, h23, 0x20), _mm256_permute2f128_pd(h01, h23, 0x31));
    _mm256_storeu_pd(gap + r, _mm256_sub_pd(_mm256_sqrt_pd(sq), _mm256_loadu_pd(rsum + r)));
  }
  boundGapsScalar(c4, a + r, b + r, rsum + r, n - r, gap + r);
}

bool avx2Available() {
  __builtin_cpu_init();
  return __builtin_cpu_supports("avx2");
}

#else

void coreDistancesAvx2(const SegmentB* prim, const int* a, const int* b, int n, double* core, double* s, double* t) {
  coreDistancesScalar(prim, a, b, n, core, s, t);
}

void boundGapsAvx2(const double* c4, const int* a, const int* b, const double* rsum, int n, double* gap) {
  boundGapsScalar(c4, a, b, rsum, n, gap);
}

bool avx2Available() { return false; }

#endif

}  // namespace reflex::control::detail
