#pragma once
// A recorded stereo session is a folder (see vision/README.md, "Session folder format"):
//
//   session.yaml       manifest: format, version, name, fps, frames, file names (optional; defaults below)
//   left.mp4 right.mp4 left/right videos, any codec OpenCV's FFmpeg backend reads
//   timestamps.csv     frame,stamp  (capture time of each stereo pair, seconds, strictly increasing)
//   left.yaml right.yaml   ROS camera_info calibration of each camera
//   objects.yaml       tag id -> object name, tag size
//   camera_mount.yaml  optional: left optical frame in the robot base frame during the recording
//   ground_truth.csv   optional: stamp,frame,object,tag_id,x,y,z,x_cam,y_cam,z_cam,visible,present
//
// SessionReader validates the folder when opened (VisionError naming the missing or bad file);
// reading frames never throws: a truncated or corrupt video ends the stream with a message.
#include "reflex/vision/calibration.hpp"
#include "reflex/vision/object_map.hpp"

#include <opencv2/core.hpp>
#include <opencv2/videoio.hpp>

#include <atomic>
#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace reflex::vision {

/// Limits on capture stamps (seconds), checked when a session is opened (loadTimestamps) and when
/// one is written (SessionWriter::write). A replay clock subtracts stamps and steps by fractions of
/// a frame period, which needs a double that still resolves microseconds: |stamp| <= 1e10 s (UNIX
/// time up to the year 2286) resolves 2 us, while near 1e17 s a double moves in steps of 16 s and a
/// schedule that adds 0.1 s never advances (`--dump` spun forever).
inline constexpr double kMaxSessionStamp = 1e10;
/// Largest gap between consecutive stamps of a session, seconds. A longer gap is not one recording
/// (a paced replay would wait through it in silence); such a session is refused at load, naming the
/// line and the gap. The recorder ends a recording at such a gap instead of writing it.
inline constexpr double kMaxFrameGap = 10.0;
/// Nominal frame rate range (session.yaml `fps`), frames per second.
inline constexpr double kMaxSessionFps = 1000.0;

/// One stereo pair. stamp: capture time in seconds (session clock: 0-based for synthetic sessions,
/// UNIX time for live recordings).
struct StereoFrame {
  int index = -1;
  double stamp = 0.0;
  cv::Mat left, right;
};

struct SessionFiles {
  std::string left_video = "left.mp4";
  std::string right_video = "right.mp4";
  std::string timestamps = "timestamps.csv";
  std::string left_calibration = "left.yaml";
  std::string right_calibration = "right.yaml";
  std::string objects = "objects.yaml";
  std::string camera_mount;  ///< empty if none
  std::string ground_truth;  ///< empty if none
};

struct SessionInfo {
  std::string dir;
  std::string name;
  double fps = 0.0;  ///< nominal frame rate
  SessionFiles files;
  std::vector<double> stamps;  ///< one per frame, strictly increasing
  StereoCalibration calibration;
  ObjectMap objects;
  std::optional<CameraMount> mount;
  std::string path(const std::string& file) const { return dir + "/" + file; }
  int frameCount() const { return static_cast<int>(stamps.size()); }
};

/// Reads and validates everything but the video contents. Throws VisionError naming the file.
SessionInfo loadSessionInfo(const std::string& dir);

/// Parses timestamps.csv (header "frame,stamp"); frames must be 0..N-1, stamps strictly increasing,
/// |stamp| <= kMaxSessionStamp and consecutive stamps at most kMaxFrameGap apart (VisionError
/// naming the file, line and value otherwise).
std::vector<double> loadTimestamps(const std::string& path);

/// One row of ground_truth.csv. visible: tag fully visible in both images (inside the image, facing
/// the camera, not occluded, not hidden, not a drop-out frame). present: not hidden and not a
/// drop-out frame (a detection of a present object is legitimate even if partially occluded).
struct GroundTruthRow {
  double stamp = 0.0;
  int frame = 0;
  std::string object;
  int tag_id = -1;
  cv::Vec3d p_B;  ///< robot base frame, metres
  cv::Vec3d p_C;  ///< left optical frame, metres
  bool visible = false;
  bool present = false;
};
std::vector<GroundTruthRow> loadGroundTruth(const std::string& path);
void saveGroundTruth(const std::string& path, const std::vector<GroundTruthRow>& rows);

enum class ReadStatus {
  kOk,       ///< frame filled
  kSkipped,  ///< this frame is unusable (message says why); reading may continue
  kEnd,      ///< no more frames; message is empty at a normal end, else why the stream stopped early
};

