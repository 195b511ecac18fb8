// reflex_calibrate: stereo calibration of the user's own rig -> the ROS camera_info pair that
// reflex_vision reads (calibrate), conversion of an OpenCV stereoCalibrate file (convert), and a
// printable calibration board (board). Thin wrapper over reflex/vision/stereo_calibrate.hpp.
#include "reflex/common/run_main.hpp"
#include "reflex/common/files.hpp"
#include "reflex/vision/error.hpp"
#include "reflex/vision/stereo_calibrate.hpp"
#include "mount_kinematics.hpp"

#include <reflex/control/urdf_loader.hpp>

#include <CLI/CLI.hpp>

#include <opencv2/calib3d.hpp>
#include <opencv2/imgcodecs.hpp>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <regex>
#include <sstream>

namespace {
using namespace reflex::vision;
namespace fs = std::filesystem;

struct BoardArgs {
  std::string kind = "checkerboard";
  BoardSpec spec;
};

void addBoardOptions(CLI::App* app, BoardArgs& b) {
  app->add_option("--board", b.kind, "checkerboard, charuco or aprilgrid")->capture_default_str();
  app->add_option("--cols", b.spec.cols,
                  "checkerboard: inner corners along a row; charuco: squares along a row; aprilgrid: tags along a row")
      ->capture_default_str();
  app->add_option("--rows", b.spec.rows, "the same down a column")->capture_default_str();
  app->add_option("--square", b.spec.square,
                  "metres: checker/ChArUco square side; aprilgrid: edge of a tag's black square (measure the print)")
      ->capture_default_str();
  app->add_option("--marker", b.spec.marker, "charuco: ArUco marker side, metres");
  app->add_option("--dictionary", b.spec.dictionary, "charuco: OpenCV dictionary")->capture_default_str();
  app->add_option("--family", b.spec.family, "aprilgrid: AprilTag family")->capture_default_str();
  app->add_option("--spacing", b.spec.spacing,
                  "aprilgrid: gap between the black squares of neighbouring tags, metres (default: the two white "
                  "borders, a quarter of --square for tag36h11)");
  app->add_option("--first-id", b.spec.first_id, "aprilgrid: id of the top-left tag (ids run row by row)")
      ->capture_default_str();
}

BoardSpec boardFrom(const BoardArgs& b) {
  BoardSpec s = b.spec;
  s.kind = parseBoardKind(b.kind);
  validateBoard(s);
  return s;
}

// Throws naming `out` when it cannot be the output folder (a device, a FIFO, a file in its place; its
// parent missing) or when left.yaml / right.yaml in it are not regular files: before any work.
void checkOutputFolder(const std::string& out) {
  if (const std::string why = reflex::common::outputFolderProblem(out); !why.empty())
    throw VisionError("--out: " + why);
  std::error_code ec;
  if (!fs::is_directory(out, ec)) return;  // made later: nothing in it yet
  for (const char* name : {"left.yaml", "right.yaml"}) {
    if (const std::string why = reflex::common::regularOutputProblem((fs::path(out) / name).string()); !why.empty())
      throw VisionError("--out: " + why);
  }
}

// Creates the output folder (its parent must exist) and returns the two camera_info paths.
std::pair<std::string, std::string> outputPaths(const std::string& out) {
  checkOutputFolder(out);
  const fs::path dir(out);
  std::error_code ec;
  if (!fs::is_directory(dir, ec)) {
    const fs::path parent = dir.has_parent_path() ? dir.parent_path() : fs::path(".");
    if (!fs::is_directory(parent, ec))
      throw VisionError("--out '" + out + "': its parent folder '" + parent.string() + "' does not exist");
    if (!fs::create_directory(dir, ec)) throw VisionError("--out '" + out + "': cannot create it: " + ec.message());
  }
  return {(dir / "left.yaml").string(), (dir / "right.yaml").string()};
}

// Checks the pair as reflex_vision will (nothing is written if it would refuse it: the error says so,
// exit 3 for a calibration this tool computed, with what to try), writes it and loads it back with
// the reader reflex_vision uses; a pair that does not read back is removed and the error raised.
void writePair(const StereoCalibration& c, const std::string& out, bool computed) {
  try {
    validateStereoCalibration(c, "left camera", "right camera");
  } catch (const VisionError& e) {
    throw VisionError(std::string(computed ? "calibration rejected" : "conversion rejected") +
                      ": reflex_vision would refuse it, so nothing was written to '" + out + "': " + e.what() +
                      (computed ? " (try --fix-k3, more views that reach the image corners, or a lower "
                                  "--outlier-factor)"
                                : ""));
  }
  const auto [left, right] = outputPaths(out);
  saveCameraInfo(left, c.left);
  saveCameraInfo(right, c.right);
  try {
    (void)loadStereoCalibration(left, right);
  } catch (const VisionError&) {
    std::error_code ec;
    fs::remove(left, ec);
    fs::remove(right, ec);
    throw;
  }
  std::cout << "wrote " << left << " and " << right << "\n";
}

double degrees(double rad) { return rad * 180.0 / M_PI; }

void printCamera(const char* side, const CameraInfo& c) {
  std::printf("  %-5s fx %.2f  fy %.2f  cx %.2f  cy %.2f  (%s:", side, c.K(0, 0), c.K(1, 1), c.K(0, 2), c.K(1, 2),
              c.distortion_model.c_str());
  for (double d : c.D) std::printf(" %.5g", d);
  std::printf(")\n");
}

int runCalibrate(const BoardArgs& ba, const std::string& pairs, const std::string& session, int every,
                 const std::string& out, const StereoCalibrateOptions& opt, bool quiet) {
  const BoardSpec board = boardFrom(ba);
  if (pairs.empty() == session.empty()) throw VisionError("give exactly one input: --pairs DIR or --session DIR");
  if (every < 1) throw VisionError("--every " + std::to_string(every) + " must be at least 1");
  (void)outputPaths(out);  // a bad --out is an error before the (long) detection
  CalibrationImages images =
      pairs.empty() ? CalibrationImages::fromSession(session, every) : CalibrationImages::fromPairsFolder(pairs);
  std::vector<StereoView> views;
  cv::Size size;
  std::string name, first;
  cv::Mat l, r;
  int with_board = 0;
  while (images.next(name, l, r)) {
    if (size.area() == 0) {
      size = l.size();
      first = name;
    } else if (l.size() != size) {
      throw VisionError(name + " is " + std::to_string(l.cols) + "x" + std::to_string(l.rows) + " but " + first +
                        " is " + std::to_string(size.width) + "x" + std::to_string(size.height) +
                        ": every pair must have the same image size");
    }
    StereoView v;
    v.name = name;
    v.left = detectBoard(board, l);
    v.right = detectBoard(board, r);
    alignStereoPair(board, v.left, v.right);
    with_board += !v.left.ids.empty() && !v.right.ids.empty();
    if (!quiet)
      std::fprintf(stderr, "view %zu/%d %s: left %zu points, right %zu points\n", views.size() + 1, images.count(),
                   name.c_str(), v.left.ids.size(), v.right.ids.size());
    views.push_back(std::move(v));
  }
  if (views.empty()) throw VisionError("no image pairs read");
  if (with_board == 0)
    throw VisionError("no " + boardKindName(board.kind) + " board (" + std::to_string(board.cols) + " x " +
                      std::to_string(board.rows) + ") found in both images of any of the " +
                      std::to_string(views.size()) +
                      " pairs: check --board, --cols, --rows (checkerboard: INNER corners) and the lighting");
  const StereoCalibrateResult res = calibrateStereo(board, views, size, opt, [&](const std::string& s) {
    if (!quiet) std::fprintf(stderr, "%s\n", s.c_str());
  });

  std::printf("%-28s %6s %9s %9s %9s  %s\n", "view", "points", "rms_L_px", "rms_R_px", "epi_px", "status");
  for (const ViewReport& v : res.views) {
    if (v.dropped && v.rms_left == 0.0)
      std::printf("%-28s %6d %9s %9s %9s  dropped: %s\n", v.name.c_str(), v.points, "-", "-", "-", v.why.c_str());
    else
      std::printf("%-28s %6d %9.3f %9.3f %9s  %s\n", v.name.c_str(), v.points, v.rms_left, v.rms_right,
                  v.dropped ? "-" : cv::format("%.3f", v.epipolar_rms).c_str(),
                  v.dropped ? ("dropped: " + v.why).c_str() : "kept");
  }
  int kept = 0;
  for (const ViewReport& v : res.views) kept += !v.dropped;
  cv::Vec3d rvec;
  cv::Rodrigues(res.R, rvec);
  std::printf("\nviews: %d kept of %zu (%d calibration rounds)\n", kept, res.views.size(), res.rounds);
  std::printf("reprojection RMS: %.3f px (good: < 0.5 px)\n", res.rms);
  std::printf(
      "rectified epipolar error |y_L - y_R|: RMS %.3f px, max %.3f px (good: RMS < 0.5 px; "
      "reflex_vision rejects a tag above 2 px)\n",
      res.epipolar_rms, res.epipolar_max);
  printCamera("left", res.calibration.left);
  printCamera("right", res.calibration.right);
  std::printf("  baseline %.5f m, T = (%.5f, %.5f, %.5f) m, rotation between the cameras %.3f deg\n",
              res.calibration.baseline(), res.T[0], res.T[1], res.T[2], degrees(cv::norm(rvec)));
  std::printf("  rectified: fx' %.2f  cx'_L %.2f  cx'_R %.2f  cy' %.2f\n", res.calibration.left.P(0, 0),
              res.calibration.left.P(0, 2), res.calibration.right.P(0, 2), res.calibration.left.P(1, 2));
  writePair(res.calibration, out, true);
  return 0;
}

struct MountArgs {
  std::string urdf, collision, head_link = "head", hand_link, tag_point, observations, out, camera_link;
  MountOptions options;
};

cv::Vec3d rpyOf(const cv::Matx33d& R) {  // URDF convention: R = Rz(yaw) Ry(pitch) Rx(roll)
  return cv::Vec3d(std::atan2(R(2, 1), R(2, 2)), std::asin(std::max(-1.0, std::min(1.0, -R(2, 0)))),
                   std::atan2(R(1, 0), R(0, 0)));
}

cv::Matx33d toCv(const Eigen::Matrix3d& m) {
  cv::Matx33d r;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) r(i, j) = m(i, j);
  return r;
}

