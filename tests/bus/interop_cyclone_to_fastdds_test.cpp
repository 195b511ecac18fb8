// Interoperability, Cyclone DDS -> Fast DDS (domain 50): bus_cyclone_writer, a C program on Cyclone
// DDS built from the same IDL with idlc, publishes Reflex topics from its own C coding of the test
// values; bus_sub_program (reflex::bus, Fast DDS, UDP-only participant profile, the Reflex QoS
// profiles) receives them and checks every field against samples.hpp.
#include <gtest/gtest.h>

#include "support/child_process.hpp"

#include <csignal>

namespace reflex::bus::test {
namespace {

using namespace std::chrono_literals;
using namespace reflex::testing;                // ChildProcess, binPath (support/child_process.hpp)
const ChildOutput kPipe = ChildOutput::pipe();  // stdout through a pipe (readUntil, output)
constexpr const char* kTypes = "joint_state,control_status,hand_targets,body_schema";

TEST(Interop, FastDdsReaderReceivesCycloneTopics) {
  ChildProcess reader({binPath("bus_sub_program"), "--domain", "50", "--types", kTypes, "--participant-profile",
                       "reflex_participant_udp", "--expect-source", "cyclone_writer", "--timeout-s", "20"},
                      kPipe);
  ChildProcess writer({binPath("bus_cyclone_writer"), "--domain", "50", "--types", kTypes, "--max-seconds", "40"},
                      kPipe);
  ASSERT_NE(writer.readUntil("running", 10s).find("running"), std::string::npos) << writer.output();

  const int code = reader.wait(30s);
  ASSERT_NE(code, ChildProcess::kStillRunning) << "Fast DDS reader did not finish; output:\n" << reader.output();
  EXPECT_EQ(code, 0) << reader.output();
  for (const char* type : {"joint_state", "control_status", "hand_targets", "body_schema"}) {
    EXPECT_NE(reader.output().find(std::string("verified ") + type), std::string::npos) << type;
  }
  writer.signal(SIGTERM);
  const int writer_code = writer.wait(10s);
  EXPECT_EQ(writer_code, 0);
  EXPECT_NE(writer.output().find("stopped by signal"), std::string::npos) << writer.output();
}

}  // namespace
}  // namespace reflex::bus::test
