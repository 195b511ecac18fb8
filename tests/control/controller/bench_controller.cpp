// Controller benchmark: one full cycle on the 21-DOF model (kinematics, every
// pair, both controllers, blend, safety filter, predictive guard) with p50/p99 from per-iteration
// timing, the same for cycles whose step the predictive guard shortens, both again as the fastest of
// 15 runs per state (the code's cost without the machine's jitter), the distance sweep alone as the
// in-process peer, and the simulation's real-time factor. The full cycle also says which of its
// cycles the machine interrupted (interrupted_share, p99_uninterrupted_us; see BM_MachineInterruptions).
// Run: build/bin/bench_controller [--robot=NAME|PATH.urdf] [--config=YAML] [--benchmark_repetitions=3]
// --robot: a robot of bringup/robots by name (asimo_like, the default; many_segment_humanoid, the
// >= 1,000-pair robot) or a URDF path, with its default collision configuration; --config: its
// controller YAML (default: the built-in configuration, whose arm joint and hand names are
// asimo_like's). Every benchmark prints `pairs` (checked pairs of the robot).
#include "reflex/control/controller.hpp"
#include "reflex/control/scenarios.hpp"
#include "reflex/control/urdf_loader.hpp"
#include "../bench_support.hpp"

#include <benchmark/benchmark.h>

#include <algorithm>
#include <chrono>
#include <cstdint>
#include <ctime>
#include <cstdio>
#include <map>
#include <string>
#include <vector>

