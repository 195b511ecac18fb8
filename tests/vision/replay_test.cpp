// Replay and publication rate: the publications that reflex_vision hands
// to its DDS writer come from runVision's on_publish; here the same path hands them to a recorder of
// call times. 10 Hz +- 2 % on the replay clock at real rate, 2x and 0.5x; loop, start offset.
// The progress reports (reflex_vision --progress prints them) with a start offset and
// a loop: frame i/N against the session's own frame count and its timestamps file (loadSessionInfo),
// the time against the frame's stamp minus the session's first stamp.
#include "vision_test_util.hpp"

#include <gtest/gtest.h>

#include <chrono>
#include <functional>
#include <thread>

#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

using namespace reflex::vision;
using namespace reflex::vision::test;

namespace {

class Replay : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = std::make_unique<TempDir>("replay");
    makeSession(parseSceneScript(nearScript(5.0), "near"), *dir_ / "s");
    makeSession(parseSceneScript(nearScript(1.0), "near"), *dir_ / "one");
  }
  static void TearDownTestSuite() { dir_.reset(); }

  struct Run {
    std::vector<double> wall;  // steady clock, s
    std::vector<Publication> pubs;
    std::vector<double> frame_stamps;
    std::vector<int> frame_index;
    int progress_calls = 0;
    std::vector<RunProgress> progress;
    RunStats stats;
  };
  static Run run(const std::string& session, double rate, double duration, bool loop = false, double start = 0.0,
                 double max_lag = ReplayOptions{}.max_lag, const std::function<void(int)>& after_frame = nullptr) {
    SessionSource source(session, start);
    StereoTagPipeline pipeline(source.calibration(), source.info().mount.value(), source.info().objects,
                               PipelineOptions{});
    Run r;
    RunCallbacks cb;
    cb.on_publish = [&](const Publication& p) {
      r.wall.push_back(std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count());
      r.pubs.push_back(p);
    };
    cb.on_frame = [&](const StereoFrame& f, double s, const StereoResult&) {
      r.frame_stamps.push_back(s);
      r.frame_index.push_back(f.index);
      if (after_frame) after_frame(f.index);
    };
    cb.on_progress = [&](const RunProgress& p) {
      ++r.progress_calls;
      r.progress.push_back(p);
    };
    ReplayOptions o;
    o.rate = rate;
    o.duration = duration;
    o.loop = loop;
    o.publish_hz = 10.0;
    o.max_lag = max_lag;
    std::atomic<bool> stop{false};
    r.stats = runVision(source, pipeline, o, cb, stop);
    return r;
  }
  static void expectWallRate(const Run& r, double hz) {
    ASSERT_GE(r.wall.size(), 10u);
    // The rate from the least-squares slope of publication time over index: one callback woken late
    // (a loaded machine) at either end moved a first-to-last mean by up to 2 % at 2x speed.
    const double n = static_cast<double>(r.wall.size()), i_mean = (n - 1.0) / 2.0;
    double w_mean = 0.0;
    for (const double w : r.wall) w_mean += w / n;
    double sxy = 0.0, sxx = 0.0;
    for (std::size_t i = 0; i < r.wall.size(); ++i) {
      sxy += (static_cast<double>(i) - i_mean) * (r.wall[i] - w_mean);
      sxx += (static_cast<double>(i) - i_mean) * (static_cast<double>(i) - i_mean);
    }
    const double mean = sxx / sxy;
    double worst = 0.0;
    for (std::size_t i = 1; i < r.wall.size(); ++i)
      worst = std::max(worst, std::abs(r.wall[i] - r.wall[i - 1] - 1.0 / hz));
    std::cout << "publications " << r.wall.size() << ", mean rate " << mean << " Hz (target " << hz
              << "), worst period error " << 1000.0 * worst << " ms\n";
    EXPECT_NEAR(mean, hz, 0.02 * hz);
  }
  static std::unique_ptr<TempDir> dir_;
};
std::unique_ptr<TempDir> Replay::dir_;

}  // namespace

