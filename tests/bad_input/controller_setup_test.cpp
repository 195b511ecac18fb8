// Bad files and values given to the real reflex_controller at start: every one is
// a clear error before the loop starts — exit code 2 and a message quoting the bad file or value
// — never a crash (a signal) and never a running controller. Domain 106 (only reached by the
// profile cases).
#include "controller_run.hpp"
#include "support/child_process.hpp"

#include <cstdio>
#include <cstdlib>
#include <stdexcept>

namespace reflex::bad_input {
namespace {

struct Case {
  std::string name;               // test case name (also the catalogue row)
  std::vector<std::string> args;  // after the executable
  std::string expect;             // text the error output must contain
};

// A fresh folder per run: nothing left over from an earlier run (e.g. a collision YAML that sits
// next to a URDF) can change what the controller reads.
std::string tmp(const std::string& file) {
  static const std::string dir = [] {
    std::string templ = ::testing::TempDir() + "reflex_bad_setup_XXXXXX";
    if (mkdtemp(templ.data()) == nullptr) throw std::runtime_error("mkdtemp failed for '" + templ + "'");
    return templ + "/";
  }();
  return dir + file;
}

std::vector<Case> cases() {
  const std::string robots = std::string(REFLEX_SOURCE_DIR) + "/bringup/robots/";
  const std::string urdf = robots + "asimo_like.urdf";
  const std::string profiles = std::string(REFLEX_SOURCE_DIR) + "/bringup/dds/reflex_profiles.xml";
  const std::string base_profiles = readFile(profiles);
  // Bad files, written once.
  writeFile(tmp("malformed.urdf"), "<robot name='x'><link name='a'>");
  writeFile(tmp("empty.urdf"), "");
  writeFile(tmp("binary.urdf"), std::string("\x7f"
                                            "ELF\x02\x01\x01\0\0\0",
                                            10));
  writeFile(tmp("mesh.urdf"),
            "<robot name='m'><link name='base'><collision><geometry><mesh filename='x.stl'/></geometry></collision>"
            "</link></robot>");
  writeFile(tmp("collision_malformed.yaml"), "exclude: [[a, b\n");
  writeFile(tmp("collision_unknown.yaml"), "exclude:\n  - [l_hand, no_such_segment]\n");
  writeFile(tmp("malformed.controller.yaml"), "d_a: [1, 2\n");
  writeFile(tmp("negative.controller.yaml"), "d_r: -0.005\n");
  writeFile(tmp("unordered.controller.yaml"), "d_a: 0.005\nd_b: 0.010\n");
  writeFile(tmp("nan.controller.yaml"), "k_virtual: .nan\n");
  writeFile(tmp("unknown_key.controller.yaml"), "d_z: 0.01\n");
  writeFile(tmp("unknown_joint.controller.yaml"), "arms:\n  left:\n    joints: [l_no_such_joint]\n");
  // small_humanoid's own configuration with d_r 20 mm: its feet are 11.63 mm apart at rest.
  writeFile(tmp("red_rest.controller.yaml"),
            readFile(robots + "small_humanoid.controller.yaml") + "d_r: 0.02\nd_b: 0.03\n");
  writeFile(tmp("truncated.xml"), base_profiles.substr(0, base_profiles.size() / 2));
  writeFile(tmp("not_xml.xml"), "this is not XML at all {\n");
  writeFile(tmp("bad_qos.xml"),
            "<?xml version='1.0'?><dds xmlns='http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles'><profiles>"
            "<participant profile_name='reflex_participant'><rtps><name>x</name></rtps></participant>"
            "<data_writer profile_name='reflex_state'><topic><historyQos><kind>KEEP_LAST</kind><depth>abc</depth>"
            "</historyQos></topic></data_writer></profiles></dds>");
  writeFile(tmp("no_profiles.xml"),
            "<?xml version='1.0'?><dds xmlns='http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles'><profiles>"
            "</profiles></dds>");
  // A user's own profiles file written for an older Reflex, without the controller's default (UDP-only)
  // participant profile: refused at start naming it, never a silent fall-back to shared memory.
  {
    std::string without_udp = base_profiles;
    const auto a = without_udp.find("<participant profile_name=\"reflex_participant_udp\">");
    const auto b = without_udp.find("</participant>", a);
    if (a == std::string::npos || b == std::string::npos)
      throw std::runtime_error("no reflex_participant_udp in " + profiles);
    without_udp.erase(a, b + std::string("</participant>").size() - a);
    writeFile(tmp("no_udp_profile.xml"), without_udp);
  }
  const std::string d = "106";
  return {
      {"missing URDF", {"--urdf", "/nonexistent/robot.urdf"}, "/nonexistent/robot.urdf"},
      {"malformed URDF", {"--urdf", tmp("malformed.urdf")}, tmp("malformed.urdf")},
      {"empty URDF", {"--urdf", tmp("empty.urdf")}, tmp("empty.urdf")},
      {"binary URDF", {"--urdf", tmp("binary.urdf")}, tmp("binary.urdf")},
      {"URDF is a folder", {"--urdf", ::testing::TempDir()}, ::testing::TempDir()},
      {"mesh-only collision URDF", {"--urdf", tmp("mesh.urdf")}, "mesh"},
      {"missing collision YAML", {"--urdf", urdf, "--collision", "/nonexistent/c.yaml"}, "/nonexistent/c.yaml"},
      {"malformed collision YAML",
       {"--urdf", urdf, "--collision", tmp("collision_malformed.yaml")},
       tmp("collision_malformed.yaml")},
      {"unknown segment in collision YAML",
       {"--urdf", urdf, "--collision", tmp("collision_unknown.yaml")},
       "no_such_segment"},
      {"missing controller YAML", {"--controller", "/nonexistent/ctl.yaml"}, "/nonexistent/ctl.yaml"},
      {"malformed controller YAML", {"--controller", tmp("malformed.controller.yaml")}, "YAML syntax error"},
      {"negative d_r", {"--controller", tmp("negative.controller.yaml")}, "d_r"},
      {"d_a < d_b", {"--controller", tmp("unordered.controller.yaml")}, "d_r < d_b < d_a"},
      {"NaN gain", {"--controller", tmp("nan.controller.yaml")}, "k_virtual"},
      {"unknown controller key", {"--controller", tmp("unknown_key.controller.yaml")}, "d_z"},
      {"unknown joint in controller YAML", {"--controller", tmp("unknown_joint.controller.yaml")}, "l_no_such_joint"},
      {"rest posture inside the red zone",
       {"--urdf", robots + "small_humanoid.urdf", "--controller", tmp("red_rest.controller.yaml")},
       "is above the distance of 'l_foot' and 'r_foot' at the rest posture, 11.63 mm"},
      {"missing profiles XML", {"--domain", d, "--profiles", "/nonexistent/p.xml"}, "/nonexistent/p.xml"},
      {"truncated profiles XML", {"--domain", d, "--profiles", tmp("truncated.xml")}, tmp("truncated.xml")},
      {"profiles file not XML", {"--domain", d, "--profiles", tmp("not_xml.xml")}, tmp("not_xml.xml")},
      {"bad QoS value in profiles XML", {"--domain", d, "--profiles", tmp("bad_qos.xml")}, tmp("bad_qos.xml")},
      {"profiles XML without any profile",
       {"--domain", d, "--profiles", tmp("no_profiles.xml")},
       tmp("no_profiles.xml")},
      {"unknown participant profile", {"--domain", d, "--participant-profile", "no_such_profile"}, "no_such_profile"},
      {"profiles XML without the default participant profile",
       {"--domain", d, "--profiles", tmp("no_udp_profile.xml")},
       "unknown participant QoS profile 'reflex_participant_udp'"},
      {"domain id out of range", {"--domain", "999"}, "999"},
      {"domain id not a number", {"--domain", "abc"}, "abc"},
      {"negative duration", {"--duration", "-1"}, "-1"},
      {"zero input timeout", {"--input-timeout", "0"}, "0"},
      {"NaN input timeout", {"--input-timeout", "nan"}, "nan"},
      {"unknown option", {"--no-such-option"}, "--no-such-option"},
      // A --log that cannot be written is an error before the loop.
      {"--log on a full device",
       {"--domain", d, "--log", reflex::testing::fullDevice()},
       "'" + reflex::testing::fullDevice() + "': No space left on device"},
      {"--log in a missing folder",
       {"--domain", d, "--log", tmp("no_such_folder/run.csv")},
       tmp("no_such_folder/run.csv")},
      {"--log is a folder", {"--domain", d, "--log", tmp("")}, "is a directory"},
      // The module name is the key of the heartbeat (at most 255 bytes).
      {"--name of 256 bytes", {"--domain", d, "--name", std::string(256, 'n')}, "at most 255 bytes"},
      {"--name of 100000 bytes", {"--domain", d, "--name", std::string(100000, 'n')}, "100000 bytes long"},
      {"negative --peer-probe", {"--peer-probe", "-1"}, "--peer-probe"},
  };
}

TEST(ControllerBadSetup, EveryBadFileOrValueIsAClearErrorAtStart) {
  int n = 0;
  for (const Case& c : cases()) {
    SCOPED_TRACE(c.name);
    const std::string log = tmp("case_" + std::to_string(n++) + ".log");
    std::vector<std::string> argv = {controllerExe()};
    argv.insert(argv.end(), c.args.begin(), c.args.end());
    argv.insert(argv.end(), {"--duration", "1"});  // a controller that starts anyway stops by itself
    if (c.args.size() >= 2 && c.args[0] == "--duration") argv.resize(argv.size() - 2);
    testing::ChildProcess p(argv, log);
    ASSERT_TRUE(p.started());
    const int rc = p.wait(std::chrono::seconds(20));
    const std::string out = readFile(log);
    // Refused: exit code 2 (docs/tools.md, "Exit codes"); 1 would be a run that failed, 128+ a crash.
    EXPECT_EQ(rc, 2) << "exit code " << rc << ", output:\n" << out;
    EXPECT_NE(out.find(c.expect), std::string::npos) << "the message does not quote '" << c.expect << "':\n" << out;
    EXPECT_EQ(out.find("running at"), std::string::npos) << "the loop started:\n" << out;
  }
}

TEST(ControllerBadSetup, HelpExitsZero) {
  const std::string log = tmp("help.log");
  testing::ChildProcess p({controllerExe(), "--help"}, log);
  EXPECT_EQ(p.wait(std::chrono::seconds(10)), 0);
  EXPECT_NE(readFile(log).find("--input-timeout"), std::string::npos);
}

}  // namespace
}  // namespace reflex::bad_input
