// Bad input: corrupt or truncated video, left and right of different length or
// size, missing or inconsistent calibration, unknown tag family, a session folder missing a file,
// bad timestamps, bad command lines. Each gives a clear error (naming the file/value) or a
// reported, skipped frame -- never a crash.
// At the end: sessions no rig can produce (swapped or
// identical videos, impossible calibration, tag size, frame count, fps) refused at load; stamps no
// replay clock can follow refused; SIGTERM/SIGINT end a paced replay within a second; outputs that
// cannot be written (--dump /dev/full, a file-size limit) are errors naming the file and cause.
#include "support/child_process.hpp"
#include "support/errors.hpp"
#include "reflex/vision/error.hpp"
#include "reflex/vision/output_file.hpp"
#include "vision_test_util.hpp"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <opencv2/videoio.hpp>

#include <sys/resource.h>

#include <chrono>
#include <csignal>
#include <cstdlib>
#include <filesystem>
#include <functional>
#include <regex>
#include <thread>

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

  // A private copy of a base session to break (`as`: the copy's folder name, default `which`).
  std::string copyOf(const std::string& which, const std::string& as = "") {
    const std::string dst = dir_ / (as.empty() ? which : as);
    fs::copy(*base_ / which, dst, fs::copy_options::recursive);
    return dst;
  }
  static std::string errorOpening(const std::string& dir) {
    return reflex::testing::messageOf<VisionError>([&] { SessionReader r(dir); });
  }
  // Runs the whole --dump path; returns stats (throws only for setup errors).
  static RunStats runAll(const std::string& dir) {
    SessionSource source(dir, 0.0);
    StereoTagPipeline pipeline(source.calibration(), test::shippedMount(), source.info().objects, PipelineOptions{});
    ReplayOptions ro;
    ro.rate = 0.0;
    std::atomic<bool> stop{false};
    return runVision(source, pipeline, ro, RunCallbacks{}, stop);
  }
  static int runCli(const std::string& args, std::string& err) {
    TempDir tmp("cli");
    const std::string cmd =
        std::string(REFLEX_BIN_DIR) + "/reflex_vision " + args + " > " + (tmp / "out") + " 2> " + (tmp / "err");
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
  writeText(d + "/right.yaml",
            std::regex_replace(right, std::regex(R"((projection_matrix:[\s\S]*?data: \[[^,]+, [^,]+, [^,]+, )[^,]+,)"),
                               "$1 0,"));
  EXPECT_THAT(errorOpening(d), AllOf(HasSubstr("right.yaml"), HasSubstr("P[0][3]")));
  // Image size disagreeing with the left camera (wider: the principal point stays inside the image).
  writeText(d + "/right.yaml", std::regex_replace(right, std::regex("image_width: 640"), "image_width: 800"));
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
    StereoTagPipeline p(source.calibration(), test::shippedMount(), source.info().objects, o);
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
  // (the manifest's frame count is compared first; without it, the video's)
  EXPECT_THAT(errorOpening(d), AllOf(HasSubstr("frames = 15"), HasSubstr("lists 14")));
  fs::remove(d + "/session.yaml");
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
  EXPECT_EQ(runCli("--session " + (*base_ / "mp4") + " --dump " + (dir_ / "x.csv") + " --max-lag 0", err), 2);
  EXPECT_THAT(err, HasSubstr("max lag 0.000000 s must be in (0, 10]"));
  EXPECT_EQ(runCli("--session " + (*base_ / "mp4") + " --dump " + (dir_ / "x.csv") + " --image-rate 31", err), 2);
  EXPECT_THAT(err, HasSubstr("--image-rate 31 must be in [0, 30] Hz"));
  EXPECT_EQ(runCli("--session " + (*base_ / "mp4") + " --dump " + (dir_ / "x.csv") + " --image-rate nan", err), 2);
  EXPECT_THAT(err, HasSubstr("--image-rate"));
  EXPECT_EQ(runCli("--session " + (*base_ / "mp4") + " --dump " + (dir_ / "x.csv") + " --image-width 10", err), 2);
  EXPECT_THAT(err, HasSubstr("--image-width 10 must be in [64, 4096] pixels"));
  EXPECT_EQ(runCli("--session " + (*base_ / "mp4") + " --dump " + (dir_ / "x.csv") + " --start 99", err), 2);
  EXPECT_THAT(err, HasSubstr("start offset 99"));
  EXPECT_EQ(runCli("--session " + (*base_ / "mp4") + " --dump " + (dir_ / "x.csv") + " --rectify sideways", err), 2);
  EXPECT_THAT(err, HasSubstr("'sideways'"));
  EXPECT_EQ(runCli("--dump " + (dir_ / "x.csv"), err), 2);
  EXPECT_THAT(err, HasSubstr("exactly one source"));
  EXPECT_EQ(runCli("--camera-left 7 --camera-right 8 --calib-left " + (*base_ / "mp4/left.yaml") + " --calib-right " +
                       (*base_ / "mp4/right.yaml") + " --objects " + (*base_ / "mp4/objects.yaml") + " --mount " +
                       (*base_ / "mp4/camera_mount.yaml") + " --dump " + (dir_ / "x.csv"),
                   err),
            2);
  EXPECT_THAT(err, HasSubstr("cannot open camera '7'"));
  // No silent default mount: live cameras without --mount, and a session without
  // camera_mount.yaml, are errors naming what to pass.
  EXPECT_EQ(runCli("--camera-left 7 --camera-right 8 --calib-left " + (*base_ / "mp4/left.yaml") + " --calib-right " +
                       (*base_ / "mp4/right.yaml") + " --objects " + (*base_ / "mp4/objects.yaml") + " --dump " +
                       (dir_ / "x.csv"),
                   err),
            2);
  EXPECT_THAT(err, HasSubstr("live cameras need --mount FILE"));
  EXPECT_THAT(err, HasSubstr("bringup/vision/camera_mount.yaml"));
  const std::string no_mount = copyOf("mp4");
  std::filesystem::remove(no_mount + "/camera_mount.yaml");
  writeText(no_mount + "/session.yaml",
            std::regex_replace(readText(no_mount + "/session.yaml"), std::regex("camera_mount: .*\n"), ""));
  EXPECT_EQ(runCli("--session " + no_mount + " --dump " + (dir_ / "x.csv"), err), 2);
  EXPECT_THAT(err, HasSubstr("has no camera_mount.yaml: pass --mount FILE"));
  EXPECT_EQ(
      runCli("--session " + no_mount + " --dump " + (dir_ / "x.csv") + " --mount " + (*base_ / "mp4/camera_mount.yaml"),
             err),
      0)
      << err;
  EXPECT_EQ(runCli("--session " + (*base_ / "mp4") + " --dump /no/such/dir/x.csv", err), 2);
  EXPECT_THAT(err, HasSubstr("/no/such/dir/x.csv"));
  EXPECT_NE(runCli("--bogus-flag", err), 0);
  EXPECT_EQ(runCli("--help", err), 0);
}

