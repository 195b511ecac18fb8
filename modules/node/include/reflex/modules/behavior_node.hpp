// The behavior process on the bus: a thin DDS adapter around BehaviorHost (STYLE.md Sec. 8, 9).
//
// It owns the participant (module name = the configuration's `process`, or the module's name with
// --module), subscribes to reflex/object_targets (if a module wants objects) and reflex/joint_state,
// converts samples to reflex::modules types and hands them to the host; it creates writers only for
// what the modules claim (hand targets, motion priority, body schema, walk command) and publishes
// what the host's sink receives. A heartbeat (reflex/heartbeat, 2 Hz) tells the controller and
// tools that the process is alive; at stop the host's removals (hands "no target", segments
// detached, priority equal, walking stopped) are published and acknowledged before exit.
#pragma once

#include "reflex/modules/host.hpp"
#include "reflex/modules/registry.hpp"

#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace reflex::bus {
class Participant;
}  // namespace reflex::bus

namespace reflex::modules {

struct NodeOptions {
  std::string config;  ///< behavior configuration YAML
  std::string module;  ///< run only this module of the configuration ("" = all)
  /// Replaces the configuration's inputs.object_sources when not empty (--object-source).
  std::vector<std::string> object_sources;
  /// Replaces the configuration's inputs.joint_state_sources when not empty (--joint-state-source).
  std::vector<std::string> joint_state_sources;
  std::optional<int> domain_id;  ///< DDS domain (empty: $REFLEX_DOMAIN_ID, else 0)
  std::string profiles_file;     ///< QoS profiles ("" = bus default)
  std::string participant_profile = "reflex_participant";
  double duration = 0.0;         ///< [s] stop after this long (0 = until SIGINT / SIGTERM)
  double progress_period = 5.0;  ///< [s] status line on stderr (0 = none)
  bool quiet = false;            ///< no log lines on stderr
  /// Module type -> plugin file that registered it (HostConfig::type_plugins: named in errors).
  std::map<std::string, std::string> type_plugins;
};

class BehaviorNode {
 public:
  /// Reads the configuration, builds the host (modules configured) and the DDS entities. Throws
  /// ConfigError (configuration) or reflex::bus::BusError (DDS) naming what failed.
  BehaviorNode(const NodeOptions& options, const ModuleRegistry& registry);
  ~BehaviorNode();
  BehaviorNode(const BehaviorNode&) = delete;
  BehaviorNode& operator=(const BehaviorNode&) = delete;

  /// Starts the modules, runs until stop() / the duration, then stops the modules and waits (up to
  /// 2 s) until the removals are acknowledged by matched readers. Signals are the program's business:
  /// main installs reflex::bus::StopOnSignal on bus() (so nodes compose in one process).
  void run();
  /// Thread-safe.
  void stop() noexcept;
  /// The node's participant (to stop it from a signal: bus::StopOnSignal).
  bus::Participant& bus();

  const BehaviorHost& host() const;
  /// "frames=... objects_accepted=... rejected_future=... ..." (the exit report).
  std::string report() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace reflex::modules
