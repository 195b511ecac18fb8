// By hand (built with the benchmarks, not a CTest: it is meant to crash): reproduces the start race
// of libapriltag's worker pool (before 3.4.3; upstream issue #70, fixed by PR #339) with libapriltag
// alone, no Reflex code. One detector, one 640x480 image with six tag36h11 tags; each detect
// alternates nthreads between N and N+1, so libapriltag destroys its pool and starts a new one
// (N or N+1 fresh threads) on every call, then fills its task list while those threads start.
// With the race, a worker takes a task from the list while the caller is still appending to it;
// when the list grows, realloc frees the old block and the worker calls a function pointer read
// from freed memory: SIGSEGV (exit 139 from a shell). --reuse keeps one pool for the whole run
// (nthreads fixed): the control, which must not crash.
//   build/bin/apriltag_pool_race [--starts 20000] [--threads 2] [--reuse]
// Exit: 0 every detect found the six tags, 1 a detect found another number, 2 bad arguments.
#include <apriltag/apriltag.h>
#include <apriltag/common/image_u8.h>
#include <apriltag/tag36h11.h>

#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

int main(int argc, char** argv) {
  long starts = 20000;
  int threads = 2;
  bool reuse = false;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--starts" && i + 1 < argc) {
      starts = std::atol(argv[++i]);
    } else if (a == "--threads" && i + 1 < argc) {
      threads = std::atoi(argv[++i]);
    } else if (a == "--reuse") {
      reuse = true;
    } else {
      std::fprintf(stderr,
                   "usage: apriltag_pool_race [--starts N (>= 1)] [--threads T (2..64)] [--reuse]\n"
                   "Starts libapriltag's worker pool N times (one detect each); see the file's header.\n");
      return a == "--help" ? 0 : 2;
    }
  }
  if (starts < 1 || threads < 2 || threads > 64) {
    std::fprintf(stderr, "apriltag_pool_race: error: --starts %ld must be >= 1 and --threads %d in 2..64\n", starts,
                 threads);
    return 2;
  }
  constexpr int kWidth = 640, kHeight = 480, kCell = 12, kTags = 6;
  std::vector<std::uint8_t> pixels(kWidth * kHeight, 200);
  apriltag_family_t* family = tag36h11_create();
  for (int t = 0; t < kTags; ++t) {  // 120 px tags on a grey page, two rows of three
    image_u8_t* bits = apriltag_to_image(family, t);
    const int ox = 20 + (t % 3) * 200, oy = 40 + (t / 3) * 220;
    for (int r = 0; r < bits->height * kCell; ++r)
      for (int c = 0; c < bits->width * kCell; ++c)
        pixels[(oy + r) * kWidth + ox + c] = bits->buf[(r / kCell) * bits->stride + c / kCell];
    image_u8_destroy(bits);
  }
  image_u8_t image{kWidth, kHeight, kWidth, pixels.data()};
  apriltag_detector_t* detector = apriltag_detector_create();
  apriltag_detector_add_family_bits(detector, family, 2);
  int wrong = 0;
  for (long i = 0; i < starts; ++i) {
    detector->nthreads = reuse ? threads : threads + static_cast<int>(i % 2);
    zarray_t* detections = apriltag_detector_detect(detector, &image);
    if (zarray_size(detections) != kTags) {
      ++wrong;
      std::fprintf(stderr, "detect %ld: %d tags instead of %d\n", i, zarray_size(detections), kTags);
    }
    apriltag_detections_destroy(detections);
    if ((i + 1) % 1000 == 0) std::fprintf(stderr, "%ld detects\n", i + 1);
  }
  apriltag_detector_destroy(detector);
  tag36h11_destroy(family);
  std::printf("%ld detects (%s), %d with a wrong tag count, no crash\n", starts, reuse ? "one pool" : "a new pool each",
              wrong);
  return wrong == 0 ? 0 : 1;
}
