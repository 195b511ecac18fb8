#include "reflex/record/recorder.hpp"

#include "reflex/common/files.hpp"

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>
#include <unordered_map>

namespace reflex::record {

std::uint64_t convertRecording(const std::string& input, const std::string& output, const RecordingOptions& options,
                               const SceneChannelOptions& scene, std::string* scene_note) {
  const std::unique_ptr<SampleReader> reader = openRecording(input);
  std::error_code ec;
  if (std::filesystem::equivalent(input, output, ec))  // creating the output would truncate the input
    throw RecordError("convert: output '" + output + "' is the input recording '" + input + "'");
  std::unique_ptr<SceneChannels> channels;  // the robot files before the output file
  if (scene.enabled && options.format == RecordingFormat::kMcap) channels = std::make_unique<SceneChannels>(scene);
  const std::unique_ptr<SampleWriter> writer = createRecording(output, options);
  auto* mcap = dynamic_cast<McapSampleWriter*>(writer.get());
  RecordEntry e;
  std::uint64_t n = 0;
  while (reader->next(e)) {
    if (e.type.rfind("foxglove.", 0) == 0) continue;  // the input's scene channels: made again, or not wanted
    writer->append(e);
    ++n;
    if (channels && mcap) channels->add(e, mcap->mcap());
  }
  writer->close();
  if (scene_note)
    *scene_note = channels        ? channels->summary()
                  : scene.enabled ? "an .rfx output has no scene channels (/tf, /reflex/scene)"
                                  : "";
  return n;
}

std::string csvFileNameForTopic(const std::string& topic) {
  std::string name;
  for (char c : topic) {
    const auto b = static_cast<unsigned char>(c);
    if (c == '/' || c == ':' || c == ' ') {
      name += '_';
    } else if (std::isalnum(b) || c == '_' || c == '-' || c == '.') {
      name += c;
    } else {  // '%' too, so that a %XX in the name always stands for one escaped byte
      char buf[4];
      std::snprintf(buf, sizeof(buf), "%%%02X", b);
      name += buf;
    }
  }
  return name + ".csv";
}

std::map<std::string, std::vector<std::string>> csvFileNameCollisions(const std::vector<std::string>& topics) {
  std::map<std::string, std::vector<std::string>> by_name, out;
  for (const std::string& t : topics) {
    std::vector<std::string>& group = by_name[csvFileNameForTopic(t)];
    if (std::find(group.begin(), group.end(), t) == group.end()) group.push_back(t);
  }
  for (auto& kv : by_name)
    if (kv.second.size() > 1) out.emplace(kv.first, std::move(kv.second));
  return out;
}

namespace {

/// The CSV files of one export, at most kMaxOpen of them open at a time (the least recently written
/// is closed first and reopened for appending when its topic comes again): 3,000 topics must not take
/// 3,000 file descriptors (the usual limit is 1,024).
class CsvFiles {
 public:
  static constexpr std::size_t kMaxOpen = 64;
  struct File {
    CsvExport* target = nullptr;
    const TopicCodec* codec = nullptr;
    std::unique_ptr<std::ofstream> out;
    std::uint64_t last_use = 0;
  };

  /// Creates (or empties) every target's file before the pass: an unwritable one is an error before
  /// reading, as with one file.
  CsvFiles(std::vector<CsvExport>& targets, const std::vector<const TopicCodec*>& codecs) {
    for (std::size_t i = 0; i < targets.size(); ++i) {
      File& f = files_[targets[i].topic];
      f.target = &targets[i];
      f.codec = codecs[i];
      open(f, false);
    }
  }
  File* find(const std::string& topic) {
    const auto it = files_.find(topic);
    return it == files_.end() ? nullptr : &it->second;
  }
  /// The open stream of `f`, reopened for appending if it was closed.
  std::ofstream& stream(File& f) {
    if (!f.out) open(f, true);
    f.last_use = ++clock_;
    return *f.out;
  }
  /// Closes every file; throws RecordError naming the first one that could not be written.
  void closeAll() {
    for (auto& kv : files_)
      if (kv.second.out) close(kv.second);
  }

