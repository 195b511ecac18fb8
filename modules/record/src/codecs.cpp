#include "reflex/record/codecs.hpp"

#include "sample_serialization.hpp"

#include <reflex/bus/bus.hpp>

#include <cinttypes>
#include <cstdio>
#include <limits>
#include <sstream>

namespace reflex::record {

namespace msg = reflex::msg;

namespace {

// ---- CSV columns per type ----------------------------------------------------------------------

std::string num(double v) {
  char buf[40];
  std::snprintf(buf, sizeof(buf), "%.9g", v);
  return buf;
}

void hand(std::ostream& o, const msg::HandTarget& h) {
  o << ',' << static_cast<int>(h.status()) << ',' << num(h.position_base().x()) << ',' << num(h.position_base().y())
    << ',' << num(h.position_base().z()) << ',' << csvField(h.object_name());
}
void arm(std::ostream& o, const msg::ArmStatus& a) {
  o << ',' << num(a.blend_f()) << ',' << num(a.distance()) << ',' << static_cast<int>(a.zone()) << ','
    << (a.estop_latched() ? 1 : 0) << ',' << csvField(a.closest_segment_a()) << ',' << csvField(a.closest_segment_b());
}

void csvColumns(std::ostream& o, const msg::ObjectTargets&) {
  o << ",capture_stamp_ns,image_index,frame_id,n_objects,object,tag_id,x,y,z,x_cam,y_cam,z_cam,confidence";
}
void csvRows(std::ostream& o, const std::string& prefix, const msg::ObjectTargets& s) {
  const std::string head = prefix + "," + std::to_string(s.capture_stamp_ns()) + "," + std::to_string(s.image_index()) +
                           "," + csvField(s.frame_id()) + "," + std::to_string(s.objects().size());
  if (s.objects().empty()) o << head << ",,,,,,,,,\n";
  for (const auto& obj : s.objects()) {
    o << head << ',' << csvField(obj.name()) << ',' << obj.tag_id() << ',' << num(obj.position_base().x()) << ','
      << num(obj.position_base().y()) << ',' << num(obj.position_base().z()) << ',' << num(obj.position_camera().x())
      << ',' << num(obj.position_camera().y()) << ',' << num(obj.position_camera().z()) << ',' << num(obj.confidence())
      << '\n';
  }
}

void csvColumns(std::ostream& o, const msg::HandTargets&) {
  o << ",left_status,left_x,left_y,left_z,left_object,right_status,right_x,right_y,right_z,right_object";
}
void csvRows(std::ostream& o, const std::string& prefix, const msg::HandTargets& s) {
  o << prefix;
  hand(o, s.left());
  hand(o, s.right());
  o << '\n';
}

void csvColumns(std::ostream& o, const msg::MotionPriority&) { o << ",priority"; }
void csvRows(std::ostream& o, const std::string& prefix, const msg::MotionPriority& s) {
  o << prefix << ',' << static_cast<int>(s.priority()) << '\n';
}

void csvColumns(std::ostream& o, const msg::BodySchemaChange&) {
  o << ",segment_name,operation,parent_link,shape,a_x,a_y,a_z,b_x,b_y,b_z,radius,motion_priority,enabled,virtual_"
       "segment";
}
void csvRows(std::ostream& o, const std::string& prefix, const msg::BodySchemaChange& s) {
  o << prefix << ',' << csvField(s.segment_name()) << ',' << static_cast<int>(s.operation()) << ','
    << csvField(s.parent_link()) << ',' << static_cast<int>(s.shape()) << ',' << num(s.point_a().x()) << ','
    << num(s.point_a().y()) << ',' << num(s.point_a().z()) << ',' << num(s.point_b().x()) << ',' << num(s.point_b().y())
    << ',' << num(s.point_b().z()) << ',' << num(s.radius()) << ',' << s.motion_priority() << ','
    << (s.enabled() ? 1 : 0) << ',' << (s.virtual_segment() ? 1 : 0) << '\n';
}

void csvColumns(std::ostream& o, const msg::WalkCommand&) { o << ",goal_x,goal_y,goal_yaw,speed,stop"; }
void csvRows(std::ostream& o, const std::string& prefix, const msg::WalkCommand& s) {
  o << prefix << ',' << num(s.goal_x()) << ',' << num(s.goal_y()) << ',' << num(s.goal_yaw()) << ',' << num(s.speed())
    << ',' << (s.stop() ? 1 : 0) << '\n';
}

void csvColumns(std::ostream& o, const msg::JointState& first) {
  for (const auto& n : first.names()) o << ",q_" << n;
  for (const auto& n : first.names()) o << ",qd_" << n;
}
void csvRows(std::ostream& o, const std::string& prefix, const msg::JointState& s) {
  o << prefix;
  for (double v : s.positions()) o << ',' << num(v);
  for (double v : s.velocities()) o << ',' << num(v);
  o << '\n';
}

void csvColumns(std::ostream& o, const msg::ControlStatus&) {
  for (const char* a : {"left", "right"})
    o << ',' << a << "_f," << a << "_distance," << a << "_zone," << a << "_estop," << a << "_closest_a," << a
      << "_closest_b";
  o << ",cycle_period_us,compute_time_us,lateness_us,overrun_count,arm_distance,rejected_hand_targets,"
       "rejected_body_schema,rejected_walk_commands,rejected_robot_states,last_rejection";
}
void csvRows(std::ostream& o, const std::string& prefix, const msg::ControlStatus& s) {
  o << prefix;
  arm(o, s.left());
  arm(o, s.right());
  o << ',' << num(s.cycle_period_us()) << ',' << num(s.compute_time_us()) << ',' << num(s.lateness_us()) << ','
    << s.overrun_count() << ',' << num(s.arm_distance()) << ',' << s.rejected_hand_targets() << ','
    << s.rejected_body_schema() << ',' << s.rejected_walk_commands() << ',' << s.rejected_robot_states() << ','
    << csvField(s.last_rejection()) << '\n';
}

void csvColumns(std::ostream& o, const msg::Heartbeat&) { o << ",module_name,host,pid,state,period_ms,detail"; }
void csvRows(std::ostream& o, const std::string& prefix, const msg::Heartbeat& s) {
  o << prefix << ',' << csvField(s.module_name()) << ',' << csvField(s.host()) << ',' << s.pid() << ','
    << static_cast<int>(s.state()) << ',' << s.period_ms() << ',' << csvField(s.detail()) << '\n';
}

void csvColumns(std::ostream& o, const msg::ControllerProtection&) { o << ",avoidance,estop,reason,period,robot"; }
void csvRows(std::ostream& o, const std::string& prefix, const msg::ControllerProtection& s) {
  o << prefix << ',' << (s.avoidance() ? 1 : 0) << ',' << (s.estop() ? 1 : 0) << ',' << csvField(s.reason()) << ','
    << num(s.period()) << ',' << csvField(s.robot()) << '\n';
}

// The robot boundary (idl/robot.idl): one row per sample; the joints named by the first
// sample give the columns (like JointState).
void csvColumns(std::ostream& o, const msg::RobotState& first) {
  for (const auto& n : first.names()) o << ",q_" << n;
  for (const auto& n : first.names()) o << ",qd_" << n;
  for (const auto& n : first.names()) o << ",effort_" << n;
  o << ",applied_command_seq,holding";
}
void csvRows(std::ostream& o, const std::string& prefix, const msg::RobotState& s) {
  o << prefix;
  for (double v : s.positions()) o << ',' << num(v);
  for (double v : s.velocities()) o << ',' << num(v);
  // Efforts may be empty (not measured): empty cells, so the row keeps the header's width.
  for (std::size_t i = 0; i < s.names().size(); ++i) o << ',' << (i < s.efforts().size() ? num(s.efforts()[i]) : "");
  o << ',' << s.applied_command_seq() << ',' << (s.holding() ? 1 : 0) << '\n';
}

void csvColumns(std::ostream& o, const msg::JointCommand& first) {
  o << ",valid_until_ns,state_seq,state_stamp_ns";
  for (const auto& n : first.names()) o << ",q_" << n;
  for (const auto& n : first.names()) o << ",qd_" << n;
}
void csvRows(std::ostream& o, const std::string& prefix, const msg::JointCommand& s) {
  o << prefix << ',' << s.valid_until_ns() << ',' << s.state_seq() << ',' << s.state_stamp_ns();
  for (double v : s.positions()) o << ',' << num(v);
  for (double v : s.velocities()) o << ',' << num(v);
  o << '\n';
}

// One row per reported pair (like ObjectTargets); a sample without pairs is one row with empty cells.
void csvColumns(std::ostream& o, const msg::RobotContacts&) {
  o << ",state_seq,total_contact_steps,n_contacts,segment_a,segment_b,distance";
}
void csvRows(std::ostream& o, const std::string& prefix, const msg::RobotContacts& s) {
  const std::string head = prefix + "," + std::to_string(s.state_seq()) + "," +
                           std::to_string(s.total_contact_steps()) + "," + std::to_string(s.contacts().size());
  if (s.contacts().empty()) o << head << ",,,\n";
  for (const auto& c : s.contacts())
    o << head << ',' << csvField(c.segment_a()) << ',' << csvField(c.segment_b()) << ',' << num(c.distance()) << '\n';
}

// The image itself is not a CSV cell: its size and format are.
void csvColumns(std::ostream& o, const msg::CameraImage&) {
  o << ",capture_stamp_ns,image_index,frame_id,format,width,height,bytes";
}
void csvRows(std::ostream& o, const std::string& prefix, const msg::CameraImage& s) {
  o << prefix << ',' << s.capture_stamp_ns() << ',' << s.image_index() << ',' << csvField(s.frame_id()) << ','
    << csvField(s.format()) << ',' << s.width() << ',' << s.height() << ',' << s.data().size() << '\n';
}

// ---- restamping for replay ---------------------------------------------------------------------

// A stamp comes from the recorded payload (any int64): the shifted value saturates instead of
// overflowing.
std::int64_t shifted(std::int64_t stamp, std::int64_t shift) {
  std::int64_t out = 0;
  if (!__builtin_add_overflow(stamp, shift, &out)) return out;
  return shift > 0 ? std::numeric_limits<std::int64_t>::max() : std::numeric_limits<std::int64_t>::min();
}
template <class T>
void shiftStamps(T& s, std::int64_t shift) {
  s.header().stamp_ns(shifted(s.header().stamp_ns(), shift));
}
template <>
void shiftStamps(msg::CameraImage& s, std::int64_t shift) {
  s.header().stamp_ns(shifted(s.header().stamp_ns(), shift));
  s.capture_stamp_ns(shifted(s.capture_stamp_ns(), shift));
}
template <>
void shiftStamps(msg::ObjectTargets& s, std::int64_t shift) {
  s.header().stamp_ns(shifted(s.header().stamp_ns(), shift));
  s.capture_stamp_ns(shifted(s.capture_stamp_ns(), shift));
}
// A command's deadline and the stamp of the state it answered move with it (a replayed command keeps
// its age and its latency; it is played only when named with --topic, see player.cpp).
template <>
void shiftStamps(msg::JointCommand& s, std::int64_t shift) {
  s.header().stamp_ns(shifted(s.header().stamp_ns(), shift));
  s.valid_until_ns(shifted(s.valid_until_ns(), shift));
  s.state_stamp_ns(shifted(s.state_stamp_ns(), shift));
}

// ---- the codec ------------------------------------------------------------------------------------

template <class T>
class Publisher final : public SamplePublisher {
 public:
  explicit Publisher(bus::Writer<T>& w) : writer_(w) {}
  bool publish(const std::vector<std::uint8_t>& payload, std::int64_t shift_ns) override {
    if (!deserializeSample(payload, sample_)) return false;
    if (shift_ns != 0) shiftStamps(sample_, shift_ns);
    return writer_.write(sample_);
  }
  int matchedReaders() const override { return writer_.stats().matched_readers; }

