// Counting replacements of the global operator new / delete, every form (plain, array, nothrow,
// aligned), on malloc / free, and of malloc / calloc / realloc themselves while an AllocationCount
// lives (Eigen's dynamic matrices allocate with malloc, not operator new). For the tests that assert
// that a real-time path allocates nothing: the count before and after the call, with nothing else
// running on other threads of the program that could allocate meanwhile (or with their allocations
// accounted for), or the calling thread's own operator new count (threadAllocations()).
//
// Include this header in EXACTLY ONE source file of a test program (it defines the replacements).
// Under AddressSanitizer, which owns malloc, only operator new is counted (kCountsMalloc is false).
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

inline std::atomic<int>& mallocCountersAlive() {
  static std::atomic<int> n{0};
  return n;
}

// Under AddressSanitizer malloc belongs to the sanitizer: count operator new only. GCC says so with
// __SANITIZE_ADDRESS__, clang with __has_feature(address_sanitizer).
#if defined(__SANITIZE_ADDRESS__)
#define REFLEX_TESTING_UNDER_ASAN 1
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
#define REFLEX_TESTING_UNDER_ASAN 1
#endif
#endif
#if defined(REFLEX_TESTING_UNDER_ASAN)
inline constexpr bool kCountsMalloc = false;
#else
inline constexpr bool kCountsMalloc = true;
#endif

/// Every allocation of the program (operator new, and malloc / calloc / realloc where kCountsMalloc)
/// from construction to count(): operator new alone is counted all the time; the malloc family only
/// while an AllocationCount lives (an operator new inside one then counts twice).
class AllocationCount {
 public:
  AllocationCount() : start_(allocations()) { ++mallocCountersAlive(); }
  ~AllocationCount() { --mallocCountersAlive(); }
  AllocationCount(const AllocationCount&) = delete;
  AllocationCount& operator=(const AllocationCount&) = delete;
  long count() const { return allocations() - start_; }

 private:
  long start_;
};
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

#if !defined(REFLEX_TESTING_UNDER_ASAN)
// The malloc family on glibc's own entry points, counted while an AllocationCount lives.
extern "C" {
void* __libc_malloc(std::size_t) noexcept;
void* __libc_calloc(std::size_t, std::size_t) noexcept;
void* __libc_realloc(void*, std::size_t) noexcept;
void* malloc(std::size_t n) noexcept {
  if (reflex::testing::mallocCountersAlive().load(std::memory_order_relaxed) > 0)
    ++reflex::testing::allocationCounter();
  return __libc_malloc(n);
}
void* calloc(std::size_t n, std::size_t m) noexcept {
  if (reflex::testing::mallocCountersAlive().load(std::memory_order_relaxed) > 0)
    ++reflex::testing::allocationCounter();
  return __libc_calloc(n, m);
}
void* realloc(void* p, std::size_t n) noexcept {
  if (reflex::testing::mallocCountersAlive().load(std::memory_order_relaxed) > 0)
    ++reflex::testing::allocationCounter();
  return __libc_realloc(p, n);
}
}
#endif
