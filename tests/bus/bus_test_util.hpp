// Helpers shared by the bus tests: a BusConfig on a given domain with this checkout's profiles file,
// and the mapping from a topic type to its distinctive test sample (samples.hpp).
#pragma once

#include <reflex/bus/config.hpp>

#include <string>

#include "samples.hpp"

#ifndef REFLEX_SOURCE_DIR
#error "REFLEX_SOURCE_DIR must be defined (reflex_add_test does it)"
#endif

namespace reflex::bus::test {

inline const std::string kProfilesFile = std::string(REFLEX_SOURCE_DIR) + "/bringup/dds/reflex_profiles.xml";

/// A configuration on `domain` (each test binary uses its own domain ids, see CMakeLists.txt).
inline BusConfig testConfig(const std::string& module, int domain,
                            const std::string& participant_profile = "reflex_participant") {
  BusConfig c;
  c.module_name = module;
  c.domain_id = domain;
  c.profiles_file = kProfilesFile;
  c.participant_profile = participant_profile;
  return c;
}

template <class T>
T sampleOf(int k);
template <>
inline msg::ObjectTargets sampleOf<msg::ObjectTargets>(int k) {
  return objectTargets(k);
}
template <>
inline msg::HandTargets sampleOf<msg::HandTargets>(int k) {
  return handTargets(k);
}
template <>
inline msg::MotionPriority sampleOf<msg::MotionPriority>(int k) {
  return motionPriority(k);
}
template <>
inline msg::BodySchemaChange sampleOf<msg::BodySchemaChange>(int k) {
  return bodySchemaChange(k);
}
template <>
inline msg::WalkCommand sampleOf<msg::WalkCommand>(int k) {
  return walkCommand(k);
}
template <>
inline msg::JointState sampleOf<msg::JointState>(int k) {
  return jointState(k);
}
template <>
inline msg::ControlStatus sampleOf<msg::ControlStatus>(int k) {
  return controlStatus(k);
}
template <>
inline msg::Heartbeat sampleOf<msg::Heartbeat>(int k) {
  return heartbeat(k);
}
template <>
inline msg::ControllerProtection sampleOf<msg::ControllerProtection>(int k) {
  return controllerProtection(k);
}
template <>
inline msg::RobotState sampleOf<msg::RobotState>(int k) {
  return robotState(k);
}
template <>
inline msg::JointCommand sampleOf<msg::JointCommand>(int k) {
  return jointCommand(k);
}
template <>
inline msg::RobotContacts sampleOf<msg::RobotContacts>(int k) {
  return robotContacts(k);
}
template <>
inline msg::CameraImage sampleOf<msg::CameraImage>(int k) {
  return cameraImage(k);
}

}  // namespace reflex::bus::test