int runMount(const MountArgs& a) {
  std::vector<double> tp;
  {
    std::stringstream ss(a.tag_point);
    std::string c;
    while (std::getline(ss, c, ',')) {
      const double v = parseNumber(c, "--tag-point '" + a.tag_point + "'");
      if (std::abs(v) > 2.0)
        throw VisionError("--tag-point '" + a.tag_point + "': " + c + " m is more than 2 m from the hand link");
      tp.push_back(v);
    }
  }
  if (tp.size() != 3)
    throw VisionError("--tag-point '" + a.tag_point + "' must be X,Y,Z (metres, in the hand link frame)");
  reflex::control::Model model;
  try {
    model = reflex::control::loadModel(a.urdf, reflex::control::loadCollisionConfigFor(a.urdf, a.collision));
  } catch (const reflex::control::ModelError& e) {
    throw VisionError(e.what());
  }
  auto link = [&](const std::string& name, const char* option) {
    const int i = model.linkIndex(name);
    if (i < 0) throw VisionError(std::string(option) + " '" + name + "': no such link in " + a.urdf);
    return i;
  };
  MountKinematics k;
  k.model = &model;
  k.head_link = link(a.head_link, "--head-link");
  k.hand_link = link(a.hand_link, "--hand-link");
  k.p_hand = Eigen::Vector3d(tp[0], tp[1], tp[2]);
  const int camera_link = a.camera_link.empty() ? -1 : link(a.camera_link, "--camera-link");
  if (std::error_code ec;
      !fs::is_directory(fs::path(a.out).has_parent_path() ? fs::path(a.out).parent_path() : ".", ec))
    throw VisionError("--out '" + a.out + "': its folder does not exist");
  const std::vector<MountObservation> obs = readMountObservations(a.observations, k);
  const MountResult r =
      estimateCameraInHead(obs, a.options, [](const std::string& s) { std::fprintf(stderr, "%s\n", s.c_str()); });

  std::printf("%-20s %12s  %s\n", "view", "residual_mm", "status");
  for (const MountViewReport& v : r.views)
    std::printf("%-20s %12.2f  %s\n", v.name.c_str(), 1000.0 * v.residual,
                v.dropped ? ("dropped: " + v.why).c_str() : "kept");
  int kept = 0;
  for (const MountViewReport& v : r.views) kept += !v.dropped;
  const cv::Vec3d rpy = rpyOf(r.R_H_C);
  std::printf(
      "\nviews: %d kept of %zu; residual RMS %.2f mm, max %.2f mm (good: a few mm, about the stereo error at "
      "that distance)\n",
      kept, r.views.size(), 1000.0 * r.rms, 1000.0 * r.max);
  std::printf(
      "camera in %s (URDF origin of a fixed joint %s -> camera): xyz=\"%.5f %.5f %.5f\" rpy=\"%.5f %.5f %.5f\"\n",
      a.head_link.c_str(), a.head_link.c_str(), r.p_H_C[0], r.p_H_C[1], r.p_H_C[2], rpy[0], rpy[1], rpy[2]);
  const Eigen::Isometry3d X_B_H = linkPoseAtZero(model, k.head_link);
  CameraMount mount;
  mount.R_B_C = toCv(X_B_H.linear()) * r.R_H_C;
  const Eigen::Vector3d t = X_B_H.translation();
  mount.p_B_C = toCv(X_B_H.linear()) * r.p_H_C + cv::Vec3d(t.x(), t.y(), t.z());
  if (camera_link >= 0) {
    const Eigen::Isometry3d X_B_Cu = linkPoseAtZero(model, camera_link);
    const Eigen::Vector3d tc = X_B_Cu.translation();
    cv::Vec3d rv;
    cv::Rodrigues(mount.R_B_C * toCv(X_B_Cu.linear()).t(), rv);
    std::printf("against the URDF's %s: %.2f mm, %.3f deg apart\n", a.camera_link.c_str(),
                1000.0 * cv::norm(mount.p_B_C - cv::Vec3d(tc.x(), tc.y(), tc.z())), cv::norm(rv) * 180.0 / M_PI);
  }
  saveCameraMount(a.out, mount,
                  "measured by reflex_calibrate mount (" + std::to_string(kept) + " views, residual RMS " +
                      cv::format("%.2f", 1000.0 * r.rms) + " mm); every joint of " + model.name + " at zero");
  std::printf("wrote %s (the mount with every joint at zero, for reflex_vision --mount)\n", a.out.c_str());
  return 0;
}

