// A behavior module: the layer between vision and the controller (paper Sec. 8.4, 8.5, 9.1). It
// turns object targets and the robot's state into hand targets, motion priority, body-schema
// segments and walking goals. Modules never touch DDS: they talk to the world through a
// ModuleContext, so the same module runs in the behavior process (reflex_behavior, over the bus), on
// its own (reflex_behavior --module NAME) or in a unit test with fake inputs.
//
// Life cycle (called by the BehaviorHost, always from one thread):
//   1. construct(name)        by the registry's factory; no I/O.
//   2. configure(config, robot)  read and validate every key; throw ConfigError naming
//                              file/key/value on any bad one. No outputs yet. claims() is valid after.
//   3. start(ctx)             publish the initial outputs (e.g. attach a segment, hands "no target").
//   4. onObjects(frame, ctx)  on every accepted ObjectTargets frame (only validated objects: finite,
//                              known names, not from the future); onJointState(ctx) after every
//                              accepted joint state (ctx.robot() is updated); step(ctx) every
//                              stepPeriod() seconds if > 0. Never throw here: a bad situation gives a
//                              safe output (no target) and a log line. What a module throws anyway
//                              (a std::exception or not) ends the run as a ModuleError naming the
//                              call, the module and its plugin (host.hpp).
//   5. stop(ctx)              remove everything the module added: detach its segments, its hands to
//                              "no target", the priority back to equal, walking stopped. The host
//                              checks afterwards and removes (and reports) whatever is left.
//
// Outputs go through ctx and only to what claims() declared: a module writing an output it did not
// claim is a programming error (std::logic_error, reported by the host as a ModuleError). Two modules
// of one process may not claim the same output (the host refuses the configuration), so one
// HandTargets sample merges the hands of several modules.
//
// To write a module: derive from Module, implement the five calls, and register a factory
// (registry.hpp, ModuleRegistry::add). modules/README.md has the walk-through.
#pragma once

#include "reflex/modules/config.hpp"
#include "reflex/modules/robot_state.hpp"
#include "reflex/modules/types.hpp"

#include <string>
#include <vector>

namespace reflex::modules {

/// What a module writes (and reads). Declared after configure(), fixed afterwards.
struct Claims {
  bool hands[2] = {false, false};     ///< indexed by handIndex(Hand)
  bool priority = false;              ///< motion priority between the arms
  bool walk = false;                  ///< walking commands
  std::vector<std::string> segments;  ///< body-schema segment names it attaches
  bool objects = false;               ///< wants onObjects (the process then subscribes to object targets)
};

/// The world as a module sees it during start / onObjects / onJointState / step / stop.
class ModuleContext {
 public:
  virtual ~ModuleContext() = default;
  /// Monotonic time [s] (see Now).
  virtual const Now& now() const = 0;
  virtual const RobotState& robot() const = 0;
  /// Sets the target of a claimed hand (published with the other hand's on change).
  virtual void setHand(Hand hand, const HandTarget& target) = 0;
  /// Sets the motion priority (claimed), published on change.
  virtual void setPriority(ArmPriority priority) = 0;
  /// Attaches or updates a claimed segment (published on change).
  virtual void attachSegment(const SegmentSpec& segment) = 0;
  /// Removes a claimed segment (published if it was attached).
  virtual void detachSegment(const std::string& name) = 0;
  /// Sends a walking command (claimed), published on change.
  virtual void setWalk(const WalkGoal& goal) = 0;
  /// A line for the process log, prefixed with the module name.
  virtual void log(const std::string& line) = 0;
};

class Module {
 public:
  explicit Module(std::string name) : name_(std::move(name)) {}
  virtual ~Module() = default;
  Module(const Module&) = delete;
  Module& operator=(const Module&) = delete;

  /// Instance name (unique in a configuration; also the process name with --module).
  const std::string& name() const { return name_; }

  virtual void configure(const ConfigNode& config, const RobotState& robot) = 0;
  virtual Claims claims() const = 0;
  /// Period of step() [s]; 0 = never stepped (purely input-driven).
  virtual double stepPeriod() const { return 0.0; }
  virtual void start(ModuleContext& ctx) = 0;
  virtual void onObjects(const ObjectsFrame& /*frame*/, ModuleContext& /*ctx*/) {}
  virtual void onJointState(ModuleContext& /*ctx*/) {}
  virtual void step(ModuleContext& /*ctx*/) {}
  virtual void stop(ModuleContext& ctx) = 0;
  /// One line of state for the heartbeat detail and the exit report (e.g. "left=can right=cup").
  virtual std::string status() const { return {}; }

 private:
  std::string name_;
};

}  // namespace reflex::modules
