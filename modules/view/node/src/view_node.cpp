// reflex_view's bus side (view_node.hpp): readers -> scene (reflex::scene) -> server.
#include "reflex/view_node/view_node.hpp"

#include "reflex/view_node/scene_feed.hpp"

#include <reflex/bus/bus.hpp>
#include <reflex/view/scene.hpp>

#include <chrono>
#include <cstdio>
#include <sstream>

namespace reflex::view_node {
namespace {

constexpr std::uint32_t kChannelTf = 1, kChannelScene = 2, kChannelStatus = 3, kChannelCamera = 4;
}  // namespace

struct ViewNode::Impl {
  ViewOptions options;
  view::SceneModel scene;
  std::unique_ptr<view::SceneData> data;
  std::unique_ptr<SceneFeed> feed;
  std::string protection;
  std::unique_ptr<ViewServer> server;
  std::unique_ptr<bus::Participant> bus;
  bus::Reader<msg::JointState>* joints = nullptr;
  bus::Reader<msg::ControlStatus>* status = nullptr;
  bus::Reader<msg::HandTargets>* targets = nullptr;
  bus::Reader<msg::ObjectTargets>* objects = nullptr;
  bus::Reader<msg::ControllerProtection>* protection_reader = nullptr;
  bus::Reader<msg::BodySchemaChange>* schema_reader = nullptr;
  bus::Reader<msg::CameraImage>* camera = nullptr;
  msg::CameraImage camera_msg;
  msg::JointState joint_msg;
  msg::ControlStatus status_msg;
  msg::HandTargets targets_msg;
  msg::ObjectTargets objects_msg;
  msg::ControllerProtection protection_msg;
  msg::BodySchemaChange schema_msg;
};

ViewNode::ViewNode(const ViewOptions& options) : impl_(std::make_unique<Impl>()) {
  Impl& m = *impl_;
  m.options = options;
  if (!(options.rate > 0.0 && options.rate <= 200.0))
    throw ViewError("--rate " + std::to_string(options.rate) + " must be in (0, 200] messages per second");
  m.scene = view::loadSceneModel(options.urdf, options.collision, options.controller);
  m.data = std::make_unique<view::SceneData>(m.scene);
  m.feed = std::make_unique<SceneFeed>(m.scene);

  std::vector<Channel> channels{
      {kChannelTf, "/tf", "foxglove.FrameTransforms", view::frameTransformsSchema().dump()},
      {kChannelScene, "/reflex/scene", "foxglove.SceneUpdate", view::sceneUpdateSchema().dump()},
      {kChannelStatus, "/reflex/status", "reflex.ViewStatus", view::viewStatusSchema().dump()},
      {kChannelCamera, "/reflex/camera/left", "foxglove.CompressedImage", view::compressedImageSchema().dump()}};
  ServerOptions so = options.server;
  so.metadata_robot = m.scene.model.name;
  m.server = std::make_unique<ViewServer>(so, std::move(channels));

  bus::BusConfig config;
  config.module_name = options.module_name;
  if (options.domain_id >= 0) config.domain_id = options.domain_id;
  config.profiles_file = options.profiles_file;
  config.participant_profile = options.participant_profile;
  m.bus = std::make_unique<bus::Participant>(config);
  // Readers only, with each topic's own reader profile (TopicTraits): the view never writes.
  m.joints = &m.bus->makeReader<msg::JointState>();
  m.status = &m.bus->makeReader<msg::ControlStatus>();
  m.targets = &m.bus->makeReader<msg::HandTargets>();
  m.objects = &m.bus->makeReader<msg::ObjectTargets>();
  m.protection_reader = &m.bus->makeReader<msg::ControllerProtection>();
  m.schema_reader = &m.bus->makeReader<msg::BodySchemaChange>();
  m.camera = &m.bus->makeReader<msg::CameraImage>();
}

ViewNode::~ViewNode() = default;

const ViewServer& ViewNode::server() const { return *impl_->server; }

bus::Participant& ViewNode::bus() { return *impl_->bus; }

void ViewNode::stop() noexcept {
  if (impl_->bus) impl_->bus->stop();
}

std::string ViewNode::report() const {
  const ServerStats& s = impl_->server->stats();
  std::ostringstream out;
  out << "joint_states=" << stats_.joint_states << " joint_entries_skipped=" << stats_.joint_entries_skipped
      << " statuses=" << stats_.statuses << " hand_targets=" << stats_.hand_targets
      << " object_frames=" << stats_.object_frames << " object_frames_other_frame=" << stats_.object_frames_other_frame
      << " schema_changes=" << stats_.schema_changes << " scenes=" << stats_.scenes
      << " camera_images=" << stats_.camera_images << " camera_images_refused=" << stats_.camera_images_refused
      << " connections=" << s.connections.load() << " subscriptions=" << s.subscriptions.load()
      << " messages_sent=" << s.messages_sent.load() << " dropped_slow_client=" << s.dropped.load()
      << " bad_client_messages=" << s.bad_client_messages.load() << " replies_not_sent=" << s.replies_not_sent.load()
      << " clients_disconnected=" << s.clients_disconnected.load() << " clients_refused=" << s.clients_refused.load()
      << " http_requests=" << s.http_requests.load() << " http_not_found=" << s.http_not_found.load();
  return out.str();
}

void ViewNode::run() {
  Impl& m = *impl_;
  m.server->start();
  std::printf(
      "reflex_view: serving %s (web page) and %s (Foxglove: Open connection -> Foxglove WebSocket); robot %s, "
      "domain %d\n",
      m.server->url().c_str(), ("ws" + m.server->url().substr(4)).c_str(), m.scene.model.name.c_str(),
      m.bus->domainId());
  std::printf("reflex_view: %s\n", m.scene.controller_note.c_str());
  std::fflush(stdout);

  auto poll = [&m, this] {
    while (m.joints->takeNext(m.joint_msg)) m.feed->add(m.joint_msg);
    while (m.status->takeNext(m.status_msg)) m.feed->add(m.status_msg);
    while (m.targets->takeNext(m.targets_msg)) m.feed->add(m.targets_msg);
    while (m.objects->takeNext(m.objects_msg)) m.feed->add(m.objects_msg);
    while (m.schema_reader->takeNext(m.schema_msg)) m.feed->add(m.schema_msg);
    static_cast<SceneFeedStats&>(stats_) = m.feed->stats();
    // The camera image goes out as it comes (a few Hz), not at the scene's rate. One that is not a
    // JPEG or PNG of a sane size is counted and dropped (the page would show a broken image).
    while (m.camera->takeNext(m.camera_msg)) {
      const std::string& format = m.camera_msg.format();
      if ((format != "jpeg" && format != "png") || m.camera_msg.data().empty() ||
          m.camera_msg.data().size() > bus::kMaxCameraImageBytes) {
        ++stats_.camera_images_refused;
        continue;
      }
      ++stats_.camera_images;
      if (m.server->subscribed(kChannelCamera))
        m.server->publish(kChannelCamera,
                          static_cast<std::uint64_t>(std::max<std::int64_t>(m.camera_msg.capture_stamp_ns(), 0)),
                          std::make_shared<const std::string>(dumpJson(view::buildCompressedImage(
                              m.camera_msg.capture_stamp_ns(), m.camera_msg.frame_id(), format, m.camera_msg.data()))));
    }
    while (m.protection_reader->takeNext(m.protection_msg)) {
      m.protection = std::string(m.protection_msg.avoidance() ? "avoidance on" : "AVOIDANCE OFF") +
                     (m.protection_msg.estop() ? ", e-stop on" : ", E-STOP OFF") +
                     (m.protection_msg.reason().empty() ? "" : " (" + m.protection_msg.reason() + ")");
    }
  };
  auto serve = [&m, this, poll] {
    poll();
    if (!m.feed->takeFresh()) return;
    const view::SceneInput& input = m.feed->input();
    if (!view::updateScene(m.scene, *m.data, input)) return;
    ++stats_.scenes;
    const auto stamp = static_cast<std::uint64_t>(std::max<std::int64_t>(input.stamp_ns, 0));
    if (m.server->subscribed(kChannelTf))
      m.server->publish(
          kChannelTf, stamp,
          std::make_shared<const std::string>(dumpJson(view::buildFrameTransforms(m.scene, *m.data, input))));
    if (m.server->subscribed(kChannelScene))
      m.server->publish(kChannelScene, stamp,
                        std::make_shared<const std::string>(dumpJson(view::buildSceneUpdate(m.scene, *m.data, input))));
    if (m.server->subscribed(kChannelStatus))
      m.server->publish(
          kChannelStatus, stamp,
          std::make_shared<const std::string>(dumpJson(view::buildViewStatus(m.scene, input, m.protection))));
  };
  const auto period = std::chrono::nanoseconds(static_cast<std::int64_t>(1e9 / m.options.rate));
  m.bus->every(period, serve);
  if (m.options.progress_period > 0.0) {
    m.bus->every(std::chrono::nanoseconds(static_cast<std::int64_t>(1e9 * m.options.progress_period)),
                 [this] { std::fprintf(stderr, "reflex_view: %s\n", report().c_str()); });
  }
  if (m.options.duration > 0.0) {
    m.bus->runFor(std::chrono::nanoseconds(static_cast<std::int64_t>(1e9 * m.options.duration)));
  } else {
    m.bus->run();
  }
  m.server->stop();
}

}  // namespace reflex::view_node