class SessionReader {
 public:
  /// Opens and validates the session (VisionError naming the file for a missing file, a video that
  /// cannot be opened, left/right frame counts or sizes that differ from each other, from the
  /// timestamps or from the calibration; left and right videos that show the same images, see
  /// kSameImagesMeanAbsDiff, or that look swapped: the first pairs with content, rectified, are
  /// shifted the wrong way, a negative dominant disparity that no correct pair has).
  explicit SessionReader(const std::string& dir);
  /// Left and right images whose mean absolute grey difference is below this (grey levels, 0..255)
  /// are "the same image" (the same video twice differs only by compression noise; two cameras
  /// differ by parallax and sensor noise, several grey levels).
  static constexpr double kSameImagesMeanAbsDiff = 1.0;

  const SessionInfo& info() const { return info_; }
  /// Next frame. Never throws.
  ReadStatus read(StereoFrame& frame, std::string& message);
  /// Restarts at frame `first` (0-based, clamped to the session), decoding and dropping earlier frames;
  /// stops early (at a frame before `first`) when *stop becomes true.
  void restart(int first, const std::atomic<bool>* stop = nullptr);
  /// Index of the next frame read() returns.
  int position() const { return next_; }

 private:
  void open();
  void checkLeftAndRightDiffer();
  SessionInfo info_;
  cv::VideoCapture cap_[2];
  int next_ = 0;
};

/// The pseudo-FourCC of SessionWriterOptions::codecs for H.264 at a chosen quality: the `ffmpeg` program
/// (libx264, constant rate factor SessionWriterOptions::crf) encodes the frames the writer pipes to it.
/// OpenCV's own H.264 writer ("avc1") has no quality setting (x264's default CRF 23).
inline constexpr const char* kX264Codec = "x264";

struct SessionWriterOptions {
  std::string name = "session";
  double fps = 10.0;
  /// FourCC and container tried in order until one opens (H.264 in MP4, then MPEG-4 part 2, MJPEG in AVI;
  /// kX264Codec: H.264 by ffmpeg at `crf`, opened when the ffmpeg program is found).
  std::vector<std::pair<std::string, std::string>> codecs = {{"avc1", "mp4"}, {"mp4v", "mp4"}, {"MJPG", "avi"}};
  /// kX264Codec's constant rate factor, 0..51: lower is better and larger (18 is visually lossless;
  /// 23 is x264's default; each +6 about halves the size).
  int crf = 18;
};

/// Why `dir` cannot be written as a session folder, or "" if it can: the folder is missing (its parent
/// exists) or a folder, and every file a session writer or generator may write in it (videos in each
/// container of SessionWriterOptions, timestamps.csv, session.yaml, calibrations, object map, mount,
/// ground truth) is missing or a regular file: a device, a FIFO or a folder in its place is refused,
/// naming it. The tools call it before any work; the writer again.
std::string sessionFolderProblem(const std::string& dir);

/// Writes a session folder. The constructor creates the folder (its parent folder must exist: a
/// missing one is an error at the start, naming it) and writes the calibration, object map and
/// mount; write() appends one pair; finish() writes timestamps.csv and session.yaml and checks the
/// videos hold every written pair. Every file written is checked (write and close): a failure
/// throws VisionError naming the file and the cause (e.g. "No space left on device").
class SessionWriter {
 public:
  SessionWriter(const std::string& dir, const StereoCalibration& calibration, const ObjectMap& objects,
                const std::optional<CameraMount>& mount, const SessionWriterOptions& options);
  ~SessionWriter();
  SessionWriter(const SessionWriter&) = delete;
  SessionWriter& operator=(const SessionWriter&) = delete;

  /// Appends a pair (8-bit BGR or gray, the calibration's size). Throws VisionError on a wrong size,
  /// a stamp not after the previous one, |stamp| > kMaxSessionStamp or a gap > kMaxFrameGap.
  void write(double stamp, const cv::Mat& left, const cv::Mat& right);
  /// Finishes the folder; ground_truth_file (already written into the folder) is listed if non-empty.
  /// Throws VisionError naming the file if a file could not be written or a video holds fewer
  /// frames than were written (disk full, write error).
  void finish(const std::string& ground_truth_file = "");
  /// Stops without finishing (after an error part-way): the videos are closed, and neither
  /// timestamps.csv nor session.yaml is written, so no reader takes the folder for a session.
  void abandon();
  int frames() const { return static_cast<int>(stamps_.size()); }
  const std::string& codec() const { return codec_; }

 private:
  std::string dir_;
  SessionWriterOptions options_;
  cv::Size size_;
  SessionFiles files_;
  cv::VideoWriter writer_[2];
  class FfmpegPipe;
  std::unique_ptr<FfmpegPipe> pipe_[2];  ///< kX264Codec: the ffmpeg processes (else empty)
  std::string codec_;
  std::vector<double> stamps_;
  bool finished_ = false;
};

}  // namespace reflex::vision
