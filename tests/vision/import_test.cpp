// Offline import of real video files and a video file standing in for a camera
// ending at its end. The videos are real files written here by cv::VideoWriter (FFmpeg backend,
// FFV1 in AVI: lossless) from the frames of a session rendered at test time. Independent answer:
// that session itself -- the session imported from the files (left/right pair, or one side-by-side
// file) must give exactly the detections of the session the frames came from, with its stamps; every
// bad input is an error naming the value, and leaves no session.yaml behind.
#include "vision_test_util.hpp"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <opencv2/core.hpp>
#include <opencv2/videoio.hpp>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <filesystem>

using namespace reflex::vision;
using namespace reflex::vision::test;
using ::testing::AllOf;
using ::testing::HasSubstr;

namespace {

int runTool(const std::string& cmd, std::string& out, const TempDir& dir) {
  const int rc = std::system((cmd + " > " + (dir / "stdout.txt") + " 2> " + (dir / "stderr.txt")).c_str());
  out = readText(dir / "stderr.txt") + readText(dir / "stdout.txt");
  return WIFEXITED(rc) ? WEXITSTATUS(rc) : -1;
}

struct Frames {
  std::vector<cv::Mat> left, right;
  std::vector<double> stamps;
};

Frames decodeSession(const std::string& dir) {
  SessionReader reader(dir);
  Frames f;
  StereoFrame fr;
  std::string msg;
  while (reader.read(fr, msg) == ReadStatus::kOk) {
    f.left.push_back(fr.left.clone());
    f.right.push_back(fr.right.clone());
    f.stamps.push_back(fr.stamp);
  }
  return f;
}

/// Writes frames [0, count) into a lossless FFV1 AVI; the file is checked to hold them all.
/// (OpenCV's FFmpeg writer rounds an odd width down; its own MJPEG writer, `odd_width`, keeps it.)
void writeVideo(const std::string& path, const std::vector<cv::Mat>& frames, std::size_t count,
                bool odd_width = false) {
  ASSERT_GT(count, 0u);
  cv::VideoWriter w(
      path, odd_width ? cv::CAP_OPENCV_MJPEG : cv::CAP_FFMPEG,
      odd_width ? cv::VideoWriter::fourcc('M', 'J', 'P', 'G') : cv::VideoWriter::fourcc('F', 'F', 'V', '1'), 10.0,
      frames[0].size(), true);
  ASSERT_TRUE(w.isOpened()) << path;
  for (std::size_t i = 0; i < count; ++i) w.write(frames[i]);
  w.release();
  cv::VideoCapture check(path, cv::CAP_FFMPEG);
  ASSERT_EQ(std::lround(check.get(cv::CAP_PROP_FRAME_COUNT)), static_cast<long>(count)) << path;
}

std::vector<cv::Mat> sideBySide(const Frames& f) {
  std::vector<cv::Mat> out;
  for (std::size_t i = 0; i < f.left.size(); ++i) {
    cv::Mat both;
    cv::hconcat(f.left[i], f.right[i], both);
    out.push_back(both);
  }
  return out;
}

/// A rendered 1 s session (10 pairs, two tags) and its frames, shared by the tests of this file.
struct Fixture {
  TempDir dir{"import"};
  std::string session = dir / "s";
  Frames frames;
  std::string calib;  // the calibration, object map and mount options of reflex_vision_record
  Fixture() {
    makeSession(parseSceneScript(nearScript(1.0), "near"), session);
    frames = decodeSession(session);
    calib = " --calib-left " + session + "/left.yaml --calib-right " + session + "/right.yaml --objects " + session +
            "/objects.yaml --mount " + session + "/camera_mount.yaml";
  }
  /// Every frame as lossless left.avi and right.avi in `dir`.
  void writeVideos(const TempDir& out) const {
    writeVideo(out / "left.avi", frames.left, frames.left.size());
    writeVideo(out / "right.avi", frames.right, frames.right.size());
  }
};

Fixture& fixture() {
  static Fixture f;
  return f;
}

const std::string kRecord = std::string(REFLEX_BIN_DIR) + "/reflex_vision_record";

void expectSameDetections(const std::string& original, const std::string& imported) {
  const std::vector<Detection> a = detectSession(original), b = detectSession(imported);
  ASSERT_GE(a.size(), 10u);  // two tags in most of the 10 pairs
  ASSERT_EQ(a.size(), b.size());
  for (std::size_t i = 0; i < a.size(); ++i) {
    EXPECT_EQ(a[i].frame, b[i].frame);
    EXPECT_EQ(a[i].object, b[i].object);
    EXPECT_EQ(cv::norm(a[i].p_B - b[i].p_B), 0.0) << "frame " << a[i].frame << " " << a[i].object;
  }
}

}  // namespace

