// reflex_detect on an image the test renders: three tag36h11 tags at known poses
// in front of a pinhole camera, each warped by the exact homography of its pose (4x4 supersampled).
// Independent answers: libapriltag's own detections, computed here with its C API on the same grey
// image with the same settings (ids, hamming, margin exactly; corners and centres to 1e-9 px after
// the documented -0.5 px shift to OpenCV's pixel-centre convention), and the rendered poses (within
// 1 mm and 0.5 degree at 0.45-0.7 m; measured 0.18 mm and 0.15 degree). The JSON is parsed back,
// the CSV's column count checked, the annotated image read back, and every bad input named.
#include "reflex/vision/calibration.hpp"
#include "reflex/vision/tag_detector.hpp"
#include "vision_test_util.hpp"

#include <apriltag/apriltag.h>
#include <apriltag/tag36h11.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <opencv2/calib3d.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include <cstdlib>

using namespace reflex::vision;
using namespace reflex::vision::test;
using ::testing::AllOf;
using ::testing::HasSubstr;

namespace {

constexpr double kTagSize = 0.08;  // black square edge, metres
const cv::Matx33d kK(600, 0, 319.5, 0, 600, 239.5, 0, 0, 1);

struct TagTruth {
  int id;
  cv::Vec3d rvec;  // R_C_T, axis-angle
  cv::Vec3d t_C;   // tag centre, camera optical frame
};

const std::vector<TagTruth> kTags = {
    {3, {0.0, 20.0 * CV_PI / 180, 0.0}, {-0.12, -0.05, 0.45}},
    {17, {-0.5, 0.0, 0.25}, {0.10, 0.06, 0.55}},
    {42, {0.0, -35.0 * CV_PI / 180, 0.05}, {0.0, -0.02, 0.70}},
};

/// Grey page (170) with the tags' bitmaps (white border included) at their true poses.
cv::Mat renderImage() {
  constexpr int kSuper = 4, kBitmapScale = 32;
  const TagFamily family("tag36h11");
  const double total = family.totalWidth(), cell = kTagSize / family.widthAtBorder();
  cv::Mat big(480 * kSuper, 640 * kSuper, CV_8U, cv::Scalar(170));
  // Big-image pixel centres: x_big = kSuper x + (kSuper - 1) / 2 for output pixel x.
  const cv::Matx33d A(kSuper, 0, (kSuper - 1) / 2.0, 0, kSuper, (kSuper - 1) / 2.0, 0, 0, 1);
  // Bitmap pixel (i, j) of the upscaled bitmap -> tag-plane point (x right, y down), metres.
  const double offset = (0.5 / kBitmapScale - total / 2) * cell;
  const cv::Matx33d S_to_T(cell / kBitmapScale, 0, offset, 0, cell / kBitmapScale, offset, 0, 0, 1);
  for (const TagTruth& t : kTags) {
    cv::Mat bits;
    cv::resize(family.bitmap(t.id), bits, cv::Size(), kBitmapScale, kBitmapScale, cv::INTER_NEAREST);
    cv::Matx33d R;
    cv::Rodrigues(t.rvec, R);
    const cv::Matx33d T_to_C(R(0, 0), R(0, 1), t.t_C[0], R(1, 0), R(1, 1), t.t_C[1], R(2, 0), R(2, 1), t.t_C[2]);
    const cv::Matx33d H = A * kK * T_to_C * S_to_T;
    cv::warpPerspective(bits, big, cv::Mat(H), big.size(), cv::INTER_LINEAR, cv::BORDER_TRANSPARENT);
  }
  cv::Mat img;
  cv::resize(big, img, cv::Size(640, 480), 0, 0, cv::INTER_AREA);
  return img;
}

void writeCamera(const std::string& path) {
  CameraInfo c;
  c.camera_name = "test";
  c.image_size = {640, 480};
  c.K = kK;
  c.P = cv::Matx34d(600, 0, 319.5, 0, 0, 600, 239.5, 0, 0, 0, 1, 0);
  saveCameraInfo(path, c);
}

int runTool(const std::string& args, std::string& out, std::string& err, const TempDir& dir) {
  const int rc = std::system(
      (std::string(REFLEX_BIN_DIR) + "/reflex_detect " + args + " > " + (dir / "out.txt") + " 2> " + (dir / "err.txt"))
          .c_str());
  out = readText(dir / "out.txt");
  err = readText(dir / "err.txt");
  return WIFEXITED(rc) ? WEXITSTATUS(rc) : -1;
}

struct Fixture {
  TempDir dir{"detect"};
  std::string image = dir / "tags.png", camera = dir / "camera.yaml";
  cv::Mat grey;
  Fixture() {
    grey = renderImage();
    cv::imwrite(image, grey);
    writeCamera(camera);
  }
};

Fixture& fixture() {
  static Fixture f;
  return f;
}

/// libapriltag's own detections, C API, the settings reflex_detect uses by default.
struct Reference {
  int id, hamming;
  double margin;
  double c[2], p[4][2];
};
std::vector<Reference> libapriltagDetections(const cv::Mat& grey) {
  apriltag_family_t* fam = tag36h11_create();
  apriltag_detector_t* td = apriltag_detector_create();
  apriltag_detector_add_family_bits(td, fam, 2);
  td->quad_decimate = 1.0f;
  td->quad_sigma = 0.0f;
  td->nthreads = 1;
  td->refine_edges = 1;
  image_u8_t im{grey.cols, grey.rows, static_cast<int32_t>(grey.step[0]), grey.data};
  zarray_t* dets = apriltag_detector_detect(td, &im);
  std::vector<Reference> out;
  for (int i = 0; i < zarray_size(dets); ++i) {
    apriltag_detection_t* d = nullptr;
    zarray_get(dets, i, &d);
    Reference r{d->id, d->hamming, d->decision_margin, {d->c[0], d->c[1]}, {}};
    for (int k = 0; k < 4; ++k) r.p[k][0] = d->p[k][0], r.p[k][1] = d->p[k][1];
    out.push_back(r);
  }
  apriltag_detections_destroy(dets);
  apriltag_detector_destroy(td);
  tag36h11_destroy(fam);
  return out;
}

}  // namespace

