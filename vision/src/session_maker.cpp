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
#include <limits>

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
cv::Vec3d vec3Of(const ConfigNode& n) {
  const std::vector<double> v = n.asNumbers(3);
  return cv::Vec3d(v[0], v[1], v[2]);
}

std::vector<Keyframe> parsePath(const ConfigNode& n) {
  const std::vector<ConfigNode> keys = n.elements();
  if (keys.empty()) n.failHere("the list is empty", "a non-empty list of keyframes {t, p, rpy_deg}");
  std::vector<Keyframe> out;
  for (const ConfigNode& e : keys) {
    e.requireMap("a keyframe {t, p, rpy_deg}");
    e.rejectUnknown({"t", "p", "rpy_deg"});
    Keyframe k;
    k.t = e.requiredNumber("t", -kAnyNumber, kAnyNumber, "s");
    k.p_B = vec3Of(e.at("p", "[x, y, z] in m"));
    if (e.has("rpy_deg")) k.rpy_deg = vec3Of(e.at("rpy_deg", "[roll, pitch, yaw] in degrees"));
    if (!out.empty() && !(k.t > out.back().t))
      e.fail("t", "not after the previous keyframe's t", "t > " + fmt(out.back().t) + " s");
    out.push_back(k);
  }
  return out;
}

std::vector<std::pair<double, double>> parseIntervals(const ConfigNode& parent, const std::string& key) {
  std::vector<std::pair<double, double>> out;
  if (!parent.has(key)) return out;
  for (const ConfigNode& e : parent.at(key, "a list of [t0, t1] intervals").elements()) {
    const std::vector<double> v = e.asNumbers(2);
    if (!(v[1] > v[0])) e.failHere("t1 is not after t0", "[t0, t1] with t1 > t0");
    out.emplace_back(v[0], v[1]);
  }
  return out;
}

