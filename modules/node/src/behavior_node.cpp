#include "reflex/modules/behavior_node.hpp"

#include <reflex/bus/bus.hpp>

#include <algorithm>
#include <array>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <sstream>

namespace reflex::modules {

namespace {

msg::Vector3 toMsg(const Eigen::Vector3d& v) {
  msg::Vector3 m;
  m.x(v.x());
  m.y(v.y());
  m.z(v.z());
  return m;
}

void fillHand(msg::HandTarget& out, const HandTarget& in) {
  out.status(in.given ? msg::TARGET_GIVEN : msg::TARGET_NONE);
  out.position_base(toMsg(in.given ? in.p_B : Eigen::Vector3d::Zero()));
  out.object_name(in.given ? in.object : std::string());
}

// The host's outputs, published on the bus. Writers exist only for what the modules claim.
class DdsSink final : public OutputSink {
 public:
  void bind(bus::Participant& bus, const Claims& claims) {
    if (claims.hands[0] || claims.hands[1]) hands_ = &bus.makeWriter<msg::HandTargets>();
    if (claims.priority) priority_ = &bus.makeWriter<msg::MotionPriority>();
    if (!claims.segments.empty()) schema_ = &bus.makeWriter<msg::BodySchemaChange>();
    if (claims.walk) walk_ = &bus.makeWriter<msg::WalkCommand>();
  }
  void handTargets(const HandTarget& left, const HandTarget& right) override {
    fillHand(hands_msg_.left(), left);
    fillHand(hands_msg_.right(), right);
    count(hands_->publish(hands_msg_), "hand targets", "");
  }
  void motionPriority(ArmPriority p) override {
    msg::MotionPriority m;
    m.priority(p == ArmPriority::kLeftHigher    ? msg::PRIORITY_LEFT_HIGHER
               : p == ArmPriority::kRightHigher ? msg::PRIORITY_RIGHT_HIGHER
                                                : msg::PRIORITY_EQUAL);
    count(priority_->publish(m), "motion priority", "");
  }
  void segmentAttached(const SegmentSpec& s) override {
    msg::BodySchemaChange m;
    m.segment_name(s.name);
    m.operation(msg::SCHEMA_ATTACH);
    m.parent_link(s.parent_link);
    m.shape(s.capsule ? msg::SHAPE_CAPSULE : msg::SHAPE_SPHERE);
    m.point_a(toMsg(s.a_L));
    m.point_b(toMsg(s.capsule ? s.b_L : s.a_L));
    m.radius(s.radius);
    m.motion_priority(s.motion_priority);
    m.enabled(s.enabled);
    m.virtual_segment(s.virtual_segment);
    count(schema_->publish(m), "body-schema segment", s.name);
  }
  void segmentDetached(const std::string& name) override {
    msg::BodySchemaChange m;
    m.segment_name(name);
    m.operation(msg::SCHEMA_DETACH);
    m.enabled(false);
    count(schema_->publish(m), "body-schema segment", name);
  }
  void walk(const WalkGoal& g) override {
    msg::WalkCommand m;
    m.goal_x(g.x);
    m.goal_y(g.y);
    m.goal_yaw(g.yaw);
    m.speed(g.speed);
    m.stop(g.stop);
    count(walk_->publish(m), "walk command", "");
  }
  /// Samples the bus refused (e.g. a key string above bus::kMaxKeyStringBytes), counted.
  std::uint64_t refused() const { return refused_; }
  /// Waits until every matched reader acknowledged what was published (reliable writers).
  void waitForAcknowledgments(std::chrono::milliseconds timeout) {
    const eprosima::fastrtps::Duration_t d(static_cast<std::int32_t>(timeout.count() / 1000),
                                           static_cast<std::uint32_t>((timeout.count() % 1000) * 1000000));
    if (hands_) hands_->native().wait_for_acknowledgments(d);
    if (priority_) priority_->native().wait_for_acknowledgments(d);
    if (schema_) schema_->native().wait_for_acknowledgments(d);
    if (walk_) walk_->native().wait_for_acknowledgments(d);
  }

 private:
  bus::Writer<msg::HandTargets>* hands_ = nullptr;
  bus::Writer<msg::MotionPriority>* priority_ = nullptr;
  bus::Writer<msg::BodySchemaChange>* schema_ = nullptr;
  bus::Writer<msg::WalkCommand>* walk_ = nullptr;
  msg::HandTargets hands_msg_;
  std::uint64_t refused_ = 0;

