// The image pairs reflex_calibrate reads: a folder of left/right image pairs or a session's videos.
#include "reflex/vision/error.hpp"
#include "reflex/vision/image_file.hpp"
#include "reflex/vision/stereo_calibrate.hpp"
#include "yaml_util.hpp"

#include <opencv2/imgcodecs.hpp>

#include <algorithm>
#include <filesystem>
#include <map>
#include <set>

namespace reflex::vision {
namespace {
namespace fs = std::filesystem;

bool isImageFile(const fs::path& p) {
  static const std::set<std::string> kExt = {".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".pgm", ".ppm"};
  std::string e = p.extension().string();
  std::transform(e.begin(), e.end(), e.begin(), [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return kExt.count(e) > 0;
}

std::vector<std::string> imageNames(const fs::path& dir) {
  std::vector<std::string> out;
  for (const fs::directory_entry& e : fs::directory_iterator(dir))
    if (e.is_regular_file() && isImageFile(e.path())) out.push_back(e.path().filename().string());
  std::sort(out.begin(), out.end());
  return out;
}

cv::Mat readImage(const std::string& path) { return readImageWithinBudget(path, cv::IMREAD_GRAYSCALE); }

}  // namespace

CalibrationImages CalibrationImages::fromPairsFolder(const std::string& dir) {
  std::error_code ec;
  if (!fs::is_directory(dir, ec)) throw VisionError("image folder '" + dir + "' does not exist");
  CalibrationImages c;
  const fs::path root(dir);
  if (fs::is_directory(root / "left", ec) && fs::is_directory(root / "right", ec)) {
    const std::vector<std::string> l = imageNames(root / "left"), r = imageNames(root / "right");
    const std::set<std::string> rs(r.begin(), r.end()), ls(l.begin(), l.end());
    for (const std::string& n : l) {
      if (!rs.count(n))
        throw VisionError((root / "left" / n).string() + " has no right image (expected " +
                          (root / "right" / n).string() + ")");
      c.files_.emplace_back((root / "left" / n).string(), (root / "right" / n).string());
    }
    for (const std::string& n : r)
      if (!ls.count(n))
        throw VisionError((root / "right" / n).string() + " has no left image (expected " +
                          (root / "left" / n).string() + ")");
  } else {
    std::map<std::string, std::string> left, right;  // suffix -> file
    for (const std::string& n : imageNames(root)) {
      if (n.rfind("left", 0) == 0) left[n.substr(4)] = n;
      if (n.rfind("right", 0) == 0) right[n.substr(5)] = n;
    }
    for (const auto& [suffix, n] : left) {
      if (!right.count(suffix))
        throw VisionError((root / n).string() + " has no right image (expected " +
                          (root / ("right" + suffix)).string() + ")");
      c.files_.emplace_back((root / n).string(), (root / right[suffix]).string());
    }
    for (const auto& [suffix, n] : right)
      if (!left.count(suffix))
        throw VisionError((root / n).string() + " has no left image (expected " + (root / ("left" + suffix)).string() +
                          ")");
  }
  if (c.files_.empty())
    throw VisionError("no image pairs in '" + dir +
                      "': expected left/ and right/ subfolders with equal file names, or files left<S> and right<S> "
                      "(e.g. left_000.png, right_000.png)");
  c.count_ = static_cast<int>(c.files_.size());
  return c;
}

CalibrationImages CalibrationImages::fromSession(const std::string& dir, int every) {
  using namespace detail;
  std::error_code ec;
  if (!fs::is_directory(dir, ec)) throw VisionError("session folder '" + dir + "' does not exist");
  if (every < 1) throw VisionError("--every " + std::to_string(every) + " must be at least 1");
  CalibrationImages c;
  c.every_ = every;
  std::string lv = "left.mp4", rv = "right.mp4";
  const std::string manifest = dir + "/session.yaml";
  if (fs::exists(manifest, ec)) {
    const ConfigNode root = parseYaml(readTextFile(manifest, "session manifest"), manifest);
    lv = root.string("left_video", lv);
    rv = root.string("right_video", rv);
  }
  c.left_video_ = dir + "/" + lv;
  c.right_video_ = dir + "/" + rv;
  const std::string* paths[2] = {&c.left_video_, &c.right_video_};
  for (int i = 0; i < 2; ++i) {
    if (const std::string why = common::inputFileProblem(*paths[i]); !why.empty())
      throw VisionError(std::string(i ? "right" : "left") + " video file " + why);
    c.cap_[i] = std::make_shared<cv::VideoCapture>(*paths[i], cv::CAP_FFMPEG);
    if (!c.cap_[i]->isOpened()) throw VisionError("cannot open video '" + *paths[i] + "'");
  }
  const double frames = c.cap_[0]->get(cv::CAP_PROP_FRAME_COUNT);
  c.count_ = frames > 0 ? static_cast<int>((frames + every - 1) / every) : 0;
  return c;
}

bool CalibrationImages::next(std::string& name, cv::Mat& left, cv::Mat& right) {
  if (!cap_[0]) {
    if (next_file_ >= files_.size()) return false;
    const auto& [l, r] = files_[next_file_++];
    left = readImage(l);
    right = readImage(r);
    name = fs::path(l).filename().string();
    if (left.size() != right.size())
      throw VisionError("image sizes differ: " + l + " is " + std::to_string(left.cols) + "x" +
                        std::to_string(left.rows) + " but " + r + " is " + std::to_string(right.cols) + "x" +
                        std::to_string(right.rows));
    return true;
  }
  for (;;) {
    cv::Mat l, r;
    const bool gl = cap_[0]->read(l), gr = cap_[1]->read(r);
    if (!gl && !gr) return false;
    if (gl != gr)
      throw VisionError(std::string(gl ? "right" : "left") + " video ended at frame " + std::to_string(frame_) +
                        " before the other one (" + (gl ? right_video_ : left_video_) + ")");
    const int index = frame_++;
    if (index % every_ != 0) continue;
    if (l.size() != r.size())
      throw VisionError("frame " + std::to_string(index) + ": left and right video sizes differ (" +
                        std::to_string(l.cols) + "x" + std::to_string(l.rows) + " vs " + std::to_string(r.cols) + "x" +
                        std::to_string(r.rows) + ")");
    left = l;
    right = r;
    name = "frame " + std::to_string(index);
    return true;
  }
}

}  // namespace reflex::vision
