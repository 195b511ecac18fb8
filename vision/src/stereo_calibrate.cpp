#include "reflex/vision/stereo_calibrate.hpp"

#include "reflex/vision/error.hpp"
#include "reflex/vision/tag_detector.hpp"
#include "yaml_util.hpp"

#include <opencv2/aruco.hpp>
#include <opencv2/aruco/charuco.hpp>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <sstream>

namespace reflex::vision {
namespace {
using detail::fmt;

struct DictionaryName {
  const char* name;
  cv::aruco::PREDEFINED_DICTIONARY_NAME id;
};
const DictionaryName kDictionaries[] = {
    {"DICT_4X4_50", cv::aruco::DICT_4X4_50},
    {"DICT_4X4_100", cv::aruco::DICT_4X4_100},
    {"DICT_4X4_250", cv::aruco::DICT_4X4_250},
    {"DICT_4X4_1000", cv::aruco::DICT_4X4_1000},
    {"DICT_5X5_50", cv::aruco::DICT_5X5_50},
    {"DICT_5X5_100", cv::aruco::DICT_5X5_100},
    {"DICT_5X5_250", cv::aruco::DICT_5X5_250},
    {"DICT_5X5_1000", cv::aruco::DICT_5X5_1000},
    {"DICT_6X6_50", cv::aruco::DICT_6X6_50},
    {"DICT_6X6_100", cv::aruco::DICT_6X6_100},
    {"DICT_6X6_250", cv::aruco::DICT_6X6_250},
    {"DICT_6X6_1000", cv::aruco::DICT_6X6_1000},
    {"DICT_7X7_50", cv::aruco::DICT_7X7_50},
    {"DICT_7X7_100", cv::aruco::DICT_7X7_100},
    {"DICT_7X7_250", cv::aruco::DICT_7X7_250},
    {"DICT_7X7_1000", cv::aruco::DICT_7X7_1000},
    {"DICT_ARUCO_ORIGINAL", cv::aruco::DICT_ARUCO_ORIGINAL},
};

cv::Ptr<cv::aruco::Dictionary> dictionaryByName(const std::string& name) {
  std::string known;
  for (const DictionaryName& d : kDictionaries) {
    if (name == d.name) return cv::aruco::getPredefinedDictionary(d.id);
    known += (known.empty() ? "" : ", ") + std::string(d.name);
  }
  throw VisionError("unknown ChArUco dictionary '" + name + "' (known: " + known + ")");
}

cv::Ptr<cv::aruco::CharucoBoard> charucoBoard(const BoardSpec& b) {
  return cv::aruco::CharucoBoard::create(b.cols, b.rows, static_cast<float>(b.square), static_cast<float>(b.marker),
                                         dictionaryByName(b.dictionary));
}

// Default gap between neighbouring AprilTags: exactly the white borders of both (totalWidth -
// widthAtBorder cells), e.g. 2 cells = a quarter of the black square for tag36h11.
double aprilGridSpacing(const BoardSpec& b, const TagFamily& family) {
  if (b.spacing > 0.0) return b.spacing;
  return b.square * (family.totalWidth() - family.widthAtBorder()) / family.widthAtBorder();
}

// A checkerboard's corners come back in one of two orders (the board looks the same turned by 180
// degrees): "first corner nearer the image's top-left than the last" in each image. Near the
// diagonal the two cameras can disagree; alignStereoPair makes the pair agree.
void orderCheckerboard(std::vector<cv::Point2f>& corners) {
  if (corners.empty()) return;
  const cv::Point2f& a = corners.front();
  const cv::Point2f& z = corners.back();
  if (a.x + a.y > z.x + z.y) std::reverse(corners.begin(), corners.end());
}

double median(std::vector<double> v) {
  if (v.empty()) return 0.0;
  const std::size_t mid = v.size() / 2;
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(mid), v.end());
  return v[mid];
}

// The points of a view seen in both images (ids in both observations), with their board points.
struct CommonPoints {
  std::vector<cv::Point3f> board;
  std::vector<cv::Point2f> left, right;
};

CommonPoints commonPoints(const std::map<int, cv::Point3f>& points, const BoardObservation& l,
                          const BoardObservation& r) {
  CommonPoints c;
  std::size_t j = 0;
  for (std::size_t i = 0; i < l.ids.size(); ++i) {
    while (j < r.ids.size() && r.ids[j] < l.ids[i]) ++j;
    if (j == r.ids.size()) break;
    if (r.ids[j] != l.ids[i]) continue;
    const auto it = points.find(l.ids[i]);
    if (it == points.end()) continue;
    c.board.push_back(it->second);
    c.left.push_back(l.pixels[i]);
    c.right.push_back(r.pixels[j]);
  }
  return c;
}

CameraInfo cameraInfo(const std::string& name, const cv::Size& size, const cv::Mat& K, const cv::Mat& D,
                      const cv::Mat& R, const cv::Mat& P) {
  CameraInfo c;
  c.camera_name = name;
  c.image_size = size;
  for (int i = 0; i < 9; ++i) c.K.val[i] = K.at<double>(i / 3, i % 3);
  for (int i = 0; i < 9; ++i) c.R.val[i] = R.at<double>(i / 3, i % 3);
  for (int i = 0; i < 12; ++i) c.P.val[i] = P.at<double>(i / 4, i % 4);
  const cv::Mat d = D.reshape(1, 1);
  c.D.assign(d.begin<double>(), d.end<double>());
  c.distortion_model = c.D.size() == 8 ? "rational_polynomial" : "plumb_bob";
  return c;
}

}  // namespace

