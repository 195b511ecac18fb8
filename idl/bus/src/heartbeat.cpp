#include "reflex/bus/heartbeat.hpp"

#include <unistd.h>

#include <climits>

namespace reflex::bus {

namespace {

std::string hostName() {
  char buf[HOST_NAME_MAX + 1] = {};
  if (::gethostname(buf, sizeof buf - 1) != 0) return "unknown";
  return buf;
}

}  // namespace

HeartbeatPublisher::HeartbeatPublisher(Participant& bus, std::chrono::milliseconds period)
    : writer_(bus.makeWriter<reflex::msg::Heartbeat>()) {
  if (period.count() <= 0) {
    throw BusError("heartbeat period must be > 0 ms, got " + std::to_string(period.count()) + " ms");
  }
  const auto& lease = writer_.native().get_qos().liveliness().lease_duration;
  if (lease != eprosima::fastrtps::c_TimeInfinite) {
    const auto lease_ms = static_cast<long long>(lease.seconds) * 1000 + lease.nanosec / 1'000'000;
    if (period.count() >= lease_ms) {
      throw BusError("heartbeat period " + std::to_string(period.count()) +
                     " ms is not shorter than the liveliness lease " + std::to_string(lease_ms) + " ms of profile '" +
                     writer_.profileName() + "'");
    }
  }
  sample_.module_name(bus.moduleName());
  sample_.host(hostName());
  sample_.pid(static_cast<std::int32_t>(::getpid()));
  sample_.period_ms(static_cast<std::uint32_t>(period.count()));
  setState(reflex::msg::STATE_CONFIGURING);
  bus.every(period, [this] { writer_.publish(sample_); });
}

void HeartbeatPublisher::setState(reflex::msg::ModuleState state, const std::string& detail) {
  sample_.state(state);
  sample_.detail(detail);
  writer_.publish(sample_);
}

}  // namespace reflex::bus