 private:
  bus::Writer<T>& writer_;
  T sample_;
};

template <class T>
class Codec final : public TopicCodec {
 public:
  Codec() : name_(typename bus::TopicTraits<T>::PubSubType().getName()) {}
  const std::string& typeName() const override { return name_; }
  std::string shortName() const override { return name_.substr(name_.rfind(':') + 1); }
  const char* defaultTopic() const override { return bus::TopicTraits<T>::kTopicName; }
  const char* defaultProfile() const override { return bus::TopicTraits<T>::kProfile; }
  bool isState() const override {
    const std::string p = defaultProfile();
    return p == bus::kProfileBehavior || p == bus::kProfileHeartbeat || p == bus::kProfileControllerInfo;
  }

  bus::detail::ReaderBase& subscribe(bus::Participant& bus, const std::string& topic, const std::string& profile,
                                     std::function<void(RecordEntry&&)> sink) const override {
    auto& reader = bus.makeReader<T>(topic, profile);
    reader.onDataWithInfo([sink = std::move(sink), topic, type = name_](const T& s, const bus::dds::SampleInfo& info) {
      RecordEntry e;
      e.receive_ns = bus::nowNs();
      e.source_ns = info.source_timestamp.to_ns();
      e.topic = topic;
      e.type = type;
      e.payload = serializeSample(s);
      sink(std::move(e));
    });
    return reader;
  }
  std::unique_ptr<SamplePublisher> makePublisher(bus::Participant& bus, const std::string& topic,
                                                 const std::string& profile) const override {
    return std::make_unique<Publisher<T>>(bus.makeWriter<T>(topic, profile));
  }

