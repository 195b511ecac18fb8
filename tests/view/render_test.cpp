// The flagship report's 3D robot: modules/view/tools/render_scenes.py turns a row of
// a controller time series into the live view's SceneUpdate (reflex_scene) and draws it with the live
// view's own page (view.js, static mode) in Debian's Chromium, headless. A known posture is drawn and
// the PNG is checked against independent answers:
//   - where the hands are: reflex::control forward kinematics (not the scene library) of the logged q,
//     projected in this file with the camera the page documents (orbit about the target, 40 deg
//     vertical field of view, aspect width / height, z up): the pixel there has the hand's zone colour
//     (the left arm's zone is red in the log, the right arm's free = green), read with OpenCV;
//   - how much is red: pixels of the red zone colour exist; a point of space 0.35 m above the left hand
//     is background;
//   - what the page says it drew (state.tiles): as many capsules as the model has capsule primitives.
// Failure paths: Chromium missing (exit 3 naming it), a log of another robot (exit 2 naming the column).
// The PNG stays in build/artefacts/view/render/ (scene_0.png).
#include "support/child_process.hpp"

#include <reflex/control/kinematics.hpp>
#include <reflex/control/urdf_loader.hpp>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>

#include <Eigen/Geometry>

#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

namespace {

namespace fs = std::filesystem;
const std::string kUrdf = std::string(REFLEX_SOURCE_DIR) + "/bringup/robots/asimo_like.urdf";
const std::string kScript = std::string(REFLEX_SOURCE_DIR) + "/modules/view/tools/render_scenes.py";
const std::string kBuild = fs::path(REFLEX_BIN_DIR).parent_path().string();

// The camera the test asks for (render_scenes.py --camera): from the front, a little above.
constexpr double kAzimuth = 0.15, kElevation = 0.2, kRadius = 2.4;
const Eigen::Vector3d kTarget(0.0, 0.0, 0.95);
constexpr int kWidth = 400, kHeight = 440;
constexpr double kFovY = 40.0 * M_PI / 180.0;

std::string readFile(const std::string& path) {
  std::ifstream in(path);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

/// Runs render_scenes.py with `args`; returns its exit code, its output in `log`.
int runRender(const std::string& args, const std::string& out, std::string& log) {
  fs::create_directories(out);
  const std::string log_path = out + "/render.log";
  reflex::testing::ChildProcess p(
      {"/bin/sh", "-c", "exec /usr/bin/python3 " + kScript + " --build " + kBuild + " " + args}, log_path);
  const int rc = p.wait(std::chrono::seconds(110));
  log = readFile(log_path);
  return rc;
}

/// Pixel (u right, v down) [px] of the world point p_B in a kWidth x kHeight picture, as a pinhole camera
/// at target + radius (cos el cos az, cos el sin az, sin el) looking at the target, z up.
Eigen::Vector2d project(const Eigen::Vector3d& p_B) {
  const Eigen::Vector3d c_B =
      kTarget + kRadius * Eigen::Vector3d(std::cos(kElevation) * std::cos(kAzimuth),
                                          std::cos(kElevation) * std::sin(kAzimuth), std::sin(kElevation));
  const Eigen::Vector3d forward = (kTarget - c_B).normalized();
  const Eigen::Vector3d right = forward.cross(Eigen::Vector3d::UnitZ()).normalized();
  const Eigen::Vector3d up = right.cross(forward);
  const Eigen::Vector3d d = p_B - c_B;
  const double depth = d.dot(forward), t = std::tan(kFovY / 2.0), aspect = double(kWidth) / kHeight;
  const double x_ndc = d.dot(right) / (depth * t * aspect), y_ndc = d.dot(up) / (depth * t);
  return {(x_ndc + 1.0) / 2.0 * kWidth, (1.0 - y_ndc) / 2.0 * kHeight};
}

enum class Hue { kRed, kGreen, kBackground, kOther };
Hue hueOf(const cv::Vec3b& bgr) {
  const int b = bgr[0], g = bgr[1], r = bgr[2];
  if (r > 90 && r > 2 * g && r > 2 * b) return Hue::kRed;
  if (g > 80 && g > r + 30 && g > b + 20) return Hue::kGreen;
  if (std::abs(r - 0x16) < 12 && std::abs(g - 0x18) < 12 && std::abs(b - 0x1d) < 12) return Hue::kBackground;
  return Hue::kOther;
}

/// Count of pixels of `hue` in the (2k+1)^2 window around (u, v).
int countAround(const cv::Mat& img, const Eigen::Vector2d& uv, Hue hue, int k = 3) {
  int n = 0;
  for (int dv = -k; dv <= k; ++dv)
    for (int du = -k; du <= k; ++du) {
      const int u = static_cast<int>(std::lround(uv.x())) + du, v = static_cast<int>(std::lround(uv.y())) + dv;
      if (u >= 0 && v >= 0 && u < img.cols && v < img.rows && hueOf(img.at<cv::Vec3b>(v, u)) == hue) ++n;
    }
  return n;
}

TEST(ReportRender, AKnownPostureIsDrawnWhereForwardKinematicsPutsIt) {
  using namespace reflex::control;
  const Model model = loadModel(kUrdf, loadCollisionConfigFor(kUrdf, ""));
  Eigen::VectorXd q = Eigen::VectorXd::Zero(model.nq);
  // Arms raised sideways, elbows a little bent: both hands clear of the body seen from the front.
  const std::pair<const char*, double> posture[] = {
      {"l_shoulder_roll", 1.1}, {"r_shoulder_roll", -1.1}, {"l_elbow", -0.4}, {"r_elbow", -0.4}};
  for (const auto& [name, value] : posture) {
    ASSERT_GE(model.qIndex(name), 0) << name;
    q[model.qIndex(name)] = value;
  }
  const std::string out = std::string(REFLEX_ARTEFACT_DIR) + "/render";
  fs::remove_all(out);
  fs::create_directories(out);
  const std::string csv = out + "/log.csv";
  {
    std::ofstream f(csv);
    f << "time,wall_time,left_f,left_distance,left_pair,left_zone,right_f,right_distance,right_pair,right_zone,estop";
    for (const std::string& name : model.q_names) f << ",q_" << name;
    f << "\n0.5,1796170000.0,1,0.004,,red,0,0.2,,free,0";
    for (int i = 0; i < model.nq; ++i) f << "," << q[i];
    f << "\n";
  }
  std::string log;
  std::ostringstream camera;
  camera << kAzimuth << "," << kElevation << "," << kRadius << "," << kTarget.x() << "," << kTarget.y() << ","
         << kTarget.z();
  const auto t0 = std::chrono::steady_clock::now();
  ASSERT_EQ(runRender("--log " + csv + " --at 0.5 --out " + out + " --tile " + std::to_string(kWidth) + "x" +
                          std::to_string(kHeight) + " --camera " + camera.str(),
                      out, log),
            0)
      << log;
  std::printf("render_scenes.py: %.1f s\n",
              std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());

  const cv::Mat img = cv::imread(out + "/scene_0.png", cv::IMREAD_COLOR);
  ASSERT_FALSE(img.empty()) << log;
  ASSERT_EQ(img.cols, kWidth);
  ASSERT_EQ(img.rows, kHeight);

  // What the page says it drew: every capsule primitive of the model (a sphere primitive is no capsule).
  const nlohmann::json render = nlohmann::json::parse(readFile(out + "/render.json"));
  int capsules = 0;
  for (int s = 0; s < model.num_robot_segments; ++s)
    for (int p = 0; p < model.segments[s].num_primitives; ++p)
      capsules += model.primitives[model.segments[s].first_primitive + p].sphere ? 0 : 1;
  EXPECT_EQ(render["tiles"][0]["page"]["capsulesDrawn"].get<int>(), capsules) << render.dump();
  EXPECT_TRUE(render["tiles"][0]["page"]["zoneColours"].contains("red")) << render.dump();

  int red = 0;
  for (int v = 0; v < img.rows; ++v)
    for (int u = 0; u < img.cols; ++u) red += hueOf(img.at<cv::Vec3b>(v, u)) == Hue::kRed ? 1 : 0;
  EXPECT_GT(red, 500) << "pixels of the red zone colour (the left arm)";

  KinematicsData kin(model);
  ASSERT_TRUE(computeForwardKinematics(model, kin, q));
  auto centre = [&](const char* segment) {
    const Segment& seg = model.segments[model.segmentIndex(segment)];
    const Primitive& prim = model.primitives[seg.first_primitive];
    return Eigen::Vector3d(kin.X_B_L[seg.link] * (0.5 * (prim.a_L + prim.b_L)));
  };
  const Eigen::Vector3d left_hand = centre("l_hand"), right_hand = centre("r_hand");
  const Eigen::Vector2d uv_left = project(left_hand), uv_right = project(right_hand);
  std::printf("left hand at (%.3f %.3f %.3f) m -> pixel (%.1f, %.1f); right hand -> (%.1f, %.1f); red pixels %d\n",
              left_hand.x(), left_hand.y(), left_hand.z(), uv_left.x(), uv_left.y(), uv_right.x(), uv_right.y(), red);
  // 7 x 7 windows: most of the window around each projected hand centre has the arm's zone colour.
  EXPECT_GE(countAround(img, uv_left, Hue::kRed), 30) << "left hand (zone red) not drawn at its FK position";
  EXPECT_GE(countAround(img, uv_right, Hue::kGreen), 30) << "right hand (zone free) not drawn at its FK position";
  EXPECT_EQ(countAround(img, uv_left, Hue::kGreen), 0);
  EXPECT_EQ(countAround(img, uv_right, Hue::kRed), 0);
  // Space 0.35 m above the left hand is empty (background colour there).
  const Eigen::Vector2d uv_empty = project(left_hand + Eigen::Vector3d(0.0, 0.0, 0.35));
  EXPECT_EQ(countAround(img, uv_empty, Hue::kBackground), 49) << "(" << uv_empty.transpose() << ")";
}

TEST(ReportRender, MissingChromiumOrAnotherRobotsLogIsNamed) {
  const std::string out = std::string(REFLEX_ARTEFACT_DIR) + "/render_errors";
  std::string log;
  const std::string csv = out + "/other_robot.csv";
  fs::create_directories(out);
  std::ofstream(csv) << "time,q_some_joint\n0,0\n";
  EXPECT_EQ(runRender("--log " + csv + " --at 0 --out " + out + " --chromium /no/such/chromium", out, log), 3) << log;
  EXPECT_NE(log.find("Chromium not found (/no/such/chromium)"), std::string::npos) << log;
  EXPECT_EQ(runRender("--log " + csv + " --at 0 --out " + out, out, log), 2) << log;
  EXPECT_NE(log.find("no column q_"), std::string::npos) << log;
  EXPECT_EQ(runRender("--log " + csv + " --at 0 --out " + out + " --tile 3x3", out, log), 2) << log;
  EXPECT_NE(log.find("--tile '3x3'"), std::string::npos) << log;
}

}  // namespace
