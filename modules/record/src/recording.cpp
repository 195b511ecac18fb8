#include "reflex/record/recording.hpp"

#include "reflex/common/files.hpp"

#include <algorithm>
#include <cstring>
#include <fstream>

namespace reflex::record {

RecordingFormat recordingFormatFor(const std::string& path, const std::string& format) {
  if (format == "mcap") return RecordingFormat::kMcap;
  if (format == "rfx") return RecordingFormat::kRfx;
  if (format == "auto" || format.empty()) {
    const std::string ext = ".rfx";
    const bool rfx = path.size() >= ext.size() && path.compare(path.size() - ext.size(), ext.size(), ext) == 0;
    return rfx ? RecordingFormat::kRfx : RecordingFormat::kMcap;
  }
  throw RecordError("unknown recording format '" + format + "' (mcap, rfx or auto)");
}

std::unique_ptr<SampleWriter> createRecording(const std::string& path, const RecordingOptions& options) {
  if (options.format == RecordingFormat::kRfx) return std::make_unique<RecordWriter>(path, options.rfx);
  if (options.rfx.append)
    throw RecordError("--append works for .rfx recordings only ('" + path + "' would be MCAP; use --format rfx)");
  return std::make_unique<McapSampleWriter>(path, options.mcap);
}

std::unique_ptr<SampleReader> openRecording(const std::string& path) {
  // Before any open: a FIFO blocks open(2) and read(2) until a writer appears; a device never ends.
  if (const std::string why = common::inputFileProblem(path); !why.empty()) throw RecordError("recording " + why);
  char head[8] = {};
  std::ifstream in(path, std::ios::binary);
  in.read(head, sizeof(head));
  const auto n = static_cast<std::size_t>(in.gcount());
  if (n > 0 && std::memcmp(head, kMcapMagic, n) == 0) return std::make_unique<McapSampleReader>(path);
  return std::make_unique<RecordReader>(path);  // throws "not a Reflex recording" for anything else
}

}  // namespace reflex::record
