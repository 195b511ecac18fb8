#include "vision_publisher.hpp"

#include <algorithm>
#include <cmath>

namespace reflex::vision {

namespace {
/// A publication's capture stamp (ns) and image index, as every sample of its frame carries them.
std::int64_t captureStampNs(const Publication& p) {
  return static_cast<std::int64_t>(std::llround(p.capture_wall * 1e9));
}
std::uint64_t imageIndex(const Publication& p) { return p.frame < 0 ? 0 : static_cast<std::uint64_t>(p.frame); }
}  // namespace

void toObjectTargets(const Publication& p, const std::string& frame_id, reflex::msg::ObjectTargets& out) {
  out.capture_stamp_ns(captureStampNs(p));
  out.image_index(imageIndex(p));
  out.frame_id(frame_id);
  std::vector<reflex::msg::ObjectTarget>& objects = out.objects();
  objects.clear();
  // The type bounds the sequence at 32 (another vendor's reader drops longer samples).
  const std::size_t n = std::min<std::size_t>(p.objects.size(), 32);
  for (std::size_t i = 0; i < n; ++i) {
    const ObjectObservation& o = p.objects[i];
    reflex::msg::ObjectTarget t;
    t.name(o.name);
    t.tag_id(o.tag_id);
    t.position_base().x(o.p_B[0]);
    t.position_base().y(o.p_B[1]);
    t.position_base().z(o.p_B[2]);
    t.position_camera().x(o.p_C[0]);
    t.position_camera().y(o.p_C[1]);
    t.position_camera().z(o.p_C[2]);
    t.confidence(o.confidence);
    objects.push_back(t);
  }
}

VisionPublisher::VisionPublisher(const reflex::bus::BusConfig& config, std::string frame_id)
    : bus_(config),
      writer_(bus_.makeWriter<reflex::msg::ObjectTargets>()),
      image_writer_(bus_.makeWriter<reflex::msg::CameraImage>()),
      heartbeat_(bus_),
      frame_id_(std::move(frame_id)) {}

void VisionPublisher::publish(const Publication& p) {
  toObjectTargets(p, frame_id_, sample_);
  writer_.publish(sample_);
}

bool VisionPublisher::publishImage(const Publication& p, const std::vector<std::uint8_t>& jpeg, int width, int height) {
  if (jpeg.size() > reflex::bus::kMaxCameraImageBytes) return false;
  image_.capture_stamp_ns(captureStampNs(p));
  image_.image_index(imageIndex(p));
  image_.frame_id("left_camera_optical");
  image_.format("jpeg");
  image_.width(static_cast<std::uint32_t>(width));
  image_.height(static_cast<std::uint32_t>(height));
  image_.data(jpeg);
  image_writer_.publish(image_);
  return true;
}

}  // namespace reflex::vision