TEST_F(Replay, RealTimePublishesAt10HzOnTheReplayClock) {
  const Run r = run(*dir_ / "s", 1.0, 3.0);
  expectWallRate(r, 10.0);
  ASSERT_FALSE(r.pubs.empty());
  for (std::size_t k = 0; k < r.pubs.size(); ++k) {
    EXPECT_NEAR(r.pubs[k].publish_time - r.pubs[0].publish_time, 0.1 * k, 1e-9);
    EXPECT_EQ(r.pubs[k].sequence, k);
    // A publication carries a frame captured at or before it was due (+ the stamp jitter).
    if (r.pubs[k].frame >= 0) {
      EXPECT_LE(r.pubs[k].capture_stamp, r.pubs[k].publish_time + 0.005);
    }
    if (k > 0) {
      EXPECT_GE(r.pubs[k].capture_stamp, r.pubs[k - 1].capture_stamp);
    }
  }
  EXPECT_GE(r.progress_calls, r.stats.frames) << "progress is reported for every processed frame";
}

TEST_F(Replay, TwiceAsFastAndHalfSpeed) {
  const Run fast = run(*dir_ / "s", 2.0, 3.0);
  expectWallRate(fast, 20.0);  // 10 Hz on the replay clock = 20 Hz of wall time at 2x
  for (std::size_t k = 1; k < fast.pubs.size(); ++k)
    EXPECT_NEAR(fast.pubs[k].publish_time - fast.pubs[k - 1].publish_time, 0.1, 1e-9);
  const Run slow = run(*dir_ / "s", 0.5, 1.0);
  expectWallRate(slow, 5.0);
}

TEST_F(Replay, AsFastAsPossibleStillPublishesOnTheSessionClock) {
  const Run r = run(*dir_ / "s", 0.0, 0.0);
  EXPECT_EQ(r.stats.frames + r.stats.skipped, 50);
  const double span = r.frame_stamps.back() - r.frame_stamps.front();
  EXPECT_EQ(static_cast<int>(r.pubs.size()), static_cast<int>(std::floor(span * 10.0 + 1e-9)) + 1);
}

TEST_F(Replay, LoopKeepsStampsIncreasing) {
  const Run r = run(*dir_ / "one", 0.0, 2.5, true);
  EXPECT_GE(r.stats.passes, 2);
  EXPECT_GE(r.frame_stamps.size(), 24u);
  for (std::size_t i = 1; i < r.frame_stamps.size(); ++i) EXPECT_GT(r.frame_stamps[i], r.frame_stamps[i - 1]);
  EXPECT_EQ(r.frame_index[10], 0) << "second pass restarts at the first frame";
}

TEST_F(Replay, StartOffset) {
  // The first frame is the first one stamped at least `start` after the session's first frame.
  const std::vector<double> stamps = loadSessionInfo(*dir_ / "s").stamps;
  auto firstAfter = [&](double start) {
    int i = 0;
    while (stamps[static_cast<std::size_t>(i)] < stamps[0] + start - 1e-9) ++i;
    return i;
  };
  const Run r = run(*dir_ / "s", 0.0, 0.0, false, 2.0);
  ASSERT_FALSE(r.frame_index.empty());
  EXPECT_EQ(r.frame_index.front(), firstAfter(2.0));
  EXPECT_EQ(static_cast<int>(r.frame_index.size()) + r.stats.skipped, 50 - firstAfter(2.0));
  // Loop from an offset restarts at the offset.
  const Run l = run(*dir_ / "s", 0.0, 5.0, true, 4.0);
  const int first = firstAfter(4.0);
  ASSERT_GT(l.frame_index.size(), static_cast<std::size_t>(2 * (50 - first)));
  EXPECT_EQ(l.frame_index.front(), first);
  EXPECT_EQ(l.frame_index[static_cast<std::size_t>(50 - first)], first);
}