TEST(Detect, JsonEqualsLibapriltagAndPosesMatchTheRendering) {
  Fixture& fx = fixture();
  const cv::Mat grey = cv::imread(fx.image, cv::IMREAD_GRAYSCALE);  // what reflex_detect reads
  const std::vector<Reference> ref = libapriltagDetections(grey);
  ASSERT_EQ(ref.size(), kTags.size());
  std::string out, err;
  ASSERT_EQ(runTool(fx.image + " --format json --calibration " + fx.camera + " --tag-size 0.08", out, err, fx.dir), 0)
      << err;
  const nlohmann::json j = nlohmann::json::parse(out);
  ASSERT_EQ(j["images"].size(), 1u);
  const nlohmann::json& img = j["images"][0];
  EXPECT_EQ(img["image"], fx.image);
  EXPECT_EQ(img["width"], 640);
  EXPECT_EQ(img["height"], 480);
  ASSERT_EQ(img["tags"].size(), ref.size());
  double worst_t = 0.0, worst_deg = 0.0;
  for (const Reference& r : ref) {
    const nlohmann::json* tag = nullptr;
    for (const nlohmann::json& t : img["tags"])
      if (t["id"] == r.id) tag = &t;
    ASSERT_NE(tag, nullptr) << "id " << r.id;
    EXPECT_EQ((*tag)["family"], "tag36h11");
    EXPECT_EQ((*tag)["hamming"], r.hamming);
    EXPECT_EQ((*tag)["decision_margin"].get<double>(), r.margin);
    for (int a = 0; a < 2; ++a) EXPECT_NEAR((*tag)["center"][a].get<double>(), r.c[a] - 0.5, 1e-9);
    for (int k = 0; k < 4; ++k)
      for (int a = 0; a < 2; ++a) EXPECT_NEAR((*tag)["corners"][k][a].get<double>(), r.p[k][a] - 0.5, 1e-9);
    // Pose against the rendering.
    const TagTruth* truth = nullptr;
    for (const TagTruth& t : kTags)
      if (t.id == r.id) truth = &t;
    ASSERT_NE(truth, nullptr);
    const nlohmann::json& pose = (*tag)["pose"];
    ASSERT_TRUE(pose.is_object());
    const cv::Vec3d t(pose["t_C"][0].get<double>(), pose["t_C"][1].get<double>(), pose["t_C"][2].get<double>());
    const cv::Vec3d rv(pose["rvec"][0].get<double>(), pose["rvec"][1].get<double>(), pose["rvec"][2].get<double>());
    cv::Matx33d R, R_true;
    cv::Rodrigues(rv, R);
    cv::Rodrigues(truth->rvec, R_true);
    cv::Vec3d dr;
    cv::Rodrigues(R_true.t() * R, dr);
    worst_t = std::max(worst_t, cv::norm(t - truth->t_C));
    worst_deg = std::max(worst_deg, cv::norm(dr) * 180 / CV_PI);
    EXPECT_LT(cv::norm(t - truth->t_C), 0.001) << "id " << r.id;
    EXPECT_LT(cv::norm(dr) * 180 / CV_PI, 0.5) << "id " << r.id;
    EXPECT_LT(pose["reprojection_px"].get<double>(), 0.5);
    EXPECT_NEAR(pose["distance"].get<double>(), cv::norm(truth->t_C), 0.003);
    for (int a = 0; a < 3; ++a)
      for (int b = 0; b < 3; ++b) EXPECT_NEAR(pose["R_C_T"][a][b].get<double>(), R(a, b), 1e-12);
  }
  std::cout << "pose error vs the rendering: worst " << 1000 * worst_t << " mm, " << worst_deg << " deg\n";
}

