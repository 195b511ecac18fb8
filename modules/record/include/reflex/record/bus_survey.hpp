// What runs on the bus, like `ros2 node list` / `ros2 topic hz`: the live
// processes from their heartbeats, and the rate of every Reflex topic, measured by listening for a
// while. Used by `reflex_bus`; reads only (no writer is made, no heartbeat is published).
#pragma once

#include <reflex/bus/config.hpp>

#include <cstdint>
#include <string>
#include <vector>

namespace reflex::record {

/// One module's last heartbeat.
struct ModuleSeen {
  std::string module_name;
  std::string host;
  int pid = 0;
  std::string state;  ///< RUNNING, CONFIGURING, STOPPING, ERROR
  unsigned period_ms = 0;
  std::string detail;
  int heartbeats = 0;  ///< heartbeats received in the window (the first is the module's last beat)
  double age_s = 0.0;  ///< time since its stamp when the window ended (s)
};

/// One process: the modules that share a host and pid.
struct ProcessSeen {
  std::string host;
  int pid = 0;
  std::vector<ModuleSeen> modules;
};

/// One topic's traffic in the window.
struct TopicSeen {
  std::string topic, type;
  std::uint64_t samples = 0;
  /// (samples - 1) / the time from the first to the last sample received (as `ros2 topic hz`: the
  /// time discovery takes at the window's start is not counted as silence); samples / window when
  /// fewer than two arrived.
  double hz = 0.0;
  int writers = 0;  ///< matched writers when the window ended
};

struct BusSurvey {
  double window_s = 0.0;  ///< how long it listened: the window (at least 2 s), plus up to 5 s while discovery went on
  /// False if, after the extra 5 s, a participant was discovered or a heartbeat writer matched whose
  /// beat never arrived (a process may be missing from the list: said, never silent).
  bool settled = true;
  /// Remote participants discovered that sent no heartbeat (tools that publish none, such as another
  /// reflex_bus, or processes whose beat had not arrived after the extra 5 s).
  int silent_participants = 0;
  int domain = 0;
  std::vector<ProcessSeen> processes;  ///< sorted by host, pid
  std::vector<TopicSeen> topics;       ///< every known topic (or the ones asked for), sorted by name
};

/// Listens on the bus for `window_s` seconds (> 0) and reports. `topics` empty: every default topic
/// of idl/; else these ("reflex/joint_state" or "NAME:TYPE"). Throws RecordError / BusError naming a
/// bad topic, window or bus set-up.
BusSurvey surveyBus(const bus::BusConfig& config, double window_s, const std::vector<std::string>& topics = {});

}  // namespace reflex::record
