// Benchmark (run by hand, not a CTest): stereo 640x480 detect + triangulate pairs/s
// of the full pipeline, against libapriltag's bare detector (C API, no wrapper) on the same frames in
// the same process, and the ratio. Frames: a generated session with two tags, a textured background
// and a person (decoded to memory first, so video decoding is not measured).
//   build-*/bin/vision_benchmark [--benchmark_min_time=2]
#include "reflex/vision/stereo_pipeline.hpp"
#include "vision_test_util.hpp"

#include <apriltag/apriltag.h>
#include <apriltag/tag36h11.h>
#include <benchmark/benchmark.h>
#include <opencv2/imgproc.hpp>

#include <future>
#include <iostream>
#include <map>

using namespace reflex::vision;
using namespace reflex::vision::test;

namespace {

struct Frames {
  std::vector<cv::Mat> left, right, left_gray, right_gray;
  StereoCalibration calib;
  ObjectMap objects;
  CameraMount mount;
};

const Frames& frames() {
  static const Frames f = [] {
    Frames out;
    TempDir dir("bench");
    makeSession(parseSceneScript(nearScript(3.0), "near"), dir / "s");
    SessionReader reader(dir / "s");
    out.calib = reader.info().calibration;
    out.objects = reader.info().objects;
    out.mount = reader.info().mount.value();
    StereoFrame fr;
    std::string msg;
    while (reader.read(fr, msg) == ReadStatus::kOk) {
      out.left.push_back(fr.left.clone());
      out.right.push_back(fr.right.clone());
      cv::Mat gl, gr;
      cv::cvtColor(fr.left, gl, cv::COLOR_BGR2GRAY);
      cv::cvtColor(fr.right, gr, cv::COLOR_BGR2GRAY);
      out.left_gray.push_back(gl);
      out.right_gray.push_back(gr);
    }
    return out;
  }();
  return f;
}

void pipelineBench(benchmark::State& state, RectifyMode mode, bool parallel, double decimate, bool refine = true) {
  const Frames& f = frames();
  PipelineOptions o;
  o.rectify = mode;
  o.parallel = parallel;
  o.detector.decimate = decimate;
  o.refine_with_tag_size = refine;
  StereoTagPipeline p(f.calib, f.mount, f.objects, o);
  StereoResult r;
  std::size_t i = 0, found = 0;
  for (auto _ : state) {
    p.process(f.left[i], f.right[i], r);
    found += r.objects.size();
    i = (i + 1) % f.left.size();
  }
  state.counters["pairs_per_s"] =
      benchmark::Counter(static_cast<double>(state.iterations()), benchmark::Counter::kIsRate);
  state.counters["objects_per_pair"] = static_cast<double>(found) / static_cast<double>(state.iterations());
}

// libapriltag alone: both gray images of the pair, one detector per image, each with one thread;
// `parallel` detects the right image on a second thread (the pipeline's own parallelism). Not
// libapriltag's worker pool (nthreads > 1): before libapriltag 3.4.3 it can crash when its threads
// start (tag_detector.hpp, apriltag_pool_race.cpp) -- this benchmark once crashed here, where
// every benchmark call started a new two-thread pool.
void bareBench(benchmark::State& state, bool parallel, double decimate) {
  const Frames& f = frames();
  apriltag_family_t* fam[2] = {tag36h11_create(), tag36h11_create()};
  apriltag_detector_t* td[2];
  for (int k = 0; k < 2; ++k) {
    td[k] = apriltag_detector_create();
    apriltag_detector_add_family_bits(td[k], fam[k], 2);
    td[k]->nthreads = 1;
    td[k]->quad_decimate = static_cast<float>(decimate);
  }
  auto detect = [&](int k, const cv::Mat& g) {
    image_u8_t im{g.cols, g.rows, static_cast<int32_t>(g.step[0]), g.data};
    zarray_t* d = apriltag_detector_detect(td[k], &im);
    const int n = zarray_size(d);
    apriltag_detections_destroy(d);
    return static_cast<std::size_t>(n);
  };
  std::size_t i = 0, found = 0;
  for (auto _ : state) {
    if (parallel) {
      auto right = std::async(std::launch::async, [&] { return detect(1, f.right_gray[i]); });
      found += detect(0, f.left_gray[i]);
      found += right.get();
    } else {
      found += detect(0, f.left_gray[i]) + detect(1, f.right_gray[i]);
    }
    i = (i + 1) % f.left.size();
  }
  for (int k = 0; k < 2; ++k) {
    apriltag_detector_destroy(td[k]);  // before its family (the detector's decode table lives in it)
    tag36h11_destroy(fam[k]);
  }
  state.counters["pairs_per_s"] =
      benchmark::Counter(static_cast<double>(state.iterations()), benchmark::Counter::kIsRate);
  state.counters["tags_per_pair"] = static_cast<double>(found) / static_cast<double>(state.iterations());
}

// Collects the per-iteration real time of every run to print the ratios at the end.
class RatioReporter : public benchmark::ConsoleReporter {
 public:
  void ReportRuns(const std::vector<Run>& runs) override {
    for (const Run& r : runs)
      if (r.run_type == Run::RT_Iteration && r.iterations > 0)
        seconds_per_pair[r.benchmark_name()] = r.real_accumulated_time / static_cast<double>(r.iterations);
    ConsoleReporter::ReportRuns(runs);
  }
  std::map<std::string, double> seconds_per_pair;
};

}  // namespace

