// Helpers for the behavior-module tests: a sink that records every output of a host, a host built
// from YAML text, and frames of fake object targets.
#pragma once

#include <reflex/modules/host.hpp>
#include <reflex/modules/registry.hpp>

#include <gtest/gtest.h>

#include <memory>
#include <string>
#include <utility>
#include <vector>

namespace reflex::modules::testing {

/// Records every output of a BehaviorHost in order.
class RecordingSink final : public OutputSink {
 public:
  struct Hands {
    HandTarget left, right;
  };
  std::vector<Hands> hands;
  std::vector<ArmPriority> priorities;
  std::vector<SegmentSpec> attached;
  std::vector<std::string> detached;
  std::vector<WalkGoal> walks;
  std::vector<std::string> events;  ///< "hands", "priority", "attach:<name>", "detach:<name>", "walk"

  void handTargets(const HandTarget& l, const HandTarget& r) override {
    hands.push_back({l, r});
    events.push_back("hands");
  }
  void motionPriority(ArmPriority p) override {
    priorities.push_back(p);
    events.push_back("priority");
  }
  void segmentAttached(const SegmentSpec& s) override {
    attached.push_back(s);
    events.push_back("attach:" + s.name);
  }
  void segmentDetached(const std::string& name) override {
    detached.push_back(name);
    events.push_back("detach:" + name);
  }
  void walk(const WalkGoal& g) override {
    walks.push_back(g);
    events.push_back("walk");
  }
};

/// Wall clock of the fake world: 1e18 ns plus t seconds.
inline Now at(double t) { return Now{t, static_cast<std::int64_t>(1e18) + static_cast<std::int64_t>(t * 1e9)}; }

inline ObjectObservation object(const std::string& name, const Eigen::Vector3d& p_B, double confidence = 1.0) {
  ObjectObservation o;
  o.name = name;
  o.p_B = p_B;
  o.confidence = confidence;
  return o;
}

/// A frame captured and stamped at t (the fake wall clock).
inline ObjectsFrame frameAt(double t, std::vector<ObjectObservation> objects) {
  ObjectsFrame f;
  f.stamp_ns = at(t).wall_ns;
  f.capture_stamp_ns = f.stamp_ns;
  f.source = "vision";  // written by the default object source (InputPolicy::object_sources)
  f.objects = std::move(objects);
  return f;
}

/// A host plus its recording sink and log, built from configuration text.
struct TestHost {
  RecordingSink sink;
  std::vector<std::string> log;
  std::unique_ptr<BehaviorHost> host;

  explicit TestHost(const std::string& yaml, const ModuleRegistry& registry = builtinRegistry(),
                    const std::string& only = "") {
    const HostConfig config = parseHostConfig(ConfigNode::loadString(yaml, "test.yaml"), registry);
    host = std::make_unique<BehaviorHost>(
        config, registry, sink, [this](const std::string& l) { log.push_back(l); }, only);
  }
  BehaviorHost* operator->() { return host.get(); }
  const HandTarget& lastHand(Hand h) const {
    return h == Hand::kLeft ? sink.hands.back().left : sink.hands.back().right;
  }
};

/// Shoulder of the default robot at rest, from its kinematics.
inline Eigen::Vector3d shoulder(const BehaviorHost& host, Hand h) { return host.robot().shoulder_B(h); }

}  // namespace reflex::modules::testing
