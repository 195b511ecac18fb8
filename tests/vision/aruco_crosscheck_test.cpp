// Cross-check of the AprilTag detections against OpenCV's own AprilTag dictionary detector
// (cv::aruco, DICT_APRILTAG_36h11, sub-pixel corner refinement) on the same rectified frames of a
// generated session: the same ids, and corners within 1 px.
#include "reflex/vision/stereo_pipeline.hpp"
#include "vision_test_util.hpp"

#include <opencv2/aruco.hpp>
#include <opencv2/imgproc.hpp>

#include <gtest/gtest.h>

#include <set>

using namespace reflex::vision;
using namespace reflex::vision::test;

TEST(ArucoCrossCheck, SameIdsAndCornersWithinOnePixel) {
  TempDir dir("aruco");
  makeSession(parseSceneScript(nearScript(3.0), "near"), dir / "s");
  SessionReader reader(dir / "s");
  const std::vector<GroundTruthRow> truth = loadGroundTruth(dir / "s/ground_truth.csv");
  const StereoRectifier rect(reader.info().calibration);
  TagDetector april(DetectorOptions{});
  const cv::Ptr<cv::aruco::Dictionary> dict = cv::aruco::getPredefinedDictionary(cv::aruco::DICT_APRILTAG_36h11);
  cv::Ptr<cv::aruco::DetectorParameters> params = cv::aruco::DetectorParameters::create();
  params->cornerRefinementMethod = cv::aruco::CORNER_REFINE_SUBPIX;

  StereoFrame f;
  std::string msg;
  int compared = 0, frames_with_tags = 0;
  double worst = 0.0;
  while (reader.read(f, msg) == ReadStatus::kOk) {
    for (int side = 0; side < 2; ++side) {
      cv::Mat gray, r;
      cv::cvtColor(side ? f.right : f.left, gray, cv::COLOR_BGR2GRAY);
      rect.rectifyImage(gray, r, side == 1);
      const std::vector<TagDetection> a = april.detect(r);
      std::vector<int> ids;
      std::vector<std::vector<cv::Point2f>> corners, rejected;
      cv::aruco::detectMarkers(r, dict, corners, ids, params, rejected);
      std::set<int> ida, idb(ids.begin(), ids.end());
      for (const TagDetection& d : a) ida.insert(d.id);
      // Every fully visible tag (ground truth) that both detectors found is compared; a partially
      // occluded tag has no well-defined corners.
      std::set<int> visible;
      for (const GroundTruthRow& g : truth)
        if (g.frame == f.index && g.visible) visible.insert(g.tag_id);
      for (const TagDetection& d : a) {
        const auto it = std::find(ids.begin(), ids.end(), d.id);
        if (it == ids.end() || !visible.count(d.id)) continue;
        const std::vector<cv::Point2f>& c = corners[static_cast<std::size_t>(it - ids.begin())];
        // aruco: clockwise from top-left; apriltag: counter-clockwise from bottom-left (on screen).
        // Find the best cyclic alignment of aruco's reversed order.
        double best = 1e9;
        for (int shift = 0; shift < 4; ++shift) {
          double e = 0.0;
          for (int k = 0; k < 4; ++k) {
            const cv::Point2f& q = c[static_cast<std::size_t>((shift - k + 8) % 4)];
            e = std::max(e, cv::norm(d.corners[static_cast<std::size_t>(k)] - cv::Point2d(q.x, q.y)));
          }
          best = std::min(best, e);
        }
        worst = std::max(worst, best);
        EXPECT_LT(best, 1.0) << "frame " << f.index << " side " << side << " id " << d.id;
        ++compared;
      }
      for (int id : idb) EXPECT_TRUE(id == 0 || id == 1) << "cv::aruco found an id that is not in the scene: " << id;
      for (int id : ida) EXPECT_TRUE(id == 0 || id == 1) << "apriltag found an id that is not in the scene: " << id;
      if (!ida.empty()) ++frames_with_tags;
      // Every fully visible tag (ground truth) must be found by both detectors.
      for (const GroundTruthRow& g : truth)
        if (g.frame == f.index && g.visible) {
          EXPECT_TRUE(ida.count(g.tag_id)) << "apriltag missed id " << g.tag_id << " at frame " << f.index;
          EXPECT_TRUE(idb.count(g.tag_id)) << "cv::aruco missed id " << g.tag_id << " at frame " << f.index;
        }
    }
  }
  std::cout << "compared " << compared << " tag detections, worst corner disagreement " << worst << " px\n";
  EXPECT_GT(compared, 80);
  EXPECT_GT(frames_with_tags, 40);
}