TEST_F(Replay, ProgressWithAStartOffsetCountsTheSessionsFramesAndPrintsSessionTime) {
  // The independent answer: the session's own timestamps (timestamps.csv through loadSessionInfo).
  // The 1 s session (10 frames) from 0.5 s: 0.5 s passes, looped for 1.2 s (cheap: ~12 frames detected).
  const std::vector<double> stamps = loadSessionInfo(*dir_ / "one").stamps;
  const int total = static_cast<int>(stamps.size());
  const double start = 0.5;
  const Run r = run(*dir_ / "one", 0.0, 1.2, true, start);
  ASSERT_GE(r.progress.size(), 10u);
  int max_shown = 0, passes = 0;
  for (const RunProgress& p : r.progress) {
    ASSERT_GE(p.frame, 0);
    ASSERT_LT(p.frame, total);
    EXPECT_EQ(p.frames, total) << "N is the session's frame count, with --start too";
    EXPECT_LE(p.frame + 1, p.frames) << "the printed frame number i never passes N";
    // Session time: the frame's stamp from the session's first frame (the offset included), in every pass.
    EXPECT_DOUBLE_EQ(p.session_time, stamps[static_cast<std::size_t>(p.frame)] - stamps.front());
    EXPECT_GE(p.session_time, start - 0.1 - 1e-9);  // frames start at the offset (10 fps)
    max_shown = std::max(max_shown, p.frame + 1);
    passes = std::max(passes, p.pass + 1);
  }
  EXPECT_EQ(max_shown, total) << "the last frame of a pass is shown as N/N";
  EXPECT_GE(passes, 2);
  EXPECT_GT(r.progress.back().run_time, r.progress.back().session_time - start)
      << "run time (since the offset) keeps growing across passes; session time starts again";
}

// Paced replay keeps every frame it can: a frame processed late (a slow frame, a process descheduled
// by a competing load) is still processed, unless it is more than max_lag behind the replay clock;
// every frame is accounted for (processed, skipped or dropped).
TEST_F(Replay, ASlowFrameDelaysTheNextOnesInsteadOfDroppingThem) {
  // The 1 s session: 10 frames at 10 Hz. Processing stalls 0.25 s (2.5 periods) after frame 3.
  const auto stall = [](double seconds) {
    return [seconds](int index) {
      if (index == 3) std::this_thread::sleep_for(std::chrono::duration<double>(seconds));
    };
  };
  const Run kept = run(*dir_ / "one", 1.0, 0.0, false, 0.0, 0.5, stall(0.25));
  EXPECT_EQ(kept.stats.dropped, 0) << "2.5 periods late is within max_lag 0.5 s";
  EXPECT_EQ(kept.stats.frames + kept.stats.skipped, 10);
  // The old rule (a frame one period late is dropped) lost the frames behind the stall.
  const Run strict = run(*dir_ / "one", 1.0, 0.0, false, 0.0, 0.1, stall(0.25));
  EXPECT_GE(strict.stats.dropped, 1);
  EXPECT_EQ(strict.stats.frames + strict.stats.skipped + strict.stats.dropped, 10);
  // A stall longer than max_lag: the frames it left behind are dropped and counted.
  const Run late = run(*dir_ / "one", 1.0, 0.0, false, 0.0, 0.5, stall(0.8));
  EXPECT_GE(late.stats.dropped, 1);
  EXPECT_EQ(late.stats.frames + late.stats.skipped + late.stats.dropped, 10);
  // Stamps stay the frames' own and increasing (a late frame is published with its capture stamp).
  for (std::size_t k = 1; k < kept.frame_stamps.size(); ++k) EXPECT_GT(kept.frame_stamps[k], kept.frame_stamps[k - 1]);
}

TEST_F(Replay, UnderFourBusyProcessesAPacedReplayKeepsAtLeast95PercentOfFrames) {
  // Four competing processes spinning for the whole replay (two per core on this two-core machine;
  // with two, the replay's share of a core was enough even for the old rule). With four, the old rule
  // (a frame one period late is dropped, max_lag 0.1 here) lost 11, 0 and 4 of the 50 frames in three
  // runs; with six, both lose frames (the replay cannot keep up on average).
  std::vector<pid_t> busy;
  for (int k = 0; k < 4; ++k) {
    const pid_t pid = fork();
    ASSERT_GE(pid, 0);
    if (pid == 0) {
      volatile unsigned long x = 0;
      for (;;) x = x + 1;
    }
    busy.push_back(pid);
  }
  const Run r = run(*dir_ / "s", 1.0, 0.0);
  for (const pid_t pid : busy) {
    kill(pid, SIGKILL);
    waitpid(pid, nullptr, 0);
  }
  std::cout << "paced replay under four busy processes: " << r.stats.frames << " processed, " << r.stats.skipped
            << " skipped, " << r.stats.dropped << " dropped of 50\n";
  EXPECT_EQ(r.stats.frames + r.stats.skipped + r.stats.dropped, 50) << "every frame accounted for";
  EXPECT_GE(r.stats.frames + r.stats.skipped, 48) << "at least 95 % of the pairs kept";
}
