#include "reflex/common/run_main.hpp"
#include "reflex/common/shipped.hpp"
#include "cli.hpp"

#include "reflex/record/recorder.hpp"

#include <reflex/bus/bus.hpp>
#include <reflex/bus/cli.hpp>

#include "reflex/common/files.hpp"

#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <filesystem>

namespace reflex::record::cli {

namespace {

using bus::BusOptions;

/// Format and MCAP options of a command that writes a recording (record, convert).
struct OutputOptions {
  std::string format = "auto";
  std::string compression = "zstd";
  std::uint64_t chunk_bytes = 1u << 20;
  int chunk_ms = 500;
  void add(CLI::App& app) {
    app.add_option("--format", format, "file format: mcap, rfx, or auto (rfx if the file name ends in .rfx, else MCAP)")
        ->capture_default_str();
    app.add_option("--compression", compression, "MCAP chunk compression: none, zstd or lz4")->capture_default_str();
    app.add_option("--chunk-size", chunk_bytes, "MCAP: close a chunk when its records reach this many bytes")
        ->capture_default_str()
        ->check(CLI::Range(std::uint64_t{1}, std::uint64_t{1} << 30));
    app.add_option("--chunk-ms", chunk_ms,
                   "MCAP: close a chunk when its first message is this old (ms); a crash loses the open chunk")
        ->capture_default_str()
        ->check(CLI::Range(1, 600000));
  }
  /// Throws RecordError naming a bad --format or --compression value.
  RecordingOptions options(const std::string& path) const {
    RecordingOptions o;
    o.format = recordingFormatFor(path, format);
    o.mcap.compression = parseMcapCompression(compression);
    o.mcap.chunk_bytes = chunk_bytes;
    o.mcap.chunk_interval = std::chrono::milliseconds(chunk_ms);
    return o;
  }
};

/// The robot model of the scene channels (record, convert; scene_channels.hpp). Defaults as the
/// controller's: the shipped URDF, its collision file, its controller configuration (beside it, else built-in).
struct SceneOptions {
  SceneChannelOptions scene;
  bool none = false;
  void add(CLI::App& app) {
    scene.urdf = reflex::common::defaultUrdf();
    app.add_option("--urdf", scene.urdf, "scene channels: robot URDF (the controller's)")->capture_default_str();
    app.add_option("--collision", scene.collision,
                   "scene channels: collision configuration (default: next to the URDF)");
    app.add_option("--controller", scene.controller,
                   "scene channels: controller YAML, arms and zone thresholds (default: <URDF stem>.controller.yaml "
                   "beside the URDF if it exists, else built-in)");
    app.add_option("--scene-rate", scene.rate,
                   "scene channels: messages per second of recording time at most, (0, 200]")
        ->capture_default_str();
    app.add_flag("--no-scene", none,
                 "MCAP without the scene channels /tf and /reflex/scene (made by default from reflex/joint_state, "
                 "status, targets, objects and body schema, so Foxglove's 3D panel shows the robot)");
  }
  SceneChannelOptions options() const {
    SceneChannelOptions o = scene;
    o.enabled = !none;
    return o;
  }
};

/// Runs a command: an exception is an error message and exit status 2 (a reflex::Error: a bad file,
/// option or recording) or 1 (anything else); standard output that could not be written
/// (`reflex_record info run.rfx > /dev/full`) is exit status 1.
template <class F>
int guarded(const char* tool, F&& f) {
  const int status = reflex::runGuarded(tool, f);
  if (const std::string why = common::flushStandardOutput(); !why.empty()) {
    std::fprintf(stderr, "%s: error: %s\n", tool, why.c_str());
    return 1;
  }
  return status;
}

}  // namespace

std::function<int()> addPlay(CLI::App& app) {
  auto o = std::make_shared<PlayerOptions>();
  auto b = std::make_shared<BusOptions>();
  auto quiet = std::make_shared<bool>(false);
  app.add_option("file", o->input, "recording to play")->required();
  app.add_option("-r,--rate", o->rate, "speed factor: 1 real time, 2 twice as fast; 0 as fast as possible")
      ->capture_default_str();
  app.add_flag("-l,--loop", o->loop, "play again from the start offset when the end is reached");
  app.add_option("-s,--start", o->start, "start offset, seconds after the first sample")->capture_default_str();
  app.add_option("--duration", o->duration, "play only this many seconds of recording time (0: to the end)");
  app.add_option("--delay", o->delay, "seconds to wait after creating the writers (discovery)")->capture_default_str();
  app.add_option("--wait-readers", o->wait_readers,
                 "hold the start until every played topic has this many matched readers (then 0.3 s for their "
                 "side of the match, then --delay), so the first samples reach them; 0: --delay alone")
      ->capture_default_str();
  app.add_option("--wait-timeout", o->wait_timeout,
                 "seconds --wait-readers waits; then exit 1 naming each topic short of readers")
      ->capture_default_str();
  app.add_option("-t,--topic", o->topics, "topic to play (repeatable; default: every topic in the file)");
  app.add_option("-x,--exclude", o->exclude,
                 "topic not to play (repeatable). Command topics are not played anyway without --commands: "
                 "'-x reflex/hand_targets' is then accepted and changes nothing");
  app.add_flag("--commands", o->commands,
               "also play the command topics (reflex/hand_targets, reflex/motion_priority, reflex/body_schema, "
               "reflex/walk_command, reflex/joint_command, and reflex/robot_state: a controller over DDS computes "
               "its commands from it). Default: observations only, so a replay never steers a live controller or "
               "robot; -t of a command topic needs this flag");
  app.add_flag("--restamp", o->restamp,
               "move sample time stamps (header.stamp_ns, capture_stamp_ns) to the playing time");
  app.add_option("--max-gap", o->max_gap,
                 "longest wait between two records, seconds of recording time; longer gaps are played "
                 "this long (reported)")
      ->capture_default_str();
  app.add_flag("--progress", o->progress, "show progress even if stderr is not a terminal");
  app.add_flag("-q,--quiet", *quiet, "no progress display");
  b->add(app);
  return [o, b, quiet] {
    return guarded("reflex_play", [&] {
      o->bus = b->config("player");
      o->progress = !*quiet && (o->progress || isatty(STDERR_FILENO));
      Player player(*o);
      bus::StopOnSignal stop_on_signal(player.bus());
      std::fprintf(stderr, "reflex_play: %s, %.2f s window, rate %g%s, domain %d\n", o->input.c_str(),
                   player.windowSeconds(), o->rate, o->loop ? ", loop" : "", player.bus().domainId());
      if (!player.commandsSkipped().empty()) {
        std::string skipped;
        for (const std::string& t : player.commandsSkipped()) skipped += (skipped.empty() ? "" : ", ") + t;
        std::fprintf(stderr, "reflex_play: command topics not played (observations only; --commands plays them): %s\n",
                     skipped.c_str());
      }
      for (const std::string& ex : o->exclude)
        if (!o->commands && isCommandTopic(ex))
          std::fprintf(stderr,
                       "reflex_play: note: -x %s changes nothing: command topics are played only with "
                       "--commands\n",
                       ex.c_str());
      if (player.stats().gaps_shortened > 0)
        std::fprintf(stderr,
                     "reflex_play: %llu gap(s) between records longer than --max-gap %g s are played as %g s "
                     "(longest %.6g s, ending %.6g s into the window); a pass takes %.3f s at rate 1\n",
                     static_cast<unsigned long long>(player.stats().gaps_shortened), o->max_gap, o->max_gap,
                     player.stats().longest_gap, player.stats().longest_gap_at, player.playedSeconds());
      player.run();
      const auto& s = player.stats();
      std::fprintf(stderr, "reflex_play: published %llu samples (%llu failed), %llu complete passes; file: %s\n",
                   static_cast<unsigned long long>(s.published), static_cast<unsigned long long>(s.failed),
                   static_cast<unsigned long long>(s.loops), toString(s.tail));
      return s.failed == 0 ? 0 : 2;
    });
  };
}

std::function<int()> addRecord(CLI::App& app) {
  auto o = std::make_shared<RecorderOptions>();
  auto b = std::make_shared<BusOptions>();
  auto flush_ms = std::make_shared<int>(100);
  auto sync_ms = std::make_shared<int>(1000);
  auto late_joiner = std::make_shared<bool>(false);
  auto name = std::make_shared<std::string>("recorder");
  auto out = std::make_shared<OutputOptions>();
  auto scene = std::make_shared<SceneOptions>();
  app.add_option("-o,--output", o->output, "recording file to write (run.mcap; run.rfx for the old format)")
      ->required();
  app.add_option("-t,--topic", o->topics,
                 "topic to record (repeatable): a Reflex topic name, or NAME:TYPE for another topic name "
                 "(default: every Reflex topic)");
  app.add_option("-x,--exclude", o->exclude, "topic not to record (repeatable)");
  app.add_option("--duration", o->duration, "seconds to record (0: until Ctrl-C / SIGTERM)")
      ->check(CLI::NonNegativeNumber);
  out->add(app);
  app.add_option("--flush-ms", *flush_ms, "rfx: hand buffered records to the kernel at least this often (ms)")
      ->capture_default_str()
      ->check(CLI::Range(0, 60000));
  app.add_option("--sync-ms", *sync_ms, "fsync the file this often (ms; 0: after every flush)")
      ->capture_default_str()
      ->check(CLI::Range(0, 600000));
  app.add_flag("--append", o->writer.append, "rfx: append to an existing recording (a torn last record is cut off)");
  app.add_flag("--late-joiner-state", *late_joiner,
               "read state topics (hand targets, priority, body schema, walk, heartbeat) with their own "
               "reliable transient-local profile: the recording starts with the state published before it "
               "started, but keeps only the newest of a burst (default: every topic with reflex_record; the "
               "controller's protection state, published once, is always read with its own profile)");
  app.add_flag("--progress", o->progress, "print a status line every second");
  app.add_option("--name", *name, "module name on the bus")->capture_default_str();
  scene->add(app);
  b->add(app);
  return [o, b, flush_ms, sync_ms, late_joiner, name, out, scene] {
    return guarded("reflex_record", [&] {
      o->bus = b->config(*name);
      const RecordingOptions recording = out->options(o->output);
      if (o->writer.append && recording.format == RecordingFormat::kMcap)  // before any DDS entity
        throw RecordError("--append works for .rfx recordings only ('" + o->output + "' would be MCAP)");
      o->format = recording.format == RecordingFormat::kMcap ? "mcap" : "rfx";
      o->mcap = recording.mcap;
      o->writer.flush_interval = std::chrono::milliseconds(*flush_ms);
      o->writer.sync_interval = std::chrono::milliseconds(*sync_ms);
      o->mcap.sync_interval = std::chrono::milliseconds(*sync_ms);
      o->late_joiner_state = *late_joiner;
      o->scene = scene->options();
      Recorder recorder(*o);
      bus::StopOnSignal stop_on_signal(recorder.bus());
      std::fprintf(stderr, "reflex_record: recording %zu topics to %s (%s) on domain %d\n", recorder.counts().size(),
                   o->output.c_str(), o->format == "mcap" ? "MCAP" : "rfx", recorder.bus().domainId());
      if (!recorder.sceneChannels() && !recorder.sceneNote().empty())
        std::fprintf(stderr, "reflex_record: %s\n", recorder.sceneNote().c_str());
      recorder.run();
      std::fprintf(stderr, "reflex_record: %llu samples written to %s\n",
                   static_cast<unsigned long long>(recorder.totalSamples()), o->output.c_str());
      for (const auto& kv : recorder.counts())
        std::fprintf(stderr, "  %-28s %-30s %llu\n", kv.first.c_str(), kv.second.type.c_str(),
                     static_cast<unsigned long long>(kv.second.samples));
      if (recorder.sceneChannels()) std::fprintf(stderr, "reflex_record: %s\n", recorder.sceneNote().c_str());
      return 0;
    });
  };
}

std::function<int()> addExport(CLI::App& app) {
  auto input = std::make_shared<std::string>();
  auto topics = std::make_shared<std::vector<std::string>>();
  auto csv = std::make_shared<std::string>();
  auto dir = std::make_shared<std::string>();
  app.add_option("file", *input, "recording")->required();
  app.add_option("-t,--topic", *topics, "topic to export (repeatable with --dir; default with --dir: all)");
  app.add_option("--csv", *csv, "CSV file to write (one --topic)");
  app.add_option("--dir", *dir,
                 "folder to write one CSV per topic into (<topic with / : and space as _, other bytes but letters, "
                 "digits, _ - . as %XX>.csv; topics that would share a name are refused, naming them)");
  return [input, topics, csv, dir] {
    return guarded("reflex_record export", [&] {
      if (csv->empty() == dir->empty())
        throw RecordError("give exactly one of --csv FILE (with one --topic) or --dir DIR");
      std::vector<CsvExport> targets;
      bool refused = false;
      RecordingInfo info;
      if (!csv->empty()) {
        if (topics->size() != 1)
          throw RecordError("--csv needs exactly one --topic (got " + std::to_string(topics->size()) + ")");
        targets.push_back({topics->front(), *csv, 0});
      } else {
        if (const std::string why = common::outputFolderProblem(*dir); !why.empty()) throw RecordError(why);
        std::error_code ec;
        std::filesystem::create_directories(*dir, ec);
        if (ec) throw RecordError("cannot create folder '" + *dir + "': " + ec.message());
        info = scanRecording(*input);
        std::vector<std::string> list = *topics;
        if (list.empty()) {
          for (const auto& kv : info.topics) {
            if (findCodecByType(kv.second.type))
              list.push_back(kv.first);
            else  // the scene channels (/tf, /reflex/scene: JSON for viewers) have no CSV form
              std::fprintf(stderr, "reflex_record: %s (%s) is not a Reflex topic type: no CSV\n",
                           printableName(kv.first).c_str(), printableName(kv.second.type).c_str());
          }
        }
        // Topics that would share a file: none of them is written (one would overwrite the other).
        const auto collisions = csvFileNameCollisions(list);
        for (const auto& kv : collisions) {
          std::string names;
          for (const std::string& t : kv.second) names += (names.empty() ? "'" : ", '") + printableName(t) + "'";
          std::fprintf(stderr,
                       "reflex_record: error: topics %s would all be written to %s: none of them exported "
                       "(export each with --csv)\n",
                       names.c_str(), printableName(kv.first).c_str());
          refused = true;
        }
        for (const std::string& t : list) {
          if (collisions.count(csvFileNameForTopic(t))) continue;
          if (std::any_of(targets.begin(), targets.end(), [&](const CsvExport& x) { return x.topic == t; })) continue;
          targets.push_back({t, (std::filesystem::path(*dir) / csvFileNameForTopic(t)).string(), 0});
        }
      }
      const CsvExportReport report = exportCsvFiles(*input, targets, csv->empty() ? &info : nullptr);
      for (const CsvExport& f : report.files)
        std::fprintf(stderr, "reflex_record: %llu samples of %s -> %s\n", static_cast<unsigned long long>(f.samples),
                     printableName(f.topic).c_str(), printableName(f.path).c_str());
      if (report.undecodable > 0)
        std::fprintf(stderr, "reflex_record: error: %s\n", report.undecodableMessage().c_str());
      return report.undecodable > 0 || refused ? 1 : 0;
    });
  };
}

std::function<int()> addInfo(CLI::App& app) {
  auto input = std::make_shared<std::string>();
  auto print = std::make_shared<int>(0);
  app.add_option("file", *input, "recording")->required();
  app.add_option("--print", *print, "also print the first N samples")->check(CLI::NonNegativeNumber);
  return [input, print] {
    return guarded("reflex_record info", [&] {
      const RecordingInfo info = scanRecording(*input);
      std::printf("file:      %s (%s, %llu bytes, valid up to byte %llu)\n", input->c_str(), info.format.c_str(),
                  static_cast<unsigned long long>(info.file_size), static_cast<unsigned long long>(info.valid_end));
      const bool unfinished_mcap = info.format == "mcap" && info.tail == TailState::kTorn;
      std::printf("end:       %s%s\n",
                  unfinished_mcap ? "unfinished (no footer: the recorder did not close it); every complete chunk read"
                                  : toString(info.tail),
                  info.skipped_bytes ? (" (" + std::to_string(info.skipped_bytes) + " bytes skipped)").c_str() : "");
      if (!info.problem.empty()) std::printf("problem:   %s\n", info.problem.c_str());
      std::printf("samples:   %llu\n", static_cast<unsigned long long>(info.records));
      std::printf("duration:  %.3f s\n", 1e-9 * static_cast<double>(info.last_ns - info.first_ns));
      for (const auto& kv : info.topics)
        std::printf("  %-28s %-30s %8llu\n", printableName(kv.first).c_str(), printableName(kv.second.type).c_str(),
                    static_cast<unsigned long long>(kv.second.samples));
      if (*print > 0) {
        const std::unique_ptr<SampleReader> reader = openRecording(*input);
        RecordEntry e;
        for (int i = 0; i < *print && reader->next(e); ++i) {
          const TopicCodec* c = findCodecByType(e.type);
          std::string line;
          try {
            line = c ? c->summary(e) : printableName(e.topic) + " (unknown type " + printableName(e.type) + ")";
          } catch (const RecordError& err) {  // one undecodable sample is a line, not the end of the listing
            line = printableName(e.topic) + " (does not decode: " + err.what() + ")";
          }
          std::printf("%.6f %s\n", 1e-9 * static_cast<double>(e.receive_ns - info.first_ns), line.c_str());
        }
      }
      return 0;
    });
  };
}

std::function<int()> addConvert(CLI::App& app) {
  auto input = std::make_shared<std::string>();
  auto output = std::make_shared<std::string>();
  auto out = std::make_shared<OutputOptions>();
  app.add_option("input", *input, "recording to read (.rfx or MCAP, detected by its first bytes)")->required();
  app.add_option("output", *output, "recording to write (format: --format, by default from the name)")->required();
  auto scene = std::make_shared<SceneOptions>();
  out->add(app);
  scene->add(app);
  return [input, output, out, scene] {
    return guarded("reflex_record convert", [&] {
      const RecordingOptions options = out->options(*output);
      std::string scene_note;
      const std::uint64_t n = convertRecording(*input, *output, options, scene->options(), &scene_note);
      const RecordingInfo info = scanRecording(*input);
      std::fprintf(stderr, "reflex_record: %llu samples of %s (%s) -> %s (%s)\n", static_cast<unsigned long long>(n),
                   input->c_str(), toString(info.tail), output->c_str(),
                   options.format == RecordingFormat::kMcap ? "MCAP" : "rfx");
      if (!scene_note.empty()) std::fprintf(stderr, "reflex_record: %s\n", scene_note.c_str());
      return 0;
    });
  };
}

}  // namespace reflex::record::cli
