#pragma once
// The DDS side of the vision node (reflex::vision_node, only in a build with reflex::bus; never in reflex::vision):
// owns the bus participant, the ObjectTargets writer (topic reflex/object_targets, profile
// reflex_object_targets from bringup/dds/reflex_profiles.xml), the CameraImage writer (reflex/camera_left)
// and the heartbeat, and turns a runner Publication into an ObjectTargets sample.
#include "reflex/vision/runner.hpp"

#include <reflex/bus/bus.hpp>
#include <reflex/msg/vision.h>

#include <chrono>
#include <cstdint>
#include <string>
#include <vector>

namespace reflex::vision {

/// Fills an ObjectTargets sample from a publication (header left to Writer::publish).
/// capture_stamp_ns: the frame's capture time on the system clock (replayed sessions: the capture
/// mapped onto the replay clock, so consumers see fresh data; see runner.hpp).
void toObjectTargets(const Publication& p, const std::string& frame_id, reflex::msg::ObjectTargets& out);

class VisionPublisher {
 public:
  /// Throws reflex::bus::BusError naming what failed (profiles file, domain id, writer).
  VisionPublisher(const reflex::bus::BusConfig& config, std::string frame_id);
  /// Called from one thread (the runner's publication thread). Never throws.
  void publish(const Publication& p);
  /// Publishes an encoded image of the publication's frame on reflex/camera_left (same capture stamp and
  /// index as its ObjectTargets). The publication thread, as publish(). Throws nothing but
  /// std::bad_alloc; false if the image is larger than reflex::bus::kMaxCameraImageBytes (not published).
  bool publishImage(const Publication& p, const std::vector<std::uint8_t>& jpeg, int width, int height);
  std::uint64_t imagesPublished() const { return image_writer_.lastSeq(); }
  reflex::bus::Participant& bus() { return bus_; }
  reflex::bus::HeartbeatPublisher& heartbeat() { return heartbeat_; }
  std::uint64_t published() const { return writer_.lastSeq(); }
  /// Readers of reflex/object_targets matched now (under DDS-Security: authenticated and keyed).
  int matchedReaders() const { return writer_.stats().matched_readers; }
  /// Blocks until `count` readers matched (true) or `timeout` passes (false).
  bool waitForReaders(int count, std::chrono::nanoseconds timeout) const {
    return writer_.waitForReaders(count, timeout);
  }

 private:
  reflex::bus::Participant bus_;
  reflex::bus::Writer<reflex::msg::ObjectTargets>& writer_;
  reflex::bus::Writer<reflex::msg::CameraImage>& image_writer_;
  reflex::bus::HeartbeatPublisher heartbeat_;
  std::string frame_id_;
  reflex::msg::ObjectTargets sample_;
  reflex::msg::CameraImage image_;
};

}  // namespace reflex::vision
