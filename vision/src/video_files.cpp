#include "reflex/vision/video_files.hpp"

#include "reflex/common/files.hpp"
#include "reflex/vision/error.hpp"
#include "yaml_util.hpp"

#include <chrono>
#include <cmath>
#include <filesystem>

namespace reflex::vision {
namespace {

using detail::fmt;

std::string sizeText(cv::Size s) { return std::to_string(s.width) + "x" + std::to_string(s.height); }

void openVideo(cv::VideoCapture& cap, const std::string& path) {
  std::error_code ec;
  if (!std::filesystem::exists(path, ec)) throw VisionError("video file '" + path + "' does not exist");
  if (const std::string why = common::inputFileProblem(path); !why.empty()) throw VisionError("video file " + why);
  if (!cap.open(path, cv::CAP_FFMPEG) || !cap.isOpened())
    throw VisionError("cannot open video '" + path + "' (not a video, or a codec OpenCV's FFmpeg backend cannot read)");
}

long frameCountOf(cv::VideoCapture& cap) {
  const double n = cap.get(cv::CAP_PROP_FRAME_COUNT);
  return std::isfinite(n) && n > 0.0 ? std::lround(n) : -1;
}

cv::Size frameSizeOf(cv::VideoCapture& cap) {
  return {static_cast<int>(cap.get(cv::CAP_PROP_FRAME_WIDTH)), static_cast<int>(cap.get(cv::CAP_PROP_FRAME_HEIGHT))};
}

}  // namespace

VideoFilesReader::VideoFilesReader(const VideoFilesSpec& spec, cv::Size image_size) : spec_(spec), size_(image_size) {
  if (!spec_.timestamps.empty() && spec_.fps != 0.0)
    throw VisionError("give either a timestamps CSV ('" + spec_.timestamps + "') or a frame rate (" + fmt(spec_.fps) +
                      " fps), not both");
  if (spec_.fps != 0.0 && !(spec_.fps >= kMinImportFps && spec_.fps <= kMaxSessionFps))
    throw VisionError("frame rate " + fmt(spec_.fps) + " fps must be in [" + fmt(kMinImportFps) + ", " +
                      fmt(kMaxSessionFps) + "] (consecutive stamps at most " + fmt(kMaxFrameGap) + " s apart)");
  const int videos = spec_.side_by_side() ? 1 : 2;
  const std::string paths[2] = {spec_.left, spec_.right};
  long counts[2] = {-1, -1};
  cv::Size sizes[2];
  for (int k = 0; k < videos; ++k) {
    openVideo(cap_[k], paths[k]);
    counts[k] = frameCountOf(cap_[k]);
    sizes[k] = frameSizeOf(cap_[k]);
  }
  if (spec_.side_by_side()) {
    if (sizes[0].width % 2 != 0)
      throw VisionError("side-by-side video '" + paths[0] + "' is " + std::to_string(sizes[0].width) +
                        " pixels wide: an odd width cannot be split into equal left and right halves");
    sizes[0].width /= 2;
    if (sizes[0] != size_)
      throw VisionError("side-by-side video '" + paths[0] + "' has " + sizeText(sizes[0]) +
                        " halves but the calibration says " + sizeText(size_) + " (the full frame must be " +
                        sizeText({2 * size_.width, size_.height}) + ")");
  } else {
    if (sizes[0] != sizes[1])
      throw VisionError("left video '" + paths[0] + "' is " + sizeText(sizes[0]) + " but right video '" + paths[1] +
                        "' is " + sizeText(sizes[1]));
    if (sizes[0] != size_)
      throw VisionError("videos '" + paths[0] + "' and '" + paths[1] + "' are " + sizeText(sizes[0]) +
                        " but the calibration says " + sizeText(size_));
    if (counts[0] > 0 && counts[1] > 0 && counts[0] != counts[1])
      throw VisionError("left video '" + paths[0] + "' has " + std::to_string(counts[0]) + " frames but right video '" +
                        paths[1] + "' has " + std::to_string(counts[1]));
  }
  const long video_frames = counts[0] > 0 ? counts[0] : counts[1];
  const double video_fps = cap_[0].get(cv::CAP_PROP_FPS);
  const bool video_fps_ok = std::isfinite(video_fps) && video_fps >= kMinImportFps && video_fps <= kMaxSessionFps;
  if (!spec_.timestamps.empty()) {
    stamps_ = loadTimestamps(spec_.timestamps);  // header, order, monotonic, range, gaps: named there
    if (video_frames > 0 && static_cast<long>(stamps_.size()) != video_frames)
      throw VisionError("timestamps '" + spec_.timestamps + "' lists " + std::to_string(stamps_.size()) +
                        " frames but video '" + paths[0] + "' has " + std::to_string(video_frames));
    frames_ = static_cast<int>(stamps_.size());
    const double span = stamps_.back() - stamps_.front();
    nominal_fps_ = video_fps_ok ? video_fps : (stamps_.size() > 1 && span > 0.0 ? (stamps_.size() - 1) / span : 10.0);
    nominal_fps_ = std::min(std::max(nominal_fps_, kMinImportFps), kMaxSessionFps);
  } else {
    if (spec_.fps == 0.0 && !video_fps_ok)
      throw VisionError("video '" + paths[0] + "' states no usable frame rate (" + fmt(video_fps) +
                        "): give --fps F or --timestamps CSV");
    fps_ = spec_.fps != 0.0 ? spec_.fps : video_fps;
    nominal_fps_ = fps_;
    frames_ = video_frames > 0 ? static_cast<int>(video_frames) : -1;
  }
}

bool VideoFilesReader::next(StereoFrame& frame) {
  const std::string& left_path = spec_.left;
  cv::Mat& first = spec_.side_by_side() ? sbs_ : frame.left;
  const bool got_left = cap_[0].read(first) && !first.empty();
  const bool got_right = spec_.side_by_side() ? got_left : cap_[1].read(frame.right) && !frame.right.empty();
  const bool more_stamps = stamps_.empty() || next_ < static_cast<int>(stamps_.size());
  if (!got_left && !got_right) {
    if (more_stamps && !stamps_.empty())
      throw VisionError("video '" + left_path + "' ended after " + std::to_string(next_) + " frames but timestamps '" +
                        spec_.timestamps + "' lists " + std::to_string(stamps_.size()));
    return false;  // the normal end
  }
  if (got_left != got_right)
    throw VisionError(std::string(got_left ? "right" : "left") + " video '" + (got_left ? spec_.right : spec_.left) +
                      "' ended after " + std::to_string(next_) + " frames but the " + (got_left ? "left" : "right") +
                      " video '" + (got_left ? spec_.left : spec_.right) + "' has more");
  if (!more_stamps)
    throw VisionError("video '" + left_path + "' has more frames than the " + std::to_string(stamps_.size()) +
                      " listed in timestamps '" + spec_.timestamps + "'");
  if (spec_.side_by_side()) {
    if (sbs_.cols != 2 * size_.width || sbs_.rows != size_.height)
      throw VisionError("frame " + std::to_string(next_) + " of side-by-side video '" + left_path + "' is " +
                        sizeText(sbs_.size()) + ", not " + sizeText({2 * size_.width, size_.height}));
    frame.left = sbs_.colRange(0, size_.width).clone();
    frame.right = sbs_.colRange(size_.width, 2 * size_.width).clone();
  } else if (frame.left.size() != size_ || frame.right.size() != size_) {
    throw VisionError("frame " + std::to_string(next_) + " of videos '" + spec_.left + "' / '" + spec_.right + "' is " +
                      sizeText(frame.left.size()) + " / " + sizeText(frame.right.size()) + ", not the calibration's " +
                      sizeText(size_));
  }
  frame.index = next_;
  frame.stamp = stamps_.empty() ? next_ / fps_ : stamps_[static_cast<std::size_t>(next_)];
  ++next_;
  return true;
}

ImportStats importVideoFiles(VideoFilesReader& reader, SessionWriter& writer, const std::atomic<bool>& stop,
                             const std::function<void(int, int)>& on_progress) {
  const auto t0 = std::chrono::steady_clock::now();
  ImportStats stats;
  StereoFrame frame;
  while (true) {
    if (stop.load()) {
      stats.stopped = true;
      break;
    }
    if (!reader.next(frame)) break;
    writer.write(frame.stamp, frame.left, frame.right);
    if (stats.frames == 0) stats.first_stamp = frame.stamp;
    stats.last_stamp = frame.stamp;
    ++stats.frames;
    if (on_progress) on_progress(stats.frames, reader.frameCount());
  }
  stats.wall_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return stats;
}

}  // namespace reflex::vision
