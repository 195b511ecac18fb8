// reflex::record — the bus recorder, player and exporter.
//
//   Recorder  subscribes chosen (or all) Reflex topics and appends every received sample to a
//             recording file: MCAP (mcap.hpp, the default) or .rfx (record_file.hpp); both survive
//             kill -9 with a torn tail detected;
//   Player    publishes a recording again with its original timing, scaled by a rate, from a
//             start offset, optionally looped (like `ros2 bag play`);
//   exportCsv writes the samples of one topic as a CSV table (for reports and plots).
//
// Each is a library class with a thin main (reflex_record / reflex_play). The Recorder and Player own
// their bus::Participant; stop() is thread-safe and is what SIGINT / SIGTERM call.
#pragma once

#include "reflex/record/codecs.hpp"
#include "reflex/record/record_file.hpp"
#include "reflex/record/recording.hpp"
#include "reflex/record/scene_channels.hpp"

#include <reflex/bus/config.hpp>

#include <atomic>
#include <chrono>
#include <cstdint>
#include <map>
#include <memory>
#include <string>
#include <vector>

namespace reflex::bus {
class Participant;
}

namespace reflex::record {

struct RecorderOptions {
  std::string output;                ///< recording file to create (or append to, see writer.append)
  std::string format = "auto";       ///< "mcap", "rfx" or "auto": rfx for a name ending in .rfx, else MCAP
  std::vector<std::string> topics;   ///< topic specs (parseTopicSpec); empty = every known topic
  std::vector<std::string> exclude;  ///< topic names not to record (with the default "all")
  /// false (default): each topic is read with a reader that keeps the writers' promise and every
  /// sample of a burst: best-effort topics (200 Hz state, vision) with reflex_record (best effort,
  /// keep last 256), reliable topics (behavior decisions, heartbeats) with reflex_record_reliable
  /// (reliable, volatile, keep last 256), so a sample dropped on a loaded host is repaired as the
  /// writer promised instead of lost. true: state topics (behavior decisions,
  /// heartbeats: reliable + transient local) are read with their own reader profile instead, so the
  /// recording starts with the state published BEFORE the recorder started, but that profile keeps
  /// only the newest sample per instance (a burst of changes between two takes keeps its last one).
  bool late_joiner_state = false;
  double duration = 0.0;   ///< seconds to record (0: until stop())
  bool progress = false;   ///< print a status line to stderr about once a second
  WriterOptions writer;    ///< .rfx durability policy (and append)
  McapWriterOptions mcap;  ///< MCAP chunking, compression, fsync period
  /// MCAP only: also write the scene channels /tf and /reflex/scene (scene_channels.hpp) from the
  /// recorded joint state, status, targets, objects and body schema. Not for .rfx, nor when
  /// reflex/joint_state is not recorded (sceneNote() says why).
  SceneChannelOptions scene;
  bus::BusConfig bus;
};

/// Per-topic counts of a recorder.
struct TopicCount {
  std::string type;
  std::uint64_t samples = 0;
};

class Recorder {
 public:
  /// Parses the topics, opens the file and creates the readers. Throws RecordError / bus::BusError
  /// naming the bad topic, file or entity.
  explicit Recorder(const RecorderOptions& options);
  ~Recorder();
  Recorder(const Recorder&) = delete;
  Recorder& operator=(const Recorder&) = delete;

  /// Records until stop() or the duration; closes (fsyncs) the file at the end. Throws RecordError
  /// on a write error.
  void run();
  void stop() noexcept;

  bus::Participant& bus();
  const std::map<std::string, TopicCount>& counts() const { return counts_; }
  /// Blocks until every recorded topic's reader has matched at least one writer, or `timeout`
  /// passes; true if all matched. Discovery is asymmetric: a writer that sees this reader may still
  /// be unknown to it, and a best-effort sample from a writer the reader has not matched is dropped.
  bool waitForWriters(std::chrono::nanoseconds timeout) const;
  std::uint64_t totalSamples() const;
  /// The MCAP writer of an MCAP recording (nullptr for .rfx), to add channels of other encodings
  /// (McapWriter::addChannel) and write to them. Use it from the bus thread only (bus().every(...) or a
  /// reader callback): the recorder writes samples from there.
  McapWriter* mcap();
  /// The scene channels (nullptr if not written: not asked for, .rfx, or no joint state recorded).
  const SceneChannels* sceneChannels() const { return scene_.get(); }
  /// One line about the scene channels: why there are none, or (after run()) what was written; "" if
  /// they were not asked for.
  std::string sceneNote() const;

