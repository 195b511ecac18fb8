#include "reflex/control_node/unitree_hg.hpp"

#include "reflex/control/controller.hpp"

#include <reflex/common/yaml_reader.hpp>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <set>

namespace reflex::unitree_hg {

std::atomic<std::uint64_t> g_undecodable_low_states{0};
std::atomic<std::uint64_t> g_undecodable_low_cmds{0};

std::uint64_t undecodableLowStates() noexcept { return g_undecodable_low_states.load(std::memory_order_relaxed); }
std::uint64_t undecodableLowCmds() noexcept { return g_undecodable_low_cmds.load(std::memory_order_relaxed); }

std::uint32_t crc32Core(const std::uint32_t* words, std::size_t count) noexcept {
  constexpr std::uint32_t kPoly = 0x04c11db7u;
  std::uint32_t crc = 0xFFFFFFFFu;
  for (std::size_t i = 0; i < count; ++i) {
    const std::uint32_t data = words[i];
    for (int bit = 31; bit >= 0; --bit) {  // most-significant bit first
      const bool top = (crc & 0x80000000u) != 0;
      const bool in = ((data >> bit) & 1u) != 0;
      crc <<= 1;
      if (top != in) crc ^= kPoly;
    }
  }
  return crc;
}

namespace {

// Little-endian stores at a byte offset (the robot's layout, whatever this host's order).
template <std::size_t N>
void put8(std::array<std::uint8_t, N>& b, std::size_t at, std::uint8_t v) noexcept {
  b[at] = v;
}
template <std::size_t N>
void put16(std::array<std::uint8_t, N>& b, std::size_t at, std::int16_t v) noexcept {
  const auto u = static_cast<std::uint16_t>(v);
  b[at] = static_cast<std::uint8_t>(u & 0xFFu);
  b[at + 1] = static_cast<std::uint8_t>(u >> 8);
}
template <std::size_t N>
void put32(std::array<std::uint8_t, N>& b, std::size_t at, std::uint32_t v) noexcept {
  for (int k = 0; k < 4; ++k) b[at + static_cast<std::size_t>(k)] = static_cast<std::uint8_t>((v >> (8 * k)) & 0xFFu);
}
template <std::size_t N>
void putf(std::array<std::uint8_t, N>& b, std::size_t at, float v) noexcept {
  std::uint32_t u = 0;
  std::memcpy(&u, &v, sizeof(u));
  put32(b, at, u);
}

template <std::size_t N>
std::uint32_t crcOfPacked(const std::array<std::uint8_t, N>& b, std::size_t words) noexcept {
  std::array<std::uint32_t, N / 4> w{};
  for (std::size_t i = 0; i < N / 4; ++i)
    w[i] = static_cast<std::uint32_t>(b[4 * i]) | static_cast<std::uint32_t>(b[4 * i + 1]) << 8 |
           static_cast<std::uint32_t>(b[4 * i + 2]) << 16 | static_cast<std::uint32_t>(b[4 * i + 3]) << 24;
  return crc32Core(w.data(), words);
}

}  // namespace

void packLowCmd(const LowCmd& c, std::array<std::uint8_t, kLowCmdBytes>& b) noexcept {
  b.fill(0);
  put8(b, LowCmdOffsets::mode_pr, c.mode_pr());
  put8(b, LowCmdOffsets::mode_machine, c.mode_machine());
  for (std::size_t i = 0; i < static_cast<std::size_t>(kMotors); ++i) {
    const auto& m = c.motor_cmd()[i];
    const std::size_t at = LowCmdOffsets::motor_cmd + i * MotorCmdOffsets::size;
    put8(b, at + MotorCmdOffsets::mode, m.mode());
    putf(b, at + MotorCmdOffsets::q, m.q());
    putf(b, at + MotorCmdOffsets::dq, m.dq());
    putf(b, at + MotorCmdOffsets::tau, m.tau());
    putf(b, at + MotorCmdOffsets::kp, m.kp());
    putf(b, at + MotorCmdOffsets::kd, m.kd());
    put32(b, at + MotorCmdOffsets::reserve, m.reserve());
  }
  for (std::size_t k = 0; k < 4; ++k) put32(b, LowCmdOffsets::reserve + 4 * k, c.reserve()[k]);
  put32(b, LowCmdOffsets::crc, c.crc());
}

void packLowState(const LowState& s, std::array<std::uint8_t, kLowStateBytes>& b) noexcept {
  b.fill(0);
  for (std::size_t k = 0; k < 2; ++k) put32(b, LowStateOffsets::version + 4 * k, s.version()[k]);
  put8(b, LowStateOffsets::mode_pr, s.mode_pr());
  put8(b, LowStateOffsets::mode_machine, s.mode_machine());
  put32(b, LowStateOffsets::tick, s.tick());
  const auto& imu = s.imu_state();
  const std::size_t ia = LowStateOffsets::imu_state;
  for (std::size_t k = 0; k < 4; ++k) putf(b, ia + ImuOffsets::quaternion + 4 * k, imu.quaternion()[k]);
  for (std::size_t k = 0; k < 3; ++k) {
    putf(b, ia + ImuOffsets::gyroscope + 4 * k, imu.gyroscope()[k]);
    putf(b, ia + ImuOffsets::accelerometer + 4 * k, imu.accelerometer()[k]);
    putf(b, ia + ImuOffsets::rpy + 4 * k, imu.rpy()[k]);
  }
  put16(b, ia + ImuOffsets::temperature, imu.temperature());
  for (std::size_t i = 0; i < static_cast<std::size_t>(kMotors); ++i) {
    const auto& m = s.motor_state()[i];
    const std::size_t at = LowStateOffsets::motor_state + i * MotorStateOffsets::size;
    put8(b, at + MotorStateOffsets::mode, m.mode());
    putf(b, at + MotorStateOffsets::q, m.q());
    putf(b, at + MotorStateOffsets::dq, m.dq());
    putf(b, at + MotorStateOffsets::ddq, m.ddq());
    putf(b, at + MotorStateOffsets::tau_est, m.tau_est());
    for (std::size_t k = 0; k < 2; ++k) put16(b, at + MotorStateOffsets::temperature + 2 * k, m.temperature()[k]);
    putf(b, at + MotorStateOffsets::vol, m.vol());
    for (std::size_t k = 0; k < 2; ++k) put32(b, at + MotorStateOffsets::sensor + 4 * k, m.sensor()[k]);
    put32(b, at + MotorStateOffsets::motorstate, m.motorstate());
    for (std::size_t k = 0; k < 4; ++k) put32(b, at + MotorStateOffsets::reserve + 4 * k, m.reserve()[k]);
  }
  for (std::size_t k = 0; k < 40; ++k) put8(b, LowStateOffsets::wireless_remote + k, s.wireless_remote()[k]);
  for (std::size_t k = 0; k < 4; ++k) put32(b, LowStateOffsets::reserve + 4 * k, s.reserve()[k]);
  put32(b, LowStateOffsets::crc, s.crc());
}

std::uint32_t lowCmdCrc(const LowCmd& cmd) noexcept {
  std::array<std::uint8_t, kLowCmdBytes> b;
  packLowCmd(cmd, b);
  return crcOfPacked(b, kLowCmdCrcWords);
}

std::uint32_t lowStateCrc(const LowState& state) noexcept {
  std::array<std::uint8_t, kLowStateBytes> b;
  packLowState(state, b);
  return crcOfPacked(b, kLowStateCrcWords);
}

// ---- the joint map

namespace {

[[noreturn]] void raise(const std::string& message) { throw control::ConfigError(message); }

HgJointMap readMap(const common::ConfigNode& root) {
  HgJointMap map;
  map.source = root.file();
  root.rejectUnknown({"robot", "motors", "fixed"});
  map.robot = root.string("robot", "");
  std::set<int> motors;
  std::set<std::string> names;
  if (!root.has("motors")) root.fail("motors", "missing", "a list of {motor, joint[, kp, kd]}");
  for (const common::ConfigNode& e : root.list("motors")) {
    e.rejectUnknown({"motor", "joint", "kp", "kd"});
    HgMotor m;
    m.motor = e.at("motor", "a motor slot 0..34").asInteger(0, kMotors - 1);
    if (m.motor == kWeightSlot) e.fail("motor", "slot 29 is the arm_sdk weight, not a motor", "0..28 or 30..34");
    if (!motors.insert(m.motor).second) e.fail("motor", "motor listed twice", "each motor once");
    m.joint = e.requiredString("joint", "a URDF joint name");
    if (!names.insert(m.joint).second) e.fail("joint", "joint listed twice", "each joint once");
    if (e.has("kp") != e.has("kd")) e.failAt(e.has("kp") ? "kp" : "kd", "kp and kd come together (both or neither)");
    if (e.has("kp")) {
      m.has_gains = true;
      m.kp = e.requiredNumber("kp", 0.0, 1000.0, "N m/rad");
      m.kd = e.requiredNumber("kd", 0.0, 100.0, "N m s/rad");
    }
    map.motors.push_back(m);
  }
  if (root.has("fixed")) {
    const common::ConfigNode fixed = root.child("fixed");
    for (const auto& [name, value] : fixed.entries()) {
      if (!names.insert(name).second) fixed.fail(name, "joint listed twice (as a motor and fixed)", "each joint once");
      map.fixed.push_back({name, value.asNumber(-1e4, 1e4, "rad or m")});
    }
  }
  if (map.motors.empty()) root.fail("motors", "no motor", "a list of {motor, joint[, kp, kd]}");
  return map;
}

}  // namespace

HgJointMap loadHgJointMap(const std::string& path) {
  return readMap(common::ConfigNode::loadFile(path, "unitree_hg joint map", &raise));
}

std::string hgJointMapFor(const std::string& urdf, const std::string& joint_map) {
  if (!joint_map.empty()) return joint_map;
  const std::string beside = control::robotFileBeside(urdf, ".hg.yaml");
  std::error_code ec;
  if (!std::filesystem::exists(beside, ec))
    throw control::ConfigError("no joint map: --joint-map not given and no '" + beside +
                               "' beside the URDF (motor index <-> URDF joint; idl/README.md)");
  return beside;
}

HgJointMap loadHgJointMapFromString(const std::string& text, const std::string& origin) {
  return readMap(common::ConfigNode::loadString(text, origin, &raise));
}

HgResolvedMap resolveHgJointMap(const HgJointMap& map, const control::Model& model) {
  HgResolvedMap r;
  r.q_of_motor.fill(-1);
  r.motor_of_q.assign(static_cast<std::size_t>(model.nq), -2);  // -2: not yet seen
  r.fixed_value.assign(static_cast<std::size_t>(model.nq), 0.0);
  const auto unknown = [&](const std::string& name) {
    throw control::ConfigError(map.source + ": joint '" + name + "' is not a joint of the robot model '" + model.name +
                               "' (unknown joint name; the model has " + std::to_string(model.nq) + " joints)");
  };
  for (const HgMotor& m : map.motors) {
    const int qi = model.qIndex(m.joint);
    if (qi < 0) unknown(m.joint);
    r.q_of_motor[static_cast<std::size_t>(m.motor)] = qi;
    r.motor_of_q[static_cast<std::size_t>(qi)] = m.motor;
    r.has_gains[static_cast<std::size_t>(m.motor)] = m.has_gains;
    r.kp[static_cast<std::size_t>(m.motor)] = static_cast<float>(m.kp);
    r.kd[static_cast<std::size_t>(m.motor)] = static_cast<float>(m.kd);
  }
  for (const HgFixedJoint& f : map.fixed) {
    const int qi = model.qIndex(f.joint);
    if (qi < 0) unknown(f.joint);
    if (f.value < model.q_lower[qi] || f.value > model.q_upper[qi])
      throw control::ConfigError(map.source + ": fixed joint '" + f.joint + "' value " + common::numberText(f.value) +
                                 " is outside its limits [" + common::numberText(model.q_lower[qi]) + ", " +
                                 common::numberText(model.q_upper[qi]) + "]");
    r.motor_of_q[static_cast<std::size_t>(qi)] = -1;
    r.fixed_value[static_cast<std::size_t>(qi)] = f.value;
  }
  for (int qi = 0; qi < model.nq; ++qi)
    if (r.motor_of_q[static_cast<std::size_t>(qi)] == -2)
      throw control::ConfigError(map.source + ": the model's joint '" + model.q_names[qi] +
                                 "' has no motor and no fixed value (every joint's position is needed for the "
                                 "distances: map it to a motor, or list it under 'fixed')");
  return r;
}

}  // namespace reflex::unitree_hg
