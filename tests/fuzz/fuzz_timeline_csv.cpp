// libFuzzer target: the scripted module's timeline CSV (the `file: *.csv` of a behavior
// configuration, e.g. bringup/behavior/scripted_timeline.csv) -> readTimelineCsv (via a temp file).
// Documented error: reflex::modules::ConfigError. Invariant of an accepted timeline
// (modules/include/reflex/modules/scripted.hpp): events in time order, times >= 0, targets finite.
#include "fuzz_util.hpp"

#include "reflex/modules/scripted.hpp"

#include <cmath>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace reflex::modules;
  const std::string& path = reflex::fuzz::writeTemp(data, size, ".timeline.csv");
  reflex::fuzz::expectOnly<ConfigError>("readTimelineCsv", [&] {
    const std::vector<TimelineEvent> events = readTimelineCsv(path);
    double last = 0.0;
    for (const TimelineEvent& e : events) {
      const bool ok = std::isfinite(e.t) && e.t >= last && (!e.target.given || e.target.p_B.allFinite());
      if (!ok) {
        std::fprintf(stderr, "FUZZ FINDING: readTimelineCsv accepted an event at t = %g out of order or not finite\n",
                     e.t);
        std::abort();
      }
      last = e.t;
    }
  });
  return 0;
}
