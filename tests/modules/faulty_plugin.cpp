// A module plugin whose modules misbehave on purpose, for modules_plugin_faults_test: each type fails
// in one way a module can fail that the host cannot prevent, only name.
//   spin        step() never returns (a busy loop, 100 % of a core)
//   throw_int   throws the int 42 from the call named by its `call` key (configure, start, step, stop)
//   null_deref  step() writes through a null pointer (SIGSEGV)
#include <reflex/modules/module.hpp>
#include <reflex/modules/plugin.hpp>

#include <memory>
#include <string>

namespace {

using namespace reflex::modules;

class FaultyModule : public Module {
 public:
  using Module::Module;
  void configure(const ConfigNode& config, const RobotState& /*robot*/) override {
    config.rejectUnknown({"call"});
    call_ = config.choice("call", "step", {"configure", "start", "step", "stop"});
    if (call_ == "configure") throwInt();
  }
  Claims claims() const override { return {}; }
  double stepPeriod() const override { return 0.05; }
  void start(ModuleContext& /*ctx*/) override {
    if (call_ == "start") throwInt();
  }
  void stop(ModuleContext& /*ctx*/) override {
    if (call_ == "stop") throwInt();
  }

 protected:
  // Not a std::exception: what a careless plugin (or a C library's callback) may throw.
  [[noreturn]] static void throwInt() { throw 42; }
  std::string call_;
};

class SpinModule final : public FaultyModule {
 public:
  using FaultyModule::FaultyModule;
  void step(ModuleContext& /*ctx*/) override {
    volatile unsigned long spins = 0;  // volatile: a loop with a side effect, never optimised away
    for (;;) spins = spins + 1;
  }
};

class ThrowIntModule final : public FaultyModule {
 public:
  using FaultyModule::FaultyModule;
  void step(ModuleContext& /*ctx*/) override {
    if (call_ == "step") throwInt();
  }
};

class NullDerefModule final : public FaultyModule {
 public:
  using FaultyModule::FaultyModule;
  void step(ModuleContext& /*ctx*/) override {
    volatile int* volatile nowhere = nullptr;  // volatile: the compiler may not prove it null and drop the write
    *nowhere = 1;
  }
};

}  // namespace

REFLEX_MODULE_PLUGIN(registry) {
  registry.add("spin", "step() never returns", [](const std::string& n) { return std::make_unique<SpinModule>(n); });
  registry.add("throw_int", "throws an int from the call named by `call`",
               [](const std::string& n) { return std::make_unique<ThrowIntModule>(n); });
  registry.add("null_deref", "step() writes through a null pointer",
               [](const std::string& n) { return std::make_unique<NullDerefModule>(n); });
}