 private:
  RecorderOptions options_;
  std::unique_ptr<bus::Participant> bus_;
  std::unique_ptr<SampleWriter> writer_;
  std::unique_ptr<SceneChannels> scene_;
  std::string scene_note_;
  std::map<std::string, TopicCount> counts_;
  std::vector<const bus::detail::ReaderBase*> readers_;
};

struct PlayerOptions {
  std::string input;      ///< recording to play
  double rate = 1.0;      ///< speed factor (> 0); 0 = as fast as possible
  bool loop = false;      ///< start again at the start offset when the end is reached
  double start = 0.0;     ///< seconds after the first record to start from
  double duration = 0.0;  ///< seconds of recording time to play from the start (0: to the end)
  double delay = 0.5;     ///< seconds between creating the writers and the first sample (discovery)
  /// Hold the start until every played topic has this many matched readers (then 0.3 s for their side
  /// of the match, then `delay`), at most wait_timeout seconds; else a RecordError naming each topic
  /// short of readers and how many it had. 0: start after `delay` alone.
  int wait_readers = 0;
  double wait_timeout = 60.0;        ///< seconds (> 0)
  std::vector<std::string> topics;   ///< topic names to play; empty = every topic in the file but
                                     ///< reflex/controller_protection (a live controller's claim; see player.cpp)
                                     ///< and, without `commands`, the command topics (isCommandTopic)
  std::vector<std::string> exclude;  ///< topic names not to play (a command topic without `commands`: a no-op)
  /// Play the command topics too (reflex_play --commands). Off by default: a replay
  /// republishes observations only, so it never steers a live controller or robot. Without it a
  /// command topic named in `topics` is a RecordError naming the topic and the option.
  bool commands = false;
  bool restamp = false;   ///< move sample time stamps to the playing time (see SamplePublisher)
  bool progress = false;  ///< status line on stderr
  /// Longest wait between consecutive played records, seconds of recording time (> 0). A longer gap
  /// (a recording resumed hours later, crafted receive times 100 years apart) is played as max_gap:
  /// the player never waits in silence for longer; the shortened gaps are counted and reported.
  double max_gap = 10.0;
  bus::BusConfig bus;
};

/// The topics that command the robot (isCommandTopic): the behavior layer's outputs to the controller
/// (hand targets, motion priority, body schema, walk command), the controller's joint command to
/// a robot driver, and the robot's measured state (a controller over DDS computes its commands from
/// it). Every other Reflex topic is an observation (what vision saw, what the controller did, the
/// robot's contacts, heartbeats).
const std::vector<std::string>& commandTopics();
bool isCommandTopic(const std::string& topic);

struct PlayerStats {
  std::uint64_t published = 0;         ///< samples written
  std::uint64_t failed = 0;            ///< payloads that did not deserialize or writes refused
  std::uint64_t loops = 0;             ///< completed passes
  std::uint64_t gaps_shortened = 0;    ///< gaps in the played window longer than max_gap (one pass)
  double longest_gap = 0.0;            ///< the longest of them, seconds of recording time (0 if none)
  double longest_gap_at = 0.0;         ///< where it ends, seconds after the start offset
  TailState tail = TailState::kClean;  ///< how the file ended
};

class Player {
 public:
  /// Scans the file (time range, topics), checks the options and creates one writer per played
  /// topic with its type's profile. Throws RecordError naming the bad option value or the file.
  explicit Player(const PlayerOptions& options);
  ~Player();
  Player(const Player&) = delete;
  Player& operator=(const Player&) = delete;

  /// Plays until the end (or forever with loop) or stop().
  void run();
  void stop() noexcept { stop_ = true; }

  bus::Participant& bus();
  const PlayerStats& stats() const { return stats_; }
  /// Length of the played window, seconds of recording time.
  double windowSeconds() const { return 1e-9 * static_cast<double>(end_ns_ - begin_ns_); }
  /// How long one pass takes at rate 1 once gaps are shortened to max_gap, seconds.
  double playedSeconds() const { return played_seconds_; }
  /// Command topics in the file left out because PlayerOptions::commands was off (the start line says so).
  const std::vector<std::string>& commandsSkipped() const { return commands_skipped_; }

