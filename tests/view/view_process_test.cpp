// reflex_view as a real process (issue 14, items 3 and 4 of its tests): fed by a running
// reflex_controller and reflex_behavior (scripted crossing arms; for the page also the grasped bar, the
// gaze line and synthetic vision objects: separate processes, real DDS), checked by independent clients:
//   - the Foxglove protocol's reference client (@foxglove/ws-protocol in Node, ws_client_check.js):
//     >= 20 scene updates/s, capsule / sphere / transform counts from the URDF text, every message valid
//     against its advertised schema, protocol errors answered with a status message;
//   - a DDS participant of this test that watches discovery: reflex_view announces no writer at all;
//   - Debian's Chromium, headless with SwiftShader WebGL, driven over the DevTools protocol
//     (page_check.js): window.reflexView counts equal the URDF's, pixels of the robot really rendered,
//     zone colours present, no page error; the screenshot stays in the build tree;
//   - start-up errors (port in use, bad --bind, missing web folder, bad --rate, bad URDF) exit 2 with a
//     message naming the value; --help exits 0.
// Node, Chromium or bringup/web/node_modules missing is a FAILURE (bringup/setup.sh installs them).
// DDS domains 130..133.
#include "support/child_process.hpp"

#include <fastdds/dds/domain/DomainParticipant.hpp>
#include <fastdds/dds/domain/DomainParticipantFactory.hpp>
#include <fastdds/dds/domain/DomainParticipantListener.hpp>
#include <fastdds/dds/domain/qos/DomainParticipantQos.hpp>
#include <fastrtps/rtps/participant/ParticipantDiscoveryInfo.h>
#include <fastrtps/rtps/reader/ReaderDiscoveryInfo.h>
#include <fastrtps/rtps/writer/WriterDiscoveryInfo.h>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <unistd.h>

#include <fstream>
#include <mutex>
#include <regex>
#include <set>
#include <sstream>
#include <thread>

