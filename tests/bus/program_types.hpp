// Topic types by short name, for the test programs' --types option.
#pragma once

#include <reflex/msg/behavior.h>
#include <reflex/msg/control.h>
#include <reflex/msg/robot.h>
#include <reflex/msg/system.h>
#include <reflex/msg/vision.h>

#include <sstream>
#include <string>
#include <vector>

namespace reflex::bus::test {

inline const std::vector<std::string> kAllTypeNames = {
    "object_targets", "hand_targets", "motion_priority", "body_schema",   "walk_command",  "joint_state",
    "control_status", "heartbeat",    "robot_state",     "joint_command", "robot_contacts"};

/// Calls fn(static_cast<T*>(nullptr)) for the type named `name`; false if the name is unknown.
template <class Fn>
bool forTypeName(const std::string& name, Fn&& fn) {
  if (name == "object_targets") return fn(static_cast<msg::ObjectTargets*>(nullptr)), true;
  if (name == "hand_targets") return fn(static_cast<msg::HandTargets*>(nullptr)), true;
  if (name == "motion_priority") return fn(static_cast<msg::MotionPriority*>(nullptr)), true;
  if (name == "body_schema") return fn(static_cast<msg::BodySchemaChange*>(nullptr)), true;
  if (name == "walk_command") return fn(static_cast<msg::WalkCommand*>(nullptr)), true;
  if (name == "joint_state") return fn(static_cast<msg::JointState*>(nullptr)), true;
  if (name == "control_status") return fn(static_cast<msg::ControlStatus*>(nullptr)), true;
  if (name == "heartbeat") return fn(static_cast<msg::Heartbeat*>(nullptr)), true;
  if (name == "robot_state") return fn(static_cast<msg::RobotState*>(nullptr)), true;
  if (name == "joint_command") return fn(static_cast<msg::JointCommand*>(nullptr)), true;
  if (name == "robot_contacts") return fn(static_cast<msg::RobotContacts*>(nullptr)), true;
  return false;
}

/// Splits "a,b,c" ("all" = every type).
inline std::vector<std::string> splitTypes(const std::string& list) {
  if (list == "all") return kAllTypeNames;
  std::vector<std::string> out;
  std::stringstream s(list);
  for (std::string item; std::getline(s, item, ',');) {
    if (!item.empty()) out.push_back(item);
  }
  return out;
}

}  // namespace reflex::bus::test