cv::Size parseSize(const std::string& text) {
  if (text.empty()) return {};
  std::smatch m;
  if (!std::regex_match(text, m, std::regex(R"((\d{1,6})x(\d{1,6}))")))
    throw VisionError("--size '" + text + "' must be WIDTHxHEIGHT, e.g. 640x480");
  return cv::Size(std::stoi(m[1]), std::stoi(m[2]));
}

}  // namespace

/// The `mount` subcommand and its options.
CLI::App* addMountCommand(CLI::App& app, MountArgs& mount_args) {
  CLI::App* mnt = app.add_subcommand(
      "mount", "the camera in the head frame (and camera_mount.yaml) from a tag on a hand seen in several poses");
  mnt->add_option("--urdf", mount_args.urdf, "the robot's URDF (kinematics)")->required();
  mnt->add_option("--collision", mount_args.collision, "its collision YAML (default: next to the URDF, if any)");
  mnt->add_option("--head-link", mount_args.head_link, "link the cameras are fixed to")->capture_default_str();
  mnt->add_option("--hand-link", mount_args.hand_link, "link the tag is fixed to")->required();
  mnt->add_option("--tag-point", mount_args.tag_point, "the tag centre in the hand link frame: X,Y,Z metres")
      ->required();
  mnt->add_option("--observations", mount_args.observations,
                  "CSV: view,x_cam,y_cam,z_cam,<joint>,... (tag centre in the left optical frame, joint values)")
      ->required();
  mnt->add_option("--out", mount_args.out, "camera_mount.yaml to write (every joint at zero)")->required();
  mnt->add_option("--camera-link", mount_args.camera_link, "compare with this URDF frame (e.g. head_camera)");
  mnt->add_option("--outlier-factor", mount_args.options.outlier_factor,
                  "drop views whose residual exceeds this x the median (and 5 mm), refit")
      ->capture_default_str();
  mnt->add_option("--min-views", mount_args.options.min_views, "fewest usable views")->capture_default_str();
  return mnt;
}

