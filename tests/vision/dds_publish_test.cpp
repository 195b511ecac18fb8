// reflex_vision over real DDS (domain 85): the real executable replays a generated session and
// publishes reflex/object_targets; this process reads them with reflex::bus and checks the rate
// (10 Hz +- 2 % from the publisher's header stamps), the header, and the positions against the
// session's ground truth.
#include "support/child_process.hpp"
#include "vision_test_util.hpp"

#include <reflex/bus/bus.hpp>
#include <reflex/msg/vision.h>

#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <csignal>
#include <cstdlib>
#include <thread>

using namespace reflex::vision;
using namespace reflex::vision::test;

TEST(VisionDds, PublishesObjectTargetsAt10HzMatchingGroundTruth) {
  TempDir dir("dds");
  makeSession(parseSceneScript(nearScript(5.0), "near"), dir / "s");
  const std::vector<GroundTruthRow> truth = loadGroundTruth(dir / "s/ground_truth.csv");

  reflex::bus::BusConfig config;
  config.module_name = "vision_dds_test";
  config.domain_id = 85;
  reflex::bus::Participant bus(config);
  auto& reader = bus.makeReader<reflex::msg::ObjectTargets>();
  std::vector<reflex::msg::ObjectTargets> got;
  reader.onData([&](const reflex::msg::ObjectTargets& s) { got.push_back(s); });

  const std::string cmd = std::string(REFLEX_BIN_DIR) + "/reflex_vision --session " + (dir / "s") +
                          " --domain 85 --loop --duration 8 --quiet > " + (dir / "log.txt") + " 2>&1";
  int rc = -1;
  std::atomic<bool> done{false};
  std::thread vision([&] {
    rc = std::system(cmd.c_str());
    done.store(true);
  });
  // Read until the process has exited (bounded), however long start-up takes on a loaded machine.
  for (int i = 0; i < 900 && !done.load(); ++i) bus.runFor(std::chrono::milliseconds(100));
  bus.runFor(std::chrono::milliseconds(200));
  vision.join();
  ASSERT_EQ(rc, 0) << readText(dir / "log.txt");

  // 8 s (the 5 s session looped) at 10 Hz = 80 publications; best effort loses those sent before
  // discovery completes, which takes seconds on a loaded machine.
  ASSERT_GE(got.size(), 30u);
  // Rate from the writer's sequence numbers and header stamps (robust to a lost sample).
  const double mean_period = 1e-9 * static_cast<double>(got.back().header().stamp_ns() - got.front().header().stamp_ns()) /
                             static_cast<double>(got.back().header().seq() - got.front().header().seq());
  std::cout << got.size() << " samples, mean period " << 1000.0 * mean_period << " ms\n";
  EXPECT_NEAR(1.0 / mean_period, 10.0, 0.2);
  int compared = 0;
  for (std::size_t i = 0; i < got.size(); ++i) {
    const reflex::msg::ObjectTargets& s = got[i];
    EXPECT_EQ(s.header().source(), "vision");
    EXPECT_EQ(s.frame_id(), "base_link");
    if (i > 0) {
      EXPECT_GT(s.header().seq(), got[i - 1].header().seq());
      EXPECT_GE(s.capture_stamp_ns(), got[i - 1].capture_stamp_ns());
    }
    // Captured (on the replay clock) before it was published, and not long before (the bound is
    // loose for a CPU-starved CI machine; runner frames late by a period are dropped).
    EXPECT_LE(s.capture_stamp_ns(), s.header().stamp_ns() + 5'000'000);
    EXPECT_GT(s.capture_stamp_ns(), s.header().stamp_ns() - 1'000'000'000);
    for (const reflex::msg::ObjectTarget& o : s.objects()) {
      for (const GroundTruthRow& g : truth) {  // image_index is the pair index within a pass
        if (g.frame != static_cast<int>(s.image_index()) || g.object != o.name()) continue;
        ASSERT_TRUE(g.present) << "invented " << o.name() << " at frame " << g.frame;
        const cv::Vec3d p(o.position_base().x(), o.position_base().y(), o.position_base().z());
        if (g.visible) {
          EXPECT_LT(cv::norm(p - g.p_B), 0.005) << o.name() << " frame " << g.frame;
          ++compared;
        }
        EXPECT_GE(o.confidence(), 0.0);
        EXPECT_LE(o.confidence(), 1.0);
      }
    }
  }
  EXPECT_GT(compared, 50);
}

// Issue 16, item 13: the publishing reflex_vision (DDS path: the bus loop on the main thread, vision
// on a worker) ends within a second of SIGTERM while the replay waits 9.5 s for the next frame (a
// valid gap). Before, the worker slept through the whole wait after the bus had stopped (on stamps
// near 1e17 s it spun for 14 minutes). Domain 85.
TEST(VisionDds, SigtermEndsTheProcessWithinASecondDuringAWait) {
  TempDir dir("dds_term");
  makeSession(parseSceneScript(nearScript(1.0), "near"), dir / "s");
  std::string ts = "frame,stamp\n";
  for (int k = 0; k < 10; ++k) ts += std::to_string(k) + "," + std::to_string(0.1 * k + (k >= 3 ? 9.5 : 0.0)) + "\n";
  writeText(dir / "s/timestamps.csv", ts);
  reflex::testing::ChildProcess p({std::string(REFLEX_BIN_DIR) + "/reflex_vision", "--session", dir / "s", "--domain",
                                   "85", "--progress"},
                                  dir / "log.txt");
  ASSERT_TRUE(p.started());
  const auto t0 = std::chrono::steady_clock::now();
  const auto since = [](std::chrono::steady_clock::time_point t) {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - t).count();
  };
  while (readText(dir / "log.txt").find("[pass 1]") == std::string::npos && since(t0) < 30.0)
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  ASSERT_NE(readText(dir / "log.txt").find("[pass 1]"), std::string::npos) << readText(dir / "log.txt");
  std::this_thread::sleep_for(std::chrono::milliseconds(800));  // inside the 9.5 s wait for frame 3
  const auto t_signal = std::chrono::steady_clock::now();
  p.signal(SIGTERM);
  EXPECT_EQ(p.wait(std::chrono::milliseconds(1500)), 0) << readText(dir / "log.txt");
  EXPECT_LT(since(t_signal), 1.5);
}
