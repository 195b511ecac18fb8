// Scenes from a recorded controller time series: the rows of a
// `reflex_controller --log` CSV (or reflex_sim's timeseries.csv, the same format) at chosen times,
// turned into SceneInputs, so that the flagship report draws the robot with the live view's renderer
// (modules/view/web/view.js, static mode) from the same foxglove.SceneUpdate the live view gets.
//
// Columns read (header names; any order, others ignored):
//   time                 [s] controller time of the row (required)
//   q_<joint>            [rad or m] one per joint of the model (required, finite)
//   wall_time            [s since the epoch] -> SceneInput.stamp_ns (optional; 0 when absent)
//   <arm>_f, <arm>_distance [m], <arm>_pair ("segA|segB", or empty), <arm>_zone (free / yellow /
//   orange / red), estop (EstopState number, non-zero = latched) -> SceneInput.arms: the arm's status
//   as ControlStatus carried it (all optional: without <arm>_zone the arm is drawn neutral)
//   <arm>_status ("given" or other), <arm>_target_x/_y/_z [m, in B] -> SceneInput.targets
// <arm> is SceneModel::arm_names ("left", "right").
//
// Bad input (setup-time, so it throws control::ConfigError naming the file, the row and the value):
// a missing file or column, a row with fewer values than the header, a non-finite time or joint position, a
// zone that is none of the four names, a number that does not parse. Times in `at` pick the nearest
// row each (ties: the earlier row); a non-finite time is an error.
#pragma once

#include <reflex/view/scene.hpp>

#include <cstddef>
#include <string>
#include <vector>

namespace reflex::view {

/// One row of a controller time series as a scene input.
struct LogScene {
  double t = 0.0;       ///< [s] the row's `time`
  std::size_t row = 0;  ///< 1-based data row (the header is row 0)
  SceneInput input;     ///< q (model order), arms, targets; no objects, no body-schema segments
};

/// Reads the rows of the CSV `path` nearest to each time of `at` (one LogScene per entry of `at`, in
/// that order). Throws control::ConfigError as described at the top of this file.
std::vector<LogScene> readLogScenes(const SceneModel& scene, const std::string& path, const std::vector<double>& at);

}  // namespace reflex::view
