// reflex_fit: fits capsules and spheres to a robot's collision meshes (and boxes) and writes the fit
// overlay `<urdf stem>.fit.yaml` (or -o FILE) that the loader reads. Never edits the URDF.
// See control/README.md, "Meshes".
#include "reflex/common/run_main.hpp"
#include "reflex/common/files.hpp"
#include "reflex/control/mesh_fit.hpp"
#include "package_args.hpp"
#include "reflex/control/urdf_loader.hpp"

#include <CLI/CLI.hpp>

#include <cerrno>
#include <cstdio>
#include <fstream>
#include <iostream>
#include <string>
#include <vector>

int main(int argc, char** argv) {
  CLI::App app{
      "reflex_fit: fit capsules and spheres enclosing every vertex of a robot's collision meshes "
      "and boxes; writes the fit overlay the loader reads (<urdf stem>.fit.yaml). Never edits the URDF."};
  std::string urdf_path, out_path;
  std::vector<std::string> package_args;
  reflex::control::FitOptions options;
  bool quiet = false;
  app.add_option("urdf", urdf_path, "URDF file whose mesh and box collision elements are fitted")->required();
  app.add_option("--package-path", package_args,
                 "NAME=DIR: where package://NAME/... meshes are (repeatable; then ROS_PACKAGE_PATH is searched)");
  app.add_option("-o,--output", out_path, "overlay file to write (default: <urdf stem>.fit.yaml next to the URDF)");
  app.add_option("--max-primitives", options.max_primitives, "most primitives per link")->check(CLI::Range(1, 16));
  app.add_option("--split-ratio", options.split_ratio,
                 "split a link while fitted volume / convex-hull volume is above this")
      ->check(reflex::FiniteRange(1.0, 100.0));
  app.add_option("--max-pieces", options.max_pieces,
                 "tight model: most convex pieces per link while a piece's gap is above --piece-gap")
      ->check(CLI::Range(1, 256));
  app.add_option("--piece-gap", options.piece_gap,
                 "tight model: a piece is cut while its surface stands off the mesh by more than this (m)")
      ->check(reflex::FiniteRange(0.0005, 0.1));
  app.add_flag("-q,--quiet", quiet, "no per-link progress lines");
  return reflex::runMain("reflex_fit", app, argc, argv, [&]() -> int {
    const reflex::control::PackagePaths paths = reflex::control::parsePackagePathArgs(package_args);
    if (out_path.empty()) out_path = reflex::control::defaultFitOverlayPath(urdf_path);
    if (const std::string why = reflex::common::replaceableFileProblem(out_path); !why.empty())
      throw reflex::Error(why);
    if (const std::string why = reflex::common::outputFileProblem(out_path); !why.empty())
      throw reflex::Error("output " + why);
    const auto overlay = reflex::control::fitRobot(urdf_path, paths, options, [&](const std::string& line) {
      if (!quiet) std::cerr << line << std::endl;
    });
    if (overlay.links.empty())
      std::cerr << urdf_path << ": no link has mesh or box collision elements; the overlay lists none" << std::endl;
    const std::string text = reflex::control::fitOverlayText(overlay, out_path);
    if (const std::string why = reflex::common::writeFileReplacing(out_path, text); !why.empty())
      throw reflex::Error(why);
    // Summary: one line per link.
    std::cout << "# link,primitives,vertices_enclosed,vertices,volume_ratio,worst_gap_m\n";
    for (const auto& l : overlay.links) {
      char buf[64];
      std::snprintf(buf, sizeof buf, "%.3f,%.4f", l.stats.volume_ratio, l.stats.worst_gap);
      std::cout << l.link << "," << l.primitives.size() << "," << l.stats.vertices_enclosed << "," << l.stats.vertices
                << "," << buf << "\n";
    }
    std::cout << "# wrote " << out_path << std::endl;
    return 0;
  });
}