TEST(Detect, CsvAndTextCarryTheSameTags) {
  Fixture& fx = fixture();
  std::string out, err;
  ASSERT_EQ(runTool(fx.image + " --format csv --calibration " + fx.camera + " --tag-size 0.08", out, err, fx.dir), 0)
      << err;
  std::istringstream lines(out);
  std::string line;
  std::vector<std::vector<std::string>> rows;
  while (std::getline(lines, line)) {
    std::vector<std::string> cols;
    std::string col;
    std::istringstream ls(line);
    while (std::getline(ls, col, ',')) cols.push_back(col);
    if (!line.empty() && line.back() == ',') cols.push_back("");
    rows.push_back(cols);
  }
  ASSERT_EQ(rows.size(), 1 + kTags.size());
  EXPECT_EQ(rows[0][0], "image");
  for (const auto& r : rows) EXPECT_EQ(r.size(), 24u) << out;
  const std::vector<Reference> ref = libapriltagDetections(fx.grey);
  for (std::size_t i = 1; i < rows.size(); ++i) {
    const int id = std::stoi(rows[i][2]);
    for (const Reference& r : ref) {
      if (r.id != id) continue;
      for (int k = 0; k < 4; ++k) EXPECT_NEAR(std::stod(rows[i][7 + 2 * k]), r.p[k][0] - 0.5, 1e-9);
    }
    EXPECT_GT(std::stod(rows[i][17]), 0.4);  // tz
  }
  // Without a calibration the pose columns stay empty (the count does not change).
  ASSERT_EQ(runTool(fx.image + " --format csv", out, err, fx.dir), 0) << err;
  std::istringstream again(out);
  std::getline(again, line);
  std::getline(again, line);
  EXPECT_EQ(std::count(line.begin(), line.end(), ','), 23) << line;
  ASSERT_EQ(runTool(fx.image + " --calibration " + fx.camera + " --tag-size 0.08", out, err, fx.dir), 0) << err;
  EXPECT_THAT(out, AllOf(HasSubstr("3 tag36h11 tags"), HasSubstr("id 3:"), HasSubstr("id 17:"), HasSubstr("id 42:"),
                         HasSubstr("pose: t_C = (")));
}

TEST(Detect, DrawWritesAnAnnotatedCopy) {
  Fixture& fx = fixture();
  std::string out, err;
  const std::string drawn = fx.dir / "drawn.png";
  ASSERT_EQ(runTool(fx.image + " --calibration " + fx.camera + " --tag-size 0.08 --draw " + drawn, out, err, fx.dir), 0)
      << err;
  const cv::Mat a = cv::imread(drawn, cv::IMREAD_COLOR);
  ASSERT_EQ(a.size(), fx.grey.size());
  // Green outline along the first tag's first edge, red dot at its first corner.
  const std::vector<Reference> ref = libapriltagDetections(fx.grey);
  const cv::Point2d p0(ref[0].p[0][0] - 0.5, ref[0].p[0][1] - 0.5), p1(ref[0].p[1][0] - 0.5, ref[0].p[1][1] - 0.5);
  const cv::Vec3b mid = a.at<cv::Vec3b>(cvRound(0.5 * (p0.y + p1.y)), cvRound(0.5 * (p0.x + p1.x)));
  EXPECT_GT(mid[1], 200);
  EXPECT_LT(mid[0], 80);
  const cv::Vec3b corner = a.at<cv::Vec3b>(cvRound(p0.y), cvRound(p0.x));
  EXPECT_GT(corner[2], 200);
  EXPECT_LT(corner[1], 80);
  // Several images into a folder: one <name>_tags.png each.
  ASSERT_EQ(runTool(fx.image + " " + fx.image + " --draw " + fx.dir.path(), out, err, fx.dir), 0) << err;
  EXPECT_FALSE(cv::imread(fx.dir / "tags_tags.png").empty());
}