/// `convert`: an OpenCV stereoCalibrate FileStorage file -> the camera_info pair in `out`.
int runConvert(const std::vector<std::string>& files, ConvertOptions copt, const std::string& size,
               const std::string& out) {
  copt.size = parseSize(size);
  std::string notes;
  const StereoCalibration c = convertOpenCvStereo(files, copt, notes);
  std::cout << notes;
  writePair(c, out, false);
  return 0;
}

/// `board`: a printable board image.
int runBoard(const BoardArgs& draw_board, int ppu, const std::string& board_out) {
  const BoardSpec b = boardFrom(draw_board);
  double mpp = 0.0;
  cv::Point2d origin;
  const cv::Mat img = drawBoard(b, ppu, mpp, origin);
  bool ok = false;
  try {
    ok = cv::imwrite(board_out, img);
  } catch (const cv::Exception& e) {
    throw VisionError("cannot write '" + board_out + "': " + e.err);
  }
  if (!ok) throw VisionError("cannot write '" + board_out + "' (missing folder, or not a .png name?)");
  std::printf(
      "wrote %s: %dx%d px; print it so that one %s measures %.4f m (%.4f mm per pixel), then measure "
      "the print and pass what you measure as --square\n",
      board_out.c_str(), img.cols, img.rows, b.kind == BoardKind::kAprilGrid ? "tag's black square" : "square",
      b.square, 1000.0 * mpp);
  return 0;
}

