// Shared pieces of the libFuzzer targets (tests/fuzz/README.md).
//
// Contract checked by every target: a parser of outside input either returns a value or throws its
// documented setup error (ModelError, ConfigError, VisionError, ...). A crash, a sanitizer report,
// or ANY other exception type (e.g. a raw YAML::BadConversion without the file name) is a finding:
// the target prints it and aborts, and libFuzzer saves the input as a reproducer.
#pragma once

#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <fstream>
#include <string>
#include <typeinfo>
#include <unistd.h>

namespace reflex::fuzz {

/// The input as text.
inline std::string asText(const std::uint8_t* data, std::size_t size) {
  return std::string(reinterpret_cast<const char*>(data), size);
}

/// Writes the input to a per-process temporary file (for parsers that only read files) and
/// returns its path; the same file is overwritten by every run of this process.
inline const std::string& writeTemp(const std::uint8_t* data, std::size_t size, const char* suffix) {
  static const std::string path = [&] {
    const char* dir = std::getenv("TMPDIR");
    return std::string(dir && *dir ? dir : "/tmp") + "/reflex_fuzz_" + std::to_string(getpid()) + suffix;
  }();
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(reinterpret_cast<const char*>(data), static_cast<std::streamsize>(size));
  return path;
}

/// Aborts with a message: an exception that is not the parser's documented error type.
[[noreturn]] inline void undocumentedException(const char* parser, const std::exception& e) {
  std::fprintf(stderr, "FUZZ FINDING: %s threw an undocumented %s: %s\n", parser, typeid(e).name(), e.what());
  std::abort();
}

/// Runs `fn`; the documented exception type `Documented` is fine, any other one is a finding.
template <class Documented, class Fn>
void expectOnly(const char* parser, Fn fn) {
  try {
    fn();
  } catch (const Documented& e) {
    // The documented reaction to bad input; REFLEX_FUZZ_VERBOSE=1 prints its message (replays).
    static const bool verbose = std::getenv("REFLEX_FUZZ_VERBOSE") != nullptr;
    if (verbose) std::fprintf(stderr, "%s: %s\n", parser, e.what());
  } catch (const std::exception& e) {
    undocumentedException(parser, e);
  }
}

}  // namespace reflex::fuzz
