#include "reflex/record/recorder.hpp"

#include <reflex/bus/bus.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <thread>

namespace reflex::record {

// Recording time -> playing time (seconds after the start offset, at rate 1) with every forward
// gap between consecutive played records longer than max_gap shortened to max_gap. Records are
// taken in file order; one that goes back in time is played at once (no wait), as before.
class PlayClock {
 public:
  explicit PlayClock(double max_gap) : max_gap_(max_gap) {}
  /// Gap in recording time between the previous record (or the start offset) and this one, s.
  double gapBefore(std::int64_t since_begin_ns) const { return 1e-9 * static_cast<double>(since_begin_ns - prev_ns_); }
  /// Playing time of this record; advances the clock.
  double playTime(std::int64_t since_begin_ns) {
    const double gap = gapBefore(since_begin_ns);
    if (gap > max_gap_) removed_ += gap - max_gap_;
    if (since_begin_ns > prev_ns_) prev_ns_ = since_begin_ns;
    last_ = 1e-9 * static_cast<double>(since_begin_ns) - removed_;
    return last_;
  }
  void reset() { prev_ns_ = 0, removed_ = 0.0, last_ = 0.0; }
  double last() const { return last_; }

 private:
  double max_gap_;
  std::int64_t prev_ns_ = 0;  // latest recording time seen, ns after the start offset
  double removed_ = 0.0;      // seconds cut out of the gaps so far
  double last_ = 0.0;
};

// The topics a live controller or robot acts on. The robot's measured state is one of them: replayed
// beside `reflex_controller --robot dds`, recorded positions would be what a real robot is commanded from.
const std::vector<std::string>& commandTopics() {
  static const std::vector<std::string> topics = {
      bus::TopicTraits<msg::HandTargets>::kTopicName,      bus::TopicTraits<msg::MotionPriority>::kTopicName,
      bus::TopicTraits<msg::BodySchemaChange>::kTopicName, bus::TopicTraits<msg::WalkCommand>::kTopicName,
      bus::TopicTraits<msg::JointCommand>::kTopicName,     bus::TopicTraits<msg::RobotState>::kTopicName};
  return topics;
}

bool isCommandTopic(const std::string& topic) {
  const auto& c = commandTopics();
  return std::find(c.begin(), c.end(), topic) != c.end();
}

RecordingInfo scanRecording(const std::string& path) {
  const std::unique_ptr<SampleReader> source = openRecording(path);
  SampleReader& reader = *source;
  RecordingInfo info;
  info.format = reader.formatName();
  RecordEntry e;
  while (reader.next(e)) {
    if (info.records == 0) info.first_ns = info.last_ns = e.receive_ns;
    info.first_ns = std::min(info.first_ns, e.receive_ns);
    info.last_ns = std::max(info.last_ns, e.receive_ns);
    ++info.records;
    TopicCount& c = info.topics[e.topic];
    c.type = e.type;
    ++c.samples;
  }
  info.tail = reader.tailState();
  info.valid_end = reader.validEnd();
  info.file_size = reader.fileSize();
  info.skipped_bytes = reader.skippedBytes();
  info.problem = reader.problem();
  return info;
}

Player::Player(const PlayerOptions& options) : options_(options) {
  if (!std::isfinite(options.rate) || options.rate < 0.0)
    throw RecordError("--rate " + std::to_string(options.rate) + " must be > 0 (or 0: as fast as possible)");
  if (!std::isfinite(options.start) || options.start < 0.0)
    throw RecordError("--start " + std::to_string(options.start) + " s must not be negative");
  if (!std::isfinite(options.duration) || options.duration < 0.0)
    throw RecordError("--duration " + std::to_string(options.duration) + " s must not be negative");
  if (!std::isfinite(options.delay) || options.delay < 0.0)
    throw RecordError("--delay " + std::to_string(options.delay) + " s must not be negative");
  if (options.wait_readers < 0)
    throw RecordError("--wait-readers " + std::to_string(options.wait_readers) + " must not be negative");
  if (!std::isfinite(options.wait_timeout) || !(options.wait_timeout > 0.0))
    throw RecordError("--wait-timeout " + std::to_string(options.wait_timeout) + " s must be positive");
  if (!std::isfinite(options.max_gap) || !(options.max_gap > 0.0))
    throw RecordError("--max-gap " + std::to_string(options.max_gap) + " s must be positive");
  const RecordingInfo info = scanRecording(options.input);
  if (info.records == 0) throw RecordError("recording '" + options.input + "' holds no sample");
  stats_.tail = info.tail;
  first_ns_ = info.first_ns;
  // Offsets are compared with the recording's length (last - first >= 0: receive times are never
  // negative) before they are added, so no --start / --duration overflows an int64.
  const double length_ns = static_cast<double>(info.last_ns - info.first_ns);
  if (options.start * 1e9 <= length_ns) {
    begin_ns_ = info.first_ns + static_cast<std::int64_t>(std::llround(options.start * 1e9));
    end_ns_ = options.duration > 0.0 && options.duration * 1e9 < static_cast<double>(info.last_ns - begin_ns_)
                  ? begin_ns_ + static_cast<std::int64_t>(std::llround(options.duration * 1e9))
                  : info.last_ns;
    end_ns_ = std::min(end_ns_, info.last_ns);
  }
  if (options.start * 1e9 > length_ns || begin_ns_ > info.last_ns) {
    char buf[160];
    std::snprintf(buf, sizeof(buf), "--start %.3f s is beyond the end of the recording (%.3f s long)", options.start,
                  1e-9 * static_cast<double>(info.last_ns - info.first_ns));
    throw RecordError(std::string(buf) + " '" + options.input + "'");
  }
  // Played by default: every recorded topic but the controller's protection state. That sample is a
  // live controller's claim to be THE controller of this domain (reflex_controller refuses to start,
  // or leaves, when it sees an earlier one); replayed beside a live controller it
  // would be a phantom peer. It is played only when named with --topic.
  // Nor, by default, the command topics (the joint commands among them): a replay
  // beside a live controller or robot would steer it. They are played only with
  // PlayerOptions::commands (--commands). Nor are channels of a type that is no Reflex topic type (the
  // scene channels /tf and /reflex/scene of an MCAP recording, JSON for viewers, not bus samples):
  // naming one with --topic is an error (unknown type) below.
  const std::string protection_topic = bus::TopicTraits<msg::ControllerProtection>::kTopicName;
  std::vector<std::string> topics = options.topics;
  if (topics.empty()) {
    for (const auto& kv : info.topics) {
      if (kv.first == protection_topic || !findCodecByType(kv.second.type)) continue;
      if (options.commands || !isCommandTopic(kv.first))
        topics.push_back(kv.first);
      else
        commands_skipped_.push_back(kv.first);
    }
  }
  for (const std::string& t : options.topics) {
    if (!info.topics.count(t)) {
      std::string have;
      for (const auto& kv : info.topics) have += " " + kv.first;
      throw RecordError("topic '" + t + "' is not in recording '" + options.input + "' (it has:" + have + ")");
    }
    if (isCommandTopic(t) && !options.commands)
      throw RecordError("topic '" + t +
                        "' is a command topic: a replay publishes observations only unless "
                        "--commands is given (it would steer a live controller or robot)");
  }
  for (const std::string& ex : options.exclude) {
    const auto it = std::find(topics.begin(), topics.end(), ex);
    const bool not_played =
        ex == protection_topic || (info.topics.count(ex) && !findCodecByType(info.topics.at(ex).type));
    if (it == topics.end() && not_played && options.topics.empty()) continue;     // not played anyway
    if (it == topics.end() && isCommandTopic(ex) && !options.commands) continue;  // not played anyway (note: cli)
    if (it == topics.end()) throw RecordError("--exclude '" + ex + "' is not among the played topics");
    topics.erase(it);
  }
  if (topics.empty()) throw RecordError("no topic left to play from '" + options.input + "'");

  bus_ = std::make_unique<bus::Participant>(options.bus);
  for (const std::string& t : topics) {
    const std::string& type = info.topics.at(t).type;
    const TopicCodec* codec = findCodecByType(type);
    if (!codec) throw RecordError("topic '" + t + "' in '" + options.input + "' has unknown type '" + type + "'");
    publishers_[t] = codec->makePublisher(*bus_, t, codec->defaultProfile());
  }
  // One pass over the window as run() plays it: count the records and the gaps run() shortens.
  const std::unique_ptr<SampleReader> source = openRecording(options.input);
  SampleReader& reader = *source;
  RecordEntry e;
  PlayClock clock(options_.max_gap);
  while (reader.next(e)) {
    if (e.receive_ns < begin_ns_) continue;
    if (e.receive_ns > end_ns_) break;
    if (!publishers_.count(e.topic)) continue;
    ++window_records_;
    const double gap = clock.gapBefore(e.receive_ns - begin_ns_);
    if (gap > options_.max_gap) {
      ++stats_.gaps_shortened;
      if (gap > stats_.longest_gap) {
        stats_.longest_gap = gap;
        stats_.longest_gap_at = 1e-9 * static_cast<double>(e.receive_ns - begin_ns_);
      }
    }
    (void)clock.playTime(e.receive_ns - begin_ns_);
  }
  played_seconds_ = clock.last();
}

Player::~Player() = default;

bus::Participant& Player::bus() { return *bus_; }

void Player::run() {
  using Clock = std::chrono::steady_clock;
  const bool fast = options_.rate == 0.0;
  const auto sleepFor = [&](double seconds) {  // interruptible by stop()
    const auto until =
        Clock::now() + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(seconds));
    while (!stop_ && !bus_->stopRequested() && Clock::now() < until)
      std::this_thread::sleep_for(std::min<Clock::duration>(until - Clock::now(), std::chrono::milliseconds(50)));
  };
  if (options_.wait_readers > 0) {
    // Every played topic's writer has matched that many readers, so the first samples reach them.
    const auto deadline = Clock::now() + std::chrono::duration_cast<Clock::duration>(
                                             std::chrono::duration<double>(options_.wait_timeout));
    auto short_of_readers = [&] {
      std::string missing;
      for (const auto& [topic, publisher] : publishers_)
        if (publisher->matchedReaders() < options_.wait_readers)
          missing += (missing.empty() ? "" : ", ") + topic + " (" + std::to_string(publisher->matchedReaders()) + ")";
      return missing;
    };
    std::fprintf(stderr,
                 "reflex_play: holding the start until every played topic has %d matched reader(s) (at most "
                 "%g s)\n",
                 options_.wait_readers, options_.wait_timeout);
    const auto t0 = Clock::now();
    std::string missing = short_of_readers();
    while (!missing.empty() && !stop_ && !bus_->stopRequested() && Clock::now() < deadline) {
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
      missing = short_of_readers();
    }
    if (stop_ || bus_->stopRequested()) return;
    if (!missing.empty()) {
      char timeout[32];
      std::snprintf(timeout, sizeof timeout, "%g", options_.wait_timeout);
      throw reflex::Failure("--wait-readers " + std::to_string(options_.wait_readers) + ": after " + timeout +
                            " s (--wait-timeout) these topics had fewer matched readers (matched): " + missing +
                            "; is every consumer running on this domain?");
    }
    std::fprintf(stderr, "reflex_play: readers matched after %.2f s, starting\n",
                 std::chrono::duration<double>(Clock::now() - t0).count());
    sleepFor(std::chrono::duration<double>(bus::kReaderSideMatchGrace).count());  // the readers' side of the match
  }
  sleepFor(options_.delay);
  const double window = windowSeconds();
  auto last_print = Clock::now() - std::chrono::seconds(1);
  const std::unique_ptr<SampleReader> source = openRecording(options_.input);
  SampleReader& reader = *source;
  RecordEntry e;
  PlayClock clock(options_.max_gap);
  do {
    reader.rewind();
    clock.reset();
    std::uint64_t in_pass = 0;
    const auto pass_start = Clock::now();
    while (!stop_ && !bus_->stopRequested() && reader.next(e)) {
      if (e.receive_ns < begin_ns_) continue;
      if (e.receive_ns > end_ns_) break;
      auto it = publishers_.find(e.topic);
      if (it == publishers_.end()) continue;
      const double t_rec = 1e-9 * static_cast<double>(e.receive_ns - begin_ns_);
      const double t_play = clock.playTime(e.receive_ns - begin_ns_);  // gaps shortened to max_gap
      if (!fast) {
        // Slept in slices of at most 50 ms, each followed by a look at stop (SIGINT/SIGTERM).
        const auto due = pass_start + std::chrono::duration_cast<Clock::duration>(
                                          std::chrono::duration<double>(t_play / options_.rate));
        while (!stop_ && !bus_->stopRequested() && Clock::now() < due)
          std::this_thread::sleep_for(std::min<Clock::duration>(due - Clock::now(), std::chrono::milliseconds(50)));
        if (stop_ || bus_->stopRequested()) break;
      }
      const std::int64_t shift = options_.restamp ? bus::nowNs() - e.receive_ns : 0;
      if (it->second->publish(e.payload, shift))
        ++stats_.published;
      else
        ++stats_.failed;
      ++in_pass;
      const auto now = Clock::now();
      if (options_.progress && now - last_print >= std::chrono::milliseconds(250)) {
        last_print = now;
        std::fprintf(stderr, "\rreflex_play: %7.2f / %.2f s (%3.0f%%)  %llu / %llu samples  rate %gx  loop %llu   ",
                     t_rec + options_.start, window + options_.start, window > 0 ? 100.0 * t_rec / window : 100.0,
                     static_cast<unsigned long long>(in_pass), static_cast<unsigned long long>(window_records_),
                     options_.rate, static_cast<unsigned long long>(stats_.loops + 1));
      }
    }
    if (stop_ || bus_->stopRequested()) break;
    ++stats_.loops;
  } while (options_.loop);
  if (options_.progress) std::fprintf(stderr, "\n");
}

}  // namespace reflex::record
