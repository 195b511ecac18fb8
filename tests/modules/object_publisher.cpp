// reflex_modules_object_publisher: synthetic ObjectTargets for the behavior integration tests, over
// real DDS (a separate process, in place of reflex_vision). Objects stand still at the given
// positions; --inject-bad adds samples the behavior process must reject: a NaN copy of the first
// object and an unknown "ghost" in every frame, every third frame an extra frame stamped 10 s in
// the future that puts the first object somewhere else, and every third frame (another one) an
// extra frame in frame_id "odom" that puts the first object somewhere else. --image FILE (a JPEG) also
// publishes that image on reflex/camera_left every fifth frame, as reflex_vision publishes the left
// camera's image.
#include <reflex/bus/bus.hpp>

#include <CLI/CLI.hpp>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <iterator>
#include <limits>
#include <sstream>
#include <thread>
#include <vector>

namespace {

struct Obj {
  std::string name;
  double x, y, z;
};

Obj parseObject(const std::string& text) {
  const auto eq = text.find('=');
  Obj o{};
  char extra = 0;
  if (eq == std::string::npos || eq == 0 ||
      std::sscanf(text.c_str() + eq + 1, "%lf,%lf,%lf%c", &o.x, &o.y, &o.z, &extra) != 3)
    throw std::invalid_argument("--object '" + text + "': expected NAME=X,Y,Z (metres, base frame)");
  o.name = text.substr(0, eq);
  return o;
}

reflex::msg::ObjectTarget target(const std::string& name, int tag, double x, double y, double z) {
  reflex::msg::ObjectTarget t;
  t.name(name);
  t.tag_id(tag);
  reflex::msg::Vector3 p;
  p.x(x);
  p.y(y);
  p.z(z);
  t.position_base(p);
  t.confidence(1.0);
  return t;
}

/// A JPEG file's bytes and its size from its start-of-frame marker (baseline or progressive).
struct Jpeg {
  std::vector<std::uint8_t> bytes;
  int width = 0, height = 0;
};

Jpeg readJpeg(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  Jpeg j;
  j.bytes.assign(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
  const std::vector<std::uint8_t>& b = j.bytes;
  if (b.size() < 4 || b[0] != 0xFF || b[1] != 0xD8) throw std::invalid_argument("--image '" + path + "' is not a JPEG");
  for (std::size_t i = 2; i + 9 < b.size();) {  // marker segments: FF xx, 16-bit length
    if (b[i] != 0xFF) break;
    const int marker = b[i + 1];
    const std::size_t length = (std::size_t{b[i + 2]} << 8) | b[i + 3];
    if (marker >= 0xC0 && marker <= 0xC2) {
      j.height = (b[i + 5] << 8) | b[i + 6];
      j.width = (b[i + 7] << 8) | b[i + 8];
      return j;
    }
    i += 2 + length;
  }
  throw std::invalid_argument("--image '" + path + "': no JPEG start-of-frame marker");
}

}  // namespace

int main(int argc, char** argv) {
  using namespace reflex;
  CLI::App app{"reflex_modules_object_publisher: synthetic reflex/object_targets for the behavior tests"};
  std::string domain;
  std::vector<std::string> object_texts;
  double duration = 5.0, rate = 10.0;
  bool inject = false;
  app.add_option("--domain", domain, "DDS domain id")->required();
  app.add_option("--object", object_texts, "NAME=X,Y,Z in the base frame [m] (repeatable)")->required();
  app.add_option("--duration", duration, "seconds to publish")->check(CLI::PositiveNumber)->capture_default_str();
  app.add_option("--rate", rate, "frames per second")->check(CLI::Range(0.5, 100.0))->capture_default_str();
  app.add_flag("--inject-bad", inject, "add NaN, unknown, future and wrong-frame samples");
  std::string image_path;
  app.add_option("--image", image_path, "a JPEG also published on reflex/camera_left every fifth frame");
  std::string image_format = "jpeg";
  app.add_option("--image-format", image_format, "the format the image claims (a wrong one for the bad-input tests)")
      ->capture_default_str();
  CLI11_PARSE(app, argc, argv);
  try {
    std::vector<Obj> objects;
    for (const auto& t : object_texts) objects.push_back(parseObject(t));
    bus::BusConfig config;
    config.module_name = "vision";  // the default inputs.object_sources of reflex_behavior
    config.domain_id = bus::parseDomainId(domain, "--domain");
    bus::Participant participant(config);
    auto& writer = participant.makeWriter<msg::ObjectTargets>();
    Jpeg jpeg;
    bus::Writer<msg::CameraImage>* image_writer = nullptr;
    if (!image_path.empty()) {
      jpeg = readJpeg(image_path);
      image_writer = &participant.makeWriter<msg::CameraImage>();
    }
    bus::StopOnSignal stop_on_signal(participant);
    const auto period = std::chrono::duration<double>(1.0 / rate);
    const auto t_end = std::chrono::steady_clock::now() + std::chrono::duration<double>(duration);
    auto next = std::chrono::steady_clock::now();
    std::uint64_t index = 0;
    const double nan = std::numeric_limits<double>::quiet_NaN();
    while (std::chrono::steady_clock::now() < t_end && !participant.stopRequested()) {
      msg::ObjectTargets frame;
      frame.capture_stamp_ns(bus::nowNs());
      frame.image_index(++index);
      frame.frame_id("base_link");
      if (inject) frame.objects().push_back(target(objects[0].name, 0, nan, objects[0].y, objects[0].z));
      for (std::size_t i = 0; i < objects.size(); ++i)
        frame.objects().push_back(
            target(objects[i].name, static_cast<int>(i), objects[i].x, objects[i].y, objects[i].z));
      if (inject) frame.objects().push_back(target("ghost", 99, 0.40, 0.0, 1.0));
      writer.publish(frame);
      if (image_writer != nullptr && index % 5 == 1) {
        msg::CameraImage image;
        image.capture_stamp_ns(frame.capture_stamp_ns());
        image.image_index(index);
        image.frame_id("left_camera_optical");
        image.format(image_format);
        image.width(static_cast<std::uint32_t>(jpeg.width));
        image.height(static_cast<std::uint32_t>(jpeg.height));
        image.data(jpeg.bytes);
        image_writer->publish(image);
      }
      if (inject && index % 3 == 0) {
        msg::ObjectTargets future;
        const std::int64_t ahead = bus::nowNs() + 10'000'000'000LL;
        future.header().stamp_ns(ahead);
        future.header().seq(index);
        future.header().source("vision");
        future.capture_stamp_ns(ahead);
        future.image_index(index);
        future.frame_id("base_link");
        future.objects().push_back(target(objects[0].name, 0, 0.30, 0.30, 0.50));
        writer.write(future);
      }
      if (inject && index % 3 == 1) {
        msg::ObjectTargets odom;
        odom.capture_stamp_ns(bus::nowNs());
        odom.image_index(index);
        odom.frame_id("odom");
        odom.objects().push_back(target(objects[0].name, 0, 0.35, -0.30, 0.60));
        writer.publish(odom);
      }
      next += std::chrono::duration_cast<std::chrono::steady_clock::duration>(period);
      std::this_thread::sleep_until(next);
    }
    std::printf("reflex_modules_object_publisher: published %llu frames\n", static_cast<unsigned long long>(index));
    return 0;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "reflex_modules_object_publisher: error: %s\n", e.what());
    return 2;
  }
}
