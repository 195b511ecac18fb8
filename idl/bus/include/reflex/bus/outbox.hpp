// A real-time loop's DDS writes, off the loop's thread (reflex_controller's 5 ms loop; a robot
// driver's servo loop). A DDS write can block: on Fast DDS 2.9's shared-memory transport a writer
// whose reader process was killed waits for that port's health check, about 1 s, in the write call
// (idl/README.md), and a reliable writer with a full history waits max_blocking_time. Written from
// the controller's loop, that froze it — no distance computed, no e-stop possible — because some
// OTHER process died or lagged.
//
// Contract:
//  - queue (OutboxQueue<T>, made by Outbox::add before start): a preallocated ring of `capacity`
//    samples of one topic, every slot a copy of a prototype and then given `reserve` (a copy of a
//    string does not keep its capacity: `reserve` reserves every string a sample may carry to its
//    longest value). Then same-size vectors and strings within those capacities copy into a slot
//    without allocating.
//  - push (the loop's thread): stamps the sample's header (Writer::stamp: the time and the
//    sequence number are the control cycle's; a type without a Reflex header, such as a robot's own
//    Unitree LowCmd_, is queued as it is) and copies it into the ring. No allocation (see
//    above), no I/O, no lock, no system call, never throws. A full ring (the writer thread is stuck
//    in a write) drops the sample and counts it; its sequence number is used, so every reader sees
//    the gap. Nothing is lost silently.
//  - notify (the loop's thread, once per cycle): wakes the writer thread (sem_post: one futex wake
//    at most, no allocation).
//  - the writer thread writes every queued sample in order, each topic's in push order; it times
//    every write and, when one takes longer than `stall_report` (50 ms), says so on stderr (rate
//    limited) with the topic, the time and what was dropped meanwhile.
//  - close: wakes the thread, which writes what is queued — for at most `close_budget` (1 s): a stuck
//    writer does not hold up the process's exit; what is left is dropped and counted — and exits;
//    joined. Idempotent.
// Single producer (push, notify), single consumer (the writer thread), per queue.
#pragma once

#include "reflex/bus/participant.hpp"

#include <semaphore.h>

#include <atomic>
#include <chrono>
#include <cstdint>
#include <functional>
#include <limits>
#include <memory>
#include <mutex>
#include <stdexcept>
#include <string>
#include <thread>
#include <type_traits>
#include <utility>
#include <vector>

namespace reflex::bus {

/// What the outbox did, over its life (totals).
struct OutboxStats {
  std::uint64_t queued = 0;          ///< samples pushed and queued
  std::uint64_t written = 0;         ///< samples the middleware accepted
  std::uint64_t write_failures = 0;  ///< samples the middleware refused (write() false)
  std::uint64_t dropped = 0;         ///< samples dropped: their ring was full, or close() ran out of time
  std::uint64_t stalls = 0;          ///< writes that took longer than the stall threshold
  double longest_write_s = 0.0;      ///< the longest single write
  std::string longest_topic;         ///< its topic ("" if nothing was written)
};

namespace detail {
/// True for a type with a Reflex Header (`sample.header().seq()`), which push() stamps (a ROS 2
/// std_msgs/Header has no seq: sent as it is).
template <class T, class = void>
struct HasHeader : std::false_type {};
template <class T>
struct HasHeader<T, std::void_t<decltype(std::declval<T&>().header().seq())>> : std::true_type {};

class OutboxQueueBase {
 public:
  virtual ~OutboxQueueBase() = default;
  /// Writer thread: writes every queued sample; adds to the totals. Past `deadline` (close()) the
  /// rest is dropped and counted instead of written.
  virtual void drain(OutboxStats& totals, double stall_s, std::string& stall_topic, double& stall_time,
                     std::chrono::steady_clock::time_point deadline) = 0;
  virtual std::uint64_t dropped() const noexcept = 0;
  virtual std::uint64_t queued() const noexcept = 0;
};
}  // namespace detail

/// One topic's ring. Made by Outbox::add; owned by the outbox.
template <class T>
class OutboxQueue final : public detail::OutboxQueueBase {
 public:
  OutboxQueue(Writer<T>& writer, std::size_t capacity, const T& prototype, const std::function<void(T&)>& reserve)
      : writer_(writer), ring_(capacity, prototype) {
    if (reserve)
      for (T& slot : ring_) reserve(slot);
  }

