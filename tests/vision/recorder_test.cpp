// The recorder fed by fake cameras: video files opened through the same
// VideoCapture path as a device. The recorded session must read back with the same frames and
// give the same detections; a side-by-side camera is split into left/right halves.
#include "reflex/vision/error.hpp"
#include "vision_test_util.hpp"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <opencv2/core.hpp>
#include <opencv2/videoio.hpp>

#include <cstdlib>

using namespace reflex::vision;
using namespace reflex::vision::test;
using ::testing::HasSubstr;

namespace {

int run(const std::string& cmd, std::string& err, const TempDir& dir) {
  const int rc = std::system((cmd + " > " + (dir / "out.txt") + " 2> " + (dir / "err.txt")).c_str());
  err = readText(dir / "err.txt") + readText(dir / "out.txt");
  return WIFEXITED(rc) ? WEXITSTATUS(rc) : -1;
}

// Per (frame, object) detection positions of a session.
std::map<std::pair<int, std::string>, cv::Vec3d> detectionsOf(const std::string& dir) {
  std::map<std::pair<int, std::string>, cv::Vec3d> out;
  for (const Detection& d : detectSession(dir)) out[{d.frame, d.object}] = d.p_B;
  return out;
}

void compareSessions(const std::string& original, const std::string& recorded, int frames) {
  SessionReader rec(recorded);
  EXPECT_EQ(rec.info().frameCount(), frames);
  // Live stamps: UNIX time, paced at the stand-in file's 10 fps.
  const std::vector<double>& s = rec.info().stamps;
  EXPECT_GT(s.front(), 1.6e9);
  const double period = (s.back() - s.front()) / (s.size() - 1);
  EXPECT_NEAR(period, 0.1, 0.01);
  const auto a = detectionsOf(original);
  const auto b = detectionsOf(recorded);
  int matched = 0;
  for (const auto& [key, p] : a) {
    const auto it = b.find(key);
    if (it == b.end()) continue;
    EXPECT_LT(cv::norm(it->second - p), 0.005) << "frame " << key.first << " " << key.second;
    ++matched;
  }
  EXPECT_GE(matched, static_cast<int>(0.95 * a.size()));
}

}  // namespace

TEST(Recorder, TwoFakeCamerasFromVideoFiles) {
  TempDir dir("rec");
  makeSession(parseSceneScript(nearScript(2.0), "near"), dir / "s");
  const std::string s = dir / "s";
  std::string out;
  const std::string cmd = std::string(REFLEX_BIN_DIR) + "/reflex_vision_record --camera-left " + s +
                          "/left.mp4 --camera-right " + s + "/right.mp4 --calib-left " + s +
                          "/left.yaml --calib-right " + s + "/right.yaml --objects " + s + "/objects.yaml --mount " +
                          s + "/camera_mount.yaml --out " + (dir / "rec") + " --quiet";
  ASSERT_EQ(run(cmd, out, dir), 0) << out;
  EXPECT_THAT(out, HasSubstr("recorded 20 pairs"));
  compareSessions(s, dir / "rec", 20);
}

TEST(Recorder, SideBySideFakeCameraAndFrameLimit) {
  TempDir dir("rec_sbs");
  makeSession(parseSceneScript(nearScript(2.0), "near"), dir / "s");
  const std::string s = dir / "s";
  {
    SessionReader r(s);
    cv::VideoWriter w(dir / "sbs.avi", cv::CAP_FFMPEG, cv::VideoWriter::fourcc('M', 'J', 'P', 'G'), 10,
                      cv::Size(1280, 480), true);
    w.set(cv::VIDEOWRITER_PROP_QUALITY, 95);
    StereoFrame f;
    std::string msg;
    while (r.read(f, msg) == ReadStatus::kOk) {
      cv::Mat both;
      cv::hconcat(f.left, f.right, both);
      w.write(both);
    }
  }
  std::string out;
  const std::string cmd = std::string(REFLEX_BIN_DIR) + "/reflex_vision_record --side-by-side " + (dir / "sbs.avi") +
                          " --calib-left " + s + "/left.yaml --calib-right " + s + "/right.yaml --objects " + s +
                          "/objects.yaml --mount " + s + "/camera_mount.yaml --out " + (dir / "rec") +
                          " --frames 15 --quiet";
  ASSERT_EQ(run(cmd, out, dir), 0) << out;
  EXPECT_THAT(out, HasSubstr("recorded 15 pairs"));
  SessionReader rec(dir / "rec");
  EXPECT_EQ(rec.info().frameCount(), 15);
  // reflex_vision on the recording finds the objects where the original says they are.
  const auto a = detectionsOf(s);
  const auto b = detectionsOf(dir / "rec");
  int matched = 0;
  for (const auto& [key, p] : b) {
    ASSERT_TRUE(a.count(key)) << "invented detection at frame " << key.first;
    EXPECT_LT(cv::norm(a.at(key) - p), 0.005);
    ++matched;
  }
  EXPECT_GE(matched, 20);
}

TEST(Recorder, ErrorsAreClear) {
  TempDir dir("rec_err");
  makeSession(parseSceneScript(nearScript(0.5), "near"), dir / "s");
  const std::string s = dir / "s";
  const std::string bin = std::string(REFLEX_BIN_DIR) + "/reflex_vision_record";
  const std::string calib = " --calib-left " + s + "/left.yaml --calib-right " + s + "/right.yaml --objects " + s +
                            "/objects.yaml --out " + (dir / "rec") + " --quiet";
  std::string out;
  EXPECT_EQ(run(bin + " --camera-left /no/such.mp4 --camera-right " + s + "/right.mp4" + calib, out, dir), 2);
  EXPECT_THAT(out, HasSubstr("cannot open camera '/no/such.mp4'"));
  EXPECT_EQ(run(bin + " --camera-left " + s + "/left.mp4" + calib, out, dir), 2);
  EXPECT_THAT(out, HasSubstr("together"));
  // A side-by-side stream whose halves do not match the calibration: every frame skipped, reported.
  EXPECT_EQ(run(bin + " --side-by-side " + s + "/left.mp4" + calib, out, dir), 3);
  EXPECT_THAT(out, AllOf(HasSubstr("skipped frame 0"), HasSubstr("320x480"), HasSubstr("no frame recorded")));
  EXPECT_EQ(run(bin + " --help", out, dir), 0);
}