void alignStereoPair(const BoardSpec& board, const BoardObservation& left, BoardObservation& right) {
  if (board.kind != BoardKind::kCheckerboard) return;
  if (left.pixels.size() < 2 || left.pixels.size() != right.pixels.size()) return;
  const cv::Point2f dl = left.pixels.back() - left.pixels.front();
  const cv::Point2f dr = right.pixels.back() - right.pixels.front();
  if (dl.dot(dr) < 0.0f) std::reverse(right.pixels.begin(), right.pixels.end());
}

BoardKind parseBoardKind(const std::string& name) {
  if (name == "checkerboard") return BoardKind::kCheckerboard;
  if (name == "charuco") return BoardKind::kCharuco;
  if (name == "aprilgrid") return BoardKind::kAprilGrid;
  throw VisionError("unknown board '" + name + "' (known: checkerboard, charuco, aprilgrid)");
}

std::string boardKindName(BoardKind kind) {
  switch (kind) {
    case BoardKind::kCheckerboard: return "checkerboard";
    case BoardKind::kCharuco: return "charuco";
    case BoardKind::kAprilGrid: return "aprilgrid";
  }
  return "?";
}

void validateBoard(const BoardSpec& b) {
  const std::string what = boardKindName(b.kind) + " board: ";
  const char* unit = b.kind == BoardKind::kCheckerboard ? "inner corners"
                     : b.kind == BoardKind::kCharuco    ? "squares"
                                                        : "tags";
  const int min_side = b.kind == BoardKind::kAprilGrid ? 1 : 2;
  if (b.cols < min_side || b.rows < min_side || b.cols > 200 || b.rows > 200)
    throw VisionError(what + std::to_string(b.cols) + " x " + std::to_string(b.rows) + " " + unit +
                      ": each side must be in [" + std::to_string(min_side) + ", 200]");
  if (b.kind == BoardKind::kAprilGrid && b.cols * b.rows < 2)
    throw VisionError(what + "a grid of one tag is too few points (at least 2 tags)");
  if (!(b.square > 0.0 && b.square < 10.0))
    throw VisionError(what + "square = " + fmt(b.square) + " m must be in (0, 10) m");
  if (b.kind == BoardKind::kCheckerboard && b.cols == b.rows)
    throw VisionError(what + std::to_string(b.cols) + " x " + std::to_string(b.rows) +
                      " inner corners: a square board looks the same turned by 90 degrees; use different numbers "
                      "(e.g. 9 x 6)");
  if (b.kind == BoardKind::kCharuco) {
    if (!(b.marker > 0.0 && b.marker < b.square))
      throw VisionError(what + "marker = " + fmt(b.marker) + " m must be positive and smaller than the square (" +
                        fmt(b.square) + " m)");
    const cv::Ptr<cv::aruco::Dictionary> d = dictionaryByName(b.dictionary);
    const int markers = (b.cols * b.rows) / 2;
    if (markers > d->bytesList.rows)
      throw VisionError(what + std::to_string(b.cols) + " x " + std::to_string(b.rows) + " squares need " +
                        std::to_string(markers) + " markers but " + b.dictionary + " has " +
                        std::to_string(d->bytesList.rows));
  }
  if (b.kind == BoardKind::kAprilGrid) {
    const TagFamily family(b.family);
    const double cell = b.square / family.widthAtBorder();
    const double min_gap = cell * (family.totalWidth() - family.widthAtBorder());
    if (b.spacing != 0.0 && !(b.spacing >= min_gap - 1e-9))
      throw VisionError(what + "spacing = " + fmt(b.spacing) + " m is less than the white borders of two " + b.family +
                        " tags of " + fmt(b.square) + " m (" + fmt(min_gap) + " m)");
    if (b.first_id < 0 || b.first_id + b.cols * b.rows > family.codeCount())
      throw VisionError(what + "ids " + std::to_string(b.first_id) + " .. " +
                        std::to_string(b.first_id + b.cols * b.rows - 1) + " are outside " + b.family + " (0 .. " +
                        std::to_string(family.codeCount() - 1) + ")");
  }
}