TEST(Import, LeftRightFilesWithTimestampsGiveTheSessionsOwnDetections) {
  Fixture& fx = fixture();
  TempDir dir("import_lr");
  const std::size_t n = fx.frames.left.size();
  ASSERT_EQ(n, 10u);
  fx.writeVideos(dir);
  std::string out;
  ASSERT_EQ(runTool(kRecord + " --from-files " + (dir / "left.avi") + " " + (dir / "right.avi") + " --timestamps " +
                        fx.session + "/timestamps.csv --codec FFV1 --out " + (dir / "imported") + fx.calib,
                    out, dir),
            0)
      << out;
  EXPECT_THAT(out, AllOf(HasSubstr("imported 10 pairs"), HasSubstr("codec FFV1"), HasSubstr("pairs/s achieved")));
  SessionReader imported(dir / "imported");
  ASSERT_EQ(imported.info().frameCount(), 10);
  for (std::size_t i = 0; i < n; ++i) EXPECT_NEAR(imported.info().stamps[i], fx.frames.stamps[i], 1e-6);
  // The images themselves came through unchanged (lossless both ways).
  const Frames back = decodeSession(dir / "imported");
  ASSERT_EQ(back.left.size(), n);
  for (std::size_t i = 0; i < n; ++i) {
    EXPECT_EQ(cv::norm(back.left[i], fx.frames.left[i], cv::NORM_INF), 0.0) << "left " << i;
    EXPECT_EQ(cv::norm(back.right[i], fx.frames.right[i], cv::NORM_INF), 0.0) << "right " << i;
  }
  expectSameDetections(fx.session, dir / "imported");
}

TEST(Import, SideBySideFileWithFpsGivesTheSessionsOwnDetections) {
  Fixture& fx = fixture();
  TempDir dir("import_sbs");
  writeVideo(dir / "sbs.avi", sideBySide(fx.frames), fx.frames.left.size());
  std::string out;
  ASSERT_EQ(runTool(kRecord + " --from-side-by-side " + (dir / "sbs.avi") + " --fps 12.5 --codec FFV1 --out " +
                        (dir / "imported") + fx.calib,
                    out, dir),
            0)
      << out;
  EXPECT_THAT(out, AllOf(HasSubstr("imported 10 pairs"), HasSubstr("span 0.720 s")));
  SessionReader imported(dir / "imported");
  ASSERT_EQ(imported.info().frameCount(), 10);
  for (int i = 0; i < 10; ++i) EXPECT_NEAR(imported.info().stamps[static_cast<std::size_t>(i)], i / 12.5, 1e-9);
  EXPECT_DOUBLE_EQ(imported.info().fps, 12.5);
  expectSameDetections(fx.session, dir / "imported");
}

