// Configuration of a Reflex bus participant: which DDS domain, which QoS profiles file, which
// participant profile, and the module name stamped into every published sample.
//
// Resolution (first match wins), implemented by resolveDomainId / resolveProfilesFile:
//   domain id:     BusConfig::domain_id  >  env REFLEX_DOMAIN_ID  >  0
//   profiles file: BusConfig::profiles_file  >  env FASTRTPS_DEFAULT_PROFILES_FILE  >
//                  reflex::common::defaultProfilesFile() (the shipped dds/reflex_profiles.xml:
//                  installed, PREFIX/share/reflex; in the build tree, the checkout's bringup/dds)
// The profiles file is always loaded explicitly by the Participant constructor (also when it came
// from FASTRTPS_DEFAULT_PROFILES_FILE, which Fast DDS itself would only log errors about), so a
// missing or malformed file is a BusError naming the path.
#pragma once

#include <optional>
#include <string>

namespace reflex::bus {

/// Highest domain id Fast DDS accepts with the default UDP port mapping (RTPS: PB + DG * id < 65536).
inline constexpr int kMaxDomainId = 232;

struct BusConfig {
  /// Name of the process's module: DDS participant name, and Header::source of every published sample.
  std::string module_name = "reflex";
  /// DDS domain id in [0, kMaxDomainId]; empty: env REFLEX_DOMAIN_ID, else 0.
  std::optional<int> domain_id;
  /// QoS profiles XML file; empty: env FASTRTPS_DEFAULT_PROFILES_FILE, else the shipped one.
  std::string profiles_file;
  /// Participant profile in the profiles file ("reflex_participant_udp": UDP only, no shared memory).
  std::string participant_profile = "reflex_participant";
};

/// The domain id to use: `configured` if set, else env REFLEX_DOMAIN_ID, else 0.
/// Throws BusError quoting the value and its origin if it is not an integer in [0, kMaxDomainId].
int resolveDomainId(const std::optional<int>& configured);

/// Parses a domain id given as text (command-line argument or environment); `origin` names where it
/// came from for the error message. Throws BusError if not an integer in [0, kMaxDomainId].
int parseDomainId(const std::string& text, const std::string& origin);

/// The profiles file to load: `configured` if not empty, else env FASTRTPS_DEFAULT_PROFILES_FILE,
/// else reflex::common::defaultProfilesFile(). Does not check that the file exists (the Participant does).
std::string resolveProfilesFile(const std::string& configured);

}  // namespace reflex::bus
