// Unitree's "hg" low-level interface (G1, H1-2) as Reflex speaks it: the crc of a message, the
// topics' type supports on the bus, and the joint map (motor index <-> URDF joint). The port that
// uses them is unitree_hg_port.hpp; the contract for users is idl/README.md, "Robots that already
// have an interface".
//
// The crc. Unitree's Crc32Core: CRC-32 with polynomial 0x04c11db7, fed 32-bit words most-significant
// bit first, initial value 0xFFFFFFFF, no final xor, over the message AS THE SDK'S C STRUCT LAYS IT
// OUT IN MEMORY (natural alignment, little-endian as on the robot), all words but the last (the crc
// itself): 250 words of LowCmd_ (1004 bytes), 522 of LowState_ (2092 bytes). The generated Fast DDS
// classes have their own layout, so pack*() writes every field at its offset in the SDK's layout
// (kLowCmdOffsets / kLowStateOffsets below, from the SDK's headers) into a zeroed buffer; padding is
// always zero. No allocation, no exception.
//
// The joint map (YAML, loadHgJointMap): which motor slot measures which URDF joint, the gains Reflex
// sends for the motors it commands, and the model joints no motor measures (held at a fixed value,
// e.g. a simulated robot's virtual base). Every error names the file, the key and the bad value.
#pragma once

#include "reflex/control/model.hpp"

#include <reflex/bus/topics.hpp>
#include <reflex/msg/unitree_hgPubSubTypes.h>

#include <array>
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

