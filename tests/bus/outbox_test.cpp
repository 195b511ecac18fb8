// The bus outbox (idl/bus/include/reflex/bus/outbox.hpp; reflex_controller's loop writes through
// it): the loop's samples reach a reader in push order, with the sequence numbers and stamps of the
// push (the control cycle), not of the later write; a full ring drops the newest, counts it and
// leaves a gap in the sequence numbers a reader can see; a push never allocates (counted by
// replacing operator new) and never waits for the writer thread, also while every write blocks for
// 200 ms. Real DDS entities (one participant, domain 223); the real controller with blocked writes
// is faults_process_test's ABusWriteThatBlocksNeverStopsTheControlLoop.
#include "support/count_allocations.hpp"

#include <reflex/bus/bus.hpp>
#include <reflex/bus/outbox.hpp>

#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <new>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

namespace reflex::bus {
namespace {

using namespace std::chrono_literals;
constexpr int kDomain = 223;

std::int64_t nowNs() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::system_clock::now().time_since_epoch())
      .count();
}

struct Bus {
  Participant p;
  Writer<msg::JointState>& writer;
  Reader<msg::JointState>& reader;
  explicit Bus(const std::string& topic)
      : p([] {
          BusConfig c;
          c.module_name = "outbox_test";
          c.domain_id = kDomain;
          return c;
        }()),
        writer(p.makeWriter<msg::JointState>(topic, kProfileState)),
        reader(p.makeReader<msg::JointState>(topic, kProfileRecord)) {
    EXPECT_TRUE(reader.waitForWriters(1, 10s));
  }
  // Every sample that arrives within `timeout`, until `n` did.
  std::vector<msg::JointState> receive(std::size_t n, std::chrono::milliseconds timeout) {
    std::vector<msg::JointState> got;
    const auto end = std::chrono::steady_clock::now() + timeout;
    while (got.size() < n && std::chrono::steady_clock::now() < end) {
      reader.takeAll(got);
      std::this_thread::sleep_for(2ms);
    }
    return got;
  }
};

msg::JointState prototype() {
  msg::JointState js;
  js.names({"a_joint", "b_joint", "c_joint"});
  js.positions().assign(3, 0.0);
  js.velocities().assign(3, 0.0);
  js.header().source("outbox_test");
  return js;
}

TEST(BusOutbox, SamplesArriveInPushOrderWithTheStampAndSequenceNumberOfThePush) {
  Bus bus("test/outbox_order");
  Outbox outbox("outbox_test");
  msg::JointState js = prototype();
  auto& q = outbox.add(bus.writer, js, 64);
  outbox.start();
  std::vector<std::int64_t> pushed_at;
  std::vector<msg::JointState> got;
  for (int burst = 0; burst < 10; ++burst) {  // 10 bursts of 40 (< 64: nothing dropped)
    for (int i = 0; i < 40; ++i) {
      const int k = burst * 40 + i;
      js.positions()[0] = k;
      js.positions()[2] = -0.5 * k;
      ASSERT_TRUE(q.push(js));
      pushed_at.push_back(nowNs());
      EXPECT_EQ(js.header().seq(), static_cast<std::uint64_t>(k + 1)) << "push stamps the caller's sample";
    }
    outbox.notify();
    const auto part = bus.receive(40, 5000ms);
    ASSERT_EQ(part.size(), 40U) << "burst " << burst;
    got.insert(got.end(), part.begin(), part.end());
  }
  outbox.close();
  ASSERT_EQ(got.size(), 400U);
  for (std::size_t k = 0; k < got.size(); ++k) {
    EXPECT_EQ(got[k].header().seq(), k + 1);
    EXPECT_EQ(got[k].positions()[0], static_cast<double>(k));
    EXPECT_EQ(got[k].positions()[2], -0.5 * static_cast<double>(k));
    EXPECT_LE(got[k].header().stamp_ns(), pushed_at[k]) << "stamped at the push, before it returned";
    if (k > 0) {
      EXPECT_GE(got[k].header().stamp_ns(), pushed_at[k - 1]) << "and after the previous push";
    }
  }
  const OutboxStats s = outbox.stats();
  EXPECT_EQ(s.queued, 400U);
  EXPECT_EQ(s.written, 400U);
  EXPECT_EQ(s.dropped, 0U);
  EXPECT_EQ(s.write_failures, 0U);
  EXPECT_EQ(s.longest_topic, "test/outbox_order");
  EXPECT_GT(s.longest_write_s, 0.0);
}

