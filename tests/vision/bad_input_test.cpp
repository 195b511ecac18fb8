// Bad input (issue 5, item 10): corrupt or truncated video, left and right of different length or
// size, missing or inconsistent calibration, unknown tag family, a session folder missing a file,
// bad timestamps, bad command lines. Each gives a clear error (naming the file/value) or a
// reported, skipped frame -- never a crash.
#include "reflex/vision/error.hpp"
#include "vision_test_util.hpp"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <opencv2/videoio.hpp>

#include <cstdlib>
#include <filesystem>
#include <regex>

using namespace reflex::vision;
using namespace reflex::vision::test;
using ::testing::HasSubstr;
namespace fs = std::filesystem;

namespace {

class BadInput : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    base_ = std::make_unique<TempDir>("bad_base");
    makeSession(parseSceneScript(nearScript(1.5), "near"), *base_ / "mp4");
    SceneScript avi = parseSceneScript(nearScript(1.5), "near");
    avi.codecs = {{"MJPG", "avi"}};
    makeSession(avi, *base_ / "avi");
    makeSession(parseSceneScript(nearScript(1.0), "near"), *base_ / "short");
  }
  static void TearDownTestSuite() { base_.reset(); }

  // A private copy of a base session to break.
  std::string copyOf(const std::string& which) {
    const std::string dst = dir_ / which;
    fs::copy(*base_ / which, dst, fs::copy_options::recursive);
    return dst;
  }
  static std::string errorOpening(const std::string& dir) {
    try {
      SessionReader r(dir);
    } catch (const VisionError& e) {
      return e.what();
    }
    return "no error";
  }
  // Runs the whole --dump path; returns stats (throws only for setup errors).
  static RunStats runAll(const std::string& dir) {
    SessionSource source(dir, 0.0);
    StereoTagPipeline pipeline(source.calibration(), defaultCameraMount(), source.info().objects, PipelineOptions{});
    ReplayOptions ro;
    ro.rate = 0.0;
    std::atomic<bool> stop{false};
    return runVision(source, pipeline, ro, RunCallbacks{}, stop);
  }
  static int runCli(const std::string& args, std::string& err) {
    TempDir tmp("cli");
    const std::string cmd = std::string(REFLEX_BIN_DIR) + "/reflex_vision " + args + " > " + (tmp / "out") + " 2> " +
                            (tmp / "err");
    const int rc = std::system(cmd.c_str());
    err = readText(tmp / "err");
    return WIFEXITED(rc) ? WEXITSTATUS(rc) : -1;
  }

  static std::unique_ptr<TempDir> base_;
  TempDir dir_{"bad"};
};
std::unique_ptr<TempDir> BadInput::base_;

}  // namespace

TEST_F(BadInput, IntactSessionsRead) {
  EXPECT_EQ(errorOpening(copyOf("mp4")), "no error");
  const RunStats s = runAll(copyOf("avi"));
  EXPECT_EQ(s.frames, 15);
  EXPECT_TRUE(s.end_message.empty());
}

TEST_F(BadInput, SessionMissingAFile) {
  for (const char* f : {"left.mp4", "right.mp4", "timestamps.csv", "left.yaml", "right.yaml", "objects.yaml",
                        "camera_mount.yaml", "ground_truth.csv"}) {
    const std::string d = copyOf("mp4");
    fs::remove(d + "/" + f);
    EXPECT_THAT(errorOpening(d), AllOf(HasSubstr("missing"), HasSubstr(std::string("'") + f + "'"))) << f;
    fs::remove_all(d);
  }
  EXPECT_THAT(errorOpening(dir_ / "nope"), HasSubstr("does not exist"));
}

TEST_F(BadInput, CorruptVideoCannotBeOpened) {
  const std::string d = copyOf("mp4");
  {
    std::ofstream os(d + "/left.mp4", std::ios::binary | std::ios::trunc);
    for (int i = 0; i < 100000; ++i) os.put(static_cast<char>((i * 7919) % 251));
  }
  EXPECT_THAT(errorOpening(d), AllOf(HasSubstr("cannot open video"), HasSubstr("left.mp4")));
}

