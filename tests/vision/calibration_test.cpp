// Tests of vision/include/reflex/vision/calibration.hpp and object_map.hpp: the ROS camera_info
// format (round trip, every error path), stereo consistency, the camera mount.
#include "reflex/vision/calibration.hpp"
#include "reflex/vision/error.hpp"
#include "reflex/vision/object_map.hpp"
#include "reflex/vision/session_maker.hpp"
#include "vision_test_util.hpp"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <regex>

using namespace reflex::vision;
using reflex::vision::test::errorOf;
using ::testing::AllOf;
using ::testing::HasSubstr;
using ::testing::Not;

namespace {

// A camera_info file as ROS camera_calibration writes it (values from a real-looking 640x480 rig).
const char* kLeft = R"(image_width: 640
image_height: 480
camera_name: narrow_stereo/left
camera_matrix:
  rows: 3
  cols: 3
  data: [501.2, 0, 318.7, 0, 500.9, 241.3, 0, 0, 1]
distortion_model: plumb_bob
distortion_coefficients:
  rows: 1
  cols: 5
  data: [-0.041, 0.013, 0.0004, -0.0002, 0]
rectification_matrix:
  rows: 3
  cols: 3
  data: [1, 0, 0, 0, 1, 0, 0, 0, 1]
projection_matrix:
  rows: 3
  cols: 4
  data: [495.0, 0, 320.0, 0, 0, 495.0, 240.0, 0, 0, 0, 1, 0]
)";

std::string rightFrom(const std::string& left) {
  std::string r = std::regex_replace(left, std::regex("narrow_stereo/left"), "narrow_stereo/right");
  return std::regex_replace(r, std::regex(R"(\[495.0, 0, 320.0, 0,)"), "[495.0, 0, 320.0, -29.7,");
}

}  // namespace

TEST(Calibration, ParsesRosCameraInfo) {
  const CameraInfo c = parseCameraInfo(kLeft, "left.yaml");
  EXPECT_EQ(c.image_size, cv::Size(640, 480));
  EXPECT_EQ(c.camera_name, "narrow_stereo/left");
  EXPECT_DOUBLE_EQ(c.K(0, 0), 501.2);
  EXPECT_DOUBLE_EQ(c.K(1, 2), 241.3);
  ASSERT_EQ(c.D.size(), 5u);
  EXPECT_DOUBLE_EQ(c.D[0], -0.041);
  EXPECT_DOUBLE_EQ(c.P(0, 0), 495.0);
}

TEST(Calibration, SaveLoadRoundTrip) {
  test::TempDir dir("calib");
  CameraInfo c = parseCameraInfo(kLeft, "left.yaml");
  saveCameraInfo(dir / "c.yaml", c);
  const CameraInfo d = loadCameraInfo(dir / "c.yaml");
  for (int i = 0; i < 9; ++i) EXPECT_DOUBLE_EQ(c.K.val[i], d.K.val[i]);
  for (int i = 0; i < 12; ++i) EXPECT_DOUBLE_EQ(c.P.val[i], d.P.val[i]);
  EXPECT_EQ(c.D, d.D);
  EXPECT_EQ(c.distortion_model, d.distortion_model);
}

TEST(Calibration, StereoBaselineFromProjection) {
  StereoCalibration s{parseCameraInfo(kLeft, "l"), parseCameraInfo(rightFrom(kLeft), "r")};
  EXPECT_NO_THROW(validateStereoCalibration(s, "l", "r"));
  EXPECT_NEAR(s.baseline(), 29.7 / 495.0, 1e-12);  // P[0][3] = -fx' * B
}

