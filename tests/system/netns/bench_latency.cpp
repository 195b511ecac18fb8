// reflex_latency_bench: frame capture time -> the controller applying the new target,
// over real DDS with the real reflex_controller process, on one host or across network namespaces;
// then the controller's cycle lateness over a long run. Not a ctest: run by hand, figures go into
// bringup/README.md.
//
// How "applied" is observed without instrumenting the controller: the bench alternates the left hand
// target between two points 12 cm apart (every --period s). The controller's reaching reference runs
// along a straight line to the newest target (paper Sec. 8), so in the cycle that takes a new target
// the left arm's joint velocity turns by more than 60 degrees; that cycle's reflex/joint_state stamp
// (Header.stamp_ns, written by the controller right after computing it) is the application time.
// The capture time is the target's own source stamp (HandTargets.header.stamp_ns, or with
// --path objects the ObjectTargets capture_stamp_ns that reflex_behavior turns into hand targets).
// All stamps are CLOCK_REALTIME of one kernel (network namespaces share it), so no clock sync enters.
//
// Reported, p50 / p99 / max over the targets:
//   capture -> hand target received here (transport [+ behavior]; this process sits on the source host)
//   capture -> applied by the controller (includes waiting for the next 5 ms cycle: uniform 0..5 ms)
// and, from `reflex_controller --duration` at exit, the cycle lateness p50 / p99 / max.
#include "support/child_process.hpp"

#include <reflex/bus/bus.hpp>
#include <reflex/record/record_file.hpp>

#include <CLI/CLI.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <map>
#include <mutex>
#include <regex>
#include <sstream>
#include <thread>
#include <unistd.h>

