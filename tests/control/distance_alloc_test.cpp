// The per-cycle path (computeForwardKinematics + computeSegmentDistances, also with body-schema
// slots attached, and the Jacobian functions) makes no heap allocation.
//
// This binary replaces the global operator new / delete with counting versions. Eigen's dynamic
// matrices allocate with std::malloc, not operator new, so malloc / calloc / realloc are counted as
// well (forwarding to glibc's __libc_* entry points); under AddressSanitizer, which owns malloc,
// only operator new is counted.
#include "reflex/control/distance.hpp"
#include "reflex/control/kinematics.hpp"
#include "test_support.hpp"

#include <gtest/gtest.h>

#include <atomic>
#include <cstdlib>
#include <limits>
#include <memory>
#include <new>
#include <random>
#include <vector>

namespace {
std::atomic<long> g_allocations{0};
}  // namespace

void* operator new(std::size_t n) {
  ++g_allocations;
  if (void* p = std::malloc(n ? n : 1)) return p;
  throw std::bad_alloc();
}
void* operator new[](std::size_t n) { return operator new(n); }
void* operator new(std::size_t n, const std::nothrow_t&) noexcept {
  ++g_allocations;
  return std::malloc(n ? n : 1);
}
void* operator new[](std::size_t n, const std::nothrow_t& t) noexcept { return operator new(n, t); }
void* operator new(std::size_t n, std::align_val_t a) {
  ++g_allocations;
  void* p = nullptr;
  if (posix_memalign(&p, static_cast<std::size_t>(a), n ? n : 1) != 0) throw std::bad_alloc();
  return p;
}
void* operator new[](std::size_t n, std::align_val_t a) { return operator new(n, a); }
void operator delete(void* p) noexcept { std::free(p); }
void operator delete[](void* p) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }
void operator delete[](void* p, std::size_t) noexcept { std::free(p); }
void operator delete(void* p, std::align_val_t) noexcept { std::free(p); }
void operator delete[](void* p, std::align_val_t) noexcept { std::free(p); }
void operator delete(void* p, std::size_t, std::align_val_t) noexcept { std::free(p); }
void operator delete[](void* p, std::size_t, std::align_val_t) noexcept { std::free(p); }

// Under AddressSanitizer malloc belongs to the sanitizer: count operator new only. GCC says so with
// __SANITIZE_ADDRESS__, clang with __has_feature(address_sanitizer).
#if defined(__SANITIZE_ADDRESS__)
#define REFLEX_UNDER_ASAN 1
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
#define REFLEX_UNDER_ASAN 1
#endif
#endif
#if !defined(REFLEX_UNDER_ASAN)
#define REFLEX_COUNT_MALLOC 1
extern "C" {
void* __libc_malloc(std::size_t);
void* __libc_calloc(std::size_t, std::size_t);
void* __libc_realloc(void*, std::size_t);
// Counted only while armed, so that operator new above (which calls malloc) counts once.
std::atomic<bool> g_count_malloc{false};
void* malloc(std::size_t n) {
  if (g_count_malloc.load(std::memory_order_relaxed)) ++g_allocations;
  return __libc_malloc(n);
}
void* calloc(std::size_t n, std::size_t m) {
  if (g_count_malloc.load(std::memory_order_relaxed)) ++g_allocations;
  return __libc_calloc(n, m);
}
void* realloc(void* p, std::size_t n) {
  if (g_count_malloc.load(std::memory_order_relaxed)) ++g_allocations;
  return __libc_realloc(p, n);
}
}
#endif

namespace reflex::control {
namespace {

/// Counts allocations between construction and count().
class AllocationCounter {
 public:
  AllocationCounter() {
    g_allocations = 0;
#ifdef REFLEX_COUNT_MALLOC
    g_count_malloc = true;
#endif
  }
  ~AllocationCounter() { stop(); }
  long stop() {
#ifdef REFLEX_COUNT_MALLOC
    g_count_malloc = false;
#endif
    return g_allocations.load();
  }