TEST(Calibration, ErrorsNameFileAndField) {
  auto bad = [](const std::string& from, const std::string& to) {
    return errorOf([&] { parseCameraInfo(std::regex_replace(kLeft, std::regex(from), to), "cam.yaml"); });
  };
  // wrong rows*cols vs data length
  EXPECT_THAT(bad(R"(data: \[501.2, 0, 318.7, 0, 500.9, 241.3, 0, 0, 1\])", "data: [501.2, 0, 318.7, 0, 500.9, 241.3]"),
              AllOf(HasSubstr("cam.yaml:"), HasSubstr("camera_matrix.data: has 6 numbers (value"),
                    HasSubstr("expected rows*cols = 3*3 numbers)")));
  // non-positive focal length
  EXPECT_THAT(bad("501.2", "-501.2"), AllOf(HasSubstr("cam.yaml"), HasSubstr("fx = -501.2")));
  EXPECT_THAT(bad(R"(\[495.0, 0, 320.0, 0, 0, 495.0)", "[0, 0, 320.0, 0, 0, 495.0"),
              AllOf(HasSubstr("projection_matrix"), HasSubstr("fx'")));
  // missing field
  EXPECT_THAT(bad("image_height: 480\n", ""), AllOf(HasSubstr("cam.yaml"), HasSubstr("image_height")));
  EXPECT_THAT(bad("rectification_matrix:", "rectification_matrixx:"),
              HasSubstr("rectification_matrix: missing (expected a 3x3 matrix {rows, cols, data})"));
  // unknown distortion model, wrong coefficient count
  EXPECT_THAT(bad("plumb_bob", "fisheye62"), HasSubstr("distortion_model: unknown distortion model (value 'fisheye62', "
                                                       "expected one of plumb_bob, rational_polynomial, equidistant)"));
  EXPECT_THAT(bad("plumb_bob", "rational_polynomial"),
              HasSubstr("distortion_coefficients.data: has 5 coefficients (value '[-0.041, 0.013, 0.0004, -0.0002, "
                        "0]', expected 8 for the distortion model 'rational_polynomial')"));
  // wrong shape
  EXPECT_THAT(bad("  rows: 3\n  cols: 4", "  rows: 4\n  cols: 3"),
              HasSubstr("projection_matrix: a 4x3 matrix (value '{rows: 4, cols: 3, data: "));
  // not a number, not a rotation, negative size, syntax
  EXPECT_THAT(bad("318.7", "abc"),
              HasSubstr("camera_matrix.data[2]: not a finite number (value 'abc', expected a list of finite numbers)"));
  EXPECT_THAT(bad(R"(data: \[1, 0, 0, 0, 1, 0, 0, 0, 1\])", "data: [2, 0, 0, 0, 1, 0, 0, 0, 1]"),
              HasSubstr("rectification_matrix.data: not a rotation (value '[2, 0, 0, 0, 1, 0, 0, 0, 1]', expected R "
                        "R^T = I and det > 0)"));
  EXPECT_THAT(bad("image_width: 640", "image_width: -640"),
              HasSubstr("image_width: out of range (value '-640', expected an integer in [16, 16384])"));
  EXPECT_THAT(bad("camera_matrix:", "camera_matrix: [oops"), HasSubstr("YAML syntax error"));
  EXPECT_THAT(errorOf([] { loadCameraInfo("/nonexistent/left.yaml"); }), HasSubstr("/nonexistent/left.yaml"));
}

TEST(Calibration, StereoInconsistenciesAreErrors) {
  const CameraInfo l = parseCameraInfo(kLeft, "l");
  const CameraInfo r = parseCameraInfo(rightFrom(kLeft), "r");
  StereoCalibration swapped{r, l};
  EXPECT_THAT(errorOf([&] { validateStereoCalibration(swapped, "L.yaml", "R.yaml"); }),
              AllOf(HasSubstr("L.yaml"), HasSubstr("left/right swapped")));
  StereoCalibration sizes{l, r};
  sizes.right.image_size = cv::Size(320, 240);
  EXPECT_THAT(errorOf([&] { validateStereoCalibration(sizes, "L.yaml", "R.yaml"); }),
              AllOf(HasSubstr("image sizes differ"), HasSubstr("640x480"), HasSubstr("320x240")));
  StereoCalibration focal{l, r};
  focal.right.P(0, 0) = 600.0;
  EXPECT_THAT(errorOf([&] { validateStereoCalibration(focal, "L.yaml", "R.yaml"); }),
              HasSubstr("rectified intrinsics differ"));
  StereoCalibration vertical{l, r};
  vertical.right.P(1, 3) = -10.0;
  EXPECT_THAT(errorOf([&] { validateStereoCalibration(vertical, "L.yaml", "R.yaml"); }), HasSubstr("horizontal"));
  // A mirrored solution (rectified focal lengths negative, P[0][3] = 0 on the left): named as what it
  // is, not as "P[0][3] = 0 must be 0" (the tolerance scaled by a negative focal length).
  StereoCalibration mirrored{l, r};
  for (CameraInfo* c : {&mirrored.left, &mirrored.right}) {
    c->P(0, 0) = -c->P(0, 0);
    c->P(1, 1) = -c->P(1, 1);
  }
  mirrored.right.P(0, 3) = -mirrored.right.P(0, 3);
  const std::string why = errorOf([&] { validateStereoCalibration(mirrored, "L.yaml", "R.yaml"); });
  EXPECT_THAT(why,
              AllOf(HasSubstr("L.yaml"), HasSubstr("rectified focal lengths fx' = -"), HasSubstr("must be positive")));
  EXPECT_THAT(why, Not(HasSubstr("must be 0")));
}