TEST(Import, BadInputsAreNamedAndLeaveNoSession) {
  Fixture& fx = fixture();
  TempDir dir("import_bad");
  const std::size_t n = fx.frames.left.size();
  fx.writeVideos(dir);
  writeVideo(dir / "short.avi", fx.frames.right, n - 3);
  std::vector<cv::Mat> small;
  for (const cv::Mat& m : fx.frames.right) small.push_back(m(cv::Rect(0, 0, 320, 240)).clone());
  writeVideo(dir / "small.avi", small, n);
  std::vector<cv::Mat> odd;
  for (const cv::Mat& m : sideBySide(fx.frames)) odd.push_back(m(cv::Rect(0, 0, 1279, 480)).clone());
  writeVideo(dir / "odd.avi", odd, n, true);
  std::string rows_short = "frame,stamp\n", rows_long = "frame,stamp\n", rows_back = "frame,stamp\n";
  for (std::size_t i = 0; i < n + 2; ++i) {
    const std::string row = std::to_string(i) + "," + std::to_string(0.1 * static_cast<double>(i)) + "\n";
    if (i < n - 1) rows_short += row;
    rows_long += row;
    if (i < n) rows_back += std::to_string(i) + "," + (i == 7 ? std::string("0.5") : std::to_string(0.1 * i)) + "\n";
  }
  writeText(dir / "short.csv", rows_short);
  writeText(dir / "long.csv", rows_long);
  writeText(dir / "back.csv", rows_back);
  const std::string lr = " --from-files " + (dir / "left.avi") + " " + (dir / "right.avi");
  const std::string tail = " --out " + (dir / "out") + fx.calib + " --quiet";
  struct Case {
    std::string args, expected;
  };
  const std::vector<Case> cases = {
      {" --from-files " + (dir / "nope.avi") + " " + (dir / "right.avi"),
       "'" + (dir / "nope.avi") + "' does not exist"},
      {" --from-files " + (dir / "left.avi") + " " + (dir / "short.avi"), "has 10 frames but right video"},
      {" --from-files " + (dir / "left.avi") + " " + (dir / "small.avi"), "is 640x480 but right video"},
      {" --from-side-by-side " + (dir / "odd.avi"), "is 1279 pixels wide"},
      {" --from-files " + (dir / "left.avi") + " " + (dir / "left.avi"),
       "the left and the right video are the same file"},
      {" --from-side-by-side " + (dir / "left.avi"), "has 320x480 halves but the calibration says 640x480"},
      {lr + " --timestamps " + (dir / "short.csv"), "lists 9 frames but video"},
      {lr + " --timestamps " + (dir / "long.csv"), "lists 12 frames but video"},
      {lr + " --timestamps " + (dir / "back.csv"), "line 9: stamp 0.5 is not after the previous 0.6"},
      {lr + " --fps 0", "--fps 0"},
      {lr + " --fps -3", "--fps -3"},
      {lr + " --fps nan", "--fps nan"},
      {lr + " --fps 10 --timestamps " + (dir / "long.csv"), "not both"},
      {lr + " --frames 5", "--frames and --duration apply to cameras"},
      {lr + " --crf 52", "--crf 52 must be an integer in 0..51"},
      {lr + " --crf -1", "--crf -1 must be an integer in 0..51"},
      {" --timestamps " + (dir / "long.csv") + " --camera-left 0 --camera-right 1", "--timestamps applies to"},
  };
  for (const Case& c : cases) {
    std::string out;
    EXPECT_EQ(runTool(kRecord + c.args + tail, out, dir), 2) << c.args << "\n" << out;
    EXPECT_THAT(out, HasSubstr(c.expected)) << c.args;
    EXPECT_FALSE(std::filesystem::exists(dir / "out/session.yaml")) << c.args;
  }
  std::string out;
  EXPECT_EQ(runTool(kRecord + " --help", out, dir), 0);
  EXPECT_THAT(out, AllOf(HasSubstr("--from-files"), HasSubstr("--from-side-by-side"), HasSubstr("--timestamps")));
}

/// Mean PSNR (dB) of the left images of session `dir` against `reference`.
double meanLeftPsnr(const std::string& dir, const std::vector<cv::Mat>& reference) {
  const Frames back = decodeSession(dir);
  EXPECT_EQ(back.left.size(), reference.size());
  double sum = 0.0;
  for (std::size_t i = 0; i < std::min(back.left.size(), reference.size()); ++i)
    sum += cv::PSNR(back.left[i], reference[i]);
  return back.left.empty() ? 0.0 : sum / static_cast<double>(back.left.size());
}

