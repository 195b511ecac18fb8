// Tests of vision/include/reflex/vision/stereo_pipeline.hpp and tag_detector.hpp against analytic
// answers: exact projections triangulate back, the stereo tag pose fit recovers a known pose, a
// rendered tag is found where it was drawn, bad options and families are errors.
#include "reflex/vision/error.hpp"
#include "reflex/vision/session_maker.hpp"
#include "reflex/vision/stereo_pipeline.hpp"
#include "reflex/vision/tag_detector.hpp"
#include "vision_test_util.hpp"

#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cmath>

using namespace reflex::vision;
using ::testing::HasSubstr;

namespace {

StereoCalibration testRig() {
  RigSpec rig;
  rig.K_right = cv::Matx33d(503, 0, 322, 0, 502, 241, 0, 0, 1);
  rig.D_left = {-0.04, 0.012, 0.0005, -0.0003, 0};
  rig.D_right = {-0.038, 0.010, -0.0004, 0.0002, 0};
  rig.right_rpy_deg = cv::Vec3d(0.3, -0.5, 0.2);
  return rigCalibration(rig);
}

// Raw (distorted) pixel of a left-optical-frame point in the left or right camera of testRig().
cv::Point2d projectRaw(const StereoCalibration& c, const cv::Vec3d& p_C, bool right) {
  RigSpec rig;
  const double d2r = M_PI / 180.0;
  cv::Matx33d R_L_R = cv::Matx33d::eye();
  if (right) {
    const cv::Vec3d a = cv::Vec3d(0.3, -0.5, 0.2) * d2r;  // same rpy convention as the maker (Rz Ry Rx)
    const cv::Matx33d Rx(1, 0, 0, 0, std::cos(a[0]), -std::sin(a[0]), 0, std::sin(a[0]), std::cos(a[0]));
    const cv::Matx33d Ry(std::cos(a[1]), 0, std::sin(a[1]), 0, 1, 0, -std::sin(a[1]), 0, std::cos(a[1]));
    const cv::Matx33d Rz(std::cos(a[2]), -std::sin(a[2]), 0, std::sin(a[2]), std::cos(a[2]), 0, 0, 0, 1);
    R_L_R = Rz * Ry * Rx;
  }
  const cv::Vec3d p = right ? R_L_R.t() * (p_C - cv::Vec3d(0.06, 0, 0)) : p_C;
  const CameraInfo& cam = right ? c.right : c.left;
  std::vector<cv::Point2d> uv;
  cv::projectPoints(std::vector<cv::Point3d>{cv::Point3d(p[0], p[1], p[2])}, cv::Vec3d(0, 0, 0), cv::Vec3d(0, 0, 0),
                    cam.K, cam.D, uv);
  return uv[0];
}

}  // namespace

TEST(StereoRectifier, TriangulatesExactProjectionsBack) {
  const StereoCalibration c = testRig();
  const StereoRectifier rect(c);
  for (const cv::Vec3d& p_C :
       {cv::Vec3d(0.0, 0.0, 0.5), cv::Vec3d(-0.12, 0.08, 0.7), cv::Vec3d(0.3, -0.2, 1.5), cv::Vec3d(0.05, 0.1, 1.0)}) {
    std::vector<cv::Point2d> l, r;
    rect.rectifyPoints({projectRaw(c, p_C, false)}, l, false);
    rect.rectifyPoints({projectRaw(c, p_C, true)}, r, true);
    EXPECT_NEAR(l[0].y, r[0].y, 1e-3) << "rectified rows must agree";
    cv::Vec3d p_rect;
    ASSERT_TRUE(rect.triangulate(l[0], r[0], p_rect));
    const cv::Vec3d back = rect.rectToCamera(p_rect);
    EXPECT_LT(cv::norm(back - p_C), 1e-5 * cv::norm(p_C)) << p_C << " -> " << back;
  }
}

TEST(StereoRectifier, RejectsNonPositiveDisparity) {
  const StereoRectifier rect(testRig());
  cv::Vec3d p;
  EXPECT_FALSE(rect.triangulate(cv::Point2d(300, 200), cv::Point2d(320, 200), p));
}

