// bench_soak: runs simulated hours of random reactive episodes (soak.hpp) and reports the closest
// approach of any physical pair. Exit 0 if no episode violated safety (below d_r, e-stop,
// non-finite, velocity limit), 1 if one did (its seed is printed: rerun it with --seed S --hours
// <one episode>), 2 for bad arguments. SIGINT / SIGTERM or --wall-limit stop early with a report.
#include "soak.hpp"

#include "reflex/control/urdf_loader.hpp"

#include <CLI/CLI.hpp>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <mutex>
#include <thread>
#include <vector>

namespace {

std::atomic<bool> g_stop{false};
extern "C" void onSignal(int) { g_stop = true; }

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{
      "bench_soak: simulated hours of random reactive targets for the reflex controller; reports the\n"
      "closest approach of any pair and fails on any pair below d_r, e-stop, NaN or velocity-limit breach."};
  double hours = 0.0, episode = 10.0, progress = 10.0, wall_limit = 0.0;
  std::uint64_t first_seed = 1;
  int threads = 1;
  std::string urdf = REFLEX_SOURCE_DIR "/bringup/robots/asimo_like.urdf", collision, controller;
  app.add_option("--hours", hours, "simulated hours to run")->required()->check(CLI::PositiveNumber);
  app.add_option("--episode", episode, "simulated seconds per episode")
      ->capture_default_str()
      ->check(CLI::Range(0.5, 3600.0));
  app.add_option("--seed", first_seed, "seed of the first episode (episode k uses seed + k)")->capture_default_str();
  app.add_option("--threads", threads, "worker threads")->capture_default_str()->check(CLI::Range(1, 64));
  app.add_option("--progress", progress, "wall seconds between progress lines (0: none)")
      ->capture_default_str()
      ->check(CLI::NonNegativeNumber);
  app.add_option("--wall-limit", wall_limit, "stop after this many wall seconds (0: none) and report what was reached")
      ->capture_default_str()
      ->check(CLI::NonNegativeNumber);
  app.add_option("--urdf", urdf, "robot URDF")->capture_default_str();
  app.add_option("--collision", collision, "collision configuration (default: next to the URDF)");
  app.add_option(
      "--controller", controller,
      "controller configuration (default: <URDF stem>.controller.yaml beside the URDF if it exists, else built-in)");
  CLI11_PARSE(app, argc, argv);

  using namespace reflex::control;
  Model model;
  ControllerModel cm;
  try {
    const std::string coll = collision.empty() ? defaultCollisionConfigPath(urdf) : collision;
    model = loadModel(urdf, loadCollisionConfig(coll));
    const ControllerConfig config = loadControllerConfigFor(urdf, controller);
    cm = makeControllerModel(model, config);
    std::fprintf(stderr, "bench_soak: %s\n", describeControllerConfig(config, urdf).c_str());
  } catch (const std::exception& e) {
    std::fprintf(stderr, "bench_soak: error: %s\n", e.what());
    return 2;
  }
  std::signal(SIGINT, onSignal);
  std::signal(SIGTERM, onSignal);

  const auto episodes_total = static_cast<std::uint64_t>(std::ceil(hours * 3600.0 / episode));
  std::atomic<std::uint64_t> next{0};
  std::mutex mutex;
  std::uint64_t done = 0, cycles = 0, violations = 0;
  reflex::soak::EpisodeOutcome worst;
  worst.min_distance = 1e9;
  std::vector<reflex::soak::EpisodeOutcome> bad;
  const auto t0 = std::chrono::steady_clock::now();
  auto wall = [&] { return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(); };

  auto worker = [&] {
    for (;;) {
      if (g_stop || (wall_limit > 0.0 && wall() >= wall_limit)) return;
      const std::uint64_t k = next.fetch_add(1);
      if (k >= episodes_total) return;
      const reflex::soak::EpisodeOutcome o = reflex::soak::runEpisode(model, cm, first_seed + k, episode);
      std::lock_guard<std::mutex> lock(mutex);
      ++done;
      cycles += o.cycles;
      if (o.min_distance < worst.min_distance) worst = o;
      if (o.violation) {
        ++violations;
        if (bad.size() < 20) bad.push_back(o);
        std::fprintf(stderr, "bench_soak: VIOLATION in episode seed %llu: %s(closest %.2f mm, pair %d, t = %.3f s)\n",
                     static_cast<unsigned long long>(o.seed), o.why.c_str(), o.min_distance * 1000.0, o.min_pair,
                     o.min_time);
      }
    }
  };
  auto report = [&](const char* what) {
    std::lock_guard<std::mutex> lock(mutex);
    const double sim_h = static_cast<double>(done) * episode / 3600.0;
    const double w = wall();
    std::printf(
        "bench_soak: %s %.3f of %.3f simulated hours, %llu episodes, %llu cycles, wall %.0f s (x%.1f real time), "
        "closest approach %.2f mm (seed %llu, pair %d), violations %llu\n",
        what, sim_h, hours, static_cast<unsigned long long>(done), static_cast<unsigned long long>(cycles), w,
        w > 0.0 ? sim_h * 3600.0 / w : 0.0, worst.min_distance * 1000.0, static_cast<unsigned long long>(worst.seed),
        worst.min_pair, static_cast<unsigned long long>(violations));
    std::fflush(stdout);
  };

  std::vector<std::thread> pool;
  for (int i = 0; i < threads; ++i) pool.emplace_back(worker);
  double last = 0.0;
  for (;;) {
    std::this_thread::sleep_for(std::chrono::milliseconds(200));
    bool finished;
    {
      std::lock_guard<std::mutex> lock(mutex);
      finished = next.load() >= episodes_total && done >= std::min<std::uint64_t>(episodes_total, next.load());
    }
    if (finished || g_stop || (wall_limit > 0.0 && wall() >= wall_limit)) break;
    if (progress > 0.0 && wall() - last >= progress) {
      last = wall();
      report("progress:");
    }
  }
  for (auto& t : pool) t.join();
  report(done >= episodes_total ? "done:" : "stopped early:");
  if (violations > 0) {
    std::fprintf(
        stderr, "bench_soak: %llu episodes violated safety; first seeds:", static_cast<unsigned long long>(violations));
    for (const auto& o : bad) std::fprintf(stderr, " %llu", static_cast<unsigned long long>(o.seed));
    std::fprintf(stderr, "\n");
    return 1;
  }
  return 0;
}
