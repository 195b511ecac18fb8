// Scene channels of an MCAP recording (scene_channels.hpp).
#include "reflex/record/scene_channels.hpp"

#include "sample_serialization.hpp"

#include <reflex/view/scene.hpp>
#include <reflex/view_node/scene_feed.hpp>

#include <algorithm>
#include <cstdio>

namespace reflex::record {

struct SceneChannels::Impl {
  view::SceneModel scene;
  std::unique_ptr<view::SceneData> data;
  std::unique_ptr<view_node::SceneFeed> feed;
  std::int64_t period_ns = 0;
  std::uint16_t tf_channel = 0, scene_channel = 0, camera_channel = 0;  ///< 0: not added yet
  std::uint32_t sequence = 0;
  bool have_scene = false;
  std::int64_t last_scene_ns = 0;
  msg::JointState joints;
  msg::ControlStatus status;
  msg::HandTargets targets;
  msg::ObjectTargets objects;
  msg::BodySchemaChange schema;
  msg::CameraImage image;

  /// Decodes `e` into `sample` and feeds it; false if it does not decode.
  template <class T>
  bool feedSample(const RecordEntry& e, T& sample) {
    if (e.topic != bus::TopicTraits<T>::kTopicName) return true;  // another topic of this type: not the scene's
    if (!deserializeSample(e.payload, sample)) return false;
    feed->add(sample);
    return true;
  }
  void write(McapWriter* writer, std::uint16_t channel, std::uint64_t log_time, std::uint64_t publish_time,
             const std::string& text) {
    writer->write(channel, sequence, log_time, publish_time, reinterpret_cast<const std::uint8_t*>(text.data()),
                  text.size());
  }
};

SceneChannels::SceneChannels(const SceneChannelOptions& options) : impl_(std::make_unique<Impl>()) {
  if (!(options.rate > 0.0 && options.rate <= 200.0)) {
    char text[120];
    std::snprintf(text, sizeof(text), "--scene-rate %g must be in (0, 200] scene messages per second", options.rate);
    throw RecordError(text);
  }
  Impl& m = *impl_;
  m.scene = view::loadSceneModel(options.urdf, options.collision, options.controller);
  m.data = std::make_unique<view::SceneData>(m.scene);
  m.feed = std::make_unique<view_node::SceneFeed>(m.scene);
  m.period_ns = static_cast<std::int64_t>(1e9 / options.rate);
}

SceneChannels::~SceneChannels() = default;

const std::string& SceneChannels::robotName() const { return impl_->scene.model.name; }

void SceneChannels::add(const RecordEntry& e, McapWriter& writer) {
  Impl& m = *impl_;
  const std::string& t = e.type;
  if (t == "reflex::msg::CameraImage") {
    addCameraImage(e, writer);
    return;
  }
  bool ok = true;
  if (t == "reflex::msg::JointState")
    ok = m.feedSample(e, m.joints);
  else if (t == "reflex::msg::ControlStatus")
    ok = m.feedSample(e, m.status);
  else if (t == "reflex::msg::HandTargets")
    ok = m.feedSample(e, m.targets);
  else if (t == "reflex::msg::ObjectTargets")
    ok = m.feedSample(e, m.objects);
  else if (t == "reflex::msg::BodySchemaChange")
    ok = m.feedSample(e, m.schema);
  else
    return;
  if (!ok) ++stats_.undecodable;
  stats_.joint_states = m.feed->stats().joint_states;
  stats_.joint_entries_skipped = m.feed->stats().joint_entries_skipped;
  if (!m.feed->takeFresh()) return;
  if (m.have_scene && e.receive_ns < m.last_scene_ns) {
    ++stats_.out_of_order;
    return;
  }
  // receive_ns >= last_scene_ns here; the difference in unsigned arithmetic cannot overflow (crafted
  // receive times of a converted file may be anything).
  if (m.have_scene && static_cast<std::uint64_t>(e.receive_ns) - static_cast<std::uint64_t>(m.last_scene_ns) <
                          static_cast<std::uint64_t>(m.period_ns))
    return;
  const view::SceneInput& input = m.feed->input();
  if (!view::updateScene(m.scene, *m.data, input)) {
    ++stats_.not_drawn;
    return;
  }
  if (m.tf_channel == 0) {
    McapChannelSpec tf{"/tf", "json", "foxglove.FrameTransforms", "jsonschema", view::frameTransformsSchema().dump(),
                       {}};
    McapChannelSpec scene{"/reflex/scene",
                          "json",
                          "foxglove.SceneUpdate",
                          "jsonschema",
                          view::sceneUpdateSchema().dump(),
                          {{"robot", m.scene.model.name}}};
    m.tf_channel = writer.addChannel(tf);
    m.scene_channel = writer.addChannel(scene);
  }
  m.have_scene = true;
  m.last_scene_ns = e.receive_ns;
  ++m.sequence;
  const auto log_time = static_cast<std::uint64_t>(std::max<std::int64_t>(e.receive_ns, 0));
  const auto publish_time = input.stamp_ns > 0 ? static_cast<std::uint64_t>(input.stamp_ns) : log_time;
  m.write(&writer, m.tf_channel, log_time, publish_time,
          view_node::dumpJson(view::buildFrameTransforms(m.scene, *m.data, input)));
  m.write(&writer, m.scene_channel, log_time, publish_time,
          view_node::dumpJson(view::buildSceneUpdate(m.scene, *m.data, input)));
  ++stats_.scenes;
}

void SceneChannels::addCameraImage(const RecordEntry& e, McapWriter& writer) {
  Impl& m = *impl_;
  if (e.topic != bus::TopicTraits<msg::CameraImage>::kTopicName) return;
  if (!deserializeSample(e.payload, m.image)) {
    ++stats_.undecodable;
    return;
  }
  if (m.camera_channel == 0)
    m.camera_channel = writer.addChannel({"/reflex/camera/left",
                                          "json",
                                          "foxglove.CompressedImage",
                                          "jsonschema",
                                          view::compressedImageSchema().dump(),
                                          {}});
  ++m.sequence;
  const auto log_time = static_cast<std::uint64_t>(std::max<std::int64_t>(e.receive_ns, 0));
  const std::int64_t stamp = m.image.header().stamp_ns();
  m.write(&writer, m.camera_channel, log_time, stamp > 0 ? static_cast<std::uint64_t>(stamp) : log_time,
          view_node::dumpJson(view::buildCompressedImage(m.image.capture_stamp_ns(), m.image.frame_id(),
                                                         m.image.format(), m.image.data())));
  ++stats_.camera_images;
}

std::string SceneChannels::summary() const {
  char line[400];
  if (stats_.joint_states == 0) {
    std::snprintf(line, sizeof(line), "no reflex/joint_state sample: no scene channels (/tf, /reflex/scene)");
  } else {
    std::snprintf(line, sizeof(line),
                  "scene channels /tf and /reflex/scene: %llu scenes from %llu joint states (robot %s)",
                  static_cast<unsigned long long>(stats_.scenes), static_cast<unsigned long long>(stats_.joint_states),
                  robotName().c_str());
  }
  std::string out = line;
  if (stats_.camera_images) out += "; /reflex/camera/left: " + std::to_string(stats_.camera_images) + " camera images";
  if (stats_.joint_entries_skipped)
    out += "; " + std::to_string(stats_.joint_entries_skipped) +
           " joint entries not in the robot model or not finite were skipped (another robot? give --urdf)";
  if (stats_.undecodable) out += "; " + std::to_string(stats_.undecodable) + " samples did not decode";
  if (stats_.out_of_order) out += "; " + std::to_string(stats_.out_of_order) + " joint states out of time order";
  if (stats_.not_drawn) out += "; " + std::to_string(stats_.not_drawn) + " joint states not drawn (not finite)";
  return out;
}

}  // namespace reflex::record
