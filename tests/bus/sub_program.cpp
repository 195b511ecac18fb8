// bus_sub_program: waits for one sample of each selected topic type (default topics and profiles)
// and checks it field by field against the distinctive test sample (samples.hpp, variant 7); the
// header must come from --expect-source with seq >= 1 and a stamp within a minute of now.
// Exit 0 when every type was received intact, 1 on a mismatch, a timeout or a setup error.
// Used by bus_two_process_test and the Cyclone DDS interoperability tests.
#include <CLI/CLI.hpp>

#include <reflex/bus/bus.hpp>

#include <cstdlib>
#include <iostream>
#include <set>

#include "bus_test_util.hpp"
#include "program_types.hpp"

int main(int argc, char** argv) {
  using namespace reflex::bus;
  CLI::App app("Receive and verify one Reflex bus test sample per type.");
  int domain = 0;
  std::string types = "all";
  std::string participant_profile = "reflex_participant";
  std::string expect_source = "two_process_pub";
  double timeout_s = 15.0;
  app.add_option("--domain", domain, "DDS domain id")->required()->check(CLI::Range(0, kMaxDomainId));
  app.add_option("--types", types, "comma-separated type names, or 'all'");
  app.add_option("--participant-profile", participant_profile, "participant profile in the profiles file");
  app.add_option("--expect-source", expect_source, "expected Header.source of the samples");
  app.add_option("--timeout-s", timeout_s, "fail after this long")->check(CLI::PositiveNumber);
  CLI11_PARSE(app, argc, argv);

  try {
    Participant bus(test::testConfig("two_process_sub", domain, participant_profile));
    std::set<std::string> missing;
    int failures = 0;
    for (const auto& name : test::splitTypes(types)) {
      missing.insert(name);
      const bool known = test::forTypeName(name, [&](auto* tag) {
        using T = std::remove_pointer_t<decltype(tag)>;
        auto& reader = bus.makeReader<T>();
        reader.onData([&, name](const T& got) {
          if (missing.count(name) == 0) return;  // already verified
          T expected = test::sampleOf<T>(7);
          test::Diffs d;
          const auto& h = got.header();
          if (h.source() != expect_source)
            d.push_back("header.source: expected " + expect_source + ", got " + h.source());
          if (h.seq() < 1) d.push_back("header.seq: expected >= 1, got 0");
          if (std::llabs(h.stamp_ns() - nowNs()) > 60'000'000'000LL) {
            d.push_back("header.stamp_ns " + std::to_string(h.stamp_ns()) + " is not within a minute of now");
          }
          expected.header(h);  // the header was checked above; the rest must match exactly
          test::diff(name, expected, got, d);
          if (!d.empty()) {
            std::cerr << "bus_sub_program: " << name << " differs:\n" << test::join(d);
            ++failures;
          } else {
            std::cout << "verified " << name << " (seq " << h.seq() << ")" << std::endl;
          }
          missing.erase(name);
          if (missing.empty()) bus.stop();
        });
      });
      if (!known) {
        std::cerr << "bus_sub_program: unknown type '" << name << "' in --types\n";
        return 1;
      }
    }
    const bool timed_out =
        bus.runFor(std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::duration<double>(timeout_s)));
    if (timed_out) {
      std::cerr << "bus_sub_program: timed out after " << timeout_s << " s; never received:";
      for (const auto& m : missing) std::cerr << " " << m;
      std::cerr << "\n";
      return 1;
    }
    return failures == 0 ? 0 : 1;
  } catch (const BusError& e) {
    std::cerr << "bus_sub_program: " << e.what() << "\n";
    return 1;
  }
}
