// Interoperability, Fast DDS -> Cyclone DDS (domain 49): bus_pub_program (reflex::bus, Fast DDS,
// UDP-only participant profile) publishes Reflex topics; bus_cyclone_reader, a C program on Cyclone
// DDS built from the same IDL with idlc, receives them and checks every field against its own C
// coding of the values. Covers a sequence type (joint_state), nested structs / enums / uint64
// (control_status), a reliable transient-local stream (hand_targets) and a keyed one (body_schema).
#include <gtest/gtest.h>

#include "support/child_process.hpp"

#include <csignal>

namespace reflex::bus::test {
namespace {

using namespace std::chrono_literals;
using namespace reflex::testing;                // ChildProcess, binPath (support/child_process.hpp)
const ChildOutput kPipe = ChildOutput::pipe();  // stdout through a pipe (readUntil, output)
constexpr const char* kTypes = "joint_state,control_status,hand_targets,body_schema";

TEST(Interop, CycloneReaderReceivesFastDdsTopics) {
  ChildProcess reader({binPath("bus_cyclone_reader"), "--domain", "49", "--types", kTypes, "--expect-source",
                       "interop_fastdds", "--timeout-s", "20"},
                      kPipe);
  ChildProcess writer({binPath("bus_pub_program"), "--domain", "49", "--types", kTypes, "--participant-profile",
                       "reflex_participant_udp", "--module", "interop_fastdds", "--max-seconds", "40"},
                      kPipe);
  ASSERT_NE(writer.readUntil("running", 10s).find("running"), std::string::npos) << writer.output();

  const int code = reader.wait(30s);
  ASSERT_NE(code, ChildProcess::kStillRunning) << "Cyclone reader did not finish; output:\n" << reader.output();
  EXPECT_EQ(code, 0) << reader.output();
  for (const char* type : {"joint_state", "control_status", "hand_targets", "body_schema"}) {
    EXPECT_NE(reader.output().find(std::string("verified ") + type), std::string::npos) << type;
  }
  writer.signal(SIGTERM);
  EXPECT_EQ(writer.wait(10s), 0);
}

}  // namespace
}  // namespace reflex::bus::test
