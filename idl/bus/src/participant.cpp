#include "reflex/bus/participant.hpp"

#include "reflex/common/files.hpp"

#include <fastdds/dds/core/condition/StatusCondition.hpp>
#include <fastdds/dds/domain/DomainParticipantFactory.hpp>
#include <fastdds/dds/domain/qos/DomainParticipantQos.hpp>
#include <fastdds/dds/publisher/Publisher.hpp>
#include <fastdds/dds/publisher/qos/DataWriterQos.hpp>
#include <fastdds/dds/subscriber/Subscriber.hpp>
#include <fastdds/dds/subscriber/qos/DataReaderQos.hpp>
#include <fastdds/dds/topic/Topic.hpp>

#include <fastdds/dds/domain/DomainParticipantListener.hpp>
#include <fastrtps/rtps/participant/ParticipantDiscoveryInfo.h>

#include <fcntl.h>
#include <sys/file.h>
#include <unistd.h>

#include <algorithm>
#include <condition_variable>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <mutex>
#include <thread>

namespace reflex::bus {

namespace {

using eprosima::fastrtps::types::ReturnCode_t;
using Clock = std::chrono::steady_clock;

eprosima::fastrtps::Duration_t toDuration(std::chrono::nanoseconds ns) {
  if (ns.count() <= 0) return eprosima::fastrtps::Duration_t(0, 0);
  const auto s = std::chrono::duration_cast<std::chrono::seconds>(ns);
  return eprosima::fastrtps::Duration_t(static_cast<std::int32_t>(s.count()),
                                        static_cast<std::uint32_t>((ns - s).count()));
}

// Where the profiles file path came from, for error messages (mirrors resolveProfilesFile).
std::string profilesFileOrigin(const std::string& configured) {
  if (!configured.empty()) return "the bus configuration";
  if (const char* env = std::getenv("FASTRTPS_DEFAULT_PROFILES_FILE"); env && *env) {
    return "environment variable FASTRTPS_DEFAULT_PROFILES_FILE";
  }
  return "the compiled-in default";
}

// Polls `ok` every few milliseconds until it holds or `timeout` passes (setup-time waits only).
template <class Pred>
bool pollUntil(Pred ok, std::chrono::nanoseconds timeout) {
  const auto end = Clock::now() + timeout;
  while (!ok()) {
    if (Clock::now() >= end) return false;
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  return true;
}

}  // namespace

int nextParticipantId() noexcept {
  // Without the file (or when it cannot be advanced): the pid's value, then the next ones.
  static std::atomic<unsigned> in_process{0};
  unsigned n = static_cast<unsigned>(::getpid()) + in_process.fetch_add(1);
  // O_NOFOLLOW: /dev/shm is shared by every user; a link planted there is not followed.
  const std::string path = "/dev/shm/reflex_bus_participant_ids_" + std::to_string(::getuid());
  const int fd = ::open(path.c_str(), O_RDWR | O_CREAT | O_CLOEXEC | O_NOFOLLOW, 0600);
  if (fd < 0) return static_cast<int>(n % static_cast<unsigned>(kParticipantIdRange));
  if (::flock(fd, LOCK_EX) == 0) {
    std::uint32_t stored = n;  // a new (empty) file starts from the fallback
    (void)::pread(fd, &stored, sizeof stored, 0);
    const std::uint32_t advanced = stored + 1;
    if (::pwrite(fd, &advanced, sizeof advanced, 0) == static_cast<ssize_t>(sizeof advanced)) n = stored;
    ::flock(fd, LOCK_UN);
  }
  ::close(fd);
  return static_cast<int>(n % static_cast<unsigned>(kParticipantIdRange));
}

std::vector<int> participantIdsOfThisProcess() {
  std::vector<int> ids;
  auto* factory = dds::DomainParticipantFactory::get_instance();
  // Every domain id RTPS allows (port 7400 + 250 d stays below 65536 for d <= 232).
  for (dds::DomainId_t d = 0; d <= 232; ++d) {
    for (const dds::DomainParticipant* p : factory->lookup_participants(d)) {
      const auto& v = p->guid().guidPrefix.value;
      ids.push_back(static_cast<int>(static_cast<std::uint32_t>(v[8]) | (static_cast<std::uint32_t>(v[9]) << 8) |
                                     (static_cast<std::uint32_t>(v[10]) << 16) |
                                     (static_cast<std::uint32_t>(v[11]) << 24)));
    }
  }
  return ids;
}

std::int64_t nowNs() noexcept {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::system_clock::now().time_since_epoch())
      .count();
}

// ---- status counters -------------------------------------------------------------------------

namespace detail {

void ReaderCounters::on_requested_deadline_missed(dds::DataReader*, const dds::RequestedDeadlineMissedStatus& s) {
  deadline_missed_.store(static_cast<std::uint64_t>(s.total_count));
}
void ReaderCounters::on_sample_lost(dds::DataReader*, const dds::SampleLostStatus& s) {
  samples_lost_.store(static_cast<std::uint64_t>(s.total_count));
}
void ReaderCounters::on_sample_rejected(dds::DataReader*, const dds::SampleRejectedStatus& s) {
  samples_rejected_.store(static_cast<std::uint64_t>(s.total_count));
}
void ReaderCounters::on_requested_incompatible_qos(dds::DataReader*, const dds::RequestedIncompatibleQosStatus& s) {
  incompatible_qos_.store(static_cast<std::uint64_t>(s.total_count));
}
void ReaderCounters::on_liveliness_changed(dds::DataReader*, const dds::LivelinessChangedStatus& s) {
  alive_writers_.store(s.alive_count);
  if (s.not_alive_count_change > 0) {
    liveliness_lost_.fetch_add(static_cast<std::uint64_t>(s.not_alive_count_change));
  }
}
void ReaderCounters::on_subscription_matched(dds::DataReader*, const dds::SubscriptionMatchedStatus& s) {
  matched_writers_.store(s.current_count);
}
ReaderStats ReaderCounters::snapshot() const {
  ReaderStats r;
  r.deadline_missed = deadline_missed_.load();
  r.samples_lost = samples_lost_.load();
  r.samples_rejected = samples_rejected_.load();
  r.incompatible_qos = incompatible_qos_.load();
  r.liveliness_lost = liveliness_lost_.load();
  r.alive_writers = alive_writers_.load();
  r.matched_writers = matched_writers_.load();
  return r;
}

void WriterCounters::on_offered_deadline_missed(dds::DataWriter*, const dds::OfferedDeadlineMissedStatus& s) {
  deadline_missed_.store(static_cast<std::uint64_t>(s.total_count));
}
void WriterCounters::on_liveliness_lost(dds::DataWriter*, const dds::LivelinessLostStatus& s) {
  liveliness_lost_.store(static_cast<std::uint64_t>(s.total_count));
}
void WriterCounters::on_offered_incompatible_qos(dds::DataWriter*, const dds::OfferedIncompatibleQosStatus& s) {
  incompatible_qos_.store(static_cast<std::uint64_t>(s.total_count));
}
void WriterCounters::on_publication_matched(dds::DataWriter*, const dds::PublicationMatchedStatus& s) {
  matched_readers_.store(s.current_count);
}
WriterStats WriterCounters::snapshot() const {
  WriterStats w;
  w.deadline_missed = deadline_missed_.load();
  w.liveliness_lost = liveliness_lost_.load();
  w.incompatible_qos = incompatible_qos_.load();
  w.matched_readers = matched_readers_.load();
  return w;
}

// ---- writer / reader bases -------------------------------------------------------------------

bool WriterBase::writeRaw(void* sample) noexcept { return writer_->write(sample); }

bool WriterBase::waitForReaders(int count, std::chrono::nanoseconds timeout) const {
  return pollUntil([&] { return counters_.snapshot().matched_readers >= count; }, timeout);
}

bool ReaderBase::waitForWriters(int count, std::chrono::nanoseconds timeout) const {
  return pollUntil([&] { return counters_.snapshot().matched_writers >= count; }, timeout);
}

bool ReaderBase::waitForData(std::chrono::nanoseconds timeout) {
  return reader_->wait_for_unread_message(toDuration(timeout));
}

}  // namespace detail

// ---- participant -----------------------------------------------------------------------------

// What the Participant keeps beside its entities: the names remote participants announce
// (discovery, Fast DDS threads), the result of the security check, and the expiry watchdog.
struct Participant::Extras final : public dds::DomainParticipantListener {
  // Discovery: GUID prefix -> announced name (not authenticated).
  void on_participant_discovery(dds::DomainParticipant*,
                                eprosima::fastrtps::rtps::ParticipantDiscoveryInfo&& info) override {
    using Status = eprosima::fastrtps::rtps::ParticipantDiscoveryInfo;
    GuidPrefix prefix{};
    std::copy(std::begin(info.info.m_guid.guidPrefix.value), std::end(info.info.m_guid.guidPrefix.value),
              prefix.begin());
    const std::lock_guard<std::mutex> lock(names_mutex);
    if (info.status == Status::DISCOVERED_PARTICIPANT || info.status == Status::CHANGED_QOS_PARTICIPANT) {
      names[prefix] = info.info.m_participantName.to_string();
    } else if (info.status == Status::REMOVED_PARTICIPANT || info.status == Status::DROPPED_PARTICIPANT) {
      names.erase(prefix);
    }
  }

