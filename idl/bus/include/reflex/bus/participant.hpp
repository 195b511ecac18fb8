// reflex::bus — the one RAII skeleton of every Reflex DDS process (STYLE.md Sec. 8).
//
// A Participant owns the DDS domain participant, one publisher, one subscriber, the topics, and every
// Writer<T> / Reader<T> made from it. Writers and readers are created from NAMED QoS profiles of the
// profiles XML file (bringup/dds/reflex_profiles.xml); QoS never lives in code. The constructor and
// the make* functions throw BusError naming what failed (profile, file, topic, entity); the data path
// (publish, take) never throws.
//
//   reflex::bus::Participant bus({"pointing"});                      // module name; domain from env
//   auto& targets = bus.makeWriter<reflex::msg::HandTargets>();      // default topic + profile
//   auto& objects = bus.makeReader<reflex::msg::ObjectTargets>();
//   objects.onData([&](const reflex::msg::ObjectTargets& o) { ...; targets.publish(out); });
//   reflex::bus::StopOnSignal stop_on_signal(bus);                   // SIGINT / SIGTERM -> bus.stop()
//   bus.run();                                                       // WaitSet loop until stop()
//
// Threading: make* and run* are called from one thread (the owner); stop() from any thread;
// Writer::publish and Reader::take* from any one thread per writer / reader. A Writer<T>& or
// Reader<T>& stays valid as long as its Participant lives. Readers' onData callbacks and every()
// timers run inside run() / runFor(), on the calling thread.
//
// To extend: a new topic type gets its IDL in idl/ and a TopicTraits specialization in topics.hpp.
#pragma once

#include <fastdds/dds/core/condition/GuardCondition.hpp>
#include <fastdds/dds/core/condition/WaitSet.hpp>
#include <fastdds/dds/domain/DomainParticipant.hpp>
#include <fastdds/dds/publisher/DataWriter.hpp>
#include <fastdds/dds/publisher/DataWriterListener.hpp>
#include <fastdds/dds/subscriber/DataReader.hpp>
#include <fastdds/dds/subscriber/DataReaderListener.hpp>
#include <fastdds/dds/subscriber/SampleInfo.hpp>
#include <fastdds/dds/topic/TypeSupport.hpp>
#include <fastrtps/types/TypesBase.h>

#include <atomic>
#include <chrono>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "reflex/bus/config.hpp"
#include "reflex/bus/error.hpp"
#include "reflex/bus/security.hpp"
#include "reflex/bus/topics.hpp"

