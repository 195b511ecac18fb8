#pragma once
// Stereo calibration of the user's own rig (the library behind `reflex_calibrate`):
// calibration boards (checkerboard, ChArUco, AprilTag grid), their detection in image pairs, OpenCV
// calib3d stereo calibration with per-view reprojection errors and named outlier views, the
// rectified epipolar error, and the conversion of an OpenCV `stereoCalibrate` FileStorage file.
// The result is a StereoCalibration (the ROS camera_info pair, calibration.hpp) that vision reads.
//
// Frames and units: the board frame has its origin at the board's first corner (checkerboard: the
// first inner corner; ChArUco: the outer top-left corner of the squares; AprilTag grid: the top-left
// corner of the black square of the first tag), x along a row (to the right on the printed board),
// y down the columns, z into the board; metres. Pixels: OpenCV's convention (integer = pixel centre).
// Left camera = reference: R, T take left-camera points to right-camera points, p_R = R p_L + T, so a
// right camera to the right of the left one has T[0] < 0 and baseline |T|.
// Errors: bad setup (a board size, a file, too few views) throws VisionError naming the value.
#include "reflex/vision/calibration.hpp"

#include <opencv2/core.hpp>
#include <opencv2/videoio.hpp>

#include <functional>
#include <memory>
#include <map>
#include <string>
#include <vector>

