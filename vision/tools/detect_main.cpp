// reflex_detect: AprilTags in still images -- to check a print, a lighting set-up or a tag size
// before running the stereo vision. Thin main over reflex::vision::TagDetector, estimateTagPose and
// drawTags: parse the options, detect in each image, print text / CSV / JSON, write annotated copies.
#include "reflex/common/run_main.hpp"
#include "reflex/common/files.hpp"
#include "reflex/vision/error.hpp"
#include "reflex/vision/image_file.hpp"
#include "reflex/vision/single_view.hpp"
#include "reflex/vision/tag_detector.hpp"

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include <opencv2/core/utils/logger.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

namespace {

using namespace reflex::vision;

/// Margin and corrected bits below which the stereo vision pipeline keeps a detection (its defaults).
constexpr double kPipelineMinMargin = 20.0;
constexpr int kPipelineMaxHamming = 1;

struct ImageResult {
  std::string path;
  cv::Size size;
  std::vector<TagDetection> tags;
  std::vector<std::optional<TagPose>> poses;  ///< empty without --calibration
};

std::string num(double v) {  // shortest text that reads back as the same double
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.17g", v);
  return buf;
}

void printText(const ImageResult& r, const std::string& family) {
  std::printf("%s: %dx%d, %zu %s tag%s\n", r.path.c_str(), r.size.width, r.size.height, r.tags.size(), family.c_str(),
              r.tags.size() == 1 ? "" : "s");
  for (std::size_t i = 0; i < r.tags.size(); ++i) {
    const TagDetection& t = r.tags[i];
    std::string drop;
    if (t.decision_margin < kPipelineMinMargin) drop = "margin < 20";
    if (t.hamming > kPipelineMaxHamming) drop += (drop.empty() ? "" : ", ") + std::string("hamming > 1");
    std::printf("  id %d: margin %.1f, hamming %d, centre (%.2f, %.2f) px, corners", t.id, t.decision_margin, t.hamming,
                t.center.x, t.center.y);
    for (const cv::Point2d& c : t.corners) std::printf(" (%.2f, %.2f)", c.x, c.y);
    std::printf("%s\n", drop.empty() ? "" : ("  [the vision pipeline drops it: " + drop + "]").c_str());
    if (i < r.poses.size()) {
      if (const std::optional<TagPose>& p = r.poses[i])
        std::printf("    pose: t_C = (%.4f, %.4f, %.4f) m, distance %.4f m, tilt %.1f deg, reprojection %.3f px\n",
                    p->t_C[0], p->t_C[1], p->t_C[2], p->distance, p->tilt_deg, p->reprojection_px);
      else
        std::printf("    pose: none (degenerate corners)\n");
    }
  }
}

const char* kCsvHeader =
    "image,family,id,hamming,decision_margin,center_x,center_y,x0,y0,x1,y1,x2,y2,x3,y3,"
    "tx,ty,tz,rx,ry,rz,distance,tilt_deg,reprojection_px";

void printCsv(const ImageResult& r, const std::string& family) {
  for (std::size_t i = 0; i < r.tags.size(); ++i) {
    const TagDetection& t = r.tags[i];
    std::ostringstream os;
    os << r.path << ',' << family << ',' << t.id << ',' << t.hamming << ',' << num(t.decision_margin) << ','
       << num(t.center.x) << ',' << num(t.center.y);
    for (const cv::Point2d& c : t.corners) os << ',' << num(c.x) << ',' << num(c.y);
    const TagPose* p = i < r.poses.size() && r.poses[i] ? &*r.poses[i] : nullptr;
    for (int k = 0; k < 3; ++k) os << ',' << (p ? num(p->t_C[k]) : "");
    for (int k = 0; k < 3; ++k) os << ',' << (p ? num(p->rvec[k]) : "");
    os << ',' << (p ? num(p->distance) : "") << ',' << (p ? num(p->tilt_deg) : "") << ','
       << (p ? num(p->reprojection_px) : "");
    std::printf("%s\n", os.str().c_str());
  }
}

nlohmann::json toJson(const ImageResult& r, const std::string& family) {
  nlohmann::json tags = nlohmann::json::array();
  for (std::size_t i = 0; i < r.tags.size(); ++i) {
    const TagDetection& t = r.tags[i];
    nlohmann::json j = {{"family", family},
                        {"id", t.id},
                        {"hamming", t.hamming},
                        {"decision_margin", t.decision_margin},
                        {"center", {t.center.x, t.center.y}}};
    j["corners"] = nlohmann::json::array();
    for (const cv::Point2d& c : t.corners) j["corners"].push_back({c.x, c.y});
    if (i < r.poses.size() && r.poses[i]) {
      const TagPose& p = *r.poses[i];
      nlohmann::json R = nlohmann::json::array();
      for (int row = 0; row < 3; ++row) R.push_back({p.R_C_T(row, 0), p.R_C_T(row, 1), p.R_C_T(row, 2)});
      j["pose"] = {{"t_C", {p.t_C[0], p.t_C[1], p.t_C[2]}},
                   {"rvec", {p.rvec[0], p.rvec[1], p.rvec[2]}},
                   {"R_C_T", R},
                   {"distance", p.distance},
                   {"tilt_deg", p.tilt_deg},
                   {"reprojection_px", p.reprojection_px}};
    } else if (i < r.poses.size()) {
      j["pose"] = nullptr;
    }
    tags.push_back(j);
  }
  return {{"image", r.path}, {"width", r.size.width}, {"height", r.size.height}, {"tags", tags}};
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{
      "reflex_detect: AprilTags in still images (to check a print, the lighting, a tag size). For each tag:\n"
      "family, id, decision margin, corrected bits (hamming), centre and the four corners in pixels\n"
      "(integer = pixel centre, OpenCV's convention; libapriltag's own coordinates are 0.5 px larger), in\n"
      "libapriltag's corner order. With --calibration (ROS camera_info YAML of the camera that took the\n"
      "image) and --tag-size (edge of the black square, metres): each tag's pose in the camera's optical\n"
      "frame (t_C, metres; rvec, radians; tag frame x right, y down, z into the tag). Reports every tag\n"
      "libapriltag decodes (up to 2 corrected bits); text output flags those the stereo vision pipeline\n"
      "drops (margin < 20 or more than 1 corrected bit).\n"
      "Exit: 0 done (also when no tag is found), 2 bad option or input (named), 4 --draw could not be written."};
  std::vector<std::string> images;
  std::string family = "tag36h11", calibration_path, format = "text", draw;
  double tag_size = 0.0;
  DetectorOptions options;
  options.max_hamming = 2;
  options.min_decision_margin = 0.0;
  app.add_option("images", images, "image files (any format OpenCV reads: PNG, JPEG, PGM, ...)")->required();
  app.add_option("--family", family, "AprilTag family")->capture_default_str();
  app.add_option("--decimate", options.decimate, "libapriltag quad_decimate (>= 1)")->capture_default_str();
  app.add_option("--blur", options.blur_sigma, "libapriltag quad_sigma, Gaussian blur in pixels (>= 0)")
      ->capture_default_str();
  app.add_option("--max-hamming", options.max_hamming, "report tags with at most this many corrected bits (0..2)")
      ->capture_default_str();
  app.add_option("--min-margin", options.min_decision_margin, "report tags with at least this decision margin")
      ->capture_default_str();
  app.add_option("--calibration", calibration_path, "camera_info YAML of the camera (for poses; needs --tag-size)");
  auto* size_opt = app.add_option("--tag-size", tag_size, "edge of the black square in metres (for poses)");
  app.add_option("--format", format, "text, csv or json")->capture_default_str();
  app.add_option("--draw", draw,
                 "annotated copy: an image file (one input image), or an existing folder (one <name>_tags.png per "
                 "image)");
  if (const int code = reflex::parseCommandLine(app, argc, argv); code >= 0) return code;
  cv::utils::logging::setLogLevel(cv::utils::logging::LOG_LEVEL_ERROR);  // our own messages name the file
  try {
    if (format != "text" && format != "csv" && format != "json")
      throw VisionError("--format '" + format + "' must be text, csv or json");
    options.family = family;
    TagDetector detector(options);  // family, decimate, blur, hamming, margin checked (named)
    if (size_opt->count() > 0 && !(tag_size > 0.0 && tag_size <= 5.0))
      throw VisionError("--tag-size " + std::to_string(tag_size) + " m must be in (0, 5]");
    if (calibration_path.empty() != (size_opt->count() == 0))
      throw VisionError("poses need both --calibration and --tag-size");
    std::optional<CameraInfo> camera;
    if (!calibration_path.empty()) camera = loadCameraInfo(calibration_path);
    std::error_code ec;
    const bool draw_folder = !draw.empty() && std::filesystem::is_directory(draw, ec);
    if (!draw.empty() && !draw_folder) {
      if (images.size() != 1)
        throw VisionError("--draw '" + draw + "' is not a folder: with " + std::to_string(images.size()) +
                          " images, give an existing folder");
      if (const std::string why = reflex::common::regularOutputProblem(draw); !why.empty())
        throw VisionError("--draw: " + why);
    }
    // Every annotated file is a regular file or a new one (a device, a FIFO or a folder in its place
    // is refused), checked before any image is read.
    const auto drawPath = [&](const std::string& image) {
      return draw_folder
                 ? (std::filesystem::path(draw) / (std::filesystem::path(image).stem().string() + "_tags.png")).string()
                 : draw;
    };
    if (draw_folder) {
      for (const std::string& path : images) {
        if (const std::string why = reflex::common::regularOutputProblem(drawPath(path)); !why.empty())
          throw VisionError("--draw: " + why);
      }
    }

    nlohmann::json all = nlohmann::json::array();
    if (format == "csv") std::printf("%s\n", kCsvHeader);
    for (const std::string& path : images) {
      const cv::Mat bgr = reflex::vision::readImageWithinBudget(path, cv::IMREAD_COLOR);
      if (camera && bgr.size() != camera->image_size)
        throw VisionError("image '" + path + "' is " + std::to_string(bgr.cols) + "x" + std::to_string(bgr.rows) +
                          " but the calibration '" + calibration_path + "' is for " +
                          std::to_string(camera->image_size.width) + "x" + std::to_string(camera->image_size.height));
      cv::Mat grey;
      cv::cvtColor(bgr, grey, cv::COLOR_BGR2GRAY);
      ImageResult r;
      r.path = path;
      r.size = bgr.size();
      r.tags = detector.detect(grey);
      if (camera)
        for (const TagDetection& t : r.tags) r.poses.push_back(estimateTagPose(*camera, t, tag_size));
      if (format == "text") printText(r, family);
      if (format == "csv") printCsv(r, family);
      if (format == "json") all.push_back(toJson(r, family));
      if (!draw.empty()) {
        cv::Mat annotated = bgr.clone();
        drawTags(annotated, r.tags, r.poses, camera ? &*camera : nullptr, tag_size);
        const std::string out = drawPath(path);
        bool ok = false;
        try {
          ok = cv::imwrite(out, annotated);
        } catch (const cv::Exception& e) {
          std::cerr << "reflex_detect: error: cannot write '" << out << "': " << e.what() << "\n";
          return 4;
        }
        if (!ok) {
          std::cerr << "reflex_detect: error: cannot write '" << out
                    << "' (unknown image extension, or the disk refused it)\n";
          return 4;
        }
      }
    }
    if (format == "json") std::printf("%s\n", nlohmann::json{{"images", all}}.dump(2).c_str());
    if (const std::string why = reflex::common::flushStandardOutput(); !why.empty()) {
      std::cerr << "reflex_detect: error: " << why << "\n";
      return 4;
    }
  } catch (const std::exception& e) {
    return reflex::reportException("reflex_detect", e);
  }
  return 0;
}
