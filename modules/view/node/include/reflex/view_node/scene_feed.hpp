// SceneFeed: the bus samples a scene is made of (JointState, ControlStatus, HandTargets,
// ObjectTargets, BodySchemaChange) folded into one view::SceneInput, the latest of each. One copy of
// this translation serves both users: reflex_view (live samples from its readers) and the recorder's
// scene channels (modules/record scene_channels.hpp: samples decoded from the recording).
//
// Contract per sample (never throws; bad values are counted or left out, as scene.hpp draws them):
//   JointState        q from names/positions (jointPositionsToQ): a name the robot does not have or a
//                     non-finite position is skipped and counted (joint_entries_skipped); stamp =
//                     header.stamp_ns [ns, system clock]; marks the input fresh.
//   ControlStatus     both arms' zone, distance, f(d), closest pair, e-stop (an unknown zone: red).
//   HandTargets       both hands' target (given only when status is TARGET_GIVEN), position_base in B.
//   ObjectTargets     replaces the object list, unless frame_id is neither "base_link" nor the URDF root
//                     (then not drawn, counted in object_frames_other_frame): those are not base-frame
//                     positions.
//   BodySchemaChange  attach/update a segment by name, detach removes it; at most kMaxSchemaSegments
//                     (the reflex_behavior profile's instance limit), further new names are ignored.
#pragma once

#include <reflex/bus/topics.hpp>
#include <reflex/view/scene.hpp>

#include <cstdint>
#include <map>
#include <string>

namespace reflex::view_node {

/// Counts of what a SceneFeed was given.
struct SceneFeedStats {
  std::uint64_t joint_states = 0;           ///< joint state samples taken
  std::uint64_t joint_entries_skipped = 0;  ///< names unknown to the robot or non-finite positions
  std::uint64_t statuses = 0;
  std::uint64_t hand_targets = 0;
  std::uint64_t object_frames = 0;
  std::uint64_t object_frames_other_frame = 0;  ///< frame_id neither "base_link" nor the URDF root: not drawn
  std::uint64_t schema_changes = 0;             ///< reflex/body_schema samples
};

class SceneFeed {
 public:
  static constexpr std::size_t kMaxSchemaSegments = 64;

  /// `scene` must outlive the feed. The input starts at q = 0, no status, no targets, no objects.
  explicit SceneFeed(const view::SceneModel& scene);

  void add(const msg::JointState& s);
  void add(const msg::ControlStatus& s);
  void add(const msg::HandTargets& s);
  void add(const msg::ObjectTargets& s);
  void add(const msg::BodySchemaChange& s);

  /// The scene input made of the latest samples.
  const view::SceneInput& input() const { return input_; }
  /// True once a joint state was added.
  bool haveJoints() const { return stats_.joint_states > 0; }
  /// True if a joint state was added since the last call (and clears the mark).
  bool takeFresh() {
    const bool f = fresh_;
    fresh_ = false;
    return f;
  }
  const SceneFeedStats& stats() const { return stats_; }

 private:
  const view::SceneModel& scene_;
  view::SceneInput input_;
  std::map<std::string, view::SchemaSegmentState> schema_;  ///< by segment name (the topic key)
  bool fresh_ = false;
  SceneFeedStats stats_;
};

/// Dumps a scene message as compact JSON text. Strings from the bus that are not valid UTF-8 (a
/// segment, object or joint name) are written with U+FFFD in place of the bad bytes instead of
/// throwing (nlohmann's default), so a bad name never stops the view or a recording.
std::string dumpJson(const nlohmann::json& message);

}  // namespace reflex::view_node