namespace reflex::unitree_hg {

using LowCmd = ::unitree_hg::msg::dds_::LowCmd_;
using LowState = ::unitree_hg::msg::dds_::LowState_;

inline constexpr int kMotors = 35;       ///< motor slots of LowCmd_ / LowState_
inline constexpr int kWeightSlot = 29;   ///< rt/arm_sdk: motor_cmd[29].q is the weight in [0, 1]
inline constexpr int kArmSdkFirst = 12;  ///< rt/arm_sdk: the weight blends motors 12..28 (waist, arms)
inline constexpr int kArmSdkLast = 28;
inline constexpr std::size_t kLowCmdBytes = 1004;                         ///< sizeof the SDK's LowCmd_
inline constexpr std::size_t kLowStateBytes = 2092;                       ///< sizeof the SDK's LowState_
inline constexpr std::size_t kLowCmdCrcWords = kLowCmdBytes / 4 - 1;      ///< 250
inline constexpr std::size_t kLowStateCrcWords = kLowStateBytes / 4 - 1;  ///< 522
inline constexpr const char* kStateTopic = "rt/lowstate";
inline constexpr const char* kArmSdkTopic = "rt/arm_sdk";
inline constexpr const char* kLowCmdTopic = "rt/lowcmd";
/// QoS profile of both topics (bringup/dds/reflex_profiles.xml): a reliable writer and a best-effort
/// reader, which match whatever QoS Unitree's closed library uses.
inline constexpr const char* kProfile = "reflex_unitree_hg";

/// Byte offsets of the SDK's C structs (unitree_sdk2 include/unitree/idl/hg/*.hpp, natural alignment).
struct MotorCmdOffsets {
  static constexpr std::size_t mode = 0, q = 4, dq = 8, tau = 12, kp = 16, kd = 20, reserve = 24, size = 28;
};
struct MotorStateOffsets {
  static constexpr std::size_t mode = 0, q = 4, dq = 8, ddq = 12, tau_est = 16, temperature = 20, vol = 24, sensor = 28,
                               motorstate = 36, reserve = 40, size = 56;
};
struct ImuOffsets {
  static constexpr std::size_t quaternion = 0, gyroscope = 16, accelerometer = 28, rpy = 40, temperature = 52,
                               size = 56;
};
struct LowCmdOffsets {
  static constexpr std::size_t mode_pr = 0, mode_machine = 1, motor_cmd = 4, reserve = 984, crc = 1000,
                               size = kLowCmdBytes;
};
struct LowStateOffsets {
  static constexpr std::size_t version = 0, mode_pr = 8, mode_machine = 9, tick = 12, imu_state = 16, motor_state = 72,
                               wireless_remote = 2032, reserve = 2072, crc = 2088, size = kLowStateBytes;
};

/// Crc32Core over `count` 32-bit words (see the header). No allocation.
std::uint32_t crc32Core(const std::uint32_t* words, std::size_t count) noexcept;

/// The message in the SDK's memory layout (little-endian, padding zero), crc field included as it is.
void packLowCmd(const LowCmd& cmd, std::array<std::uint8_t, kLowCmdBytes>& out) noexcept;
void packLowState(const LowState& state, std::array<std::uint8_t, kLowStateBytes>& out) noexcept;

/// The crc the message must carry (Crc32Core over the packed layout, all words but the last).
std::uint32_t lowCmdCrc(const LowCmd& cmd) noexcept;
std::uint32_t lowStateCrc(const LowState& state) noexcept;

/// Counts of LowState_ / LowCmd_ samples the type support refused to decode: a payload whose size is
/// not the type's (another motor count, another version of the type), or malformed. Fast DDS drops
/// such a sample silently; the port reads this counter to count and name it. Process-wide.
std::uint64_t undecodableLowStates() noexcept;
std::uint64_t undecodableLowCmds() noexcept;

/// SafePubSubType (reflex/bus/topics.hpp) that also refuses a payload of another size than the fixed
/// type's and counts every refusal in `counter`.
template <class Generated, std::atomic<std::uint64_t>& counter>
class CountingPubSubType final : public Generated {
 public:
  bool deserialize(eprosima::fastrtps::rtps::SerializedPayload_t* payload, void* data) override {
    // The encapsulation (4 bytes) + the fixed CDR size, padded to 4 bytes by some writers.
    const std::size_t expected = 4 + Generated::type::getCdrSerializedSize(typename Generated::type());
    if (payload->length < expected || payload->length > expected + 3) {
      counter.fetch_add(1, std::memory_order_relaxed);
      return false;
    }
    try {
      if (Generated::deserialize(payload, data)) return true;
    } catch (const eprosima::fastcdr::exception::Exception&) {
    }
    counter.fetch_add(1, std::memory_order_relaxed);
    return false;
  }
};

extern std::atomic<std::uint64_t> g_undecodable_low_states;
extern std::atomic<std::uint64_t> g_undecodable_low_cmds;

// ---- the joint map

struct HgMotor {
  int motor = -1;          ///< slot 0..34 (never 29, the arm_sdk weight)
  std::string joint;       ///< URDF joint name
  bool has_gains = false;  ///< kp and kd given (required for a motor Reflex commands)
  double kp = 0.0;         ///< N m/rad, sent in MotorCmd_.kp
  double kd = 0.0;         ///< N m s/rad, sent in MotorCmd_.kd
};

struct HgFixedJoint {
  std::string joint;
  double value = 0.0;  ///< rad or m, reported for this joint in every state
};

struct HgJointMap {
  std::string source;               ///< the file it was read from
  std::string robot;                ///< free text ("g1_29dof")
  std::vector<HgMotor> motors;      ///< in file order
  std::vector<HgFixedJoint> fixed;  ///< in file order
};

/// Reads a joint map file. Checks the file on its own: motors in 0..34 but not 29, each motor and
/// joint name once, gains finite and >= 0, kp and kd together. Throws control::ConfigError
/// ("FILE:LINE:COL: KEY: PROBLEM (value 'TEXT', expected ...)").
HgJointMap loadHgJointMap(const std::string& path);
/// The joint map to use: `joint_map` if given, else <URDF stem>.hg.yaml beside the URDF (the rule of
/// the controller configuration). Throws control::ConfigError naming that path when it does not exist.
std::string hgJointMapFor(const std::string& urdf, const std::string& joint_map);
HgJointMap loadHgJointMapFromString(const std::string& text, const std::string& origin);

/// The map against a robot model, resolved to q indices. Throws control::ConfigError naming the file
/// and the joint: a name the model does not have ("unknown joint"), a model joint neither mapped nor
/// fixed, a fixed value outside the joint's limits.
struct HgResolvedMap {
  std::array<int, kMotors> q_of_motor{};  ///< q index per slot, -1 unmapped
  std::vector<int> motor_of_q;            ///< slot per q index, -1 for a fixed joint
  std::vector<double> fixed_value;        ///< per q index (used where motor_of_q is -1)
  std::array<float, kMotors> kp{}, kd{};  ///< per slot (0 where no gains)
  std::array<bool, kMotors> has_gains{};
};
HgResolvedMap resolveHgJointMap(const HgJointMap& map, const control::Model& model);

}  // namespace reflex::unitree_hg

namespace reflex::bus {

template <>
struct TopicTraits<unitree_hg::LowState> {
  using PubSubType = unitree_hg::CountingPubSubType<::unitree_hg::msg::dds_::LowState_PubSubType,
                                                    unitree_hg::g_undecodable_low_states>;
  static constexpr const char* kTopicName = unitree_hg::kStateTopic;
  static constexpr const char* kProfile = unitree_hg::kProfile;
};

template <>
struct TopicTraits<unitree_hg::LowCmd> {
  using PubSubType =
      unitree_hg::CountingPubSubType<::unitree_hg::msg::dds_::LowCmd_PubSubType, unitree_hg::g_undecodable_low_cmds>;
  static constexpr const char* kTopicName = unitree_hg::kArmSdkTopic;
  static constexpr const char* kProfile = unitree_hg::kProfile;
};

}  // namespace reflex::bus
