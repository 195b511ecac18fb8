#include "reflex/bus/identity.hpp"

namespace reflex::bus {

GuidPrefix writerParticipant(const dds::SampleInfo& info) noexcept {
  GuidPrefix prefix{};
  for (std::size_t i = 0; i < prefix.size(); ++i) prefix[i] = info.publication_handle.value[i];
  return prefix;
}

WriterIdentities::WriterIdentities(const Participant& bus, const std::vector<std::string>& candidates)
    : bus_(bus), secure_(bus.secure()) {
  for (const auto& name : candidates) {
    if (name.empty()) throw BusError("empty identity name among the writer identities to recognise");
    subjects_.emplace_back(name, subjectGuidBits(identitySubject(name)));
  }
}

std::string WriterIdentities::identify(const dds::SampleInfo& info) const {
  const GuidPrefix prefix = writerParticipant(info);
  if (!secure_) return bus_.discoveredName(prefix);
  for (const auto& [name, bits] : subjects_) {
    if (prefixMatchesSubjectBits(prefix, bits)) return name;
  }
  return "";
}

std::string WriterIdentities::describe(const dds::SampleInfo& info) const {
  const GuidPrefix prefix = writerParticipant(info);
  const std::string name = bus_.discoveredName(prefix);
  return "participant " + toString(prefix) + (name.empty() ? "" : " announcing the name '" + name + "'");
}

}  // namespace reflex::bus
