#include "reflex/vision/session_maker.hpp"

#include "reflex/vision/error.hpp"
#include "reflex/vision/object_map.hpp"
#include "reflex/vision/session.hpp"
#include "reflex/vision/tag_detector.hpp"
#include "yaml_util.hpp"

#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <array>
#include <cmath>

namespace reflex::vision {
namespace {
using namespace detail;

constexpr double kDeg = M_PI / 180.0;
constexpr int kMargin = 40;  // px of ideal (undistorted) image rendered beyond each border

cv::Matx33d rotX(double a) { return {1, 0, 0, 0, std::cos(a), -std::sin(a), 0, std::sin(a), std::cos(a)}; }
cv::Matx33d rotY(double a) { return {std::cos(a), 0, std::sin(a), 0, 1, 0, -std::sin(a), 0, std::cos(a)}; }
cv::Matx33d rotZ(double a) { return {std::cos(a), -std::sin(a), 0, std::sin(a), std::cos(a), 0, 0, 0, 1}; }
cv::Matx33d rpyMatrix(const cv::Vec3d& rpy_deg) {
  return rotZ(rpy_deg[2] * kDeg) * rotY(rpy_deg[1] * kDeg) * rotX(rpy_deg[0] * kDeg);
}
// A quad facing the robot: x_Q = -y_B, y_Q = -z_B, z_Q = +x_B.
const cv::Matx33d kFacing(0, 0, 1, -1, 0, 0, 0, -1, 0);

bool inIntervals(const std::vector<std::pair<double, double>>& iv, double t) {
  for (const auto& [a, b] : iv)
    if (t >= a && t < b) return true;
  return false;
}

// ---------------------------------------------------------------- script parsing
std::vector<Keyframe> parsePath(const YAML::Node& n, const std::string& where) {
  if (!n.IsSequence() || n.size() == 0) throw VisionError(where + ": expected a non-empty list of keyframes");
  std::vector<Keyframe> out;
  for (std::size_t i = 0; i < n.size(); ++i) {
    const std::string w = where + "[" + std::to_string(i) + "]";
    Keyframe k;
    k.t = asDouble(require(n[i], "t", w), w + ".t");
    const std::vector<double> p = asDoublesN(require(n[i], "p", w), 3, w + ".p");
    k.p_B = cv::Vec3d(p[0], p[1], p[2]);
    if (n[i]["rpy_deg"]) {
      const std::vector<double> r = asDoublesN(n[i]["rpy_deg"], 3, w + ".rpy_deg");
      k.rpy_deg = cv::Vec3d(r[0], r[1], r[2]);
    }
    if (!out.empty() && !(k.t > out.back().t))
      throw VisionError(w + ".t = " + fmt(k.t) + " must be after the previous keyframe's " + fmt(out.back().t));
    out.push_back(k);
  }
  return out;
}

std::vector<std::pair<double, double>> parseIntervals(const YAML::Node& n, const std::string& where) {
  std::vector<std::pair<double, double>> out;
  if (!n) return out;
  if (!n.IsSequence()) throw VisionError(where + ": expected a list of [t0, t1] intervals");
  for (std::size_t i = 0; i < n.size(); ++i) {
    const std::vector<double> v = asDoublesN(n[i], 2, where + "[" + std::to_string(i) + "]");
    if (!(v[1] > v[0])) throw VisionError(where + "[" + std::to_string(i) + "]: t1 must be after t0");
    out.emplace_back(v[0], v[1]);
  }
  return out;
}

cv::Matx33d parseIntrinsics(const YAML::Node& n, const std::string& where, std::vector<double>& D) {
  const double fx = asDouble(require(n, "fx", where), where + ".fx");
  const double fy = asDouble(require(n, "fy", where), where + ".fy");
  const double cx = asDouble(require(n, "cx", where), where + ".cx");
  const double cy = asDouble(require(n, "cy", where), where + ".cy");
  if (!(fx > 0.0) || !(fy > 0.0)) throw VisionError(where + ": focal lengths must be positive");
  D = std::vector<double>(5, 0.0);
  if (n["distortion"]) D = asDoublesN(n["distortion"], 5, where + ".distortion");
  return {fx, 0, cx, 0, fy, cy, 0, 0, 1};
}

// ---------------------------------------------------------------- rendering
struct RenderCamera {
  cv::Matx33d R_C_B;  // base -> camera rotation
  cv::Vec3d p_B_C;    // camera position in base
  cv::Matx33d K;      // true intrinsics
  std::vector<double> D;
  cv::Matx33d K_ideal;  // K shifted by kMargin: intrinsics of the undistorted render canvas
  cv::Size ideal_size;
  cv::Mat map_x, map_y;  // distorted pixel -> ideal canvas pixel
  cv::Mat background;    // static scene on the ideal canvas
  cv::Vec3d toCamera(const cv::Vec3d& p_B) const { return R_C_B * (p_B - p_B_C); }
};

struct Quad {
  std::array<cv::Vec3d, 4> corners_B;  // TL, TR, BR, BL as seen facing it
  cv::Vec3d centre_B;
  const cv::Mat* texture = nullptr;
  int object = -1;  // index of the scripted object whose card this is, else -1
};

Quad makeQuad(const QuadPose& pose, double w, double h, const cv::Mat* tex, int object) {
  Quad q;
  const double hw = 0.5 * w, hh = 0.5 * h;
  const cv::Vec3d local[4] = {{-hw, -hh, 0}, {hw, -hh, 0}, {hw, hh, 0}, {-hw, hh, 0}};
  for (int k = 0; k < 4; ++k) q.corners_B[static_cast<std::size_t>(k)] = pose.R_B_Q * local[k] + pose.p_B;
  q.centre_B = pose.p_B;
  q.texture = tex;
  q.object = object;
  return q;
}

bool projectIdeal(const RenderCamera& cam, const cv::Vec3d& p_B, cv::Point2d& uv) {
  const cv::Vec3d p = cam.toCamera(p_B);
  if (p[2] < 0.02) return false;
  const cv::Vec3d h = cam.K_ideal * (p / p[2]);
  uv = cv::Point2d(h[0], h[1]);
  return true;
}

// Draws a textured planar quad on the ideal canvas, anti-aliased by S x S supersampling:
// the texture is warped by the exact homography of the projected corners into an S-times finer
// grid of the quad's bounding box, then box-filtered down and alpha-blended.
void drawQuad(cv::Mat& canvas, const RenderCamera& cam, const Quad& quad, int S) {
  std::array<cv::Point2d, 4> uv;
  for (std::size_t k = 0; k < 4; ++k)
    if (!projectIdeal(cam, quad.corners_B[k], uv[k])) return;
  double x0 = 1e9, y0 = 1e9, x1 = -1e9, y1 = -1e9;
  for (const cv::Point2d& p : uv) {
    x0 = std::min(x0, p.x), y0 = std::min(y0, p.y), x1 = std::max(x1, p.x), y1 = std::max(y1, p.y);
  }
  const cv::Rect box(cv::Point(static_cast<int>(std::floor(x0)) - 2, static_cast<int>(std::floor(y0)) - 2),
                     cv::Point(static_cast<int>(std::ceil(x1)) + 3, static_cast<int>(std::ceil(y1)) + 3));
  const cv::Rect roi = box & cv::Rect(0, 0, canvas.cols, canvas.rows);
  if (roi.empty()) return;
  const cv::Mat& tex = *quad.texture;
  const double tw = tex.cols, th = tex.rows;
  // Texture pixel centres are integers, so the texture's outer edges are at -0.5 and size - 0.5.
  const cv::Point2f src[4] = {{-0.5f, -0.5f},
                              {static_cast<float>(tw - 0.5), -0.5f},
                              {static_cast<float>(tw - 0.5), static_cast<float>(th - 0.5)},
                              {-0.5f, static_cast<float>(th - 0.5)}};
  cv::Point2f dst[4];
  for (int k = 0; k < 4; ++k) {
    // canvas coordinate x -> supersampled ROI coordinate X = S (x - roi.x + 0.5) - 0.5
    dst[k] = cv::Point2f(static_cast<float>(S * (uv[static_cast<std::size_t>(k)].x - roi.x + 0.5) - 0.5),
                         static_cast<float>(S * (uv[static_cast<std::size_t>(k)].y - roi.y + 0.5) - 0.5));
  }
  const cv::Mat H = cv::getPerspectiveTransform(src, dst);
  const cv::Size big(roi.width * S, roi.height * S);
  cv::Mat warped, mask, small, small_mask;
  cv::warpPerspective(tex, warped, H, big, cv::INTER_LINEAR, cv::BORDER_CONSTANT, cv::Scalar::all(0));
  cv::warpPerspective(cv::Mat(tex.size(), CV_8U, cv::Scalar(255)), mask, H, big, cv::INTER_LINEAR,
                      cv::BORDER_CONSTANT, cv::Scalar(0));
  cv::resize(warped, small, roi.size(), 0, 0, cv::INTER_AREA);
  cv::resize(mask, small_mask, roi.size(), 0, 0, cv::INTER_AREA);
  cv::Mat alpha, beta;
  small_mask.convertTo(alpha, CV_32F, 1.0 / 255.0);
  beta = 1.0f - alpha;
  cv::Mat target = canvas(roi);
  cv::Mat blended;
  cv::blendLinear(small, target, alpha, beta, blended);
  blended.copyTo(target);
}

cv::Mat noiseTexture(cv::RNG& rng, cv::Size size, cv::Scalar base, double amp, int cells) {
  // Low-frequency luminance variation with a little colour, plus fine grain.
  cv::Mat low(std::max(2, size.height / cells), std::max(2, size.width / cells), CV_32F);
  rng.fill(low, cv::RNG::NORMAL, 0.0, amp);
  cv::Mat tint(low.size(), CV_32FC3);
  rng.fill(tint, cv::RNG::NORMAL, 0.0, amp * 0.25);
  cv::Mat low3;
  cv::merge(std::vector<cv::Mat>{low, low, low}, low3);
  low3 += tint;
  cv::Mat up;
  cv::resize(low3, up, size, 0, 0, cv::INTER_CUBIC);
  cv::Mat fine(size, CV_32F);
  rng.fill(fine, cv::RNG::NORMAL, 0.0, amp * 0.3);
  cv::Mat fine3;
  cv::merge(std::vector<cv::Mat>{fine, fine, fine}, fine3);
  cv::Mat out;
  cv::Mat sum = up + fine3 + cv::Scalar(base[0], base[1], base[2]);
  sum.convertTo(out, CV_8UC3);
  return out;
}

cv::Mat wallTexture(cv::RNG& rng) {
  cv::Mat t = noiseTexture(rng, cv::Size(800, 320), cv::Scalar(175, 185, 190), 12, 16);
  for (int i = 0; i < 14; ++i) {  // posters, shelves, frames
    const int w = rng.uniform(30, 140), h = rng.uniform(20, 110);
    const cv::Point p(rng.uniform(0, t.cols - w), rng.uniform(0, t.rows - h));
    const cv::Scalar c(rng.uniform(20, 235), rng.uniform(20, 235), rng.uniform(20, 235));
    cv::rectangle(t, cv::Rect(p, cv::Size(w, h)), c, cv::FILLED);
    if (i % 3 == 0) cv::rectangle(t, cv::Rect(p, cv::Size(w, h)), cv::Scalar(30, 30, 30), 3);
    if (i % 4 == 1)
      for (int l = 0; l < 4; ++l)
        cv::line(t, p + cv::Point(5, 8 + 9 * l), p + cv::Point(w - 5, 8 + 9 * l), cv::Scalar(40, 40, 40), 2);
  }
  return t;
}

cv::Mat floorTexture(cv::RNG& rng) {
  cv::Mat t = noiseTexture(rng, cv::Size(480, 480), cv::Scalar(95, 120, 140), 10, 24);
  for (int y = 0; y < t.rows; y += 40) cv::line(t, {0, y}, {t.cols, y}, cv::Scalar(70, 90, 110), 2);
  return t;
}

cv::Mat cardTexture(const TagFamily& family, int id, int cell_px) {
  const cv::Mat bits = family.bitmap(id);  // includes its one-cell white border
  cv::Mat padded;
  cv::copyMakeBorder(bits, padded, 1, 1, 1, 1, cv::BORDER_CONSTANT, cv::Scalar(255));
  cv::Mat big, bgr;
  cv::resize(padded, big, cv::Size(), cell_px, cell_px, cv::INTER_NEAREST);
  cv::cvtColor(big, bgr, cv::COLOR_GRAY2BGR);
  // Printed black is not 0 and paper white is not 255.
  bgr.convertTo(bgr, -1, (235.0 - 25.0) / 255.0, 25.0);
  return bgr;
}

RenderCamera makeCamera(const cv::Matx33d& R_B_C, const cv::Vec3d& p_B_C, const cv::Matx33d& K,
                        const std::vector<double>& D, cv::Size size) {
  RenderCamera c;
  c.R_C_B = R_B_C.t();
  c.p_B_C = p_B_C;
  c.K = K;
  c.D = D;
  c.K_ideal = K;
  c.K_ideal(0, 2) += kMargin;
  c.K_ideal(1, 2) += kMargin;
  c.ideal_size = cv::Size(size.width + 2 * kMargin, size.height + 2 * kMargin);
  std::vector<cv::Point2f> grid;
  grid.reserve(static_cast<std::size_t>(size.area()));
  for (int y = 0; y < size.height; ++y)
    for (int x = 0; x < size.width; ++x) grid.emplace_back(static_cast<float>(x), static_cast<float>(y));
  std::vector<cv::Point2f> ideal;
  cv::undistortPoints(grid, ideal, K, D, cv::noArray(), c.K_ideal,
                      cv::TermCriteria(cv::TermCriteria::COUNT + cv::TermCriteria::EPS, 40, 1e-12));
  c.map_x.create(size, CV_32F);
  c.map_y.create(size, CV_32F);
  for (int y = 0; y < size.height; ++y)
    for (int x = 0; x < size.width; ++x) {
      const cv::Point2f& p = ideal[static_cast<std::size_t>(y * size.width + x)];
      c.map_x.at<float>(y, x) = p.x;
      c.map_y.at<float>(y, x) = p.y;
    }
  return c;
}

// Projects base-frame points with the true (distorted) camera model; false if any is behind.
bool projectDistorted(const RenderCamera& cam, const std::vector<cv::Vec3d>& pts_B, std::vector<cv::Point2d>& uv) {
  std::vector<cv::Point3d> pc;
  for (const cv::Vec3d& p : pts_B) {
    const cv::Vec3d q = cam.toCamera(p);
    if (q[2] < 0.02) return false;
    pc.emplace_back(q[0], q[1], q[2]);
  }
  cv::projectPoints(pc, cv::Vec3d(0, 0, 0), cv::Vec3d(0, 0, 0), cam.K, cam.D, uv);
  return true;
}

}  // namespace

QuadPose evaluateTrajectory(const std::vector<Keyframe>& path, double t) {
  QuadPose pose;
  const std::size_t n = path.size();
  if (n == 1 || t <= path.front().t) {
    pose.p_B = path.front().p_B;
    pose.R_B_Q = kFacing * rpyMatrix(path.front().rpy_deg);
    return pose;
  }
  if (t >= path.back().t) {
    pose.p_B = path.back().p_B;
    pose.R_B_Q = kFacing * rpyMatrix(path.back().rpy_deg);
    return pose;
  }
  std::size_t i = 0;
  while (path[i + 1].t < t) ++i;
  const Keyframe& a = path[i];
  const Keyframe& b = path[i + 1];
  const double h = b.t - a.t;
  const double s = (t - a.t) / h;
  auto tangent = [&](std::size_t k) -> cv::Vec3d {
    const std::size_t lo = k == 0 ? 0 : k - 1;
    const std::size_t hi = std::min(k + 1, n - 1);
    return (path[hi].p_B - path[lo].p_B) / (path[hi].t - path[lo].t);
  };
  const cv::Vec3d ma = tangent(i) * h, mb = tangent(i + 1) * h;
  const double s2 = s * s, s3 = s2 * s;
  pose.p_B = (2 * s3 - 3 * s2 + 1) * a.p_B + (s3 - 2 * s2 + s) * ma + (-2 * s3 + 3 * s2) * b.p_B + (s3 - s2) * mb;
  pose.R_B_Q = kFacing * rpyMatrix((1.0 - s) * a.rpy_deg + s * b.rpy_deg);
  return pose;
}

SceneScript parseSceneScript(const std::string& yaml_text, const std::string& source) {
  const YAML::Node root = parseYaml(yaml_text, source);
  SceneScript s;
  if (root["name"]) s.name = asString(root["name"], source + ": name");
  s.duration = asDouble(require(root, "duration", source), source + ": duration");
  s.fps = asDouble(require(root, "fps", source), source + ": fps");
  if (!(s.duration > 0.0)) throw VisionError(source + ": duration = " + fmt(s.duration) + " must be positive");
  if (!(s.fps > 0.0) || s.fps > 120.0) throw VisionError(source + ": fps = " + fmt(s.fps) + " must be in (0, 120]");
  if (root["seed"]) s.seed = root["seed"].as<std::uint64_t>();
  if (root["family"]) s.family = asString(root["family"], source + ": family");
  if (root["codecs"]) {
    s.codecs.clear();
    const YAML::Node c = root["codecs"];
    for (std::size_t i = 0; i < c.size(); ++i) {
      if (!c[i].IsSequence() || c[i].size() != 2)
        throw VisionError(source + ": codecs[" + std::to_string(i) + "]: expected [fourcc, extension]");
      s.codecs.emplace_back(c[i][0].as<std::string>(), c[i][1].as<std::string>());
    }
  }
  if (const YAML::Node rig = root["rig"]) {
    const std::string w = source + ": rig";
    if (rig["image_size"]) {
      const std::vector<double> v = asDoublesN(rig["image_size"], 2, w + ".image_size");
      s.rig.image_size = cv::Size(static_cast<int>(v[0]), static_cast<int>(v[1]));
      if (s.rig.image_size.width < 64 || s.rig.image_size.height < 64)
        throw VisionError(w + ".image_size must be at least 64x64");
    }
    if (rig["left"]) s.rig.K_left = parseIntrinsics(rig["left"], w + ".left", s.rig.D_left);
    if (rig["right"]) s.rig.K_right = parseIntrinsics(rig["right"], w + ".right", s.rig.D_right);
    if (rig["baseline"]) s.rig.baseline = asDouble(rig["baseline"], w + ".baseline");
    if (!(s.rig.baseline > 0.0)) throw VisionError(w + ".baseline must be positive");
    if (rig["right_rpy_deg"]) {
      const std::vector<double> v = asDoublesN(rig["right_rpy_deg"], 3, w + ".right_rpy_deg");
      s.rig.right_rpy_deg = cv::Vec3d(v[0], v[1], v[2]);
    }
    if (!rig["mount"])
      throw VisionError(w + ": missing field 'mount' (the left camera in the robot base frame, the format of "
                        "camera_mount.yaml; the shipped robot with its head at zero: bringup/vision/camera_mount.yaml)");
    s.rig.mount = parseCameraMount(YAML::Dump(rig["mount"]), w + ".mount");
  } else {
    throw VisionError(source + ": missing field 'rig' (image size, cameras, baseline and mount)");
  }
  if (const YAML::Node r = root["render"]) {
    const std::string w = source + ": render";
    if (r["supersample"]) s.render.supersample = asInt(r["supersample"], w + ".supersample");
    if (s.render.supersample < 1 || s.render.supersample > 8) throw VisionError(w + ".supersample must be 1..8");
    if (r["noise_sigma"]) s.render.noise_sigma = asDouble(r["noise_sigma"], w + ".noise_sigma");
    if (r["blur_sigma"]) {
      const std::vector<double> v = asDoublesN(r["blur_sigma"], 2, w + ".blur_sigma");
      s.render.blur_sigma = cv::Vec2d(v[0], v[1]);
    }
    if (r["lighting"]) {
      const std::vector<double> v = asDoublesN(r["lighting"], 3, w + ".lighting");
      s.render.lighting = cv::Vec3d(v[0], v[1], v[2]);
    }
    if (r["dropout_probability"]) s.render.dropout_probability = asDouble(r["dropout_probability"], w + ".dropout_probability");
    if (r["timestamp_jitter"]) s.render.timestamp_jitter = asDouble(r["timestamp_jitter"], w + ".timestamp_jitter");
    if (r["person"]) s.render.person = asBool(r["person"], w + ".person");
    if (s.render.timestamp_jitter < 0.0 || s.render.timestamp_jitter >= 0.5 / s.fps)
      throw VisionError(w + ".timestamp_jitter must be in [0, half a frame period)");
  }
  const YAML::Node objs = require(root, "objects", source);
  if (!objs.IsSequence()) throw VisionError(source + ": objects: expected a list");
  for (std::size_t i = 0; i < objs.size(); ++i) {
    const std::string w = source + ": objects[" + std::to_string(i) + "]";
    ScriptedObject o;
    o.name = asString(require(objs[i], "name", w), w + ".name");
    o.tag_id = asInt(require(objs[i], "id", w), w + ".id");
    o.tag_size = asDouble(require(objs[i], "size", w), w + ".size");
    o.path = parsePath(require(objs[i], "path", w), w + ".path");
    o.hidden = parseIntervals(objs[i]["hidden"], w + ".hidden");
    if (objs[i]["hand"]) o.hand = asBool(objs[i]["hand"], w + ".hand");
    s.objects.push_back(o);
  }
  if (const YAML::Node occ = root["occluders"]) {
    for (std::size_t i = 0; i < occ.size(); ++i) {
      const std::string w = source + ": occluders[" + std::to_string(i) + "]";
      ScriptedOccluder o;
      o.name = occ[i]["name"] ? asString(occ[i]["name"], w + ".name") : "occluder" + std::to_string(i);
      const std::vector<double> sz = asDoublesN(require(occ[i], "size", w), 2, w + ".size");
      o.size = cv::Vec2d(sz[0], sz[1]);
      if (occ[i]["colour"]) {
        const std::vector<double> c = asDoublesN(occ[i]["colour"], 3, w + ".colour");
        o.colour_bgr = cv::Vec3d(c[0], c[1], c[2]);
      }
      o.path = parsePath(require(occ[i], "path", w), w + ".path");
      o.active = parseIntervals(occ[i]["active"], w + ".active");
      s.occluders.push_back(o);
    }
  }
  // Validates ids/names/sizes and the family the same way a session's objects.yaml is validated.
  std::vector<ObjectSpec> specs;
  for (const ScriptedObject& o : s.objects) specs.push_back({o.tag_id, o.name, o.tag_size});
  const ObjectMap check(s.family, specs, source);
  const TagFamily family(s.family);
  for (const ScriptedObject& o : s.objects)
    if (o.tag_id >= family.codeCount())
      throw VisionError(source + ": object '" + o.name + "' id " + std::to_string(o.tag_id) + " is out of range for " +
                        s.family);
  return s;
}

SceneScript loadSceneScript(const std::string& path) {
  return parseSceneScript(readTextFile(path, "scene script"), path);
}

StereoCalibration rigCalibration(const RigSpec& rig) {
  // Right camera pose in the left optical frame; OpenCV's (R, T) map left coordinates to right ones.
  const cv::Matx33d R_L_R = rpyMatrix(rig.right_rpy_deg);
  const cv::Vec3d p_L_R(rig.baseline, 0.0, 0.0);
  const cv::Matx33d R = R_L_R.t();
  const cv::Vec3d T = -(R_L_R.t() * p_L_R);
  cv::Mat R1, R2, P1, P2, Q;
  cv::stereoRectify(rig.K_left, rig.D_left, rig.K_right, rig.D_right, rig.image_size, R, T, R1, R2, P1, P2, Q,
                    cv::CALIB_ZERO_DISPARITY, 0.0);
  StereoCalibration c;
  c.left.camera_name = "left";
  c.right.camera_name = "right";
  c.left.image_size = c.right.image_size = rig.image_size;
  c.left.K = rig.K_left;
  c.right.K = rig.K_right;
  c.left.D = rig.D_left;
  c.right.D = rig.D_right;
  c.left.R = cv::Matx33d(R1);
  c.right.R = cv::Matx33d(R2);
  c.left.P = cv::Matx34d(P1);
  c.right.P = cv::Matx34d(P2);
  c.left.P(0, 3) = 0.0;  // exactly, not -0 or 1e-17
  return c;
}

MakeSummary makeSession(const SceneScript& script, const std::string& out_dir,
                        const std::function<void(int, int)>& progress) {
  const RigSpec& rig = script.rig;
  const cv::Size size = rig.image_size;
  const int S = script.render.supersample;
  const TagFamily family(script.family);
  const double cell_scale = 1.0 / family.widthAtBorder();  // card cells per tag size

  // Cameras: left optical frame from the mount, right one offset by the baseline and rotated.
  const cv::Matx33d R_L_R = rpyMatrix(rig.right_rpy_deg);
  RenderCamera cams[2] = {
      makeCamera(rig.mount.R_B_C, rig.mount.p_B_C, rig.K_left, rig.D_left, size),
      makeCamera(rig.mount.R_B_C * R_L_R, rig.mount.p_B_C + rig.mount.R_B_C * cv::Vec3d(rig.baseline, 0, 0),
                 rig.K_right, rig.D_right, size)};

  // Static scene on each camera's ideal canvas.
  cv::RNG tex_rng(script.seed * 7919 + 17);
  const cv::Mat wall = wallTexture(tex_rng);
  const cv::Mat floor = floorTexture(tex_rng);
  const cv::Mat shirt = noiseTexture(tex_rng, cv::Size(180, 240), cv::Scalar(140, 80, 60), 14, 12);
  const cv::Mat face = noiseTexture(tex_rng, cv::Size(90, 110), cv::Scalar(120, 150, 205), 8, 10);
  const cv::Mat trousers = noiseTexture(tex_rng, cv::Size(120, 260), cv::Scalar(70, 55, 45), 10, 12);
  const cv::Mat skin = noiseTexture(tex_rng, cv::Size(70, 100), cv::Scalar(115, 145, 200), 8, 10);
  std::vector<Quad> statics;
  {
    Quad w;
    w.corners_B = {cv::Vec3d(3.5, 4, 3.2), cv::Vec3d(3.5, -4, 3.2), cv::Vec3d(3.5, -4, 0), cv::Vec3d(3.5, 4, 0)};
    w.texture = &wall;
    Quad f;
    f.corners_B = {cv::Vec3d(3.5, 4, 0), cv::Vec3d(3.5, -4, 0), cv::Vec3d(0.35, -4, 0), cv::Vec3d(0.35, 4, 0)};
    f.texture = &floor;
    statics = {w, f};
    if (script.render.person) {
      QuadPose torso{cv::Vec3d(1.05, 0.0, 1.10), kFacing};
      QuadPose head{cv::Vec3d(1.08, 0.0, 1.55), kFacing};
      QuadPose legs{cv::Vec3d(1.07, 0.0, 0.40), kFacing};
      statics.push_back(makeQuad(legs, 0.36, 0.80, &trousers, -1));
      statics.push_back(makeQuad(torso, 0.46, 0.62, &shirt, -1));
      statics.push_back(makeQuad(head, 0.19, 0.24, &face, -1));
    }
  }
  for (RenderCamera& c : cams) {
    c.background = cv::Mat(c.ideal_size, CV_8UC3, cv::Scalar(128, 128, 128));
    for (const Quad& q : statics) drawQuad(c.background, c, q, S);
  }

  std::vector<cv::Mat> cards;
  std::vector<cv::Mat> occluder_tex;
  for (const ScriptedObject& o : script.objects) cards.push_back(cardTexture(family, o.tag_id, 32));
  for (const ScriptedOccluder& o : script.occluders)
    occluder_tex.push_back(noiseTexture(tex_rng, cv::Size(64, 64),
                                        cv::Scalar(o.colour_bgr[0], o.colour_bgr[1], o.colour_bgr[2]), 10, 8));

  const StereoCalibration calib = rigCalibration(rig);
  std::vector<ObjectSpec> specs;
  for (const ScriptedObject& o : script.objects) specs.push_back({o.tag_id, o.name, o.tag_size});
  const ObjectMap objects(script.family, specs, "scene script '" + script.name + "'");
  SessionWriterOptions wopt;
  wopt.name = script.name;
  wopt.fps = script.fps;
  wopt.codecs = script.codecs;
  SessionWriter writer(out_dir, calib, objects, rig.mount, wopt);

  MakeSummary summary;
  summary.visible_frames.assign(script.objects.size(), 0);
  std::vector<GroundTruthRow> truth;
  const int frames = static_cast<int>(std::floor(script.duration * script.fps + 1e-9));
  cv::RNG stamp_rng(script.seed * 104729 + 3);
  cv::Mat out[2];
  for (int k = 0; k < frames; ++k) {
    const double jitter =
        script.render.timestamp_jitter > 0.0 ? stamp_rng.uniform(-script.render.timestamp_jitter,
                                                                 script.render.timestamp_jitter)
                                             : 0.0;
    const double t = k / script.fps + jitter;
    cv::RNG rng(script.seed * 1000003ULL + static_cast<std::uint64_t>(k) * 7ULL + 11ULL);

    // Dynamic quads at time t.
    std::vector<Quad> quads;
    std::vector<QuadPose> poses(script.objects.size());
    std::vector<bool> hidden(script.objects.size(), false);
    for (std::size_t i = 0; i < script.objects.size(); ++i) {
      const ScriptedObject& o = script.objects[i];
      poses[i] = evaluateTrajectory(o.path, t);
      hidden[i] = inIntervals(o.hidden, t);
      if (hidden[i]) continue;
      const double card = o.tag_size * cell_scale * (family.totalWidth() + 2);
      quads.push_back(makeQuad(poses[i], card, card, &cards[i], static_cast<int>(i)));
      if (o.hand) {
        QuadPose hand = poses[i];
        hand.p_B = poses[i].p_B + poses[i].R_B_Q * cv::Vec3d(0.0, 0.5 * card + 0.02, 0.012);
        quads.push_back(makeQuad(hand, 0.075, 0.10, &skin, -1));
      }
    }
    for (std::size_t j = 0; j < script.occluders.size(); ++j) {
      const ScriptedOccluder& o = script.occluders[j];
      if (!o.active.empty() && !inIntervals(o.active, t)) continue;
      quads.push_back(makeQuad(evaluateTrajectory(o.path, t), o.size[0], o.size[1], &occluder_tex[j], -1));
    }

    bool dropped[2] = {false, false};
    for (int c = 0; c < 2; ++c) {
      const RenderCamera& cam = cams[c];
      cv::Mat canvas = cam.background.clone();
      std::vector<const Quad*> order;
      for (const Quad& q : quads) order.push_back(&q);
      std::sort(order.begin(), order.end(), [&](const Quad* a, const Quad* b) {
        return cv::norm(a->centre_B - cam.p_B_C) > cv::norm(b->centre_B - cam.p_B_C);
      });
      for (const Quad* q : order) drawQuad(canvas, cam, *q, S);
      cv::remap(canvas, out[c], cam.map_x, cam.map_y, cv::INTER_LINEAR, cv::BORDER_REPLICATE);
      const cv::Vec3d& L = script.render.lighting;
      const double gain = 0.5 * (L[0] + L[1]) + 0.5 * (L[1] - L[0]) * std::sin(2 * M_PI * t / L[2] + 0.7 * c);
      out[c].convertTo(out[c], -1, gain, 0.0);
      const double sigma = rng.uniform(script.render.blur_sigma[0], script.render.blur_sigma[1]);
      if (sigma > 0.05) cv::GaussianBlur(out[c], out[c], cv::Size(0, 0), sigma);
      if (script.render.noise_sigma > 0.0) {
        cv::Mat noise(out[c].size(), CV_16SC3);
        rng.fill(noise, cv::RNG::NORMAL, 0.0, script.render.noise_sigma);
        cv::Mat wide;
        out[c].convertTo(wide, CV_16SC3);
        wide += noise;
        wide.convertTo(out[c], CV_8UC3);
      }
      if (script.render.dropout_probability > 0.0 && rng.uniform(0.0, 1.0) < script.render.dropout_probability) {
        dropped[c] = true;
        out[c].setTo(cv::Scalar::all(0));
      }
    }
    if (dropped[0] || dropped[1]) ++summary.dropouts;

    // Ground truth and visibility.
    for (std::size_t i = 0; i < script.objects.size(); ++i) {
      const ScriptedObject& o = script.objects[i];
      GroundTruthRow row;
      row.stamp = t;
      row.frame = k;
      row.object = o.name;
      row.tag_id = o.tag_id;
      row.p_B = poses[i].p_B;
      row.p_C = cams[0].toCamera(poses[i].p_B);
      row.present = !hidden[i] && !dropped[0] && !dropped[1];
      bool visible = row.present;
      const double half = 0.5 * o.tag_size * cell_scale * family.totalWidth();
      std::vector<cv::Vec3d> region;
      for (const cv::Vec3d& l : {cv::Vec3d(-half, -half, 0), cv::Vec3d(half, -half, 0), cv::Vec3d(half, half, 0),
                                 cv::Vec3d(-half, half, 0)})
        region.push_back(poses[i].R_B_Q * l + poses[i].p_B);
      for (int c = 0; c < 2 && visible; ++c) {
        const RenderCamera& cam = cams[c];
        const cv::Vec3d view = cam.p_B_C - poses[i].p_B;
        const cv::Vec3d z = poses[i].R_B_Q * cv::Vec3d(0, 0, 1);
        if (!(-z.dot(view) > std::cos(70.0 * kDeg) * cv::norm(view))) visible = false;
        std::vector<cv::Point2d> uv;
        if (!visible || !projectDistorted(cam, region, uv)) {
          visible = false;
          break;
        }
        for (const cv::Point2d& p : uv)
          if (p.x < 1.0 || p.y < 1.0 || p.x > size.width - 2.0 || p.y > size.height - 2.0) visible = false;
        // Occluded if any quad nearer to this camera overlaps the tag region in the image.
        std::vector<cv::Point2f> poly;
        for (const cv::Vec3d& p : region) {
          cv::Point2d q;
          if (!projectIdeal(cam, p, q)) visible = false;
          poly.emplace_back(static_cast<float>(q.x), static_cast<float>(q.y));
        }
        const double dist = cv::norm(poses[i].p_B - cam.p_B_C);
        for (const Quad& q : quads) {
          if (!visible) break;
          if (q.object == static_cast<int>(i) || !(cv::norm(q.centre_B - cam.p_B_C) < dist)) continue;
          std::vector<cv::Point2f> other;
          bool ok = true;
          for (const cv::Vec3d& p : q.corners_B) {
            cv::Point2d uvq;
            ok = ok && projectIdeal(cam, p, uvq);
            other.emplace_back(static_cast<float>(uvq.x), static_cast<float>(uvq.y));
          }
          std::vector<cv::Point2f> inter;
          if (ok && cv::intersectConvexConvex(poly, other, inter, true) > 1e-6) visible = false;
        }
      }
      row.visible = visible;
      if (visible) ++summary.visible_frames[i];
      truth.push_back(row);
    }
    writer.write(t, out[0], out[1]);
    if (progress) progress(k + 1, frames);
  }
  saveGroundTruth(out_dir + "/ground_truth.csv", truth);
  writer.finish("ground_truth.csv");
  summary.frames = frames;
  summary.codec = writer.codec();
  return summary;
}

}  // namespace reflex::vision
