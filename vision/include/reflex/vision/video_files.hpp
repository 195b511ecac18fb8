#pragma once
// Offline import of recorded stereo video into a session folder (reflex_vision_record --from-files /
// --from-side-by-side): two video files (left, right) or one side-by-side file (left half = left
// image, right half = right image), decoded and written through SessionWriter as fast as the machine
// allows (no pacing, unlike a video file standing in for a live camera).
//
// Capture stamps (seconds, the session clock) come from one of:
//   - a timestamps CSV in the session format ("frame,stamp", frames 0..N-1, stamps strictly
//     increasing, see loadTimestamps), one row per video frame;
//   - a frame rate F: stamp i = i / F (0-based);
//   - neither: the video container's own frame rate, as F.
//
// Everything that can be checked before decoding is checked when the reader is built (VisionError
// naming the file and the value): a missing or unreadable file, left/right sizes or frame counts
// that differ, an odd side-by-side width, images of another size than the calibration, a timestamps
// CSV listing another number of frames than the video, a frame rate <= 0, NaN or out of range, and
// no frame rate at all. Containers without an exact frame count are checked while decoding: one
// video ending before the other, or the video and the CSV disagreeing, is a VisionError naming the
// frame.
#include "reflex/vision/session.hpp"

#include <opencv2/videoio.hpp>

#include <atomic>
#include <functional>
#include <string>
#include <vector>

namespace reflex::vision {

struct VideoFilesSpec {
  std::string left;        ///< left video, or the side-by-side video
  std::string right;       ///< right video; empty for a side-by-side video
  std::string timestamps;  ///< timestamps CSV, or empty
  double fps = 0.0;        ///< > 0: stamp i = i / fps; 0: unset (the CSV's stamps or the video's rate)
  bool side_by_side() const { return right.empty(); }
};

/// Lowest frame rate a stamp sequence i / fps may have: consecutive stamps at most kMaxFrameGap apart.
inline constexpr double kMinImportFps = 1.0 / kMaxFrameGap;

class VideoFilesReader {
 public:
  /// Opens and checks the files (see the header comment); `image_size` is the calibration's, which
  /// every image must have. Throws VisionError naming the file and value.
  VideoFilesReader(const VideoFilesSpec& spec, cv::Size image_size);
  /// Frames to import (the CSV's rows, else the container's count), or -1 if not known before decoding.
  int frameCount() const { return frames_; }
  /// Nominal frame rate for session.yaml: the given fps, else the video's, else derived from the stamps.
  double nominalFps() const { return nominal_fps_; }
  /// Fills the next pair (index, stamp, left, right); false at the normal end of the videos. Throws
  /// VisionError naming the file and frame if one video ends before the other, the video and the
  /// timestamps CSV disagree in length, or a frame cannot be split or has another size.
  bool next(StereoFrame& frame);

 private:
  VideoFilesSpec spec_;
  cv::Size size_;
  cv::VideoCapture cap_[2];
  std::vector<double> stamps_;  ///< from the CSV; empty: i / fps_
  double fps_ = 0.0;            ///< rate of the generated stamps
  double nominal_fps_ = 0.0;
  int frames_ = -1;
  int next_ = 0;
  cv::Mat sbs_;
};

struct ImportStats {
  int frames = 0;            ///< pairs written
  double first_stamp = 0.0;  ///< seconds, session clock
  double last_stamp = 0.0;
  double wall_seconds = 0.0;  ///< time the import took
  bool stopped = false;       ///< ended by the stop flag before the end of the videos
};

/// Copies every pair of `reader` into `writer` (which the caller finishes) until the end of the videos
/// or `stop`. on_progress(done, total) after each pair (total -1 if unknown). Throws VisionError from
/// the reader or the writer (the caller then abandons the folder).
ImportStats importVideoFiles(VideoFilesReader& reader, SessionWriter& writer, const std::atomic<bool>& stop,
                             const std::function<void(int done, int total)>& on_progress = {});

}  // namespace reflex::vision
