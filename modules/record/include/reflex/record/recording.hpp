// Opening recordings whatever their format: MCAP (.mcap, mcap.hpp; the default) or the
// Reflex log format (.rfx, record_file.hpp; what older recordings are). Readers detect the format
// by the file's magic bytes, not its name.
#pragma once

#include "reflex/record/mcap.hpp"
#include "reflex/record/record_file.hpp"

#include <memory>
#include <string>

namespace reflex::record {

enum class RecordingFormat { kMcap, kRfx };

/// The format to write: "mcap" or "rfx"; "auto" (or "") = rfx if `path` ends in ".rfx", else MCAP.
/// Throws RecordError quoting any other text.
RecordingFormat recordingFormatFor(const std::string& path, const std::string& format);

struct RecordingOptions {
  RecordingFormat format = RecordingFormat::kMcap;
  WriterOptions rfx;       ///< for kRfx
  McapWriterOptions mcap;  ///< for kMcap
};

/// Creates a recording. Throws RecordError as RecordWriter / McapWriter; --append (rfx.append) with
/// MCAP is refused (an MCAP file ends with its summary and footer).
std::unique_ptr<SampleWriter> createRecording(const std::string& path, const RecordingOptions& options);

/// Opens a recording of either format, detected by its first bytes. Throws RecordError naming the path
/// when it is missing, not a regular file, cut inside the MCAP magic, or neither format ("not a Reflex
/// recording").
std::unique_ptr<SampleReader> openRecording(const std::string& path);

}  // namespace reflex::record