namespace reflex::vision {

enum class BoardKind { kCheckerboard, kCharuco, kAprilGrid };

/// A planar calibration board. Sizes in metres.
///  - checkerboard: `cols` x `rows` INNER corners (a board of (cols+1) x (rows+1) squares), `square`
///    the side of a square;
///  - charuco: `cols` x `rows` SQUARES, `square` their side, `marker` the ArUco marker side
///    (< square), `dictionary` an OpenCV predefined dictionary (DICT_4X4_50, DICT_5X5_100, ...); the
///    board OpenCV's `aruco::CharucoBoard::create` makes (markers in the white squares, ids from 0);
///  - aprilgrid: `cols` x `rows` AprilTags of `family`, ids `first_id`, `first_id`+1, ... row by row
///    from the top left; `square` the edge of a tag's black square, `spacing` the gap between the
///    black squares of neighbouring tags (at least two cells, so that the white borders fit).
struct BoardSpec {
  BoardKind kind = BoardKind::kCheckerboard;
  int cols = 9;
  int rows = 6;
  double square = 0.025;
  double marker = 0.0;
  double spacing = 0.0;
  std::string dictionary = "DICT_4X4_50";
  std::string family = "tag36h11";
  int first_id = 0;
};

/// "checkerboard", "charuco", "aprilgrid" -> kind; throws VisionError listing the names.
BoardKind parseBoardKind(const std::string& name);
std::string boardKindName(BoardKind kind);
/// Throws VisionError naming the field and value for an impossible board (sizes <= 0, fewer than
/// 2 x 2 corners, marker >= square, spacing too small for the tag borders, unknown dictionary or
/// family, ids beyond the family).
void validateBoard(const BoardSpec& board);

/// Every point of the board a detector can report, by id, in the board frame (z = 0), metres.
/// Ids: checkerboard r * cols + c (inner corners, row-major); charuco OpenCV's corner ids;
/// aprilgrid 4 * tag_index + k with k the libapriltag corner order (see tag_detector.hpp).
std::map<int, cv::Point3f> boardPoints(const BoardSpec& board);

/// The board as a printable grey image (CV_8U, 0 black, 255 white) with `pixels_per_square` pixels
/// per checker/ChArUco square or per AprilTag cell (tag edge / cells across the black border) and a
/// white margin of one square (cell). `metres_per_pixel` receives the scale; board point (0, 0)
/// lies at pixel `origin_px` (pixel-corner coordinates: the top-left pixel spans [0, 1)).
cv::Mat drawBoard(const BoardSpec& board, int pixels_per_unit, double& metres_per_pixel, cv::Point2d& origin_px);

/// The board points found in one image: parallel vectors, ids ascending.
struct BoardObservation {
  std::vector<int> ids;
  std::vector<cv::Point2f> pixels;
};

/// Finds the board in an 8-bit grey or BGR image. Checkerboard: all inner corners or none
/// (findChessboardCornersSB, else findChessboardCorners + cornerSubPix); ChArUco: the interpolated
/// corners with at least two neighbouring markers; aprilgrid: the corners of every decoded tag of
/// the grid (libapriltag). An image without the board gives an empty observation (never throws for
/// image contents; throws VisionError for an empty image).
BoardObservation detectBoard(const BoardSpec& board, const cv::Mat& image);

/// A checkerboard looks the same turned by 180 degrees, so each image's corner order is a guess
/// (detectBoard: first corner nearer the image's top-left). For a board seen diagonally, or turned
/// about 45 degrees in the image, the two cameras of a rig can guess differently, and every corner
/// would be matched with the opposite one. The two cameras see the board nearly the same way: when
/// the first-to-last corner directions of the two images point apart (negative dot product), the
/// right list is reversed. Other boards (ids from the board itself) and partial views are left as
/// they are.
void alignStereoPair(const BoardSpec& board, const BoardObservation& left, BoardObservation& right);

/// One stereo view: the same board seen by both cameras at the same time.
struct StereoView {
  std::string name;  ///< shown in reports ("pair_012.png", "frame 340")
  BoardObservation left, right;
};

struct StereoCalibrateOptions {
  /// A view is an outlier when its reprojection RMS exceeds outlier_factor x the median of all
  /// views AND min_outlier_px; outliers are dropped and the rig recalibrated until none is left.
  double outlier_factor = 3.0;
  double min_outlier_px = 0.25;
  int min_views = 6;      ///< fewer usable views (after dropping) is an error
  int min_points = 6;     ///< a view needs at least this many points seen in both images
  double alpha = 0.0;     ///< stereoRectify free scaling: 0 = only valid pixels (ROS default), 1 = all
  bool rational = false;  ///< rational_polynomial (8 coefficients) instead of plumb_bob (5)
  bool fix_k3 = false;    ///< keep the plumb_bob k3 at 0 (few views or a narrow lens)
};

struct ViewReport {
  std::string name;
  int points = 0;         ///< points seen in both images
  double rms_left = 0.0;  ///< reprojection RMS in the left image, px (last calibration it was in)
  double rms_right = 0.0;
  double epipolar_rms = 0.0;  ///< |y_left - y_right| RMS of its points after rectification, px (kept views)
  bool dropped = false;
  std::string why;  ///< why it was dropped (empty if kept)
};

struct StereoCalibrateResult {
  StereoCalibration calibration;  ///< the camera_info pair (K, D, R = R1/R2, P = P1/P2)
  cv::Matx33d R;                  ///< p_R = R p_L + T (stereoCalibrate)
  cv::Vec3d T;                    ///< metres
  double rms = 0.0;               ///< joint reprojection RMS of the kept views, px (stereoCalibrate's)
  double epipolar_rms = 0.0;      ///< |y_L - y_R| over every kept point after rectification, px
  double epipolar_max = 0.0;
  int rounds = 0;                 ///< calibrations run (1 + rounds that dropped views)
  std::vector<ViewReport> views;  ///< every view given, in order, kept or dropped
};

/// Progress and round messages ("round 2: dropped pair_07 (2.31 px > 3 x median 0.12 px)").
using CalibrateLog = std::function<void(const std::string&)>;

/// Calibrates the stereo rig from the views (image size of both cameras: `image_size`). Each camera
/// alone first (calibrateCamera, for the initial intrinsics), then jointly (stereoCalibrate with the
/// intrinsics as a guess), per-view errors, outliers dropped and named, repeated; then stereoRectify
/// (CALIB_ZERO_DISPARITY, `alpha`) gives R1, R2, P1, P2 and the epipolar error is measured on the
/// kept views' points (undistortPoints into the rectified images). Views with fewer than
/// `min_points` common points are dropped up front (named). Throws VisionError when fewer than
/// `min_views` usable views remain (naming how many and why) or the result is not a valid stereo
/// calibration (validateStereoCalibration's message).
StereoCalibrateResult calibrateStereo(const BoardSpec& board, const std::vector<StereoView>& views,
                                      const cv::Size& image_size, const StereoCalibrateOptions& options,
                                      const CalibrateLog& log = nullptr);

/// Epipolar error of observations after rectification with `calib`: every id seen in both images,
/// undistorted into the rectified images; returns |y_L - y_R| per point (px).
std::vector<double> rectifiedEpipolarErrors(const StereoCalibration& calib, const BoardObservation& left,
                                            const BoardObservation& right);

/// Converts an OpenCV stereo calibration in cv::FileStorage files (YAML/XML/JSON; OpenCV's
/// samples/cpp/stereo_calib.cpp writes intrinsics.yml with M1 D1 M2 D2 and extrinsics.yml with
/// R T R1 R2 P1 P2 Q; both may be given, or one file with all). Accepted spellings: M1|K1|
/// cameraMatrix1|camera_matrix_left (and 2|right), D1|distCoeffs1|dist_coeffs_left, R, T, R1, R2, P1,
/// P2. Image size: image_width + image_height, or imageSize / image_size ([w, h]), or `size` when the
/// files hold none. Without R1 R2 P1 P2 the rectification is computed (stereoRectify, `alpha`).
/// `translation_scale` multiplies T (and P2's Tx) into metres (0.001 for a calibration in mm); a
/// baseline beyond CalibrationLimits says so. `notes` receives what was done (rectification taken
/// from the file or computed). Throws VisionError naming the file and every missing key, or the bad
/// value; the result passes validateStereoCalibration.
struct ConvertOptions {
  cv::Size size;                   ///< image size when the files hold none (0 x 0: not given)
  double alpha = 0.0;              ///< stereoRectify free scaling when R1 R2 P1 P2 are absent
  double translation_scale = 1.0;  ///< T units -> metres
};
StereoCalibration convertOpenCvStereo(const std::vector<std::string>& files, const ConvertOptions& options,
                                      std::string& notes);

}  // namespace reflex::vision