  // A refused sample is counted and said on stderr (the first, then every 1000th).
  void count(bool published, const char* what, const std::string& name) {
    if (published) return;
    if (refused_++ % 1000 == 0) {
      std::fprintf(stderr,
                   "reflex_behavior: %s %s%.60s%s refused by the bus (%llu so far; a key longer than %zu bytes?)\n",
                   what, name.empty() ? "" : "'", name.c_str(), name.empty() ? "" : (name.size() > 60 ? "...'" : "'"),
                   static_cast<unsigned long long>(refused_), bus::kMaxKeyStringBytes);
    }
  }
};

}  // namespace

struct BehaviorNode::Impl {
  NodeOptions options;
  HostConfig config;
  DdsSink sink;
  std::unique_ptr<BehaviorHost> host;
  std::unique_ptr<bus::Participant> bus;
  std::unique_ptr<bus::HeartbeatPublisher> heartbeat;
  std::chrono::steady_clock::time_point t_start = std::chrono::steady_clock::now();
  ObjectsFrame frame;
  JointStateSample joints;
  // Joint states come from ONE controller: the writer heard first is followed;
  // samples of any other writer are ignored, counted and said on stderr. The followed writer is
  // replaced only after kJointWriterSilence without a sample from it (a restarted controller).
  static constexpr double kJointWriterSilence = 0.5;  // s (the controller publishes every 5 ms)
  bool have_joint_writer = false;
  std::array<unsigned char, 16> joint_writer{};
  double joint_writer_last = -1.0;                 // host time of its last sample
  std::uint64_t joint_states_other_writer = 0;     // samples ignored: from a second writer
  std::uint64_t joint_writer_changes = 0;          // a silent writer replaced by a new one
  std::unique_ptr<bus::WriterIdentities> writers;  // who wrote an object frame (inputs.object_sources)
  bus::LogLimiter host_log;                        // the host's per-sample lines, rate-limited

  Now now() const {
    return Now{std::chrono::duration<double>(std::chrono::steady_clock::now() - t_start).count(), bus::nowNs()};
  }
};

BehaviorNode::BehaviorNode(const NodeOptions& options, const ModuleRegistry& registry)
    : impl_(std::make_unique<Impl>()) {
  Impl& m = *impl_;
  m.options = options;
  m.config = loadHostConfig(options.config, registry);
  if (!options.object_sources.empty()) m.config.inputs.object_sources = options.object_sources;
  if (!options.joint_state_sources.empty()) m.config.inputs.joint_state_sources = options.joint_state_sources;
  m.config.type_plugins = options.type_plugins;
  // Every host line goes through one rate limiter: a flood of bad samples is
  // counted in the host's stats but prints at most LogLimiter's rate.
  BehaviorHost::LogFn log = [&m](const std::string& line) { m.host_log.print(stderr, line); };
  if (options.quiet) log = [](const std::string&) {};
  m.host = std::make_unique<BehaviorHost>(m.config, registry, m.sink, log, options.module);
  // A body-schema segment name is the DDS key of its samples: bounded here, at start.
  for (const std::string& segment : m.host->claims().segments) {
    if (segment.size() > bus::kMaxKeyStringBytes) {
      throw ConfigError(options.config + ": body-schema segment name '" + segment + "' is " +
                        std::to_string(segment.size()) + " bytes long; at most " +
                        std::to_string(bus::kMaxKeyStringBytes) + " bytes (it is the DDS key of its samples)");
    }
  }

  bus::BusConfig bc;
  bc.module_name = m.host->processName();
  bc.domain_id = options.domain_id;
  bc.profiles_file = options.profiles_file;
  bc.participant_profile = options.participant_profile;
  m.bus = std::make_unique<bus::Participant>(bc);
  m.sink.bind(*m.bus, m.host->claims());
  m.heartbeat = std::make_unique<bus::HeartbeatPublisher>(*m.bus);  // 500 ms: 2 Hz

  // The writer of each input sample is identified from its participant (authenticated under
  // DDS-Security): the configured sources and the Reflex identities are recognised, anything else is "".
  std::vector<std::string> known = m.config.inputs.object_sources;
  known.insert(known.end(), m.config.inputs.joint_state_sources.begin(), m.config.inputs.joint_state_sources.end());
  for (const char* id : {"vision", "behavior", "controller", "recorder", "player"}) known.emplace_back(id);
  std::sort(known.begin(), known.end());
  known.erase(std::unique(known.begin(), known.end()), known.end());
  m.writers = std::make_unique<bus::WriterIdentities>(*m.bus, known);
  if (!options.quiet) {
    auto list = [](const std::vector<std::string>& v) {
      std::string out;
      for (const auto& n : v) out += (out.empty() ? "'" : ", '") + n + "'";
      return out;
    };
    std::fprintf(stderr, "%s: object targets accepted only from %s, joint states only from %s (%s)\n",
                 m.host->processName().c_str(), list(m.config.inputs.object_sources).c_str(),
                 list(m.config.inputs.joint_state_sources).c_str(),
                 m.writers->authenticated() ? "the writer's certificate, authenticated by DDS-Security"
                                            : "the name the writer's participant announces: NOT authenticated, "
                                              "plain DDS");
  }
  if (m.host->claims().objects) {
    auto& objects = m.bus->makeReader<msg::ObjectTargets>();
    objects.onDataWithInfo([&m](const msg::ObjectTargets& o, const bus::dds::SampleInfo& info) {
      m.frame.source = m.writers->identify(info);
      m.frame.stamp_ns = o.header().stamp_ns();
      m.frame.capture_stamp_ns = o.capture_stamp_ns();
      m.frame.image_index = o.image_index();
      m.frame.frame_id = o.frame_id();
      m.frame.objects.resize(o.objects().size());
      for (std::size_t i = 0; i < o.objects().size(); ++i) {
        const msg::ObjectTarget& in = o.objects()[i];
        ObjectObservation& out = m.frame.objects[i];
        out.name = in.name();
        out.tag_id = in.tag_id();
        out.p_B = Eigen::Vector3d(in.position_base().x(), in.position_base().y(), in.position_base().z());
        out.confidence = in.confidence();
      }
      m.host->onObjects(m.frame, m.now());
    });
  }
  auto& joints = m.bus->makeReader<msg::JointState>();
  joints.onDataWithInfo([&m](const msg::JointState& js, const eprosima::fastdds::dds::SampleInfo& info) {
    // A writer that is not an accepted source (inputs.joint_state_sources) is rejected and counted by
    // the host; it never becomes the followed writer (a replayed joint state cannot lock the real
    // controller out).
    m.joints.source = m.writers->identify(info);
    const auto& accepted = m.config.inputs.joint_state_sources;
    if (std::find(accepted.begin(), accepted.end(), m.joints.source) == accepted.end()) {
      m.joints.stamp_ns = js.header().stamp_ns();
      m.joints.names = js.names();
      m.joints.positions = js.positions();
      m.host->onJointState(m.joints, m.now());
      return;
    }
    std::array<unsigned char, 16> writer{};
    const unsigned char* handle = info.publication_handle.value;  // 16 bytes: the writer GUID
    std::copy(handle, handle + writer.size(), writer.begin());
    const double t = m.now().t;
    if (m.have_joint_writer && writer != m.joint_writer) {
      if (t - m.joint_writer_last <= Impl::kJointWriterSilence) {
        if (m.joint_states_other_writer++ % 1000 == 0) {
          std::fprintf(stderr,
                       "%s: WARNING: joint states from a second writer ('%s') ignored (%llu so far): another "
                       "controller on this domain?\n",
                       m.host->processName().c_str(), js.header().source().c_str(),
                       static_cast<unsigned long long>(m.joint_states_other_writer));
        }
        return;
      }
      ++m.joint_writer_changes;
    }
    m.have_joint_writer = true;
    m.joint_writer = writer;
    m.joint_writer_last = t;
    m.joints.stamp_ns = js.header().stamp_ns();
    m.joints.names = js.names();
    m.joints.positions = js.positions();
    m.host->onJointState(m.joints, m.now());
  });
  m.bus->every(
      std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::duration<double>(m.config.tick_period)),
      [&m] { m.host->tick(m.now()); });
  if (options.progress_period > 0.0 && !options.quiet) {
    m.bus->every(
        std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::duration<double>(options.progress_period)),
        [&m] { std::fprintf(stderr, "%s: %s\n", m.host->processName().c_str(), m.host->status().c_str()); });
  }
}