// ---- Sessions no rig can produce. Each case below was accepted before (exit 0, zero
// detections, a spin or a silent wait); the expected error text is written from the contract in
// vision/README.md, not copied from the output.
namespace {

std::string replaceOnce(const std::string& text, const std::string& pattern, const std::string& with) {
  const std::string out = std::regex_replace(text, std::regex(pattern), with, std::regex_constants::format_first_only);
  EXPECT_NE(out, text) << "pattern '" << pattern << "' not found";
  return out;
}
void editFile(const std::string& path, const std::string& pattern, const std::string& with) {
  writeText(path, replaceOnce(readText(path), pattern, with));
}
// timestamps.csv with the stamps of `stamp(k)` for the session's frame count.
void writeStamps(const std::string& dir, int frames, const std::function<std::string(int)>& stamp) {
  std::string ts = "frame,stamp\n";
  for (int k = 0; k < frames; ++k) ts += std::to_string(k) + "," + stamp(k) + "\n";
  writeText(dir + "/timestamps.csv", ts);
}
// `text` (camera_info YAML) with element `index` of the data list of matrix `key` set to `value`.
std::string withMatrixElement(const std::string& text, const std::string& key, int index, const std::string& value) {
  const std::size_t at = text.find(key + ":");
  std::size_t begin = text.find("data: [", at);
  EXPECT_TRUE(at != std::string::npos && begin != std::string::npos) << key;
  begin += 7;
  for (int i = 0; i < index; ++i) begin = text.find(',', begin) + 2;
  const std::size_t end = text.find_first_of(",]", begin);
  return text.substr(0, begin) + value + text.substr(end);
}
std::string bin(const std::string& name) { return std::string(REFLEX_BIN_DIR) + "/" + name; }
double secondsSince(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

}  // namespace

// Item 15: values no physical rig has, each refused when the session is opened (and by the CLI,
// exit 2), naming the file, the field and the value.
TEST_F(BadInput, SessionsThatCannotGiveAnyDetectionAreRefusedAtLoad) {
  {  // left and right videos swapped (the calibration is right, the images are not)
    const std::string d = copyOf("mp4", "case1");
    fs::rename(d + "/left.mp4", d + "/tmp.mp4");
    fs::rename(d + "/right.mp4", d + "/left.mp4");
    fs::rename(d + "/tmp.mp4", d + "/right.mp4");
    EXPECT_THAT(errorOpening(d), AllOf(HasSubstr("look swapped"), HasSubstr("left.mp4"), HasSubstr("negative")));
    std::string err;
    EXPECT_EQ(runCli("--session " + d + " --dump " + (dir_ / "swapped.csv"), err), 2);
    EXPECT_THAT(err, HasSubstr("look swapped"));
  }
  {  // the same video file named twice
    const std::string d = copyOf("mp4", "case2");
    editFile(d + "/session.yaml", "right_video: right.mp4", "right_video: left.mp4");
    EXPECT_THAT(errorOpening(d), AllOf(HasSubstr("are the same file"), HasSubstr("left.mp4")));
  }
  {  // the same video under two names
    const std::string d = copyOf("mp4", "case3");
    fs::copy_file(d + "/left.mp4", d + "/right.mp4", fs::copy_options::overwrite_existing);
    EXPECT_THAT(errorOpening(d), AllOf(HasSubstr("show the same images"), HasSubstr("right.mp4")));
  }
  {  // frame count in the manifest: negative, or not what timestamps.csv lists
    const std::string d = copyOf("mp4", "case4");
    editFile(d + "/session.yaml", "frames: 15", "frames: -3");
    EXPECT_THAT(errorOpening(d), AllOf(HasSubstr("session.yaml:"),
                                       HasSubstr(": frames: out of range (value '-3', expected an integer in [1, ")));
    editFile(d + "/session.yaml", "frames: -3", "frames: 7");
    EXPECT_THAT(errorOpening(d), AllOf(HasSubstr("frames = 7"), HasSubstr("lists 15")));
  }
  {  // nominal frame rate
    const std::string d = copyOf("mp4", "case5");
    editFile(d + "/session.yaml", "fps: 10", "fps: 1e9");
    EXPECT_THAT(errorOpening(d),
                AllOf(HasSubstr("session.yaml:"), HasSubstr(": fps: out of range (value '1e9', expected (0, ")));
  }
  {  // tag sizes no camera can see, an object map without objects
    const std::string d = copyOf("mp4", "case6");
    editFile(d + "/objects.yaml", "size: 0.06", "size: 1e-05");
    EXPECT_THAT(errorOpening(d),
                AllOf(HasSubstr("objects.yaml:"),
                      HasSubstr(": objects[0].size: out of range (value '1e-05', expected a number in [0.002, 5] m")));
    editFile(d + "/objects.yaml", "size: 1e-05", "size: 100");
    EXPECT_THAT(errorOpening(d), HasSubstr("objects[0].size: out of range (value '100'"));
    writeText(d + "/objects.yaml", "family: tag36h11\nobjects: []\n");
    EXPECT_THAT(errorOpening(d),
                AllOf(HasSubstr("objects.yaml:"), HasSubstr(": objects: the list is empty (no tag would ever be "
                                                            "reported) (value '[]', expected at least one object)")));
  }
  {  // a baseline of a nanometre (P[0][3] still negative, so the sign check passed) and of 100 km
    const std::string d = copyOf("mp4", "case7");
    const std::string p03 = R"((projection_matrix:\s+rows: 3\s+cols: 4\s+data: \[[^,]+, [^,]+, [^,]+, )[^,]+)";
    const std::string right = readText(d + "/right.yaml");
    writeText(d + "/right.yaml", replaceOnce(right, p03, "$1-1e-06"));
    EXPECT_THAT(errorOpening(d), AllOf(HasSubstr("right.yaml"), HasSubstr("baseline"), HasSubstr("-1e-06")));
    writeText(d + "/right.yaml", replaceOnce(right, p03, "$1-5e+07"));
    EXPECT_THAT(errorOpening(d), AllOf(HasSubstr("right.yaml"), HasSubstr("baseline")));
  }
  {  // absurd focal length, principal point outside the image
    const std::string d = copyOf("mp4", "case8");
    const std::string left = readText(d + "/left.yaml");
    writeText(d + "/left.yaml", withMatrixElement(left, "camera_matrix", 0, "0.5"));
    EXPECT_THAT(errorOpening(d), AllOf(HasSubstr("left.yaml"), HasSubstr("fx = 0.5 px")));
    writeText(d + "/left.yaml", withMatrixElement(left, "camera_matrix", 0, "5e+07"));
    EXPECT_THAT(errorOpening(d), AllOf(HasSubstr("left.yaml"), HasSubstr("fx = 50000000 px")));
    writeText(d + "/left.yaml", withMatrixElement(left, "camera_matrix", 2, "4000"));
    EXPECT_THAT(errorOpening(d), AllOf(HasSubstr("left.yaml"), HasSubstr("principal point"), HasSubstr("4000")));
  }
  // The intact session still opens (the checks do not refuse a real rig).
  EXPECT_EQ(errorOpening(copyOf("avi")), "no error");
}

// Item 13: stamps a replay clock cannot follow are refused at load, naming the line and the value.
TEST_F(BadInput, StampsNoClockCanFollowAreRefusedAtLoad) {
  const std::string d = copyOf("mp4");
  writeStamps(d, 15, [](int k) { return std::to_string(1e17 + 16.0 * k); });
  EXPECT_THAT(errorOpening(d), AllOf(HasSubstr("timestamps.csv: line 2"), HasSubstr("1e+17"), HasSubstr("outside")));
  writeStamps(d, 15, [](int k) { return std::to_string(0.1 * k + (k >= 5 ? 1e6 : 0.0)); });
  EXPECT_THAT(errorOpening(d), AllOf(HasSubstr("timestamps.csv: line 7"), HasSubstr("1000000"), HasSubstr("10 s")));
  writeStamps(d, 15, [](int k) { return std::to_string(-1e11 + k); });
  EXPECT_THAT(errorOpening(d), HasSubstr("outside"));
  // A gap just under the documented maximum (10 s) is a valid session.
  writeStamps(d, 15, [](int k) { return std::to_string(0.1 * k + (k >= 5 ? 9.5 : 0.0)); });
  EXPECT_EQ(errorOpening(d), "no error");
}

// Item 13 as a process: `reflex_vision --dump` on a session stamped near 1e17 s spun at 100 % CPU
// for ever (and ignored SIGTERM); now it ends at once with exit 2 naming the stamp.
TEST_F(BadInput, DumpOfASessionStampedNear1e17EndsAtOnce) {
  const std::string d = copyOf("mp4");
  writeStamps(d, 15, [](int k) { return std::to_string(1e17 + 16.0 * k); });
  const auto t0 = std::chrono::steady_clock::now();
  reflex::testing::ChildProcess p({bin("reflex_vision"), "--session", d, "--dump", dir_ / "x.csv", "--quiet"},
                                  dir_ / "log.txt");
  ASSERT_TRUE(p.started());
  EXPECT_EQ(p.wait(std::chrono::seconds(20)), 2) << readText(dir_ / "log.txt");
  EXPECT_LT(secondsSince(t0), 20.0);
  EXPECT_THAT(readText(dir_ / "log.txt"), AllOf(HasSubstr("timestamps.csv: line 2"), HasSubstr("outside")));
}

// Item 13: SIGTERM (and SIGINT) end a paced replay within a second, also in the middle of a wait
// for a frame 9.6 s later (a valid gap): the wait is sliced and looks at the stop flag.
TEST_F(BadInput, SignalsEndAPacedReplayDuringALongWait) {
  const std::string d = copyOf("mp4");
  writeStamps(d, 15, [](int k) { return std::to_string(0.1 * k + (k >= 3 ? 9.5 : 0.0)); });
  for (const int sig : {SIGTERM, SIGINT}) {
    const std::string log = dir_ / ("log" + std::to_string(sig) + ".txt");
    reflex::testing::ChildProcess p(
        {bin("reflex_vision"), "--session", d, "--dump", dir_ / "x.csv", "--rate", "1", "--progress"}, log);
    ASSERT_TRUE(p.started());
    // Progress lines appear once frames are processed; frames 0-2 take 0.2 s, then the 9.6 s wait.
    const auto t0 = std::chrono::steady_clock::now();
    while (readText(log).find("[pass 1]") == std::string::npos && secondsSince(t0) < 30.0)
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    ASSERT_NE(readText(log).find("[pass 1]"), std::string::npos) << readText(log);
    std::this_thread::sleep_for(std::chrono::milliseconds(800));  // well inside the wait
    const auto t_signal = std::chrono::steady_clock::now();
    p.signal(sig);
    EXPECT_EQ(p.wait(std::chrono::milliseconds(1500)), 0) << "signal " << sig << ": " << readText(log);
    EXPECT_LT(secondsSince(t_signal), 1.5);
    // It stopped inside the wait: the 3 frames before the gap were processed or dropped (a paced
    // replay drops frames already a period late, as at start-up), none after.
    std::smatch m;
    const std::string text = readText(log);
    ASSERT_TRUE(std::regex_search(text, m, std::regex(R"((\d+) frames processed, (\d+) skipped, (\d+) dropped)")))
        << text;
    EXPECT_EQ(std::stoi(m[1]) + std::stoi(m[2]) + std::stoi(m[3]), 3) << text;
  }
}

// Item 14: an output that cannot be written is an error naming the file and the cause, exit 4
// (was exit 0); a missing output folder is an error before any work, naming the folder.
TEST_F(BadInput, DumpThatCannotBeWrittenIsAnError) {
  std::string err;
  const std::string& full = reflex::testing::fullDevice();
  EXPECT_EQ(runCli("--session " + (*base_ / "mp4") + " --dump " + full + " --quiet", err), 4);
  EXPECT_THAT(err, AllOf(HasSubstr("'" + full + "'"), HasSubstr("No space left on device")));
  EXPECT_EQ(runCli("--session " + (*base_ / "mp4") + " --dump " + (dir_ / "no_such_dir/x.csv"), err), 2);
  EXPECT_THAT(err, HasSubstr("folder '" + (dir_ / "no_such_dir") + "' does not exist"));
}

// Item 14: the session writer checks every file it writes. A file-size limit (RLIMIT_FSIZE, with
// SIGXFSZ ignored so that write(2) fails with EFBIG) stands in for a full disk.
TEST_F(BadInput, SessionWriterReportsFilesItCouldNotWrite) {
  const SessionInfo info = loadSessionInfo(*base_ / "mp4");
  // A missing parent folder is an error at the start (it used to be created silently).
  EXPECT_THAT(errorOf([&] { SessionWriter w(dir_ / "no/such/parent/s", info.calibration, info.objects, {}, {}); }),
              AllOf(HasSubstr("folder '" + (dir_ / "no/such/parent") + "' does not exist")));
  EXPECT_FALSE(fs::exists(dir_ / "no"));
  { SessionWriter w(dir_ / "trailing/", info.calibration, info.objects, {}, {}); }  // "x/" is the folder x
  EXPECT_TRUE(fs::is_regular_file(dir_ / "trailing/session.yaml"));

  struct rlimit old {};
  ASSERT_EQ(getrlimit(RLIMIT_FSIZE, &old), 0);
  const auto old_handler = std::signal(SIGXFSZ, SIG_IGN);
  std::string error = "no error";
  {
    SessionWriter w(dir_ / "limited", info.calibration, info.objects, {}, {});  // small files: written
    struct rlimit small = old;
    small.rlim_cur = 16 * 1024;
    ASSERT_EQ(setrlimit(RLIMIT_FSIZE, &small), 0);
    cv::RNG rng(3);
    cv::Mat left(info.calibration.left.image_size, CV_8UC3), right = left.clone();
    for (int k = 0; k < 10; ++k) {  // noise does not compress: far more than 16 KiB of video
      rng.fill(left, cv::RNG::UNIFORM, 0, 255);
      rng.fill(right, cv::RNG::UNIFORM, 0, 255);
      w.write(0.1 * k, left, right);
    }
    error = errorOf([&] { w.finish(); });
    ASSERT_EQ(setrlimit(RLIMIT_FSIZE, &old), 0);
  }
  std::signal(SIGXFSZ, old_handler);
  EXPECT_THAT(error, AllOf(HasSubstr(dir_ / "limited/left."), HasSubstr("10 pairs were written")));
  EXPECT_FALSE(fs::exists(dir_ / "limited/session.yaml"));  // an unfinished folder is refused by the reader
  // Small text files: the same limit, one byte.
  ASSERT_EQ(getrlimit(RLIMIT_FSIZE, &old), 0);
  std::signal(SIGXFSZ, SIG_IGN);
  struct rlimit one = old;
  one.rlim_cur = 1;
  ASSERT_EQ(setrlimit(RLIMIT_FSIZE, &one), 0);
  const std::string text_error = errorOf([&] { saveObjectMap(dir_ / "objects.yaml", info.objects); });
  ASSERT_EQ(setrlimit(RLIMIT_FSIZE, &old), 0);
  std::signal(SIGXFSZ, old_handler);
  EXPECT_THAT(text_error, AllOf(HasSubstr(dir_ / "objects.yaml"), HasSubstr("File too large")));
}

// Item 14: reflex_make_session and reflex_vision_record name the file they could not write (exit
// non-zero; both exited 0 with broken videos before). `ulimit -f` + an ignored SIGXFSZ (inherited
// through exec) stand in for a full disk.
TEST_F(BadInput, SessionToolsNameTheFileTheyCouldNotWrite) {
  writeText(dir_ / "scene.yaml", nearScript(1.0));
  const auto limited = [&](const std::string& cmd) {
    const std::string sh = "ulimit -f 32; trap '' XFSZ; exec " + cmd + " > " + (dir_ / "out.txt") + " 2>&1";
    const int rc = std::system(("bash -c \"" + sh + "\"").c_str());
    return WIFEXITED(rc) ? WEXITSTATUS(rc) : -1;
  };
  EXPECT_EQ(
      limited(bin("reflex_make_session") + " --quiet --script " + (dir_ / "scene.yaml") + " --out " + (dir_ / "made")),
      2);
  EXPECT_THAT(readText(dir_ / "out.txt"), HasSubstr(dir_ / "made/"));
  const std::string& s = *base_ / "mp4";
  EXPECT_EQ(limited(bin("reflex_vision_record") + " --quiet --camera-left " + s + "/left.mp4 --camera-right " + s +
                    "/right.mp4 --calib-left " + s + "/left.yaml --calib-right " + s + "/right.yaml --objects " + s +
                    "/objects.yaml --out " + (dir_ / "recorded")),
            4);
  EXPECT_THAT(readText(dir_ / "out.txt"), AllOf(HasSubstr(dir_ / "recorded/"), HasSubstr("pairs were written")));
  // Missing parent folder: refused before recording or rendering anything.
  EXPECT_EQ(limited(bin("reflex_make_session") + " --quiet --script " + (dir_ / "scene.yaml") + " --out " +
                    (dir_ / "no/such/made")),
            2);
  EXPECT_THAT(readText(dir_ / "out.txt"), HasSubstr("folder '" + (dir_ / "no/such") + "' does not exist"));
}
