// UnitreeHgPort on the control thread allocates nothing (the 5 ms path): poll() taking real LowState_
// samples (crc checked, joints mapped) and command() building, crc-ing and queueing a LowCmd_ for the
// outbox's writer thread. Counted: operator new on THIS thread only (thread-local counter), so Fast
// DDS's and the outbox's own threads do not count; the states are published by a second participant
// of this program between the counted windows (domain 15). Without the outbox a command's DDS write
// made 5 allocations (measured while writing this test), which is why the controller queues them.
#include "reflex/control_node/unitree_hg_port.hpp"

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

namespace hg = reflex::unitree_hg;

TEST(UnitreeHgPortAlloc, PollAndCommandAllocateNothingOnTheControlThread) {
  const std::string urdf = std::string(REFLEX_SOURCE_DIR) + "/bringup/robots/asimo_like.urdf";
  const auto model = reflex::control::loadModel(urdf, reflex::control::loadCollisionConfigFor(urdf, ""));
  const auto cm = reflex::control::makeControllerModel(model, reflex::control::loadControllerConfigFor(urdf, ""));
  const hg::HgJointMap map = hg::loadHgJointMap(std::string(REFLEX_SOURCE_DIR) + "/bringup/robots/asimo_like.hg.yaml");
  reflex::bus::BusConfig bc;
  bc.module_name = "hg_alloc";
  bc.domain_id = 15;
  bc.participant_profile = "reflex_participant_udp";
  reflex::bus::Participant bus(bc);
  reflex::control_node::UnitreeHgPort port(model, reflex::control::drivenJoints(model, cm), map, bus, {});
  reflex::bus::Outbox outbox("hg_alloc");
  port.sendThrough(outbox);
  outbox.start();
  bc.module_name = "hg_alloc_robot";
  reflex::bus::Participant robot_bus(bc);
  auto& states = robot_bus.makeWriter<hg::LowState>();
  ASSERT_TRUE(states.waitForReaders(1, std::chrono::seconds(10)));

  const Eigen::VectorXd rest = reflex::control::restConfiguration(model, cm);
  const hg::HgResolvedMap r = hg::resolveHgJointMap(map, model);
  hg::LowState s;
  for (int motor = 0; motor < hg::kMotors; ++motor)
    if (r.q_of_motor[static_cast<std::size_t>(motor)] >= 0)
      s.motor_state()[static_cast<std::size_t>(motor)].q(
          static_cast<float>(rest[r.q_of_motor[static_cast<std::size_t>(motor)]]));
  Eigen::VectorXd qdot = Eigen::VectorXd::Zero(model.nq);
  std::uint32_t tick = 0;
  long counted = 0;
  int polled = 0;
  for (int cycle = 0; cycle < 300; ++cycle) {
    for (int k = 0; k < 2; ++k) {  // two states per cycle
      s.tick(tick += 2);
      s.crc(hg::lowStateCrc(s));
      states.write(s);
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(3));
    const long before = reflex::testing::threadAllocations();
    polled += port.poll() >= 0 ? 1 : 0;
    const Eigen::VectorXd* q = port.measuredPositions(0.0);
    if (q != nullptr) port.command(*q, qdot, 0.005);
    if (cycle >= 20)
      counted += reflex::testing::threadAllocations() - before;  // after the first cycles (the name map, once)
  }
  EXPECT_GT(port.acceptedStates(), 300u) << "states were taken";
  EXPECT_EQ(port.rejectedTotal(), 0u);
  EXPECT_GT(port.commandsSent(), 200u);
  EXPECT_EQ(counted, 0) << "operator new calls on the control thread in poll() + command()";
  outbox.close();
}

}  // namespace