TEST(StereoRectifier, HandComputedPinholeCase) {
  // No distortion, no rotation: Z = f B / d, X = (u - cx) Z / f.
  StereoCalibration c;
  c.left.image_size = c.right.image_size = cv::Size(640, 480);
  c.left.K = c.right.K = cv::Matx33d(500, 0, 320, 0, 500, 240, 0, 0, 1);
  c.left.P = cv::Matx34d(500, 0, 320, 0, 0, 500, 240, 0, 0, 0, 1, 0);
  c.right.P = cv::Matx34d(500, 0, 320, -30, 0, 500, 240, 0, 0, 0, 1, 0);  // B = 0.06
  const StereoRectifier rect(c);
  cv::Vec3d p;
  ASSERT_TRUE(rect.triangulate(cv::Point2d(370, 290), cv::Point2d(310, 290), p));  // d = 60 px
  EXPECT_NEAR(p[2], 0.5, 1e-12);
  EXPECT_NEAR(p[0], 0.05, 1e-12);
  EXPECT_NEAR(p[1], 0.05, 1e-12);
}

TEST(StereoTagPoseFit, RecoversAKnownPoseFromExactCorners) {
  const StereoCalibration c = testRig();
  const StereoRectifier rect(c);
  const double s = 0.06;
  const cv::Vec3d centre(0.05, -0.03, 0.8);
  cv::Matx33d R;
  cv::Rodrigues(cv::Vec3d(0.3, -0.4, 0.2), R);
  const cv::Vec3d model[4] = {{-s / 2, s / 2, 0}, {s / 2, s / 2, 0}, {s / 2, -s / 2, 0}, {-s / 2, -s / 2, 0}};
  std::array<cv::Point2d, 4> l, r;
  std::array<cv::Vec3d, 4> seed;
  for (std::size_t k = 0; k < 4; ++k) {
    const cv::Vec3d p = R * model[k] + centre;
    l[k] = rect.projectRect(p, false);
    r[k] = rect.projectRect(p, true);
    seed[k] = p + cv::Vec3d(0.002, -0.001, 0.004 * (k % 2 ? 1 : -1));  // a noisy stereo seed
  }
  cv::Vec3d c_fit, z_fit;
  double rms = -1;
  ASSERT_TRUE(fitTagPoseStereo(rect, l, r, seed, s, c_fit, z_fit, rms));
  EXPECT_LT(cv::norm(c_fit - centre), 1e-7);
  EXPECT_LT(cv::norm(z_fit - R * cv::Vec3d(0, 0, 1)), 1e-6);
  EXPECT_LT(rms, 1e-5);
}

// A tag whose detected corners are all shrunk (or grown) about its centre by `bias` in both images, as
// libapriltag's corners do on small tags: stereo (the disparity) is unaffected, the apparent size is not.
TEST(StereoTagPoseFit, SizePriorFadesTheApparentSizeCueOnSmallTags) {
  const StereoCalibration c = testRig();
  const StereoRectifier rect(c);
  const double s = 0.04;
  const cv::Vec3d centre(0.1, 0.05, 1.2);  // ~17 px edge at f 500
  cv::Matx33d R;
  cv::Rodrigues(cv::Vec3d(0.2, -0.3, 0.1), R);
  const cv::Vec3d model[4] = {{-s / 2, s / 2, 0}, {s / 2, s / 2, 0}, {s / 2, -s / 2, 0}, {-s / 2, -s / 2, 0}};
  for (const double bias : {-0.013, 0.025}) {
    std::array<cv::Point2d, 4> l, r;
    std::array<cv::Vec3d, 4> seed;
    cv::Point2d cl(0, 0), cr(0, 0);
    for (std::size_t k = 0; k < 4; ++k) {
      const cv::Vec3d p = R * model[k] + centre;
      l[k] = rect.projectRect(p, false);
      r[k] = rect.projectRect(p, true);
      cl += 0.25 * l[k];
      cr += 0.25 * r[k];
      seed[k] = p;
    }
    double edge = 0.0;
    for (std::size_t k = 0; k < 4; ++k) {
      l[k] = cl + (1.0 + bias) * (l[k] - cl);
      r[k] = cr + (1.0 + bias) * (r[k] - cr);
      edge += cv::norm(l[(k + 1) % 4] - l[k]) / 4.0;
    }
    ASSERT_LT(edge, 20.0);
    cv::Vec3d c_hard, c_weighted, z;
    double rms = 0.0;
    ASSERT_TRUE(fitTagPoseStereo(rect, l, r, seed, s, c_hard, z, rms));  // size exactly known: old behaviour
    TagFitWeights w;
    w.size_sigma = apparentSizeSigma(edge);
    ASSERT_TRUE(fitTagPoseStereo(rect, l, r, seed, s, c_weighted, z, rms, w));
    const double range = cv::norm(centre);
    const double hard = cv::norm(c_hard) - range, weighted = cv::norm(c_weighted) - range;
    // The hard size constraint reads the apparent size as depth (against the disparity): the range
    // moves against the bias, here by ~0.3 of it (5-9 mm at 1.2 m).
    EXPECT_GT(-hard * bias / std::abs(bias), 0.2 * std::abs(bias) * range) << "bias " << bias;
    // Weighted, the disparity decides: a small fraction of that.
    EXPECT_LT(std::abs(weighted), 0.2 * std::abs(hard)) << "bias " << bias << ", weighted " << weighted;
  }
}

