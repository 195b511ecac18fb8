#include "reflex/vision/session.hpp"

#include "reflex/common/files.hpp"
#include "reflex/vision/output_file.hpp"
#include "reflex/vision/stereo_pipeline.hpp"
#include "yaml_util.hpp"

#include <opencv2/imgproc.hpp>

#include <fcntl.h>
#include <spawn.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <csignal>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <limits>
#include <sstream>

extern char** environ;

namespace fs = std::filesystem;

namespace reflex::vision {
namespace {
using namespace detail;

std::vector<std::string> splitCsv(const std::string& line) {
  std::vector<std::string> out;
  std::string cur;
  for (char c : line) {
    if (c == ',') {
      out.push_back(cur);
      cur.clear();
    } else if (c != '\r') {
      cur += c;
    }
  }
  out.push_back(cur);
  return out;
}

double parseDouble(const std::string& s, const std::string& where) {
  try {
    std::size_t used = 0;
    const double v = std::stod(s, &used);
    if (used != s.size() || !std::isfinite(v)) throw std::invalid_argument(s);
    return v;
  } catch (const std::exception&) {
    throw VisionError(where + ": '" + s + "' is not a number");
  }
}

int parseInt(const std::string& s, const std::string& where) {
  try {
    std::size_t used = 0;
    const int v = std::stoi(s, &used);
    if (used != s.size()) throw std::invalid_argument(s);
    return v;
  } catch (const std::exception&) {
    throw VisionError(where + ": '" + s + "' is not an integer");
  }
}

void requireFile(const std::string& dir, const std::string& file, const std::string& what) {
  const std::string p = dir + "/" + file;
  std::error_code ec;  // a path the system refuses (too long, no permission) is "missing" too
  if (!fs::is_regular_file(p, ec))
    throw VisionError("session '" + dir + "' is missing its " + what + " file '" + file + "'");
}

}  // namespace

std::vector<double> loadTimestamps(const std::string& path) {
  if (const std::string why = common::inputFileProblem(path); !why.empty())
    throw VisionError("timestamps file " + why);  // a FIFO or device would block or never end
  std::ifstream in(path);
  if (!in) throw VisionError("cannot open timestamps file '" + path + "'");
  std::string line;
  if (!std::getline(in, line)) throw VisionError(path + ": empty file (expected header 'frame,stamp')");
  if (splitCsv(line).size() < 2 || splitCsv(line)[0] != "frame" || splitCsv(line)[1] != "stamp")
    throw VisionError(path + ": line 1: expected header 'frame,stamp', got '" + line + "'");
  std::vector<double> stamps;
  int lineno = 1;
  while (std::getline(in, line)) {
    ++lineno;
    if (line.empty() || line == "\r") continue;
    const std::string where = path + ": line " + std::to_string(lineno);
    const std::vector<std::string> f = splitCsv(line);
    if (f.size() < 2) throw VisionError(where + ": expected 'frame,stamp', got '" + line + "'");
    const int frame = parseInt(f[0], where + " frame");
    const double stamp = parseDouble(f[1], where + " stamp");
    if (frame != static_cast<int>(stamps.size()))
      throw VisionError(where + ": frame " + std::to_string(frame) + " out of order (expected " +
                        std::to_string(stamps.size()) + ")");
    if (!(std::abs(stamp) <= kMaxSessionStamp))
      throw VisionError(where + ": stamp " + fmt(stamp) + " s is outside +-" + fmt(kMaxSessionStamp) +
                        " s (a double no longer resolves microseconds there; UNIX time or 0-based seconds expected)");
    if (!stamps.empty() && !(stamp > stamps.back()))
      throw VisionError(where + ": stamp " + fmt(stamp) + " is not after the previous " + fmt(stamps.back()));
    if (!stamps.empty() && stamp - stamps.back() > kMaxFrameGap)
      throw VisionError(where + ": stamp " + fmt(stamp) + " is " + fmt(stamp - stamps.back()) +
                        " s after the previous " + fmt(stamps.back()) + " (more than the " + fmt(kMaxFrameGap) +
                        " s a session may skip; split the recording there)");
    stamps.push_back(stamp);
  }
  if (stamps.empty()) throw VisionError(path + ": no frames");
  return stamps;
}

std::vector<GroundTruthRow> loadGroundTruth(const std::string& path) {
  if (const std::string why = common::inputFileProblem(path); !why.empty())
    throw VisionError("ground truth file " + why);  // a FIFO or device would block or never end
  std::ifstream in(path);
  if (!in) throw VisionError("cannot open ground truth file '" + path + "'");
  std::string line;
  std::getline(in, line);
  const std::string header = "stamp,frame,object,tag_id,x,y,z,x_cam,y_cam,z_cam,visible,present";
  if (line.rfind(header, 0) != 0) throw VisionError(path + ": line 1: expected header '" + header + "'");
  std::vector<GroundTruthRow> rows;
  int lineno = 1;
  while (std::getline(in, line)) {
    ++lineno;
    if (line.empty()) continue;
    const std::string where = path + ": line " + std::to_string(lineno);
    const std::vector<std::string> f = splitCsv(line);
    if (f.size() < 12) throw VisionError(where + ": expected 12 fields, got " + std::to_string(f.size()));
    GroundTruthRow r;
    r.stamp = parseDouble(f[0], where);
    r.frame = parseInt(f[1], where);
    r.object = f[2];
    r.tag_id = parseInt(f[3], where);
    for (int k = 0; k < 3; ++k) {
      r.p_B[k] = parseDouble(f[static_cast<std::size_t>(4 + k)], where);
      r.p_C[k] = parseDouble(f[static_cast<std::size_t>(7 + k)], where);
    }
    r.visible = parseInt(f[10], where) != 0;
    r.present = parseInt(f[11], where) != 0;
    rows.push_back(r);
  }
  return rows;
}

void saveGroundTruth(const std::string& path, const std::vector<GroundTruthRow>& rows) {
  std::ostringstream os;
  os << "stamp,frame,object,tag_id,x,y,z,x_cam,y_cam,z_cam,visible,present\n" << std::fixed;
  for (const GroundTruthRow& r : rows) {
    os << std::setprecision(6) << r.stamp << ',' << r.frame << ',' << r.object << ',' << r.tag_id
       << std::setprecision(6);
    for (int k = 0; k < 3; ++k) os << ',' << r.p_B[k];
    for (int k = 0; k < 3; ++k) os << ',' << r.p_C[k];
    os << ',' << (r.visible ? 1 : 0) << ',' << (r.present ? 1 : 0) << '\n';
  }
  writeTextFile(path, os.str(), "ground truth file");
}

SessionInfo loadSessionInfo(const std::string& dir) {
  std::error_code ec;
  if (!fs::is_directory(dir, ec)) throw VisionError("session folder '" + dir + "' does not exist");
  const std::string manifest = dir + "/session.yaml";
  SessionInfo info;
  int manifest_frames = -1;  // session.yaml "frames", -1 if absent
  info.dir = dir;
  info.name = fs::path(dir).filename().string();
  if (fs::exists(manifest, ec)) {
    const ConfigNode root = parseYaml(readTextFile(manifest, "session manifest"), manifest);
    if (root.has("format") && root.string("format", "") != "reflex_stereo_session")
      root.fail("format", "not a stereo session", "reflex_stereo_session");
    if (root.integer("version", 1, std::numeric_limits<int>::min(), std::numeric_limits<int>::max()) != 1)
      root.fail("version", "not supported", "1");
    info.name = root.string("name", info.name);
    if (root.has("fps")) {
      info.fps = root.number("fps", info.fps, -kAnyNumber, kAnyNumber, "Hz");
      if (!(info.fps > 0.0) || info.fps > kMaxSessionFps)
        root.fail("fps", "out of range", "(0, " + fmt(kMaxSessionFps) + "] Hz");
    }
    if (root.has("frames")) manifest_frames = root.integer("frames", -1, 1, std::numeric_limits<int>::max());
    auto file = [&](const char* key, std::string& field) { field = root.string(key, field); };
    file("left_video", info.files.left_video);
    file("right_video", info.files.right_video);
    file("timestamps", info.files.timestamps);
    file("left_calibration", info.files.left_calibration);
    file("right_calibration", info.files.right_calibration);
    file("objects", info.files.objects);
    file("camera_mount", info.files.camera_mount);
    file("ground_truth", info.files.ground_truth);
  } else if (fs::exists(dir + "/camera_mount.yaml", ec)) {
    info.files.camera_mount = "camera_mount.yaml";
  }
  const SessionFiles& f = info.files;
  requireFile(dir, f.left_video, "left video");
  requireFile(dir, f.right_video, "right video");
  requireFile(dir, f.timestamps, "timestamps");
  requireFile(dir, f.left_calibration, "left calibration");
  requireFile(dir, f.right_calibration, "right calibration");
  requireFile(dir, f.objects, "object map");
  if (!f.camera_mount.empty()) requireFile(dir, f.camera_mount, "camera mount");
  if (!f.ground_truth.empty()) requireFile(dir, f.ground_truth, "ground truth");

  // The same video file named twice can never give a disparity (left and right images identical).
  if (fs::equivalent(info.path(f.left_video), info.path(f.right_video), ec))
    throw VisionError("session '" + dir + "': left video '" + f.left_video + "' and right video '" + f.right_video +
                      "' are the same file (the same video twice cannot give any stereo detection)");
  info.stamps = loadTimestamps(info.path(f.timestamps));
  if (manifest_frames >= 0 && manifest_frames != info.frameCount())
    throw VisionError(manifest + ": frames = " + std::to_string(manifest_frames) + " but '" + f.timestamps +
                      "' lists " + std::to_string(info.frameCount()));
  info.calibration = loadStereoCalibration(info.path(f.left_calibration), info.path(f.right_calibration));
  info.objects = loadObjectMap(info.path(f.objects));
  if (!f.camera_mount.empty()) info.mount = loadCameraMount(info.path(f.camera_mount));
  if (info.fps <= 0.0) {
    const double span = info.stamps.back() - info.stamps.front();
    info.fps = info.stamps.size() > 1 && span > 0.0 ? (info.stamps.size() - 1) / span : 10.0;
  }
  return info;
}

SessionReader::SessionReader(const std::string& dir) : info_(loadSessionInfo(dir)) {
  open();
  checkLeftAndRightDiffer();
}

void SessionReader::checkLeftAndRightDiffer() {
  // The first pairs with content (a blank drop-out frame proves nothing):
  //  - identical images (up to compression noise) in every compared pair: the same video was given
  //    twice (under two names), and no tag can ever have a disparity;
  //  - a dominant horizontal shift between the rectified images pointing the wrong way: in a
  //    correct rig every point in front of the cameras has a disparity u_L - u_R >= 0, so a clearly
  //    negative one in every compared pair means the videos are swapped (the right camera's video
  //    given as the left one). The shift is the phase-correlation peak of the rectified images.
  constexpr int kPairs = 5;
  constexpr double kMinContentStdDev = 2.0;  // grey levels
  constexpr double kSwapDisparityPx = -1.0;  // dominant disparity below this: the pair looks swapped
  constexpr double kMinPeakResponse = 0.02;  // phase-correlation peak strength to believe the shift
  int identical = 0, compared = 0, swapped = 0, straight = 0;
  double largest_diff = 0.0, swapped_disparity = 0.0;
  const StereoRectifier rectifier(info_.calibration);
  cv::Mat raw[2], grey[2], rect[2], rect_f[2], window;
  for (int i = 0; i < std::min(kPairs, info_.frameCount()); ++i) {
    if (!cap_[0].read(raw[0]) || !cap_[1].read(raw[1]) || raw[0].empty() || raw[1].empty() ||
        raw[0].size() != raw[1].size() || raw[0].size() != info_.calibration.left.image_size)
      break;  // reading problems are reported by read(), frame by frame
    for (int k = 0; k < 2; ++k) {
      if (raw[k].channels() == 1)
        grey[k] = raw[k];
      else
        cv::cvtColor(raw[k], grey[k], raw[k].channels() == 4 ? cv::COLOR_BGRA2GRAY : cv::COLOR_BGR2GRAY);
    }
    cv::Scalar mean, stddev;
    cv::meanStdDev(grey[0], mean, stddev);
    if (stddev[0] < kMinContentStdDev) continue;
    ++compared;
    const double diff = cv::norm(grey[0], grey[1], cv::NORM_L1) / static_cast<double>(grey[0].total());
    if (diff < kSameImagesMeanAbsDiff) {
      ++identical;
      largest_diff = std::max(largest_diff, diff);
      continue;
    }
    for (int k = 0; k < 2; ++k) {
      rectifier.rectifyImage(grey[k], rect[k], k == 1);
      rect[k].convertTo(rect_f[k], CV_64F);
    }
    if (window.empty()) cv::createHanningWindow(window, rect_f[0].size(), CV_64F);
    double response = 0.0;
    // phaseCorrelate gives the shift of the second image against the first: u_R - u_L = -disparity.
    const double disparity = -cv::phaseCorrelate(rect_f[0], rect_f[1], window, &response).x;
    if (response < kMinPeakResponse) continue;
    if (disparity < kSwapDisparityPx) {
      ++swapped;
      swapped_disparity = disparity;
    } else {
      ++straight;
    }
  }
  open();  // back to the first frame
  if (compared > 0 && identical == compared)
    throw VisionError("session '" + info_.dir + "': left video '" + info_.files.left_video + "' and right video '" +
                      info_.files.right_video + "' show the same images (mean difference " + fmt(largest_diff) +
                      " grey levels in the first " + std::to_string(identical) +
                      " pair(s) with content): the same video twice cannot give any stereo detection");
  if (swapped > 0 && straight == 0)
    throw VisionError("session '" + info_.dir + "': left video '" + info_.files.left_video + "' and right video '" +
                      info_.files.right_video + "' look swapped: the rectified images are shifted the wrong way (" +
                      "dominant disparity " + fmt(swapped_disparity) + " px, negative, in " + std::to_string(swapped) +
                      " of the first pairs; a correct pair never has a negative one)");
}

void SessionReader::open() {
  const std::string paths[2] = {info_.path(info_.files.left_video), info_.path(info_.files.right_video)};
  double counts[2] = {0.0, 0.0};
  cv::Size sizes[2];
  for (int i = 0; i < 2; ++i) {
    cap_[i].release();
    if (!cap_[i].open(paths[i], cv::CAP_FFMPEG) || !cap_[i].isOpened())
      throw VisionError("cannot open video '" + paths[i] + "' (missing, corrupt or unsupported codec)");
    counts[i] = cap_[i].get(cv::CAP_PROP_FRAME_COUNT);
    sizes[i] = cv::Size(static_cast<int>(cap_[i].get(cv::CAP_PROP_FRAME_WIDTH)),
                        static_cast<int>(cap_[i].get(cv::CAP_PROP_FRAME_HEIGHT)));
  }
  if (sizes[0] != sizes[1])
    throw VisionError("video sizes differ: '" + paths[0] + "' is " + std::to_string(sizes[0].width) + "x" +
                      std::to_string(sizes[0].height) + " but '" + paths[1] + "' is " + std::to_string(sizes[1].width) +
                      "x" + std::to_string(sizes[1].height));
  const cv::Size calib = info_.calibration.left.image_size;
  if (sizes[0] != calib)
    throw VisionError("video '" + paths[0] + "' is " + std::to_string(sizes[0].width) + "x" +
                      std::to_string(sizes[0].height) + " but the calibration '" +
                      info_.path(info_.files.left_calibration) + "' says " + std::to_string(calib.width) + "x" +
                      std::to_string(calib.height));
  // Containers with an index report exact counts; 0 or negative means unknown (checked while reading).
  if (counts[0] > 0 && counts[1] > 0 && std::lround(counts[0]) != std::lround(counts[1]))
    throw VisionError("left and right videos differ in length: '" + paths[0] + "' has " +
                      std::to_string(std::lround(counts[0])) + " frames but '" + paths[1] + "' has " +
                      std::to_string(std::lround(counts[1])));
  if (counts[0] > 0 && std::lround(counts[0]) != info_.frameCount())
    throw VisionError("'" + paths[0] + "' has " + std::to_string(std::lround(counts[0])) + " frames but '" +
                      info_.path(info_.files.timestamps) + "' lists " + std::to_string(info_.frameCount()));
  next_ = 0;
}

void SessionReader::restart(int first, const std::atomic<bool>* stop) {
  open();
  first = std::clamp(first, 0, info_.frameCount());
  for (; next_ < first && !(stop && stop->load()); ++next_) {
    if (!cap_[0].grab() || !cap_[1].grab()) break;
  }
}

ReadStatus SessionReader::read(StereoFrame& frame, std::string& message) {
  message.clear();
  if (next_ >= info_.frameCount()) return ReadStatus::kEnd;
  const bool ok_left = cap_[0].read(frame.left);
  const bool ok_right = cap_[1].read(frame.right);
  const int index = next_++;
  if (!ok_left || !ok_right || frame.left.empty() || frame.right.empty()) {
    const char* which = (!ok_left || frame.left.empty())
                            ? (!ok_right || frame.right.empty() ? "both videos" : "the left video")
                            : "the right video";
    message = std::string(which) + " ended at frame " + std::to_string(index) + " of " +
              std::to_string(info_.frameCount()) + " listed in " + info_.files.timestamps +
              " (truncated or corrupt video)";
    next_ = info_.frameCount();
    return ReadStatus::kEnd;
  }
  frame.index = index;
  frame.stamp = info_.stamps[static_cast<std::size_t>(index)];
  if (frame.left.size() != frame.right.size() || frame.left.size() != info_.calibration.left.image_size) {
    message = "frame " + std::to_string(index) + " has sizes " + std::to_string(frame.left.cols) + "x" +
              std::to_string(frame.left.rows) + " / " + std::to_string(frame.right.cols) + "x" +
              std::to_string(frame.right.rows) + " differing from the calibration";
    return ReadStatus::kSkipped;
  }
  return ReadStatus::kOk;
}

namespace {

/// The ffmpeg program on PATH, or "" if there is none.
std::string findFfmpeg() {
  const char* path = std::getenv("PATH");
  std::stringstream dirs(path != nullptr ? path : "/usr/bin:/bin");
  for (std::string dir; std::getline(dirs, dir, ':');) {
    const std::string candidate = (dir.empty() ? std::string(".") : dir) + "/ffmpeg";
    if (::access(candidate.c_str(), X_OK) == 0) return candidate;
  }
  return "";
}

}  // namespace

/// One ffmpeg process encoding the 8-bit BGR frames it reads on its standard input into an MP4 with
/// libx264 at a constant rate factor. Its input is a socket, not a pipe: a write after ffmpeg died
/// fails with EPIPE (MSG_NOSIGNAL) instead of ending the writer with SIGPIPE. Its messages go to a log
/// file beside the video, quoted when it fails and removed when it succeeds.
class SessionWriter::FfmpegPipe {
 public:
  /// Starts ffmpeg. Throws VisionError naming the cause.
  FfmpegPipe(const std::string& ffmpeg, const std::string& video, cv::Size size, double fps, int crf)
      : video_(video), log_(video + ".ffmpeg.log") {
    int fds[2];
    if (::socketpair(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0, fds) != 0)
      throw VisionError("session writer: socketpair: " + std::string(std::strerror(errno)));
    fd_ = fds[0];
    std::ostringstream rate;
    rate << std::setprecision(17) << fps;
    // yuv420p halves the chroma of pixel pairs: an odd size keeps full chroma (yuv444p) instead of
    // being cropped.
    const bool even = size.width % 2 == 0 && size.height % 2 == 0;
    const std::vector<std::string> args = {ffmpeg,
                                           "-hide_banner",
                                           "-loglevel",
                                           "error",
                                           "-y",
                                           "-f",
                                           "rawvideo",
                                           "-pixel_format",
                                           "bgr24",
                                           "-video_size",
                                           std::to_string(size.width) + "x" + std::to_string(size.height),
                                           "-framerate",
                                           rate.str(),
                                           "-i",
                                           "pipe:0",
                                           "-an",
                                           "-c:v",
                                           "libx264",
                                           "-preset",
                                           "medium",
                                           "-crf",
                                           std::to_string(crf),
                                           "-pix_fmt",
                                           even ? "yuv420p" : "yuv444p",
                                           video};
    std::vector<char*> argv;
    for (const std::string& a : args) argv.push_back(const_cast<char*>(a.c_str()));
    argv.push_back(nullptr);
    posix_spawn_file_actions_t actions;
    posix_spawn_file_actions_init(&actions);
    posix_spawn_file_actions_adddup2(&actions, fds[1], 0);
    posix_spawn_file_actions_addopen(&actions, 1, "/dev/null", O_WRONLY, 0);
    posix_spawn_file_actions_addopen(&actions, 2, log_.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    const int rc = ::posix_spawn(&pid_, ffmpeg.c_str(), &actions, nullptr, argv.data(), environ);
    posix_spawn_file_actions_destroy(&actions);
    ::close(fds[1]);
    if (rc != 0) {
      pid_ = -1;
      ::close(fd_);
      fd_ = -1;
      throw VisionError("session writer: cannot start '" + ffmpeg + "': " + std::strerror(rc));
    }
  }
  ~FfmpegPipe() { kill(); }
  FfmpegPipe(const FfmpegPipe&) = delete;
  FfmpegPipe& operator=(const FfmpegPipe&) = delete;

  /// Sends one frame (8-bit BGR of the size given). Throws VisionError (with ffmpeg's message) if it
  /// cannot be sent.
  void write(const cv::Mat& bgr) {
    const cv::Mat frame = bgr.isContinuous() ? bgr : bgr.clone();
    const char* data = reinterpret_cast<const char*>(frame.data);
    std::size_t left = frame.total() * frame.elemSize();
    while (left > 0) {
      const ssize_t n = ::send(fd_, data, left, MSG_NOSIGNAL);
      if (n < 0 && errno == EINTR) continue;
      if (n <= 0) {
        const std::string why = std::strerror(errno);
        kill();
        throw VisionError("cannot write video '" + video_ + "': ffmpeg stopped reading (" + why + ")" + message());
      }
      data += n;
      left -= static_cast<std::size_t>(n);
    }
  }

  /// Ends the input and waits for ffmpeg. Throws VisionError with its message unless it exited 0.
  void finish() {
    if (pid_ < 0) return;
    ::close(fd_);
    fd_ = -1;
    const int status = reap();
    if (!(WIFEXITED(status) && WEXITSTATUS(status) == 0)) {
      const std::string code = WIFEXITED(status) ? "exit " + std::to_string(WEXITSTATUS(status))
                                                 : "signal " + std::to_string(WTERMSIG(status));
      throw VisionError("cannot write video '" + video_ + "': ffmpeg ended with " + code + message());
    }
    std::error_code ec;
    fs::remove(log_, ec);
  }

  /// Stops ffmpeg without finishing (an abandoned or failed session); the log stays.
  void kill() noexcept {
    if (fd_ >= 0) ::close(fd_);
    fd_ = -1;
    if (pid_ > 0) {
      ::kill(pid_, SIGKILL);
      reap();
    }
    pid_ = -1;
  }

 private:
  /// Waits for ffmpeg to end; its wait status. pid_ is -1 after.
  int reap() noexcept {
    int status = 0;
    while (::waitpid(pid_, &status, 0) < 0 && errno == EINTR) {
    }
    pid_ = -1;
    return status;
  }
  /// ": <ffmpeg's last line> (log: <file>)", or "" when it said nothing.
  std::string message() const {
    std::ifstream in(log_);
    std::string line, last;
    while (std::getline(in, line))
      if (!line.empty()) last = line;
    return last.empty() ? std::string() : ": " + last + " (log: " + log_ + ")";
  }
  std::string video_, log_;
  int fd_ = -1;
  pid_t pid_ = -1;
};

std::string sessionFolderProblem(const std::string& dir) {
  if (std::string why = common::outputFolderProblem(dir); !why.empty()) return why;
  std::error_code ec;
  if (!fs::is_directory(dir, ec)) return "";  // made by the writer: nothing in it yet
  const SessionFiles files;                   // the writer's own names; the optional ones as it writes them
  std::vector<std::string> names = {files.timestamps, files.left_calibration, files.right_calibration, files.objects,
                                    "session.yaml",   "camera_mount.yaml",    "ground_truth.csv"};
  for (const auto& codec : SessionWriterOptions{}.codecs) {
    names.push_back("left." + codec.second);
    names.push_back("right." + codec.second);
  }
  for (const std::string& name : names) {
    if (std::string why = common::regularOutputProblem(dir + "/" + name); !why.empty()) return why;
  }
  return "";
}

SessionWriter::SessionWriter(const std::string& dir, const StereoCalibration& calibration, const ObjectMap& objects,
                             const std::optional<CameraMount>& mount, const SessionWriterOptions& options)
    : dir_(dir), options_(options), size_(calibration.left.image_size) {
  if (const std::string why = sessionFolderProblem(dir); !why.empty()) throw VisionError("session: " + why);
  if (!(options_.fps > 0.0)) throw VisionError("session writer: fps = " + fmt(options_.fps) + " must be positive");
  std::error_code ec;
  // The session folder itself is created; its parent must exist (a mistyped path is an error now,
  // not a tree of folders created somewhere unexpected).
  fs::path folder = fs::path(dir_).lexically_normal();
  if (!folder.has_filename()) folder = folder.parent_path();  // "out/" names the folder "out"
  const fs::path parent = folder.parent_path();
  if (!parent.empty() && !fs::is_directory(parent, ec))
    throw VisionError("cannot create session folder '" + dir_ + "': folder '" + parent.string() + "' does not exist");
  fs::create_directory(dir_, ec);
  if (!fs::is_directory(dir_, ec))
    throw VisionError("cannot create session folder '" + dir_ + "'" + (ec ? ": " + ec.message() : std::string()));
  validateStereoCalibration(calibration, "left calibration", "right calibration");
  saveCameraInfo(dir_ + "/" + files_.left_calibration, calibration.left);
  saveCameraInfo(dir_ + "/" + files_.right_calibration, calibration.right);
  saveObjectMap(dir_ + "/" + files_.objects, objects);
  if (mount) {
    files_.camera_mount = "camera_mount.yaml";
    saveCameraMount(dir_ + "/" + files_.camera_mount, *mount, "camera mount during the recording");
  }
  if (!(options_.crf >= 0 && options_.crf <= 51))
    throw VisionError("session writer: crf " + std::to_string(options_.crf) + " is outside 0..51");
  std::string tried;
  for (const auto& [fourcc, ext] : options_.codecs) {
    if (fourcc.size() != 4) throw VisionError("session writer: codec '" + fourcc + "' is not a FourCC");
    files_.left_video = "left." + ext;
    files_.right_video = "right." + ext;
    if (fourcc == kX264Codec) {  // H.264 by the ffmpeg program, at options_.crf
      const std::string ffmpeg = findFfmpeg();
      if (!ffmpeg.empty()) {
        try {
          pipe_[0] =
              std::make_unique<FfmpegPipe>(ffmpeg, dir_ + "/" + files_.left_video, size_, options_.fps, options_.crf);
          pipe_[1] =
              std::make_unique<FfmpegPipe>(ffmpeg, dir_ + "/" + files_.right_video, size_, options_.fps, options_.crf);
          codec_ = fourcc;
          break;
        } catch (const VisionError&) {
          pipe_[0].reset();
          pipe_[1].reset();
        }
      }
      tried += std::string(tried.empty() ? "" : ", ") + fourcc + "/" + ext +
               (ffmpeg.empty() ? " (no ffmpeg program on PATH)" : " (ffmpeg did not start)");
      continue;
    }
    const int cc = cv::VideoWriter::fourcc(fourcc[0], fourcc[1], fourcc[2], fourcc[3]);
    const bool ok = writer_[0].open(dir_ + "/" + files_.left_video, cv::CAP_FFMPEG, cc, options_.fps, size_, true) &&
                    writer_[1].open(dir_ + "/" + files_.right_video, cv::CAP_FFMPEG, cc, options_.fps, size_, true);
    if (ok) {
      codec_ = fourcc;
      break;
    }
    writer_[0].release();
    writer_[1].release();
    fs::remove(dir_ + "/" + files_.left_video, ec);
    fs::remove(dir_ + "/" + files_.right_video, ec);
    tried += (tried.empty() ? "" : ", ") + fourcc + "/" + ext;
  }
  if (codec_.empty()) throw VisionError("session writer: no video codec could be opened (tried " + tried + ")");
}

SessionWriter::~SessionWriter() {
  if (!finished_) {
    try {
      finish();
    } catch (const std::exception&) {
      // A destructor must not throw; an unfinished folder lacks session.yaml and is refused by the reader.
    }
  }
}

void SessionWriter::write(double stamp, const cv::Mat& left, const cv::Mat& right) {
  if (finished_) throw VisionError("session writer: write after finish");
  const cv::Mat* in[2] = {&left, &right};
  for (int i = 0; i < 2; ++i) {
    if (in[i]->size() != size_ || in[i]->depth() != CV_8U)
      throw VisionError(std::string("session writer: ") + (i ? "right" : "left") + " frame is " +
                        std::to_string(in[i]->cols) + "x" + std::to_string(in[i]->rows) +
                        " (8-bit expected), calibration says " + std::to_string(size_.width) + "x" +
                        std::to_string(size_.height));
  }
  if (!(std::abs(stamp) <= kMaxSessionStamp))
    throw VisionError("session writer: stamp " + fmt(stamp) + " s is outside +-" + fmt(kMaxSessionStamp) + " s");
  if (!stamps_.empty() && !(stamp > stamps_.back()))
    throw VisionError("session writer: stamp " + fmt(stamp) + " is not after the previous " + fmt(stamps_.back()));
  if (!stamps_.empty() && stamp - stamps_.back() > kMaxFrameGap)
    throw VisionError("session writer: stamp " + fmt(stamp) + " is " + fmt(stamp - stamps_.back()) +
                      " s after the previous one (more than " + fmt(kMaxFrameGap) + " s)");
  for (int i = 0; i < 2; ++i) {
    cv::Mat converted;
    if (in[i]->channels() != 3)
      cv::cvtColor(*in[i], converted, in[i]->channels() == 1 ? cv::COLOR_GRAY2BGR : cv::COLOR_BGRA2BGR);
    const cv::Mat& bgr = in[i]->channels() == 3 ? *in[i] : converted;
    if (pipe_[i])
      pipe_[i]->write(bgr);
    else
      writer_[i].write(bgr);
  }
  stamps_.push_back(stamp);
}

void SessionWriter::abandon() {
  finished_ = true;
  for (int i = 0; i < 2; ++i) {
    if (pipe_[i]) pipe_[i]->kill();
    writer_[i].release();
  }
}

void SessionWriter::finish(const std::string& ground_truth_file) {
  if (finished_) return;
  finished_ = true;
  writer_[0].release();
  writer_[1].release();
  for (auto& pipe : pipe_)
    if (pipe) pipe->finish();  // throws naming the video and ffmpeg's message
  files_.ground_truth = ground_truth_file;
  std::error_code ec;
  // cv::VideoWriter reports no write errors: the videos are opened again and must hold every pair.
  for (const std::string& video : {files_.left_video, files_.right_video}) {
    if (stamps_.empty()) break;
    const std::string path = dir_ + "/" + video;
    cv::VideoCapture check;
    const bool opened = check.open(path, cv::CAP_FFMPEG) && check.isOpened();
    const long frames = opened ? std::lround(check.get(cv::CAP_PROP_FRAME_COUNT)) : 0;  // <= 0: unknown
    std::uintmax_t bytes = fs::file_size(path, ec);
    if (ec) bytes = 0;
    if (!opened || (frames > 0 && frames != static_cast<long>(stamps_.size())) || bytes == 0) {
      throw VisionError("cannot write video '" + path + "': it holds " +
                        (opened ? std::to_string(std::max(frames, 0L)) + " frames" : std::string("no readable video")) +
                        " (" + std::to_string(bytes) + " bytes) but " + std::to_string(stamps_.size()) +
                        " pairs were written (disk full or write error?)");
    }
  }
  {
    std::ostringstream ts;
    ts << "frame,stamp\n" << std::fixed << std::setprecision(6);
    for (std::size_t i = 0; i < stamps_.size(); ++i) ts << i << ',' << stamps_[i] << '\n';
    writeTextFile(dir_ + "/" + files_.timestamps, ts.str(), "timestamps file");
  }
  std::ostringstream os;
  os << "# Reflex stereo session (see vision/README.md, \"Session folder format\").\n"
     << "format: reflex_stereo_session\nversion: 1\nname: " << options_.name << "\nfps: " << fmt(options_.fps)
     << "\nframes: " << stamps_.size() << "\ncodec: " << codec_ << "\nleft_video: " << files_.left_video
     << "\nright_video: " << files_.right_video << "\ntimestamps: " << files_.timestamps
     << "\nleft_calibration: " << files_.left_calibration << "\nright_calibration: " << files_.right_calibration
     << "\nobjects: " << files_.objects << "\n";
  if (!files_.camera_mount.empty()) os << "camera_mount: " << files_.camera_mount << "\n";
  if (!files_.ground_truth.empty()) os << "ground_truth: " << files_.ground_truth << "\n";
  writeTextFile(dir_ + "/session.yaml", os.str(), "session manifest");
}

}  // namespace reflex::vision