 private:
  void open(File& f, bool append) {
    if (open_ >= kMaxOpen) {  // close the least recently written
      File* oldest = nullptr;
      for (auto& kv : files_)
        if (kv.second.out && (!oldest || kv.second.last_use < oldest->last_use)) oldest = &kv.second;
      close(*oldest);
    }
    const std::string& csv_path = f.target->path;
    errno = 0;
    auto out = std::make_unique<std::ofstream>(csv_path, append ? std::ios::app : std::ios::out);
    if (!*out) throw RecordError(common::writeError(csv_path, errno ? errno : EIO));
    f.out = std::move(out);
    f.last_use = ++clock_;
    ++open_;
  }
  void close(File& f) {
    const std::string& csv_path = f.target->path;
    errno = 0;
    f.out->close();  // flushes: a full disk or /dev/full (ENOSPC) shows here at the latest
    const bool failed = !*f.out;
    f.out.reset();
    --open_;
    if (failed) throw RecordError(common::writeError(csv_path, errno ? errno : EIO));
  }

  std::unordered_map<std::string, File> files_;
  std::size_t open_ = 0;
  std::uint64_t clock_ = 0;
};

}  // namespace

CsvExportReport exportCsvFiles(const std::string& input, std::vector<CsvExport> targets, const RecordingInfo* scanned) {
  // Before reading the recording: a missing folder is an error at start, not after the scan.
  for (const CsvExport& t : targets)
    if (const std::string why = common::outputFileProblem(t.path); !why.empty()) throw RecordError("CSV " + why);
  const RecordingInfo info = scanned ? *scanned : scanRecording(input);
  std::vector<const TopicCodec*> codecs;
  for (const CsvExport& t : targets) {
    const auto it = info.topics.find(t.topic);
    if (it == info.topics.end()) {
      std::string have;
      for (const auto& kv : info.topics) have += " " + printableName(kv.first);
      throw RecordError("topic '" + printableName(t.topic) + "' is not in recording '" + input +
                        "' (it has:" + (have.empty() ? std::string(" nothing") : have) + ")");
    }
    const TopicCodec* codec = findCodecByType(it->second.type);
    if (!codec)
      throw RecordError("topic '" + printableName(t.topic) + "' has unknown type '" + printableName(it->second.type) +
                        "'");
    codecs.push_back(codec);
  }
  CsvExportReport report;
  report.files = std::move(targets);
  CsvFiles files(report.files, codecs);
  // One pass over the recording for every topic.
  const std::unique_ptr<SampleReader> reader = openRecording(input);
  RecordEntry e;
  CsvContext ctx;
  ctx.t0_ns = info.first_ns;
  std::uint64_t index = 0;
  while (reader->next(e)) {
    ++index;
    CsvFiles::File* f = files.find(e.topic);
    if (!f) continue;
    std::ofstream& out = files.stream(*f);  // outside the try: an output that fails is an error, not a sample
    try {
      if (f->target->samples == 0) f->codec->writeCsvHeader(out, e);
      f->codec->writeCsvRows(out, e, ctx);
      ++f->target->samples;
    } catch (const RecordError& err) {  // a sample that does not decode: skipped, counted, named once
      if (report.undecodable++ == 0) {
        char t[40];
        std::snprintf(t, sizeof(t), "%.6f", 1e-9 * static_cast<double>(e.receive_ns - ctx.t0_ns));
        report.first_undecodable = "sample " + std::to_string(index) + " of the file (t = " + t + " s): " + err.what();
      }
    }
  }
  files.closeAll();
  return report;
}

std::uint64_t exportCsv(const std::string& input, const std::string& topic, const std::string& csv_path) {
  const CsvExportReport r = exportCsvFiles(input, {CsvExport{topic, csv_path, 0}});
  if (r.undecodable > 0)
    throw RecordError(r.undecodableMessage() + "; the " + std::to_string(r.files.front().samples) +
                      " others were written to '" + csv_path + "'");
  return r.files.front().samples;
}

std::string CsvExportReport::undecodableMessage() const {
  if (undecodable == 0) return "";
  return std::to_string(undecodable) + (undecodable == 1 ? " sample" : " samples") +
         " could not be decoded, first at " + first_undecodable;
}

}  // namespace reflex::record