namespace reflex::vision {

/// The image pairs a calibration reads, in order. Inputs:
///  - a folder of pairs: subfolders left/ and right/ holding files of equal names, or files
///    left<S> and right<S> with equal suffixes <S> (left_000.png + right_000.png); image files
///    .png .jpg .jpeg .bmp .tif .tiff .pgm .ppm; a left image without its right one (or the other way
///    round) is an error naming it;
///  - a session folder (vision/README.md, "Session folder format"): its two videos (session.yaml's
///    left_video/right_video, default left.mp4/right.mp4), every `every`-th pair; the session's
///    calibration files are not needed (it is what is being made).
/// next() throws VisionError naming the file for an unreadable image or a pair of different sizes.
class CalibrationImages {
 public:
  static CalibrationImages fromPairsFolder(const std::string& dir);
  static CalibrationImages fromSession(const std::string& dir, int every);
  /// Pairs that next() will give (for a session: from the video's frame count, may be approximate).
  int count() const { return count_; }
  /// Next pair; false at the end. `name` names it in reports (file name or "frame N").
  bool next(std::string& name, cv::Mat& left, cv::Mat& right);

 private:
  std::vector<std::pair<std::string, std::string>> files_;  ///< pairs folder
  std::size_t next_file_ = 0;
  std::string left_video_, right_video_;
  std::shared_ptr<cv::VideoCapture> cap_[2];
  int every_ = 1, frame_ = 0, count_ = 0;
};

}  // namespace reflex::vision

namespace reflex::vision {

// ---- Camera mount ------------------------------------------------------------
// A tag fixed on a hand at a known point; per view the robot's joint angles (so the point is known in
// the head frame H by the robot's kinematics) and the point measured by the camera in its left optical
// frame C. Then p_H = R_H_C p_C + p_H_C for every view: the camera in the head frame is the rigid
// transform that best maps the measured points onto the kinematic ones (least squares, Kabsch/SVD).
// A known point on the hand makes this a point registration; the AX = XB of cv::calibrateHandEye is
// needed only when the target's place on the hand is unknown.

struct MountObservation {
  std::string name;  ///< shown in reports
  cv::Vec3d p_C;     ///< tag point in the left optical frame, metres (reflex_vision --dump x_cam,y_cam,z_cam)
  cv::Vec3d p_H;     ///< the same point in the head link frame from the kinematics, metres
};

struct MountOptions {
  /// A view is an outlier when its residual exceeds outlier_factor x the median residual AND
  /// min_outlier_m; outliers are dropped and the fit repeated until none is left.
  double outlier_factor = 3.0;
  double min_outlier_m = 0.005;
  int min_views = 6;
  /// The measured points must spread at least this much (RMS distance from their centroid along the
  /// second principal direction, metres): points on a line leave the rotation about it unknown.
  double min_spread_m = 0.02;
};

struct MountViewReport {
  std::string name;
  double residual = 0.0;  ///< |R p_C + t - p_H|, metres, in the last fit the view was in
  bool dropped = false;
  std::string why;
};

struct MountResult {
  cv::Matx33d R_H_C;  ///< left optical frame in the head frame
  cv::Vec3d p_H_C;    ///< metres
  double rms = 0.0;   ///< residual RMS of the kept views, metres
  double max = 0.0;   ///< largest kept residual, metres
  int rounds = 0;
  std::vector<MountViewReport> views;
};

/// Fits the camera in the head frame. Throws VisionError for fewer than min_views usable views,
/// non-finite values (naming the view) or points without spread (naming the spread).
MountResult estimateCameraInHead(const std::vector<MountObservation>& observations, const MountOptions& options,
                                 const CalibrateLog& log = nullptr);

}  // namespace reflex::vision
