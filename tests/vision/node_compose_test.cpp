// reflex::vision_node composed in one process (domain 222): two VisionNodes replay
// the same generated session under two module names, and a reader in the same process checks every
// published object against the session's ground truth (the renderer's tag positions). Stopping one
// node (stop()) ends its run() alone: the other keeps publishing. Then the program, not the library,
// installs the signal handler (bus::StopOnSignal on the second node) and raises SIGTERM: that node
// stops cleanly and this process goes on.
#include "reflex/vision_node/vision_node.hpp"
#include "vision_test_util.hpp"

#include <reflex/bus/bus.hpp>
#include <reflex/msg/vision.h>

#include <gtest/gtest.h>

#include <chrono>
#include <csignal>
#include <map>
#include <thread>

using namespace reflex::vision;
using namespace reflex::vision::test;
namespace vn = reflex::vision_node;

namespace {

constexpr int kDomain = 222;

vn::NodeOptions nodeOptions(const std::string& session, const std::string& name, const std::string& frame_id) {
  vn::NodeOptions o;
  o.session = session;
  o.replay.loop = true;  // until stopped
  o.module_name = name;
  o.frame_id = frame_id;
  o.domain_id = kDomain;
  return o;
}

double secondsSince(std::chrono::steady_clock::time_point t) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t).count();
}

}  // namespace

TEST(VisionNode, TwoNodesInOneProcessMatchGroundTruthAndStopApart) {
  TempDir dir("node_compose");
  makeSession(parseSceneScript(nearScript(3.0), "near"), dir / "s");
  const std::vector<GroundTruthRow> truth = loadGroundTruth(dir / "s/ground_truth.csv");

  reflex::bus::BusConfig config;
  config.module_name = "vision_compose_test";
  config.domain_id = kDomain;
  reflex::bus::Participant bus(config);
  auto& reader = bus.makeReader<reflex::msg::ObjectTargets>();
  std::map<std::string, std::vector<reflex::msg::ObjectTargets>> got;  // by Header.source
  reader.onData([&](const reflex::msg::ObjectTargets& s) { got[s.header().source()].push_back(s); });
  const auto count = [&](const std::string& source) { return got.count(source) ? got[source].size() : 0u; };
  // Reads until `done` or `seconds` passed; true if done.
  const auto readUntil = [&](const auto& done, double seconds) {
    const auto t0 = std::chrono::steady_clock::now();
    while (!done() && secondsSince(t0) < seconds) bus.runFor(std::chrono::milliseconds(50));
    return done();
  };

  vn::VisionNode a(nodeOptions(dir / "s", "vision_a", "base_link"));
  vn::VisionNode b(nodeOptions(dir / "s", "vision_b", "base_b"));
  ASSERT_NE(a.bus(), nullptr);
  ASSERT_NE(b.bus(), nullptr);
  std::atomic<bool> a_done{false}, b_done{false};
  std::string a_error, b_error;
  // Each node's run() on its own thread, as a program composing them would.
  const auto runOn = [](vn::VisionNode& node, std::atomic<bool>& done, std::string& error) {
    return std::thread([&node, &done, &error] {
      try {
        node.run();
      } catch (const std::exception& e) {
        error = e.what();
      }
      done.store(true);
    });
  };
  std::thread ta = runOn(a, a_done, a_error);
  std::thread tb = runOn(b, b_done, b_error);
  struct Join {  // a failed ASSERT below must not leave joinable threads behind (std::terminate)
    vn::VisionNode &a, &b;
    std::thread &ta, &tb;
    ~Join() {
      a.stop();
      b.stop();
      ta.join();
      tb.join();
    }
  } join{a, b, ta, tb};

  // Both publish (discovery takes seconds on a loaded machine).
  // 20 samples = 2 s at 10 Hz, each with up to two objects (the session hides one for a while).
  ASSERT_TRUE(readUntil([&] { return count("vision_a") >= 20 && count("vision_b") >= 20; }, 60.0))
      << "vision_a " << count("vision_a") << ", vision_b " << count("vision_b");

  // Stop b alone: its run() returns promptly; a keeps publishing.
  const auto t_stop = std::chrono::steady_clock::now();
  b.stop();
  ASSERT_TRUE(readUntil([&] { return b_done.load(); }, 5.0)) << "b.run() did not return after b.stop()";
  EXPECT_LT(secondsSince(t_stop), 1.5);
  EXPECT_EQ(b_error, "");
  EXPECT_TRUE(b.stats().end_message.empty()) << b.stats().end_message;
  bus.runFor(std::chrono::milliseconds(300));  // anything b sent before it stopped has arrived
  const std::size_t b_final = count("vision_b"), a_at_stop = count("vision_a");
  EXPECT_TRUE(readUntil([&] { return count("vision_a") >= a_at_stop + 15; }, 30.0))
      << "vision_a published " << count("vision_a") - a_at_stop << " samples after vision_b stopped";
  EXPECT_FALSE(a_done.load()) << "stopping b ended a's run(): " << a_error;
  EXPECT_EQ(count("vision_b"), b_final) << "b published after its run() returned";

  // The signal handler belongs to the program: installed on a's participant, SIGTERM stops a only.
  {
    reflex::bus::StopOnSignal stop_on_signal(*a.bus());
    const auto t_signal = std::chrono::steady_clock::now();
    std::raise(SIGTERM);
    EXPECT_TRUE(readUntil([&] { return a_done.load(); }, 5.0)) << "SIGTERM did not stop a";
    EXPECT_LT(secondsSince(t_signal), 1.5);
    EXPECT_EQ(stop_on_signal.lastSignal(), SIGTERM);
  }
  EXPECT_EQ(a_error, "");
  EXPECT_TRUE(a.stats().end_message.empty()) << a.stats().end_message;
  EXPECT_GT(a.stats().frames, b.stats().frames);

  // Every published object against the ground truth, per node; header and frame name per node.
  for (const auto& [source, frame_id] :
       std::map<std::string, std::string>{{"vision_a", "base_link"}, {"vision_b", "base_b"}}) {
    int compared = 0;
    const std::vector<reflex::msg::ObjectTargets>& samples = got[source];
    for (std::size_t i = 0; i < samples.size(); ++i) {
      const reflex::msg::ObjectTargets& s = samples[i];
      EXPECT_EQ(s.frame_id(), frame_id);
      if (i > 0) {
        EXPECT_GT(s.header().seq(), samples[i - 1].header().seq()) << source;
      }
      for (const reflex::msg::ObjectTarget& o : s.objects()) {
        for (const GroundTruthRow& g : truth) {  // image_index is the pair index within a pass
          if (g.frame != static_cast<int>(s.image_index()) || g.object != o.name()) continue;
          ASSERT_TRUE(g.present) << source << " invented " << o.name() << " at frame " << g.frame;
          const cv::Vec3d p(o.position_base().x(), o.position_base().y(), o.position_base().z());
          if (g.visible) {
            EXPECT_LT(cv::norm(p - g.p_B), 0.005) << source << ' ' << o.name() << " frame " << g.frame;
            ++compared;
          }
        }
      }
    }
    std::cout << source << ": " << samples.size() << " samples, " << compared << " objects compared\n";
    EXPECT_GE(compared, 15) << source;
  }
}
