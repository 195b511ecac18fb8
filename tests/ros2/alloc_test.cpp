// The ports whose robot reports named joints allocate nothing on the control thread (the 5 ms path):
// Ros2RobotPort's poll() taking real sensor_msgs/JointState samples (names mapped, checked) and
// command() filling and queueing the controller's command for the outbox's writer thread, for both
// command kinds; DdsRobotPort's the same with reflex/robot_state and reflex/joint_command. Joint names
// longer than 15 bytes (asimo_like's l_shoulder_pitch) made Fast CDR's string reader allocate on
// every sample before the states were read with bus/cdr_read.hpp. Counted: operator new
// on THIS thread only (thread-local counter), so Fast DDS's and the outbox's own threads do not count;
// the states are published by a second participant of this program between the counted windows
// (domain 25).
#include "reflex/control_node/dds_robot_port.hpp"
#include "reflex/control_node/ros2_port.hpp"

#include "reflex/control/controller.hpp"
#include "reflex/control/onboard.hpp"
#include "reflex/control/scenarios.hpp"
#include "reflex/control/urdf_loader.hpp"

#include <reflex/bus/outbox.hpp>

#include "support/count_allocations.hpp"

#include <gtest/gtest.h>

#include <chrono>
#include <thread>

namespace {

/// 300 cycles of the control thread: `publish` writes a state (from another participant) twice, then
/// poll() and command() run as the controller runs them. Returns the operator new calls of poll() +
/// command() on this thread after the first 20 cycles (the name map is built once, at the first state).
template <class Publish>
long allocationsOfCycles(reflex::control_node::BusRobotPort& port, int nq, Publish&& publish) {
  Eigen::VectorXd qdot = Eigen::VectorXd::Zero(nq);
  long counted = 0;
  for (int cycle = 0; cycle < 300; ++cycle) {
    for (int k = 0; k < 2; ++k) {  // two states per cycle
      publish();
      std::this_thread::sleep_for(std::chrono::microseconds(100));
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(3));
    const long before = reflex::testing::threadAllocations();
    port.poll();
    const Eigen::VectorXd* q = port.measuredPositions(0.0);
    if (q != nullptr) port.command(*q, qdot, 0.005);
    if (cycle >= 20) counted += reflex::testing::threadAllocations() - before;
  }
  return counted;
}

void pollAndCommandAllocateNothing(const std::string& kind) {
  const std::string urdf = std::string(REFLEX_SOURCE_DIR) + "/bringup/robots/asimo_like.urdf";
  const auto model = reflex::control::loadModel(urdf, reflex::control::loadCollisionConfigFor(urdf, ""));
  const auto cm = reflex::control::makeControllerModel(model, reflex::control::loadControllerConfigFor(urdf, ""));
  reflex::bus::BusConfig bc;
  bc.module_name = "ros2_alloc";
  bc.domain_id = 25;
  bc.participant_profile = "reflex_participant_udp";
  reflex::bus::Participant bus(bc);
  reflex::control_node::Ros2RobotPort::Options options;
  options.command = kind;
  options.state_topic = "alloc_" + kind + "/joint_states";  // each case its own topics
  options.controller = "alloc_" + kind;
  reflex::control_node::Ros2RobotPort port(model, reflex::control::drivenJoints(model, cm), bus, options);
  reflex::bus::Outbox outbox("ros2_alloc");
  port.sendThrough(outbox);
  outbox.start();
  bc.module_name = "ros2_alloc_robot";
  reflex::bus::Participant robot_bus(bc);
  auto& states = robot_bus.makeWriter<reflex::ros2::JointState>(port.stateTopic(), reflex::ros2::kProfile);
  ASSERT_TRUE(states.waitForReaders(1, std::chrono::seconds(10)));

  const Eigen::VectorXd rest = reflex::control::restConfiguration(model, cm);
  reflex::ros2::JointState s;
  s.name(model.q_names);
  s.name().push_back("gripper_joint");  // a joint the model does not have: ignored
  s.position().assign(s.name().size(), 0.0);
  for (int i = 0; i < model.nq; ++i) s.position()[static_cast<std::size_t>(i)] = rest[i];
  s.velocity().assign(s.name().size(), 0.0);
  const long counted = allocationsOfCycles(port, model.nq, [&] {
    const std::int64_t now = reflex::bus::nowNs();
    s.header().stamp().sec(static_cast<std::int32_t>(now / 1000000000));
    s.header().stamp().nanosec(static_cast<std::uint32_t>(now % 1000000000));
    states.write(s);
  });
  EXPECT_GT(port.acceptedStates(), 300u) << "states were taken";
  EXPECT_EQ(port.rejectedTotal(), 0u) << port.lastRejection();
  EXPECT_GT(port.commandsSent(), 200u);
  EXPECT_EQ(counted, 0) << "operator new calls on the control thread in poll() + command(), --ros-command " << kind;
  outbox.close();
}

TEST(Ros2PortAlloc, ForwardCommandsAllocateNothingOnTheControlThread) { pollAndCommandAllocateNothing("forward"); }
TEST(Ros2PortAlloc, TrajectoryCommandsAllocateNothingOnTheControlThread) {
  pollAndCommandAllocateNothing("trajectory");
}

TEST(DdsRobotPortAlloc, RobotStatesAndJointCommandsAllocateNothingOnTheControlThread) {
  const std::string urdf = std::string(REFLEX_SOURCE_DIR) + "/bringup/robots/asimo_like.urdf";
  const auto model = reflex::control::loadModel(urdf, reflex::control::loadCollisionConfigFor(urdf, ""));
  const auto cm = reflex::control::makeControllerModel(model, reflex::control::loadControllerConfigFor(urdf, ""));
  reflex::bus::BusConfig bc;
  bc.module_name = "dds_alloc";
  bc.domain_id = 25;
  bc.participant_profile = "reflex_participant_udp";
  reflex::bus::Participant bus(bc);
  reflex::control_node::DdsRobotPort port(model, reflex::control::drivenJoints(model, cm), bus, {});
  reflex::bus::Outbox outbox("dds_alloc");
  port.sendThrough(outbox);
  outbox.start();
  bc.module_name = "dds_alloc_robot";
  reflex::bus::Participant robot_bus(bc);
  auto& states = robot_bus.makeWriter<reflex::msg::RobotState>();
  ASSERT_TRUE(states.waitForReaders(1, std::chrono::seconds(10)));
  const Eigen::VectorXd rest = reflex::control::restConfiguration(model, cm);
  reflex::msg::RobotState s;
  s.names(model.q_names);
  s.positions().assign(static_cast<std::size_t>(model.nq), 0.0);
  for (int i = 0; i < model.nq; ++i) s.positions()[static_cast<std::size_t>(i)] = rest[i];
  s.velocities().assign(static_cast<std::size_t>(model.nq), 0.0);
  const long counted = allocationsOfCycles(port, model.nq, [&] { states.publish(s); });
  EXPECT_GT(port.acceptedStates(), 300u) << "states were taken";
  EXPECT_EQ(port.rejectedTotal(), 0u) << port.lastRejection();
  EXPECT_GT(port.commandsSent(), 200u);
  EXPECT_EQ(counted, 0) << "operator new calls on the control thread in DdsRobotPort poll() + command()";
  outbox.close();
}

}  // namespace