  // Sleeps until the material expires (or the participant closes); then says so and stops it.
  void watchExpiry(Participant& owner) {
    std::unique_lock<std::mutex> lock(expiry_mutex);
    if (expiry_cv.wait_until(lock, check.valid_until, [&] { return closing; })) return;
    expiry_message = "the DDS-Security " + check.valid_until_what + " of participant '" + owner.module_name_ +
                     "' expired at " + formatUtc(check.valid_until) +
                     "; stopping (Fast DDS checks validity only when peers authenticate, so Reflex stops the "
                     "process itself: deploy new credentials and restart it)";
    expired.store(true);  // after the message: run() reads it once it sees the flag
    std::fprintf(stderr, "reflex::bus: %s\n", expiry_message.c_str());
    std::fflush(stderr);
    owner.stop();
  }

  mutable std::mutex names_mutex;
  std::map<GuidPrefix, std::string> names;
  bool secure = false;
  SecurityCheck check;
  std::mutex expiry_mutex;
  std::condition_variable expiry_cv;
  bool closing = false;
  std::atomic<bool> expired{false};
  std::string expiry_message;
  std::thread watchdog;
};

bool Participant::secure() const noexcept { return extras_->secure; }
const std::string& Participant::identitySubject() const noexcept { return extras_->check.subject; }
std::chrono::system_clock::time_point Participant::credentialsValidUntil() const noexcept {
  return extras_->secure ? extras_->check.valid_until : std::chrono::system_clock::time_point::max();
}
bool Participant::credentialsExpired() const noexcept { return extras_->expired.load(); }
std::string Participant::discoveredName(const GuidPrefix& prefix) const {
  const std::lock_guard<std::mutex> lock(extras_->names_mutex);
  auto it = extras_->names.find(prefix);
  return it == extras_->names.end() ? std::string() : it->second;
}

std::vector<GuidPrefix> Participant::discoveredParticipants() const {
  const std::lock_guard<std::mutex> lock(extras_->names_mutex);
  std::vector<GuidPrefix> out;
  for (const auto& [prefix, name] : extras_->names) out.push_back(prefix);
  return out;
}

Participant::Participant(const BusConfig& config)
    : module_name_(config.module_name),
      domain_id_(resolveDomainId(config.domain_id)),
      profiles_file_(resolveProfilesFile(config.profiles_file)),
      extras_(std::make_unique<Extras>()) {
  if (module_name_.empty()) throw BusError("empty module name in the bus configuration");
  // The module name is the key of this process's heartbeat: a longer one would abort the process in
  // its first heartbeat.
  if (module_name_.size() > kMaxKeyStringBytes) {
    throw BusError("module name '" + module_name_ + "' is " + std::to_string(module_name_.size()) +
                   " bytes long; at most " + std::to_string(kMaxKeyStringBytes) +
                   " bytes (it is the DDS key of the process's heartbeat)");
  }

  const std::string origin = profilesFileOrigin(config.profiles_file);
  // Checked before any open: a FIFO or device named as the profiles file would block or never end.
  if (const std::string why = common::inputFileProblem(profiles_file_); !why.empty())
    throw BusError("DDS QoS profiles file " + why + " (from " + origin + ")");
  if (!std::ifstream(profiles_file_).good()) {
    throw BusError("cannot open the DDS QoS profiles file '" + profiles_file_ + "' (from " + origin + ")");
  }
  auto* factory = dds::DomainParticipantFactory::get_instance();
  if (factory->load_XML_profiles_file(profiles_file_) != ReturnCode_t::RETCODE_OK) {
    throw BusError("malformed DDS QoS profiles file '" + profiles_file_ + "' (from " + origin +
                   "): Fast DDS could not parse it (its log above says where)");
  }

  dds::DomainParticipantQos qos;
  if (factory->get_participant_qos_from_profile(config.participant_profile, qos) != ReturnCode_t::RETCODE_OK) {
    throw BusError("unknown participant QoS profile '" + config.participant_profile + "'" + where());
  }
  // Security material: checked here so that a bad file is named (Fast DDS would only fail below).
  std::vector<std::pair<std::string, std::string>> properties;
  for (const auto& p : qos.properties().properties()) properties.emplace_back(p.name(), p.value());
  const SecurityMaterial material = securityMaterialOf(properties);
  extras_->secure = material.enabled;
  if (material.enabled) {
    try {
      extras_->check = checkSecurityMaterial(material, std::chrono::system_clock::now());
    } catch (const BusError& e) {
      throw BusError("participant '" + module_name_ + "': " + e.what() + where());
    }
  }
  // Discovery (SPDP) is plain text even under DDS-Security: announce no more than peers need. The
  // host name, user name and process id Fast DDS adds for its monitor are left out; a secure
  // participant announces no name either (its certificate identifies it to authenticated peers).
  auto& props = qos.properties().properties();
  props.erase(std::remove_if(props.begin(), props.end(),
                             [](const eprosima::fastrtps::rtps::Property& p) {
                               return p.name().rfind("fastdds.physical_data.", 0) == 0;
                             }),
              props.end());
  qos.name(material.enabled ? std::string() : module_name_);
  // Not the lowest free id (a restarted process would take its predecessor's; see nextParticipantId).
  // Never an id a participant of this process already holds (the counter came round while it lived,
  // or Fast DDS numbered a raw participant itself): Fast DDS refuses it, and the refused attempt
  // leaves the holder deaf to participants discovered later (measured: never heard in 10 s). The
  // retry covers a participant another thread creates meanwhile.
  const bool choose_id = qos.wire_protocol().participant_id < 0;
  const std::vector<int> held = choose_id ? participantIdsOfThisProcess() : std::vector<int>{};
  for (int attempt = 0; attempt < 3 && participant_ == nullptr; ++attempt) {
    if (choose_id) {
      int id = nextParticipantId();
      for (int skip = 0; skip < kParticipantIdRange && std::count(held.begin(), held.end(), id) > 0; ++skip) {
        id = nextParticipantId();
      }
      qos.wire_protocol().participant_id = id;
    }
    // The listener gets participant discovery only (it is not in the status mask for anything else).
    participant_ = factory->create_participant(static_cast<dds::DomainId_t>(domain_id_), qos, extras_.get(),
                                               dds::StatusMask::none());
    if (!choose_id) break;
  }
  if (participant_ == nullptr) {
    throw BusError("could not create the DDS participant '" + module_name_ + "' on domain " +
                   std::to_string(domain_id_) + " with profile '" + config.participant_profile + "'" + where());
  }
  // From here on the participant exists: release it if anything else fails.
  try {
    publisher_ = participant_->create_publisher(dds::PUBLISHER_QOS_DEFAULT, nullptr, dds::StatusMask::none());
    if (publisher_ == nullptr) {
      throw BusError("could not create the DDS publisher of participant '" + module_name_ + "'");
    }
    subscriber_ = participant_->create_subscriber(dds::SUBSCRIBER_QOS_DEFAULT, nullptr, dds::StatusMask::none());
    if (subscriber_ == nullptr) {
      throw BusError("could not create the DDS subscriber of participant '" + module_name_ + "'");
    }
  } catch (...) {
    participant_->delete_contained_entities();
    factory->delete_participant(participant_);
    participant_ = nullptr;
    throw;
  }
  if (extras_->secure && extras_->check.valid_until != std::chrono::system_clock::time_point::max()) {
    extras_->watchdog = std::thread([this] { extras_->watchExpiry(*this); });
  }
}

Participant::~Participant() {
  if (extras_->watchdog.joinable()) {
    {
      const std::lock_guard<std::mutex> lock(extras_->expiry_mutex);
      extras_->closing = true;
    }
    extras_->expiry_cv.notify_all();
    extras_->watchdog.join();
  }
  // Entities first (readers, writers, publisher, subscriber, topics), then the participant; the
  // Writer/Reader objects (and their listeners) are destroyed after this body, once nothing can
  // call them any more.
  participant_->delete_contained_entities();
  dds::DomainParticipantFactory::get_instance()->delete_participant(participant_);
  participant_ = nullptr;
}

int Participant::participantId() const { return participant_->get_qos().wire_protocol().participant_id; }

std::string Participant::where() const { return " (profiles file '" + profiles_file_ + "')"; }

dds::Topic& Participant::topicFor(const std::string& topic_name, dds::TypeSupport type) {
  const std::string type_name = type.get_type_name();
  if (auto it = topics_.find(topic_name); it != topics_.end()) {
    const std::string existing = it->second->get_type_name();
    if (existing != type_name) {
      throw BusError("topic '" + topic_name + "' already exists with type '" + existing +
                     "'; cannot use it with type '" + type_name + "'");
    }
    return *it->second;
  }
  if (participant_->find_type(type_name).empty() && type.register_type(participant_) != ReturnCode_t::RETCODE_OK) {
    throw BusError("could not register type '" + type_name + "' for topic '" + topic_name + "'");
  }
  dds::Topic* topic = participant_->create_topic(topic_name, type_name, dds::TOPIC_QOS_DEFAULT);
  if (topic == nullptr) {
    throw BusError("could not create topic '" + topic_name + "' of type '" + type_name + "'");
  }
  topics_.emplace(topic_name, topic);
  return *topic;
}

void Participant::createWriter(detail::WriterBase& w, dds::TypeSupport type) {
  dds::DataWriterQos qos;
  if (publisher_->get_datawriter_qos_from_profile(w.profile_name_, qos) != ReturnCode_t::RETCODE_OK) {
    throw BusError("unknown data_writer QoS profile '" + w.profile_name_ + "' for topic '" + w.topic_name_ + "'" +
                   where());
  }
  dds::Topic& topic = topicFor(w.topic_name_, std::move(type));
  dds::StatusMask mask = dds::StatusMask::none();
  mask << dds::StatusMask::offered_deadline_missed() << dds::StatusMask::liveliness_lost()
       << dds::StatusMask::offered_incompatible_qos() << dds::StatusMask::publication_matched();
  w.writer_ = publisher_->create_datawriter(&topic, qos, &w.counters_, mask);
  if (w.writer_ == nullptr) {
    // Under DDS-Security the usual cause is access control: the identity's signed permissions grant
    // no publish rule for this topic (Fast DDS refuses the writer without saying why).
    if (secure()) {
      throw BusError("DDS-Security refused the DataWriter of topic '" + w.topic_name_ +
                     "': the permissions of this participant's identity grant no publish rule for it "
                     "(bringup/security/make_security.sh, publish[...]; or the QoS of profile '" +
                     w.profile_name_ + "' is inconsistent)" + where());
    }
    throw BusError("could not create the DataWriter of topic '" + w.topic_name_ + "' with profile '" + w.profile_name_ +
                   "' (inconsistent QoS in the profile?)" + where());
  }
}

void Participant::createReader(detail::ReaderBase& r, dds::TypeSupport type) {
  dds::DataReaderQos qos;
  if (subscriber_->get_datareader_qos_from_profile(r.profile_name_, qos) != ReturnCode_t::RETCODE_OK) {
    throw BusError("unknown data_reader QoS profile '" + r.profile_name_ + "' for topic '" + r.topic_name_ + "'" +
                   where());
  }
  dds::Topic& topic = topicFor(r.topic_name_, std::move(type));
  // Data availability is NOT in the listener mask: it goes to the reader's StatusCondition (WaitSet).
  dds::StatusMask mask = dds::StatusMask::none();
  mask << dds::StatusMask::requested_deadline_missed() << dds::StatusMask::sample_lost()
       << dds::StatusMask::sample_rejected() << dds::StatusMask::requested_incompatible_qos()
       << dds::StatusMask::liveliness_changed() << dds::StatusMask::subscription_matched();
  r.reader_ = subscriber_->create_datareader(&topic, qos, &r.counters_, mask);
  if (r.reader_ == nullptr) {
    if (secure()) {
      throw BusError("DDS-Security refused the DataReader of topic '" + r.topic_name_ +
                     "': the permissions of this participant's identity grant no subscribe rule for it "
                     "(bringup/security/make_security.sh, subscribe[...]; or the QoS of profile '" +
                     r.profile_name_ + "' is inconsistent)" + where());
    }
    throw BusError("could not create the DataReader of topic '" + r.topic_name_ + "' with profile '" + r.profile_name_ +
                   "' (inconsistent QoS in the profile?)" + where());
  }
  r.reader_->get_statuscondition().set_enabled_statuses(dds::StatusMask::data_available());
}

void Participant::every(std::chrono::nanoseconds period, std::function<void()> fn) {
  if (period.count() <= 0) {
    throw BusError("timer period must be > 0 ns, got " + std::to_string(period.count()) + " ns");
  }
  if (running_) throw BusError("every() called while participant '" + module_name_ + "' is running its loop");
  timers_.push_back(Timer{period, std::move(fn), Clock::now() + period});
}

void Participant::run() {
  loop(nullptr);
  if (credentialsExpired()) throw BusError(extras_->expiry_message);
}

bool Participant::runFor(std::chrono::nanoseconds duration) {
  const auto end = Clock::now() + duration;
  const bool ran_out = loop(&end);
  if (!ran_out && credentialsExpired()) throw BusError(extras_->expiry_message);
  return ran_out;
}

void Participant::stop() noexcept {
  stop_.store(true);
  stop_guard_.set_trigger_value(true);
}

bool Participant::loop(const Clock::time_point* end) {
  // The WaitSet lives for this call: readers that got an onData callback since the last call are
  // included, and nothing stays attached once run() returns.
  dds::WaitSet wait_set;
  wait_set.attach_condition(stop_guard_);
  std::vector<std::pair<dds::Condition*, detail::ReaderBase*>> dispatch;
  for (auto& r : readers_) {
    if (!r->hasCallback()) continue;
    dds::StatusCondition& c = r->reader_->get_statuscondition();
    wait_set.attach_condition(c);
    dispatch.emplace_back(&c, r.get());
  }
  const auto start = Clock::now();
  for (auto& t : timers_) t.next = start + t.period;
  running_ = true;
  struct Running {
    bool& flag;
    ~Running() { flag = false; }
  } running_guard{running_};

  while (!stop_.load()) {
    auto now = Clock::now();
    for (auto& t : timers_) {
      if (now < t.next) continue;
      t.fn();
      t.next += t.period;
      if (t.next <= now) t.next = now + t.period;  // skip the calls we were too late for
    }
    if (stop_.load()) break;
    now = Clock::now();
    if (end != nullptr && now >= *end) return true;

    auto wake = end != nullptr ? *end : Clock::time_point::max();
    for (const auto& t : timers_) wake = std::min(wake, t.next);
    const auto timeout = wake == Clock::time_point::max() ? eprosima::fastrtps::c_TimeInfinite : toDuration(wake - now);
    dds::ConditionSeq active;
    const ReturnCode_t rc = wait_set.wait(active, timeout);
    if (rc == ReturnCode_t::RETCODE_TIMEOUT) continue;
    if (rc != ReturnCode_t::RETCODE_OK) {
      throw BusError("WaitSet wait failed in participant '" + module_name_ + "' (return code " + std::to_string(rc()) +
                     ")");
    }
    for (dds::Condition* c : active) {
      for (auto& [condition, reader] : dispatch) {
        if (condition == c) reader->dispatch();
      }
    }
  }
  return false;
}

}  // namespace reflex::bus