std::map<int, cv::Point3f> boardPoints(const BoardSpec& b) {
  validateBoard(b);
  std::map<int, cv::Point3f> out;
  switch (b.kind) {
    case BoardKind::kCheckerboard:
      for (int r = 0; r < b.rows; ++r)
        for (int c = 0; c < b.cols; ++c)
          out[r * b.cols + c] = cv::Point3f(static_cast<float>(c * b.square), static_cast<float>(r * b.square), 0.f);
      break;
    case BoardKind::kCharuco: {
      const cv::Ptr<cv::aruco::CharucoBoard> board = charucoBoard(b);
      for (std::size_t i = 0; i < board->chessboardCorners.size(); ++i)
        out[static_cast<int>(i)] = board->chessboardCorners[i];
      break;
    }
    case BoardKind::kAprilGrid: {
      const TagFamily family(b.family);
      const double pitch = b.square + aprilGridSpacing(b, family);
      for (int i = 0; i < b.cols * b.rows; ++i) {
        const float x0 = static_cast<float>((i % b.cols) * pitch), y0 = static_cast<float>((i / b.cols) * pitch);
        const float s = static_cast<float>(b.square);
        // libapriltag's corner order on an upright tag (y down): bottom-left, bottom-right, top-right, top-left.
        out[4 * i + 0] = cv::Point3f(x0, y0 + s, 0.f);
        out[4 * i + 1] = cv::Point3f(x0 + s, y0 + s, 0.f);
        out[4 * i + 2] = cv::Point3f(x0 + s, y0, 0.f);
        out[4 * i + 3] = cv::Point3f(x0, y0, 0.f);
      }
      break;
    }
  }
  return out;
}

