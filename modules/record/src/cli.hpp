// Command-line front ends of reflex_record and reflex_play (shared by both executables).
#pragma once

#include <CLI/CLI.hpp>

#include <memory>

namespace reflex::record::cli {

/// Adds the "play" options to `app` (a subcommand or the whole reflex_play app) and returns the
/// function that runs it after parsing (exit code).
std::function<int()> addPlay(CLI::App& app);
std::function<int()> addRecord(CLI::App& app);
std::function<int()> addExport(CLI::App& app);
std::function<int()> addInfo(CLI::App& app);
std::function<int()> addConvert(CLI::App& app);

}  // namespace reflex::record::cli
