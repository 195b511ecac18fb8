#include "reflex/record/recorder.hpp"

#include <reflex/bus/bus.hpp>

#include <algorithm>
#include <chrono>
#include <cstdio>

namespace reflex::record {

Recorder::Recorder(const RecorderOptions& options) : options_(options) {
  if (options.output.empty()) throw RecordError("no output file given for the recording");
  if (!(options.duration >= 0.0))
    throw RecordError("recording duration " + std::to_string(options.duration) + " s must not be negative");
  std::vector<TopicSpec> specs;
  if (options.topics.empty()) {
    for (const TopicCodec* c : allCodecs()) specs.push_back({c->defaultTopic(), c});
  } else {
    for (const std::string& t : options.topics) specs.push_back(parseTopicSpec(t));
  }
  for (const std::string& ex : options.exclude) {
    const auto it = std::find_if(specs.begin(), specs.end(), [&](const TopicSpec& s) { return s.topic == ex; });
    if (it == specs.end()) throw RecordError("--exclude '" + ex + "' is not among the recorded topics");
    specs.erase(it);
  }
  if (specs.empty()) throw RecordError("no topic left to record");

  bus_ = std::make_unique<bus::Participant>(options.bus);
  RecordingOptions recording;
  recording.format = recordingFormatFor(options.output, options.format);
  recording.rfx = options.writer;
  recording.mcap = options.mcap;
  if (options.scene.enabled) {  // the robot files before the recording file: a bad one leaves no file
    const bool joints =
        std::any_of(specs.begin(), specs.end(), [](const TopicSpec& s) { return s.topic == "reflex/joint_state"; });
    if (recording.format != RecordingFormat::kMcap)
      scene_note_ = "an .rfx recording has no scene channels (/tf, /reflex/scene): record MCAP or convert it";
    else if (!joints)
      scene_note_ = "reflex/joint_state is not recorded: no scene channels (/tf, /reflex/scene)";
    else
      scene_ = std::make_unique<SceneChannels>(options.scene);
  }
  writer_ = createRecording(options.output, recording);
  for (const TopicSpec& s : specs) {
    if (counts_.count(s.topic)) throw RecordError("topic '" + s.topic + "' given twice");
    counts_[s.topic].type = s.codec->typeName();
    // isState(): the writers are reliable (behavior decisions, heartbeats); read them reliably. A
    // state published once (the controller's protection: avoidance on or off, e-stop) is always read
    // with its own transient-local profile, so every recording says how the robot was protected.
    const bool once = std::string(s.codec->defaultProfile()) == bus::kProfileControllerInfo;
    const std::string profile = !s.codec->isState()                 ? bus::kProfileRecord
                                : options.late_joiner_state || once ? s.codec->defaultProfile()
                                                                    : bus::kProfileRecordReliable;
    TopicCount* count = &counts_[s.topic];
    readers_.push_back(&s.codec->subscribe(*bus_, s.topic, profile, [this, count](RecordEntry&& e) {
      writer_->append(e);
      ++count->samples;
      if (scene_) scene_->add(e, *mcap());
    }));
  }
}

bool Recorder::waitForWriters(std::chrono::nanoseconds timeout) const {
  const auto end = std::chrono::steady_clock::now() + timeout;
  for (const bus::detail::ReaderBase* r : readers_) {
    const auto left =
        std::max(std::chrono::nanoseconds(0), std::chrono::nanoseconds(end - std::chrono::steady_clock::now()));
    if (!r->waitForWriters(1, left)) return false;
  }
  return true;
}

Recorder::~Recorder() = default;

bus::Participant& Recorder::bus() { return *bus_; }

McapWriter* Recorder::mcap() {
  auto* w = dynamic_cast<McapSampleWriter*>(writer_.get());
  return w ? &w->mcap() : nullptr;
}

std::string Recorder::sceneNote() const { return scene_ ? scene_->summary() : scene_note_; }

void Recorder::stop() noexcept { bus_->stop(); }

std::uint64_t Recorder::totalSamples() const {
  std::uint64_t n = 0;
  for (const auto& kv : counts_) n += kv.second.samples;
  return n;
}

void Recorder::run() {
  const auto start = std::chrono::steady_clock::now();
  auto last_print = start;
  // The flush/sync policy is time based; poll it also when nothing arrives.
  bus_->every(std::chrono::milliseconds(20), [&] {
    writer_->poll();
    const auto now = std::chrono::steady_clock::now();
    if (options_.progress && now - last_print >= std::chrono::seconds(1)) {
      last_print = now;
      std::fprintf(stderr, "reflex_record: %.0f s, %llu samples, %.1f MB -> %s\n",
                   std::chrono::duration<double>(now - start).count(), static_cast<unsigned long long>(totalSamples()),
                   1e-6 * static_cast<double>(writer_->bytesWritten()), options_.output.c_str());
    }
  });
  if (options_.duration > 0.0)
    bus_->runFor(std::chrono::nanoseconds(static_cast<std::int64_t>(options_.duration * 1e9)));
  else
    bus_->run();
  writer_->close();
}

}  // namespace reflex::record
