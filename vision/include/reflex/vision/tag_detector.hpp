#pragma once
// RAII wrappers around the AprilTag 3 C library: a tag family and a detector.
// One TagDetector is not safe to call from two threads at once; use one per thread.
//
// Worker threads per image (DetectorOptions::threads > 1) are libapriltag's own worker pool. Before
// libapriltag 3.4.3 that pool starts racily: its threads take tasks from a list the caller is still
// filling, without a lock, and when the list grows (realloc) a worker calls a function pointer read
// from freed memory -- SIGSEGV: 5 of 6 runs of up to 30000 pool starts crashed, after 3000-22000,
// on this 2-core machine at load ~15 (tests/vision/apriltag_pool_race.cpp, libapriltag alone;
// upstream issue #70, fixed by PR #339). It once crashed vision_benchmark. Built against such a library,
// threads > 1 is refused (VisionError naming the version); the stereo pipeline's parallelism
// (left and right image on two threads, one detector each) does not use the pool.
#include <opencv2/core.hpp>

#include <array>
#include <memory>
#include <string>
#include <vector>

struct apriltag_family;
struct apriltag_detector;

namespace reflex::vision {

/// libapriltag's version this library was built against (pkg-config), e.g. "3.3.0".
std::string apriltagVersion();
/// False if that version's worker pool has the start race above (then threads must be 1).
bool apriltagWorkerPoolIsSafe();

/// Names accepted by TagFamily (those shipped with libapriltag 3.3).
std::vector<std::string> knownTagFamilies();

/// Owns one apriltag_family_t. Throws VisionError naming the family if it is unknown.
class TagFamily {
 public:
  explicit TagFamily(const std::string& name);
  ~TagFamily();
  TagFamily(const TagFamily&) = delete;
  TagFamily& operator=(const TagFamily&) = delete;

  const std::string& name() const { return name_; }
  apriltag_family* get() const { return family_; }
  int codeCount() const;
  /// Cells across the black border (8 for tag36h11) and across the whole bitmap incl. white border (10).
  int widthAtBorder() const;
  int totalWidth() const;
  /// The tag's bitmap from the family's code table (apriltag_to_image): CV_8U, totalWidth() square,
  /// one pixel per cell, 0 = black, 255 = white. Throws VisionError if the id is out of range.
  cv::Mat bitmap(int tag_id) const;

 private:
  std::string name_;
  apriltag_family* family_ = nullptr;
  void (*destroy_)(apriltag_family*) = nullptr;
};

struct DetectorOptions {
  std::string family = "tag36h11";
  double decimate = 1.0;  ///< quad_decimate (>= 1); corners are refined at full resolution
  int threads = 1;        ///< libapriltag worker threads of one detector (1..64; only 1 if !apriltagWorkerPoolIsSafe())
  double blur_sigma = 0.0;  ///< quad_sigma (>= 0)
  bool refine_edges = true;
  int max_hamming = 1;                ///< detections with more corrected bits are dropped (0..2)
  double min_decision_margin = 20.0;  ///< detections below this margin are dropped (>= 0)
};

/// Throws VisionError naming the option and value if out of range (family checked by TagFamily).
void validateDetectorOptions(const DetectorOptions& options);

/// One tag in one image, pixel coordinates of that image (x right, y down; integer = pixel centre,
/// OpenCV's convention: libapriltag's own coordinates are shifted by -0.5 to get there).
/// corners follow libapriltag's order (counter-clockwise around the tag in the tag's own frame,
/// starting at its (-1, +1) corner); center is the homography image of the tag centre.
struct TagDetection {
  int id = -1;
  int hamming = 0;
  double decision_margin = 0.0;
  cv::Point2d center;
  std::array<cv::Point2d, 4> corners;
};

class TagDetector {
 public:
  explicit TagDetector(const DetectorOptions& options);
  ~TagDetector();
  TagDetector(const TagDetector&) = delete;
  TagDetector& operator=(const TagDetector&) = delete;

  /// Detects tags in an 8-bit single-channel image (throws VisionError for another type; an empty
  /// image gives no detections). Results are sorted by id.
  std::vector<TagDetection> detect(const cv::Mat& gray);
  const DetectorOptions& options() const { return options_; }
  const TagFamily& family() const { return *family_; }

 private:
  DetectorOptions options_;
  std::unique_ptr<TagFamily> family_;
  apriltag_detector* detector_ = nullptr;
};

}  // namespace reflex::vision
