#include "reflex/vision/tag_detector.hpp"

#include "reflex/vision/image_file.hpp"

#include "reflex/vision/error.hpp"

#include <apriltag/apriltag.h>
#include <apriltag/common/image_u8.h>
#include <apriltag/tag16h5.h>
#include <apriltag/tag25h9.h>
#include <apriltag/tag36h10.h>
#include <apriltag/tag36h11.h>
#include <apriltag/tagCircle21h7.h>
#include <apriltag/tagCircle49h12.h>
#include <apriltag/tagCustom48h12.h>
#include <apriltag/tagStandard41h12.h>
#include <apriltag/tagStandard52h13.h>

#include <algorithm>
#include <cmath>

namespace reflex::vision {
namespace {

struct FamilyEntry {
  const char* name;
  apriltag_family_t* (*create)();
  void (*destroy)(apriltag_family_t*);
};

const FamilyEntry kFamilies[] = {
    {"tag36h11", tag36h11_create, tag36h11_destroy},
    {"tag36h10", tag36h10_create, tag36h10_destroy},
    {"tag25h9", tag25h9_create, tag25h9_destroy},
    {"tag16h5", tag16h5_create, tag16h5_destroy},
    {"tagCircle21h7", tagCircle21h7_create, tagCircle21h7_destroy},
    {"tagCircle49h12", tagCircle49h12_create, tagCircle49h12_destroy},
    {"tagCustom48h12", tagCustom48h12_create, tagCustom48h12_destroy},
    {"tagStandard41h12", tagStandard41h12_create, tagStandard41h12_destroy},
    {"tagStandard52h13", tagStandard52h13_create, tagStandard52h13_destroy},
};

std::string knownList() {
  std::string s;
  for (const FamilyEntry& f : kFamilies) s += (s.empty() ? "" : ", ") + std::string(f.name);
  return s;
}

}  // namespace

std::string apriltagVersion() { return REFLEX_APRILTAG_VERSION; }

bool apriltagWorkerPoolIsSafe() { return REFLEX_APRILTAG_POOL_SAFE != 0; }

std::vector<std::string> knownTagFamilies() {
  std::vector<std::string> out;
  for (const FamilyEntry& f : kFamilies) out.emplace_back(f.name);
  return out;
}

TagFamily::TagFamily(const std::string& name) : name_(name) {
  for (const FamilyEntry& f : kFamilies) {
    if (name == f.name) {
      family_ = f.create();
      destroy_ = f.destroy;
      break;
    }
  }
  if (family_ == nullptr) throw VisionError("unknown tag family '" + name + "' (known: " + knownList() + ")");
}

TagFamily::~TagFamily() {
  if (family_ != nullptr) destroy_(family_);
}

int TagFamily::codeCount() const { return static_cast<int>(family_->ncodes); }
int TagFamily::widthAtBorder() const { return family_->width_at_border; }
int TagFamily::totalWidth() const { return family_->total_width; }

cv::Mat TagFamily::bitmap(int tag_id) const {
  if (tag_id < 0 || tag_id >= codeCount())
    throw VisionError("tag id " + std::to_string(tag_id) + " is out of range for family " + name_ + " (0.." +
                      std::to_string(codeCount() - 1) + ")");
  image_u8_t* im = apriltag_to_image(family_, tag_id);
  if (im == nullptr) throw VisionError("apriltag_to_image failed for " + name_ + " id " + std::to_string(tag_id));
  cv::Mat out(im->height, im->width, CV_8U);
  for (int r = 0; r < im->height; ++r)
    std::copy(im->buf + r * im->stride, im->buf + r * im->stride + im->width, out.ptr<std::uint8_t>(r));
  image_u8_destroy(im);
  return out;
}

void validateDetectorOptions(const DetectorOptions& o) {
  if (!(o.decimate >= 1.0) || !std::isfinite(o.decimate))
    throw VisionError("detector option decimate = " + std::to_string(o.decimate) + " must be >= 1");
  if (o.threads < 1 || o.threads > 64)
    throw VisionError("detector option threads = " + std::to_string(o.threads) + " must be in 1..64");
  if (o.threads > 1 && !apriltagWorkerPoolIsSafe())
    throw VisionError("detector option threads = " + std::to_string(o.threads) + ": libapriltag " + apriltagVersion() +
                      " (this build's) can crash when its worker threads start (a race fixed in libapriltag 3.4.3, "
                      "AprilRobotics/apriltag PR #339), so only 1 thread per image is allowed; the stereo pipeline "
                      "already detects the left and right images on two threads");
  if (!(o.blur_sigma >= 0.0) || !std::isfinite(o.blur_sigma))
    throw VisionError("detector option blur_sigma = " + std::to_string(o.blur_sigma) + " must be >= 0");
  if (o.max_hamming < 0 || o.max_hamming > 2)
    throw VisionError("detector option max_hamming = " + std::to_string(o.max_hamming) + " must be in 0..2");
  if (!(o.min_decision_margin >= 0.0))
    throw VisionError("detector option min_decision_margin = " + std::to_string(o.min_decision_margin) +
                      " must be >= 0");
}

TagDetector::TagDetector(const DetectorOptions& options) : options_(options) {
  validateDetectorOptions(options_);
  family_ = std::make_unique<TagFamily>(options_.family);
  detector_ = apriltag_detector_create();
  if (detector_ == nullptr) throw VisionError("apriltag_detector_create failed");
  // Correct up to 2 bits (the library default); max_hamming then filters what we accept.
  apriltag_detector_add_family_bits(detector_, family_->get(), 2);
  detector_->quad_decimate = static_cast<float>(options_.decimate);
  detector_->quad_sigma = static_cast<float>(options_.blur_sigma);
  detector_->nthreads = options_.threads;
  detector_->refine_edges = options_.refine_edges;
}

TagDetector::~TagDetector() {
  if (detector_ != nullptr) apriltag_detector_destroy(detector_);
}

std::vector<TagDetection> TagDetector::detect(const cv::Mat& gray) {
  std::vector<TagDetection> out;
  if (gray.empty()) return out;
  if (gray.type() != CV_8UC1)
    throw VisionError("TagDetector::detect needs an 8-bit single-channel image, got type " +
                      std::to_string(gray.type()));
  // libapriltag crashes on images 1-2 px high and aborts at a width of 32768: refused here whatever
  // the caller checked.
  if (const std::string why = imageSizeProblem("the image", gray.size()); !why.empty())
    throw VisionError("TagDetector::detect: " + why);
  image_u8_t im{gray.cols, gray.rows, static_cast<int32_t>(gray.step[0]), const_cast<std::uint8_t*>(gray.data)};
  zarray_t* dets = apriltag_detector_detect(detector_, &im);
  out.reserve(static_cast<std::size_t>(zarray_size(dets)));
  for (int i = 0; i < zarray_size(dets); ++i) {
    apriltag_detection_t* d = nullptr;
    zarray_get(dets, i, &d);
    if (d->hamming > options_.max_hamming || d->decision_margin < options_.min_decision_margin) continue;
    TagDetection t;
    t.id = d->id;
    t.hamming = d->hamming;
    t.decision_margin = d->decision_margin;
    // libapriltag puts pixel centres at +0.5 (its issue #121); OpenCV and the calibration put them
    // at integers, so shift into the calibration's convention.
    t.center = cv::Point2d(d->c[0] - 0.5, d->c[1] - 0.5);
    for (int k = 0; k < 4; ++k)
      t.corners[static_cast<std::size_t>(k)] = cv::Point2d(d->p[k][0] - 0.5, d->p[k][1] - 0.5);
    out.push_back(t);
  }
  apriltag_detections_destroy(dets);
  std::sort(out.begin(), out.end(), [](const TagDetection& a, const TagDetection& b) { return a.id < b.id; });
  return out;
}

}  // namespace reflex::vision
