// reflex::bus identity of a sample's writer: which Reflex participant wrote it.
//
// A name inside a message (Header.source) is not an identity: any permitted writer can claim it.
// What a reader can tie a sample to is its WRITER: SampleInfo::publication_handle is the writer's
// GUID, whose first 12 bytes are its participant's GUID prefix.
//   - Secure participants (DDS-Security, PKI-DH): the prefix proves the subject of the writer's
//     certificate (see security.hpp). identify() returns the candidate identity name whose subject
//     "CN=reflex.<name>" the prefix derives from — AUTHENTICATED: only a holder of that identity's
//     private key (signed by the Reflex CA) can write under that prefix.
//   - Plain participants: there is no authentication. identify() returns the participant name the
//     writer's participant announced in discovery — a label that guards against mistakes (a replay
//     beside a live vision process), not against an attacker, who can announce any name.
#pragma once

#include <fastdds/dds/subscriber/SampleInfo.hpp>

#include <array>
#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include "reflex/bus/participant.hpp"
#include "reflex/bus/security.hpp"

namespace reflex::bus {

/// The participant GUID prefix of the writer of a sample.
GuidPrefix writerParticipant(const dds::SampleInfo& info) noexcept;

class WriterIdentities {
 public:
  /// `candidates`: identity names to recognise in secure mode (e.g. the configured sources and the
  /// Reflex module names). Throws BusError if a candidate does not make a valid subject name.
  WriterIdentities(const Participant& bus, const std::vector<std::string>& candidates);
  /// The identity of the sample's writer as described above; "" when it is none of the candidates
  /// (secure) or its participant is unknown or announced no name (plain).
  std::string identify(const dds::SampleInfo& info) const;
  /// True when identify() is authenticated (the participant is secure).
  bool authenticated() const noexcept { return secure_; }
  /// "participant 80.1f.…" plus, when it announced one, " announcing the name 'x'" (for log lines).
  std::string describe(const dds::SampleInfo& info) const;

 private:
  const Participant& bus_;
  bool secure_ = false;
  std::vector<std::pair<std::string, std::array<std::uint8_t, 6>>> subjects_;
};

}  // namespace reflex::bus
