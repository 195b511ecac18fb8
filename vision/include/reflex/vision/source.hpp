#pragma once
// Stereo frame sources: a recorded session, or live cameras (two devices, or one side-by-side
// device) through OpenCV's VideoCapture. A capture spec is a device index ("0") or anything
// VideoCapture opens (a video file, a URL) -- which is also how tests feed a fake camera.
#include "reflex/vision/calibration.hpp"
#include "reflex/vision/session.hpp"

#include <opencv2/videoio.hpp>

#include <atomic>
#include <chrono>
#include <functional>
#include <memory>
#include <string>

namespace reflex::vision {

class StereoSource {
 public:
  virtual ~StereoSource() = default;
  /// Next pair; never throws (see ReadStatus).
  virtual ReadStatus next(StereoFrame& frame, std::string& message) = 0;
  /// Goes back to the first frame (after the start offset); false if the source cannot (live).
  virtual bool restart() = 0;
  virtual bool live() const = 0;
  /// Frames in one pass, or -1 if unknown (live).
  virtual int frameCount() const = 0;
  /// Stamp of the first frame of a pass and the nominal frame period, seconds (session clock).
  virtual double firstStamp() const = 0;
  virtual double framePeriod() const = 0;
  /// Frames of the whole recording (a session: before the start offset too), -1 if unknown (live).
  /// Frame indices (StereoFrame::index) count from the recording's first frame: always < this.
  virtual int recordingFrames() const { return frameCount(); }
  /// Stamp of the recording's first frame, seconds (session clock): "session time" is the stamp
  /// minus this (a session: the start offset included).
  virtual double recordingStart() const { return firstStamp(); }
  virtual const StereoCalibration& calibration() const = 0;
  /// The run's stop flag: loops inside the source (skipping to the start offset on a restart) end
  /// early once it is true. runVision sets it; `stop` must outlive the source's use.
  virtual void watchStop(const std::atomic<bool>* stop) { (void)stop; }
};

/// A recorded session, from `start` seconds after its first frame.
class SessionSource : public StereoSource {
 public:
  /// Throws VisionError for a bad session or a start offset outside [0, session length).
  SessionSource(const std::string& dir, double start);
  ReadStatus next(StereoFrame& frame, std::string& message) override;
  bool restart() override;
  bool live() const override { return false; }
  int frameCount() const override { return reader_.info().frameCount() - first_; }
  double firstStamp() const override { return reader_.info().stamps[static_cast<std::size_t>(first_)]; }
  double framePeriod() const override { return 1.0 / reader_.info().fps; }
  int recordingFrames() const override { return reader_.info().frameCount(); }
  double recordingStart() const override { return reader_.info().stamps.front(); }
  const StereoCalibration& calibration() const override { return reader_.info().calibration; }
  const SessionInfo& info() const { return reader_.info(); }
  void watchStop(const std::atomic<bool>* stop) override { stop_ = stop; }

 private:
  SessionReader reader_;
  int first_ = 0;
  const std::atomic<bool>* stop_ = nullptr;
};

/// True if a capture spec names a device index ("0", "1", ...) rather than a file or URL.
bool isDeviceSpec(const std::string& spec);
/// Opens a capture spec: an integer is a device index (V4L2), anything else a file or URL.
/// Throws VisionError naming the spec if it cannot be opened.
std::unique_ptr<cv::VideoCapture> openCapture(const std::string& spec);

/// Live stereo cameras. Stamps are UNIX time (system clock) taken right after both grab() calls.
/// A camera that stops delivering frames ends the stream with a message (an error for the caller).
/// A video file standing in for a camera (a capture that reports a frame count > 0; devices and live
/// streams report none) ends normally (kEnd, empty message) once it has delivered that many frames;
/// ending earlier is still an error (a truncated file).
class CameraSource : public StereoSource {
 public:
  static constexpr double kMinPaceFps = 0.1;
  /// Two captures (left, right), or right == nullptr with side_by_side: the left half of each
  /// frame is the left image. pace_fps > 0 throttles reading to that rate (used when a file stands
  /// in for a camera, which would otherwise be read as fast as it decodes); it must be 0 or in
  /// [kMinPaceFps, kMaxSessionFps] (a file claiming 1e-6 fps would wait days per frame): VisionError.
  CameraSource(std::unique_ptr<cv::VideoCapture> left, std::unique_ptr<cv::VideoCapture> right,
               const StereoCalibration& calibration, double pace_fps);
  ReadStatus next(StereoFrame& frame, std::string& message) override;
  bool restart() override { return false; }
  bool live() const override { return true; }
  int frameCount() const override { return -1; }
  double firstStamp() const override { return first_stamp_; }
  double framePeriod() const override { return period_; }
  const StereoCalibration& calibration() const override { return calibration_; }
  void watchStop(const std::atomic<bool>* stop) override { stop_ = stop; }

 private:
  std::unique_ptr<cv::VideoCapture> cap_[2];
  long file_frames_[2] = {0, 0};  ///< frame count of a stand-in video file, 0 for a device or stream
  long grabbed_[2] = {0, 0};      ///< frames grabbed so far from each capture
  const std::atomic<bool>* stop_ = nullptr;
  StereoCalibration calibration_;
  double period_ = 0.1;
  double pace_ = 0.0;
  double first_stamp_ = 0.0;
  int index_ = 0;
  int failures_ = 0;
  cv::Mat sbs_;
  std::chrono::steady_clock::time_point next_due_{};
};

struct RecordOptions {
  int max_frames = 0;     ///< stop after this many recorded pairs (0 = no limit)
  double duration = 0.0;  ///< stop after this many seconds since the first pair (0 = no limit)
};

struct RecordStats {
  int recorded = 0;
  int skipped = 0;
  std::string end_message;  ///< why the source stopped, if it did
};

/// Copies pairs from a (live) source into a session writer until a limit, the end of the source, or
/// `stop`. Skipped frames are reported through on_skip and not written. Never throws for bad frames.
/// A pair more than kMaxFrameGap after the previous one (a camera that stalled) ends the recording
/// with end_message saying so: a session never holds a gap its reader would refuse.
RecordStats recordSession(StereoSource& source, SessionWriter& writer, const RecordOptions& options,
                          const std::atomic<bool>& stop,
                          const std::function<void(int frame, const std::string& why)>& on_skip = {},
                          const std::function<void(int recorded, double seconds)>& on_progress = {});

}  // namespace reflex::vision