 private:
};

TEST(DistanceAlloc, CounterSeesOperatorNewAndEigenAllocations) {
  {
    AllocationCounter c;
    auto v = std::make_unique<std::vector<int>>(100);
    EXPECT_GE(c.stop(), 2);
  }
#ifdef REFLEX_COUNT_MALLOC
  {
    AllocationCounter c;
    Eigen::MatrixXd m(50, 50);  // std::malloc inside Eigen
    m.setZero();
    EXPECT_GE(c.stop(), 1);
  }
#endif
}

void runCycles(const char* robot) {
  const Model model = testing::loadRobot(robot);
  KinematicsData kin(model);
  DistanceData dist(model);
  std::mt19937_64 rng(17);
  std::vector<Eigen::VectorXd> qs;
  for (int i = 0; i < 50; ++i) qs.push_back(test::randomConfiguration(model, rng));
  Eigen::VectorXd q_nan = qs[0];
  q_nan[0] = std::numeric_limits<double>::quiet_NaN();
  Eigen::MatrixXd J(3, model.nq);
  Eigen::RowVectorXd row(model.nq);
  const int hand = model.linkIndex("l_hand");
  const int head = model.linkIndex("head");
  const DistanceOptions rows_on{};
  const DistanceOptions rows_off{-std::numeric_limits<double>::infinity()};
  const DistanceOptions rows_near{0.04};
  const DistanceOptions pruned{0.04, 0.04};  // the controller's: rows and broad phase at d_a
  std::vector<int> listed;
  for (int p = 0; p < static_cast<int>(model.pairs.size()); p += 2) listed.push_back(p);
  DistanceData scratch(model);

  AllocationCounter counter;
  for (int i = 0; i < 50; ++i) {
    computeForwardKinematics(model, kin, qs[i]);
    computeSegmentDistances(model, kin, dist, rows_on);
    computeSegmentDistances(model, kin, dist, rows_off);
    computeSegmentDistances(model, kin, dist, rows_near);
    computeSegmentDistances(model, kin, dist, pruned);
    computeListedPairDistances(model, kin, dist.slots, scratch, listed.data(), static_cast<int>(listed.size()));
    computeListedPairDistances(model, kin, dist.slots, scratch, listed.data(), static_cast<int>(listed.size()), 0.02);
    computePointJacobian(model, kin, hand, kin.X_B_L[hand].translation(), J);
    computeRelativeJacobian(model, kin, hand, kin.X_B_L[hand].translation(), head, kin.X_B_L[head].translation(), J);
    computeDirectionalRow(model, kin, hand, kin.X_B_L[hand].translation(), head, kin.X_B_L[head].translation(),
                          Eigen::Vector3d::UnitX(), row);
    // Body schema at run time: attach, check, detach.
    if (i == 10) attachBodySchemaSegment(model, dist, 0, hand, Eigen::Vector3d(0, 0, -0.05), Eigen::Vector3d(0.2, 0, -0.05),
                                         0.02, 0);
    if (i == 20) attachBodySchemaSegment(model, dist, 3, head, Eigen::Vector3d::Zero(), Eigen::Vector3d(0.5, 0, 0), 0.03);
    if (i == 40) detachBodySchemaSegment(dist, 0);
    computeForwardKinematics(model, kin, q_nan);  // rejected, still no allocation
  }
  const long allocations = counter.stop();
  EXPECT_EQ(allocations, 0) << robot;
  // The loop really ran the slots (else the test would prove less than it claims).
  EXPECT_TRUE(dist.slots[3].enabled);
  EXPECT_GE(dist.closest, 0);
}

TEST(DistanceAlloc, PerCycleRoutinesDoNotAllocateOnTheShippedRobot) { runCycles(testing::kAsimo); }

TEST(DistanceAlloc, PerCycleRoutinesDoNotAllocateOnTheSecondHumanoid) { runCycles(testing::kSmall); }

// The tight model: convex pieces, the narrow phase's candidate lists and early stops.
TEST(DistanceAlloc, PerCycleRoutinesDoNotAllocateOnTheTightModel) { runCycles("mesh_humanoid"); }

}  // namespace
}  // namespace reflex::control