TEST_F(BadInput, CorruptVideoMiddleNeverCrashes) {
  for (const char* which : {"mp4", "avi"}) {
    const std::string d = copyOf(which);
    const std::string video = d + "/right." + which;
    const auto size = fs::file_size(video);
    {
      std::fstream f(video, std::ios::in | std::ios::out | std::ios::binary);
      f.seekp(static_cast<std::streamoff>(size * 4 / 10));
      for (std::uintmax_t i = 0; i < size / 5; ++i) f.put(static_cast<char>((i * 131) % 256));
    }
    RunStats s;
    std::string error;
    try {
      s = runAll(d);
    } catch (const VisionError& e) {
      error = e.what();  // a clear setup error is acceptable too
    }
    std::cout << which << ": frames " << s.frames << ", skipped " << s.skipped << ", end '" << s.end_message
              << "', error '" << error << "'\n";
    EXPECT_LE(s.frames + s.skipped, 15);
    fs::remove_all(d);
  }
}

TEST_F(BadInput, TruncatedVideo) {
  // MP4 keeps its index at the end: a truncated file cannot be opened (clear error).
  {
    const std::string d = copyOf("mp4");
    fs::resize_file(d + "/left.mp4", fs::file_size(d + "/left.mp4") / 2);
    EXPECT_THAT(errorOpening(d), HasSubstr("left.mp4"));
  }
  // AVI streams: the truncated one opens and ends early, which the run reports.
  {
    const std::string d = copyOf("avi");
    fs::resize_file(d + "/left.avi", fs::file_size(d + "/left.avi") / 2);
    std::string error;
    RunStats s;
    try {
      s = runAll(d);
    } catch (const VisionError& e) {
      error = e.what();
    }
    if (error.empty()) {
      EXPECT_LT(s.frames, 15);
      EXPECT_THAT(s.end_message, AllOf(HasSubstr("left video ended at frame"), HasSubstr("truncated or corrupt")));
    } else {
      EXPECT_THAT(error, HasSubstr("left.avi"));
    }
  }
}

TEST_F(BadInput, LeftAndRightDifferInLengthOrSize) {
  const std::string d = copyOf("mp4");
  fs::copy_file(*base_ / "short/right.mp4", d + "/right.mp4", fs::copy_options::overwrite_existing);
  EXPECT_THAT(errorOpening(d), AllOf(HasSubstr("differ in length"), HasSubstr("15"), HasSubstr("10")));

  const std::string e = copyOf("avi");
  {
    cv::VideoWriter w(e + "/right.avi", cv::CAP_FFMPEG, cv::VideoWriter::fourcc('M', 'J', 'P', 'G'), 10,
                      cv::Size(320, 240), true);
    for (int i = 0; i < 15; ++i) w.write(cv::Mat(240, 320, CV_8UC3, cv::Scalar::all(128)));
  }
  EXPECT_THAT(errorOpening(e), AllOf(HasSubstr("video sizes differ"), HasSubstr("320x240")));
}

TEST_F(BadInput, MissingOrInconsistentCalibration) {
  const std::string d = copyOf("mp4");
  const std::string right = readText(d + "/right.yaml");
  // Right projection without the baseline.
  writeText(d + "/right.yaml", std::regex_replace(right, std::regex(R"((projection_matrix:[\s\S]*?data: \[[^,]+, [^,]+, [^,]+, )[^,]+,)"), "$1 0,"));
  EXPECT_THAT(errorOpening(d), AllOf(HasSubstr("right.yaml"), HasSubstr("P[0][3]")));
  // Image size disagreeing with the left camera.
  writeText(d + "/right.yaml", std::regex_replace(right, std::regex("image_width: 640"), "image_width: 320"));
  EXPECT_THAT(errorOpening(d), HasSubstr("image sizes differ"));
  // Field with a wrong element count.
  writeText(d + "/right.yaml", std::regex_replace(right, std::regex("rows: 1\n  cols: 5"), "rows: 1\n  cols: 4"));
  EXPECT_THAT(errorOpening(d), AllOf(HasSubstr("right.yaml"), HasSubstr("distortion_coefficients")));
  // Calibration of another camera size than the videos.
  writeText(d + "/right.yaml", right);
  for (const char* f : {"/left.yaml", "/right.yaml"})
    writeText(d + f, std::regex_replace(readText(d + f), std::regex("image_width: 640"), "image_width: 800"));
  EXPECT_THAT(errorOpening(d), AllOf(HasSubstr("640x480"), HasSubstr("800x480")));
}

