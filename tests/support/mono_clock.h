/* The monotonic clock for the C test robots (tests/unitree_hg/cyclone, tests/ros2/cyclone): seconds
 * since an arbitrary start, and a sleep until such a time. Header-only, C11 + POSIX. */
#ifndef REFLEX_TESTS_SUPPORT_MONO_CLOCK_H
#define REFLEX_TESTS_SUPPORT_MONO_CLOCK_H

#include <time.h>

static inline double mono_now_s(void) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

static inline void mono_sleep_until(double t) {
  const double d = t - mono_now_s();
  if (d <= 0) return;
  struct timespec ts = {(time_t)d, (long)((d - (double)(time_t)d) * 1e9)};
  nanosleep(&ts, NULL);
}

#endif
