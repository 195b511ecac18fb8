// Checks on the files a user names to a Reflex tool.
//
// Inputs: every loader of a file given by a user (URDF, collision / controller / behavior YAML,
// timeline CSV, DDS profiles XML, recordings, robot-state file, vision calibration / session / mount /
// object map files, joint CSVs) calls inputFileProblem() before opening it. Only a regular file (or a
// symbolic link to one) is read: a FIFO blocks the reader until some writer appears (forever), a
// character device such as /dev/zero or /dev/urandom never ends, a terminal waits for typing, a
// directory "opens" and then fails obscurely. Each of those is refused at once with a message naming
// the path and what it is.
//
// Outputs: outputFileProblem() says at start-up, before any work is done, why a file cannot be
// written where the user asked (missing folder, a folder in its place); devices (/dev/null,
// /dev/stdout) and FIFOs stay allowed as outputs. Write errors found later (/dev/full: ENOSPC) are
// reported by the writer naming the file (writeError()).
//
// No dependency beyond the C++ library and POSIX: usable from every layer (see CMakeLists.txt).
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <sys/types.h>

namespace reflex::common {

/// "a regular file", "a directory", "a FIFO (named pipe)", "a character device", "a block device",
/// "a socket", "a symbolic link" (only from lstat) or "an unknown kind of file", from st_mode.
const char* fileKind(mode_t mode) noexcept;

/// Why `path` must not be read as an input file, or "" if it may be.
///   ""  : a regular file, or a symbolic link to one; also a path stat() cannot see (missing, no
///         permission, too long): the caller's own open reports that with its own message.
///   else: "'<path>' is a FIFO (named pipe), not a regular file" (likewise "is a character device",
///         "is a directory", "is a block device", "is a socket").
/// Never blocks (stat(2) only).
std::string inputFileProblem(const std::string& path);

/// Why `path` cannot be created or written as an output file, or "" if it can (as far as can be
/// known before writing):
///   ""  : the path is a regular file, a character device (/dev/null, /dev/stdout on a terminal),
///         a FIFO (a pipe the user set up), or does not exist yet while its folder does.
///   else: "folder '<dir>' of output file '<path>' does not exist", "... is not a folder",
///         "output file '<path>' is a directory", "cannot write into folder '<dir>': Permission denied".
std::string outputFileProblem(const std::string& path);

/// Why `dir` cannot serve as an output folder that the tool will create if missing, or "" if it
/// can: "" when it is a folder, or when it does not exist but its nearest existing ancestor is a
/// writable folder; else "output folder '<dir>' is a regular file", "... cannot be created under
/// '<ancestor>': Permission denied", and so on.
std::string outputFolderProblem(const std::string& dir);

/// "cannot write '<path>': <strerror(err)>" -- the one wording of a failed write / flush / close.
std::string writeError(const std::string& path, int err);

/// Writes `text` to `path` through a fresh temporary file beside it (mkstemp) renamed over it, so a
/// reader never sees half a file; "" when done, else the reason. Only a regular file is replaced: a
/// path that is a directory, a device, a FIFO (or a link to one) is refused, never replaced; a link
/// to a regular file is written through (the target replaced, the link kept). The temporary file is
/// removed on every failure.
std::string writeFileReplacing(const std::string& path, const std::string& text);

/// "" if writeFileReplacing may replace `path` (missing, a regular file, or a link to one: then
/// `target`, if given, is the file the link resolves to), else why not (naming the path and its kind).
/// For a tool to check its output before any work.
std::string replaceableFileProblem(const std::string& path, std::string* target = nullptr);

/// Why `path` cannot be written as an output that is read back as a whole (a configuration, a
/// calibration, an image, a scene module), or "" if it can: outputFileProblem()'s checks, and only a
/// regular file (or a link to one) or a new file: a device, a FIFO or a directory (or a link to one)
/// is refused, "output file '<path>' [(a link to '<target>')] is <kind>: only a regular file is
/// written". Streams (a time series, a dump, a recording, a CSV export) use outputFileProblem() and
/// may go to a device or a FIFO.
std::string regularOutputProblem(const std::string& path);

/// Opens `path` to stream into it (created or truncated, mode 0644 less the umask, close-on-exec):
/// the file descriptor, or -1 with errno set. A FIFO without a reader fails at once (ENXIO) instead of
/// blocking the tool until one comes; the descriptor is blocking once open. Callers check the path
/// with outputFileProblem() first.
int openOutputStream(const std::string& path) noexcept;

/// Flushes std::cout and stdout; "" if everything written to them reached the kernel, else
/// "cannot write the standard output: <cause>" (e.g. `tool > /dev/full`: No space left on device).
/// Tools call it last and exit non-zero with the message: output that was lost is not success.
std::string flushStandardOutput();

/// Parses `text` as one finite number written whole (no leading/trailing characters, no NaN/inf):
/// true and the value in `out`, else false (out unchanged). The callers name the bad text in their
/// own error type. Never throws.
bool parseFiniteNumber(const std::string& text, double& out) noexcept;

/// Reads exactly n bytes of file descriptor `fd` at `offset` (pread, EINTR retried): false on a short
/// read or an error. The one home of this loop (the .rfx and the MCAP readers).
bool preadAll(int fd, std::uint64_t offset, void* dst, std::size_t n) noexcept;

}  // namespace reflex::common
