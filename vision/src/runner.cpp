#include "reflex/vision/runner.hpp"

#include "reflex/vision/error.hpp"

#include <chrono>
#include <cmath>
#include <condition_variable>
#include <algorithm>
#include <memory>
#include <mutex>
#include <thread>

namespace reflex::vision {
namespace {

using SteadyClock = std::chrono::steady_clock;

double unixNow() { return std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch()).count(); }

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

namespace {

/// The publications of a run: the latest processed frame (written by the reader) and what is
/// published from it at s0 + k * period on the replay clock. Paced (rate > 0): a thread of its own
/// keeps those absolute deadlines; unpaced: the reader publishes what is due before each frame and,
/// at the end, up to the last frame.
class Publisher {
 public:
  Publisher(const ReplayOptions& options, const RunCallbacks& cb, const std::atomic<bool>& stop, RunStats& stats)
      : period_(1.0 / options.publish_hz), rate_(options.rate), cb_(cb), stop_(stop), stats_(stats) {
    if (rate_ > 0.0) thread_ = std::thread([this] { runPaced(); });
  }
  Publisher(const Publisher&) = delete;
  Publisher& operator=(const Publisher&) = delete;
  ~Publisher() { endThread(end_time_); }  // a run left by an exception: no unpaced publication

  /// The run's first frame at session time `first`: the clock starts (and the paced thread with it).
  void startClock(double first) {
    s0_ = first;
    clock_ = std::make_unique<ReplayClock>(rate_, s0_);
    std::lock_guard<std::mutex> lock(start_mutex_);
    clock_ready_ = true;
    started_.notify_all();
  }
  bool clockStarted() const { return clock_ != nullptr; }
  const ReplayClock& clock() const { return *clock_; }
  double s0() const { return s0_; }

  /// A processed frame, captured at session time s: what the next publications carry.
  void update(const StereoFrame& frame, double s, bool live, const StereoResult& result) {
    std::lock_guard<std::mutex> lock(mutex_);
    latest_.capture_stamp = s;
    latest_.capture_wall = live ? frame.stamp : clock_->unixAt(s);
    latest_.frame = frame.index;
    latest_.objects = result.objects;
    end_time_ = s;
  }

  /// Unpaced: the publications due before session time s carry the previous frame. Bounded: stamps
  /// are at most kMaxFrameGap apart in a session (checked at load), and `stop` ends it in any case.
  void publishDueBefore(double s) {
    while (dueAt(next_k_) < s - 1e-9 && !stop_.load()) publish(dueAt(next_k_++));
  }

  /// The end of the run (last frame at session time last_stamp): unpaced, the publications due up to
  /// it; paced, the thread publishes up to the last frame and ends. Idempotent.
  void finish(double last_stamp) {
    if (!finished_called_ && clock_ && !clock_->paced())
      while (dueAt(next_k_) <= last_stamp + 1e-9 && !stop_.load()) publish(dueAt(next_k_++));
    endThread(last_stamp);
  }

 private:
  void endThread(double last_stamp) {
    if (finished_called_) return;
    finished_called_ = true;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      finished_ = true;
      end_time_ = std::max(end_time_, last_stamp);
    }
    wake_.notify_all();
    if (thread_.joinable()) {
      {
        // A thread still waiting for the clock (no frame was ever read) is released here.
        std::lock_guard<std::mutex> lock(start_mutex_);
        abort_ = true;
        started_.notify_all();
      }
      thread_.join();
    }
  }

  // Publication k is due at s0 + k * period: computed from the integer k, never by adding period to a
  // running sum (near large stamps that sum stops advancing).
  double dueAt(std::uint64_t k) const { return s0_ + static_cast<double>(k) * period_; }

  void publish(double due) {
    Publication p;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      p = latest_;
    }
    if (p.frame < 0) return;  // nothing processed yet: no publication (not even an empty one)
    p.sequence = sequence_++;
    p.publish_time = due;
    ++stats_.publications;
    if (cb_.on_publish) cb_.on_publish(p);
  }