BehaviorNode::~BehaviorNode() = default;

const BehaviorHost& BehaviorNode::host() const { return *impl_->host; }

void BehaviorNode::stop() noexcept { impl_->bus->stop(); }

bus::Participant& BehaviorNode::bus() { return *impl_->bus; }

void BehaviorNode::run() {
  Impl& m = *impl_;
  std::string names;
  for (const auto& n : m.host->moduleNames()) names += (names.empty() ? "" : ",") + n;
  try {
    m.host->start(m.now());
    m.heartbeat->setState(msg::STATE_RUNNING, "modules: " + names);
    if (m.options.duration > 0.0) {
      m.bus->runFor(
          std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::duration<double>(m.options.duration)));
    } else {
      m.bus->run();
    }
    m.heartbeat->setState(msg::STATE_STOPPING, "modules: " + names);
    m.host->stop(m.now());
    m.sink.waitForAcknowledgments(std::chrono::milliseconds(2000));
  } catch (const std::exception& e) {
    m.heartbeat->setState(msg::STATE_ERROR, e.what());
    throw;
  }
}

std::string BehaviorNode::report() const {
  const HostStats& s = impl_->host->stats();
  std::ostringstream m;
  m << "frames=" << s.frames_received << " objects_accepted=" << s.objects_accepted
    << " rejected_source=" << s.frames_rejected_source << " rejected_future=" << s.frames_rejected_future
    << " rejected_frame=" << s.frames_rejected_frame << " rejected_invalid=" << s.objects_rejected_invalid
    << " rejected_unknown=" << s.objects_rejected_unknown << " rejected_range=" << s.objects_rejected_range
    << " rejected_duplicate=" << s.objects_rejected_duplicate << " joint_states=" << s.joint_states
    << " joint_states_rejected=" << s.joint_states_rejected
    << " joint_states_rejected_source=" << s.joint_states_rejected_source
    << " hand_targets=" << s.hand_targets_published << " priority=" << s.priority_published
    << " segment_changes=" << s.segment_changes_published << " walk=" << s.walk_published
    << " outputs_rejected=" << s.outputs_rejected << " forced_cleanups=" << s.forced_cleanups
    << " outputs_refused_by_bus=" << impl_->sink.refused()
    << " joint_states_other_writer=" << impl_->joint_states_other_writer
    << " joint_writer_changes=" << impl_->joint_writer_changes;
  return m.str();
}

}  // namespace reflex::modules