  /// The loop's thread: stamps `sample`'s header and queues a copy. False if the sample was refused
  /// (a @key string too long: counted by the writer) or the ring was full (dropped, counted).
  bool push(T& sample) noexcept {
    if constexpr (detail::HasHeader<T>::value) {
      if (!writer_.stamp(sample)) return false;
    }
    const std::uint64_t head = head_.load(std::memory_order_relaxed);
    if (head - tail_.load(std::memory_order_acquire) >= ring_.size()) {
      dropped_.fetch_add(1, std::memory_order_relaxed);
      return false;
    }
    ring_[head % ring_.size()] = sample;
    head_.store(head + 1, std::memory_order_release);
    return true;
  }
  std::uint64_t dropped() const noexcept override { return dropped_.load(std::memory_order_relaxed); }
  std::uint64_t queued() const noexcept override { return head_.load(std::memory_order_relaxed); }
  const std::string& topicName() const { return writer_.topicName(); }

  void drain(OutboxStats& totals, double stall_s, std::string& stall_topic, double& stall_time,
             std::chrono::steady_clock::time_point deadline) override {
    const std::uint64_t head = head_.load(std::memory_order_acquire);
    for (std::uint64_t tail = tail_.load(std::memory_order_relaxed); tail != head; ++tail) {
      const auto t0 = std::chrono::steady_clock::now();
      if (t0 > deadline) {  // closing, out of time: the rest is dropped, counted
        dropped_.fetch_add(head - tail, std::memory_order_relaxed);
        tail_.store(head, std::memory_order_release);
        return;
      }
      const bool ok = writer_.write(ring_[tail % ring_.size()]);
      const double dt = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
      tail_.store(tail + 1, std::memory_order_release);  // the slot is free once written
      ++(ok ? totals.written : totals.write_failures);
      if (dt > totals.longest_write_s) {
        totals.longest_write_s = dt;
        totals.longest_topic = writer_.topicName();
      }
      if (dt > stall_s) {
        ++totals.stalls;
        if (dt > stall_time) {
          stall_time = dt;
          stall_topic = writer_.topicName();
        }
      }
    }
  }

 private:
  Writer<T>& writer_;
  std::vector<T> ring_;
  std::atomic<std::uint64_t> head_{0};  // next slot push writes (producer)
  std::atomic<std::uint64_t> tail_{0};  // next slot the writer thread writes (consumer)
  std::atomic<std::uint64_t> dropped_{0};
};

class Outbox {
 public:
  /// `name` prefixes the stall lines on stderr ("reflex_controller"). `stall_report`: a write longer
  /// than this is a stall (counted, reported). `close_budget`: how long close() keeps writing.
  explicit Outbox(std::string name, std::chrono::milliseconds stall_report = std::chrono::milliseconds(50),
                  std::chrono::milliseconds close_budget = std::chrono::milliseconds(1000));
  ~Outbox();
  Outbox(const Outbox&) = delete;
  Outbox& operator=(const Outbox&) = delete;

  /// Before start(): a ring of `capacity` samples for `writer`, each slot a copy of `prototype` given
  /// `reserve` (may be empty: a type without strings that grow).
  template <class T>
  OutboxQueue<T>& add(Writer<T>& writer, const T& prototype, std::size_t capacity = 64,
                      const std::function<void(T&)>& reserve = {}) {
    if (capacity == 0) throw std::invalid_argument("Outbox::add: capacity must be positive");
    if (thread_.joinable() || stop_.load())
      throw std::logic_error("Outbox::add after start() or close(): the writer thread reads the queue list");
    auto q = std::make_unique<OutboxQueue<T>>(writer, capacity, prototype, reserve);
    OutboxQueue<T>& ref = *q;
    queues_.push_back(std::move(q));
    return ref;
  }
  /// Starts the writer thread (once).
  void start();
  /// The loop's thread: wakes the writer thread. No allocation, never throws.
  void notify() noexcept { sem_post(&wake_); }
  /// Writes what is queued, stops and joins the writer thread. Idempotent.
  void close();
  /// Totals so far (as of the writer thread's last pass; exact after close()).
  OutboxStats stats() const;

 private:
  void loop();
  void drainAll();
  std::chrono::steady_clock::time_point deadline() const;

  std::string name_;
  double stall_s_;
  std::chrono::milliseconds close_budget_;
  std::atomic<std::int64_t> deadline_ns_{std::numeric_limits<std::int64_t>::max()};  // steady clock; set by close()
  std::vector<std::unique_ptr<detail::OutboxQueueBase>> queues_;
  sem_t wake_{};
  std::atomic<bool> stop_{false};
  std::thread thread_;
  mutable std::mutex stats_mu_;  // the writer thread (after each pass) and stats(); never the control thread
  OutboxStats totals_;
  std::uint64_t dropped_reported_ = 0;
  std::chrono::steady_clock::time_point last_report_{};
};

}  // namespace reflex::bus