int main(int argc, char** argv) {
  CLI::App app{
      "reflex_calibrate: calibrate your own stereo camera for reflex_vision.\n"
      "  calibrate  stereo calibration from image pairs (--pairs DIR) or a recorded session (--session DIR) of a\n"
      "             checkerboard, ChArUco board or AprilTag grid; per-view reprojection errors, outlier views\n"
      "             dropped and named, the rectified epipolar error; writes OUT/left.yaml and OUT/right.yaml\n"
      "             (ROS camera_info, what --calib-left/--calib-right and session folders take)\n"
      "  convert    an OpenCV stereoCalibrate FileStorage file (M1 D1 M2 D2 R T [R1 R2 P1 P2]) -> the same pair\n"
      "  board      a printable board image (PNG) for the board options given\n"
      "  mount      the camera in the head frame and camera_mount.yaml, from a tag on a hand seen in several robot\n"
      "             poses (joint values + the tag centre measured by reflex_vision --dump) and the robot's URDF\n"
      "Exit: 0 done, 2 bad option or input (named), 3 calibration failed (too few views, stereoCalibrate "
      "failed, or a result reflex_vision would refuse: nothing is written then)."};
  app.require_subcommand(1);

  BoardArgs cal_board, draw_board;
  std::string pairs, session, cal_out;
  int every = 1;
  bool quiet = false;
  StereoCalibrateOptions opt;
  CLI::App* cal = app.add_subcommand("calibrate", "stereo calibration from image pairs or a session");
  addBoardOptions(cal, cal_board);
  cal->add_option("--pairs", pairs,
                  "folder of image pairs: left/ + right/ with equal names, or left*.png + right*.png");
  cal->add_option("--session", session, "recorded session folder (its two videos; no calibration needed)");
  cal->add_option("--every", every, "session: use every N-th pair")->capture_default_str();
  cal->add_option("--out", cal_out, "folder for left.yaml and right.yaml (created; its parent must exist)")->required();
  cal->add_option("--outlier-factor", opt.outlier_factor,
                  "drop views whose reprojection RMS exceeds this x the median (and --min-outlier-px), recalibrate")
      ->capture_default_str();
  cal->add_option("--min-outlier-px", opt.min_outlier_px, "never drop a view below this RMS, px")
      ->capture_default_str();
  cal->add_option("--min-views", opt.min_views, "fewest usable views")->capture_default_str();
  cal->add_option("--min-points", opt.min_points, "fewest points seen in both images for a view to count")
      ->capture_default_str();
  cal->add_option("--alpha", opt.alpha, "rectification free scaling: 0 valid pixels only, 1 all pixels")
      ->capture_default_str();
  cal->add_flag("--rational", opt.rational, "rational_polynomial distortion (8 coefficients) for wide-angle lenses");
  cal->add_flag("--fix-k3", opt.fix_k3, "keep k3 = 0 (few views, or a narrow lens)");
  cal->add_flag("--quiet", quiet, "no per-view progress");

  std::vector<std::string> conv_files;
  std::string conv_out, conv_size;
  ConvertOptions copt;
  CLI::App* conv = app.add_subcommand("convert", "OpenCV stereoCalibrate FileStorage file(s) -> camera_info pair");
  conv->add_option("FILE", conv_files, "FileStorage file(s): one with everything, or intrinsics.yml extrinsics.yml")
      ->required();
  conv->add_option("--out", conv_out, "folder for left.yaml and right.yaml (created; its parent must exist)")
      ->required();
  conv->add_option("--size", conv_size, "image size WIDTHxHEIGHT when the file holds none");
  conv->add_option("--alpha", copt.alpha, "rectification free scaling when the file has no R1 R2 P1 P2")
      ->capture_default_str();
  conv->add_option("--scale", copt.translation_scale, "multiplies T into metres (0.001 for millimetres)")
      ->capture_default_str();

  std::string board_out;
  int ppu = 100;
  CLI::App* draw = app.add_subcommand("board", "write a printable board image");
  addBoardOptions(draw, draw_board);
  draw->add_option("--out", board_out, "PNG file")->required();
  draw->add_option("--pixels", ppu, "pixels per square (checkerboard, charuco) or per tag cell (aprilgrid)")
      ->capture_default_str();

  MountArgs mount_args;
  CLI::App* mnt = addMountCommand(app, mount_args);

  if (const int code = reflex::parseCommandLine(app, argc, argv); code >= 0) return code;
  try {
    // Outputs first, before any image is read.
    if (mnt->parsed()) {
      if (const std::string why = reflex::common::regularOutputProblem(mount_args.out); !why.empty())
        throw VisionError("--out: " + why);
    }
    if (cal->parsed()) checkOutputFolder(cal_out);
    if (conv->parsed()) checkOutputFolder(conv_out);
    if (draw->parsed()) {
      if (const std::string why = reflex::common::regularOutputProblem(board_out); !why.empty())
        throw VisionError("--out: " + why);
    }
    if (mnt->parsed()) return runMount(mount_args);
    if (cal->parsed()) return runCalibrate(cal_board, pairs, session, every, cal_out, opt, quiet);
    if (conv->parsed()) return runConvert(conv_files, copt, conv_size, conv_out);
    if (draw->parsed()) return runBoard(draw_board, ppu, board_out);
  } catch (const VisionError& e) {
    const std::string what = e.what();
    std::cerr << "reflex_calibrate: error: " << what << "\n";
    return what.rfind("too few usable views", 0) == 0 || what.rfind("OpenCV stereoCalibrate", 0) == 0 ||
                   what.rfind("calibration rejected", 0) == 0
               ? 3
               : 2;
  } catch (const std::exception& e) {
    std::cerr << "reflex_calibrate: error: " << e.what() << "\n";
    return 2;
  }
  return 0;
}
