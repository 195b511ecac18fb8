// Tests of the camera mount: estimateCameraInHead (stereo_calibrate.hpp) and
// `reflex_calibrate mount` against a KNOWN camera-in-head transform, and the shipped robot's
// mount file against the shipped URDF.
//
// Independent answers: a camera-in-head transform chosen here (the URDF's head_camera frame moved
// by 7 mm and turned by ~2.7 deg, so that the URDF cannot give the answer away); the tag points the
// camera "measures" are that transform applied to points the robot's forward kinematics
// (reflex::control, the controller's own FK) puts on the hand for random joint values, plus 1 mm
// noise. The shipped bringup/vision/camera_mount.yaml must be the URDF's head_camera frame at q = 0.
#include "reflex/vision/calibration.hpp"
#include "reflex/vision/error.hpp"
#include "reflex/vision/stereo_calibrate.hpp"
#include "vision_test_util.hpp"

#include <reflex/control/kinematics.hpp>
#include <reflex/control/urdf_loader.hpp>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <opencv2/calib3d.hpp>

#include <sys/wait.h>

#include <cmath>
#include <cstdlib>
#include <fstream>

using namespace reflex::vision;
using reflex::vision::test::TempDir;
using ::testing::HasSubstr;

namespace {

const std::string kUrdf = std::string(REFLEX_SOURCE_DIR) + "/bringup/robots/asimo_like.urdf";

reflex::control::Model robot() {
  return reflex::control::loadModel(kUrdf, reflex::control::loadCollisionConfigFor(kUrdf, ""));
}

cv::Matx33d rotCv(const Eigen::Matrix3d& m) {
  cv::Matx33d r;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) r(i, j) = m(i, j);
  return r;
}

cv::Vec3d vecCv(const Eigen::Vector3d& v) { return cv::Vec3d(v.x(), v.y(), v.z()); }

double angleDeg(const cv::Matx33d& a, const cv::Matx33d& b) {
  cv::Vec3d r;
  cv::Rodrigues(a * b.t(), r);
  return cv::norm(r) * 180.0 / M_PI;
}

int runCalibrate(const std::string& args, std::string& out, std::string& err) {
  TempDir tmp("mcli");
  const std::string cmd =
      std::string(REFLEX_BIN_DIR) + "/reflex_calibrate " + args + " > " + (tmp / "out") + " 2> " + (tmp / "err");
  const int rc = std::system(cmd.c_str());
  out = test::readText(tmp / "out");
  err = test::readText(tmp / "err");
  return WIFEXITED(rc) ? WEXITSTATUS(rc) : -1;
}

// The true camera in the head frame: the URDF's head_camera moved and turned.
struct TrueMount {
  cv::Matx33d R_H_C;
  cv::Vec3d p_H_C;
};

TrueMount trueMount(const reflex::control::Model& m) {
  reflex::control::KinematicsData d(m);
  reflex::control::computeForwardKinematics(m, d, Eigen::VectorXd::Zero(m.nq));
  const Eigen::Isometry3d X_H_Cu = d.X_B_L[static_cast<std::size_t>(m.linkIndex("head"))].inverse() *
                                   d.X_B_L[static_cast<std::size_t>(m.linkIndex("head_camera"))];
  cv::Matx33d turn;
  cv::Rodrigues(cv::Vec3d(0.035, -0.026, 0.018), turn);  // ~2.7 deg
  return {rotCv(X_H_Cu.linear()) * turn, vecCv(X_H_Cu.translation()) + cv::Vec3d(0.005, -0.004, 0.003)};
}

const char* const kJoints[] = {"neck_yaw",       "neck_pitch", "l_shoulder_pitch", "l_shoulder_roll",
                               "l_shoulder_yaw", "l_elbow",    "l_wrist"};

