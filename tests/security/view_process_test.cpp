// reflex_view in secure mode: the live view runs under its own identity `view`
// (bringup/security/make_security.sh), whose permissions grant subscriptions only. Real processes on
// domain 203: reflex_controller with the controller's profiles file publishes joint state and status
// encrypted; reflex_view with --profiles <dir>/profiles/view.xml reads them. Independent answers:
//  - the Foxglove protocol's reference client (@foxglove/ws-protocol in Node, tests/view/
//    ws_client_check.js) receives /reflex/scene updates with the URDF's 17 capsules (counted from the
//    URDF text) from the secure view; the same view without credentials (plain profiles) on the same
//    domain receives no joint state, so it draws nothing (the bus is really closed to it);
//  - the view's signed permissions document has no <publish> rule (read from the file), and Fast DDS
//    refuses to create a writer of EVERY Reflex topic for a participant holding the view identity
//    (create_datawriter returns null; reflex::bus throws BusError naming the topic), while the readers
//    reflex_view needs are created.
#include "support/child_process.hpp"
#include "security_support.hpp"

#include <nlohmann/json.hpp>

#include <gtest/gtest.h>

#include <csignal>
#include <regex>
#include <sstream>
#include <thread>
#include <sys/stat.h>

namespace reflex::security_test {
namespace {

using namespace std::chrono_literals;
constexpr int kDomain = 203;
const std::string kBin = REFLEX_BIN_DIR;
const std::string kSource = REFLEX_SOURCE_DIR;
const std::string kModules = kSource + "/bringup/web/node_modules";
const std::string kUrdf = kSource + "/bringup/robots/asimo_like.urdf";

/// reflex_view's port from its banner (0 if it did not start within 20 s).
int viewPort(const std::string& log) {
  const std::regex banner("serving http://127\\.0\\.0\\.1:([0-9]+)");
  const auto end = std::chrono::steady_clock::now() + 20s;
  while (std::chrono::steady_clock::now() < end) {
    std::smatch m;
    const std::string text = readFile(log);
    if (std::regex_search(text, m, banner)) return std::stoi(m[1]);
    std::this_thread::sleep_for(100ms);
  }
  return 0;
}

/// The reference client for `seconds` against the view on `port`: its JSON result line.
nlohmann::json wsClient(int port, const std::string& log) {
  testing::ChildProcess p(
      {REFLEX_NODE, kSource + "/tests/view/ws_client_check.js", "--url", "ws://127.0.0.1:" + std::to_string(port),
       "--urdf", kUrdf, "--modules", kModules, "--seconds", "3"},
      log);
  EXPECT_EQ(p.wait(30s), 0) << readFile(log);
  std::istringstream lines(readFile(log));
  std::string line, last;
  while (std::getline(lines, line))
    if (!line.empty() && line[0] == '{') last = line;
  const nlohmann::json j = nlohmann::json::parse(last, nullptr, false);
  EXPECT_FALSE(j.is_discarded()) << "no JSON result in:\n" << readFile(log);
  return j.is_discarded() ? nlohmann::json::object() : j;
}

bool toolsPresent() {
  struct stat st {};
  return !std::string(REFLEX_NODE).empty() && ::stat(REFLEX_NODE, &st) == 0 &&
         ::stat((kModules + "/@foxglove/ws-protocol").c_str(), &st) == 0;
}

TEST(SecureView, ReceivesTheSceneUnderAReadOnlyIdentityThatCannotWrite) {
  ASSERT_TRUE(toolsPresent()) << "node (Debian nodejs) and bringup/web/node_modules (npm ci) are needed";
  const std::string dir = makeSecurityMaterial("view");
  const std::string dom = std::to_string(kDomain);

  // The permissions document: subscriptions only.
  const std::string permissions = readFile(dir + "/view/permissions.xml");
  EXPECT_NE(permissions.find("<subject_name>CN=reflex.view</subject_name>"), std::string::npos) << permissions;
  EXPECT_NE(permissions.find("<subscribe>"), std::string::npos) << permissions;
  EXPECT_EQ(permissions.find("<publish>"), std::string::npos) << "the view may publish nothing:\n" << permissions;

  testing::ChildProcess controller({kBin + "/reflex_controller", "--domain", dom, "--duration", "40", "--profiles",
                                    dir + "/profiles/controller.xml"},
                                   dir + "/controller.log");
  const std::string view_log = dir + "/view.log", plain_log = dir + "/plain_view.log";
  testing::ChildProcess view({kBin + "/reflex_view", "--domain", dom, "--port", "0", "--duration", "40", "--profiles",
                              dir + "/profiles/view.xml"},
                             view_log);
  testing::ChildProcess plain_view(
      {kBin + "/reflex_view", "--domain", dom, "--port", "0", "--duration", "40", "--profiles", kBaseProfiles},
      plain_log);
  ASSERT_TRUE(controller.started() && view.started() && plain_view.started());
  const int port = viewPort(view_log), plain_port = viewPort(plain_log);
  ASSERT_GT(port, 0) << readFile(view_log);
  ASSERT_GT(plain_port, 0) << readFile(plain_log);
  std::this_thread::sleep_for(4s);  // secure discovery (authentication handshakes) and the first samples

  // A client of 3 s, again (at most 3 times) while the handshakes have not let the scenes flow yet
  // (1-5 s per pair on a loaded machine).
  nlohmann::json r;
  int scenes = 0;
  for (int attempt = 0; attempt < 3 && scenes < 30; ++attempt) {
    r = wsClient(port, dir + "/ws_secure.log");
    ASSERT_TRUE(r.contains("counts")) << r.dump();
    scenes = r["counts"].value("/reflex/scene", 0);
  }
  EXPECT_GE(scenes, 30) << "about 3 s of scenes from the secure view\n" << readFile(view_log);
  EXPECT_EQ(r["expectedCapsules"], 17);
  for (const auto& n : r["capsules"]) ASSERT_EQ(n, r["expectedCapsules"]);
  EXPECT_TRUE(r["schemaErrors"].empty()) << r["schemaErrors"].dump();
  std::printf("secure view: %d scenes in %.1f s\n", scenes, r.value("seconds", 0.0));

  const nlohmann::json plain = wsClient(plain_port, dir + "/ws_plain.log");
  ASSERT_TRUE(plain.contains("counts")) << plain.dump();
  EXPECT_EQ(plain["counts"].value("/reflex/scene", -1), 0)
      << "a view without credentials gets no joint state from the secure controller";

  // Writes by the view identity: refused for every Reflex topic; the readers it needs are granted.
  loadProfiles(dir);
  auto as_view = secureParticipant(dir, "view", kDomain + 1);
  try {
    as_view->makeWriter<msg::HandTargets>();
    ADD_FAILURE() << "the view identity created a hand-targets writer";
  } catch (const bus::BusError& e) {
    EXPECT_NE(std::string(e.what()).find("reflex/hand_targets"), std::string::npos) << e.what();
  }
  EXPECT_THROW(as_view->makeWriter<msg::ObjectTargets>(), bus::BusError);
  EXPECT_THROW(as_view->makeWriter<msg::MotionPriority>(), bus::BusError);
  EXPECT_THROW(as_view->makeWriter<msg::BodySchemaChange>(), bus::BusError);
  EXPECT_THROW(as_view->makeWriter<msg::WalkCommand>(), bus::BusError);
  EXPECT_THROW(as_view->makeWriter<msg::RobotContacts>(), bus::BusError);
  EXPECT_THROW(as_view->makeWriter<msg::JointState>(), bus::BusError);
  EXPECT_THROW(as_view->makeWriter<msg::ControlStatus>(), bus::BusError);
  EXPECT_THROW(as_view->makeWriter<msg::Heartbeat>(), bus::BusError);
  EXPECT_THROW(as_view->makeWriter<msg::ControllerProtection>(), bus::BusError);
  EXPECT_THROW(as_view->makeWriter<msg::RobotState>(), bus::BusError);
  EXPECT_THROW(as_view->makeWriter<msg::JointCommand>(), bus::BusError);
  EXPECT_NO_THROW(as_view->makeReader<msg::JointState>());
  EXPECT_NO_THROW(as_view->makeReader<msg::ControlStatus>());
  EXPECT_NO_THROW(as_view->makeReader<msg::BodySchemaChange>());
  EXPECT_THROW(as_view->makeReader<msg::WalkCommand>(), bus::BusError) << "nor does it read what it does not draw";

  view.signal(SIGINT);
  plain_view.signal(SIGINT);
  EXPECT_EQ(view.wait(15s), 0) << readFile(view_log);
  EXPECT_EQ(plain_view.wait(15s), 0) << readFile(plain_log);
  // The plain view's own count: it never took a joint state.
  EXPECT_NE(readFile(plain_log).find("joint_states=0 "), std::string::npos) << readFile(plain_log);
}

}  // namespace
}  // namespace reflex::security_test
