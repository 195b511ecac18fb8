// The one error type of Reflex and the exit codes of its programs.
//
// Every error a layer throws for something the user can fix (a bad argument, file, configuration,
// robot description, or a resource that cannot be set up: a port in use, a profile that does not
// exist) is a reflex::Error: its message names the bad value and where it came from. The layers
// keep their own types (control::ModelError, bus::BusError, vision::VisionError, ...) so a caller
// can tell them apart; all of them derive from reflex::Error, so a program catches one type.
//
// Exit codes, the same in every program (runMain in run_main.hpp maps them):
//   0  done
//   1  ran and failed: the run's own outcome (a check failed, the credentials expired; a
//      reflex::Failure) or an unexpected internal error (a bug: please report it)
//   2  refused: a bad command-line argument, or a reflex::Error (a bad file, configuration, robot
//      description, or a set-up failure), with one line naming the bad value
//   3..9  program-specific outcomes, listed in the program's --help and docs/tools.md
#pragma once

#include <stdexcept>
#include <string>

namespace reflex {

inline constexpr int kExitOk = 0;
inline constexpr int kExitFailed = 1;
inline constexpr int kExitRefused = 2;

class Error : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

/// A run that started and failed on its own terms, with a message naming why (exit 1, not 2): a
/// player whose topics found no reader within its wait, say. Not a reflex::Error: nothing given was bad.
class Failure : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

namespace common {
/// A configuration file's error (the YAML reader's default; control::ConfigError and
/// modules::ConfigError are this type).
class ConfigError : public Error {
 public:
  using Error::Error;
};
}  // namespace common

}  // namespace reflex