TEST(StereoTagPoseFit, SizePriorKeepsExactCornersExact) {
  const StereoCalibration c = testRig();
  const StereoRectifier rect(c);
  const double s = 0.06;
  const cv::Vec3d centre(-0.05, 0.02, 0.45);
  const cv::Vec3d model[4] = {{-s / 2, s / 2, 0}, {s / 2, s / 2, 0}, {s / 2, -s / 2, 0}, {-s / 2, -s / 2, 0}};
  std::array<cv::Point2d, 4> l, r;
  std::array<cv::Vec3d, 4> seed;
  for (std::size_t k = 0; k < 4; ++k) {
    const cv::Vec3d p = model[k] + centre;
    l[k] = rect.projectRect(p, false);
    r[k] = rect.projectRect(p, true);
    seed[k] = p + cv::Vec3d(-0.001, 0.002, 0.003 * (k % 2 ? -1 : 1));
  }
  for (const double sigma : {1e-4, 0.01, 0.3}) {
    TagFitWeights w;
    w.size_sigma = sigma;
    cv::Vec3d c_fit, z_fit;
    double rms = -1;
    ASSERT_TRUE(fitTagPoseStereo(rect, l, r, seed, s, c_fit, z_fit, rms, w));
    EXPECT_LT(cv::norm(c_fit - centre), 1e-7) << sigma;
    EXPECT_LT(rms, 1e-5) << sigma;
  }
}

