// Unitree's hg interface (control/node/include/reflex/control_node/unitree_hg.hpp): the packed C
// layout, the crc and the joint map, each against an independent answer.
//  - Layout: the SDK's C structs written again here from the published field list (plain C structs,
//    the compiler lays them out); their offsetof / sizeof are checked against the spec's table, and
//    packLowCmd / packLowState must produce byte for byte what memcpy of such a struct holds, for
//    random field values (padding zeroed in both).
//  - Crc: Crc32Core must equal CRC-32/MPEG-2 (bytewise, bit by bit, written here) over the words'
//    bytes in big-endian order; the MPEG-2 routine itself is checked on its catalogue check value
//    ("123456789" -> 0x0376E6E7). One hand-made vector: one zero word gives 0xC704DD7B (0xFFFFFFFF
//    shifted through 32 zero bits; Crc32Core's table-free definition, computed independently below).
//  - Joint map: the shipped G1 map against the spec's motor table; the asimo_like map against the
//    model; every error path names the bad value.
//  - The type support: a LowState_ round-trips through Fast DDS's serializer at the XCDR1 size worked
//    out by hand (2092 bytes); a payload 5 motors short or 4 bytes long is refused and counted.
//  - The crc of a state and of a command (the port computes both every cycle) allocates nothing
//    (operator new counted; no other thread runs in this program).
#include "reflex/control_node/unitree_hg.hpp"

#include "reflex/control/controller.hpp"
#include "reflex/control/urdf_loader.hpp"
#include "support/count_allocations.hpp"
#include "support/errors.hpp"

#include <gtest/gtest.h>

#include <cstddef>
#include <cstring>
#include <random>

