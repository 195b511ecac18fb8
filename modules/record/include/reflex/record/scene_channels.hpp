// Scene channels of an MCAP recording: `/tf` (foxglove.FrameTransforms) and
// `/reflex/scene` (foxglove.SceneUpdate), JSON-encoded with their JSON schemas, made from the recorded
// samples with the same builder and the same sample translation as reflex_view (reflex::scene,
// view_node::SceneFeed), so a recording opened in Foxglove shows the robot in 3D with no set-up.
//
// What feeds them: the samples of the default topics reflex/joint_state, reflex/control_status,
// reflex/hand_targets, reflex/object_targets and reflex/body_schema, decoded from their recorded
// bytes (a payload that does not decode is counted in `undecodable` and ignored). Samples on another
// topic name (NAME:TYPE) do not feed the scene.
// When: after a joint state whose receive time is at least 1/rate after the last scene's (recording
// time, so a live recording and a conversion give the same channels), never for a joint state received
// before the last scene (log times stay monotonic; counted in `out_of_order`).
// Stamps: MCAP log time = the joint state's receive time (so every scene message lies within the
// recording), publish time = the joint state's header.stamp_ns (its log time if not positive), and the
// messages' own timestamps are header.stamp_ns (as reflex_view sends them).
// Channels are added to the file with the first scene: a recording without joint states has none.
// The camera: every reflex/camera_left sample (vision's left image) becomes a `/reflex/camera/left`
// message (foxglove.CompressedImage, JSON, the bytes as base64, its capture stamp as its timestamp),
// log time its receive time, so Foxglove's Image panel shows what the robot saw.
#pragma once

#include "reflex/record/mcap.hpp"
#include "reflex/record/record_file.hpp"

#include <cstdint>
#include <memory>
#include <string>

namespace reflex::record {

struct SceneChannelOptions {
  bool enabled = false;    ///< false: no scene channels
  std::string urdf;        ///< robot description (the controller's)
  std::string collision;   ///< collision YAML ("" = next to the URDF)
  std::string controller;  ///< controller YAML ("" = the built-in defaults): arms and zone thresholds
  double rate = 30.0;      ///< scene messages per second of recording time at most, (0, 200]
};

struct SceneChannelStats {
  std::uint64_t joint_states = 0;           ///< joint state samples seen
  std::uint64_t joint_entries_skipped = 0;  ///< names the robot model does not have, non-finite positions
  std::uint64_t scenes = 0;                 ///< /tf + /reflex/scene pairs written
  std::uint64_t undecodable = 0;            ///< payloads of a scene topic that did not decode
  std::uint64_t out_of_order = 0;           ///< joint states received before the last scene (no scene)
  std::uint64_t not_drawn = 0;              ///< joint states whose q is not finite (no scene)
  std::uint64_t camera_images = 0;          ///< /reflex/camera/left messages written
};

class SceneChannels {
 public:
  /// Loads the robot as reflex_controller does (before any file is made, so a bad robot file leaves
  /// none). Throws RecordError for a bad rate ("--scene-rate 500 must be in (0, 200] ..."), and control::ModelError / ConfigError naming the robot
  /// file and value.
  explicit SceneChannels(const SceneChannelOptions& options);
  ~SceneChannels();
  SceneChannels(const SceneChannels&) = delete;
  SceneChannels& operator=(const SceneChannels&) = delete;

  /// Feeds one recorded sample (see the top of this file); writes the scene channels into `writer`
  /// when due (always the same writer). Throws RecordError only when the file cannot be written.
  void add(const RecordEntry& entry, McapWriter& writer);

  const SceneChannelStats& stats() const { return stats_; }
  /// Name of the robot model ("asimo_like").
  const std::string& robotName() const;
  /// One line for the end of a recording or conversion: what was written, or why nothing was
  /// ("no reflex/joint_state sample: no scene channels").
  std::string summary() const;

 private:
  void addCameraImage(const RecordEntry& entry, McapWriter& writer);
  struct Impl;
  std::unique_ptr<Impl> impl_;
  SceneChannelStats stats_;
};

}  // namespace reflex::record