TEST(Detect, BadInputsAreNamed) {
  Fixture& fx = fixture();
  writeText(fx.dir / "not_an_image.png", "hello");
  writeText(fx.dir / "small.yaml", readText(fx.camera));
  struct Case {
    std::string args, expected;
    int rc;
  };
  const std::string img = fx.image;
  const std::vector<Case> cases = {
      {fx.dir / "missing.png", "cannot read image '" + (fx.dir / "missing.png") + "'", 2},
      {fx.dir / "not_an_image.png", "cannot read image '" + (fx.dir / "not_an_image.png") + "'", 2},
      {img + " --family tag99h1", "unknown tag family 'tag99h1'", 2},
      {img + " --calibration " + fx.camera + " --tag-size 0", "--tag-size 0", 2},
      {img + " --calibration " + fx.camera + " --tag-size -0.05", "--tag-size -0.05", 2},
      {img + " --calibration " + fx.camera, "both --calibration and --tag-size", 2},
      {img + " --tag-size 0.08", "both --calibration and --tag-size", 2},
      {img + " --format xml", "--format 'xml'", 2},
      {img + " --decimate 0.5", "decimate", 2},
      {img + " " + img + " --draw " + (fx.dir / "one.png"), "give an existing folder", 2},
      {img + " --draw " + (fx.dir / "no/such/folder.png"), "does not exist", 2},
      {img + " --draw " + (fx.dir / "x.unknownext"), "cannot write", 4},
      {fx.dir / "", "image '" + (fx.dir / "") + "' is a directory", 2},
  };
  for (const Case& c : cases) {
    std::string out, err;
    EXPECT_EQ(runTool(c.args, out, err, fx.dir), c.rc) << c.args << "\n" << err;
    EXPECT_THAT(err, HasSubstr(c.expected)) << c.args;
  }
  // Sizes libapriltag cannot take (1 px high: it crashed, SIGSEGV; 40000 px wide: it aborted) and a
  // PNG whose header says 20000 x 20000 (a 431 KB file of that size decoded to 5 GB): refused with the
  // size, the last before decoding.
  cv::imwrite(fx.dir / "thin.png", cv::Mat(1, 100, CV_8UC1, cv::Scalar(128)));
  cv::imwrite(fx.dir / "wide.png", cv::Mat(16, 40000, CV_8UC1, cv::Scalar(128)));
  {
    std::string png = readText(fx.dir / "thin.png");
    const unsigned char wh[8] = {0, 0, 0x4e, 0x20, 0, 0, 0x4e, 0x20};  // 20000, 20000 (big-endian)
    png.replace(16, 8, reinterpret_cast<const char*>(wh), 8);
    writeText(fx.dir / "huge.png", png);
  }
  const std::vector<Case> sizes = {
      {fx.dir / "thin.png", "image '" + (fx.dir / "thin.png") + "' is 100x1 px: smaller than 16 px a side", 2},
      {fx.dir / "wide.png", "image '" + (fx.dir / "wide.png") + "' is 40000x16 px: more than 16384 px a side", 2},
      {fx.dir / "huge.png",
       "image '" + (fx.dir / "huge.png") +
           "' is 20000x20000 px: more than 16384 px a side or 50 "
           "megapixels, refused before decoding",
       2},
  };
  for (const Case& c : sizes) {
    std::string out, err;
    EXPECT_EQ(runTool(c.args, out, err, fx.dir), c.rc) << c.args << "\n" << err;
    EXPECT_THAT(err, HasSubstr(c.expected)) << c.args;
  }
  std::string out, err;
  EXPECT_EQ(runTool("--help", out, err, fx.dir), 0);
  EXPECT_THAT(out, AllOf(HasSubstr("--calibration"), HasSubstr("--tag-size"), HasSubstr("--draw")));
}
