// The flagship experiment's outcome (issue 7, item 4), asserted on real processes: the shipped session
// replayed through reflex_vision -> reflex_behavior -> reflex_controller over DDS (run_flagship.py),
// with and without avoidance. With avoidance the arms come within 15 mm while the objects cross, never
// below d_r, the e-stop never fires and the hands track reachable targets; without it they penetrate.
// The criteria of the run with avoidance are flagship_outcome.hpp's, shared with the secure run
// (tests/security/flagship_test.cpp).
#include "flagship_outcome.hpp"

#include <gtest/gtest.h>

#include <string>

namespace {

using reflex::flagship::field;

TEST(Flagship, AvoidanceKeepsTheCrossingArmsApartAndWithoutItTheyPenetrate) {
  const std::string out = ::testing::TempDir() + "reflex_flagship_test";
  const reflex::flagship::Run run = reflex::flagship::runFlagship(out, "--domain 74");
  ASSERT_EQ(run.exit_code, 0) << run.log;
  ASSERT_FALSE(run.summary.empty()) << run.log;
  const std::string& json = run.summary;

  EXPECT_EQ(reflex::flagship::flag(json, "avoidance", "secure"), 0) << "a plain run\n" << json;
  reflex::flagship::expectAvoidanceOutcome(json);
  EXPECT_LT(field(json, "no_avoidance", "min_arm_distance_m"), 0.0) << "without avoidance the arms penetrate\n"
                                                                    << json;
  // The report's strip draws the robot with the live view's renderer (headless Chromium), not 2D sticks.
  EXPECT_NE(json.find("\"strip_robot\": \"3d\""), std::string::npos) << json;
}

}  // namespace
