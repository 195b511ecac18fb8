// The "wave" module type: one hand waves between two points of the base frame, one stroke per `period`
// seconds. A complete behavior module from outside the Reflex tree, loaded by the stock reflex_behavior
// from the configuration's `plugins:` list (see wave.yaml and modules/README.md).
#include <reflex/modules/module.hpp>
#include <reflex/modules/plugin.hpp>

#include <cmath>
#include <memory>
#include <string>

namespace {

using namespace reflex::modules;

class WaveModule final : public Module {
 public:
  using Module::Module;

  void configure(const ConfigNode& config, const RobotState& /*robot*/) override {
    config.rejectUnknown({"hand", "from", "to", "period"});
    hand_ = config.choice("hand", "left", {"left", "right"}) == "left" ? Hand::kLeft : Hand::kRight;
    from_ = config.vec3("from", from_);
    to_ = config.vec3("to", to_);
    period_ = config.number("period", period_, 0.2, 60.0);
  }
  Claims claims() const override {
    Claims c;
    c.hands[handIndex(hand_)] = true;
    return c;
  }
  double stepPeriod() const override { return 0.05; }
  void start(ModuleContext& ctx) override {
    t0_ = ctx.now().t;
    step(ctx);
  }
  void step(ModuleContext& ctx) override {
    // Smooth back and forth: s in [0, 1], a half cosine per stroke.
    const double s = 0.5 - 0.5 * std::cos(M_PI * (ctx.now().t - t0_) / period_);
    ctx.setHand(hand_, HandTarget::at(from_ + s * (to_ - from_)));
    ++strokes_updates_;
  }
  void stop(ModuleContext& ctx) override { ctx.setHand(hand_, HandTarget::none()); }
  std::string status() const override {
    return std::string("hand=") + handName(hand_) + " updates=" + std::to_string(strokes_updates_);
  }

 private:
  Hand hand_ = Hand::kLeft;
  Eigen::Vector3d from_{0.25, 0.25, 0.95};
  Eigen::Vector3d to_{0.30, 0.05, 1.05};
  double period_ = 2.0;
  double t0_ = 0.0;
  long strokes_updates_ = 0;
};

}  // namespace

REFLEX_MODULE_PLUGIN(registry) {
  registry.add("wave", "waves one hand between two points (an out-of-tree plugin example)",
               [](const std::string& name) { return std::make_unique<WaveModule>(name); });
}
