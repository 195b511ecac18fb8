#include "reflex/bus/outbox.hpp"

#include <cerrno>
#include <cstdio>
#include <ctime>

namespace reflex::bus {

Outbox::Outbox(std::string name, std::chrono::milliseconds stall_report, std::chrono::milliseconds close_budget)
    : name_(std::move(name)),
      stall_s_(std::chrono::duration<double>(stall_report).count()),
      close_budget_(close_budget) {
  sem_init(&wake_, 0, 0);
}

Outbox::~Outbox() {
  close();
  sem_destroy(&wake_);
}

void Outbox::start() {
  if (thread_.joinable() || stop_.load()) return;
  thread_ = std::thread([this] { loop(); });
}

void Outbox::drainAll() {
  OutboxStats pass;
  std::string stall_topic;
  double stall_time = 0.0;
  const auto until = deadline();
  for (auto& q : queues_) q->drain(pass, stall_s_, stall_topic, stall_time, until);
  std::uint64_t dropped = 0;
  for (const auto& q : queues_) dropped += q->dropped();
  {
    std::lock_guard<std::mutex> lock(stats_mu_);
    totals_.written += pass.written;
    totals_.write_failures += pass.write_failures;
    totals_.stalls += pass.stalls;
    if (pass.longest_write_s > totals_.longest_write_s) {
      totals_.longest_write_s = pass.longest_write_s;
      totals_.longest_topic = pass.longest_topic;
    }
  }
  // Said on stderr, at most once a second: a stall, or samples dropped since the last report.
  const auto now = std::chrono::steady_clock::now();
  if ((stall_time > 0.0 || dropped > dropped_reported_) && now - last_report_ >= std::chrono::seconds(1)) {
    last_report_ = now;
    if (stall_time > 0.0) {
      std::fprintf(stderr,
                   "%s: writing %s took %.0f ms (a reader process died? Fast DDS's shared-memory port check); "
                   "the control loop did not wait: %llu output samples dropped so far\n",
                   name_.c_str(), stall_topic.c_str(), 1e3 * stall_time, static_cast<unsigned long long>(dropped));
    } else {
      std::fprintf(stderr, "%s: %llu output samples dropped so far (the bus writer could not keep up)\n", name_.c_str(),
                   static_cast<unsigned long long>(dropped));
    }
    dropped_reported_ = dropped;
  }
}

void Outbox::loop() {
  while (!stop_.load()) {
    timespec until{};
    clock_gettime(CLOCK_REALTIME, &until);
    until.tv_nsec += 100000000L;  // a pass at least every 100 ms even without a wake-up
    if (until.tv_nsec >= 1000000000L) {
      until.tv_nsec -= 1000000000L;
      ++until.tv_sec;
    }
    while (sem_timedwait(&wake_, &until) != 0 && errno == EINTR) {
    }
    while (sem_trywait(&wake_) == 0) {  // one pass takes everything queued: fold the pending wake-ups
    }
    drainAll();
  }
  drainAll();  // what was queued before close()
}

std::chrono::steady_clock::time_point Outbox::deadline() const {
  const std::int64_t ns = deadline_ns_.load();
  if (ns == std::numeric_limits<std::int64_t>::max()) return std::chrono::steady_clock::time_point::max();
  return std::chrono::steady_clock::time_point(std::chrono::nanoseconds(ns));
}

void Outbox::close() {
  if (deadline_ns_.load() == std::numeric_limits<std::int64_t>::max()) {
    deadline_ns_.store(std::chrono::duration_cast<std::chrono::nanoseconds>(
                           (std::chrono::steady_clock::now() + close_budget_).time_since_epoch())
                           .count());
  }
  if (stop_.exchange(true)) {
    if (thread_.joinable()) thread_.join();
    return;
  }
  sem_post(&wake_);
  if (thread_.joinable()) {
    thread_.join();
  } else {
    drainAll();  // never started: write what was queued here
  }
}

OutboxStats Outbox::stats() const {
  OutboxStats s;
  {
    std::lock_guard<std::mutex> lock(stats_mu_);
    s = totals_;
  }
  s.queued = 0;
  s.dropped = 0;
  for (const auto& q : queues_) {
    s.queued += q->queued();
    s.dropped += q->dropped();
  }
  return s;
}

}  // namespace reflex::bus