// Rows "view,x_cam,y_cam,z_cam,<joints>" for random poses in which the camera sees the tag point
// (0.2-1.2 m ahead, inside a ~60 x 48 deg view); 1 mm noise; row `outlier` moved by 5 cm.
std::string observationsCsv(const reflex::control::Model& m, const TrueMount& t, const Eigen::Vector3d& p_hand, int n,
                            int outlier, std::vector<MountObservation>* exact = nullptr) {
  cv::RNG rng(5);
  reflex::control::KinematicsData d(m);
  std::ostringstream os;
  os << "view,x_cam,y_cam,z_cam";
  for (const char* j : kJoints) os << "," << j;
  os << "\n";
  int rows = 0;
  for (int tries = 0; rows < n && tries < 200000; ++tries) {
    Eigen::VectorXd q = Eigen::VectorXd::Zero(m.nq);
    std::vector<double> v = {rng.uniform(-0.5, 0.5), rng.uniform(-0.3, 0.5), rng.uniform(-1.6, 0.3),
                             rng.uniform(-0.2, 1.0), rng.uniform(-0.8, 0.8), rng.uniform(-1.8, -0.1),
                             rng.uniform(-0.8, 0.8)};
    for (std::size_t i = 0; i < v.size(); ++i) q[m.qIndex(kJoints[i])] = v[i];
    reflex::control::computeForwardKinematics(m, d, q);
    const Eigen::Vector3d p_B = d.X_B_L[static_cast<std::size_t>(m.linkIndex("l_hand"))] * p_hand;
    const cv::Vec3d p_H = vecCv(d.X_B_L[static_cast<std::size_t>(m.linkIndex("head"))].inverse() * p_B);
    cv::Vec3d p_C = t.R_H_C.t() * (p_H - t.p_H_C);
    if (p_C[2] < 0.2 || p_C[2] > 1.2 || std::abs(p_C[0]) > 0.55 * p_C[2] || std::abs(p_C[1]) > 0.42 * p_C[2]) continue;
    if (exact) exact->push_back({"v" + std::to_string(rows), p_C, p_H});
    p_C += cv::Vec3d(rng.gaussian(0.001), rng.gaussian(0.001), rng.gaussian(0.001));
    if (rows == outlier) p_C += cv::Vec3d(0.03, -0.03, 0.03);
    os << (rows == outlier ? "moved_tag" : "pose_" + std::to_string(rows)) << ","
       << cv::format("%.6f,%.6f,%.6f", p_C[0], p_C[1], p_C[2]);
    for (double x : v) os << "," << cv::format("%.6f", x);
    os << "\n";
    ++rows;
  }
  EXPECT_EQ(rows, n);
  return os.str();
}

}  // namespace

// The shipped mount file is the shipped URDF's head_camera frame with every joint at zero.
TEST(Mount, ShippedMountFileIsTheUrdfHeadCamera) {
  const reflex::control::Model m = robot();
  reflex::control::KinematicsData d(m);
  reflex::control::computeForwardKinematics(m, d, Eigen::VectorXd::Zero(m.nq));
  const Eigen::Isometry3d X_B_C = d.X_B_L[static_cast<std::size_t>(m.linkIndex("head_camera"))];
  const CameraMount shipped = test::shippedMount();
  EXPECT_LT(cv::norm(shipped.p_B_C - vecCv(X_B_C.translation())), 1e-6);
  EXPECT_LT(angleDeg(shipped.R_B_C, rotCv(X_B_C.linear())), 0.01);  // the URDF writes pi/2 as 1.5708
}

// Exact correspondences give the transform back exactly; points on a line are refused; too few views.
TEST(Mount, RegistrationIsExactOnExactDataAndRefusesDegenerateData) {
  const reflex::control::Model m = robot();
  const TrueMount t = trueMount(m);
  std::vector<MountObservation> exact;
  (void)observationsCsv(m, t, Eigen::Vector3d(0, 0, -0.05), 12, -1, &exact);
  const MountResult r = estimateCameraInHead(exact, MountOptions{});
  EXPECT_LT(angleDeg(r.R_H_C, t.R_H_C), 1e-6);
  EXPECT_LT(cv::norm(r.p_H_C - t.p_H_C), 1e-9);
  EXPECT_LT(r.rms, 1e-9);
  std::vector<MountObservation> line;
  for (int i = 0; i < 8; ++i)
    line.push_back({"l" + std::to_string(i), cv::Vec3d(0, 0, 0.3 + 0.05 * i), cv::Vec3d(0.3 + 0.05 * i, 0, 0)});
  EXPECT_THROW(
      {
        try {
          estimateCameraInHead(line, MountOptions{});
        } catch (const VisionError& e) {
          EXPECT_THAT(std::string(e.what()), HasSubstr("not on one line"));
          throw;
        }
      },
      VisionError);
  exact.resize(4);
  EXPECT_THROW(estimateCameraInHead(exact, MountOptions{}), VisionError);
}

