// The robot state file of reflex_controller --robot-state (control/node/.../robot_state_file.hpp):
// round trip, the crash cases (a torn newest slot falls back to the previous cycle; a file cut at
// every length loads exactly what the format says or is refused), the refusals (garbage, another
// robot, a position outside the limits, a second user of the file), the CRC against its published
// check value, and that save() allocates nothing (counted by replacing operator new) and what it costs.
#include "support/count_allocations.hpp"
#include "support/errors.hpp"

#include <reflex/control_node/robot_state_file.hpp>

#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <iterator>
#include <memory>
#include <new>
#include <sys/resource.h>

namespace reflex::control_node {
namespace {

struct Robot {
  std::vector<std::string> names{"a_joint", "b_joint", "c_joint"};
  Eigen::VectorXd lower = Eigen::Vector3d(-1.0, -2.0, -3.0);
  Eigen::VectorXd upper = Eigen::Vector3d(1.0, 2.0, 3.0);
};

std::string freshPath(const std::string& name) {
  const std::string p = ::testing::TempDir() + "robot_state_" + name + ".bin";
  std::remove(p.c_str());
  return p;
}

std::vector<char> readBytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::vector<char>((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
}
void writeBytes(const std::string& path, const std::vector<char>& bytes) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
}

std::string errorOf(const std::string& path, const Robot& r) {
  return reflex::testing::messageOf<RobotStateError>([&] { RobotStateFile f(path, r.names, r.lower, r.upper); }, "");
}

TEST(RobotStateFile, Crc32AndNameHashMatchTheirPublishedDefinitions) {
  const std::string check = "123456789";  // the CRC-32 check value of the IEEE polynomial is 0xCBF43926
  EXPECT_EQ(crc32(reinterpret_cast<const unsigned char*>(check.data()), check.size()), 0xCBF43926U);
  EXPECT_EQ(crc32(nullptr, 0), 0U);
  EXPECT_EQ(jointNamesHash({}), 0xcbf29ce484222325ULL) << "FNV-1a 64 offset basis";
  // FNV-1a 64 of "a" is 0xaf63dc4c8601ec8c; one more byte '\0': (h ^ 0) * prime.
  EXPECT_EQ(jointNamesHash({"a"}), 0xaf63dc4c8601ec8cULL * 0x100000001b3ULL);
  EXPECT_NE(jointNamesHash({"ab"}), jointNamesHash({"a", "b"}));
  EXPECT_NE(jointNamesHash({"a", "b"}), jointNamesHash({"b", "a"}));
}

TEST(RobotStateFile, NoFileStartsFromRestThenTheLastRecordIsLoaded) {
  const Robot r;
  const std::string path = freshPath("roundtrip");
  {
    RobotStateFile f(path, r.names, r.lower, r.upper);
    EXPECT_FALSE(f.loaded());
    for (int k = 1; k <= 7; ++k) ASSERT_TRUE(f.save(Eigen::Vector3d(0.1 * k, -0.2 * k, 0.3 * k)));
    EXPECT_EQ(f.sequence(), 7U);
    EXPECT_EQ(f.writeErrors(), 0U);
  }
  EXPECT_EQ(readBytes(path).size(), 2 * robotStateSlotSize(3)) << "two fixed-size slots";
  RobotStateFile g(path, r.names, r.lower, r.upper);
  ASSERT_TRUE(g.loaded());
  EXPECT_EQ(g.loadedSequence(), 7U);
  EXPECT_EQ(g.loadedPositions(), Eigen::VectorXd(Eigen::Vector3d(0.1 * 7, -0.2 * 7, 0.3 * 7)));  // bit-exact
  const auto age_ns =
      std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::system_clock::now().time_since_epoch())
          .count() -
      g.loadedWallNs();
  EXPECT_GE(age_ns, 0);
  EXPECT_LT(age_ns, 60'000'000'000LL) << "written just now";
  // The sequence continues, into the slot that does not hold the newest record.
  ASSERT_TRUE(g.save(Eigen::Vector3d(0.5, 0.5, 0.5)));
  EXPECT_EQ(g.sequence(), 8U);

  // An empty file (e.g. `touch`) is no state either.
  const std::string empty = freshPath("empty");
  writeBytes(empty, {});
  RobotStateFile e(empty, r.names, r.lower, r.upper);
  EXPECT_FALSE(e.loaded());
}

TEST(RobotStateFile, ATornNewestSlotFallsBackToThePreviousCycle) {
  const Robot r;
  const std::string path = freshPath("torn");
  {
    RobotStateFile f(path, r.names, r.lower, r.upper);
    for (int k = 1; k <= 5; ++k) ASSERT_TRUE(f.save(Eigen::Vector3d(0.1 * k, 0.0, 0.0)));
  }
  const std::vector<char> good = readBytes(path);
  const std::size_t slot = robotStateSlotSize(3);
  // Record 5 is in slot 0 (odd sequence), record 4 in slot 1. Damage every byte of record 5 that
  // the CRC covers (or the CRC itself), one at a time: record 4 is loaded.
  for (std::size_t i = 0; i < slot - 4; ++i) {
    std::vector<char> bad = good;
    bad[i] = static_cast<char>(bad[i] ^ 0x20);
    writeBytes(path, bad);
    RobotStateFile f(path, r.names, r.lower, r.upper);
    ASSERT_TRUE(f.loaded()) << "byte " << i;
    EXPECT_EQ(f.loadedSequence(), 4U) << "byte " << i;
    EXPECT_EQ(f.loadedPositions()[0], 0.1 * 4) << "byte " << i;
  }
  // Both slots damaged: refused, naming the file and both reasons.
  std::vector<char> bad = good;
  bad[20] = static_cast<char>(bad[20] ^ 1);
  bad[slot + 50] = static_cast<char>(bad[slot + 50] ^ 1);
  writeBytes(path, bad);
  const std::string msg = errorOf(path, r);
  EXPECT_NE(msg.find(path), std::string::npos) << msg;
  EXPECT_NE(msg.find("no valid robot state"), std::string::npos) << msg;
  EXPECT_NE(msg.find("CRC mismatch"), std::string::npos) << msg;
  EXPECT_NE(msg.find("delete it to start from rest"), std::string::npos) << msg;
}

TEST(RobotStateFile, AFileCutAtEveryLengthLoadsTheLastCompleteRecordOrIsRefused) {
  const Robot r;
  const std::string path = freshPath("cut");
  {
    RobotStateFile f(path, r.names, r.lower, r.upper);
    ASSERT_TRUE(f.save(Eigen::Vector3d(0.1, 0.2, 0.3)));     // record 1, slot 0
    ASSERT_TRUE(f.save(Eigen::Vector3d(-0.1, -0.2, -0.3)));  // record 2, slot 1
  }
  const std::vector<char> whole = readBytes(path);
  const std::size_t slot = robotStateSlotSize(3);
  ASSERT_EQ(whole.size(), 2 * slot);
  for (std::size_t len = 1; len < whole.size(); ++len) {
    writeBytes(path, std::vector<char>(whole.begin(), whole.begin() + static_cast<long>(len)));
    // A record is complete with its CRC (the last 4 bytes of a slot are padding).
    const std::uint64_t expected = len >= 2 * slot - 4 ? 2 : len >= slot - 4 ? 1 : 0;
    if (expected == 0) {
      EXPECT_NE(errorOf(path, r).find("no valid robot state"), std::string::npos) << "length " << len;
      continue;
    }
    RobotStateFile f(path, r.names, r.lower, r.upper);
    ASSERT_TRUE(f.loaded()) << "length " << len;
    EXPECT_EQ(f.loadedSequence(), expected) << "length " << len;
    EXPECT_DOUBLE_EQ(f.loadedPositions()[2], expected == 2 ? -0.3 : 0.3) << "length " << len;
  }
}

TEST(RobotStateFile, GarbageAnotherRobotOrAPositionOutsideTheLimitsIsRefusedNamingTheFile) {
  const Robot r;
  const std::string garbage = freshPath("garbage");
  writeBytes(garbage, std::vector<char>(300, 'x'));
  std::string msg = errorOf(garbage, r);
  EXPECT_NE(msg.find(garbage), std::string::npos) << msg;
  EXPECT_NE(msg.find("no 'RFXQ' magic"), std::string::npos) << msg;

  // Another robot: other joint names (same count), or another joint count.
  const std::string other = freshPath("other");
  {
    Robot o = r;
    o.names[1] = "elbow";
    RobotStateFile f(other, o.names, o.lower, o.upper);
    ASSERT_TRUE(f.save(Eigen::Vector3d::Zero()));
  }
  msg = errorOf(other, r);
  EXPECT_NE(msg.find(other), std::string::npos) << msg;
  EXPECT_NE(msg.find("another robot (3 joints"), std::string::npos) << msg;
  const std::string bigger = freshPath("bigger");
  {
    RobotStateFile f(bigger, {"a", "b", "c", "d"}, Eigen::VectorXd::Constant(4, -1.0),
                     Eigen::VectorXd::Constant(4, 1.0));
    ASSERT_TRUE(f.save(Eigen::VectorXd::Zero(4)));
    ASSERT_TRUE(f.save(Eigen::VectorXd::Zero(4)));
  }
  msg = errorOf(bigger, r);
  EXPECT_NE(msg.find("another robot (4 joints"), std::string::npos) << msg;
  EXPECT_NE(msg.find("this robot: 3 joints"), std::string::npos) << msg;

  // A position outside this robot's limits (saved under wider limits).
  const std::string outside = freshPath("outside");
  {
    RobotStateFile f(outside, r.names, Eigen::Vector3d::Constant(-9.0), Eigen::Vector3d::Constant(9.0));
    ASSERT_TRUE(f.save(Eigen::Vector3d(0.0, 2.5, 0.0)));
  }
  msg = errorOf(outside, r);
  EXPECT_NE(msg.find("joint 'b_joint' = 2.5"), std::string::npos) << msg;

  // A folder is no state file; a file in a missing folder cannot be created.
  EXPECT_NE(errorOf(::testing::TempDir(), r).find("robot state file"), std::string::npos);
  EXPECT_NE(errorOf("/nonexistent/dir/state.bin", r).find("cannot open robot state file '/nonexistent/dir/state.bin'"),
            std::string::npos);
}

TEST(RobotStateFile, TwoUsersOfOneFileAreRefusedTheLockIsReleasedWithTheFirst) {
  const Robot r;
  const std::string path = freshPath("lock");
  auto first = std::make_unique<RobotStateFile>(path, r.names, r.lower, r.upper);
  EXPECT_NE(errorOf(path, r).find("in use by another process"), std::string::npos);
  first.reset();
  EXPECT_EQ(errorOf(path, r), "");
}

TEST(RobotStateFile, SaveAllocatesNothingAndItsCostIsPrinted) {
  const std::string path = freshPath("cost");
  // The shipped robot's size: 33 joints.
  std::vector<std::string> names;
  for (int i = 0; i < 33; ++i) names.push_back("joint_" + std::to_string(i));
  const Eigen::VectorXd lower = Eigen::VectorXd::Constant(33, -4.0), upper = Eigen::VectorXd::Constant(33, 4.0);
  auto f = std::make_unique<RobotStateFile>(path, names, lower, upper);
  Eigen::VectorXd q = Eigen::VectorXd::Zero(33);
  constexpr int kN = 20000;
  std::vector<double> us;
  us.reserve(kN);
  const long before = testing::allocations();
  rusage ru0{}, ru1{};
  getrusage(RUSAGE_THREAD, &ru0);
  for (int k = 0; k < kN; ++k) {
    q[k % 33] += 1e-4;
    const auto t0 = std::chrono::steady_clock::now();
    const bool ok = f->save(q);
    us.push_back(std::chrono::duration<double, std::micro>(std::chrono::steady_clock::now() - t0).count());
    ASSERT_TRUE(ok);
  }
  getrusage(RUSAGE_THREAD, &ru1);
  EXPECT_EQ(testing::allocations() - before, 0) << "save() must not allocate (200 Hz loop)";
  std::sort(us.begin(), us.end());
  // Voluntary context switches = the thread blocked (in pwrite); involuntary = it was preempted
  // (on a loaded machine the rare long samples are preemptions, multiples of the 4 ms tick).
  std::printf(
      "robot state save (33 joints, %zu-byte pwrite to %s): p50 %.2f us, p99 %.2f us, p99.9 %.2f us, max "
      "%.1f us over %d writes; context switches while writing: voluntary %ld, involuntary %ld\n",
      robotStateSlotSize(33), ::testing::TempDir().c_str(), us[kN / 2], us[kN * 99 / 100], us[kN * 999 / 1000],
      us.back(), kN, ru1.ru_nvcsw - ru0.ru_nvcsw, ru1.ru_nivcsw - ru0.ru_nivcsw);
  EXPECT_LT(us[kN / 2], 500.0) << "a tenth of the 5 ms period, with a wide margin for a loaded machine";
  f.reset();
  RobotStateFile g(path, names, lower, upper);
  EXPECT_EQ(g.loadedSequence(), static_cast<std::uint64_t>(kN));
  EXPECT_EQ(g.loadedPositions(), q) << "bit-exact";
}

}  // namespace
}  // namespace reflex::control_node