namespace reflex {
namespace {

using namespace std::chrono_literals;
const std::string kBin = REFLEX_BIN_DIR;
const std::string kSource = REFLEX_SOURCE_DIR;
const std::string kModules = kSource + "/bringup/web/node_modules";
const std::string kUrdf = kSource + "/bringup/robots/asimo_like.urdf";

std::string readText(const std::string& path) {
  std::ifstream in(path);
  return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
}

bool exists(const std::string& path) {
  struct stat st {};
  return ::stat(path.c_str(), &st) == 0;
}

/// The tools the tests need, or a failure naming what is missing.
::testing::AssertionResult toolsPresent(bool chromium) {
  if (std::string(REFLEX_NODE).empty() || !exists(REFLEX_NODE))
    return ::testing::AssertionFailure() << "node not found (Debian package nodejs; bringup/setup.sh installs it)";
  if (!exists(kModules + "/ws") || !exists(kModules + "/@foxglove/ws-protocol") || !exists(kModules + "/three/build"))
    return ::testing::AssertionFailure() << kModules << " incomplete: run `npm ci` in bringup/web (bringup/setup.sh)";
  if (chromium && (std::string(REFLEX_CHROMIUM).empty() || !exists(REFLEX_CHROMIUM)))
    return ::testing::AssertionFailure() << "chromium not found (Debian package chromium; bringup/setup.sh installs it)";
  return ::testing::AssertionSuccess();
}

/// Runs a command to its end (timeout) and returns the last line of its output parsed as JSON.
nlohmann::json runJson(std::vector<std::string> argv, const std::string& log, std::chrono::milliseconds timeout) {
  testing::ChildProcess p(std::move(argv), log);
  EXPECT_TRUE(p.started());
  const int rc = p.wait(timeout);
  const std::string text = readText(log);
  EXPECT_EQ(rc, 0) << text;
  std::istringstream lines(text);
  std::string line, last;
  while (std::getline(lines, line))
    if (!line.empty() && line[0] == '{') last = line;
  nlohmann::json j = nlohmann::json::parse(last, nullptr, false);
  EXPECT_FALSE(j.is_discarded()) << "no JSON result in:\n" << text;
  return j.is_discarded() ? nlohmann::json::object() : j;
}

/// Controller + scripted behavior + reflex_view on one domain; the view's port from its banner.
/// `behavior_config`: a file of bringup/behavior/; `objects`: NAME=X,Y,Z published as vision objects
/// by reflex_modules_object_publisher (none: no publisher).
struct LiveSystem {
  LiveSystem(int domain, const std::string& name, const std::string& behavior_config = "scripted.yaml",
             const std::vector<std::string>& objects = {})
      : controller({kBin + "/reflex_controller", "--domain", std::to_string(domain), "--duration", "60"},
                   ::testing::TempDir() + name + "_controller.log"),
        behavior({kBin + "/reflex_behavior", "--config", kSource + "/bringup/behavior/" + behavior_config, "--domain",
                  std::to_string(domain), "--duration", "60"},
                 ::testing::TempDir() + name + "_behavior.log"),
        publisher(publisherArgs(domain, objects), ::testing::TempDir() + name + "_objects.log"),
        view_log(::testing::TempDir() + name + "_view.log"),
        view({kBin + "/reflex_view", "--domain", std::to_string(domain), "--port", "0", "--duration", "60"}, view_log) {
    const auto end = std::chrono::steady_clock::now() + 20s;
    const std::regex banner("serving http://127\\.0\\.0\\.1:([0-9]+)");
    while (port == 0 && std::chrono::steady_clock::now() < end) {
      std::smatch m;
      const std::string text = readText(view_log);
      if (std::regex_search(text, m, banner)) port = std::stoi(m[1]);
      std::this_thread::sleep_for(100ms);
    }
  }
  std::string url() const { return "http://127.0.0.1:" + std::to_string(port) + "/"; }
  static std::vector<std::string> publisherArgs(int domain, const std::vector<std::string>& objects) {
    if (objects.empty()) return {"/bin/true"};
    std::vector<std::string> argv{kBin + "/reflex_modules_object_publisher", "--domain", std::to_string(domain),
                                  "--duration", "60", "--rate", "10"};
    for (const std::string& o : objects) argv.insert(argv.end(), {"--object", o});
    return argv;
  }
  testing::ChildProcess controller, behavior, publisher;
  std::string view_log;
  testing::ChildProcess view;
  int port = 0;
};

/// Watches discovery on a domain: participant names and the writers / readers of each participant.
class DiscoveryWatch final : public eprosima::fastdds::dds::DomainParticipantListener {
 public:
  void on_participant_discovery(eprosima::fastdds::dds::DomainParticipant*,
                                eprosima::fastrtps::rtps::ParticipantDiscoveryInfo&& info) override {
    if (info.status != eprosima::fastrtps::rtps::ParticipantDiscoveryInfo::DISCOVERED_PARTICIPANT) return;
    const std::lock_guard<std::mutex> lock(mutex_);
    names_[text(info.info.m_guid.guidPrefix)] = info.info.m_participantName.to_string();
  }
  void on_publisher_discovery(eprosima::fastdds::dds::DomainParticipant*,
                              eprosima::fastrtps::rtps::WriterDiscoveryInfo&& info) override {
    const std::lock_guard<std::mutex> lock(mutex_);
    writers_[text(info.info.guid().guidPrefix)].insert(info.info.topicName().to_string());
  }
  void on_subscriber_discovery(eprosima::fastdds::dds::DomainParticipant*,
                               eprosima::fastrtps::rtps::ReaderDiscoveryInfo&& info) override {
    const std::lock_guard<std::mutex> lock(mutex_);
    readers_[text(info.info.guid().guidPrefix)].insert(info.info.topicName().to_string());
  }
  /// GUID prefix of the participant that announced `name` ("" if none yet).
  std::string prefixOf(const std::string& name) {
    const std::lock_guard<std::mutex> lock(mutex_);
    for (const auto& [g, n] : names_)
      if (n == name) return g;
    return "";
  }
  std::set<std::string> writersOf(const std::string& prefix) {
    const std::lock_guard<std::mutex> lock(mutex_);
    return writers_[prefix];
  }
  std::set<std::string> readersOf(const std::string& prefix) {
    const std::lock_guard<std::mutex> lock(mutex_);
    return readers_[prefix];
  }