  void writeCsvHeader(std::ostream& out, const RecordEntry& first) const override {
    const T s = decode(first);  // before writing: an undecodable sample leaves the file as it was
    out << "t,receive_ns,source_ns,stamp_ns,seq,source";
    csvColumns(out, s);
    out << '\n';
  }
  void writeCsvRows(std::ostream& out, const RecordEntry& e, const CsvContext& ctx) const override {
    const T s = decode(e);
    char t[40];
    std::snprintf(t, sizeof(t), "%.6f", 1e-9 * static_cast<double>(e.receive_ns - ctx.t0_ns));
    const std::string prefix = std::string(t) + "," + std::to_string(e.receive_ns) + "," + std::to_string(e.source_ns) +
                               "," + std::to_string(s.header().stamp_ns()) + "," + std::to_string(s.header().seq()) +
                               "," + csvField(s.header().source());
    csvRows(out, prefix, s);
  }
  std::string summary(const RecordEntry& e) const override {
    const T s = decode(e);
    std::ostringstream o;
    o << printableName(e.topic) << " seq " << s.header().seq() << " from '" << printableName(s.header().source())
      << "' stamp " << s.header().stamp_ns() << ":";
    std::ostringstream row;
    csvRows(row, "", s);
    std::string r = row.str();
    if (!r.empty() && r.back() == '\n') r.pop_back();
    if (r.size() > 160) r = r.substr(0, 160) + "...";
    o << r;
    return o.str();
  }