namespace reflex::bus {

namespace dds = eprosima::fastdds::dds;

class Participant;

/// Nanoseconds since the Unix epoch on the system clock (the Header::stamp_ns clock).
std::int64_t nowNs() noexcept;

/// How long a publisher that held its start until its writer matched N readers (reflex_vision and
/// reflex_play --wait-readers) waits more: each reader matches the writer on its own, a moment later,
/// and drops best-effort samples of a writer it does not know yet. One host matches both sides
/// within milliseconds when idle; the first frames were lost once on a loaded machine.
inline constexpr std::chrono::milliseconds kReaderSideMatchGrace{300};

/// Participant ids Participant hands out when its profile leaves the id to Fast DDS (ids 0-99: the
/// RTPS unicast ports 7410 + 250 domain + 2 id (+1) stay inside the domain's 250 ports).
inline constexpr int kParticipantIdRange = 100;

/// The participant id for a profile that sets none: the next of a per-user counter that every
/// process of the host shares (a 4-byte file in /dev/shm, locked while it is read and advanced),
/// modulo kParticipantIdRange; without that file, the process id's. WHY: left to itself, Fast DDS 2.9
/// gives a new participant the lowest free id, so a restarted process takes the id, ports and
/// shared-memory port of the process it replaces, and its peers found it 2-29 s late (bringup/README,
/// "A controller restart"). Consecutive participants on a host get different ids; a busy port is
/// still skipped by Fast DDS (it moves to the next id's ports). Never throws.
int nextParticipantId() noexcept;

/// The participant ids of every DDS participant of this process, on every domain (Reflex's and any a
/// plugin or tool created with Fast DDS itself): bytes 8-11 of each GUID prefix, where RTPS puts the
/// id. Participant never hands out one of them (a refused attempt on a held id leaves the holder deaf
/// to later participants).
std::vector<int> participantIdsOfThisProcess();

/// Status counters of a reader since it was created (totals, never reset).
struct ReaderStats {
  std::uint64_t deadline_missed = 0;   ///< requested deadline missed (no sample within the deadline)
  std::uint64_t samples_lost = 0;      ///< samples the reader knows it will never receive
  std::uint64_t samples_rejected = 0;  ///< samples dropped for lack of resources
  std::uint64_t incompatible_qos = 0;  ///< writers seen whose offered QoS does not match
  // Liveliness is tracked only by readers whose profile requests a finite lease (reflex_heartbeat).
  std::uint64_t liveliness_lost = 0;  ///< times a matched writer was declared not alive
  std::int32_t alive_writers = 0;     ///< matched writers currently alive
  std::int32_t matched_writers = 0;   ///< matched writers now
};

/// Status counters of a writer since it was created (totals, never reset).
struct WriterStats {
  std::uint64_t deadline_missed = 0;   ///< offered deadline missed (did not publish within the deadline)
  std::uint64_t liveliness_lost = 0;   ///< times this writer failed to assert liveliness in its lease
  std::uint64_t incompatible_qos = 0;  ///< readers seen whose requested QoS does not match
  std::int32_t matched_readers = 0;    ///< matched readers now
  /// Samples publish() / write() refused because a @key string exceeds kMaxKeyStringBytes (never
  /// handed to DDS, whose key computation would abort the process).
  std::uint64_t refused_key_too_long = 0;
};

namespace detail {

// Counts reader statuses into atomics; called on Fast DDS threads.
class ReaderCounters final : public dds::DataReaderListener {
 public:
  void on_requested_deadline_missed(dds::DataReader*, const dds::RequestedDeadlineMissedStatus& s) override;
  void on_sample_lost(dds::DataReader*, const dds::SampleLostStatus& s) override;
  void on_sample_rejected(dds::DataReader*, const dds::SampleRejectedStatus& s) override;
  void on_requested_incompatible_qos(dds::DataReader*, const dds::RequestedIncompatibleQosStatus& s) override;
  void on_liveliness_changed(dds::DataReader*, const dds::LivelinessChangedStatus& s) override;
  void on_subscription_matched(dds::DataReader*, const dds::SubscriptionMatchedStatus& s) override;
  ReaderStats snapshot() const;

 private:
  std::atomic<std::uint64_t> deadline_missed_{0}, samples_lost_{0}, samples_rejected_{0}, incompatible_qos_{0},
      liveliness_lost_{0};
  std::atomic<std::int32_t> alive_writers_{0}, matched_writers_{0};
};

// Counts writer statuses into atomics; called on Fast DDS threads.
class WriterCounters final : public dds::DataWriterListener {
 public:
  void on_offered_deadline_missed(dds::DataWriter*, const dds::OfferedDeadlineMissedStatus& s) override;
  void on_liveliness_lost(dds::DataWriter*, const dds::LivelinessLostStatus& s) override;
  void on_offered_incompatible_qos(dds::DataWriter*, const dds::OfferedIncompatibleQosStatus& s) override;
  void on_publication_matched(dds::DataWriter*, const dds::PublicationMatchedStatus& s) override;
  WriterStats snapshot() const;

 private:
  std::atomic<std::uint64_t> deadline_missed_{0}, liveliness_lost_{0}, incompatible_qos_{0};
  std::atomic<std::int32_t> matched_readers_{0};
};

/// The type-independent part of a writer. The DDS entity is owned by the Participant.
class WriterBase {
 public:
  WriterBase(const WriterBase&) = delete;
  WriterBase& operator=(const WriterBase&) = delete;
  virtual ~WriterBase() = default;

  const std::string& topicName() const { return topic_name_; }
  const std::string& profileName() const { return profile_name_; }
  WriterStats stats() const {
    WriterStats w = counters_.snapshot();
    w.refused_key_too_long = refused_key_.load(std::memory_order_relaxed);
    return w;
  }
  /// Blocks until at least `count` readers are matched or `timeout` passes; true if matched.
  bool waitForReaders(int count, std::chrono::nanoseconds timeout) const;
  /// The underlying Fast DDS writer (for what this layer does not wrap).
  dds::DataWriter& native() { return *writer_; }

 protected:
  WriterBase(std::string topic_name, std::string profile_name, std::string source)
      : topic_name_(std::move(topic_name)), profile_name_(std::move(profile_name)), source_(std::move(source)) {}
  bool writeRaw(void* sample) noexcept;