 private:
  PlayerOptions options_;
  std::unique_ptr<bus::Participant> bus_;
  std::map<std::string, std::unique_ptr<SamplePublisher>> publishers_;
  std::int64_t first_ns_ = 0, begin_ns_ = 0, end_ns_ = 0;
  std::uint64_t window_records_ = 0;
  double played_seconds_ = 0.0;
  std::vector<std::string> commands_skipped_;
  std::atomic<bool> stop_{false};
  PlayerStats stats_;
};

/// Summary of a recording (reflex_record info).
struct RecordingInfo {
  std::int64_t first_ns = 0, last_ns = 0;
  std::uint64_t records = 0;
  std::map<std::string, TopicCount> topics;  ///< topic -> type + count
  TailState tail = TailState::kClean;
  std::uint64_t valid_end = 0, file_size = 0, skipped_bytes = 0;
  std::string format;   ///< "mcap" or "rfx"
  std::string problem;  ///< the first problem met, with its byte offset ("" if none)
};
/// Scans a recording (either format). Throws RecordError if it cannot be opened or is not a recording.
RecordingInfo scanRecording(const std::string& path);

/// Writes the samples of `topic` in `input` as CSV to `csv_path` (header from the first sample,
/// t = seconds since the first record of the file). Returns the number of samples written. Throws
/// RecordError if the topic is not in the recording (naming the topics that are), its type is
/// unknown, or the output cannot be written; and, after writing every other sample, if some did not
/// decode (CsvExportReport::undecodableMessage).
std::uint64_t exportCsv(const std::string& input, const std::string& topic, const std::string& csv_path);

/// One topic's CSV file of an export.
struct CsvExport {
  std::string topic;
  std::string path;
  std::uint64_t samples = 0;  ///< rows written (set by exportCsvFiles)
};
struct CsvExportReport {
  std::vector<CsvExport> files;   ///< the targets, with their sample counts
  std::uint64_t undecodable = 0;  ///< samples of those topics that did not decode: skipped
  std::string first_undecodable;  ///< where the first was and why ("sample 12 of the file (t = ...): ...")
  /// "3 samples could not be decoded, first at sample 12 of the file (t = 0.500000 s): ..."; "" if none.
  std::string undecodableMessage() const;
};
/// Writes the CSV file of every target topic in two passes over `input` whatever their number (one
/// scan for the topics' types and t = 0, skipped if `scanned` is given, and one that writes every
/// file; at most 64 files open at once). A sample that does not decode is skipped and counted, the
/// others are written. Throws RecordError as exportCsv before writing anything (a topic not in the
/// recording, an unknown type, an output that cannot be written) and if an output fails.
CsvExportReport exportCsvFiles(const std::string& input, std::vector<CsvExport> targets,
                               const RecordingInfo* scanned = nullptr);

/// Copies every sample of `input` (either format) into a new recording `output` (options.format),
/// e.g. an .rfx log into MCAP (a torn or damaged input gives every sample its reader yields). Returns
/// the number of samples. Throws RecordError as openRecording / createRecording, and if `output` is
/// `input` (naming both). The input's own viewer channels (schema foxglove.*: the scene channels of an
/// MCAP input) are not copied; with `scene.enabled` and an MCAP output they are made again from the
/// copied samples (scene_channels.hpp). `scene_note` (if given) gets the line saying what was written.
std::uint64_t convertRecording(const std::string& input, const std::string& output, const RecordingOptions& options,
                               const SceneChannelOptions& scene = {}, std::string* scene_note = nullptr);

/// A file name for a topic's CSV: "reflex/control_status" -> "reflex_control_status.csv". '/', ':' and
/// ' ' become '_'; letters, digits, '_', '-' and '.' stay; every other byte (control bytes, '%', '\',
/// non-ASCII) becomes %XX. So two topics share a name only if they differ in '/', ':', ' ' against
/// '_' ("reflex/heartbeat", "reflex_heartbeat", "reflex:heartbeat"): csvFileNameCollisions finds
/// them, and `export --dir` refuses every topic of such a group, naming them, instead of writing them
/// into one file.
std::string csvFileNameForTopic(const std::string& topic);
/// The file names (csvFileNameForTopic) that more than one of `topics` would get, with those topics.
std::map<std::string, std::vector<std::string>> csvFileNameCollisions(const std::vector<std::string>& topics);

}  // namespace reflex::record
