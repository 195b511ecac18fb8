// Counting replacements of the global operator new / delete, every form (plain, array, nothrow,
// aligned), on malloc / free. For the tests that assert that a real-time path allocates nothing:
// the count before and after the call, with nothing else running on other threads of the program
// that could allocate meanwhile (or with their allocations accounted for), or the calling thread's own
// count (threadAllocations()).
//
// Include this header in EXACTLY ONE source file of a test program (it defines the replacements).
// Counted: operator new only, not malloc (Eigen's dynamic matrices allocate with malloc;
// distance_alloc_test counts malloc too, with its own replacements).
#pragma once

#include <atomic>
#include <cstdlib>
#include <new>

namespace reflex::testing {
inline std::atomic<long>& allocationCounter() {
  static std::atomic<long> count{0};
  return count;
}
/// operator new calls so far, on every thread of this program.
inline long allocations() { return allocationCounter().load(); }
inline long& threadAllocationCounter() {
  thread_local long count = 0;
  return count;
}
/// operator new calls so far on the calling thread only: a real-time thread's own, while other
/// threads of the program (Fast DDS's, an outbox's writer) allocate as they like.
inline long threadAllocations() { return threadAllocationCounter(); }
}  // namespace reflex::testing

// GCC cannot see that the replaced new / delete are a pair once inlined and warns about every pair.
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic ignored "-Wmismatched-new-delete"
#endif

void* operator new(std::size_t n) {
  ++reflex::testing::allocationCounter();
  ++reflex::testing::threadAllocationCounter();
  if (void* p = std::malloc(n == 0 ? 1 : n)) return p;
  throw std::bad_alloc();
}
void* operator new[](std::size_t n) { return operator new(n); }
void* operator new(std::size_t n, const std::nothrow_t&) noexcept {
  ++reflex::testing::allocationCounter();
  ++reflex::testing::threadAllocationCounter();
  return std::malloc(n == 0 ? 1 : n);
}
void* operator new[](std::size_t n, const std::nothrow_t& t) noexcept { return operator new(n, t); }
void* operator new(std::size_t n, std::align_val_t a) {
  ++reflex::testing::allocationCounter();
  ++reflex::testing::threadAllocationCounter();
  void* p = nullptr;
  if (posix_memalign(&p, static_cast<std::size_t>(a), n == 0 ? 1 : n) != 0) throw std::bad_alloc();
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