  std::string topic_name_, profile_name_, source_;
  std::atomic<std::uint64_t> seq_{0};
  std::atomic<std::uint64_t> refused_key_{0};
  dds::DataWriter* writer_ = nullptr;
  WriterCounters counters_;

  friend class reflex::bus::Participant;
};

/// The type-independent part of a reader. The DDS entity is owned by the Participant.
class ReaderBase {
 public:
  ReaderBase(const ReaderBase&) = delete;
  ReaderBase& operator=(const ReaderBase&) = delete;
  virtual ~ReaderBase() = default;

  const std::string& topicName() const { return topic_name_; }
  const std::string& profileName() const { return profile_name_; }
  ReaderStats stats() const { return counters_.snapshot(); }
  /// Blocks until at least `count` writers are matched or `timeout` passes; true if matched.
  bool waitForWriters(int count, std::chrono::nanoseconds timeout) const;
  /// Blocks until an unread sample is available or `timeout` passes; true if one is.
  bool waitForData(std::chrono::nanoseconds timeout);
  /// The underlying Fast DDS reader (for what this layer does not wrap).
  dds::DataReader& native() { return *reader_; }

 protected:
  ReaderBase(std::string topic_name, std::string profile_name)
      : topic_name_(std::move(topic_name)), profile_name_(std::move(profile_name)) {}
  virtual bool hasCallback() const = 0;
  virtual void dispatch() = 0;  // takes every available sample and hands it to the callback

  std::string topic_name_, profile_name_;
  dds::DataReader* reader_ = nullptr;
  ReaderCounters counters_;

  friend class reflex::bus::Participant;
};

}  // namespace detail

/// A typed writer. Made by Participant::makeWriter; owned by the Participant.
template <class T>
class Writer final : public detail::WriterBase {
 public:
  /// Stamps sample.header() — stamp_ns = nowNs(), seq = previous + 1 (first is 1), source = the
  /// participant's module name — then writes it. Returns false if the middleware refused the sample,
  /// or if a @key string is longer than kMaxKeyStringBytes: such a sample is refused before DDS sees
  /// it (its key computation would abort the process), counted in stats().refused_key_too_long, and
  /// takes no sequence number. Does not allocate once the source string has been assigned once (the
  /// header's string keeps its capacity). Never throws.
  bool publish(T& sample) noexcept { return stamp(sample) && writeRaw(&sample); }
  /// publish() in two steps, for a caller that writes from another thread (a real-time loop hands its
  /// samples to a writer thread): stamps sample.header() as publish() does — the time and sequence
  /// number are those of this call — and returns true; write(sample) then sends it unchanged. A
  /// sample with a @key string above kMaxKeyStringBytes is refused and counted as in publish(), and
  /// takes no sequence number. Does not allocate once the source string was assigned once. Never throws.
  bool stamp(T& sample) noexcept {
    if (keyStringBytes(sample) > kMaxKeyStringBytes) {
      refused_key_.fetch_add(1, std::memory_order_relaxed);
      return false;
    }
    auto& header = sample.header();
    header.stamp_ns(nowNs());
    header.seq(seq_.fetch_add(1, std::memory_order_relaxed) + 1);
    if (header.source() != source_) header.source(source_);
    return true;
  }
  /// Writes the sample as is, header untouched (replay, tests). Returns false on refusal (also a key
  /// string above kMaxKeyStringBytes: refused and counted as in publish()).
  bool write(const T& sample) noexcept {
    if (keyStringBytes(sample) > kMaxKeyStringBytes) {
      refused_key_.fetch_add(1, std::memory_order_relaxed);
      return false;
    }
    // Fast DDS 2.9 takes a non-const void* but only reads (serializes) the sample.
    return writeRaw(const_cast<T*>(&sample));
  }
  /// Sequence number of the last published sample (0 before the first publish()).
  std::uint64_t lastSeq() const { return seq_.load(std::memory_order_relaxed); }

 private:
  using WriterBase::WriterBase;
  friend class Participant;
};

/// A typed reader. Made by Participant::makeReader; owned by the Participant.
template <class T>
class Reader final : public detail::ReaderBase {
 public:
  using Callback = std::function<void(const T&, const dds::SampleInfo&)>;