TEST(Calibration, RigCalibrationMatchesStereoRectifyConventions) {
  RigSpec rig;
  rig.right_rpy_deg = cv::Vec3d(0.3, -0.5, 0.2);
  const StereoCalibration c = rigCalibration(rig);
  EXPECT_NO_THROW(validateStereoCalibration(c, "l", "r"));
  EXPECT_NEAR(c.baseline(), 0.06, 1e-9);  // |T| = baseline
  EXPECT_DOUBLE_EQ(c.left.P(0, 3), 0.0);
}

// The shipped robot's mount is a file (no built-in default); it says what the
// README says. (That it is the URDF's head_camera frame at q = 0 is checked in mount_test.cpp.)
TEST(CameraMount, ShippedFileIsTheHeadLookingAhead) {
  const CameraMount m = reflex::vision::test::shippedMount();
  // The optical axis z_C looks along +x_B, image right x_C along -y_B, image down y_C along -z_B.
  EXPECT_EQ(m.toBase(cv::Vec3d(0, 0, 1)) - m.p_B_C, cv::Vec3d(1, 0, 0));
  EXPECT_EQ(m.toBase(cv::Vec3d(1, 0, 0)) - m.p_B_C, cv::Vec3d(0, -1, 0));
  EXPECT_EQ(m.toBase(cv::Vec3d(0, 1, 0)) - m.p_B_C, cv::Vec3d(0, 0, -1));
  EXPECT_EQ(m.p_B_C, cv::Vec3d(0.08, 0.03, 1.15));
}

// A scene script must name its mount (no default).
TEST(CameraMount, SceneScriptWithoutMountIsRefused) {
  const std::string script = reflex::vision::test::nearScript(1.0);
  EXPECT_NO_THROW(parseSceneScript(script, "s.yaml"));
  const std::string without = std::regex_replace(script, std::regex("  mount:[^\n]*\n(    [^\n]*\n)*"), "");
  EXPECT_THAT(
      errorOf([&] { parseSceneScript(without, "s.yaml"); }),
      AllOf(HasSubstr("s.yaml:"), HasSubstr(": rig.mount: missing (expected the left camera in the robot base frame"),
            HasSubstr("bringup/vision/camera_mount.yaml")));
  const std::string no_rig = std::regex_replace(script, std::regex("rig:\n(  [^\n]*\n)*"), "");
  EXPECT_THAT(errorOf([&] { parseSceneScript(no_rig, "s.yaml"); }),
              HasSubstr(": rig: missing (expected a map {image_size, left, right, baseline, right_rpy_deg, mount})"));
}

TEST(CameraMount, ParseAndErrors) {
  const CameraMount m =
      parseCameraMount("translation: [0.1, 0.0, 1.0]\nrotation_matrix: [0,0,1, -1,0,0, 0,-1,0]\n", "mount.yaml");
  EXPECT_EQ(m.p_B_C, cv::Vec3d(0.1, 0.0, 1.0));
  EXPECT_THAT(
      errorOf([] { parseCameraMount("translation: [0.1, 0.0]\nrotation_matrix: [1,0,0,0,1,0,0,0,1]", "m.yaml"); }),
      HasSubstr("m.yaml:1:14: translation: has 2 numbers (value '[0.1, 0.0]', expected a list of 3 finite numbers)"));
  EXPECT_THAT(
      errorOf([] { parseCameraMount("translation: [0, 0, 1]\nrotation_matrix: [1,0,0,0,1,0,0,0,-1]", "m.yaml"); }),
      HasSubstr("m.yaml:2:18: rotation_matrix: not a rotation (value '[1, 0, 0, 0, 1, 0, 0, 0, -1]', expected R R^T = "
                "I within 1e-5 and det > 0)"));
  EXPECT_THAT(errorOf([] { parseCameraMount("translation: [0, 0, 1]\n", "m.yaml"); }),
              HasSubstr("m.yaml:1:1: rotation_matrix: missing (expected 9 numbers, row-major)"));
}

