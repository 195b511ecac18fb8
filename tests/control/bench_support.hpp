// Shared main() of the control benchmarks (bench_distance, bench_controller): the robot option, then
// Google Benchmark. Not a test; the benchmarks are run by hand (control/README.md, "Speed").
#pragma once

#include "reflex/control/urdf_loader.hpp"

#include <benchmark/benchmark.h>

#include <cstdio>
#include <exception>
#include <functional>
#include <string>

namespace reflex::control::bench {

/// A robot of bringup/robots by name ("asimo_like") or a path ending in .urdf, as a URDF path.
inline std::string robotUrdf(const std::string& name_or_path) {
  if (name_or_path.size() > 5 && name_or_path.compare(name_or_path.size() - 5, 5, ".urdf") == 0) return name_or_path;
  return std::string(REFLEX_SOURCE_DIR) + "/bringup/robots/" + name_or_path + ".urdf";
}

/// The collision configuration a benchmark loads its robot with: --collision=YAML, else the one next
/// to the URDF (defaultCollisionConfigPath), so a robot set up by reflex_setup into another folder
/// (with its fit) is measured as the controller runs it.
inline std::string& collisionOption() {
  static std::string path;
  return path;
}
inline std::string collisionPathFor(const std::string& urdf) {
  return collisionOption().empty() ? reflex::control::defaultCollisionConfigPath(urdf) : collisionOption();
}

/// Takes --robot=NAME|PATH.urdf into *urdf, --collision=YAML (collisionOption()) and, if config is
/// not null, --config=YAML into *config;
/// --help prints `usage` and Google Benchmark's options. Then `announce` (loads the robot, prints what
/// is measured; an exception there is a clear error, exit 2) and every benchmark. Returns the exit code.
inline int benchMain(int argc, char** argv, const char* program, const char* usage, std::string* urdf,
                     std::string* config, const std::function<void()>& announce) {
  int kept = 1;
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    if (arg == "--help" || arg == "-h") {
      std::printf("%s", usage);
      benchmark::PrintDefaultHelp();
      return 0;
    }
    const bool robot = arg.rfind("--robot=", 0) == 0;
    const bool yaml = config != nullptr && arg.rfind("--config=", 0) == 0;
    const bool collision = arg.rfind("--collision=", 0) == 0;
    if (!robot && !yaml && !collision) {
      argv[kept++] = argv[i];
      continue;
    }
    const std::string value = arg.substr(arg.find('=') + 1);
    if (value.empty()) {
      std::fprintf(stderr, "%s: %s needs a value (see --help)\n", program,
                   robot       ? "--robot"
                   : collision ? "--collision"
                               : "--config");
      return 2;
    }
    if (robot)
      *urdf = robotUrdf(value);
    else if (collision)
      collisionOption() = value;
    else
      *config = value;
  }
  argc = kept;
  try {
    announce();
  } catch (const std::exception& e) {
    std::fprintf(stderr, "%s: %s\n", program, e.what());
    return 2;
  }
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 2;
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}

}  // namespace reflex::control::bench