// The default import writes H.264 at CRF 18 by the ffmpeg program and says so; --crf sets the
// quality. Independent answers: the encoder's own settings record in the video (x264 writes its
// options, "crf=18.0", into the stream), the PSNR of the decoded images against the lossless source,
// and the detections of the source session. Without ffmpeg the import says loudly what it used instead.
TEST(Import, DefaultIsH264AtCrf18AndCrfSetsTheQuality) {
  Fixture& fx = fixture();
  TempDir dir("import_quality");
  fx.writeVideos(dir);
  const std::string lr = " --from-files " + (dir / "left.avi") + " " + (dir / "right.avi") + fx.calib + " --quiet";
  std::string out;
  ASSERT_EQ(runTool(kRecord + lr + " --out " + (dir / "crf18"), out, dir), 0) << out;
  EXPECT_THAT(out, HasSubstr("with codec x264 (H.264 by ffmpeg/libx264 at CRF 18)"));
  EXPECT_THAT(readText(dir / "crf18/session.yaml"), HasSubstr("codec: x264"));
  EXPECT_THAT(readText(dir / "crf18/left.mp4"), HasSubstr("crf=18.0"));
  EXPECT_FALSE(std::filesystem::exists(dir / "crf18/left.mp4.ffmpeg.log")) << "the log goes when ffmpeg succeeds";
  ASSERT_EQ(runTool(kRecord + lr + " --crf 35 --out " + (dir / "crf35"), out, dir), 0) << out;
  EXPECT_THAT(out, HasSubstr("at CRF 35)"));
  EXPECT_THAT(readText(dir / "crf35/left.mp4"), HasSubstr("crf=35.0"));
  // The default keeps every detection of the source, within a millimetre.
  const std::vector<Detection> a = detectSession(fx.session), b = detectSession(dir / "crf18");
  ASSERT_EQ(a.size(), b.size());
  for (std::size_t i = 0; i < a.size(); ++i) {
    EXPECT_EQ(a[i].frame, b[i].frame);
    EXPECT_EQ(a[i].object, b[i].object);
    EXPECT_LT(cv::norm(a[i].p_B - b[i].p_B), 1e-3) << "frame " << a[i].frame << " " << a[i].object;
  }
  // No ffmpeg program on PATH: OpenCV's H.264, said loudly.
  ASSERT_EQ(runTool("PATH=" + (dir / "empty") + " " + kRecord + lr + " --out " + (dir / "noffmpeg"), out, dir), 0)
      << out;
  EXPECT_THAT(out, AllOf(HasSubstr("warning: the videos are avc1"), HasSubstr("not x264 at CRF 18"),
                         HasSubstr("no ffmpeg program on PATH")));
  // Quality against the lossless source: CRF 18 above OpenCV's H.264 (x264's default CRF 23, the
  // import's codec before), CRF 35 below both and smallest.
  const double psnr18 = meanLeftPsnr(dir / "crf18", fx.frames.left);
  const double psnr23 = meanLeftPsnr(dir / "noffmpeg", fx.frames.left);
  const double psnr35 = meanLeftPsnr(dir / "crf35", fx.frames.left);
  auto bytes = [&](const std::string& folder) { return std::filesystem::file_size(dir / (folder + "/left.mp4")); };
  std::printf(
      "left images against the lossless source: CRF 18 %.1f dB %ju bytes, avc1 %.1f dB %ju bytes, "
      "CRF 35 %.1f dB %ju bytes\n",
      psnr18, bytes("crf18"), psnr23, bytes("noffmpeg"), psnr35, bytes("crf35"));
  EXPECT_GT(psnr18, psnr23 + 0.3);
  EXPECT_GT(psnr23, psnr35 + 1.0);
  EXPECT_GT(bytes("crf18"), bytes("noffmpeg"));
  EXPECT_GT(bytes("noffmpeg"), bytes("crf35"));
}

// A video file used as a camera (paced at its own 10 fps) ends at its end: exit 0 with the summary;
// a file cut short (its container still lists every frame) is still an error, like a camera that stops.
TEST(StandInCamera, AVideoFileEndsNormallyAndATruncatedOneIsAnError) {
  Fixture& fx = fixture();
  TempDir dir("standin");
  fx.writeVideos(dir);
  const std::string vision = std::string(REFLEX_BIN_DIR) + "/reflex_vision --calib-left " + fx.session +
                             "/left.yaml --calib-right " + fx.session + "/right.yaml --objects " + fx.session +
                             "/objects.yaml --mount " + fx.session + "/camera_mount.yaml --quiet --dump " +
                             (dir / "dump.csv");
  std::string out;
  ASSERT_EQ(
      runTool(vision + " --camera-left " + (dir / "left.avi") + " --camera-right " + (dir / "right.avi"), out, dir), 0)
      << out;
  EXPECT_THAT(out, HasSubstr("10 frames processed"));
  EXPECT_THAT(out, ::testing::Not(HasSubstr("error")));
  // Truncated: the AVI header still says 10 frames, the data stops after about half of them.
  const std::string data = readText(dir / "right.avi");
  writeText(dir / "cut.avi", data.substr(0, data.size() / 2));
  EXPECT_EQ(runTool(vision + " --camera-left " + (dir / "left.avi") + " --camera-right " + (dir / "cut.avi"), out, dir),
            3)
      << out;
  EXPECT_THAT(out,
              AllOf(HasSubstr("right video file ended after"), HasSubstr("of the 10 frames"), HasSubstr("truncated")));
}