TEST(ObjectMap, ParseAndErrors) {
  const ObjectMap m = parseObjectMap(
      "family: tag36h11\nobjects:\n  - {id: 0, name: cup, size: 0.06}\n"
      "  - {id: 3, name: can, size: 0.05}\n",
      "objects.yaml");
  ASSERT_NE(m.find(3), nullptr);
  EXPECT_EQ(m.find(3)->name, "can");
  EXPECT_EQ(m.find(1), nullptr);
  EXPECT_EQ(m.findByName("cup")->tag_id, 0);
  EXPECT_THAT(errorOf([] {
                parseObjectMap("objects:\n  - {id: 0, name: a, size: 0.06}\n  - {id: 0, name: b, size: 0.06}\n",
                               "o.yaml");
              }),
              AllOf(HasSubstr("o.yaml"), HasSubstr("duplicate tag id")));
  EXPECT_THAT(errorOf([] { parseObjectMap("objects:\n  - {id: 0, name: a, size: -1}\n", "o.yaml"); }),
              HasSubstr("o.yaml:2:28: objects[0].size: out of range (value '-1', expected a number in [0.002, 5] m "
                        "(edge of the black square))"));
  EXPECT_THAT(errorOf([] { parseObjectMap("objects:\n  - {id: 0, size: 0.06}\n", "o.yaml"); }),
              HasSubstr("o.yaml:2:5: objects[0].name: missing (expected the object's name)"));
  EXPECT_THAT(errorOf([] { parseObjectMap("family: tag36h11\n", "o.yaml"); }),
              HasSubstr("o.yaml:1:1: objects: missing (expected a list of {id, name, size})"));
}

// Values no physical camera has, each refused with the file, field, value and
// range (the ranges are CalibrationLimits / ObjectMap::kMin/kMaxTagSize, documented in
// vision/README.md). Each of these parsed without error before.
TEST(Calibration, PhysicallyImpossibleValuesAreRefused) {
  auto bad = [](const std::string& from, const std::string& to) {
    return errorOf([&] { parseCameraInfo(std::regex_replace(kLeft, std::regex(from), to), "cam.yaml"); });
  };
  EXPECT_EQ(bad("xxx", "xxx"), "no error");
  // focal length against the 640 px width: [32, 32000] px
  EXPECT_THAT(
      bad("501.2", "0.001"),
      AllOf(HasSubstr("cam.yaml:"), HasSubstr(": camera_matrix.data: focal length fx = 0.001 px is out of range"),
            HasSubstr("[32, 32000]")));
  EXPECT_THAT(bad("501.2", "1e9"), HasSubstr("fx = 1000000000 px"));
  EXPECT_EQ(bad("501.2, 0, 318.7, 0, 500.9", "32, 0, 318.7, 0, 32"), "no error");  // the limit itself is accepted
  // pixel aspect fy/fx in [0.25, 4]
  EXPECT_THAT(bad("500.9", "50000"), AllOf(HasSubstr("fy = 50000 px"), HasSubstr("pixel aspect")));
  // principal point inside the image, K and P
  EXPECT_THAT(bad("318.7", "-5"), AllOf(HasSubstr("principal point"), HasSubstr("(-5, 241.3)"), HasSubstr("640x480")));
  EXPECT_THAT(bad("241.3", "481"), HasSubstr("principal point (cx, cy) = (318.7, 481)"));
  EXPECT_THAT(bad(R"(495.0, 240.0, 0)", "495.0, 9000, 0"),
              AllOf(HasSubstr("projection_matrix"), HasSubstr("(cx', cy') = (320, 9000)")));
  EXPECT_THAT(bad(R"(\[495.0, 0, 320.0, 0, 0, 495.0)", "[1e7, 0, 320.0, 0, 0, 1e7"),
              AllOf(HasSubstr("projection_matrix"), HasSubstr("fx' = 10000000 px")));
  // P's last row
  EXPECT_THAT(bad("0, 0, 1, 0]", "0, 0, 2, 0]"), HasSubstr("projection_matrix.data: last row is not [0, 0, 1, 0]"));
  // image size
  EXPECT_THAT(bad("image_width: 640", "image_width: 4"),
              HasSubstr("image_width: out of range (value '4', expected an integer in [16, 16384])"));
  EXPECT_THAT(bad("image_height: 480", "image_height: 100000"),
              HasSubstr("image_height: out of range (value '100000'"));
}