TEST(BusOutbox, AFullRingDropsTheNewestCountsItAndReadersSeeTheGap) {
  Bus bus("test/outbox_full");
  Outbox outbox("outbox_test");
  msg::JointState js = prototype();
  auto& q = outbox.add(bus.writer, js, 8);
  // The writer thread not started yet: the ring fills. 8 queued, 3 dropped (their numbers used).
  for (int k = 0; k < 11; ++k) {
    js.positions()[0] = k;
    EXPECT_EQ(q.push(js), k < 8) << k;
  }
  EXPECT_EQ(q.dropped(), 3U);
  outbox.start();
  EXPECT_THROW(outbox.add(bus.writer, js, 8), std::logic_error) << "the writer thread reads the queue list";
  outbox.notify();
  auto got = bus.receive(8, 5000ms);
  ASSERT_EQ(got.size(), 8U);
  for (std::size_t k = 0; k < 8; ++k) EXPECT_EQ(got[k].header().seq(), k + 1);
  js.positions()[0] = 11;
  ASSERT_TRUE(q.push(js));
  outbox.notify();
  got = bus.receive(1, 5000ms);
  ASSERT_EQ(got.size(), 1U);
  EXPECT_EQ(got[0].header().seq(), 12U) << "seq 9..11 were dropped: the reader sees the gap";
  EXPECT_EQ(got[0].positions()[0], 11.0);
  outbox.close();
  const OutboxStats s = outbox.stats();
  EXPECT_EQ(s.queued, 9U);
  EXPECT_EQ(s.written, 9U);
  EXPECT_EQ(s.dropped, 3U);
}

TEST(BusOutbox, APushAndANotifyNeverAllocate) {
  Bus bus("test/outbox_alloc");
  auto& status_writer = bus.p.makeWriter<msg::ControlStatus>("test/outbox_alloc_status", kProfileState);
  msg::JointState js = prototype();
  msg::ControlStatus st;
  st.header().source("outbox_test");
  const auto reserve = [](msg::ControlStatus& s) {
    s.left().closest_segment_a().reserve(kMaxKeyStringBytes);
    s.left().closest_segment_b().reserve(kMaxKeyStringBytes);
  };
  reserve(st);
  // Every value a cycle can put in: the longest segment name, a shorter one, new numbers. The writer
  // thread is not started (it allocates inside DDS, allowed there): counted here is the control
  // thread's push and notify, into empty slots (the first copy into each) and into a full ring.
  const std::string longest(kMaxKeyStringBytes, 'x');
  auto pushAll = [&](Outbox& outbox, OutboxQueue<msg::JointState>& qj, OutboxQueue<msg::ControlStatus>& qs) {
    const long before = testing::allocations();
    for (int k = 0; k < 100; ++k) {  // 64 queued per ring, 36 dropped
      js.positions()[1] = 0.001 * k;
      st.left().closest_segment_a().assign(k % 2 ? longest.c_str() : "l_forearm");
      st.left().closest_segment_b().assign(k % 3 ? "torso" : longest.c_str());
      st.left().distance(0.01 * k);
      qj.push(js);
      qs.push(st);
      outbox.notify();
    }
    return testing::allocations() - before;
  };
  Outbox outbox("outbox_test");
  auto& qj = outbox.add(bus.writer, js, 64);
  auto& qs = outbox.add<msg::ControlStatus>(status_writer, st, 64, reserve);
  EXPECT_EQ(pushAll(outbox, qj, qs), 0) << "push and notify on the control thread";
  EXPECT_EQ(qj.dropped(), 36U);
  EXPECT_EQ(qs.dropped(), 36U);
  outbox.start();
  outbox.close();
  EXPECT_EQ(outbox.stats().written, 128U);
  // The same without `reserve`: a slot's string is a copy of the prototype's, whose capacity a copy
  // does not keep, so the long names allocate: the count sees it (the test can fail).
  Outbox unreserved("outbox_test");
  auto& qj2 = unreserved.add(bus.writer, js, 64);
  msg::ControlStatus fresh;  // short strings, as a controller's status before its first cycle
  fresh.header().source("outbox_test");
  auto& qs2 = unreserved.add(status_writer, fresh, 64);
  EXPECT_GT(pushAll(unreserved, qj2, qs2), 0);
}