  void runPaced() {
    {
      std::unique_lock<std::mutex> lock(start_mutex_);
      started_.wait(lock, [&] { return clock_ready_ || abort_; });
      if (!clock_ready_) return;
    }
    for (std::uint64_t k = 0;; ++k) {
      const double due = dueAt(k);
      std::unique_lock<std::mutex> lock(mutex_);
      wake_.wait_until(lock, clock_->wallAt(due), [&] { return stop_.load() || (finished_ && due > end_time_); });
      if (stop_.load() || (finished_ && due > end_time_)) return;
      lock.unlock();
      publish(due);
    }
  }

  const double period_, rate_;
  const RunCallbacks& cb_;
  const std::atomic<bool>& stop_;
  RunStats& stats_;
  double s0_ = 0.0;
  std::unique_ptr<ReplayClock> clock_;
  std::uint64_t sequence_ = 0, next_k_ = 0;
  bool finished_called_ = false;
  std::mutex mutex_;
  std::condition_variable wake_;
  Publication latest_;     // guarded by mutex_
  bool finished_ = false;  // guarded by mutex_
  double end_time_ = 0.0;  // session time of the last processed frame (guarded by mutex_)
  std::mutex start_mutex_;
  std::condition_variable started_;
  bool clock_ready_ = false, abort_ = false;  // guarded by start_mutex_
  std::thread thread_;
};

/// Frame and time in the recording's terms: with --start the frame index counts from the recording's
/// first frame, so the total is the recording's, and the time is the frame's own stamp from the
/// recording's start (the offset included, every loop pass alike).
RunProgress progressOf(const StereoSource& source, const StereoFrame& frame, double s, const Publisher& pub,
                       const RunStats& stats, const StereoResult& result) {
  RunProgress p;
  p.frame = frame.index;
  p.frames = source.recordingFrames();
  p.pass = stats.passes;
  p.session_time = frame.stamp - source.recordingStart();
  p.run_time = s - pub.s0();
  p.lag = pub.clock().lagAt(s);
  p.objects = static_cast<int>(result.objects.size());
  return p;
}

}  // namespace

RunStats runVision(StereoSource& source, StereoTagPipeline& pipeline, const ReplayOptions& options,
                   const RunCallbacks& cb, const std::atomic<bool>& stop) {
  validateReplayOptions(options);
  RunStats stats;
  Publisher pub(options, cb, stop, stats);
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
  double last_stamp = 0.0;
  StereoFrame frame;
  StereoResult result;
  std::string message;
  while (!stop.load()) {
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
    if (!pub.clockStarted()) pub.startClock(s);
    if (options.duration > 0.0 && s - pub.s0() > options.duration + 1e-9) break;
    if (pub.clock().paced()) {
      // Keep up with the clock: a live camera's frame already a period late is dropped; a recorded
      // frame only beyond max_lag (the replay catches up after a competing load's burst).
      if (pub.clock().lagAt(s) > (source.live() ? source.framePeriod() : options.max_lag)) {
        ++stats.dropped;
        continue;
      }
      sleepUntil(pub.clock().wallAt(s));
      if (stop.load()) break;
    } else {
      pub.publishDueBefore(s);
    }
    pipeline.process(frame.left, frame.right, result);
    last_stamp = s;
    if (result.status == FrameStatus::kSkipped) {
      ++stats.skipped;
      if (cb.on_skip) cb.on_skip(frame.index, result.message);
    } else {
      ++stats.frames;
      if (cb.on_frame) cb.on_frame(frame, s, result);
      pub.update(frame, s, source.live(), result);
    }
    if (cb.on_progress) cb.on_progress(progressOf(source, frame, s, pub, stats, result));
  }
  pub.finish(last_stamp);
  return stats;
}

}  // namespace reflex::vision