namespace {

using namespace reflex::control;

std::string g_urdf = bench::robotUrdf("asimo_like");
std::string g_config;  // controller YAML; empty: defaultControllerConfig()

const Model& model() {
  static const Model m = loadModel(g_urdf, loadCollisionConfig(bench::collisionPathFor(g_urdf)));
  return m;
}

const ControllerModel& cmodel() {
  static const ControllerModel cm =
      makeControllerModel(model(), g_config.empty() ? defaultControllerConfig() : loadControllerConfig(g_config));
  return cm;
}

/// A target of the reference robot's coordinates (asimo_like's base frame) on the robot benchmarked:
/// about its own chest, scaled by its arms and trunk (ScenarioFrame::place; the identity on asimo_like),
/// so that the crossing and guard-acting targets cross and enter this robot's body too.
Eigen::Vector3d placed(double x, double y, double z) {
  static const ScenarioFrame frame = scenarioFrame(model(), cmodel());
  return frame.place(Eigen::Vector3d(x, y, z));
}

/// Both hands crossed in front of the chest (the crossing-arms states' targets).
ControlInput crossingInput() {
  ControlInput in;
  in.hands[kLeft] = {HandStatus::kGiven, placed(0.30, -0.08, 0.90)};
  in.hands[kRight] = {HandStatus::kGiven, placed(0.30, 0.08, 0.90)};
  return in;
}

void countPairs(benchmark::State& state) { state.counters["pairs"] = static_cast<double>(model().pairs.size()); }

/// A recorded crossing-arms run from its 200th cycle on, every `stride`-th cycle: configurations where
/// avoidance is active for both arms. Stride 1 is the controller's own sequence (one 5 ms cycle apart);
/// stride 3, the benchmarks' usual set, moves three cycles' worth between calls (less of what the
/// distance computation carries from one call to the next stays valid).
const std::vector<Eigen::VectorXd>& states(int stride = 3) {
  static const SimResult run = runScenario(model(), cmodel(), *findScenario("crossing_arms"));
  static std::map<int, std::vector<Eigen::VectorXd>> sets;
  std::vector<Eigen::VectorXd>& out = sets[stride];
  if (out.empty())
    for (std::size_t k = 200; k < run.samples.size(); k += static_cast<std::size_t>(stride))
      out.push_back(run.samples[k].q);
  return out;
}

/// This thread's CPU time (ns): on a shared machine a cycle's wall time includes the time other
/// processes held the core; its CPU time is what the cycle cost.
double threadCpuNs() {
  timespec t{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t);
  return 1e9 * static_cast<double>(t.tv_sec) + static_cast<double>(t.tv_nsec);
}

/// Per-cycle wall time (steady clock) and CPU time of one computeControl call, both in ns.
struct CycleTimes {
  std::vector<double> wall, cpu;
  CycleTimes() {
    wall.reserve(1 << 20);
    cpu.reserve(1 << 20);
  }
  /// Runs f, timed; keeps the times if keep(), evaluated after f.
  template <class F, class K>
  void time(F&& f, K&& keep) {
    const double c0 = threadCpuNs();
    const auto t0 = std::chrono::steady_clock::now();
    f();
    const auto t1 = std::chrono::steady_clock::now();
    const double c1 = threadCpuNs();
    if (keep() && wall.size() < wall.capacity()) {
      wall.push_back(std::chrono::duration<double, std::nano>(t1 - t0).count());
      cpu.push_back(c1 - c0);
    }
  }
};

double percentile(std::vector<double>& ns, double p) {
  return ns[std::min(ns.size() - 1, static_cast<std::size_t>(p * static_cast<double>(ns.size())))];
}

/// p50 / p99 / max of the wall times (p50_us, p99_us, max_us, budget_ratio_p99 = 5 ms / p99) and of
/// the CPU times (cpu_p50_us, cpu_p99_us).
void reportPercentiles(benchmark::State& state, CycleTimes& times) {
  countPairs(state);
  if (times.wall.empty()) return;
  std::sort(times.wall.begin(), times.wall.end());
  std::sort(times.cpu.begin(), times.cpu.end());
  state.counters["p50_us"] = percentile(times.wall, 0.50) / 1000.0;
  state.counters["p99_us"] = percentile(times.wall, 0.99) / 1000.0;
  state.counters["max_us"] = times.wall.back() / 1000.0;
  state.counters["budget_ratio_p99"] = 5e6 / percentile(times.wall, 0.99);  // the paper's 5 ms period / p99
  state.counters["cpu_p50_us"] = percentile(times.cpu, 0.50) / 1000.0;
  state.counters["cpu_p99_us"] = percentile(times.cpu, 0.99) / 1000.0;
}

/// The machine's share of BM_ControllerCycle's wall p99, from the same cycles: each state comes back
/// every states().size() cycles, so its fastest wall time over the run is what it costs; a cycle more
/// than kInterruptedUs above that was hit by an interruption (BM_MachineInterruptions: 38-45 us each
/// on this VM; the cycles' own spread is a few us). Counters: interrupted_share (of all cycles) and
/// p99_uninterrupted_us (the wall p99 of the others).
void reportInterruptions(benchmark::State& state, const std::vector<double>& wall,
                         const std::vector<std::uint32_t>& state_of, std::size_t num_states) {
  constexpr double kInterruptedUs = 15.0;
  if (wall.empty()) return;
  std::vector<double> fastest(num_states, 1e30);
  for (std::size_t k = 0; k < wall.size(); ++k) fastest[state_of[k]] = std::min(fastest[state_of[k]], wall[k]);
  std::vector<double> clean;
  clean.reserve(wall.size());
  for (std::size_t k = 0; k < wall.size(); ++k)
    if (wall[k] - fastest[state_of[k]] <= kInterruptedUs * 1000.0) clean.push_back(wall[k]);
  state.counters["interrupted_share"] = 1.0 - static_cast<double>(clean.size()) / static_cast<double>(wall.size());
  std::sort(clean.begin(), clean.end());
  if (!clean.empty()) state.counters["p99_uninterrupted_us"] = percentile(clean, 0.99) / 1000.0;
}

void BM_ControllerCycle(benchmark::State& state) {
  ControllerModel cm = cmodel();
  cm.params.mode = static_cast<AvoidanceMode>(state.range(0));
  ControllerData data(model(), cm);
  const ControlInput in = crossingInput();
  const auto& qs = states(static_cast<int>(state.range(1)));
  CycleTimes times;
  std::vector<std::uint32_t> state_of;  // per kept cycle, its state
  state_of.reserve(times.wall.capacity());
  std::size_t i = 0;
  std::uint64_t cycles = 0, guard_pairs = 0;
  const std::uint64_t guard_before = data.guard_count;
  for (auto _ : state) {
    times.time([&] { benchmark::DoNotOptimize(computeControl(model(), cm, data, qs[i], in)); }, [] { return true; });
    if (state_of.size() < times.wall.size()) state_of.push_back(static_cast<std::uint32_t>(i));
    i = (i + 1) % qs.size();
    ++cycles;
    guard_pairs += static_cast<std::uint64_t>(data.num_guard_pairs);
  }
  // How often the predictive guard shortened a step, and how many pairs it predicted per cycle.
  if (cycles > 0) {
    state.counters["guard_share"] = static_cast<double>(data.guard_count - guard_before) / static_cast<double>(cycles);
    state.counters["guard_pairs"] = static_cast<double>(guard_pairs) / static_cast<double>(cycles);
  }
  reportInterruptions(state, times.wall, state_of, qs.size());  // before reportPercentiles sorts the times
  reportPercentiles(state, times);
}
// states:3 the usual set (every third recorded cycle), states:1 every recorded cycle in turn.
BENCHMARK(BM_ControllerCycle)
    ->Args({static_cast<int>(AvoidanceMode::kOneDof), 3})
    ->Args({static_cast<int>(AvoidanceMode::kThreeDof), 3})
    ->Args({static_cast<int>(AvoidanceMode::kOneDof), 1})
    ->ArgNames({"mode", "states"});

/// The guard-acting loop's input at cycle k: targets jump every 0.4 s between crossing, into the
/// chest and low across; the priority flips every 0.6 s.
ControlInput guardActingInput(std::uint64_t k) {
  static const Eigen::Vector3d inside = placed(0.02, 0.0, 0.95), across_l = placed(0.30, -0.08, 0.90),
                               across_r = placed(0.30, 0.08, 0.90);
  static const Eigen::Vector3d low_l = placed(0.10, -0.05, 0.75), low_r = placed(0.10, 0.05, 0.75);
  const Eigen::Vector3d phases[4][2] = {{across_l, across_r}, {inside, across_r}, {low_l, inside}, {across_l, low_r}};
  ControlInput in;
  for (int a = 0; a < 2; ++a) in.hands[a] = {HandStatus::kGiven, phases[(k / 80) % 4][a]};
  in.priority = static_cast<MotionPriority>((k / 120) % 3);
  return in;
}

/// Cycles where the predictive guard acts: a closed loop (kinematic robot) whose targets jump every
/// 0.4 s between crossing, into the chest and low across, with the priority flipping, and the
/// first-order filter's floor at d_r (guard_margin 0) so the guard must shorten steps. Percentiles
/// over the cycles whose step the guard shortened (counter guard_share: their fraction).
void BM_ControllerCycleGuardActing(benchmark::State& state) {
  ControllerModel cm = cmodel();
  cm.params.guard_margin = 0.0;
  ControllerData data(model(), cm);
  const Eigen::VectorXd q0 = restConfiguration(model(), cm);
  Eigen::VectorXd q = q0;
  CycleTimes acting;
  std::uint64_t k = 0, cycles = 0;
  for (auto _ : state) {
    const ControlInput in = guardActingInput(k);
    const std::uint64_t before = data.guard_count;
    // Keep only the cycles whose step the guard shortened.
    acting.time([&] { benchmark::DoNotOptimize(computeControl(model(), cm, data, q, in)); },
                [&] { return data.guard_count != before; });
    q += data.qdot * cm.params.period;
    ++cycles;
    if (++k == 1600) {  // start over from rest (a new run of the same 8 s)
      k = 0;
      q = q0;
    }
  }
  state.counters["guard_share"] = cycles ? static_cast<double>(acting.wall.size()) / static_cast<double>(cycles) : 0.0;
  reportPercentiles(state, acting);
}
BENCHMARK(BM_ControllerCycleGuardActing);

/// The cycle's cost without the machine's jitter: every state's cycle timed kRepeats times (thread
/// CPU clock) from the same ControllerData (restored by copy before each run, outside the timing),
/// its fastest run kept; percentiles over the states (state_p50_us, state_p99_us, state_max_us).
/// set:0 the crossing_arms states of BM_ControllerCycle; set:1 the cycles of
/// BM_ControllerCycleGuardActing's loop whose step the guard shortens (first 1,600 cycles).
void BM_ControllerCycleFastestPerState(benchmark::State& state) {
  constexpr int kRepeats = 15;
  ControllerModel cm = cmodel();
  const bool guard = state.range(0) != 0;
  if (guard) cm.params.guard_margin = 0.0;
  std::vector<double> fastest;
  for (auto _ : state) {
    fastest.clear();
    ControllerData data(model(), cm), run(model(), cm);
    auto timeState = [&](const Eigen::VectorXd& q, const ControlInput& in) {
      double best = 1e30;
      for (int r = 0; r < kRepeats; ++r) {
        run = data;  // the same starting state each time (same sizes: no allocation inside)
        const double c0 = threadCpuNs();
        benchmark::DoNotOptimize(computeControl(model(), cm, run, q, in));
        best = std::min(best, threadCpuNs() - c0);
      }
      fastest.push_back(best);
    };
    if (!guard) {
      const ControlInput in = crossingInput();
      for (const Eigen::VectorXd& q : states()) {
        timeState(q, in);
        computeControl(model(), cm, data, q, in);  // advance as BM_ControllerCycle does
      }
    } else {
      Eigen::VectorXd q = restConfiguration(model(), cm);
      for (std::uint64_t k = 0; k < 1600; ++k) {
        const ControlInput in = guardActingInput(k);
        const std::uint64_t before = data.guard_count;
        run = data;
        computeControl(model(), cm, run, q, in);
        if (run.guard_count != before) timeState(q, in);
        computeControl(model(), cm, data, q, in);
        q += data.qdot * cm.params.period;
      }
    }
  }
  countPairs(state);
  if (fastest.empty()) return;
  std::sort(fastest.begin(), fastest.end());
  state.counters["states"] = static_cast<double>(fastest.size());
  state.counters["state_p50_us"] = percentile(fastest, 0.50) / 1000.0;
  state.counters["state_p99_us"] = percentile(fastest, 0.99) / 1000.0;
  state.counters["state_max_us"] = fastest.back() / 1000.0;
}
BENCHMARK(BM_ControllerCycleFastestPerState)
    ->ArgName("set")
    ->Arg(0)
    ->Arg(1)
    ->Iterations(1)
    ->Unit(benchmark::kMillisecond);

/// The machine's own interruptions, the peer of every p99 above: one second of reading the steady
/// clock in a loop; a step of more than 3 us between two reads is time the thread did not run
/// (interrupts, the hypervisor). A cycle of T us is hit by one with probability about
/// T * gaps_per_s / 1e6, and then takes T + gap_median_us: once that exceeds 1 %, the cycle's p99 is
/// about T + gap_median_us, whatever the code does.
void BM_MachineInterruptions(benchmark::State& state) {
  std::vector<double> gaps;
  gaps.reserve(1 << 20);
  double seconds = 0.0;
  for (auto _ : state) {
    gaps.clear();
    using Clock = std::chrono::steady_clock;
    const auto start = Clock::now();
    auto previous = start;
    while (previous - start < std::chrono::seconds(1)) {
      const auto now = Clock::now();
      const double gap_us = std::chrono::duration<double, std::micro>(now - previous).count();
      if (gap_us > 3.0 && gaps.size() < gaps.capacity()) gaps.push_back(gap_us);
      previous = now;
    }
    seconds = std::chrono::duration<double>(previous - start).count();
  }
  std::sort(gaps.begin(), gaps.end());
  double stolen = 0.0;
  for (const double g : gaps) stolen += g;
  state.counters["gaps_per_s"] = static_cast<double>(gaps.size()) / seconds;
  state.counters["gap_median_us"] = gaps.empty() ? 0.0 : percentile(gaps, 0.5);
  state.counters["gap_p90_us"] = gaps.empty() ? 0.0 : percentile(gaps, 0.9);
  state.counters["stolen_share"] = stolen * 1e-6 / seconds;
}
BENCHMARK(BM_MachineInterruptions)->Iterations(1)->Unit(benchmark::kMillisecond);

/// Peer in the same process: forward kinematics + every checked pair with rows, nothing else, with
/// the cycle's broad phase (prune:1, pairs beyond d_safe skipped) and without it (prune:0).
void BM_KinematicsAndDistancesOnly(benchmark::State& state) {
  KinematicsData kin(model());
  DistanceData dist(model());
  DistanceOptions opt;
  opt.row_threshold = cmodel().params.d_safe;
  if (state.range(0) != 0) opt.prune_distance = opt.row_threshold;
  countPairs(state);
  const auto& qs = states();
  std::size_t i = 0;
  double searches = 0.0, exact = 0.0, calls = 0.0;
  for (auto _ : state) {
    computeForwardKinematics(model(), kin, qs[i]);
    computeSegmentDistances(model(), kin, dist, opt);
    benchmark::DoNotOptimize(dist.closest);
    searches += dist.num_piece_searches;
    exact += dist.num_exact_pairs;
    calls += 1.0;
    i = (i + 1) % qs.size();
  }
  state.counters["piece_searches"] = calls > 0.0 ? searches / calls : 0.0;  // per call
  state.counters["exact_pairs"] = calls > 0.0 ? exact / calls : 0.0;
}
BENCHMARK(BM_KinematicsAndDistancesOnly)->ArgName("prune")->Arg(1)->Arg(0);

/// The kinematic simulation of a whole scenario; real-time factor = simulated time / wall time.
void BM_SimulationRealTimeFactor(benchmark::State& state) {
  const Scenario& sc = *findScenario("crossing_arms");
  SimOptions opt;
  opt.record = false;
  double simulated = 0.0, wall = 0.0;
  for (auto _ : state) {
    const auto t0 = std::chrono::steady_clock::now();
    const SimResult r = runScenario(model(), cmodel(), sc, opt);
    wall += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    simulated += static_cast<double>(r.cycles) * cmodel().params.period;
  }
  state.counters["realtime_factor"] = simulated / wall;
}
BENCHMARK(BM_SimulationRealTimeFactor)->Unit(benchmark::kMillisecond);

}  // namespace

int main(int argc, char** argv) {
  return reflex::control::bench::benchMain(
      argc, argv, "bench_controller",
      "bench_controller [--robot=NAME|PATH.urdf] [--config=YAML] [benchmark options]\n"
      "  --robot   a robot of bringup/robots by name (default asimo_like; many_segment_humanoid:\n"
      "            the >= 1,000-pair robot) or a URDF path; collision configuration next to it\n"
      "  --collision  its collision YAML instead (e.g. what reflex_setup wrote, with the fit)\n"
      "  --config  controller YAML for that robot (default: the built-in asimo_like arms)\n",
      &g_urdf, &g_config, [] {
        std::printf("robot: %s, %zu checked pairs, %zu states, %s sweep kernel\n", g_urdf.c_str(), model().pairs.size(),
                    states().size(), fastestSweepKernel() == SweepKernel::kAvx2 ? "AVX2" : "scalar");
      });
}