TEST_F(BadInput, UnknownTagFamily) {
  const std::string d = copyOf("mp4");
  writeText(d + "/objects.yaml", "family: tag99h1\nobjects:\n  - {id: 0, name: cup, size: 0.06}\n");
  SessionSource source(d, 0.0);
  PipelineOptions o;
  o.detector.family = source.info().objects.family();
  try {
    StereoTagPipeline p(source.calibration(), defaultCameraMount(), source.info().objects, o);
    FAIL() << "unknown family accepted";
  } catch (const VisionError& e) {
    EXPECT_THAT(e.what(), HasSubstr("unknown tag family 'tag99h1'"));
  }
  std::string err;
  EXPECT_EQ(runCli("--session " + d + " --dump " + (dir_ / "x.csv"), err), 2);
  EXPECT_THAT(err, HasSubstr("unknown tag family 'tag99h1'"));
}

TEST_F(BadInput, BadTimestamps) {
  const std::string d = copyOf("mp4");
  const std::string ts = readText(d + "/timestamps.csv");
  writeText(d + "/timestamps.csv", std::regex_replace(ts, std::regex("\n3,[0-9.]+\n"), "\n3,0.05\n"));
  EXPECT_THAT(errorOpening(d), AllOf(HasSubstr("timestamps.csv: line 5"), HasSubstr("not after")));
  writeText(d + "/timestamps.csv", std::regex_replace(ts, std::regex("\n14,[0-9.]+\n"), "\n"));
  EXPECT_THAT(errorOpening(d), AllOf(HasSubstr("15 frames"), HasSubstr("lists 14")));
  writeText(d + "/timestamps.csv", "frame,stamp\n0,abc\n");
  EXPECT_THAT(errorOpening(d), HasSubstr("'abc' is not a number"));
}

TEST_F(BadInput, CommandLineErrorsNameTheBadValue) {
  std::string err;
  EXPECT_EQ(runCli("--session /no/such/session --dump /tmp/x.csv", err), 2);
  EXPECT_THAT(err, HasSubstr("/no/such/session"));
  EXPECT_EQ(runCli("--session " + (*base_ / "mp4") + " --dump " + (dir_ / "x.csv") + " --rate -2", err), 2);
  EXPECT_THAT(err, HasSubstr("-2"));
  EXPECT_EQ(runCli("--session " + (*base_ / "mp4") + " --dump " + (dir_ / "x.csv") + " --start 99", err), 2);
  EXPECT_THAT(err, HasSubstr("start offset 99"));
  EXPECT_EQ(runCli("--session " + (*base_ / "mp4") + " --dump " + (dir_ / "x.csv") + " --rectify sideways", err), 2);
  EXPECT_THAT(err, HasSubstr("'sideways'"));
  EXPECT_EQ(runCli("--dump " + (dir_ / "x.csv"), err), 2);
  EXPECT_THAT(err, HasSubstr("exactly one source"));
  EXPECT_EQ(runCli("--camera-left 7 --camera-right 8 --calib-left " + (*base_ / "mp4/left.yaml") + " --calib-right " +
                       (*base_ / "mp4/right.yaml") + " --objects " + (*base_ / "mp4/objects.yaml") + " --dump " +
                       (dir_ / "x.csv"),
                   err),
            2);
  EXPECT_THAT(err, HasSubstr("cannot open camera '7'"));
  EXPECT_EQ(runCli("--session " + (*base_ / "mp4") + " --dump /no/such/dir/x.csv", err), 2);
  EXPECT_THAT(err, HasSubstr("/no/such/dir/x.csv"));
  EXPECT_NE(runCli("--bogus-flag", err), 0);
  EXPECT_EQ(runCli("--help", err), 0);
}
