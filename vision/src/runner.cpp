#include "reflex/vision/runner.hpp"

#include "reflex/vision/error.hpp"

#include <chrono>
#include <cmath>
#include <condition_variable>
#include <algorithm>
#include <mutex>
#include <thread>

namespace reflex::vision {
namespace {

using SteadyClock = std::chrono::steady_clock;

double unixNow() {
  return std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch()).count();
}

// Maps session time to wall time for a paced run; a no-op clock for rate 0.
class ReplayClock {
 public:
  ReplayClock(double rate, double s0) : rate_(rate), s0_(s0), w0_(SteadyClock::now()), unix0_(unixNow()) {}
  bool paced() const { return rate_ > 0.0; }
  // Clamped to +-1e9 s (31 years) so that the conversion to integer nanoseconds cannot overflow.
  SteadyClock::time_point wallAt(double s) const {
    const double dt = std::clamp((s - s0_) / rate_, -1e9, 1e9);
    return w0_ + std::chrono::duration_cast<SteadyClock::duration>(std::chrono::duration<double>(dt));
  }
  double unixAt(double s) const { return paced() ? unix0_ + (s - s0_) / rate_ : s; }
  double lagAt(double s) const {
    return paced() ? std::chrono::duration<double>(SteadyClock::now() - wallAt(s)).count() : 0.0;
  }

 private:
  double rate_, s0_;
  SteadyClock::time_point w0_;
  double unix0_;
};

}  // namespace

void validateReplayOptions(const ReplayOptions& o) {
  if (!(o.rate >= 0.0) || !std::isfinite(o.rate) || o.rate > 1000.0)
    throw VisionError("replay rate " + std::to_string(o.rate) + " must be in [0, 1000] (0 = as fast as possible)");
  if (!(o.publish_hz > 0.0) || o.publish_hz > 1000.0)
    throw VisionError("publish rate " + std::to_string(o.publish_hz) + " Hz must be in (0, 1000]");
  if (!(o.duration >= 0.0)) throw VisionError("duration " + std::to_string(o.duration) + " s must be >= 0");
  if (!(o.max_lag > 0.0) || o.max_lag > 10.0)
    throw VisionError("max lag " + std::to_string(o.max_lag) + " s must be in (0, 10]");
}

