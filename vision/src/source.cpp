#include "reflex/vision/source.hpp"

#include "reflex/vision/error.hpp"

#include <algorithm>
#include <cmath>
#include <thread>

namespace reflex::vision {

SessionSource::SessionSource(const std::string& dir, double start) : reader_(dir) {
  const std::vector<double>& s = reader_.info().stamps;
  const double span = s.back() - s.front();
  if (!(start >= 0.0) || start > span)
    throw VisionError("start offset " + std::to_string(start) + " s is outside the session '" + dir + "' (0.." +
                      std::to_string(span) + " s)");
  first_ = static_cast<int>(std::lower_bound(s.begin(), s.end(), s.front() + start - 1e-9) - s.begin());
  reader_.restart(first_);
}

ReadStatus SessionSource::next(StereoFrame& frame, std::string& message) { return reader_.read(frame, message); }

bool SessionSource::restart() {
  try {
    reader_.restart(first_, stop_);
  } catch (const VisionError&) {
    return false;
  }
  return true;
}

bool isDeviceSpec(const std::string& spec) {
  return !spec.empty() && spec.size() < 4 && std::all_of(spec.begin(), spec.end(), ::isdigit);
}

std::unique_ptr<cv::VideoCapture> openCapture(const std::string& spec) {
  auto cap = std::make_unique<cv::VideoCapture>();
  const bool is_index = isDeviceSpec(spec);
  bool ok = false;
  if (is_index)
    ok = cap->open(std::stoi(spec), cv::CAP_V4L2) || cap->open(std::stoi(spec), cv::CAP_ANY);
  else
    ok = cap->open(spec, cv::CAP_FFMPEG) || cap->open(spec, cv::CAP_ANY);
  if (!ok || !cap->isOpened())
    throw VisionError("cannot open camera '" + spec + "'" + (is_index ? " (no such video device?)" : ""));
  return cap;
}

CameraSource::CameraSource(std::unique_ptr<cv::VideoCapture> left, std::unique_ptr<cv::VideoCapture> right,
                           const StereoCalibration& calibration, double pace_fps)
    : calibration_(calibration), pace_(pace_fps) {
  if (!left) throw VisionError("camera source: no left (or side-by-side) capture");
  if (!(pace_ == 0.0 || (pace_ >= kMinPaceFps && pace_ <= kMaxSessionFps)))
    throw VisionError("camera source: frame rate " + std::to_string(pace_) + " fps of the stand-in video is outside [" +
                      std::to_string(kMinPaceFps) + ", " + std::to_string(kMaxSessionFps) + "]");
  cap_[0] = std::move(left);
  cap_[1] = std::move(right);
  for (int k = 0; k < 2; ++k) {
    const double count = cap_[k] ? cap_[k]->get(cv::CAP_PROP_FRAME_COUNT) : 0.0;  // -1 or 0: a device or stream
    file_frames_[k] = std::isfinite(count) && count > 0.0 ? std::lround(count) : 0;
  }
  const double fps = cap_[0]->get(cv::CAP_PROP_FPS);
  period_ = pace_ > 0.0 ? 1.0 / pace_ : (fps > 0.0 && fps < 500.0 ? 1.0 / fps : 1.0 / 30.0);
}

ReadStatus CameraSource::next(StereoFrame& frame, std::string& message) {
  message.clear();
  if (pace_ > 0.0) {
    const auto now = std::chrono::steady_clock::now();
    if (next_due_.time_since_epoch().count() == 0) next_due_ = now;
    // At most 1 / kMinPaceFps = 10 s, slept in 50 ms slices that look at the stop flag.
    while (std::chrono::steady_clock::now() < next_due_ && !(stop_ && stop_->load()))
      std::this_thread::sleep_for(std::min<std::chrono::steady_clock::duration>(
          next_due_ - std::chrono::steady_clock::now(), std::chrono::milliseconds(50)));
    if (stop_ && stop_->load()) {
      message.clear();
      return ReadStatus::kEnd;  // stopped: a normal end
    }
    next_due_ +=
        std::chrono::duration_cast<std::chrono::steady_clock::duration>(std::chrono::duration<double>(1.0 / pace_));
  }
  const bool stereo = static_cast<bool>(cap_[1]);
  const bool grabbed_left = cap_[0]->grab();
  const bool grabbed_right = grabbed_left && stereo && cap_[1]->grab();
  grabbed_[0] += grabbed_left;
  grabbed_[1] += grabbed_right;
  const bool grabbed = grabbed_left && (!stereo || grabbed_right);
  if (!grabbed) {
    // The normal end of a stand-in video file: it delivered every frame its container lists.
    const int which = grabbed_left && stereo ? 1 : 0;
    if (file_frames_[which] > 0 && grabbed_[which] >= file_frames_[which]) {
      message.clear();
      return ReadStatus::kEnd;
    }
  }
  const double stamp = std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch()).count();
  bool ok = grabbed;
  if (ok && stereo) {
    ok = cap_[0]->retrieve(frame.left) && cap_[1]->retrieve(frame.right);
  } else if (ok) {
    ok = cap_[0]->retrieve(sbs_) && !sbs_.empty() && sbs_.cols % 2 == 0;
    if (ok) {
      frame.left = sbs_.colRange(0, sbs_.cols / 2).clone();
      frame.right = sbs_.colRange(sbs_.cols / 2, sbs_.cols).clone();
    }
  }
  if (!ok || frame.left.empty() || frame.right.empty()) {
    // A camera that stops delivering (unplugged; a stand-in file cut short) ends the stream after a
    // few consecutive failures; a single failure is a skipped frame.
    if (++failures_ >= 5 || !grabbed) {
      const int which = grabbed_left && stereo ? 1 : 0;
      message = file_frames_[which] > 0
                    ? std::string(which ? "right" : "left") + " video file ended after " +
                          std::to_string(grabbed_[which]) + " of the " + std::to_string(file_frames_[which]) +
                          " frames it lists (truncated or corrupt file)"
                    : "camera stopped delivering frames after " + std::to_string(index_) + " frames";
      return ReadStatus::kEnd;
    }
    message = "camera frame " + std::to_string(index_) + " could not be retrieved";
    return ReadStatus::kSkipped;
  }
  failures_ = 0;
  if (index_ == 0) first_stamp_ = stamp;
  frame.index = index_++;
  frame.stamp = stamp;
  if (frame.left.size() != frame.right.size() || frame.left.size() != calibration_.left.image_size) {
    message = "camera frame " + std::to_string(frame.index) + " is " + std::to_string(frame.left.cols) + "x" +
              std::to_string(frame.left.rows) + " / " + std::to_string(frame.right.cols) + "x" +
              std::to_string(frame.right.rows) + " but the calibration says " +
              std::to_string(calibration_.left.image_size.width) + "x" +
              std::to_string(calibration_.left.image_size.height);
    return ReadStatus::kSkipped;
  }
  return ReadStatus::kOk;
}

