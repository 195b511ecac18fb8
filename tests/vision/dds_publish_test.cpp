// reflex_vision over real DDS (domain 85): the real executable replays a generated session and
// publishes reflex/object_targets; this process reads them with reflex::bus and checks the rate
// (10 Hz +- 2 % from the publisher's header stamps), the header, and the positions against the
// session's ground truth.
#include "vision_test_util.hpp"

#include <reflex/bus/bus.hpp>
#include <reflex/msg/vision.h>

#include <gtest/gtest.h>

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
                          " --domain 85 --quiet > " + (dir / "log.txt") + " 2>&1";
  int rc = -1;
  std::thread vision([&] { rc = std::system(cmd.c_str()); });
  bus.runFor(std::chrono::milliseconds(7000));
  vision.join();
  ASSERT_EQ(rc, 0) << readText(dir / "log.txt");

  ASSERT_GE(got.size(), 40u) << "5 s at 10 Hz";
  const double mean_period =
      1e-9 * static_cast<double>(got.back().header().stamp_ns() - got.front().header().stamp_ns()) / (got.size() - 1);
  std::cout << got.size() << " samples, mean period " << 1000.0 * mean_period << " ms\n";
  EXPECT_NEAR(1.0 / mean_period, 10.0, 0.2);
  int compared = 0;
  for (std::size_t i = 0; i < got.size(); ++i) {
    const reflex::msg::ObjectTargets& s = got[i];
    EXPECT_EQ(s.header().source(), "vision");
    EXPECT_EQ(s.frame_id(), "base_link");
    if (i > 0) {
      EXPECT_EQ(s.header().seq(), got[i - 1].header().seq() + 1);
      EXPECT_GE(s.capture_stamp_ns(), got[i - 1].capture_stamp_ns());
    }
    // Captured (on the replay clock) before it was published, and not long before.
    EXPECT_LE(s.capture_stamp_ns(), s.header().stamp_ns() + 5'000'000);
    EXPECT_GT(s.capture_stamp_ns(), s.header().stamp_ns() - 300'000'000);
    for (const reflex::msg::ObjectTarget& o : s.objects()) {
      for (const GroundTruthRow& g : truth) {
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
