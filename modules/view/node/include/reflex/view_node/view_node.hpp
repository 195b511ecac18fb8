// reflex_view: a read-only process on the bus that serves the live scene to
// Foxglove (Foxglove WebSocket protocol) and to the bundled three.js page, on one port.
//
// Reads (never writes: it creates no DDS writer and publishes no heartbeat; tested):
//   reflex/joint_state, reflex/control_status, reflex/hand_targets, reflex/object_targets,
//   reflex/controller_protection, reflex/body_schema (grasped objects and virtual segments, drawn),
//   reflex/camera_left (vision's left image).
// Serves, at most `rate` times per second and only when a joint state arrived since the last time,
// only to channels someone subscribed to (view_server.hpp):
//   channel 1 "/tf"            foxglove.FrameTransforms  every link (scene.hpp)
//   channel 2 "/reflex/scene"  foxglove.SceneUpdate      capsules by zone, closest pairs, targets, objects
//   channel 3 "/reflex/status" reflex.ViewStatus         distances, f(d), zones, d_a/d_b/d_r, targets
//   channel 4 "/reflex/camera/left" foxglove.CompressedImage  each reflex/camera_left image as it
//                                   arrives (a few Hz; not a jpeg / png, empty or too large: counted, dropped)
// Bad samples: a joint state with a name the robot does not have or a non-finite position has those
// entries skipped (counted); objects and targets with non-finite positions are not drawn; an object
// frame whose frame_id is neither "base_link" nor the URDF root is not drawn (counted).
#pragma once

#include "reflex/view_node/scene_feed.hpp"
#include "reflex/view_node/view_server.hpp"

#include <cstdint>
#include <memory>
#include <string>

namespace reflex::bus {
class Participant;
}  // namespace reflex::bus

namespace reflex::view_node {

struct ViewOptions {
  std::string urdf;        ///< robot description (as given to reflex_controller)
  std::string collision;   ///< "" = next to the URDF
  std::string controller;  ///< controller YAML ("" = defaults): arms and zone thresholds
  std::string profiles_file;
  std::string participant_profile = "reflex_participant";
  int domain_id = -1;            ///< -1 = bus default
  double duration = 0.0;         ///< s (0 = until SIGINT / SIGTERM)
  double rate = 30.0;            ///< scene messages per second at most, (0, 200]
  double progress_period = 0.0;  ///< s between status lines on stderr (0 = none)
  ServerOptions server;
  std::string module_name = "view";
};

/// The feed's counts (scene_feed.hpp) and the scenes built.
struct ViewStats : SceneFeedStats {
  std::uint64_t scenes = 0;                 ///< scene updates built
  std::uint64_t camera_images = 0;          ///< reflex/camera_left images taken (sent to the subscribed clients)
  std::uint64_t camera_images_refused = 0;  ///< ... dropped: not jpeg / png, empty or too large
};

class ViewNode {
 public:
  /// Loads the robot, opens the server (binds) and creates the participant and readers. Throws
  /// control::ModelError / ConfigError, ViewError, bus::BusError naming the bad value.
  explicit ViewNode(const ViewOptions& options);
  ~ViewNode();
  ViewNode(const ViewNode&) = delete;
  ViewNode& operator=(const ViewNode&) = delete;

  /// Serves until stop() or the duration. Signals are the program's business: main installs
  /// reflex::bus::StopOnSignal on bus() (so nodes compose in one process).
  void run();
  void stop() noexcept;
  /// The node's participant (to stop it from a signal: bus::StopOnSignal).
  bus::Participant& bus();

  const ViewServer& server() const;
  const ViewStats& stats() const { return stats_; }
  /// One line of counters (the exit line).
  std::string report() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
  ViewStats stats_;
};

}  // namespace reflex::view_node