TEST(Confidence, DocumentedFormulaOnHandComputedCases) {
  // The documented formula (stereo_pipeline.hpp, vision/README.md "The pipeline"):
  //   min(1, margin / 50) * exp(-epi^2 / 2) * exp(-((ratio - 1) / tol)^2 / 2),
  //   tol = max(0.05, 2.5 * 12 / min(edge_px, disparity_px)^2), each factor checked on its own;
  // the fit's size prior apparentSizeSigma(L) = 150 / L^3.
  EXPECT_NEAR(computeConfidence(150, 0, 1.0, 60, 60), 1.0, 1e-12);
  EXPECT_NEAR(computeConfidence(25, 0, 1.0, 60, 60), 0.5, 1e-12);
  EXPECT_NEAR(computeConfidence(50, 0, 1.0, 60, 60), 1.0, 1e-12);
  EXPECT_NEAR(computeConfidence(100, 1.0, 1.0, 60, 60), std::exp(-0.5), 1e-12);
  // Large tag (60 px: 2.5 * 12 / 3600 = 0.8 % < 5 %): the 5 % tolerance.
  EXPECT_NEAR(computeConfidence(100, 0, 1.05, 60, 80), std::exp(-0.5), 1e-12);
  EXPECT_NEAR(computeConfidence(100, 0, 0.95, 80, 60), std::exp(-0.5), 1e-12);
  // 20 px edge, 30 px disparity: sigma = 12 / 400 = 3 %, tol = 7.5 %.
  EXPECT_NEAR(computeConfidence(100, 0, 1.075, 20, 30), std::exp(-0.5), 1e-12);
  // 40 px edge but 20 px disparity (a large tag far away): the smaller one decides, the same 7.5 %.
  EXPECT_NEAR(computeConfidence(100, 0, 0.925, 40, 20), std::exp(-0.5), 1e-12);
  EXPECT_NEAR(computeConfidence(40, 2.0, 0.9, 60, 60), 0.8 * std::exp(-2.0) * std::exp(-2.0), 1e-12);
  EXPECT_NEAR(stereoSizeSigma(20, 30), 0.03, 1e-15);
  EXPECT_NEAR(apparentSizeSigma(20), 0.01875, 1e-15);      // 150 / 8000
  EXPECT_EQ(computeConfidence(0, 10, 3.0, 60, 60), 0.0);   // no decision margin: no confidence
  EXPECT_EQ(computeConfidence(-20, 0, 1.0, 60, 60), 0.0);  // a margin below 0 clamps to 0, not negative
  EXPECT_LT(computeConfidence(20, 0, 1.0, 60, 60), computeConfidence(45, 0, 1.0, 60, 60));
  EXPECT_LT(computeConfidence(90, 1.5, 1.0, 60, 60), computeConfidence(90, 0.2, 1.0, 60, 60));
  EXPECT_LT(computeConfidence(90, 0, 1.1, 60, 60), computeConfidence(90, 0, 1.01, 60, 60));
  // A wrong tag size in the object map (6 cm printed, 5 cm listed: ratio 1.2) reads low at any size.
  EXPECT_LT(computeConfidence(100, 0, 1.2, 60, 60), 0.01);
  EXPECT_LT(computeConfidence(100, 0, 1.2, 18, 25), 0.5);
}

TEST(TagDetector, FindsARenderedTagWhereItWasDrawn) {
  const TagFamily family("tag36h11");
  const cv::Mat bits = family.bitmap(42);
  ASSERT_EQ(bits.rows, family.totalWidth());
  const int cell = 12;
  cv::Mat img(480, 640, CV_8U, cv::Scalar(200));
  cv::Mat big;
  cv::resize(bits, big, cv::Size(), cell, cell, cv::INTER_NEAREST);
  const cv::Point origin(200, 150);
  big.copyTo(img(cv::Rect(origin, big.size())));
  TagDetector det(DetectorOptions{});
  const std::vector<TagDetection> found = det.detect(img);
  ASSERT_EQ(found.size(), 1u);
  EXPECT_EQ(found[0].id, 42);
  // The black square spans cells 1..9 of the 10-cell bitmap; pixel centres are integers, so its
  // outer edges lie at origin + cell - 0.5 and origin + 9 cell - 0.5.
  const double lo = cell - 0.5, hi = (family.totalWidth() - 1) * cell - 0.5;
  const double cx = origin.x + 0.5 * (lo + hi), cy = origin.y + 0.5 * (lo + hi);
  EXPECT_NEAR(found[0].center.x, cx, 0.3);
  EXPECT_NEAR(found[0].center.y, cy, 0.3);
  for (const cv::Point2d& p : found[0].corners) {
    EXPECT_NEAR(std::abs(p.x - cx), 0.5 * (hi - lo), 0.5);
    EXPECT_NEAR(std::abs(p.y - cy), 0.5 * (hi - lo), 0.5);
  }
  // libapriltag's order: counter-clockwise on screen, starting bottom-left (y down).
  EXPECT_GT(found[0].corners[0].y, cy);
  EXPECT_LT(found[0].corners[0].x, cx);
  EXPECT_GT(found[0].corners[1].x, cx);
}