  /// Takes the next valid sample (oldest first); false if there is none. Never throws.
  bool takeNext(T& out, dds::SampleInfo* info = nullptr) noexcept {
    dds::SampleInfo local;
    dds::SampleInfo& i = info ? *info : local;
    while (reader_->take_next_sample(&out, &i) == eprosima::fastrtps::types::ReturnCode_t::RETCODE_OK) {
      if (i.valid_data) return true;  // skip dispose / unregister notifications
    }
    return false;
  }
  /// Takes every available sample and keeps only the newest in `out` (and its SampleInfo in `info`,
  /// if given: e.g. the publication_handle, whose first 12 bytes are the writer's participant);
  /// false if there was none.
  bool takeLatest(T& out, dds::SampleInfo* info = nullptr) noexcept {
    bool got = false;
    dds::SampleInfo i;
    while (takeNext(scratch_, &i)) {
      std::swap(out, scratch_);
      if (info) *info = i;
      got = true;
    }
    return got;
  }
  /// Takes every available valid sample, appended to `out` oldest first; returns how many.
  std::size_t takeAll(std::vector<T>& out) {
    std::size_t n = 0;
    while (takeNext(scratch_)) {
      out.push_back(scratch_);
      ++n;
    }
    return n;
  }
  /// Registers the callback run() / runFor() call for every new valid sample (replaces any previous).
  void onData(std::function<void(const T&)> fn) {
    callback_ = [f = std::move(fn)](const T& s, const dds::SampleInfo&) { f(s); };
  }
  /// As onData, with the DDS SampleInfo (source timestamp, instance state, publication handle).
  void onDataWithInfo(Callback fn) { callback_ = std::move(fn); }

 private:
  using ReaderBase::ReaderBase;
  bool hasCallback() const override { return static_cast<bool>(callback_); }
  void dispatch() override {
    dds::SampleInfo info;
    while (takeNext(scratch_, &info)) callback_(scratch_, info);
  }

  T scratch_;
  Callback callback_;
  friend class Participant;
};

/// Owns one DDS domain participant and everything made from it. Not copyable, not movable.
class Participant {
 public:
  /// Loads the profiles file, creates the domain participant from the participant profile on the
  /// resolved domain id, plus one publisher and one subscriber. Throws BusError naming the bad
  /// domain id, the missing / malformed profiles file, the unknown participant profile, or the
  /// entity that could not be created.
  explicit Participant(const BusConfig& config);
  /// Deletes every contained entity (readers, writers, publisher, subscriber, topics), then the
  /// participant. Readers/writers handed out become invalid.
  ~Participant();
  Participant(const Participant&) = delete;
  Participant& operator=(const Participant&) = delete;
  Participant(Participant&&) = delete;
  Participant& operator=(Participant&&) = delete;

  /// The RTPS participant id (the profile's, else nextParticipantId()'s).
  int participantId() const;

  /// Makes a writer of T on `topic_name` with the data_writer profile `profile`. Throws BusError if
  /// the profile is unknown, the topic name is already used here with another type, or creation fails.
  template <class T>
  Writer<T>& makeWriter(const std::string& topic_name, const std::string& profile) {
    // Owned at once; not make_unique because the constructor is private to Participant.
    std::unique_ptr<Writer<T>> w(new Writer<T>(topic_name, profile, module_name_));
    auto& ref = *w;
    createWriter(*w, makeTypeSupport<T>());
    writers_.push_back(std::move(w));
    return ref;
  }
  /// Makes a writer of T on its default topic with its default profile (see topics.hpp).
  template <class T>
  Writer<T>& makeWriter() {
    return makeWriter<T>(TopicTraits<T>::kTopicName, TopicTraits<T>::kProfile);
  }

  /// Makes a reader of T on `topic_name` with the data_reader profile `profile`. Throws as makeWriter.
  template <class T>
  Reader<T>& makeReader(const std::string& topic_name, const std::string& profile) {
    std::unique_ptr<Reader<T>> r(new Reader<T>(topic_name, profile));
    auto& ref = *r;
    createReader(*r, makeTypeSupport<T>());
    readers_.push_back(std::move(r));
    return ref;
  }
  /// Makes a reader of T on its default topic with its default profile (see topics.hpp).
  template <class T>
  Reader<T>& makeReader() {
    return makeReader<T>(TopicTraits<T>::kTopicName, TopicTraits<T>::kProfile);
  }

