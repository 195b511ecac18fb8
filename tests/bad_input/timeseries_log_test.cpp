// The controller's streamed --log writer (control/node timeseries_log.hpp),
// checked against the file it wrote: every pushed row is in the file, in order, beyond the 120,000
// rows where the old in-memory log stopped without a word; a ring the writer cannot empty in time
// drops rows and SAYS so (count, error text, close() false); a full device is a LogError at open
// naming the file and the reason; the rows are byte-identical to reflex_sim's writeTimeseriesCsv.
#include "support/child_process.hpp"

#include <reflex/control/controller.hpp>
#include <reflex/control/scenarios.hpp>
#include <reflex/control/urdf_loader.hpp>
#include <reflex/control_node/timeseries_log.hpp>

#include <gtest/gtest.h>

#include <chrono>
#include <cstdio>
#include <fstream>
#include <iterator>
#include <sstream>
#include <thread>

namespace reflex::control_node {
namespace {

const control::Model& model() {
  static const control::Model m = control::loadModel(
      std::string(REFLEX_SOURCE_DIR) + "/bringup/robots/asimo_like.urdf",
      control::loadCollisionConfig(std::string(REFLEX_SOURCE_DIR) + "/bringup/robots/asimo_like.collision.yaml"));
  return m;
}

control::SimSample row(double t) {
  control::SimSample s;
  s.t = t;
  s.q = Eigen::VectorXd::Constant(model().nq, t);
  s.qdot = Eigen::VectorXd::Zero(model().nq);
  s.min_distance = 0.05;
  return s;
}

std::string slurp(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
}

TEST(TimeseriesLog, EveryRowReachesTheFileBeyond120000Rows) {
  const std::string path = ::testing::TempDir() + "timeseries_log_long.csv";
  const long n = 130000;
  {
    TimeseriesLog log(model(), path, 4096);
    for (long k = 0; k < n; ++k) {
      // The controller pushes 200 rows/s; this test pushes as fast as the writer drains.
      while (log.queued() > 2048) std::this_thread::sleep_for(std::chrono::milliseconds(2));
      ASSERT_TRUE(log.push(row(static_cast<double>(k)))) << "row " << k;
    }
    EXPECT_TRUE(log.close()) << log.error();
    EXPECT_EQ(log.writtenRows(), static_cast<std::uint64_t>(n));
    EXPECT_EQ(log.droppedRows(), 0U);
    EXPECT_EQ(log.error(), "");
  }
  std::ifstream in(path);
  std::string line;
  long lines = 0;
  std::string last;
  while (std::getline(in, line)) {
    ++lines;
    last = line;
  }
  EXPECT_EQ(lines, n + 1) << "header + one line per row";
  EXPECT_EQ(last.substr(0, last.find(',')), std::to_string(n - 1)) << "the last row is the last pushed";
  std::remove(path.c_str());
}

TEST(TimeseriesLog, RowsAreTheSimulatorsFormat) {
  const std::string path = ::testing::TempDir() + "timeseries_log_format.csv";
  control::SimResult r;
  {
    TimeseriesLog log(model(), path, 16);
    for (int k = 0; k < 10; ++k) {
      r.samples.push_back(row(0.005 * k));
      ASSERT_TRUE(log.push(r.samples.back()));
    }
    ASSERT_TRUE(log.close()) << log.error();
  }
  const std::string reference = ::testing::TempDir() + "timeseries_log_reference.csv";
  control::writeTimeseriesCsv(model(), control::ControllerModel{}, r, reference);
  EXPECT_EQ(slurp(path), slurp(reference));
}

TEST(TimeseriesLog, AFullRingDropsCountsAndSaysSo) {
  const std::string path = ::testing::TempDir() + "timeseries_log_drop.csv";
  TimeseriesLog log(model(), path, 8);
  int refused = 0;
  for (int k = 0; k < 1000; ++k) refused += log.push(row(k)) ? 0 : 1;  // far faster than the writer
  EXPECT_GT(refused, 0);
  EXPECT_FALSE(log.close()) << "a dropped row is not success";
  EXPECT_EQ(log.droppedRows(), static_cast<std::uint64_t>(refused));
  EXPECT_EQ(log.writtenRows() + log.droppedRows(), 1000U);
  EXPECT_NE(log.error().find(std::to_string(refused) + " rows dropped"), std::string::npos) << log.error();
  EXPECT_NE(log.error().find(path), std::string::npos) << log.error();
}

TEST(TimeseriesLog, UnwritablePathsAreErrorsAtOpenNamingFileAndReason) {
  try {
    TimeseriesLog log(model(), reflex::testing::fullDevice());
    ADD_FAILURE() << reflex::testing::fullDevice() << " accepted";
  } catch (const LogError& e) {
    EXPECT_NE(std::string(e.what()).find("'" + reflex::testing::fullDevice() + "': No space left on device"),
              std::string::npos)
        << e.what();
  }
  const std::string missing = ::testing::TempDir() + "no_such_folder_h2/x.csv";
  try {
    TimeseriesLog log(model(), missing);
    ADD_FAILURE() << "a missing folder accepted";
  } catch (const LogError& e) {
    EXPECT_NE(std::string(e.what()).find("folder '" + ::testing::TempDir() + "no_such_folder_h2' of output file '" +
                                         missing + "' does not exist"),
              std::string::npos)
        << e.what();
  }
}

}  // namespace
}  // namespace reflex::control_node