 private:
  T decode(const RecordEntry& e) const {
    T s;
    std::string why;
    if (!deserializeSample(e.payload, s, &why))
      throw RecordError("record of topic '" + printableName(e.topic) + "' does not deserialize as " + name_ + " (" +
                        std::to_string(e.payload.size()) + " bytes: " + why + ")");
    return s;
  }
  std::string name_;
};

}  // namespace

const std::vector<const TopicCodec*>& allCodecs() {
  static const Codec<msg::ObjectTargets> object_targets;
  static const Codec<msg::HandTargets> hand_targets;
  static const Codec<msg::MotionPriority> motion_priority;
  static const Codec<msg::BodySchemaChange> body_schema;
  static const Codec<msg::WalkCommand> walk_command;
  static const Codec<msg::JointState> joint_state;
  static const Codec<msg::ControlStatus> control_status;
  static const Codec<msg::Heartbeat> heartbeat;
  static const Codec<msg::ControllerProtection> controller_protection;  // who protects the robot
  static const Codec<msg::RobotState> robot_state;                      // the robot boundary
  static const Codec<msg::JointCommand> joint_command;
  static const Codec<msg::RobotContacts> robot_contacts;
  static const Codec<msg::CameraImage> camera_image;  // vision's left image (viewers, Foxglove)
  static const std::vector<const TopicCodec*> all = {
      &object_targets, &hand_targets,   &motion_priority, &body_schema,           &walk_command,
      &joint_state,    &control_status, &heartbeat,       &controller_protection, &robot_state,
      &joint_command,  &robot_contacts, &camera_image};
  return all;
}

const TopicCodec* findCodecByType(const std::string& type_name) {
  for (const TopicCodec* c : allCodecs())
    if (c->typeName() == type_name || c->shortName() == type_name) return c;
  return nullptr;
}

const TopicCodec* findCodecByTopic(const std::string& topic) {
  for (const TopicCodec* c : allCodecs())
    if (topic == c->defaultTopic()) return c;
  return nullptr;
}

TopicSpec parseTopicSpec(const std::string& text) {
  TopicSpec spec;
  const auto colon = text.find(':');
  // "reflex::msg::X" contains "::"; a spec separates topic and type with the FIRST single ':'.
  if (colon != std::string::npos && colon > 0) {
    spec.topic = text.substr(0, colon);
    const std::string type = text.substr(colon + 1);
    spec.codec = findCodecByType(type);
    if (!spec.codec) {
      std::string known;
      for (const TopicCodec* c : allCodecs()) known += " " + c->shortName();
      throw RecordError("unknown type '" + type + "' in topic '" + text + "' (known:" + known + ")");
    }
    return spec;
  }
  spec.topic = text;
  spec.codec = findCodecByTopic(text);
  if (!spec.codec) {
    std::string known;
    for (const TopicCodec* c : allCodecs()) known += std::string(" ") + c->defaultTopic();
    throw RecordError("unknown topic '" + text + "' (known:" + known + "; or give NAME:TYPE)");
  }
  return spec;
}

std::string csvField(const std::string& s) {
  if (s.find_first_of(",\"\n\r") == std::string::npos) return s;
  std::string out = "\"";
  for (char c : s) {
    if (c == '"') out += '"';
    out += c;
  }
  return out + "\"";
}

std::string printableName(const std::string& name) {
  std::string out;
  out.reserve(name.size());
  for (char c : name) {
    const auto b = static_cast<unsigned char>(c);
    if (b < 0x20 || b == 0x7F || c == '\\') {
      char buf[8];
      std::snprintf(buf, sizeof(buf), "\\x%02X", b);
      out += buf;
    } else {
      out += c;
    }
  }
  return out;
}

}  // namespace reflex::record
