// The behavior host: runs the modules a configuration names, in one process, without DDS.
//
// It owns the robot state, builds every module through the registry, configures them, checks that
// no two modules claim the same output, validates every input before a module sees it, merges the
// modules' outputs (one HandTargets for both hands, whoever sets them) and hands the changes to an
// OutputSink: the DDS adapter in modules/node, or a recording sink in tests.
//
// Input validation (InputPolicy), counted in HostStats and never forwarded to a module:
//   - an ObjectTargets frame whose writer (ObjectsFrame::source: the identity of the participant
//     that wrote it, authenticated under DDS-Security) is not one of `object_sources` (default:
//     "vision"): the whole frame is dropped — a recording replayed by reflex_play (identity
//     "player") or any other permitted writer does not steer the arms unless the configuration
//     names it;
//   - an ObjectTargets frame stamped in the future (stamp_ns or capture_stamp_ns later than the
//     host's wall clock + future_tolerance): the whole frame is dropped;
//   - an ObjectTargets frame whose frame_id is not one of `frames` (default: "base_link", the name
//     reflex_vision writes): the whole frame is dropped, since its positions are not in B (a
//     frame named "odom", "head_camera" or "" is never used as if it were the base frame);
//   - an object with a non-finite position or confidence, or a confidence outside [0, 1];
//   - an object with an unknown name ("" or not in known_objects when that list is given);
//   - an object farther than max_range from the base origin; a second object of the same name;
//   - a joint state written by an identity not in `joint_state_sources` (default "controller"), or
//     whose names and positions differ in length or hold a non-finite value.
//
// Configuration file (a YAML map; see bringup/behavior/*.yaml and modules/README.md):
//   process: behavior          # module name on the bus (Header.source, heartbeat)
//   robot: {urdf: ..., ...}    # readRobotConfig
//   inputs: {known_objects: [cup, can], future_tolerance: 0.5, max_range: 3.0, frames: [base_link],
//            object_sources: [vision], joint_state_sources: [controller]}
//   tick_period: 0.02          # s, how often modules' step() timers are checked
//   joint_state_period: 0.1    # s, modules hear of joint states at most this often
//   modules:
//     - {name: pointing, type: pointing, config: {...}}
//
// Every call into a module (its factory, configure, claims, stepPeriod, start, onObjects,
// onJointState, step, stop, status, its destructor) is marked (module_call.hpp), so a crash or a call
// that never returns can be named by the process, and guarded: whatever a module throws, a
// std::exception or not, leaves the host as a ModuleError naming the call, the module, its type and
// the plugin file that registered the type. A ConfigError from the factory or configure() passes
// unchanged (it names file, line, key and value).
#pragma once

#include "reflex/common/error.hpp"
#include "reflex/modules/config.hpp"
#include "reflex/modules/module.hpp"
#include "reflex/modules/registry.hpp"
#include "reflex/modules/robot_state.hpp"
#include "reflex/modules/types.hpp"

#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