BENCHMARK_CAPTURE(pipelineBench, pipeline_images_parallel_d1, RectifyMode::kImages, true, 1.0)->UseRealTime();
BENCHMARK_CAPTURE(pipelineBench, pipeline_points_parallel_d1, RectifyMode::kPoints, true, 1.0)->UseRealTime();
BENCHMARK_CAPTURE(pipelineBench, pipeline_images_serial_d1, RectifyMode::kImages, false, 1.0)->UseRealTime();
BENCHMARK_CAPTURE(bareBench, bare_apriltag_leftright_parallel_d1, true, 1.0)->UseRealTime();
BENCHMARK_CAPTURE(bareBench, bare_apriltag_serial_d1, false, 1.0)->UseRealTime();
BENCHMARK_CAPTURE(pipelineBench, pipeline_images_parallel_d2, RectifyMode::kImages, true, 2.0)->UseRealTime();
BENCHMARK_CAPTURE(bareBench, bare_apriltag_leftright_parallel_d2, true, 2.0)->UseRealTime();
BENCHMARK_CAPTURE(pipelineBench, pipeline_images_serial_d2, RectifyMode::kImages, false, 2.0)->UseRealTime();
BENCHMARK_CAPTURE(bareBench, bare_apriltag_serial_d2, false, 2.0)->UseRealTime();
BENCHMARK_CAPTURE(pipelineBench, pipeline_points_serial_d2, RectifyMode::kPoints, false, 2.0)->UseRealTime();
BENCHMARK_CAPTURE(pipelineBench, pipeline_images_serial_norefine_d2, RectifyMode::kImages, false, 2.0, false)
    ->UseRealTime();

int main(int argc, char** argv) {
  benchmark::Initialize(&argc, argv);
  frames();  // render and decode outside the timed runs
  RatioReporter reporter;
  benchmark::RunSpecifiedBenchmarks(&reporter);
  auto& t = reporter.seconds_per_pair;
  auto ratio = [&](const std::string& a, const std::string& b) {
    const auto ia = t.find(a + "/real_time"), ib = t.find(b + "/real_time");
    if (ia == t.end() || ib == t.end()) return;
    std::cout << a << ": " << 1.0 / ia->second << " pairs/s; " << b << ": " << 1.0 / ib->second
              << " pairs/s; pipeline time / bare time = " << ia->second / ib->second << " (overhead "
              << 100.0 * (ia->second / ib->second - 1.0) << " %)\n";
  };
  ratio("pipelineBench/pipeline_images_parallel_d1", "bareBench/bare_apriltag_leftright_parallel_d1");
  ratio("pipelineBench/pipeline_points_parallel_d1", "bareBench/bare_apriltag_leftright_parallel_d1");
  ratio("pipelineBench/pipeline_images_serial_d1", "bareBench/bare_apriltag_serial_d1");
  ratio("pipelineBench/pipeline_images_parallel_d2", "bareBench/bare_apriltag_leftright_parallel_d2");
  ratio("pipelineBench/pipeline_images_serial_d2", "bareBench/bare_apriltag_serial_d2");
  ratio("pipelineBench/pipeline_points_serial_d2", "bareBench/bare_apriltag_serial_d2");
  ratio("pipelineBench/pipeline_images_serial_norefine_d2", "bareBench/bare_apriltag_serial_d2");
  benchmark::Shutdown();
  return 0;
}