// A write that blocks, made here for certain: a RELIABLE, KEEP_ALL writer whose matched reader
// never takes its samples (the reader's history and then the writer's fill; each further write
// waits max_blocking_time, 200 ms). First what a loop that writes itself would suffer (the
// independent answer), then the same writer behind the outbox: the pushes stay fast, the writer
// thread reports the stalls, what could not wait is dropped and counted.
TEST(BusOutbox, AWriteThatBlocksNeverHoldsUpThePush) {
  const std::string xml = ::testing::TempDir() + "outbox_blocking_profiles.xml";
  {
    std::ofstream out(xml);
    out << R"(<?xml version="1.0" encoding="UTF-8"?>
<dds xmlns="http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles">
  <profiles>
    <participant profile_name="outbox_blocking_participant"><rtps><name>outbox_blocking</name></rtps></participant>
    <data_writer profile_name="outbox_blocking_writer">
      <qos>
        <reliability><kind>RELIABLE</kind><max_blocking_time><sec>0</sec><nanosec>200000000</nanosec></max_blocking_time></reliability>
      </qos>
      <topic>
        <historyQos><kind>KEEP_ALL</kind></historyQos>
        <resourceLimitsQos><max_samples>4</max_samples><max_instances>1</max_instances><max_samples_per_instance>4</max_samples_per_instance><allocated_samples>4</allocated_samples></resourceLimitsQos>
      </topic>
    </data_writer>
    <data_reader profile_name="outbox_blocking_reader">
      <qos><reliability><kind>RELIABLE</kind></reliability></qos>
      <topic>
        <historyQos><kind>KEEP_ALL</kind></historyQos>
        <resourceLimitsQos><max_samples>2</max_samples><max_instances>1</max_instances><max_samples_per_instance>2</max_samples_per_instance><allocated_samples>2</allocated_samples></resourceLimitsQos>
      </topic>
    </data_reader>
  </profiles>
</dds>
)";
  }
  BusConfig c;
  c.module_name = "outbox_test";
  c.domain_id = kDomain;
  c.profiles_file = xml;
  c.participant_profile = "outbox_blocking_participant";
  Participant p(c);
  auto& writer = p.makeWriter<msg::JointState>("test/outbox_blocking", "outbox_blocking_writer");
  auto& reader = p.makeReader<msg::JointState>("test/outbox_blocking", "outbox_blocking_reader");
  ASSERT_TRUE(reader.waitForWriters(1, 10s));
  msg::JointState js = prototype();

  // 1. Written directly: after the first few, every publish waits.
  double longest_direct = 0.0;
  for (int k = 0; k < 10; ++k) {
    const auto t0 = std::chrono::steady_clock::now();
    writer.publish(js);
    longest_direct =
        std::max(longest_direct, std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
  }
  EXPECT_GT(longest_direct, 0.15) << "the direct write blocks (the test can fail)";

  // 2. Behind the outbox, at the control loop's 200 Hz for 1 s.
  Outbox outbox("outbox_test", std::chrono::milliseconds(50));
  auto& q = outbox.add(writer, js, 16);
  outbox.start();
  double longest_push = 0.0;
  auto next = std::chrono::steady_clock::now();
  for (int k = 0; k < 200; ++k) {
    next += 5ms;
    std::this_thread::sleep_until(next);
    const auto t0 = std::chrono::steady_clock::now();
    js.positions()[0] = k;
    q.push(js);
    outbox.notify();
    longest_push = std::max(longest_push, std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
  }
  outbox.close();
  const OutboxStats s = outbox.stats();
  std::printf(
      "outbox: direct publish blocked up to %.0f ms; behind the outbox the longest push took %.1f us, the writer "
      "thread's longest write %.0f ms, %llu writes over 50 ms, %llu of 200 samples dropped\n",
      1e3 * longest_direct, 1e6 * longest_push, 1e3 * s.longest_write_s, static_cast<unsigned long long>(s.stalls),
      static_cast<unsigned long long>(s.dropped));
  // A push that waited for a write would take >= 150 ms (each write blocks that long here); 50 ms
  // leaves room for a loaded machine's preemption (2 ms did not always: the woken writer thread can
  // take the core from the pushing one).
  EXPECT_LT(longest_push, 0.050) << "a push never waits for the write";
  EXPECT_GT(s.longest_write_s, 0.15);
  EXPECT_GT(s.stalls, 0U);
  EXPECT_GT(s.dropped, 0U) << "200 samples in 1 s cannot all pass a writer that takes 200 ms each";
  EXPECT_EQ(s.written + s.write_failures + s.dropped, 200U)
      << "every sample written, refused or dropped and counted (close() gives the writer 1 s, then drops the rest)";
}

}  // namespace
}  // namespace reflex::bus
