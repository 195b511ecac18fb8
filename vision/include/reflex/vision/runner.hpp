#pragma once
// The vision process loop, without any transport: frames from a StereoSource go through the
// StereoTagPipeline; every processed frame goes to on_frame (the --dump writer); publications go to
// on_publish at publish_hz on the REPLAY clock (the DDS writer in reflex_vision, a recorder of
// call times in the rate test).
//
// Replay clock (as `ros2 bag play`): session time s maps to wall time w = w0 + (s - s0) / rate,
// where s0 is the stamp of the first frame after the start offset. rate 1 is real time, 2 twice as
// fast, 0.5 half speed; rate 0 means "as fast as possible" (virtual clock, no sleeping, used by
// --dump). With loop, the session restarts at the start offset and session time keeps increasing
// (each pass adds its length plus one frame period), so stamps stay monotonic.
// Publication k is due at session time s0 + k / publish_hz and carries the newest frame processed
// by then (its capture stamp, not the publication time); there is no publication before the first
// frame is processed. In paced mode a separate thread keeps the publication deadlines, so a slow
// frame never delays a publication. A live camera's frame already one frame period late when it is
// read is dropped (counted in RunStats::dropped): targets stay fresh. A recorded session's frame is
// dropped only when it is more than ReplayOptions::max_lag behind the replay clock: a process
// descheduled for a few periods by a competing load catches up instead of losing those frames.
// Unpaced runs (rate 0, --dump) process every frame.
// Stopping: every wait (a paced frame's due time) is slept in 50 ms slices that look at `stop`, the
// unpaced publication schedule s0 + k / publish_hz is computed from the integer k (a running sum
// stops advancing near large stamps) and looks at `stop` too, and the source gets `stop` for its own
// loops (StereoSource::watchStop). So SIGINT/SIGTERM end a run within ~50 ms whatever the stamps.
#include "reflex/vision/source.hpp"
#include "reflex/vision/stereo_pipeline.hpp"

#include <atomic>
#include <functional>
#include <string>
#include <vector>

namespace reflex::vision {

struct ReplayOptions {
  double rate = 1.0;  ///< >= 0; 0 = as fast as possible
  bool loop = false;
  double publish_hz = 10.0;  ///< > 0
  double duration = 0.0;     ///< stop after this much session time (0 = no limit)
  /// Paced replay of a recording: a frame more than this behind the replay clock (s) is dropped and
  /// counted; one less late is processed (and published with its own capture stamp). In (0, 10].
  double max_lag = 0.5;
};

/// Throws VisionError naming the option if out of range.
void validateReplayOptions(const ReplayOptions& options);

/// What one publication carries.
struct Publication {
  std::uint64_t sequence = 0;
  double publish_time = 0.0;   ///< session-clock time the publication was due at
  double capture_stamp = 0.0;  ///< session-clock capture stamp of the frame it carries (incl. loop offset)
  double capture_wall = 0.0;   ///< that capture mapped to UNIX time on the replay clock (live: the stamp)
  int frame = -1;              ///< source frame index, -1 before the first frame
  std::vector<ObjectObservation> objects;
};

struct RunProgress {
  int frame = 0;    ///< index in the recording (StereoFrame::index), < frames
  int frames = -1;  ///< frames of the whole recording (StereoSource::recordingFrames), -1 for live
  int pass = 0;
  double session_time = 0;  ///< the frame's session time: its stamp minus the recording's first stamp (s;
                            ///< with --start, the offset included; the same in every loop pass)
  double run_time = 0;      ///< session-clock seconds since this run's first frame (the start offset)
  double lag = 0;           ///< how far processing is behind the replay clock, s (paced only)
  int objects = 0;
};

struct RunCallbacks {
  std::function<void(const StereoFrame&, double capture_stamp, const StereoResult&)> on_frame;
  std::function<void(const Publication&)> on_publish;
  std::function<void(int frame, const std::string& why)> on_skip;
  std::function<void(const RunProgress&)> on_progress;
};

struct RunStats {
  int frames = 0;   ///< processed
  int skipped = 0;  ///< reported skipped frames
  int dropped = 0;  ///< paced runs: frames dropped because processing fell behind (max_lag; live: a period)
  int publications = 0;
  int passes = 0;
  std::string end_message;  ///< non-empty if the source stopped early (truncated video, camera lost)
};

/// Runs until the source ends (and loop is off), the duration is reached, or `stop` becomes true
/// (seen within ~50 ms, also during a wait). Never throws for bad frames (reported through on_skip /
/// end_message). Callbacks must not throw; one that cannot go on (a dump file that cannot be
/// written) sets `stop` and reports after the run.
RunStats runVision(StereoSource& source, StereoTagPipeline& pipeline, const ReplayOptions& options,
                   const RunCallbacks& callbacks, const std::atomic<bool>& stop);

}  // namespace reflex::vision