  /// Calls `fn` every `period` from inside run() / runFor() (first call one period after the loop
  /// starts; missed calls are skipped, not queued). Throws BusError if period <= 0 or if called
  /// while run() / runFor() is running (e.g. from a callback).
  void every(std::chrono::nanoseconds period, std::function<void()> fn);

  /// Waits on a WaitSet (readers with an onData callback + the stop guard condition) and dispatches
  /// samples and timers until stop(). Exceptions thrown by callbacks propagate out. Throws BusError
  /// when it stopped because the security material expired (credentialsExpired()).
  void run();
  /// As run(), but returns after `duration`: true if the time ran out, false if stop() was called.
  bool runFor(std::chrono::nanoseconds duration);
  /// Makes run() / runFor() return (now and every later call). Thread-safe; not async-signal-safe:
  /// from a signal handler use StopOnSignal (signals.hpp).
  void stop() noexcept;
  bool stopRequested() const noexcept { return stop_.load(); }

  // ---- security and identity ----
  // A participant whose profile enables DDS-Security has its material checked before Fast DDS sees
  // it (checkSecurityMaterial: a bad file is a BusError naming the file and the cause), announces no
  // participant name in discovery (its certificate subject identifies it to authenticated peers),
  // and stops itself when the material expires: at credentialsValidUntil() it prints one line
  // naming what expired to stderr and calls stop(); run() / runFor() then throw BusError saying so.
  // Every participant leaves out Fast DDS's fastdds.physical_data.* discovery properties (host
  // name, user name, process id).

  /// True when the participant profile enables DDS-Security (an authentication plugin is set).
  bool secure() const noexcept;
  /// Subject of this participant's identity certificate, RFC 2253 ("" when not secure).
  const std::string& identitySubject() const noexcept;
  /// When this participant's security material stops being valid (time_point::max() when not secure).
  std::chrono::system_clock::time_point credentialsValidUntil() const noexcept;
  /// True once credentialsValidUntil() has passed (the participant has then stopped).
  bool credentialsExpired() const noexcept;
  /// The participant name a discovered remote participant announced, or "" (unknown, left, or none
  /// announced). NOT authenticated: any participant can announce any name; see security.hpp for what
  /// a writer's GUID prefix does authenticate.
  std::string discoveredName(const GuidPrefix& prefix) const;
  /// The GUID prefixes of the remote participants discovered and not gone (Fast DDS's own
  /// get_discovered_participants returns RETCODE_UNSUPPORTED in 2.9).
  std::vector<GuidPrefix> discoveredParticipants() const;

  const std::string& moduleName() const { return module_name_; }
  int domainId() const { return domain_id_; }
  const std::string& profilesFile() const { return profiles_file_; }
  /// The underlying Fast DDS participant (for what this layer does not wrap).
  dds::DomainParticipant& native() { return *participant_; }

 private:
  struct Timer {
    std::chrono::nanoseconds period;
    std::function<void()> fn;
    std::chrono::steady_clock::time_point next;
  };

  template <class T>
  static dds::TypeSupport makeTypeSupport() {
    return dds::TypeSupport(new typename TopicTraits<T>::PubSubType());  // TypeSupport owns it
  }
  dds::Topic& topicFor(const std::string& topic_name, dds::TypeSupport type);
  void createWriter(detail::WriterBase& w, dds::TypeSupport type);
  void createReader(detail::ReaderBase& r, dds::TypeSupport type);
  bool loop(const std::chrono::steady_clock::time_point* end);
  std::string where() const;  // " (profiles file '...')" for error messages

  struct Extras;  // discovery listener, security check result, expiry watchdog (participant.cpp)
  std::string module_name_;
  int domain_id_ = 0;
  std::string profiles_file_;
  dds::DomainParticipant* participant_ = nullptr;
  dds::Publisher* publisher_ = nullptr;
  dds::Subscriber* subscriber_ = nullptr;
  std::map<std::string, dds::Topic*> topics_;
  // Declared before the entities are deleted in ~Participant, destroyed after it (listeners).
  std::vector<std::unique_ptr<detail::WriterBase>> writers_;
  std::vector<std::unique_ptr<detail::ReaderBase>> readers_;
  std::vector<Timer> timers_;
  dds::GuardCondition stop_guard_;
  std::atomic<bool> stop_{false};
  bool running_ = false;
  std::unique_ptr<Extras> extras_;
};

}  // namespace reflex::bus