cv::Mat drawBoard(const BoardSpec& b, int ppu, double& metres_per_pixel, cv::Point2d& origin_px) {
  validateBoard(b);
  if (ppu < 1 || ppu > 1000)
    throw VisionError("pixels per square/cell = " + std::to_string(ppu) + " must be in [1, 1000]");
  switch (b.kind) {
    case BoardKind::kCheckerboard: {
      // (cols+1) x (rows+1) squares, the top-left one black, one square of white margin around.
      cv::Mat img(cv::Size((b.cols + 3) * ppu, (b.rows + 3) * ppu), CV_8U, cv::Scalar(255));
      for (int r = 0; r <= b.rows; ++r)
        for (int c = 0; c <= b.cols; ++c)
          if ((r + c) % 2 == 0) img(cv::Rect((c + 1) * ppu, (r + 1) * ppu, ppu, ppu)).setTo(0);
      metres_per_pixel = b.square / ppu;
      origin_px = cv::Point2d(2.0 * ppu, 2.0 * ppu);
      return img;
    }
    case BoardKind::kCharuco: {
      // OpenCV draws the squares filling the image less the margin; the board frame's origin is the
      // outer corner of the squares where chessboardCorners[0] = (square, square) is measured from.
      const cv::Ptr<cv::aruco::CharucoBoard> board = charucoBoard(b);
      const cv::Size size((b.cols + 2) * ppu, (b.rows + 2) * ppu);
      cv::Mat img;
      board->draw(size, img, ppu, 1);
      metres_per_pixel = b.square / ppu;
      const cv::Point3f p0 = board->chessboardCorners.front();
      // chessboardCorners[0] lies one square in from the top-left outer corner of the drawn squares.
      origin_px = cv::Point2d(2.0 * ppu - p0.x / metres_per_pixel, 2.0 * ppu - p0.y / metres_per_pixel);
      return img;
    }
    case BoardKind::kAprilGrid: {
      const TagFamily family(b.family);
      const double cell = b.square / family.widthAtBorder();
      const double gap_cells = aprilGridSpacing(b, family) / cell;
      const int gap_px = static_cast<int>(std::lround(gap_cells * ppu));
      if (std::abs(gap_cells * ppu - gap_px) > 1e-6)
        throw VisionError("aprilgrid: the spacing is " + fmt(gap_cells) + " cells, which " + std::to_string(ppu) +
                          " pixels per cell cannot draw exactly; choose a spacing of whole cells (cell = " + fmt(cell) +
                          " m)");
      const int border = (family.totalWidth() - family.widthAtBorder()) / 2;  // white cells around the black square
      const int tag_px = family.widthAtBorder() * ppu, pitch_px = tag_px + gap_px;
      const int margin = ppu * (border + 1);
      cv::Mat img(cv::Size(2 * margin + b.cols * pitch_px - gap_px, 2 * margin + b.rows * pitch_px - gap_px), CV_8U,
                  cv::Scalar(255));
      for (int i = 0; i < b.cols * b.rows; ++i) {
        cv::Mat bits = family.bitmap(b.first_id + i), big;
        cv::resize(bits, big, cv::Size(), ppu, ppu, cv::INTER_NEAREST);
        const int x = margin + (i % b.cols) * pitch_px - border * ppu,
                  y = margin + (i / b.cols) * pitch_px - border * ppu;
        big.copyTo(img(cv::Rect(x, y, big.cols, big.rows)));
      }
      metres_per_pixel = cell / ppu;
      origin_px = cv::Point2d(margin, margin);
      return img;
    }
  }
  return {};
}

BoardObservation detectBoard(const BoardSpec& b, const cv::Mat& image) {
  if (image.empty()) throw VisionError("detectBoard: empty image");
  cv::Mat gray;
  if (image.channels() == 3)
    cv::cvtColor(image, gray, cv::COLOR_BGR2GRAY);
  else if (image.channels() == 1)
    gray = image;
  else
    throw VisionError("detectBoard: expected a grey or BGR image, got " + std::to_string(image.channels()) +
                      " channels");
  if (gray.depth() != CV_8U) throw VisionError("detectBoard: expected an 8-bit image");
  BoardObservation obs;
  switch (b.kind) {
    case BoardKind::kCheckerboard: {
      std::vector<cv::Point2f> corners;
      const cv::Size pattern(b.cols, b.rows);
      bool found = cv::findChessboardCornersSB(gray, pattern, corners, cv::CALIB_CB_ACCURACY);
      if (!found) {
        found = cv::findChessboardCorners(gray, pattern, corners,
                                          cv::CALIB_CB_ADAPTIVE_THRESH | cv::CALIB_CB_NORMALIZE_IMAGE);
        if (found)
          cv::cornerSubPix(gray, corners, cv::Size(5, 5), cv::Size(-1, -1),
                           cv::TermCriteria(cv::TermCriteria::EPS + cv::TermCriteria::COUNT, 50, 0.001));
      }
      if (!found || corners.size() != static_cast<std::size_t>(b.cols * b.rows)) return obs;
      orderCheckerboard(corners);
      for (int i = 0; i < b.cols * b.rows; ++i) obs.ids.push_back(i);
      obs.pixels = corners;
      break;
    }
    case BoardKind::kCharuco: {
      const cv::Ptr<cv::aruco::CharucoBoard> board = charucoBoard(b);
      std::vector<std::vector<cv::Point2f>> marker_corners;
      std::vector<int> marker_ids;
      cv::aruco::detectMarkers(gray, board->dictionary, marker_corners, marker_ids);
      if (marker_ids.empty()) return obs;
      std::vector<cv::Point2f> corners;
      std::vector<int> ids;
      cv::aruco::interpolateCornersCharuco(marker_corners, marker_ids, gray, board, corners, ids);
      // OpenCV 4.6's interpolated corners sat ~0.5 px off on a board warped by a known homography
      // (Board.DetectedWhereTheHomographyPutsIt); a small cornerSubPix window (7 x 7 px, clear of the
      // markers' edges) brings them within 0.35 px. A 11 x 11 window reached the markers (0.5 px).
      if (!corners.empty())
        cv::cornerSubPix(gray, corners, cv::Size(3, 3), cv::Size(-1, -1),
                         cv::TermCriteria(cv::TermCriteria::EPS + cv::TermCriteria::COUNT, 50, 0.001));
      std::vector<std::pair<int, cv::Point2f>> sorted;
      for (std::size_t i = 0; i < ids.size(); ++i) sorted.emplace_back(ids[i], corners[i]);
      std::sort(sorted.begin(), sorted.end(), [](const auto& x, const auto& y) { return x.first < y.first; });
      for (const auto& [id, p] : sorted) {
        obs.ids.push_back(id);
        obs.pixels.push_back(p);
      }
      break;
    }
    case BoardKind::kAprilGrid: {
      DetectorOptions o;
      o.family = b.family;
      o.max_hamming = 0;  // a calibration wants no doubtful tag
      TagDetector detector(o);
      for (const TagDetection& d : detector.detect(gray)) {  // sorted by id
        const int index = d.id - b.first_id;
        if (index < 0 || index >= b.cols * b.rows) continue;
        for (int k = 0; k < 4; ++k) {
          obs.ids.push_back(4 * index + k);
          obs.pixels.emplace_back(static_cast<float>(d.corners[static_cast<std::size_t>(k)].x),
                                  static_cast<float>(d.corners[static_cast<std::size_t>(k)].y));
        }
      }
      break;
    }
  }
  return obs;
}

