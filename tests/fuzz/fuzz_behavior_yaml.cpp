// libFuzzer target: behavior configuration YAML (reflex_behavior --config FILE) -> ConfigNode::
// loadString + parseHostConfig + BehaviorHost (robot, every module built by the registry and
// configured), as BehaviorNode does. Documented error of that set-up: reflex::modules::ConfigError.
//
// A configuration the host accepts is then run briefly with plausible inputs (start, two objects,
// a joint state, ticks up to 30 s, stop): that phase must not throw at all, since a value accepted
// at set-up that fails later would stop reflex_behavior mid-run.
//
// The text is parsed as if it were a file in bringup/behavior/, so the relative paths of the shipped
// configurations (../robots/asimo_like.urdf, scripted_timeline.csv) resolve as they do there.
#include "fuzz_util.hpp"

#include "reflex/modules/config.hpp"
#include "reflex/modules/host.hpp"
#include "reflex/modules/registry.hpp"

namespace {

using namespace reflex::modules;

class NullSink final : public OutputSink {
 public:
  void handTargets(const HandTarget&, const HandTarget&) override {}
  void motionPriority(ArmPriority) override {}
  void segmentAttached(const SegmentSpec&) override {}
  void segmentDetached(const std::string&) override {}
  void walk(const WalkGoal&) override {}
};

Now at(double t) {
  Now n;
  n.t = t;
  n.wall_ns = 1700000000000000000LL + static_cast<std::int64_t>(t * 1e9);
  return n;
}

void run(BehaviorHost& host) {
  host.start(at(0.0));
  ObjectsFrame frame;
  frame.stamp_ns = frame.capture_stamp_ns = at(0.1).wall_ns;
  frame.source = "vision";
  frame.objects.push_back({"cup", 3, Eigen::Vector3d(0.40, 0.15, 0.95), 0.9});
  frame.objects.push_back({"can", 4, Eigen::Vector3d(0.40, -0.15, 0.95), 0.8});
  host.onObjects(frame, at(0.1));
  JointStateSample js;
  js.source = "controller";  // the default joint_state_sources
  js.stamp_ns = at(0.2).wall_ns;
  js.names = {"l_elbow", "r_elbow"};
  js.positions = {-0.5, -0.5};
  host.onJointState(js, at(0.2));
  for (double t : {0.25, 1.0, 2.5, 5.0, 12.0, 30.0}) host.tick(at(t));
  host.stop(at(30.5));
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static const ModuleRegistry registry = builtinRegistry();
  static NullSink sink;
  const std::string text = reflex::fuzz::asText(data, size);
  std::unique_ptr<BehaviorHost> host;
  reflex::fuzz::expectOnly<ConfigError>("BehaviorHost set-up", [&] {
    const HostConfig config =
        parseHostConfig(ConfigNode::loadString(text, REFLEX_SOURCE_DIR "/bringup/behavior/fuzz.yaml"), registry);
    host = std::make_unique<BehaviorHost>(config, registry, sink, [](const std::string&) {});
  });
  if (!host) return 0;
  try {
    run(*host);
  } catch (const std::exception& e) {
    reflex::fuzz::undocumentedException("BehaviorHost run (configuration accepted at set-up)", e);
  }
  return 0;
}