TEST(Calibration, BaselineOutsideThePhysicalRangeIsRefused) {
  const CameraInfo l = parseCameraInfo(kLeft, "l");
  CameraInfo r = parseCameraInfo(rightFrom(kLeft), "r");
  EXPECT_NO_THROW(validateStereoCalibration({l, r}, "L.yaml", "R.yaml"));  // 6 cm
  for (const double baseline : {1e-9, 5e-4, 11.0, 1e5}) {
    r.P(0, 3) = -r.P(0, 0) * baseline;
    EXPECT_THAT(errorOf([&] {
                  validateStereoCalibration({l, r}, "L.yaml", "R.yaml");
                }),
                AllOf(HasSubstr("R.yaml"), HasSubstr("baseline"), HasSubstr("[0.001, 10] m")))
        << baseline;
  }
  r.P(0, 3) = -r.P(0, 0) * 0.0011;
  EXPECT_NO_THROW(validateStereoCalibration({l, r}, "L.yaml", "R.yaml"));
}

TEST(ObjectMap, ImpossibleTagSizesAndEmptyMapsAreRefused) {
  for (const char* size : {"1e-6", "0.0019", "5.1", "1e6"})
    EXPECT_THAT(
        errorOf([&] { parseObjectMap(std::string("objects:\n  - {id: 0, name: a, size: ") + size + "}\n", "o.yaml"); }),
        HasSubstr(std::string("o.yaml:2:28: objects[0].size: out of range (value '") + size +
                  "', expected a number in [0.002, 5] m (edge of the black square))"))
        << size;
  EXPECT_NO_THROW(parseObjectMap("objects:\n  - {id: 0, name: a, size: 0.002}\n  - {id: 1, name: b, size: 5}\n", "o"));
  EXPECT_THAT(errorOf([] { parseObjectMap("objects: []\n", "o.yaml"); }),
              HasSubstr("o.yaml:1:10: objects: the list is empty (no tag would ever be reported) (value '[]', expected "
                        "at least one object)"));
}

// A distortion no lens has leaves the rectified image black (zero detections).
// Independent answer: with k1 = +-1e6 a ray 0.1 rad off-axis lands ~1e3 * f px away, so nearly no
// rectified pixel sees the raw image; a real plumb_bob lens (kLeft) keeps the whole image.
TEST(Calibration, DistortionNoLensHasIsRefused) {
  const CameraInfo l = parseCameraInfo(kLeft, "l");
  const CameraInfo r = parseCameraInfo(rightFrom(kLeft), "r");
  for (const double k1 : {1e6, -1e6}) {
    StereoCalibration c{l, r};
    c.left.D[0] = k1;
    EXPECT_THAT(errorOf([&] { validateStereoCalibration(c, "L.yaml", "R.yaml"); }),
                AllOf(HasSubstr("L.yaml"), HasSubstr("% of the rectified image"), HasSubstr("at least 25 %")))
        << k1;
  }
  StereoCalibration fine{l, r};
  fine.right.D[0] = -0.3;  // a strong but real barrel distortion
  EXPECT_NO_THROW(validateStereoCalibration(fine, "L.yaml", "R.yaml"));
}

TEST(CameraMount, AMountFarFromTheRobotIsRefused) {
  EXPECT_THAT(errorOf([] {
                parseCameraMount("translation: [0.1, 1e6, 1.0]\nrotation_matrix: [0,0,1, -1,0,0, 0,-1,0]\n", "m.yaml");
              }),
              AllOf(HasSubstr("m.yaml"), HasSubstr("translation[1] = 1000000 m"), HasSubstr("10 m")));
  EXPECT_NO_THROW(parseCameraMount("translation: [0.1, -9.9, 1.0]\nrotation_matrix: [0,0,1, -1,0,0, 0,-1,0]\n", "m"));
}
