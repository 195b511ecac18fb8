#include "reflex/record/bus_survey.hpp"

#include "reflex/record/codecs.hpp"

#include <reflex/bus/bus.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <map>
#include <memory>
#include <set>
#include <sstream>
#include <tuple>

namespace reflex::record {
namespace {

const char* stateName(msg::ModuleState s) {
  switch (s) {
    case msg::STATE_CONFIGURING: return "CONFIGURING";
    case msg::STATE_RUNNING: return "RUNNING";
    case msg::STATE_STOPPING: return "STOPPING";
    case msg::STATE_ERROR: return "ERROR";
  }
  return "?";
}

}  // namespace

BusSurvey surveyBus(const bus::BusConfig& config, double window_s, const std::vector<std::string>& topics) {
  if (!(window_s > 0.0) || !std::isfinite(window_s))
    throw RecordError("listening window " + std::to_string(window_s) + " s must be positive");
  std::vector<TopicSpec> specs;
  if (topics.empty()) {
    for (const TopicCodec* c : allCodecs()) specs.push_back({c->defaultTopic(), c});
  } else {
    for (const std::string& t : topics) specs.push_back(parseTopicSpec(t));
  }
  BusSurvey survey;
  survey.window_s = window_s;
  bus::Participant bus(config);
  survey.domain = bus.domainId();

  // Heartbeats: the modules' own profile (transient local), so every running module's last beat
  // arrives at once; a module that died is gone with its writer (its liveliness lease, 1.5 s).
  std::map<std::string, ModuleSeen> modules;
  auto& hb = bus.makeReader<msg::Heartbeat>();
  std::set<std::string> writers_heard;               // the heartbeat writers whose beat arrived (GUIDs)
  std::set<bus::GuidPrefix> prefixes_heard;          // and their participants
  std::chrono::steady_clock::time_point last_new{};  // when a module was first heard
  hb.onDataWithInfo([&](const msg::Heartbeat& h, const bus::dds::SampleInfo& info) {
    std::ostringstream guid;
    guid << info.sample_identity.writer_guid();
    writers_heard.insert(guid.str());
    bus::GuidPrefix prefix{};
    const auto& gp = info.sample_identity.writer_guid().guidPrefix.value;
    std::copy(std::begin(gp), std::end(gp), prefix.begin());
    prefixes_heard.insert(prefix);
    if (!modules.count(h.module_name())) last_new = std::chrono::steady_clock::now();
    ModuleSeen& m = modules[h.module_name()];
    m.module_name = h.module_name();
    m.host = h.host();
    m.pid = h.pid();
    m.state = stateName(h.state());
    m.period_ms = h.period_ms();
    m.detail = h.detail();
    m.age_s = static_cast<double>(h.header().stamp_ns());  // stamp for now; made an age below
    ++m.heartbeats;
  });
  // Topics: the recorder's best-effort volatile reader matches every writer and counts only what
  // arrives in the window (no late-joiner history).
  std::vector<std::pair<TopicSeen, bus::detail::ReaderBase*>> seen;
  std::vector<std::pair<std::int64_t, std::int64_t>> first_last(specs.size(), {0, 0});  // steady ns
  seen.reserve(specs.size());
  for (const TopicSpec& s : specs) {
    seen.push_back({TopicSeen{s.topic, s.codec->typeName()}, nullptr});
    TopicSeen* t = &seen.back().first;
    auto* span = &first_last[seen.size() - 1];
    seen.back().second = &s.codec->subscribe(bus, s.topic, bus::kProfileRecord, [t, span](RecordEntry&&) {
      const std::int64_t now =
          std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::steady_clock::now().time_since_epoch())
              .count();
      if (t->samples++ == 0) span->first = now;
      span->second = now;
    });
  }
  // At least kMinDiscovery: a fresh participant usually finds the others in 0.1-1.5 s, from their
  // answers to its own announcements (measured: with three processes running, 0 of them seen in 3 of
  // 6 lists of 0.2-1.0 s). Those answers can be lost or late on a loaded host (a full test run: 1 of 3
  // processes in 2.0 s); every participant also announces itself at least every 3 s (Fast DDS's
  // default announcement period, the shipped profile's), so 3.5 s hears every live one regardless.
  constexpr double kMinDiscovery = 3.5;
  bus.runFor(std::chrono::duration_cast<std::chrono::nanoseconds>(
      std::chrono::duration<double>(std::max(window_s, kMinDiscovery))));
  // Discovery can take about as long as the window: a process found late was left out without a word
  // (2 of 3 listed once in 20 calls). Listening goes on, up to kSettleCap more, while a heartbeat writer
  // is matched whose beat has not arrived, or while a module appeared in the last kSettle.
  constexpr double kSettle = 1.0, kSettleCap = 5.0;
  const auto started = std::chrono::steady_clock::now();
  for (;;) {
    const auto now = std::chrono::steady_clock::now();
    std::size_t silent = 0;  // participants discovered whose heartbeat has not arrived
    for (const auto& prefix : bus.discoveredParticipants()) silent += prefixes_heard.count(prefix) ? 0 : 1;
    const bool unheard = silent > 0 || hb.stats().matched_writers > static_cast<std::int32_t>(writers_heard.size());
    const bool recent = !modules.empty() && std::chrono::duration<double>(now - last_new).count() < kSettle;
    if ((!unheard && !recent) || std::chrono::duration<double>(now - started).count() >= kSettleCap) {
      survey.settled = !unheard;
      survey.silent_participants = static_cast<int>(silent);
      break;
    }
    bus.runFor(std::chrono::milliseconds(100));
  }
  survey.window_s = std::max(window_s, kMinDiscovery) +
                    std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count();

  const double now_ns = static_cast<double>(bus::nowNs());
  std::map<std::pair<std::string, int>, ProcessSeen> processes;
  for (auto& [name, m] : modules) {
    m.age_s = (now_ns - m.age_s) * 1e-9;
    ProcessSeen& p = processes[{m.host, m.pid}];
    p.host = m.host;
    p.pid = m.pid;
    p.modules.push_back(m);
  }
  for (auto& [key, p] : processes) survey.processes.push_back(std::move(p));
  for (std::size_t k = 0; k < seen.size(); ++k) {
    auto& [t, reader] = seen[k];
    const double span_s = 1e-9 * static_cast<double>(first_last[k].second - first_last[k].first);
    t.hz = t.samples >= 2 && span_s > 0.0 ? static_cast<double>(t.samples - 1) / span_s
                                          : static_cast<double>(t.samples) / window_s;
    t.writers = static_cast<int>(reader->stats().matched_writers);
    survey.topics.push_back(t);
  }
  std::sort(survey.topics.begin(), survey.topics.end(),
            [](const TopicSeen& a, const TopicSeen& b) { return a.topic < b.topic; });
  return survey;
}

}  // namespace reflex::record
