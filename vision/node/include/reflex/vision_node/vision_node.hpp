// The vision process as a library (STYLE.md Sec. 8, 9): a VisionNode owns the stereo source (a
// recorded session, live cameras or video files standing in for them), the detection pipeline, the
// replay loop and what it feeds: the DDS publisher of reflex/object_targets (participant, writer,
// heartbeat; only in a build with reflex::bus) or, offline, the --dump CSV.
//
// Threads: with the bus, run() runs the bus loop (heartbeat timer, stop) on the calling thread and the
// replay loop (capture, detection, triangulation, publication schedule; runner.hpp) on a worker it
// joins before returning. Offline, the replay loop runs on the calling thread.
//
// Signals are the program's business: main installs reflex::bus::StopOnSignal on bus() (or, offline,
// a handler that calls stop()), so several nodes compose in one process and stopping one leaves the
// others running. reflex_vision (vision/tools/vision_main.cpp) is the thin main.
#pragma once

#include "reflex/vision/error.hpp"
#include "reflex/vision/runner.hpp"
#include "reflex/vision/stereo_pipeline.hpp"

#include <atomic>
#include <memory>
#include <optional>
#include <string>

namespace reflex::bus {
class Participant;
}  // namespace reflex::bus

namespace reflex::vision_node {

/// What reflex_vision's options say (vision/README.md, `reflex_vision --help`). Exactly one source:
/// `session`, `camera_left` + `camera_right`, or `side_by_side`.
struct NodeOptions {
  std::string session;       ///< recorded session folder
  std::string camera_left;   ///< live camera: device index or video file/URL
  std::string camera_right;  ///< (with camera_left)
  std::string side_by_side;  ///< one side-by-side stereo camera: device index or video file/URL
  std::string calib_left;    ///< camera_info YAML (cameras only; a session carries its own)
  std::string calib_right;
  std::string objects;  ///< object map YAML ("" = the session's; required for cameras)
  std::string mount;    ///< camera mount YAML ("" = the session's; required for cameras)
  /// Offline: every detection to this CSV, nothing published (no DDS). "" = publish on the bus.
  std::string dump;
  /// rate, loop, duration [s of session time], publish_hz. `rate` counts only if rate_given
  /// (else 1, or 0 with `dump`); cameras run at rate 1 (another given rate is an error).
  reflex::vision::ReplayOptions replay;
  bool rate_given = false;
  double start = 0.0;  ///< [s] offset into the session (sessions only)
  /// Detector settings and refine_with_tag_size; pipeline.rectify is set from `rectify` and
  /// pipeline.detector.family from `family` (else the object map's).
  reflex::vision::PipelineOptions pipeline;
  std::string rectify = "images";  ///< "images" or "points" (anything else is an error naming it)
  std::string family;
  /// Progress line on stderr every 200 ms (pass, frame i/N, session time, objects, lag).
  bool show_progress = false;

  // The bus (ignored with `dump`).
  std::string module_name = "vision";  ///< participant name and Header.source of every sample
  std::optional<int> domain_id;        ///< DDS domain (empty: $REFLEX_DOMAIN_ID, else 0)
  std::string profiles_file;           ///< QoS profiles ("" = bus default)
  std::string frame_id = "base_link";  ///< robot base frame name written into ObjectTargets
  /// The left camera's image on reflex/camera_left (CameraImage, JPEG) at most this often per second
  /// of session time (0: not published), scaled down to at most image_width pixels wide.
  double image_hz = 2.0;
  int image_width = 640;
  /// Hold the replay (or the cameras' first publication) until this many readers of
  /// reflex/object_targets have matched (0: start at once). A replay started before its consumers are
  /// there loses its first frames: under DDS-Security each pair of participants authenticates first
  /// (seconds on a loaded machine).
  int wait_readers = 0;
  double wait_timeout = 60.0;  ///< [s] how long to hold for wait_readers; then run() throws ReadersMissing
};

/// run() gave up waiting for NodeOptions::wait_readers readers (reflex_vision exits 5).
class ReadersMissing : public reflex::vision::VisionError {
 public:
  using reflex::vision::VisionError::VisionError;
};

class VisionNode {
 public:
  /// Checks the options, opens the source (a session is read, cameras opened), loads calibration,
  /// object map and mount, builds the pipeline, creates the dump file or the DDS entities. Throws
  /// reflex::vision::VisionError naming the bad option, file or device, or reflex::bus::BusError
  /// naming the bad domain, profiles file or entity.
  explicit VisionNode(const NodeOptions& options);
  ~VisionNode();
  VisionNode(const VisionNode&) = delete;
  VisionNode& operator=(const VisionNode&) = delete;

  /// Runs once, until the source ends, the duration is over, or stop(). With wait_readers, first holds
  /// until that many readers matched (throws ReadersMissing naming how many did after wait_timeout; a
  /// stop() while holding ends run() with nothing processed). With the bus: heartbeat
  /// RUNNING while it runs, then STOPPING, or ERROR with the reason if the video ended early or the
  /// replay loop threw. Throws VisionError if the replay loop threw (the message), BusError if the bus
  /// loop stopped because the security material expired. The video ending early is not an exception:
  /// stats().end_message says why.
  const reflex::vision::RunStats& run();
  /// Thread-safe. Offline (bus() == nullptr) it only stores an atomic flag, so a signal handler may
  /// call it; with the bus it also stops the bus loop (use bus::StopOnSignal on bus() for signals).
  void stop() noexcept;
  /// The node's participant (for bus::StopOnSignal); nullptr offline (dump) or in a build without
  /// reflex::bus.
  reflex::bus::Participant* bus() noexcept;

  const reflex::vision::RunStats& stats() const noexcept { return stats_; }
  /// Closes the dump file (nothing to do when publishing). Throws VisionError naming the file and the cause
  /// if any write or the close failed (full disk, file-size limit); a failed write also stops run().
  void closeOutput();

 private:
  /// The replay loop's callbacks: the camera image, the dump rows, skipped frames, publications, progress.
  void setUpCallbacks();
  struct Impl;
  std::unique_ptr<Impl> impl_;
  reflex::vision::RunStats stats_;
  std::atomic<bool> stop_{false};
};

}  // namespace reflex::vision_node