RecordStats recordSession(StereoSource& source, SessionWriter& writer, const RecordOptions& options,
                          const std::atomic<bool>& stop, const std::function<void(int, const std::string&)>& on_skip,
                          const std::function<void(int, double)>& on_progress) {
  source.watchStop(&stop);
  RecordStats stats;
  StereoFrame frame;
  std::string message;
  double first = 0.0, last = 0.0;
  while (!stop.load()) {
    if (options.max_frames > 0 && stats.recorded >= options.max_frames) break;
    const ReadStatus st = source.next(frame, message);
    if (st == ReadStatus::kEnd) {
      stats.end_message = message;
      break;
    }
    if (st == ReadStatus::kSkipped) {
      ++stats.skipped;
      if (on_skip) on_skip(frame.index, message);
      continue;
    }
    if (stats.recorded == 0) first = frame.stamp;
    if (options.duration > 0.0 && frame.stamp - first > options.duration) break;
    if (stats.recorded > 0 && frame.stamp - last > kMaxFrameGap) {
      stats.end_message = "no frame for " + std::to_string(frame.stamp - last) + " s after pair " +
                          std::to_string(stats.recorded - 1) + " (a session may skip at most " +
                          std::to_string(kMaxFrameGap) + " s): the recording ends there";
      break;
    }
    try {
      writer.write(frame.stamp, frame.left, frame.right);
    } catch (const VisionError& e) {
      ++stats.skipped;
      if (on_skip) on_skip(frame.index, e.what());
      continue;
    }
    ++stats.recorded;
    last = frame.stamp;
    if (on_progress) on_progress(stats.recorded, frame.stamp - first);
  }
  return stats;
}

}  // namespace reflex::vision