std::vector<double> rectifiedEpipolarErrors(const StereoCalibration& calib, const BoardObservation& left,
                                            const BoardObservation& right) {
  std::map<int, cv::Point3f> any;  // commonPoints needs board points only to pair ids: use a dummy for each id
  for (int id : left.ids) any[id] = cv::Point3f();
  const CommonPoints c = commonPoints(any, left, right);
  std::vector<double> err;
  if (c.left.empty()) return err;
  std::vector<cv::Point2f> l, r;
  cv::undistortPoints(c.left, l, calib.left.K, calib.left.D, calib.left.R, calib.left.P);
  cv::undistortPoints(c.right, r, calib.right.K, calib.right.D, calib.right.R, calib.right.P);
  for (std::size_t i = 0; i < l.size(); ++i) err.push_back(std::abs(static_cast<double>(l[i].y) - r[i].y));
  return err;
}

StereoCalibrateResult calibrateStereo(const BoardSpec& board, const std::vector<StereoView>& views,
                                      const cv::Size& image_size, const StereoCalibrateOptions& options,
                                      const CalibrateLog& log) {
  auto say = [&](const std::string& s) {
    if (log) log(s);
  };
  if (!(options.outlier_factor > 1.0))
    throw VisionError("outlier factor = " + fmt(options.outlier_factor) + " must be greater than 1");
  if (options.min_views < 3)
    throw VisionError("min views = " + std::to_string(options.min_views) + " must be at least 3");
  if (!(options.alpha >= 0.0 && options.alpha <= 1.0))
    throw VisionError("alpha = " + fmt(options.alpha) + " must be in [0, 1]");
  const std::map<int, cv::Point3f> points = boardPoints(board);
  StereoCalibrateResult res;
  std::vector<CommonPoints> common(views.size());
  std::vector<std::size_t> kept;
  for (std::size_t i = 0; i < views.size(); ++i) {
    ViewReport v;
    v.name = views[i].name;
    common[i] = commonPoints(points, views[i].left, views[i].right);
    v.points = static_cast<int>(common[i].board.size());
    if (v.points < options.min_points) {
      v.dropped = true;
      v.why = views[i].left.ids.empty() && views[i].right.ids.empty() ? "no board found"
              : views[i].left.ids.empty()                             ? "no board found in the left image"
              : views[i].right.ids.empty()
                  ? "no board found in the right image"
                  : "only " + std::to_string(v.points) + " points seen in both images (at least " +
                        std::to_string(options.min_points) + ")";
    } else {
      kept.push_back(i);
    }
    res.views.push_back(v);
  }

  const int flags = (options.rational ? cv::CALIB_RATIONAL_MODEL : 0) | (options.fix_k3 ? cv::CALIB_FIX_K3 : 0);
  cv::Mat K1, D1, K2, D2, R, T, E, F, per_view;
  for (;;) {
    if (static_cast<int>(kept.size()) < options.min_views) {
      std::string why = "too few usable views: " + std::to_string(kept.size()) + " of " + std::to_string(views.size()) +
                        " (at least " + std::to_string(options.min_views) + "; dropped:";
      int shown = 0;
      for (const ViewReport& v : res.views)
        if (v.dropped && shown++ < 8) why += " " + v.name + " (" + v.why + ")";
      if (shown > 8) why += " ...";
      throw VisionError(why + ")");
    }
    ++res.rounds;
    std::vector<std::vector<cv::Point3f>> obj;
    std::vector<std::vector<cv::Point2f>> il, ir;
    for (std::size_t k : kept) {
      obj.push_back(common[k].board);
      il.push_back(common[k].left);
      ir.push_back(common[k].right);
    }
    say("round " + std::to_string(res.rounds) + ": calibrating with " + std::to_string(kept.size()) + " views");
    K1.release(), D1.release(), K2.release(), D2.release(), R.release(), T.release();
    try {
      res.rms = cv::stereoCalibrate(obj, il, ir, K1, D1, K2, D2, image_size, R, T, E, F, per_view, flags,
                                    cv::TermCriteria(cv::TermCriteria::COUNT + cv::TermCriteria::EPS, 100, 1e-7));
    } catch (const cv::Exception& e) {
      throw VisionError("OpenCV stereoCalibrate failed: " + std::string(e.what()));
    }
    std::vector<double> err(kept.size());
    for (std::size_t j = 0; j < kept.size(); ++j) {
      ViewReport& v = res.views[kept[j]];
      v.rms_left = per_view.at<double>(static_cast<int>(j), 0);
      v.rms_right = per_view.at<double>(static_cast<int>(j), 1);
      err[j] = std::max(v.rms_left, v.rms_right);
    }
    const double med = median(err);
    const double limit = std::max(options.outlier_factor * med, options.min_outlier_px);
    say("round " + std::to_string(res.rounds) + ": reprojection RMS " + cv::format("%.3f", res.rms) +
        " px, per-view median " + cv::format("%.3f", med) + " px, outlier above " + cv::format("%.3f", limit) + " px");
    std::vector<std::size_t> next;
    for (std::size_t j = 0; j < kept.size(); ++j) {
      if (err[j] > limit) {
        ViewReport& v = res.views[kept[j]];
        v.dropped = true;
        v.why = "outlier in round " + std::to_string(res.rounds) + ": reprojection RMS " + cv::format("%.3f", err[j]) +
                " px > " + fmt(options.outlier_factor) + " x median " + cv::format("%.3f", med) + " px";
        say("dropped " + v.name + ": " + v.why);
      } else {
        next.push_back(kept[j]);
      }
    }
    if (next.size() == kept.size()) break;
    kept = next;
  }

  cv::Mat R1, R2, P1, P2, Q;
  cv::stereoRectify(K1, D1, K2, D2, image_size, R, T, R1, R2, P1, P2, Q, cv::CALIB_ZERO_DISPARITY, options.alpha);
  res.calibration.left = cameraInfo("left", image_size, K1, D1, R1, P1);
  res.calibration.right = cameraInfo("right", image_size, K2, D2, R2, P2);
  for (int i = 0; i < 9; ++i) res.R.val[i] = R.at<double>(i / 3, i % 3);
  res.T = cv::Vec3d(T.at<double>(0), T.at<double>(1), T.at<double>(2));
  validateStereoCalibration(res.calibration, "the calibrated left camera", "the calibrated right camera");

  double ss = 0.0;
  std::size_t n = 0;
  for (std::size_t k : kept) {
    const std::vector<double> e = rectifiedEpipolarErrors(res.calibration, views[k].left, views[k].right);
    double vs = 0.0;
    for (double x : e) {
      vs += x * x;
      res.epipolar_max = std::max(res.epipolar_max, x);
    }
    ss += vs;
    n += e.size();
    res.views[k].epipolar_rms = e.empty() ? 0.0 : std::sqrt(vs / static_cast<double>(e.size()));
  }
  res.epipolar_rms = n ? std::sqrt(ss / static_cast<double>(n)) : 0.0;
  return res;
}

}  // namespace reflex::vision
