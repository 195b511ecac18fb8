// The heartbeat every Reflex process publishes on "reflex/heartbeat" (profile reflex_heartbeat):
// module name (the participant's), host, pid, life-cycle state, period. The writer's liveliness is
// MANUAL_BY_TOPIC, so a process that stops publishing heartbeats (hung or dead) is declared not alive
// to every reader once the profile's lease (1.5 s) passes.
//
//   reflex::bus::Participant bus(config);
//   reflex::bus::HeartbeatPublisher heartbeat(bus);          // every 500 ms from inside bus.run()
//   heartbeat.setState(reflex::msg::STATE_RUNNING);          // publishes at once
//   bus.run();
//   heartbeat.setState(reflex::msg::STATE_STOPPING);
#pragma once

#include <chrono>
#include <string>

#include "reflex/bus/participant.hpp"

namespace reflex::bus {

class HeartbeatPublisher {
 public:
  /// Makes the heartbeat writer, publishes STATE_CONFIGURING at once, and registers a timer that
  /// republishes the current state every `period` inside bus.run(). Throws BusError if `period` is
  /// not positive or not shorter than the writer's liveliness lease (it would be declared dead).
  explicit HeartbeatPublisher(Participant& bus, std::chrono::milliseconds period = std::chrono::milliseconds(500));
  HeartbeatPublisher(const HeartbeatPublisher&) = delete;
  HeartbeatPublisher& operator=(const HeartbeatPublisher&) = delete;

  /// Sets the state (and a free-text detail, e.g. the error) and publishes it at once. Call it from
  /// the thread that runs the bus loop.
  void setState(reflex::msg::ModuleState state, const std::string& detail = {});
  const reflex::msg::Heartbeat& last() const { return sample_; }

 private:
  Writer<reflex::msg::Heartbeat>& writer_;
  reflex::msg::Heartbeat sample_;
};

}  // namespace reflex::bus
