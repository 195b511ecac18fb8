#include "reflex/record/recorder.hpp"

#include "reflex/common/files.hpp"

#include <cerrno>
#include <filesystem>
#include <fstream>

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
    *scene_note = channels      ? channels->summary()
                  : scene.enabled ? "an .rfx output has no scene channels (/tf, /reflex/scene)"
                                  : "";
  return n;
}

std::string csvFileNameForTopic(const std::string& topic) {
  std::string name;
  for (char c : topic) name += (c == '/' || c == ':' || c == ' ') ? '_' : c;
  return name + ".csv";
}

std::uint64_t exportCsv(const std::string& input, const std::string& topic, const std::string& csv_path) {
  // Before reading the recording: a missing folder is an error at start, not after the scan.
  if (const std::string why = common::outputFileProblem(csv_path); !why.empty()) throw RecordError("CSV " + why);
  const RecordingInfo info = scanRecording(input);
  const auto it = info.topics.find(topic);
  if (it == info.topics.end()) {
    std::string have;
    for (const auto& kv : info.topics) have += " " + kv.first;
    throw RecordError("topic '" + topic + "' is not in recording '" + input + "' (it has:" +
                      (have.empty() ? std::string(" nothing") : have) + ")");
  }
  const TopicCodec* codec = findCodecByType(it->second.type);
  if (!codec) throw RecordError("topic '" + topic + "' has unknown type '" + it->second.type + "'");
  errno = 0;
  std::ofstream out(csv_path);
  if (!out) throw RecordError(common::writeError(csv_path, errno ? errno : EIO));
  const std::unique_ptr<SampleReader> reader = openRecording(input);
  RecordEntry e;
  CsvContext ctx;
  ctx.t0_ns = info.first_ns;
  std::uint64_t n = 0;
  while (reader->next(e)) {
    if (e.topic != topic) continue;
    if (n == 0) codec->writeCsvHeader(out, e);
    codec->writeCsvRows(out, e, ctx);
    ++n;
  }
  errno = 0;
  out.close();  // flushes: a full disk or /dev/full (ENOSPC) shows here at the latest
  if (!out) throw RecordError(common::writeError(csv_path, errno ? errno : EIO));
  return n;
}

}  // namespace reflex::record