RunStats runVision(StereoSource& source, StereoTagPipeline& pipeline, const ReplayOptions& options,
                   const RunCallbacks& cb, const std::atomic<bool>& stop) {
  validateReplayOptions(options);
  RunStats stats;
  const double period = 1.0 / options.publish_hz;

  std::mutex mutex;
  std::condition_variable wake;
  Publication latest;       // guarded by mutex
  bool finished = false;    // guarded by mutex
  double s0 = 0.0;
  bool have_s0 = false;
  double end_time = 0.0;    // session time of the last processed frame (guarded by mutex)
  std::unique_ptr<ReplayClock> clock;
  std::uint64_t sequence = 0;

  auto publish = [&](double due) {
    Publication p;
    {
      std::lock_guard<std::mutex> lock(mutex);
      p = latest;
    }
    if (p.frame < 0) return;  // nothing processed yet: no publication (not even an empty one)
    p.sequence = sequence++;
    p.publish_time = due;
    ++stats.publications;
    if (cb.on_publish) cb.on_publish(p);
  };

  // Paced publication thread: keeps absolute deadlines s0 + k * period on the replay clock.
  std::thread publisher;
  std::mutex start_mutex;
  std::condition_variable started;
  bool clock_ready = false;
  bool abort_publisher = false;
  if (options.rate > 0.0) {
    publisher = std::thread([&] {
      {
        std::unique_lock<std::mutex> lock(start_mutex);
        started.wait(lock, [&] { return clock_ready || abort_publisher; });
        if (!clock_ready) return;
      }
      for (std::uint64_t k = 0;; ++k) {
        const double due = s0 + static_cast<double>(k) * period;
        std::unique_lock<std::mutex> lock(mutex);
        wake.wait_until(lock, clock->wallAt(due), [&] { return stop.load() || (finished && due > end_time); });
        if (stop.load() || (finished && due > end_time)) return;
        lock.unlock();
        publish(due);
      }
    });
  }
  auto startClock = [&](double first) {
    s0 = first;
    have_s0 = true;
    clock = std::make_unique<ReplayClock>(options.rate, s0);
    std::lock_guard<std::mutex> lock(start_mutex);
    clock_ready = true;
    started.notify_all();
  };

  source.watchStop(&stop);
  // Paced waits sleep in slices and look at `stop` between them, so SIGINT/SIGTERM end a run within
  // a slice whatever the stamps say.
  constexpr auto kWaitSlice = std::chrono::milliseconds(50);
  const auto sleepUntil = [&](SteadyClock::time_point until) {
    while (!stop.load()) {
      const auto now = SteadyClock::now();
      if (now >= until) return;
      std::this_thread::sleep_for(std::min<SteadyClock::duration>(until - now, kWaitSlice));
    }
  };
  double loop_offset = 0.0;
  // Unpaced publication schedule: publication k is due at s0 + k * period. Computed from the integer
  // k, never by adding period to a running sum: near large stamps that sum stops advancing.
  std::uint64_t next_k = 0;
  const auto dueAt = [&](std::uint64_t k) { return s0 + static_cast<double>(k) * period; };
  double last_stamp = 0.0;
  StereoFrame frame;
  StereoResult result;
  std::string message;
  bool done = false;
  while (!done && !stop.load()) {
    const ReadStatus st = source.next(frame, message);
    if (st == ReadStatus::kEnd) {
      if (!message.empty()) {
        stats.end_message = message;
        break;
      }
      ++stats.passes;
      if (!options.loop || !source.restart()) break;
      loop_offset += (last_stamp - loop_offset - source.firstStamp()) + source.framePeriod();
      continue;
    }
    if (st == ReadStatus::kSkipped) {
      ++stats.skipped;
      if (cb.on_skip) cb.on_skip(frame.index, message);
      continue;
    }
    const double s = frame.stamp + loop_offset;
    if (!have_s0) startClock(s);
    if (options.duration > 0.0 && s - s0 > options.duration + 1e-9) break;
    if (clock->paced()) {
      // Keep up with the clock: a live camera's frame already a period late is dropped; a recorded
      // frame only beyond max_lag (the replay catches up after a competing load's burst).
      if (clock->lagAt(s) > (source.live() ? source.framePeriod() : options.max_lag)) {
        ++stats.dropped;
        continue;
      }
      sleepUntil(clock->wallAt(s));
      if (stop.load()) break;
    } else {
      // Publications due before this frame carry the previous one. Bounded: stamps are at most
      // kMaxFrameGap apart in a session (checked at load), and `stop` ends it in any case.
      while (dueAt(next_k) < s - 1e-9 && !stop.load()) publish(dueAt(next_k++));
    }
    pipeline.process(frame.left, frame.right, result);
    last_stamp = s;
    if (result.status == FrameStatus::kSkipped) {
      ++stats.skipped;
      if (cb.on_skip) cb.on_skip(frame.index, result.message);
    } else {
      ++stats.frames;
      if (cb.on_frame) cb.on_frame(frame, s, result);
      std::lock_guard<std::mutex> lock(mutex);
      latest.capture_stamp = s;
      latest.capture_wall = source.live() ? frame.stamp : clock->unixAt(s);
      latest.frame = frame.index;
      latest.objects = result.objects;
      end_time = s;
    }
    if (cb.on_progress) {
      RunProgress p;
      p.frame = frame.index;
      // Frame and time in the recording's terms: with --start the frame index
      // counts from the recording's first frame, so the total is the recording's, and the time is
      // the frame's own stamp from the recording's start (the offset included, every loop pass alike).
      p.frames = source.recordingFrames();
      p.pass = stats.passes;
      p.session_time = frame.stamp - source.recordingStart();
      p.run_time = s - s0;
      p.lag = clock->lagAt(s);
      p.objects = static_cast<int>(result.objects.size());
      cb.on_progress(p);
    }
  }
  if (have_s0 && !clock->paced())
    while (dueAt(next_k) <= last_stamp + 1e-9 && !stop.load()) publish(dueAt(next_k++));
  {
    std::lock_guard<std::mutex> lock(mutex);
    finished = true;
    end_time = std::max(end_time, last_stamp);
  }
  wake.notify_all();
  if (publisher.joinable()) {
    {
      // A publisher still waiting for the clock (no frame was ever read) is released here.
      std::lock_guard<std::mutex> lock(start_mutex);
      abort_publisher = true;
      started.notify_all();
    }
    publisher.join();
  }
  return stats;
}

}  // namespace reflex::vision