namespace {

namespace hg = reflex::unitree_hg;

// The SDK's structs, from the published field list (natural alignment, the compiler's layout).
struct CMotorCmd {
  std::uint8_t mode;
  float q, dq, tau, kp, kd;
  std::uint32_t reserve;
};
struct CMotorState {
  std::uint8_t mode;
  float q, dq, ddq, tau_est;
  std::int16_t temperature[2];
  float vol;
  std::uint32_t sensor[2];
  std::uint32_t motorstate;
  std::uint32_t reserve[4];
};
struct CImu {
  float quaternion[4], gyroscope[3], accelerometer[3], rpy[3];
  std::int16_t temperature;
};
struct CLowCmd {
  std::uint8_t mode_pr, mode_machine;
  CMotorCmd motor_cmd[35];
  std::uint32_t reserve[4];
  std::uint32_t crc;
};
struct CLowState {
  std::uint32_t version[2];
  std::uint8_t mode_pr, mode_machine;
  std::uint32_t tick;
  CImu imu_state;
  CMotorState motor_state[35];
  std::uint8_t wireless_remote[40];
  std::uint32_t reserve[4];
  std::uint32_t crc;
};

// The spec's table (offsets and sizes).
static_assert(sizeof(CMotorCmd) == 28 && offsetof(CMotorCmd, q) == 4 && offsetof(CMotorCmd, kd) == 20 &&
              offsetof(CMotorCmd, reserve) == 24);
static_assert(sizeof(CMotorState) == 56 && offsetof(CMotorState, temperature) == 20 &&
              offsetof(CMotorState, vol) == 24 && offsetof(CMotorState, sensor) == 28 &&
              offsetof(CMotorState, motorstate) == 36 && offsetof(CMotorState, reserve) == 40);
static_assert(sizeof(CImu) == 56 && offsetof(CImu, gyroscope) == 16 && offsetof(CImu, accelerometer) == 28 &&
              offsetof(CImu, rpy) == 40 && offsetof(CImu, temperature) == 52);
static_assert(sizeof(CLowCmd) == 1004 && offsetof(CLowCmd, mode_machine) == 1 && offsetof(CLowCmd, motor_cmd) == 4 &&
              offsetof(CLowCmd, reserve) == 984 && offsetof(CLowCmd, crc) == 1000);
static_assert(sizeof(CLowState) == 2092 && offsetof(CLowState, mode_pr) == 8 &&
              offsetof(CLowState, mode_machine) == 9 && offsetof(CLowState, tick) == 12 &&
              offsetof(CLowState, imu_state) == 16 && offsetof(CLowState, motor_state) == 72 &&
              offsetof(CLowState, wireless_remote) == 2032 && offsetof(CLowState, reserve) == 2072 &&
              offsetof(CLowState, crc) == 2088);
// The library's constants agree with the table.
static_assert(hg::LowCmdOffsets::reserve == offsetof(CLowCmd, reserve) &&
              hg::LowCmdOffsets::crc == offsetof(CLowCmd, crc));
static_assert(hg::LowStateOffsets::motor_state == offsetof(CLowState, motor_state) &&
              hg::LowStateOffsets::wireless_remote == offsetof(CLowState, wireless_remote) &&
              hg::LowStateOffsets::crc == offsetof(CLowState, crc));
static_assert(hg::kLowCmdCrcWords == 250 && hg::kLowStateCrcWords == 522);

// CRC-32/MPEG-2 over bytes, bit by bit (poly 0x04C11DB7, init 0xFFFFFFFF, no reflection, no xorout).
std::uint32_t crcMpeg2(const std::uint8_t* bytes, std::size_t n) {
  std::uint32_t crc = 0xFFFFFFFFu;
  for (std::size_t i = 0; i < n; ++i) {
    crc ^= static_cast<std::uint32_t>(bytes[i]) << 24;
    for (int k = 0; k < 8; ++k) crc = (crc & 0x80000000u) ? (crc << 1) ^ 0x04C11DB7u : crc << 1;
  }
  return crc;
}

// Crc32Core of a struct held in memory (little-endian host: each word's bytes reversed for MPEG-2).
template <class T>
std::uint32_t independentCrc(const T& c) {
  std::uint8_t bytes[sizeof(T)];
  std::memcpy(bytes, &c, sizeof(T));
  std::vector<std::uint8_t> be;
  for (std::size_t w = 0; w + 1 < sizeof(T) / 4; ++w)
    for (int k = 3; k >= 0; --k) be.push_back(bytes[4 * w + static_cast<std::size_t>(k)]);
  return crcMpeg2(be.data(), be.size());
}

TEST(UnitreeHgCrc, ReferenceCheckValue) {
  const char* check = "123456789";
  EXPECT_EQ(crcMpeg2(reinterpret_cast<const std::uint8_t*>(check), 9), 0x0376E6E7u);
}

TEST(UnitreeHgCrc, OneZeroWord) {
  // 0xFFFFFFFF shifted through 32 zero input bits: the polynomial folded in at every set top bit.
  std::uint32_t crc = 0xFFFFFFFFu;
  for (int k = 0; k < 32; ++k) crc = (crc & 0x80000000u) ? (crc << 1) ^ 0x04C11DB7u : crc << 1;
  const std::uint32_t zero = 0;
  EXPECT_EQ(hg::crc32Core(&zero, 1), crc);
  EXPECT_EQ(hg::crc32Core(&zero, 1), 0xC704DD7Bu);
}

TEST(UnitreeHgCrc, WordsEqualMpeg2OnBigEndianBytes) {
  std::mt19937 rng(7);
  for (int trial = 0; trial < 20; ++trial) {
    std::vector<std::uint32_t> words(1 + rng() % 600);
    for (auto& w : words) w = rng();
    std::vector<std::uint8_t> be;
    for (const auto w : words)
      for (int k = 3; k >= 0; --k) be.push_back(static_cast<std::uint8_t>(w >> (8 * k)));
    EXPECT_EQ(hg::crc32Core(words.data(), words.size()), crcMpeg2(be.data(), be.size()));
  }
}

float randf(std::mt19937& rng) { return std::uniform_real_distribution<float>(-10.f, 10.f)(rng); }

TEST(UnitreeHgLayout, LowCmdPacksAsTheCStruct) {
  std::mt19937 rng(11);
  for (int trial = 0; trial < 5; ++trial) {
    hg::LowCmd cmd;
    CLowCmd c;
    std::memset(&c, 0, sizeof(c));
    c.mode_pr = static_cast<std::uint8_t>(rng());
    c.mode_machine = static_cast<std::uint8_t>(rng());
    cmd.mode_pr(c.mode_pr);
    cmd.mode_machine(c.mode_machine);
    for (int i = 0; i < 35; ++i) {
      auto& m = cmd.motor_cmd()[static_cast<std::size_t>(i)];
      CMotorCmd& k = c.motor_cmd[i];
      k.mode = static_cast<std::uint8_t>(rng());
      k.q = randf(rng);
      k.dq = randf(rng);
      k.tau = randf(rng);
      k.kp = randf(rng);
      k.kd = randf(rng);
      k.reserve = rng();
      m.mode(k.mode);
      m.q(k.q);
      m.dq(k.dq);
      m.tau(k.tau);
      m.kp(k.kp);
      m.kd(k.kd);
      m.reserve(k.reserve);
    }
    for (int j = 0; j < 4; ++j) cmd.reserve()[static_cast<std::size_t>(j)] = c.reserve[j] = rng();
    c.crc = rng();
    cmd.crc(c.crc);
    std::array<std::uint8_t, hg::kLowCmdBytes> packed;
    packed.fill(0xAB);
    hg::packLowCmd(cmd, packed);
    ASSERT_EQ(std::memcmp(packed.data(), &c, sizeof(c)), 0) << "trial " << trial;
    EXPECT_EQ(hg::lowCmdCrc(cmd), independentCrc(c));
  }
}

TEST(UnitreeHgLayout, LowStatePacksAsTheCStruct) {
  std::mt19937 rng(13);
  for (int trial = 0; trial < 5; ++trial) {
    hg::LowState s;
    CLowState c;
    std::memset(&c, 0, sizeof(c));
    for (int j = 0; j < 2; ++j) s.version()[static_cast<std::size_t>(j)] = c.version[j] = rng();
    c.mode_pr = static_cast<std::uint8_t>(rng());
    c.mode_machine = static_cast<std::uint8_t>(rng());
    s.mode_pr(c.mode_pr);
    s.mode_machine(c.mode_machine);
    c.tick = rng();
    s.tick(c.tick);
    auto& imu = s.imu_state();
    for (int j = 0; j < 4; ++j) imu.quaternion()[static_cast<std::size_t>(j)] = c.imu_state.quaternion[j] = randf(rng);
    for (int j = 0; j < 3; ++j) {
      imu.gyroscope()[static_cast<std::size_t>(j)] = c.imu_state.gyroscope[j] = randf(rng);
      imu.accelerometer()[static_cast<std::size_t>(j)] = c.imu_state.accelerometer[j] = randf(rng);
      imu.rpy()[static_cast<std::size_t>(j)] = c.imu_state.rpy[j] = randf(rng);
    }
    c.imu_state.temperature = static_cast<std::int16_t>(rng());
    imu.temperature(c.imu_state.temperature);
    for (int i = 0; i < 35; ++i) {
      auto& m = s.motor_state()[static_cast<std::size_t>(i)];
      CMotorState& k = c.motor_state[i];
      k.mode = static_cast<std::uint8_t>(rng());
      k.q = randf(rng);
      k.dq = randf(rng);
      k.ddq = randf(rng);
      k.tau_est = randf(rng);
      k.vol = randf(rng);
      k.temperature[0] = static_cast<std::int16_t>(rng());
      k.temperature[1] = static_cast<std::int16_t>(rng());
      k.sensor[0] = rng();
      k.sensor[1] = rng();
      k.motorstate = rng();
      for (int j = 0; j < 4; ++j) k.reserve[j] = rng();
      m.mode(k.mode);
      m.q(k.q);
      m.dq(k.dq);
      m.ddq(k.ddq);
      m.tau_est(k.tau_est);
      m.vol(k.vol);
      m.temperature() = {k.temperature[0], k.temperature[1]};
      m.sensor() = {k.sensor[0], k.sensor[1]};
      m.motorstate(k.motorstate);
      m.reserve() = {k.reserve[0], k.reserve[1], k.reserve[2], k.reserve[3]};
    }
    for (int j = 0; j < 40; ++j)
      s.wireless_remote()[static_cast<std::size_t>(j)] = c.wireless_remote[j] = static_cast<std::uint8_t>(rng());
    for (int j = 0; j < 4; ++j) s.reserve()[static_cast<std::size_t>(j)] = c.reserve[j] = rng();
    c.crc = rng();
    s.crc(c.crc);
    std::array<std::uint8_t, hg::kLowStateBytes> packed;
    packed.fill(0xCD);
    hg::packLowState(s, packed);
    ASSERT_EQ(std::memcmp(packed.data(), &c, sizeof(c)), 0) << "trial " << trial;
    EXPECT_EQ(hg::lowStateCrc(s), independentCrc(c));
  }
}

TEST(UnitreeHgLayout, CrcIgnoresTheCrcFieldAndSeesEveryOther) {
  hg::LowState s;
  const std::uint32_t base = hg::lowStateCrc(s);
  s.crc(0x12345678u);
  EXPECT_EQ(hg::lowStateCrc(s), base);
  s.reserve()[3] = 1;  // the last word before the crc is covered
  EXPECT_NE(hg::lowStateCrc(s), base);
  hg::LowCmd c;
  const std::uint32_t cbase = hg::lowCmdCrc(c);
  c.motor_cmd()[29].q(0.5f);
  EXPECT_NE(hg::lowCmdCrc(c), cbase);
}

TEST(UnitreeHgCrc, AllocatesNothing) {
  hg::LowState s;
  hg::LowCmd c;
  s.tick(7);
  c.motor_cmd()[20].q(0.25f);
  const long before = reflex::testing::allocations();
  std::uint32_t sum = 0;
  for (int k = 0; k < 100; ++k) {
    s.tick(static_cast<std::uint32_t>(k));
    sum += hg::lowStateCrc(s) + hg::lowCmdCrc(c);  // used, so nothing is optimized away
  }
  EXPECT_EQ(reflex::testing::allocations() - before, 0);
  EXPECT_NE(sum, 0u);
}

TEST(UnitreeHgTypeSupport, APayloadOfAnotherSizeIsRefusedAndCounted) {
  using Support = reflex::bus::TopicTraits<hg::LowState>::PubSubType;
  Support type;
  hg::LowState s;
  s.tick(42);
  s.motor_state()[18].q(0.5f);
  s.crc(hg::lowStateCrc(s));
  eprosima::fastrtps::rtps::SerializedPayload_t payload(type.getSerializedSizeProvider(&s)());
  ASSERT_TRUE(type.serialize(&s, &payload));
  // XCDR1 of 35 motors, by hand: version 8, modes 2 (+2 to align tick), tick 4, IMU 13 x 4 + 2 = 54
  // (ends at 70, no padding before an octet), the first motor 1 + 1 (pad) + 52 = 54, the other 34
  // 1 + 3 + 52 = 56 each, remote 40, reserve 16, crc 4: 2088 bytes + the 4-byte encapsulation.
  EXPECT_EQ(payload.length, 2092u);
  const std::uint64_t before = hg::undecodableLowStates();
  hg::LowState back;
  ASSERT_TRUE(type.deserialize(&payload, &back));
  EXPECT_EQ(back.tick(), 42u);
  EXPECT_EQ(back.crc(), s.crc());
  EXPECT_EQ(hg::lowStateCrc(back), back.crc());
  EXPECT_EQ(hg::undecodableLowStates(), before);
  // 30 motors' worth (5 x 56 bytes fewer), and 4 bytes more: refused, each counted once.
  const std::uint32_t full = payload.length;
  payload.length = full - 5 * 56;
  EXPECT_FALSE(type.deserialize(&payload, &back));
  EXPECT_EQ(hg::undecodableLowStates(), before + 1);
  payload.length = full + 4;
  payload.reserve(full + 4);
  EXPECT_FALSE(type.deserialize(&payload, &back));
  EXPECT_EQ(hg::undecodableLowStates(), before + 2);
}

// ---- joint map

const char* const kG1Table[29] = {
    "left_hip_pitch_joint",     "left_hip_roll_joint",     "left_hip_yaw_joint",         "left_knee_joint",
    "left_ankle_pitch_joint",   "left_ankle_roll_joint",   "right_hip_pitch_joint",      "right_hip_roll_joint",
    "right_hip_yaw_joint",      "right_knee_joint",        "right_ankle_pitch_joint",    "right_ankle_roll_joint",
    "waist_yaw_joint",          "waist_roll_joint",        "waist_pitch_joint",          "left_shoulder_pitch_joint",
    "left_shoulder_roll_joint", "left_shoulder_yaw_joint", "left_elbow_joint",           "left_wrist_roll_joint",
    "left_wrist_pitch_joint",   "left_wrist_yaw_joint",    "right_shoulder_pitch_joint", "right_shoulder_roll_joint",
    "right_shoulder_yaw_joint", "right_elbow_joint",       "right_wrist_roll_joint",     "right_wrist_pitch_joint",
    "right_wrist_yaw_joint"};

TEST(UnitreeHgJointMap, ShippedG1MapIsTheSpecTable) {
  const hg::HgJointMap map =
      hg::loadHgJointMap(std::string(REFLEX_SOURCE_DIR) + "/bringup/robots/unitree_g1_29dof.hg.yaml");
  ASSERT_EQ(map.motors.size(), 29u);
  for (int i = 0; i < 29; ++i) {
    EXPECT_EQ(map.motors[static_cast<std::size_t>(i)].motor, i);
    EXPECT_EQ(map.motors[static_cast<std::size_t>(i)].joint, kG1Table[i]);
    // Gains exactly on the slots arm_sdk blends.
    EXPECT_EQ(map.motors[static_cast<std::size_t>(i)].has_gains, i >= 12) << kG1Table[i];
  }
  EXPECT_TRUE(map.fixed.empty());
}

reflex::control::Model asimo() {
  const std::string urdf = std::string(REFLEX_SOURCE_DIR) + "/bringup/robots/asimo_like.urdf";
  return reflex::control::loadModel(urdf, reflex::control::loadCollisionConfigFor(urdf, ""));
}

TEST(UnitreeHgJointMap, AsimoMapCoversEveryJoint) {
  const auto model = asimo();
  const hg::HgJointMap map = hg::loadHgJointMap(std::string(REFLEX_SOURCE_DIR) + "/bringup/robots/asimo_like.hg.yaml");
  const hg::HgResolvedMap r = hg::resolveHgJointMap(map, model);
  int motors = 0, fixed = 0;
  for (int qi = 0; qi < model.nq; ++qi) (r.motor_of_q[static_cast<std::size_t>(qi)] >= 0 ? motors : fixed)++;
  EXPECT_EQ(motors + fixed, model.nq);
  EXPECT_EQ(fixed, 6);
  EXPECT_EQ(r.q_of_motor[15], model.qIndex("l_shoulder_pitch"));
  EXPECT_EQ(r.q_of_motor[hg::kWeightSlot], -1);
}

std::string errorOf(const std::string& yaml, bool resolve = false) {
  return reflex::testing::messageOf<reflex::control::ConfigError>(
      [&] {
        const hg::HgJointMap map = hg::loadHgJointMapFromString(yaml, "map.yaml");
        if (resolve) hg::resolveHgJointMap(map, asimo());
      },
      "");
}

TEST(UnitreeHgJointMap, ErrorsNameTheBadValue) {
  EXPECT_NE(errorOf("motors:\n  - {motor: 29, joint: l_elbow}\n").find("slot 29 is the arm_sdk weight"),
            std::string::npos);
  EXPECT_NE(errorOf("motors:\n  - {motor: 35, joint: l_elbow}\n").find("motors[0].motor"), std::string::npos);
  EXPECT_NE(errorOf("motors:\n  - {motor: 1, joint: a}\n  - {motor: 1, joint: b}\n").find("motor listed twice"),
            std::string::npos);
  EXPECT_NE(errorOf("motors:\n  - {motor: 1, joint: a}\n  - {motor: 2, joint: a}\n").find("joint listed twice"),
            std::string::npos);
  EXPECT_NE(errorOf("motors:\n  - {motor: 1, joint: a, kp: 3}\n").find("kp and kd come together"), std::string::npos);
  EXPECT_NE(errorOf("motors:\n  - {motor: 1, joint: a, kp: -3, kd: 1}\n").find("motors[0].kp"), std::string::npos);
  EXPECT_NE(errorOf("motorz: []\n").find("unknown key"), std::string::npos);
  // Against the model: an unknown name, a joint left out, a fixed value outside the limits.
  const std::string unknown = errorOf("motors:\n  - {motor: 1, joint: left_elbow_joint}\n", true);
  EXPECT_NE(unknown.find("joint 'left_elbow_joint' is not a joint of the robot model"), std::string::npos) << unknown;
  const std::string missing = errorOf("motors:\n  - {motor: 18, joint: l_elbow, kp: 1, kd: 1}\n", true);
  EXPECT_NE(missing.find("has no motor and no fixed value"), std::string::npos) << missing;
  const std::string outside = errorOf("motors:\n  - {motor: 18, joint: l_elbow}\nfixed:\n  body_z: 5\n", true);
  EXPECT_NE(outside.find("fixed joint 'body_z' value 5 is outside its limits"), std::string::npos) << outside;
}

}  // namespace