// reflex_calibrate mount end to end: 30 noisy views (1 mm per axis) and one with the tag moved by
// 5 cm: the camera within 2 mm and 0.5 deg (the hand's points fill a small region ~0.5 m from the
// camera, so a small turn about them trades against a shift: 1 mm noise leaves ~0.3 deg), the moved
// view dropped and named, camera_mount.yaml (every joint at zero) equal to the true head-zero mount
// and loadable by vision.
TEST(Mount, CliRecoversTheKnownMountAndDropsTheMovedTag) {
  const reflex::control::Model m = robot();
  const TrueMount t = trueMount(m);
  TempDir d("mount");
  const Eigen::Vector3d p_hand(0.0, 0.0, -0.05);
  test::writeText(d / "obs.csv", observationsCsv(m, t, p_hand, 31, 7));
  std::string out, err;
  const std::string base =
      "mount --urdf " + kUrdf + " --hand-link l_hand --tag-point 0,0,-0.05 --camera-link head_camera";
  ASSERT_EQ(runCalibrate(base + " --observations " + (d / "obs.csv") + " --out " + (d / "camera_mount.yaml"), out, err),
            0)
      << out << err;
  std::printf("%s", out.c_str());
  EXPECT_THAT(out, HasSubstr("moved_tag"));
  EXPECT_THAT(out, HasSubstr("dropped: outlier"));
  EXPECT_THAT(out, HasSubstr("views: 30 kept of 31"));
  const CameraMount got = loadCameraMount(d / "camera_mount.yaml");
  reflex::control::KinematicsData kd(m);
  reflex::control::computeForwardKinematics(m, kd, Eigen::VectorXd::Zero(m.nq));
  const Eigen::Isometry3d X_B_H = kd.X_B_L[static_cast<std::size_t>(m.linkIndex("head"))];
  const cv::Matx33d R_B_C = rotCv(X_B_H.linear()) * t.R_H_C;
  const cv::Vec3d p_B_C = rotCv(X_B_H.linear()) * t.p_H_C + vecCv(X_B_H.translation());
  EXPECT_LT(cv::norm(got.p_B_C - p_B_C), 0.002);
  EXPECT_LT(angleDeg(got.R_B_C, R_B_C), 0.5);
  std::printf("mount error: %.3f mm, %.4f deg\n", 1000.0 * cv::norm(got.p_B_C - p_B_C), angleDeg(got.R_B_C, R_B_C));

  // Bad inputs are named.
  EXPECT_EQ(runCalibrate(base + " --observations " + (d / "nope.csv") + " --out " + (d / "m.yaml"), out, err), 2);
  EXPECT_THAT(err, HasSubstr("nope.csv"));
  test::writeText(d / "bad.csv", "view,x_cam,y_cam,z_cam,neck_yaww\na,0,0,1,0\n");
  EXPECT_EQ(runCalibrate(base + " --observations " + (d / "bad.csv") + " --out " + (d / "m.yaml"), out, err), 2);
  EXPECT_THAT(err, HasSubstr("column 'neck_yaww'"));
  test::writeText(d / "bad.csv", "view,x_cam,y_cam,neck_yaw\na,0,0,1\n");
  EXPECT_EQ(runCalibrate(base + " --observations " + (d / "bad.csv") + " --out " + (d / "m.yaml"), out, err), 2);
  EXPECT_THAT(err, HasSubstr("missing column 'z_cam'"));
  test::writeText(d / "bad.csv", "view,x_cam,y_cam,z_cam\na,0,zero,1\n");
  EXPECT_EQ(runCalibrate(base + " --observations " + (d / "bad.csv") + " --out " + (d / "m.yaml"), out, err), 2);
  EXPECT_THAT(err, HasSubstr("line 2, y_cam: 'zero' is not a finite number"));
  EXPECT_EQ(runCalibrate("mount --urdf " + kUrdf + " --hand-link l_paw --tag-point 0,0,0 --observations " +
                             (d / "obs.csv") + " --out " + (d / "m.yaml"),
                         out, err),
            2);
  EXPECT_THAT(err, HasSubstr("--hand-link 'l_paw': no such link"));
  EXPECT_EQ(runCalibrate("mount --urdf " + kUrdf + " --hand-link l_hand --tag-point 0,0 --observations " +
                             (d / "obs.csv") + " --out " + (d / "m.yaml"),
                         out, err),
            2);
  EXPECT_THAT(err, HasSubstr("--tag-point '0,0'"));
  EXPECT_EQ(runCalibrate(base + " --observations " + (d / "obs.csv") + " --out /no/such/dir/m.yaml", out, err), 2);
  EXPECT_THAT(err, HasSubstr("/no/such/dir/m.yaml"));
}