namespace reflex::modules {

/// A module failed in a call at run time (threw, whatever it threw). The message names the call, the
/// module, its type and where the type came from: "step() of module 'x' (type t, plugin /abs/lib.so)
/// threw: ...". A run that failed (exit 1), not a refusal: a reflex::Failure.
class ModuleError : public reflex::Failure {
 public:
  using reflex::Failure::Failure;
};

/// Where the host's merged outputs go. Called only on change, from the host's thread.
class OutputSink {
 public:
  virtual ~OutputSink() = default;
  virtual void handTargets(const HandTarget& left, const HandTarget& right) = 0;
  virtual void motionPriority(ArmPriority priority) = 0;
  virtual void segmentAttached(const SegmentSpec& segment) = 0;
  virtual void segmentDetached(const std::string& name) = 0;
  virtual void walk(const WalkGoal& goal) = 0;
};

struct InputPolicy {
  std::vector<std::string> known_objects;  ///< empty: any non-empty name is known
  double future_tolerance = 0.5;           ///< [s] a stamp later than now + this is rejected
  double max_range = 3.0;                  ///< [m] objects farther from the base origin are rejected
  /// Names of the base frame B accepted in ObjectTargets.frame_id (exact, case-sensitive; not empty).
  std::vector<std::string> frames = {kBaseFrameId};
  /// Identities whose ObjectTargets are accepted (exact; not empty): "vision" is reflex_vision
  /// (certificate CN=reflex.vision), "player" is reflex_play (CN=reflex.player).
  std::vector<std::string> object_sources = {"vision"};
  /// Identities whose JointState samples are accepted (exact; not empty): "controller" is
  /// reflex_controller; "player" when a recording replays the robot's joint states.
  std::vector<std::string> joint_state_sources = {"controller"};
};

struct ModuleEntry {
  std::string name;  ///< instance name (unique)
  std::string type;  ///< registry type
  ConfigNode config;
};

struct HostConfig {
  std::string file;  ///< where it was read from
  std::string process = "behavior";
  RobotConfig robot;
  InputPolicy inputs;
  double tick_period = 0.02;  ///< [s]
  /// [s] modules' onJointState runs at most this often (the robot state itself follows every sample)
  double joint_state_period = 0.1;
  std::vector<ModuleEntry> modules;
  /// Module type -> the plugin file that registered it (PluginInfo::path); a type not here is built
  /// in. Not read from the file: the program that loaded the plugins fills it, for messages.
  std::map<std::string, std::string> type_plugins;
};

/// Reads a behavior configuration file; throws ConfigError naming file, line, key and value.
/// Module types are checked against `registry` here (unknown type = error at start).
HostConfig loadHostConfig(const std::string& path, const ModuleRegistry& registry);
HostConfig parseHostConfig(const ConfigNode& root, const ModuleRegistry& registry);

struct HostStats {
  std::uint64_t frames_received = 0;
  std::uint64_t frames_rejected_future = 0;
  std::uint64_t frames_rejected_frame = 0;   ///< frame_id not one of InputPolicy::frames
  std::uint64_t frames_rejected_source = 0;  ///< writer not one of InputPolicy::object_sources
  std::uint64_t objects_accepted = 0;
  std::uint64_t objects_rejected_invalid = 0;    ///< NaN / inf position or confidence, confidence out of [0, 1]
  std::uint64_t objects_rejected_unknown = 0;    ///< "" or not in known_objects
  std::uint64_t objects_rejected_range = 0;      ///< farther than max_range
  std::uint64_t objects_rejected_duplicate = 0;  ///< same name twice in one frame
  std::uint64_t joint_states = 0;
  std::uint64_t joint_states_rejected = 0;
  std::uint64_t joint_states_rejected_source = 0;  ///< writer not one of InputPolicy::joint_state_sources
  std::uint64_t outputs_rejected = 0;              ///< non-finite hand target / bad segment from a module
  std::uint64_t hand_targets_published = 0;
  std::uint64_t priority_published = 0;
  std::uint64_t segment_changes_published = 0;
  std::uint64_t walk_published = 0;
  std::uint64_t forced_cleanups = 0;  ///< things a module left behind at stop (host removed them)

  std::uint64_t rejectedObjects() const {
    return objects_rejected_invalid + objects_rejected_unknown + objects_rejected_range + objects_rejected_duplicate;
  }
};

class BehaviorHost {
 public:
  using LogFn = std::function<void(const std::string&)>;

  /// Loads the robot, creates and configures the modules (all of them, or only the one named
  /// `only_module`), and checks their claims. Throws ConfigError on any set-up error.
  BehaviorHost(const HostConfig& config, const ModuleRegistry& registry, OutputSink& sink, LogFn log = {},
               const std::string& only_module = "");
  ~BehaviorHost();
  BehaviorHost(const BehaviorHost&) = delete;
  BehaviorHost& operator=(const BehaviorHost&) = delete;

  void start(const Now& now);
  void onObjects(const ObjectsFrame& frame, const Now& now);
  void onJointState(const JointStateSample& js, const Now& now);
  /// Runs the step() of every module whose period has elapsed.
  void tick(const Now& now);
  /// Stops every module (reverse order) and removes what they left behind.
  void stop(const Now& now);

  /// Union of the modules' claims.
  const Claims& claims() const { return claims_; }
  const HostStats& stats() const { return stats_; }
  const RobotState& robot() const { return *robot_; }
  const std::string& processName() const { return process_name_; }
  std::vector<std::string> moduleNames() const;
  /// Current merged outputs.
  const HandTarget& hand(Hand h) const { return hands_[handIndex(h)]; }
  ArmPriority priority() const { return priority_; }
  const std::map<std::string, SegmentSpec>& segments() const { return segments_; }
  bool running() const { return running_; }
  /// One line: modules' status and the input counters (heartbeat detail, exit report).
  std::string status() const;

 private:
  class Context;
  struct Slot;
  void flush();
  void logLine(const std::string& line);
  void logRejected(std::uint64_t count, const std::string& line);

  std::string process_name_;
  InputPolicy inputs_;
  double joint_state_period_ = 0.1;
  double last_joint_dispatch_ = -1e9;
  std::unique_ptr<RobotState> robot_;
  OutputSink& sink_;
  LogFn log_;
  std::vector<std::unique_ptr<Slot>> slots_;
  Claims claims_;
  HostStats stats_;
  HandTarget hands_[2];
  bool hands_dirty_ = false;
  ArmPriority priority_ = ArmPriority::kEqual;
  bool priority_dirty_ = false;
  std::map<std::string, SegmentSpec> segments_;
  std::optional<WalkGoal> walk_;
  bool running_ = false;
  bool stopped_ = false;
  ObjectsFrame scratch_;
};

}  // namespace reflex::modules
