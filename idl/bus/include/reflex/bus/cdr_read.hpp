// Reading a sample's strings without allocating on every sample. Fast CDR's own string reader builds
// a new std::string each time (an allocation for every string longer than the small-string buffer,
// 15 bytes: "l_shoulder_pitch" is 16), so a robot state taken every cycle allocated on the 5 ms path.
// These read into the strings already there, reusing their capacity: after the first sample of a
// given shape, no allocation. Used through SafePubSubType's Read policy (topics.hpp) by the readers of
// states taken every cycle: reflex/robot_state (RobotStateRead) and sensor_msgs/JointState
// (control_node/ros2_port.hpp).
#pragma once

#include <fastcdr/Cdr.h>
#include <fastcdr/exceptions/BadParamException.h>
#include <fastcdr/exceptions/NotEnoughMemoryException.h>

#include <cstdint>
#include <string>
#include <vector>

namespace reflex::bus {

/// A CDR string (length with its NUL, the bytes, the NUL) into `s`, reusing its capacity. Throws
/// fastcdr exceptions on a short or malformed buffer (SafePubSubType drops the sample).
inline void readString(eprosima::fastcdr::Cdr& cdr, std::string& s) {
  std::uint32_t length = 0;
  cdr >> length;
  if (length == 0) {  // not CDR ("" is 1: its NUL), but harmless
    s.clear();
    return;
  }
  // The bytes must be there before the string is sized: a hostile length (4 GB) would otherwise be
  // allocated first (a fuzz finding: 2.8 GB for one sensor_msgs/JointState name).
  eprosima::fastcdr::Cdr::state start = cdr.getState();  // setState takes it non-const
  if (!cdr.jump(length))
    throw eprosima::fastcdr::exception::NotEnoughMemoryException("CDR string longer than the sample");
  cdr.setState(start);
  s.resize(length - 1);
  if (length > 1) cdr.deserializeArray(&s[0], length - 1);
  char nul = 0;
  cdr >> nul;
  if (nul != '\0') throw eprosima::fastcdr::exception::BadParamException("CDR string without its terminating NUL");
}

/// A CDR sequence of strings of at most `bound` elements into `v`, reusing its strings.
inline void readStrings(eprosima::fastcdr::Cdr& cdr, std::vector<std::string>& v, std::size_t bound) {
  std::uint32_t n = 0;
  cdr >> n;
  if (n > bound) throw eprosima::fastcdr::exception::BadParamException("CDR sequence longer than its bound");
  v.resize(n);
  for (std::string& s : v) readString(cdr, s);
}

/// A CDR sequence of doubles of at most `bound` elements into `v` (its capacity reused).
inline void readDoubles(eprosima::fastcdr::Cdr& cdr, std::vector<double>& v, std::size_t bound) {
  std::uint32_t n = 0;
  cdr >> n;
  if (n > bound) throw eprosima::fastcdr::exception::BadParamException("CDR sequence longer than its bound");
  v.resize(n);
  if (n > 0) cdr.deserializeArray(v.data(), n);
}

}  // namespace reflex::bus
