// reflex::bus security checks — the DDS-Security material of a participant, checked by Reflex
// before Fast DDS sees it, and the participant's identity as peers see it.
//
// Fast DDS 2.9 refuses bad material with one line, "could not create the DDS participant". Before a
// secure participant is created, checkSecurityMaterial() reads every file the participant QoS names
// (properties dds.sec.auth.builtin.PKI-DH.* and dds.sec.access.builtin.Access-Permissions.*) and
// throws BusError naming the property, the file and the cause:
//   - a file missing, not a regular file, or unreadable; a "file://" URI missing;
//   - a certificate or key that does not parse; the identity certificate not signed by the identity
//     CA, not yet valid or expired; the private key not the certificate's;
//   - governance or permissions whose S/MIME signature does not verify against the permissions CA
//     (edited after signing, signed by another CA, not S/MIME);
//   - permissions without a grant for the certificate's subject, or whose grant is expired or not
//     yet valid (<validity> not_before / not_after, UTC).
// It returns when the material stops being valid (the earliest notAfter of the identity and CA
// certificates and the grant's not_after): Fast DDS checks validity only when peers authenticate,
// so bus::Participant stops the process itself at that instant (see Participant).
//
// What a writer's participant GUID proves (used to tie inputs to their writer, not to a name in the
// message): under PKI-DH, the first 48 bits of a participant's GUID prefix are 1 followed by the
// first 47 bits of SHA-256 of its certificate's DER subject name; each peer checks this during the
// handshake against the certificate it verified (Fast DDS PKIDH begin_handshake_reply /
// process_handshake_reply), and every RTPS message of the participant is signed with the keys of that
// handshake (governance rtps_protection_kind SIGN). So a sample's writer GUID prefix authenticates
// the subject of the writer's certificate; nothing else in the sample does.
#pragma once

#include <array>
#include <chrono>
#include <cstdint>
#include <string>
#include <vector>

namespace reflex::bus {

/// The files of one participant's DDS-Security configuration (paths without "file://").
struct SecurityMaterial {
  bool enabled = false;              ///< the QoS names an authentication plugin
  bool access_control = false;       ///< the QoS names an access-control plugin (governance, permissions)
  std::string identity_ca;           ///< dds.sec.auth.builtin.PKI-DH.identity_ca
  std::string identity_certificate;  ///< dds.sec.auth.builtin.PKI-DH.identity_certificate
  std::string private_key;           ///< dds.sec.auth.builtin.PKI-DH.private_key
  std::string permissions_ca;        ///< dds.sec.access.builtin.Access-Permissions.permissions_ca
  std::string governance;            ///< dds.sec.access.builtin.Access-Permissions.governance
  std::string permissions;           ///< dds.sec.access.builtin.Access-Permissions.permissions
};

/// What checkSecurityMaterial found valid, and until when.
struct SecurityCheck {
  std::string subject;                                ///< identity certificate subject, RFC 2253 ("CN=reflex.vision")
  std::chrono::system_clock::time_point valid_until;  ///< earliest end of validity of the material
  std::string valid_until_what;                       ///< what ends then ("identity certificate '...'")
};

/// Reads the security properties of a participant QoS property list (name, value pairs).
/// Throws BusError naming the property if a value is not a "file://" URI (the only form Reflex uses).
SecurityMaterial securityMaterialOf(const std::vector<std::pair<std::string, std::string>>& properties);

/// Checks the material as described above at time `now`; throws BusError naming file and cause.
SecurityCheck checkSecurityMaterial(const SecurityMaterial& material, std::chrono::system_clock::time_point now);

/// "2026-12-01 19:50:00 UTC"
std::string formatUtc(std::chrono::system_clock::time_point t);

/// A participant GUID prefix (12 bytes).
using GuidPrefix = std::array<std::uint8_t, 12>;
std::string toString(const GuidPrefix& prefix);

/// The subject name make_security.sh gives Reflex identity `name`: "CN=reflex.<name>".
std::string identitySubject(const std::string& name);

/// The 6 leading bytes of every PKI-DH participant GUID prefix whose certificate has the subject
/// `subject` (RFC 2253 text such as "CN=reflex.vision", attributes encoded as UTF8String — what
/// `openssl req -subj` makes): a 1 bit, then the first 47 bits of SHA-256 of the DER subject name.
/// Throws BusError if `subject` does not parse.
std::array<std::uint8_t, 6> subjectGuidBits(const std::string& subject);
/// True when the first 6 bytes of `prefix` equal `bits` (the participant holds that subject's certificate).
bool prefixMatchesSubjectBits(const GuidPrefix& prefix, const std::array<std::uint8_t, 6>& bits);

}  // namespace reflex::bus