 private:
  static std::string text(const eprosima::fastrtps::rtps::GuidPrefix_t& prefix) {
    std::ostringstream out;
    out << prefix;
    return out.str();
  }
  std::mutex mutex_;
  std::map<std::string, std::string> names_;
  std::map<std::string, std::set<std::string>> writers_, readers_;
};

TEST(ReflexView, FoxgloveClientGetsTheLiveSceneAndTheViewWritesNothing) {
  ASSERT_TRUE(toolsPresent(false));
  constexpr int kDomain = 130;
  DiscoveryWatch watch;
  auto* factory = eprosima::fastdds::dds::DomainParticipantFactory::get_instance();
  eprosima::fastdds::dds::DomainParticipantQos qos;
  qos.name("view_test_watch");
  auto* watcher = factory->create_participant(kDomain, qos, &watch, eprosima::fastdds::dds::StatusMask::none());
  ASSERT_NE(watcher, nullptr);

  {
    LiveSystem sys(kDomain, "view_ws");
    ASSERT_GT(sys.port, 0) << readText(sys.view_log);
    std::this_thread::sleep_for(2s);  // the controller's first samples
    const nlohmann::json r =
        runJson({REFLEX_NODE, kSource + "/tests/view/ws_client_check.js", "--url", "ws://127.0.0.1:" + std::to_string(sys.port),
                 "--urdf", kUrdf, "--modules", kModules, "--seconds", "4"},
                ::testing::TempDir() + "view_ws_client.log", 30s);
    ASSERT_TRUE(r.contains("rates")) << r.dump();
    std::printf("ws client: %s\n", r.dump().substr(0, 600).c_str());
    EXPECT_EQ(r["subprotocol"], "foxglove.websocket.v1");
    EXPECT_EQ(r["serverInfo"]["metadata"]["robot"], "asimo_like");
    ASSERT_EQ(r["channels"].size(), 3U);
    for (const auto& c : r["channels"]) {
      EXPECT_EQ(c["encoding"], "json");
      EXPECT_EQ(c["schemaEncoding"], "jsonschema");
    }
    EXPECT_GE(r["rates"]["/reflex/scene"].get<double>(), 20.0) << "scene updates per second";
    EXPECT_GE(r["rates"]["/tf"].get<double>(), 20.0);
    EXPECT_GE(r["rates"]["/reflex/status"].get<double>(), 20.0);
    EXPECT_LE(r["rates"]["/reflex/scene"].get<double>(), 33.0) << "rate-limited to ~30 Hz";
    const int capsules = r["expectedCapsules"], spheres = r["expectedSpheres"];
    EXPECT_EQ(capsules, 17) << "asimo_like.urdf: 17 cylinder collision elements";
    EXPECT_EQ(spheres, 3) << "asimo_like.urdf: 3 sphere collision elements";
    ASSERT_GT(r["capsules"].size(), 50U);
    for (const auto& n : r["capsules"]) EXPECT_EQ(n.get<int>(), capsules);
    for (const auto& n : r["spheres"]) EXPECT_EQ(n.get<int>(), 2 * capsules + spheres) << "two end spheres per capsule";
    for (const auto& n : r["transforms"]) EXPECT_EQ(n, r["expectedTransforms"]);
    EXPECT_TRUE(r["schemaErrors"].empty()) << r["schemaErrors"].dump();
    ASSERT_EQ(r["statusErrors"].size(), 1U) << r["statusErrors"].dump();
    EXPECT_EQ(r["statusErrors"][0]["level"], 2);
    EXPECT_NE(r["statusErrors"][0]["message"].get<std::string>().find("4242"), std::string::npos);
    EXPECT_EQ(r["afterUnsubscribe"], 0) << "no /tf message after unsubscribe";

    // Never writes: its participant ("view") is discovered with its readers, and announces no writer.
    const std::string prefix = watch.prefixOf("view");
    ASSERT_FALSE(prefix.empty()) << "the view's participant was discovered";
    EXPECT_TRUE(watch.writersOf(prefix).empty()) << "reflex_view writes " << *watch.writersOf(prefix).begin();
    const std::set<std::string> readers = watch.readersOf(prefix);
    EXPECT_EQ(readers, (std::set<std::string>{"reflex/joint_state", "reflex/control_status", "reflex/hand_targets",
                                              "reflex/object_targets", "reflex/controller_protection",
                                              "reflex/body_schema"}));
    EXPECT_FALSE(watch.writersOf(watch.prefixOf("controller")).empty()) << "the watch sees writers at all";

    EXPECT_EQ(sys.view.terminate(), 0);
    const std::string log = readText(sys.view_log);
    EXPECT_NE(log.find("reflex_view: stats"), std::string::npos) << log;
    EXPECT_NE(log.find("bad_client_messages=1 "), std::string::npos) << log;
  }
  factory->delete_participant(watcher);
}

TEST(ReflexView, PageRendersTheRobotInHeadlessChromium) {
  ASSERT_TRUE(toolsPresent(true));
  // The grasped bar and the gaze line (body schema), scripted targets, and two vision objects.
  LiveSystem sys(131, "view_page", "bar_occlusion.yaml", {"red_cup=0.50,0.10,1.00", "can=0.45,-0.25,0.90"});
  ASSERT_GT(sys.port, 0) << readText(sys.view_log);
  const std::string shot = std::string(REFLEX_ARTEFACT_DIR) + "/reflex_view_page.png";
  std::remove(shot.c_str());
  const nlohmann::json r = runJson({REFLEX_NODE, kSource + "/tests/view/page_check.js", "--url", sys.url(), "--urdf", kUrdf,
                                    "--modules", kModules, "--chromium", REFLEX_CHROMIUM, "--screenshot", shot,
                                    "--seconds", "4"},
                                   ::testing::TempDir() + "view_page_check.log", 90s);
  ASSERT_TRUE(r.contains("view")) << r.dump();
  std::printf("page: %s\n", r.dump().substr(0, 900).c_str());
  const nlohmann::json& v = r["view"];
  EXPECT_TRUE(v["connected"].get<bool>());
  EXPECT_GT(v["framesReceived"].get<int>(), 0);
  EXPECT_GE(r["framesDuringWait"].get<double>() / r["waitSeconds"].get<double>(), 15.0) << "scene updates per second drawn";
  EXPECT_EQ(v["capsulesDrawn"], r["expectedCapsules"]);
  EXPECT_EQ(v["spheresDrawn"], r["expectedSpheres"]);
  EXPECT_EQ(r["expectedCapsules"], 17);
  ASSERT_FALSE(v["zoneColours"].empty()) << "segments coloured by zone";
  const std::regex hex("#[0-9a-f]{6}");
  for (const auto& [zone, colour] : v["zoneColours"].items()) {
    EXPECT_TRUE(zone == "free" || zone == "yellow" || zone == "orange" || zone == "red") << zone;
    EXPECT_TRUE(std::regex_match(colour.get<std::string>(), hex)) << colour;
  }
  EXPECT_GT(v["statusReceived"].get<int>(), 0);
  EXPECT_EQ(v["closestLines"], 2) << "one closest-pair line per arm";
  int given = 0;
  for (const auto& a : v["lastStatus"]["arms"]) given += a["target_given"].get<bool>() ? 1 : 0;
  EXPECT_NEAR(v["targetsDrawn"].get<int>(), given, 1) << "targets drawn follow the hand targets (one may change in between)";
  EXPECT_EQ(v["objectsDrawn"], 2) << "the two published objects";
  EXPECT_GE(v["schemaDrawn"].get<int>(), 1) << "the grasped bar (and the gaze line while it is enabled)";
  EXPECT_FALSE(v["cameraImage"].get<bool>());
  EXPECT_EQ(r["cameraPanel"], "no camera image on the bus");
  EXPECT_GT(r["robotPixels"].get<int>(), 2000) << "the robot is really rendered (WebGL read back)";
  EXPECT_TRUE(r["pageErrors"].empty()) << r["pageErrors"].dump();
  EXPECT_TRUE(v["errors"].empty()) << v["errors"].dump();
  const std::string png = readText(shot);
  ASSERT_GT(png.size(), 10000U) << shot;
  EXPECT_EQ(png.substr(1, 3), "PNG");
}

int listeningSocket(int& port) {
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  a.sin_port = 0;
  socklen_t len = sizeof(a);
  if (fd < 0 || ::bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof(a)) != 0 || ::listen(fd, 1) != 0 ||
      ::getsockname(fd, reinterpret_cast<sockaddr*>(&a), &len) != 0)
    return -1;
  port = ntohs(a.sin_port);
  return fd;
}

/// Resident memory of a process [kB] (VmRSS of /proc/PID/status), -1 if unreadable.
long residentKb(pid_t pid) {
  std::ifstream in("/proc/" + std::to_string(pid) + "/status");
  std::string line;
  while (std::getline(in, line))
    if (line.rfind("VmRSS:", 0) == 0) return std::stol(line.substr(6));
  return -1;
}

TEST(ReflexView, ASlowClientSkipsMessagesAndTheViewDoesNotGrow) {
  // A client that subscribes to the scene and then never reads (a frozen browser tab): a raw
  // WebSocket handshake and one masked subscribe frame (RFC 6455), with a small receive buffer.
  LiveSystem sys(133, "view_slow", "scripted.yaml");
  ASSERT_GT(sys.port, 0) << readText(sys.view_log);
  std::this_thread::sleep_for(2s);
  const long rss_before = residentKb(sys.view.pid());
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  ASSERT_GE(fd, 0);
  const int small = 4096;
  ::setsockopt(fd, SOL_SOCKET, SO_RCVBUF, &small, sizeof(small));
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  a.sin_port = htons(static_cast<std::uint16_t>(sys.port));
  ASSERT_EQ(::connect(fd, reinterpret_cast<sockaddr*>(&a), sizeof(a)), 0);
  const std::string handshake = "GET / HTTP/1.1\r\nHost: 127.0.0.1\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
                                "Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n"
                                "Sec-WebSocket-Protocol: foxglove.websocket.v1\r\n\r\n";
  ASSERT_EQ(::send(fd, handshake.data(), handshake.size(), 0), static_cast<ssize_t>(handshake.size()));
  char reply[512] = {};
  ASSERT_GT(::recv(fd, reply, sizeof(reply) - 1, 0), 0);
  ASSERT_NE(std::string(reply).find("101"), std::string::npos) << reply;
  const std::string subscribe = R"({"op":"subscribe","subscriptions":[{"id":1,"channelId":2},{"id":2,"channelId":1}]})";
  std::string frame{static_cast<char>(0x81), static_cast<char>(0x80 | subscribe.size()), 0, 0, 0, 0};  // mask 0
  frame += subscribe;
  ASSERT_EQ(::send(fd, frame.data(), frame.size(), 0), static_cast<ssize_t>(frame.size()));
  std::this_thread::sleep_for(12s);  // ~1.5 MB/s of scene and transforms, never read
  const long rss_after = residentKb(sys.view.pid());
  ::close(fd);
  EXPECT_EQ(sys.view.terminate(), 0);
  const std::string log = readText(sys.view_log);
  const std::regex dropped("dropped_slow_client=([0-9]+)"), sent("messages_sent=([0-9]+)");
  std::smatch m;
  ASSERT_TRUE(std::regex_search(log, m, dropped)) << log;
  const long n_dropped = std::stol(m[1]);
  ASSERT_TRUE(std::regex_search(log, m, sent));
  std::printf("slow client: sent %s, dropped %ld; view RSS %ld kB -> %ld kB\n", m[1].str().c_str(), n_dropped, rss_before,
              rss_after);
  EXPECT_GT(n_dropped, 0) << "messages for the blocked client were skipped\n" << log;
  // Without the limit the queue grew 8 MB in these 12 s (measured); with it 2.7 MB.
  EXPECT_LT(rss_after - rss_before, 6 * 1024) << "the view's memory stays bounded (2 MB queue + buffers)";
}

TEST(ReflexView, StartupErrorsNameTheBadValue) {
  auto run = [](std::vector<std::string> extra, int expect_rc, const std::string& expect_text) {
    std::vector<std::string> argv{kBin + "/reflex_view", "--domain", "132"};
    argv.insert(argv.end(), extra.begin(), extra.end());
    if (std::find(extra.begin(), extra.end(), "--duration") == extra.end()) argv.insert(argv.end(), {"--duration", "1"});
    const std::string log = ::testing::TempDir() + "view_setup.log";
    testing::ChildProcess p(argv, log);
    EXPECT_EQ(p.wait(15s), expect_rc) << readText(log);
    const std::string text = readText(log);
    EXPECT_NE(text.find(expect_text), std::string::npos) << "expected '" << expect_text << "' in:\n" << text;
  };
  int port = 0;
  const int fd = listeningSocket(port);
  ASSERT_GE(fd, 0);
  run({"--port", std::to_string(port)}, 2, "cannot listen on 127.0.0.1:" + std::to_string(port) + ": Address already in use");
  ::close(fd);
  run({"--bind", "999.1.2.3"}, 2, "--bind '999.1.2.3' is not an IP address");
  run({"--bind", "localhost"}, 2, "--bind 'localhost' is not an IP address");
  run({"--port", "70000"}, 2, "--port 70000 is outside 0..65535");
  run({"--web", "/nonexistent/web"}, 2, "--web folder '/nonexistent/web' has no index.html");
  run({"--three", "/nonexistent/three"}, 2, "three.js not found in '/nonexistent/three'");
  run({"--rate", "0"}, 2, "--rate 0");
  run({"--urdf", "/nonexistent/robot.urdf"}, 2, "/nonexistent/robot.urdf");
  run({"--help"}, 0, "Foxglove WebSocket");
  run({"--port", "0", "--bind", "::1", "--duration", "0.5"}, 0, "serving http://[::1]:");
}

}  // namespace
}  // namespace reflex