cv::Matx33d parseIntrinsics(const ConfigNode& n, std::vector<double>& D) {
  n.requireMap("{fx, fy, cx, cy, distortion}");
  n.rejectUnknown({"fx", "fy", "cx", "cy", "distortion"});
  const double fx = n.requiredNumber("fx", -kAnyNumber, kAnyNumber, "px");
  const double fy = n.requiredNumber("fy", -kAnyNumber, kAnyNumber, "px");
  const double cx = n.requiredNumber("cx", -kAnyNumber, kAnyNumber, "px");
  const double cy = n.requiredNumber("cy", -kAnyNumber, kAnyNumber, "px");
  if (!(fx > 0.0)) n.fail("fx", "focal length not positive", "fx > 0 px");
  if (!(fy > 0.0)) n.fail("fy", "focal length not positive", "fy > 0 px");
  D = std::vector<double>(5, 0.0);
  if (n.has("distortion")) D = n.at("distortion", "5 plumb_bob coefficients").asNumbers(5);
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
  cv::warpPerspective(cv::Mat(tex.size(), CV_8U, cv::Scalar(255)), mask, H, big, cv::INTER_LINEAR, cv::BORDER_CONSTANT,
                      cv::Scalar(0));
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
  const ConfigNode root = parseYaml(yaml_text, source);
  root.rejectUnknown({"name", "duration", "fps", "seed", "family", "codecs", "rig", "render", "objects", "occluders"});
  SceneScript s;
  s.name = root.string("name", s.name);
  s.duration = root.requiredNumber("duration", -kAnyNumber, kAnyNumber, "s");
  s.fps = root.requiredNumber("fps", -kAnyNumber, kAnyNumber, "Hz");
  if (!(s.duration > 0.0)) root.fail("duration", "not positive", "a duration > 0 s");
  if (!(s.fps > 0.0) || s.fps > 120.0) root.fail("fps", "out of range", "(0, 120] Hz");
  if (root.has("seed")) {
    try {
      s.seed = root.raw("seed").as<std::uint64_t>();
    } catch (const YAML::Exception&) {
      root.fail("seed", "not an unsigned integer", "an integer in [0, 2^64)");
    }
  }
  s.family = root.string("family", s.family);
  if (root.has("codecs")) {
    s.codecs.clear();
    for (const ConfigNode& c : root.at("codecs", "a list of [fourcc, extension]").elements()) {
      if (!c.isList() || c.node().size() != 2 || !c.node()[0].IsScalar() || !c.node()[1].IsScalar())
        c.failHere("not a codec", "[fourcc, extension]");
      s.codecs.emplace_back(c.node()[0].Scalar(), c.node()[1].Scalar());
    }
  }
  const ConfigNode rig = root.at("rig", "a map {image_size, left, right, baseline, right_rpy_deg, mount}");
  rig.requireMap("a map {image_size, left, right, baseline, right_rpy_deg, mount}");
  rig.rejectUnknown({"image_size", "left", "right", "baseline", "right_rpy_deg", "mount"});
  if (rig.has("image_size")) {
    const std::vector<double> v = rig.at("image_size", "[width, height] in px").asNumbers(2);
    s.rig.image_size = cv::Size(static_cast<int>(v[0]), static_cast<int>(v[1]));
    if (s.rig.image_size.width < 64 || s.rig.image_size.height < 64)
      rig.fail("image_size", "smaller than 64x64", "at least [64, 64] px");
  }
  if (rig.has("left")) s.rig.K_left = parseIntrinsics(rig.at("left", "intrinsics"), s.rig.D_left);
  if (rig.has("right")) s.rig.K_right = parseIntrinsics(rig.at("right", "intrinsics"), s.rig.D_right);
  s.rig.baseline = rig.number("baseline", s.rig.baseline, -kAnyNumber, kAnyNumber, "m");
  if (!(s.rig.baseline > 0.0)) rig.fail("baseline", "not positive", "a baseline > 0 m");
  if (rig.has("right_rpy_deg")) s.rig.right_rpy_deg = vec3Of(rig.at("right_rpy_deg", "[roll, pitch, yaw] in degrees"));
  s.rig.mount = readCameraMount(rig.at("mount",
                                       "the left camera in the robot base frame, the format of camera_mount.yaml (the "
                                       "shipped robot with its head at zero: bringup/vision/camera_mount.yaml)"));
  if (root.has("render")) {
    const ConfigNode r = root.child("render");
    r.rejectUnknown(
        {"supersample", "noise_sigma", "blur_sigma", "lighting", "dropout_probability", "timestamp_jitter", "person"});
    s.render.supersample = r.integer("supersample", s.render.supersample, 1, 8);
    s.render.noise_sigma = r.number("noise_sigma", s.render.noise_sigma, -kAnyNumber, kAnyNumber);
    if (r.has("blur_sigma")) {
      const std::vector<double> v = r.at("blur_sigma", "[sigma_min, sigma_max]").asNumbers(2);
      s.render.blur_sigma = cv::Vec2d(v[0], v[1]);
    }
    if (r.has("lighting")) s.render.lighting = vec3Of(r.at("lighting", "3 numbers"));
    s.render.dropout_probability =
        r.number("dropout_probability", s.render.dropout_probability, -kAnyNumber, kAnyNumber);
    s.render.timestamp_jitter = r.number("timestamp_jitter", s.render.timestamp_jitter, -kAnyNumber, kAnyNumber, "s");
    s.render.person = r.boolean("person", s.render.person);
    if (s.render.timestamp_jitter < 0.0 || s.render.timestamp_jitter >= 0.5 / s.fps)
      r.fail("timestamp_jitter", "out of range", "[0, half a frame period = " + fmt(0.5 / s.fps) + ") s");
  }
  for (const ConfigNode& o_node : root.list("objects")) {
    o_node.rejectUnknown({"name", "id", "size", "path", "hidden", "hand"});
    ScriptedObject o;
    o.name = o_node.requiredString("name", "the object's name");
    o.tag_id = o_node.at("id", "a tag id").asInteger(std::numeric_limits<int>::min(), std::numeric_limits<int>::max());
    o.tag_size = o_node.requiredNumber("size", -kAnyNumber, kAnyNumber, "m");
    o.path = parsePath(o_node.at("path", "a non-empty list of keyframes"));
    o.hidden = parseIntervals(o_node, "hidden");
    o.hand = o_node.boolean("hand", o.hand);
    s.objects.push_back(o);
  }
  if (!root.has("objects")) root.fail("objects", "missing", "a list of objects {name, id, size, path}");
  int index = 0;
  for (const ConfigNode& c : root.list("occluders")) {
    c.rejectUnknown({"name", "size", "colour", "path", "active"});
    ScriptedOccluder o;
    o.name = c.string("name", "occluder" + std::to_string(index++));
    const std::vector<double> sz = c.at("size", "[width, height] in m").asNumbers(2);
    o.size = cv::Vec2d(sz[0], sz[1]);
    if (c.has("colour")) o.colour_bgr = vec3Of(c.at("colour", "[b, g, r]"));
    o.path = parsePath(c.at("path", "a non-empty list of keyframes"));
    o.active = parseIntervals(c, "active");
    s.occluders.push_back(o);
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

/// Whether the tag of object i (at `pose`, its card `half` wide about the tag) is fully visible in both
/// cameras: facing them within 70 degrees, inside both images, and covered by no quad nearer the camera.
bool tagVisible(const RenderCamera (&cams)[2], const QuadPose& pose, double half, int i, const std::vector<Quad>& quads,
                const cv::Size& size) {
  bool visible = true;
  std::vector<cv::Vec3d> region;
  for (const cv::Vec3d& l :
       {cv::Vec3d(-half, -half, 0), cv::Vec3d(half, -half, 0), cv::Vec3d(half, half, 0), cv::Vec3d(-half, half, 0)})
    region.push_back(pose.R_B_Q * l + pose.p_B);
  for (int c = 0; c < 2 && visible; ++c) {
    const RenderCamera& cam = cams[c];
    const cv::Vec3d view = cam.p_B_C - pose.p_B;
    const cv::Vec3d z = pose.R_B_Q * cv::Vec3d(0, 0, 1);
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
    const double dist = cv::norm(pose.p_B - cam.p_B_C);
    for (const Quad& q : quads) {
      if (!visible) break;
      if (q.object == i || !(cv::norm(q.centre_B - cam.p_B_C) < dist)) continue;
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
  return visible;
}

/// Camera c's image of the quads at time t (nearest drawn last), with the script's lighting, blur,
/// noise and drop-outs (from `rng`); true if the frame is dropped (all black).
bool renderImage(const RenderCamera (&cams)[2], int c, const std::vector<Quad>& quads, const SceneScript& script,
                 double t, int S, cv::RNG& rng, cv::Mat (&out)[2]) {
  bool dropped = false;
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
    dropped = true;
    out[c].setTo(cv::Scalar::all(0));
  }
  return dropped;
}

/// The moving quads at time t: each object's card (and the hand holding it) unless hidden, and the
/// active occluders; every object's pose and whether it is hidden.
std::vector<Quad> quadsAt(const SceneScript& script, double t, const TagFamily& family, double cell_scale,
                          const std::vector<cv::Mat>& cards, const cv::Mat& skin,
                          const std::vector<cv::Mat>& occluder_tex, std::vector<QuadPose>& poses,
                          std::vector<bool>& hidden) {
  std::vector<Quad> quads;
  poses.assign(script.objects.size(), QuadPose{});
  hidden.assign(script.objects.size(), false);
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

  return quads;
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
    occluder_tex.push_back(
        noiseTexture(tex_rng, cv::Size(64, 64), cv::Scalar(o.colour_bgr[0], o.colour_bgr[1], o.colour_bgr[2]), 10, 8));

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
    const double jitter = script.render.timestamp_jitter > 0.0
                              ? stamp_rng.uniform(-script.render.timestamp_jitter, script.render.timestamp_jitter)
                              : 0.0;
    const double t = k / script.fps + jitter;
    cv::RNG rng(script.seed * 1000003ULL + static_cast<std::uint64_t>(k) * 7ULL + 11ULL);

    // Dynamic quads at time t.
    std::vector<QuadPose> poses;
    std::vector<bool> hidden;
    const std::vector<Quad> quads = quadsAt(script, t, family, cell_scale, cards, skin, occluder_tex, poses, hidden);

    bool dropped[2] = {false, false};
    for (int c = 0; c < 2; ++c) dropped[c] = renderImage(cams, c, quads, script, t, S, rng, out);
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
      if (visible) visible = tagVisible(cams, poses[i], half, static_cast<int>(i), quads, size);
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