TEST(TagDetector, BadFamilyOptionsAndImagesAreErrors) {
  DetectorOptions o;
  o.family = "tag99h1";
  try {
    TagDetector d(o);
    FAIL() << "unknown family accepted";
  } catch (const VisionError& e) {
    EXPECT_THAT(e.what(), AllOf(HasSubstr("'tag99h1'"), HasSubstr("tag36h11")));
  }
  o = DetectorOptions{};
  o.decimate = 0.5;
  EXPECT_THROW(TagDetector{o}, VisionError);
  o = DetectorOptions{};
  o.threads = 0;
  EXPECT_THROW(TagDetector{o}, VisionError);
  TagDetector d(DetectorOptions{});
  EXPECT_TRUE(d.detect(cv::Mat()).empty());
  EXPECT_THROW(d.detect(cv::Mat(10, 10, CV_32F)), VisionError);
  EXPECT_THROW(TagFamily("tag36h11").bitmap(100000), VisionError);
}

// The vision_benchmark crash: libapriltag before 3.4.3 starts its worker pool racily
// (tag_detector.hpp; tests/vision/apriltag_pool_race.cpp crashed libapriltag 3.3.0 alone in 5 of 6
// runs of up to 30000 pool starts). Built against such a library, a detector with worker threads is refused,
// naming the option, the version and the fix; with a fixed library it detects what one thread does.
TEST(TagDetector, WorkerThreadsOnlyWithALibapriltagWhosePoolStartsSafely) {
  DetectorOptions o;
  o.threads = 2;
  if (!apriltagWorkerPoolIsSafe()) {
    try {
      TagDetector d(o);
      FAIL() << "threads = 2 accepted with libapriltag " << apriltagVersion();
    } catch (const VisionError& e) {
      EXPECT_THAT(e.what(),
                  AllOf(HasSubstr("threads = 2"), HasSubstr("libapriltag " + apriltagVersion()), HasSubstr("3.4.3")));
    }
    return;
  }
  TagFamily family("tag36h11");
  cv::Mat img(480, 640, CV_8U, cv::Scalar(200));
  cv::Mat big;
  cv::resize(family.bitmap(7), big, cv::Size(), 12, 12, cv::INTER_NEAREST);
  big.copyTo(img(cv::Rect(200, 100, big.cols, big.rows)));
  TagDetector one(DetectorOptions{}), two(o);
  const std::vector<TagDetection> a = one.detect(img), b = two.detect(img);
  ASSERT_EQ(a.size(), 1u);
  ASSERT_EQ(b.size(), 1u);
  for (std::size_t k = 0; k < 4; ++k) EXPECT_LT(cv::norm(a[0].corners[k] - b[0].corners[k]), 1e-9);
}

TEST(StereoTagPipeline, BadFramesAreSkippedNotThrown) {
  const StereoCalibration c = testRig();
  ObjectMap objects("tag36h11", {{0, "cup", 0.06}}, "test");
  StereoTagPipeline p(c, test::shippedMount(), objects, PipelineOptions{});
  StereoResult r;
  p.process(cv::Mat(), cv::Mat(480, 640, CV_8U), r);
  EXPECT_EQ(r.status, FrameStatus::kSkipped);
  EXPECT_THAT(r.message, HasSubstr("left image is empty"));
  p.process(cv::Mat(480, 640, CV_8U), cv::Mat(240, 320, CV_8U), r);
  EXPECT_EQ(r.status, FrameStatus::kSkipped);
  EXPECT_THAT(r.message, HasSubstr("320x240"));
  p.process(cv::Mat(480, 640, CV_16U), cv::Mat(480, 640, CV_16U), r);
  EXPECT_EQ(r.status, FrameStatus::kSkipped);
  p.process(cv::Mat(480, 640, CV_8UC3, cv::Scalar::all(0)), cv::Mat(480, 640, CV_8UC3, cv::Scalar::all(0)), r);
  EXPECT_EQ(r.status, FrameStatus::kOk);
  EXPECT_TRUE(r.objects.empty());
  // Family mismatch and out-of-range ids are setup errors.
  PipelineOptions other;
  other.detector.family = "tag25h9";
  EXPECT_THROW(StereoTagPipeline(c, test::shippedMount(), objects, other), VisionError);
  ObjectMap huge("tag36h11", {{5000, "x", 0.06}}, "test");
  EXPECT_THROW(StereoTagPipeline(c, test::shippedMount(), huge, PipelineOptions{}), VisionError);
}
