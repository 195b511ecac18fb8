// runMain: one main() for every Reflex program. It parses the command line, runs the program and
// maps what escapes to the exit codes of error.hpp:
//   --help / --version        0, the text on stdout
//   a command-line error      2, CLI11's message naming the option on stderr
//   a reflex::Error           2, "<program>: error: <message>" on stderr
//   a reflex::Failure         1, "<program>: error: <message>" on stderr
//   any other exception       1, "<program>: internal error: <message>" on stderr
//   otherwise                 what `body` returns (0, 1, or a documented program-specific code)
// Header-only (the programs already use CLI11; the libraries do not).
#pragma once

#include "reflex/common/error.hpp"

#include <CLI/CLI.hpp>

#include <cmath>
#include <cstdio>
#include <exception>
#include <string>

namespace reflex {

/// A number option's check: finite and within [lo, hi] (CLI::Range alone lets `nan` through, since
/// every comparison with it is false). The message names the value and the range.
inline CLI::Validator FiniteRange(double lo, double hi) {
  return CLI::Validator(
      [lo, hi](std::string& text) {
        double v = 0.0;
        if (!CLI::detail::lexical_cast(text, v)) return "Value " + text + " is not a number";
        if (!std::isfinite(v) || v < lo || v > hi)
          return "Value " + text + " not in range " + std::to_string(lo) + " to " + std::to_string(hi);
        return std::string();
      },
      "FLOAT in [" + CLI::detail::to_string(lo) + " - " + CLI::detail::to_string(hi) + "]");
}

/// Parses argc/argv into `app`: -1 to go on, else the exit code to return at once (0 after --help or
/// --version, 2 after a command-line error; CLI11 has printed the text).
inline int parseCommandLine(CLI::App& app, int argc, char** argv) {
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e) == 0 ? kExitOk : kExitRefused;
  }
  return -1;
}

/// Prints what `e` says, the way runMain does, and returns its exit code (2 for a reflex::Error,
/// else 1; "internal error" unless it is a reflex::Error or reflex::Failure), for a program that
/// catches on its own.
inline int reportException(const char* program, const std::exception& e) {
  const bool refused = dynamic_cast<const Error*>(&e) != nullptr;
  const bool named = refused || dynamic_cast<const Failure*>(&e) != nullptr;
  std::fprintf(stderr, "%s: %s: %s\n", program, named ? "error" : "internal error", e.what());
  return refused ? kExitRefused : kExitFailed;
}

/// Runs `body` (int()) mapping what escapes like runMain (for a program that parses on its own).
template <class Body>
int runGuarded(const char* program, Body&& body) {
  try {
    return body();
  } catch (const std::exception& e) {
    return reportException(program, e);
  }
}

/// Runs `body` (int()) after parsing argc/argv into `app`; see the opening block.
template <class Body>
int runMain(const char* program, CLI::App& app, int argc, char** argv, Body&& body) {
  if (const int code = parseCommandLine(app, argc, argv); code >= 0) return code;
  return runGuarded(program, body);
}

}  // namespace reflex
