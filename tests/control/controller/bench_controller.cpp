// Controller benchmark (issue 4, item 15): one full cycle on the 21-DOF model (kinematics, every
// pair, both controllers, blend, safety filter, predictive guard) with p50/p99 from per-iteration
// timing, the same for cycles whose step the predictive guard shortens, the distance sweep alone as
// the in-process peer, and the simulation's real-time factor.
// Run: build/bin/bench_controller [--benchmark_repetitions=3]
#include "reflex/control/controller.hpp"
#include "reflex/control/scenarios.hpp"
#include "reflex/control/urdf_loader.hpp"

#include <benchmark/benchmark.h>

#include <algorithm>
#include <chrono>
#include <string>
#include <vector>

namespace {

using namespace reflex::control;

const std::string kUrdf = std::string(REFLEX_SOURCE_DIR) + "/bringup/robots/asimo_like.urdf";

const Model& model() {
  static const Model m = loadModel(kUrdf, loadCollisionConfig(defaultCollisionConfigPath(kUrdf)));
  return m;
}

const ControllerModel& cmodel() {
  static const ControllerModel cm = makeControllerModel(model(), defaultControllerConfig());
  return cm;
}

/// A recorded crossing-arms run: configurations where avoidance is active for both arms.
const std::vector<Eigen::VectorXd>& states() {
  static const std::vector<Eigen::VectorXd> qs = [] {
    const SimResult r = runScenario(model(), cmodel(), *findScenario("crossing_arms"));
    std::vector<Eigen::VectorXd> out;
    for (std::size_t k = 200; k < r.samples.size(); k += 3) out.push_back(r.samples[k].q);
    return out;
  }();
  return qs;
}

void reportPercentiles(benchmark::State& state, std::vector<double>& ns) {
  if (ns.empty()) return;
  std::sort(ns.begin(), ns.end());
  auto pct = [&](double p) { return ns[std::min(ns.size() - 1, static_cast<std::size_t>(p * ns.size()))]; };
  state.counters["p50_us"] = pct(0.50) / 1000.0;
  state.counters["p99_us"] = pct(0.99) / 1000.0;
  state.counters["max_us"] = ns.back() / 1000.0;
  state.counters["budget_ratio_p99"] = 5e6 / pct(0.99);  // the paper's 5 ms period / p99
}

void BM_ControllerCycle(benchmark::State& state) {
  ControllerModel cm = cmodel();
  cm.params.mode = static_cast<AvoidanceMode>(state.range(0));
  ControllerData data(model(), cm);
  ControlInput in;
  in.hands[kLeft] = {HandStatus::kGiven, Eigen::Vector3d(0.30, -0.08, 0.90)};
  in.hands[kRight] = {HandStatus::kGiven, Eigen::Vector3d(0.30, 0.08, 0.90)};
  const auto& qs = states();
  std::vector<double> ns;
  ns.reserve(1 << 20);
  std::size_t i = 0;
  for (auto _ : state) {
    const auto t0 = std::chrono::steady_clock::now();
    benchmark::DoNotOptimize(computeControl(model(), cm, data, qs[i], in));
    const auto t1 = std::chrono::steady_clock::now();
    if (ns.size() < ns.capacity()) ns.push_back(std::chrono::duration<double, std::nano>(t1 - t0).count());
    i = (i + 1) % qs.size();
  }
  reportPercentiles(state, ns);
}
BENCHMARK(BM_ControllerCycle)->Arg(static_cast<int>(AvoidanceMode::kOneDof))->Arg(static_cast<int>(AvoidanceMode::kThreeDof))
    ->ArgName("mode");

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
  const Eigen::Vector3d inside(0.02, 0.0, 0.95), across_l(0.30, -0.08, 0.90), across_r(0.30, 0.08, 0.90);
  const Eigen::Vector3d low_l(0.10, -0.05, 0.75), low_r(0.10, 0.05, 0.75);
  const Eigen::Vector3d phases[4][2] = {{across_l, across_r}, {inside, across_r}, {low_l, inside}, {across_l, low_r}};
  ControlInput in;
  std::vector<double> ns;
  ns.reserve(1 << 20);
  std::uint64_t k = 0, cycles = 0;
  for (auto _ : state) {
    for (int a = 0; a < 2; ++a) in.hands[a] = {HandStatus::kGiven, phases[(k / 80) % 4][a]};
    in.priority = static_cast<MotionPriority>((k / 120) % 3);
    const std::uint64_t before = data.guard_count;
    const auto t0 = std::chrono::steady_clock::now();
    benchmark::DoNotOptimize(computeControl(model(), cm, data, q, in));
    const auto t1 = std::chrono::steady_clock::now();
    if (data.guard_count != before && ns.size() < ns.capacity())
      ns.push_back(std::chrono::duration<double, std::nano>(t1 - t0).count());
    q += data.qdot * cm.params.period;
    ++cycles;
    if (++k == 1600) {  // start over from rest (a new run of the same 8 s)
      k = 0;
      q = q0;
    }
  }
  state.counters["guard_share"] = cycles ? static_cast<double>(ns.size()) / static_cast<double>(cycles) : 0.0;
  reportPercentiles(state, ns);
}
BENCHMARK(BM_ControllerCycleGuardActing);

/// Peer in the same process: forward kinematics + every checked pair with rows, nothing else.
void BM_KinematicsAndDistancesOnly(benchmark::State& state) {
  KinematicsData kin(model());
  DistanceData dist(model());
  DistanceOptions opt;
  opt.row_threshold = cmodel().params.d_safe;
  const auto& qs = states();
  std::size_t i = 0;
  for (auto _ : state) {
    computeForwardKinematics(model(), kin, qs[i]);
    computeSegmentDistances(model(), kin, dist, opt);
    benchmark::DoNotOptimize(dist.closest);
    i = (i + 1) % qs.size();
  }
}
BENCHMARK(BM_KinematicsAndDistancesOnly);

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

BENCHMARK_MAIN();