namespace {

using namespace reflex;
using namespace std::chrono_literals;

struct Options {
  std::string bin_dir = REFLEX_BIN_DIR;
  int domain = 90;
  int samples = 300;
  double period = 0.25;
  double minutes = 10.0;
  bool netns = false;
  bool skip_lateness = false;
  std::string path = "hands";
  std::string robot_ns;  // inner run: controller's namespace
  std::string work = "/tmp";
  int rt = 0;  // > 0: SCHED_FIFO priority for the controller, recorder and behavior (chrt -f)
};

std::vector<std::string> rtPrefix(const Options& o) {
  if (o.rt <= 0) return {};
  return {"/usr/bin/chrt", "-f", std::to_string(o.rt)};
}

struct Stats {
  double p50 = 0, p99 = 0, max = 0;
  std::size_t n = 0;
};
Stats stats(std::vector<double> v) {
  Stats s;
  if (v.empty()) return s;
  std::sort(v.begin(), v.end());
  s.n = v.size();
  s.p50 = v[v.size() / 2];
  s.p99 = v[std::min(v.size() - 1, static_cast<std::size_t>(0.99 * static_cast<double>(v.size())))];
  s.max = v.back();
  return s;
}
void print(const char* what, const Stats& s) {
  std::printf("  %-52s p50 %7.3f ms  p99 %7.3f ms  max %7.3f ms  (n=%zu)\n", what, s.p50, s.p99, s.max, s.n);
}

int sh(const std::string& cmd) {
  const int rc = std::system(cmd.c_str());
  if (rc != 0) std::fprintf(stderr, "reflex_latency_bench: command failed (%d): %s\n", rc, cmd.c_str());
  return rc;
}

std::string slurp(const std::string& path) {
  std::ifstream in(path);
  return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
}

std::vector<std::string> nsPrefix(const std::string& ns) {
  if (ns.empty()) return {};
  return {"/usr/sbin/ip", "netns", "exec", ns};
}
std::vector<std::string> cat(std::vector<std::string> a, const std::vector<std::string>& b) {
  a.insert(a.end(), b.begin(), b.end());
  return a;
}

// Joint state samples as received: stamp and the left-arm velocities.
struct JsSample {
  std::int64_t stamp;
  std::vector<double> qd;
};

int measureTargets(const Options& o) {
  const std::string dom = std::to_string(o.domain);
  const std::string profiles = o.netns ? std::string(REFLEX_SOURCE_DIR) + "/bringup/dds/reflex_profiles_lan.xml" : "";
  std::vector<std::string> ctl = {o.bin_dir + "/reflex_controller", "--domain", dom, "--duration",
                                  std::to_string(o.samples * o.period + 15.0)};
  if (!profiles.empty()) ctl = cat(ctl, {"--profiles", profiles});
  ctl = cat(rtPrefix(o), ctl);
  if (o.robot_ns.empty() == false) ctl = cat(nsPrefix(o.robot_ns), ctl);
  const std::string ctl_log = o.work + "/bench_controller.log";
  reflex::testing::ChildProcess controller(ctl, ctl_log);
  // A recorder beside the controller (same host / namespace): its receive times are when the targets
  // reach a process on the robot host (the transport part, without the wait for the next cycle).
  const std::string rfx = o.work + "/bench_targets.rfx";
  std::vector<std::string> rec = {o.bin_dir + "/reflex_record",
                                  "record",
                                  "-o",
                                  rfx,
                                  "--domain",
                                  dom,
                                  "--flush-ms",
                                  "50",
                                  "-t",
                                  "reflex/hand_targets",
                                  "-t",
                                  "reflex/object_targets"};
  if (!profiles.empty()) rec = cat(rec, {"--profiles", profiles});
  rec = cat(rtPrefix(o), rec);
  if (!o.robot_ns.empty()) rec = cat(nsPrefix(o.robot_ns), rec);
  reflex::testing::ChildProcess recorder(rec, o.work + "/bench_recorder.log");
  std::unique_ptr<reflex::testing::ChildProcess> behavior;
  if (o.path == "objects") {
    std::vector<std::string> b = {o.bin_dir + "/reflex_behavior",
                                  "--config",
                                  std::string(REFLEX_SOURCE_DIR) + "/bringup/behavior/pointing.yaml",
                                  "--domain",
                                  dom,
                                  "--progress",
                                  "0"};
    if (!profiles.empty()) b = cat(b, {"--profiles", profiles});
    b = cat(rtPrefix(o), b);
    behavior = std::make_unique<reflex::testing::ChildProcess>(b, o.work + "/bench_behavior.log");
  }
  bus::BusConfig cfg;
  cfg.module_name = o.path == "objects" ? "vision" : "behavior";  // what the samples pretend to come from
  cfg.domain_id = o.domain;
  cfg.profiles_file = profiles;
  bus::Participant bus(cfg);
  auto& hands_w = bus.makeWriter<msg::HandTargets>();
  auto& objects_w = bus.makeWriter<msg::ObjectTargets>();
  auto& heartbeat_w = bus.makeWriter<msg::Heartbeat>();
  auto& js_r = bus.makeReader<msg::JointState>("reflex/joint_state", bus::kProfileRecord);
  if (!js_r.waitForWriters(1, 20s)) {
    std::fprintf(stderr, "reflex_latency_bench: no joint state from reflex_controller:\n%s\n", slurp(ctl_log).c_str());
    return 1;
  }
  if (!hands_w.waitForReaders(2, 20s)) {  // the controller and the recorder
    std::fprintf(stderr, "reflex_latency_bench: the controller and the recorder did not both subscribe\n");
    return 1;
  }

  // Left-arm joints (names starting with "l_" on the ASIMO-like robot).
  std::vector<int> left;
  std::mutex mu;
  std::vector<JsSample> js;
  js.reserve(static_cast<std::size_t>((o.samples * o.period + 20) * 200));
  std::atomic<bool> done{false};
  std::thread reader([&] {
    msg::JointState s;
    while (!done) {
      js_r.waitForData(10ms);
      while (js_r.takeNext(s)) {
        if (left.empty())
          for (std::size_t i = 0; i < s.names().size(); ++i)
            if (s.names()[i].rfind("l_", 0) == 0) left.push_back(static_cast<int>(i));
        JsSample x{s.header().stamp_ns(), {}};
        for (int i : left) x.qd.push_back(s.velocities()[static_cast<std::size_t>(i)]);
        std::lock_guard<std::mutex> lock(mu);
        js.push_back(std::move(x));
      }
    }
  });

  // Two reachable points for the left hand (robot base frame), 12 cm apart.
  const double ax = 0.40, ay = 0.22, az = 1.00, by = 0.10;
  std::vector<std::int64_t> capture;
  msg::Heartbeat hb;
  hb.module_name(cfg.module_name);
  hb.state(msg::STATE_RUNNING);
  std::this_thread::sleep_for(1s);
  for (int i = 0; i < o.samples; ++i) {
    const double y = i % 2 == 0 ? ay : by;
    if (o.path == "hands") {
      msg::HandTargets t;
      t.left().status(msg::TARGET_GIVEN);
      t.left().position_base().x(ax);
      t.left().position_base().y(y);
      t.left().position_base().z(az);
      t.right().status(msg::TARGET_NONE);
      hands_w.publish(t);
      capture.push_back(t.header().stamp_ns());
    } else {
      msg::ObjectTargets f;
      f.frame_id("base_link");
      f.image_index(static_cast<std::uint64_t>(i));
      msg::ObjectTarget obj;
      obj.name("can");  // the pointing configuration assigns the can to the left hand
      obj.tag_id(1);
      // The pointing module aims along shoulder->object; put the object beyond the two points.
      obj.position_base().x(0.45);
      obj.position_base().y(i % 2 == 0 ? 0.30 : 0.05);
      obj.position_base().z(az);
      obj.confidence(1.0);
      f.objects().push_back(obj);
      f.capture_stamp_ns(bus::nowNs());
      objects_w.publish(f);
      capture.push_back(f.capture_stamp_ns());
    }
    if (i % 2 == 0) heartbeat_w.publish(hb);
    std::this_thread::sleep_for(std::chrono::duration<double>(o.period));
  }
  std::this_thread::sleep_for(300ms);
  done = true;
  reader.join();
  controller.terminate();
  if (behavior) behavior->terminate();
  recorder.terminate();

  // For each capture: the first joint state after it whose left-arm velocity turned > 60 degrees.
  std::vector<double> to_applied, to_received;
  std::size_t k = 1, missed = 0;
  for (std::size_t i = 0; i < capture.size(); ++i) {
    const std::int64_t c = capture[i];
    const std::int64_t next = i + 1 < capture.size() ? capture[i + 1] : c + 1'000'000'000LL;
    while (k < js.size() && js[k].stamp <= c) ++k;
    bool found = false;
    for (std::size_t j = k; j < js.size() && js[j].stamp < next; ++j) {
      const auto& a = js[j - 1].qd;
      const auto& b = js[j].qd;
      double dot = 0, na = 0, nb = 0;
      for (std::size_t m = 0; m < a.size() && m < b.size(); ++m) {
        dot += a[m] * b[m];
        na += a[m] * a[m];
        nb += b[m] * b[m];
      }
      na = std::sqrt(na);
      nb = std::sqrt(nb);
      // turned by more than 25 degrees (cos 25 = 0.906) in one 5 ms cycle, or started from rest
      const bool turned = (na > 1e-3 && nb > 1e-3 && dot < 0.906 * na * nb) || (na <= 1e-3 && nb > 1e-2);
      if (turned) {
        to_applied.push_back(1e-6 * static_cast<double>(js[j].stamp - c));
        found = true;
        break;
      }
    }
    if (!found) ++missed;
  }
  // Hand targets as the recorder beside the controller received them (receive time - capture time;
  // with --path objects the behavior's hand targets, matched to the last capture before them).
  std::vector<std::pair<std::int64_t, std::int64_t>> hand_rx_by_stamp;  // (hand target stamp, receive)
  try {
    record::RecordReader r(rfx);
    record::RecordEntry e;
    while (r.next(e)) {
      if (e.topic != "reflex/hand_targets") continue;
      msg::HandTargets h;
      msg::HandTargetsPubSubType type;
      eprosima::fastrtps::rtps::SerializedPayload_t p(static_cast<std::uint32_t>(e.payload.size()));
      std::copy(e.payload.begin(), e.payload.end(), p.data);
      p.length = static_cast<std::uint32_t>(e.payload.size());
      if (type.deserialize(&p, &h)) hand_rx_by_stamp.emplace_back(h.header().stamp_ns(), e.receive_ns);
    }
  } catch (const std::exception& ex) {
    std::fprintf(stderr, "reflex_latency_bench: recording: %s\n", ex.what());
    return 1;
  }
  if (o.path == "hands") {
    for (const auto& [stamp, rx] : hand_rx_by_stamp) to_received.push_back(1e-6 * static_cast<double>(rx - stamp));
  } else {
    // The behavior's reaction to capture i: its first hand target stamped after c_i (and before c_i+1);
    // hand targets it publishes for other reasons (re-aiming on joint state) are not reactions.
    std::sort(hand_rx_by_stamp.begin(), hand_rx_by_stamp.end());
    for (std::size_t i = 0; i < capture.size(); ++i) {
      const std::int64_t next = i + 1 < capture.size() ? capture[i + 1] : capture[i] + 1'000'000'000LL;
      const auto it = std::lower_bound(hand_rx_by_stamp.begin(), hand_rx_by_stamp.end(),
                                       std::make_pair(capture[i], std::int64_t{0}));
      if (it != hand_rx_by_stamp.end() && it->first < next)
        to_received.push_back(1e-6 * static_cast<double>(it->second - capture[i]));
    }
  }
  const bool objects = o.path == "objects";
  std::printf("latency (%s%s, %s): %d targets every %.0f ms, %zu not seen applied\n", o.rt > 0 ? "SCHED_FIFO, " : "",
              o.netns ? "across network namespaces: bench in one, controller in another (UDP)" : "one host",
              objects ? "ObjectTargets -> reflex_behavior pointing -> HandTargets -> reflex_controller"
                      : "HandTargets -> reflex_controller",
              o.samples, o.period * 1e3, missed);
  print(objects ? "capture -> behavior's hand target at the robot host" : "capture -> hand target at the robot host",
        stats(to_received));
  print("capture -> applied by the controller (joint state)", stats(to_applied));
  std::string tail = slurp(ctl_log);
  const auto pos = tail.rfind("reflex_controller:");
  std::printf("  controller: %s", pos == std::string::npos ? "(no summary)\n" : tail.substr(pos).c_str());
  return missed > capture.size() / 10 ? 1 : 0;
}

int measureLateness(const Options& o) {
  const std::string log = o.work + "/bench_lateness.log";
  const double seconds = o.minutes * 60.0;
  std::printf("lateness: reflex_controller --duration %.0f (%.1f min) ...\n", seconds, o.minutes);
  std::fflush(stdout);
  reflex::testing::ChildProcess controller(
      cat(rtPrefix(o), {o.bin_dir + "/reflex_controller", "--domain", std::to_string(o.domain + 1), "--duration",
                        std::to_string(seconds)}),
      log);
  const int rc = controller.wait(std::chrono::milliseconds(static_cast<long>((seconds + 60.0) * 1000)));
  const std::string text = slurp(log);
  const auto pos = text.rfind("reflex_controller:");
  std::printf("  %s", pos == std::string::npos ? text.c_str() : text.substr(pos).c_str());
  return rc == 0 ? 0 : 1;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{
      "reflex_latency_bench: frame capture time -> reflex_controller applying the new target (p50/p99), on one\n"
      "host or across network namespaces (--netns, needs root), then the controller's cycle lateness over a\n"
      "long run (--minutes). Starts reflex_controller (and reflex_behavior with --path objects) itself."};
  Options o;
  app.add_option("--bin-dir", o.bin_dir, "folder of reflex_controller / reflex_behavior")->capture_default_str();
  app.add_option("--domain", o.domain, "DDS domain id (the lateness run uses domain + 1)")
      ->capture_default_str()
      ->check(CLI::Range(0, 231));
  app.add_option("--samples", o.samples, "number of targets")->capture_default_str()->check(CLI::Range(10, 100000));
  app.add_option("--period", o.period, "seconds between targets")->capture_default_str()->check(CLI::Range(0.05, 5.0));
  app.add_option("--minutes", o.minutes, "length of the lateness run (0: skip)")
      ->capture_default_str()
      ->check(CLI::Range(0.0, 600.0));
  app.add_option("--path", o.path,
                 "hands: HandTargets straight to the controller; objects: ObjectTargets through "
                 "reflex_behavior (pointing)")
      ->capture_default_str()
      ->check(CLI::IsMember({"hands", "objects"}));
  app.add_flag("--netns", o.netns, "run the controller (and behavior) in another network namespace (root)");
  app.add_option("--work", o.work, "folder for the child processes' logs")->capture_default_str();
  app.add_option("--rt", o.rt,
                 "run the controller, recorder and behavior with SCHED_FIFO at this priority "
                 "(chrt -f; 0: normal scheduling)")
      ->capture_default_str()
      ->check(CLI::Range(0, 99));
  app.add_option("--robot-ns", o.robot_ns, "(internal) the controller's namespace");
  CLI11_PARSE(app, argc, argv);
  if (!o.netns || !o.robot_ns.empty()) {
    int rc = measureTargets(o);
    if (o.robot_ns.empty() && o.minutes > 0.0) rc |= measureLateness(o);
    return rc;
  }
  // --netns: two namespaces joined by a veth pair (10.<domain>.0.1 / .2); this program runs again in the
  // first, the controller in the second. Always removed afterwards.
  if (geteuid() != 0) {
    std::fprintf(stderr, "reflex_latency_bench: --netns needs root (ip netns add)\n");
    return 1;
  }
  const std::string tag = "rfxb-" + std::to_string(getpid());
  const std::string src = tag + "-src", robot = tag + "-robot";
  const std::string a_if = "rb" + std::to_string(getpid() % 100000) + "a",
                    b_if = "rb" + std::to_string(getpid() % 100000) + "b";
  const std::string net = "10." + std::to_string(o.domain) + ".0.";
  int rc = sh("ip netns add " + src) | sh("ip netns add " + robot) | sh("ip -n " + src + " link set lo up") |
           sh("ip -n " + robot + " link set lo up") | sh("ip link add " + a_if + " type veth peer name " + b_if) |
           sh("ip link set " + a_if + " netns " + src) | sh("ip link set " + b_if + " netns " + robot) |
           sh("ip -n " + src + " addr add " + net + "1/24 dev " + a_if) |
           sh("ip -n " + robot + " addr add " + net + "2/24 dev " + b_if) |
           sh("ip -n " + src + " link set " + a_if + " up") | sh("ip -n " + robot + " link set " + b_if + " up") |
           sh("ip -n " + src + " route add 224.0.0.0/4 dev " + a_if) |
           sh("ip -n " + robot + " route add 224.0.0.0/4 dev " + b_if);
  if (rc == 0) {
    std::ostringstream cmd;
    cmd << "ip netns exec " << src << " " << argv[0] << " --netns --robot-ns " << robot << " --bin-dir " << o.bin_dir
        << " --domain " << o.domain << " --samples " << o.samples << " --period " << o.period << " --path " << o.path
        << " --work " << o.work << " --rt " << o.rt << " --minutes 0";
    rc = std::system(cmd.str().c_str());
  }
  sh("ip netns del " + src);
  sh("ip netns del " + robot);
  if (rc == 0 && o.minutes > 0.0) rc = measureLateness(o);
  return rc == 0 ? 0 : 1;
}
