// DDS-Security hardening, checked against independent answers:
//   - make_security.sh refuses a private key others can read (mode from stat, not from the script);
//   - tampered, foreign, missing, expired or mismatched material stops a participant with an error
//     naming the file and the cause (each case made here with OpenSSL / openssl smime, the good
//     material first shown to work);
//   - a participant whose certificate expires during the session stops itself at that instant
//     (the certificate is made here with a 6 s lifetime; Fast DDS alone keeps it working);
//   - discovery tells an unauthenticated participant no host name, user or process id, and no
//     participant name of a secure participant (read with a raw Fast DDS listener, as an outsider);
//   - the writer of a sample is identified by its participant GUID, which PKI-DH binds to the
//     certificate subject: the hash is recomputed here and compared with the GUID Fast DDS gave
//     each secure participant, and a player writing Header.source "vision" is still "player";
//   - reflex_behavior (secure) takes object targets only from the configured identities: vision
//     by default, the player only when named (the replay set-up), counted in its exit stats.
//   - a flood of bad samples (thousands of invalid body-schema segments) gives the real controller a
//     bounded stderr: at most LogLimiter's lines per second, the rest counted as suppressed.
// Credentials: bringup/security/make_security.sh into temporary folders. Domains 120..126.
#include "security_support.hpp"

#include "../bad_input/controller_run.hpp"
#include "support/child_process.hpp"

#include <fastdds/dds/domain/DomainParticipant.hpp>
#include <fastdds/dds/domain/DomainParticipantListener.hpp>
#include <fastdds/dds/domain/qos/DomainParticipantQos.hpp>
#include <fastrtps/rtps/participant/ParticipantDiscoveryInfo.h>

#include <openssl/pem.h>
#include <openssl/x509.h>

#include <sys/stat.h>
#include <unistd.h>

#include <atomic>
#include <csignal>
#include <cstdio>
#include <map>
#include <mutex>
#include <regex>
#include <set>
#include <thread>

namespace reflex::security_test {
namespace {

using namespace std::chrono_literals;

int runShell(const std::string& cmd) {
  const int rc = std::system(cmd.c_str());
  return WIFEXITED(rc) ? WEXITSTATUS(rc) : -1;
}

std::string fileMode(const std::string& path) {
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0) return "missing";
  char buf[8];
  std::snprintf(buf, sizeof(buf), "%03o", st.st_mode & 0777);
  return buf;
}

/// One folder of material per test program: Fast DDS keeps the first participant profile of a name
/// for the whole process, so every test that makes participants uses this folder (and restores
/// what it changes).
const std::string& material() {
  static const std::string dir = [] {
    const std::string d = makeSecurityMaterial("hardening");
    loadProfiles(d);
    return d;
  }();
  return dir;
}

/// Restores a file's contents when it goes out of scope.
class Restore {
 public:
  explicit Restore(std::string path) : path_(std::move(path)), text_(readFile(path_)) {}
  ~Restore() {
    ::rmdir(path_.c_str());  // a case may have replaced the file with a folder
    writeFile(path_, text_);
  }
  Restore(const Restore&) = delete;
  Restore& operator=(const Restore&) = delete;

 private:
  std::string path_, text_;
};

/// The message of the BusError a secure participant of `identity` throws, or "" if it was created.
std::string participantError(const std::string& dir, const std::string& identity, int domain) {
  try {
    auto p = secureParticipant(dir, identity, domain);
    return "";
  } catch (const bus::BusError& e) {
    return e.what();
  }
}

/// Replaces `identity`'s certificate with one for the same key and subject, signed by the Reflex CA,
/// valid from now + from_s to now + to_s (OpenSSL C API: seconds, which `openssl x509 -days` cannot).
void makeCertificate(const std::string& dir, const std::string& identity, long from_s, long to_s) {
  auto readKey = [](const std::string& path) {
    FILE* f = std::fopen(path.c_str(), "r");
    if (f == nullptr) throw std::runtime_error("cannot open " + path);
    EVP_PKEY* k = PEM_read_PrivateKey(f, nullptr, nullptr, nullptr);
    std::fclose(f);
    if (k == nullptr) throw std::runtime_error("cannot read key " + path);
    return k;
  };
  EVP_PKEY* key = readKey(dir + "/" + identity + "/key.pem");
  EVP_PKEY* ca_key = readKey(dir + "/ca/ca.key.pem");
  FILE* f = std::fopen((dir + "/ca/ca.cert.pem").c_str(), "r");
  X509* ca = PEM_read_X509(f, nullptr, nullptr, nullptr);
  std::fclose(f);
  X509* x = X509_new();
  X509_set_version(x, 2);
  ASN1_INTEGER_set(X509_get_serialNumber(x), static_cast<long>(std::time(nullptr) & 0x7fffffff));
  X509_gmtime_adj(X509_getm_notBefore(x), from_s);
  X509_gmtime_adj(X509_getm_notAfter(x), to_s);
  X509_set_pubkey(x, key);
  const std::string cn = "reflex." + identity;
  X509_NAME_add_entry_by_txt(X509_get_subject_name(x), "CN", MBSTRING_UTF8,
                             reinterpret_cast<const unsigned char*>(cn.c_str()), -1, -1, 0);
  X509_set_issuer_name(x, X509_get_subject_name(ca));
  ASSERT_GT(X509_sign(x, ca_key, EVP_sha256()), 0);
  f = std::fopen((dir + "/" + identity + "/cert.pem").c_str(), "w");
  ASSERT_NE(f, nullptr);
  PEM_write_X509(f, x);
  std::fclose(f);
  X509_free(x);
  X509_free(ca);
  EVP_PKEY_free(key);
  EVP_PKEY_free(ca_key);
}

// ---- e. make_security.sh and loose keys -------------------------------------------------------

TEST(SecurityHardening, MakeSecurityRefusesAPrivateKeyOthersCanRead) {
  const std::string dir = makeSecurityMaterial("loose");
  const std::string key = dir + "/behavior/key.pem", ca_key = dir + "/ca/ca.key.pem";
  ASSERT_EQ(fileMode(key), "600");
  const std::string before = readFile(key);
  for (const auto& [path, mode] : std::vector<std::pair<std::string, std::string>>{{key, "644"}, {ca_key, "640"}}) {
    ASSERT_EQ(runShell("chmod " + mode + " '" + path + "'"), 0);
    const std::string log = dir + "_loose.log";
    const int rc = runShell(kScript + " '" + dir + "' > '" + log + "' 2>&1");
    const std::string out = readFile(log);
    EXPECT_NE(rc, 0) << out;
    EXPECT_NE(out.find("'" + path + "' (mode 0" + mode + ")"), std::string::npos) << out;
    EXPECT_EQ(fileMode(path), mode) << "the key is left for the operator to judge, not silently chmod-ed";
    ASSERT_EQ(runShell("chmod 600 '" + path + "'"), 0);
  }
  EXPECT_EQ(readFile(key), before);
  // Restricted again by the operator: accepted, the key kept.
  EXPECT_EQ(runShell(kScript + " '" + dir + "' > /dev/null 2>&1"), 0);
  EXPECT_EQ(readFile(key), before);
  // --force makes new material whatever the old modes were.
  ASSERT_EQ(runShell("chmod 644 '" + key + "'"), 0);
  EXPECT_EQ(runShell(kScript + " --force '" + dir + "' > /dev/null 2>&1"), 0);
  EXPECT_EQ(fileMode(key), "600");
  EXPECT_NE(readFile(key), before);
}

// ---- d. bad material named with its cause ------------------------------------------------------

TEST(SecurityHardening, BadMaterialStopsTheParticipantNamingTheFileAndTheCause) {
  const std::string& dir = material();
  constexpr int kDomain = 217;  // its own (120 is record_mcap_process_test's)
  ASSERT_EQ(participantError(dir, "vision", kDomain), "") << "positive control: the material as made works";

  const std::string gov = dir + "/governance.p7s", perm = dir + "/vision/permissions.p7s";
  const std::string cert = dir + "/vision/cert.pem", key = dir + "/vision/key.pem";
  struct Case {
    std::string what;
    std::string file;  // the file to change (restored afterwards)
    std::function<void()> change;
    std::vector<std::string> expected;  // substrings of the error
  };
  const std::string perm_xml = readFile(dir + "/vision/permissions.xml");
  auto signWithCa = [&](const std::string& xml_text, const std::string& out) {
    writeFile(dir + "/tmp_perm.xml", xml_text);
    ASSERT_EQ(runShell("openssl smime -sign -text -in '" + dir + "/tmp_perm.xml' -out '" + out + "' -signer '" + dir +
                       "/ca/ca.cert.pem' -inkey '" + dir + "/ca/ca.key.pem'"),
              0);
  };
  auto replaceAll = [](std::string s, const std::string& from, const std::string& to) {
    for (auto p = s.find(from); p != std::string::npos; p = s.find(from, p + to.size())) s.replace(p, from.size(), to);
    return s;
  };
  const std::vector<Case> cases = {
      {"governance edited after signing",
       gov,
       [&] { writeFile(gov, replaceAll(readFile(gov), "<rtps_protection_kind>SIGN", "<rtps_protection_kind>NONE")); },
       {"governance file '" + gov + "'", "bad signature"}},
      {"permissions edited after signing (a topic granted)",
       perm,
       [&] {
         writeFile(perm,
                   replaceAll(readFile(perm), "<topic>reflex/heartbeat</topic>", "<topic>reflex/hand_targets</topic>"));
       },
       {"permissions file '" + perm + "'", "bad signature"}},
      {"permissions signed by another CA",
       perm,
       [&] { writeFile(perm, readFile(dir + "/intruder/permissions.p7s")); },
       {"permissions file '" + perm + "'", "bad signature"}},
      {"governance missing", gov, [&] { std::remove(gov.c_str()); }, {"governance file '" + gov + "'", "missing"}},
      {"governance not S/MIME",
       gov,
       [&] { writeFile(gov, "<dds/>\n"); },
       {"governance file '" + gov + "'", "not an S/MIME signed document"}},
      {"permissions expired (signed by the CA)",
       perm,
       [&] {
         std::string x = std::regex_replace(perm_xml, std::regex("<not_before>[^<]*</not_before>"),
                                            "<not_before>2020-01-01T00:00:00</not_before>");
         x = std::regex_replace(x, std::regex("<not_after>[^<]*</not_after>"),
                                "<not_after>2021-01-01T00:00:00</not_after>");
         signWithCa(x, perm);
       },
       {"permissions file '" + perm + "'", "grant of 'CN=reflex.vision' expired at 2021-01-01 00:00:00 UTC"}},
      {"permissions of another identity (behavior's)",
       perm,
       [&] { writeFile(perm, readFile(dir + "/behavior/permissions.p7s")); },
       {"permissions file '" + perm + "'", "no grant for the identity certificate's subject 'CN=reflex.vision'",
        "CN=reflex.behavior"}},
      {"certificate expired an hour ago",
       cert,
       [&] { makeCertificate(dir, "vision", -7200, -3600); },
       {"identity_certificate file '" + cert + "'", "certificate 'CN=reflex.vision' expired at"}},
      {"certificate not valid yet",
       cert,
       [&] { makeCertificate(dir, "vision", 3600, 7200); },
       {"identity_certificate file '" + cert + "'", "is not valid before"}},
      {"certificate of another CA",
       cert,
       [&] { writeFile(cert, readFile(dir + "/intruder/cert.pem")); },
       {"identity_certificate file '" + cert + "'", "does not verify against the identity CA"}},
      {"private key of another identity",
       key,
       [&] { writeFile(key, readFile(dir + "/behavior/key.pem")); },
       {"private_key file '" + key + "'", "not the private key of the identity certificate"}},
      {"certificate replaced by a folder",
       cert,
       [&] {
         std::remove(cert.c_str());
         ::mkdir(cert.c_str(), 0700);
       },
       {"identity_certificate file '" + cert + "'", "not a regular file"}},
      {"private key empty", key, [&] { writeFile(key, ""); }, {"private_key file '" + key + "'", "empty"}},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.what);
    const Restore restore(c.file);
    c.change();
    const std::string error = participantError(dir, "vision", kDomain);
    EXPECT_NE(error, "") << "the participant was created";
    for (const auto& e : c.expected)
      EXPECT_NE(error.find(e), std::string::npos) << "expected '" << e << "' in: " << error;
  }
  // A private key others can read: refused at run time too, as make_security.sh refuses it.
  for (const char* mode : {"644", "640", "604"}) {
    SCOPED_TRACE(mode);
    ASSERT_EQ(runShell(std::string("chmod ") + mode + " '" + key + "'"), 0);
    const std::string error = participantError(dir, "vision", kDomain);
    EXPECT_NE(error.find("private_key file '" + key + "': readable by group or others (mode 0" + mode + ")"),
              std::string::npos)
        << error;
    ASSERT_EQ(runShell("chmod 600 '" + key + "'"), 0);
  }
  // Everything restored: the positive control again.
  EXPECT_EQ(participantError(dir, "vision", kDomain), "");
}

// ---- b. a certificate that expires during the session -------------------------------------------

TEST(SecurityHardening, AParticipantStopsItselfWhenItsCertificateExpires) {
  const std::string& dir = material();
  constexpr int kDomain = 218;  // its own (121 is record_mcap_process_test's)
  const Restore restore(dir + "/vision/cert.pem");
  makeCertificate(dir, "vision", -60, 6);  // expires 6 s from now
  auto vision = secureParticipant(dir, "vision", kDomain);
  const auto until = vision->credentialsValidUntil();
  const double left = std::chrono::duration<double>(until - std::chrono::system_clock::now()).count();
  EXPECT_GT(left, 3.0);
  EXPECT_LT(left, 7.0);
  EXPECT_FALSE(vision->credentialsExpired());
  // A behavior peer that authenticated before the expiry (what Fast DDS alone keeps working).
  auto behavior = secureParticipant(dir, "behavior", kDomain);
  auto& reader = behavior->makeReader<msg::ObjectTargets>();
  auto& writer = vision->makeWriter<msg::ObjectTargets>();
  EXPECT_TRUE(writer.waitForReaders(1, 20s)) << "authenticated before the expiry";

  const auto t0 = std::chrono::steady_clock::now();
  std::string error;
  try {
    vision->runFor(30s);
  } catch (const bus::BusError& e) {
    error = e.what();
  }
  const double stopped_after = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  ASSERT_NE(error, "") << "runFor ran its 30 s: the expired participant kept working";
  EXPECT_TRUE(vision->credentialsExpired());
  EXPECT_NE(error.find("identity certificate '" + dir + "/vision/cert.pem'"), std::string::npos) << error;
  EXPECT_NE(error.find("expired at " + bus::formatUtc(until)), std::string::npos) << error;
  const double late = std::chrono::duration<double>(std::chrono::system_clock::now() - until).count();
  EXPECT_GE(late, 0.0);
  EXPECT_LT(late, 1.0) << "stopped " << late << " s after the expiry (runFor returned after " << stopped_after << " s)";
  // Later calls stop at once and say so again.
  EXPECT_THROW(vision->runFor(5s), bus::BusError);
  (void)reader;
}

// The real controller process with a controller certificate that expires 8 s after it is made:
// it runs, then stops itself at the expiry (not at its 40 s --duration), says why and exits 1.
TEST(SecurityHardening, TheControllerStopsLoudlyWhenItsCertificateExpires) {
  const std::string& dir = material();
  const Restore restore(dir + "/controller/cert.pem");
  makeCertificate(dir, "controller", -60, 8);
  const std::string log = ::testing::TempDir() + "hardening_controller_expiry.log";
  const auto t0 = std::chrono::steady_clock::now();
  testing::ChildProcess controller({std::string(REFLEX_BIN_DIR) + "/reflex_controller", "--profiles",
                                    dir + "/profiles/controller.xml", "--domain", "126", "--duration", "40"},
                                   log);
  ASSERT_TRUE(controller.started());
  const int rc = controller.wait(30s);
  const double ran = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  const std::string out = readFile(log);
  EXPECT_EQ(rc, 1) << out;
  EXPECT_GT(ran, 4.0) << out;
  EXPECT_LT(ran, 12.0) << "stopped at the expiry, not at --duration\n" << out;
  EXPECT_NE(out.find("identity certificate '" + dir + "/controller/cert.pem' of participant 'controller' expired at"),
            std::string::npos)
      << out;
  EXPECT_NE(out.find(" cycles, lateness"), std::string::npos) << "the exit summary is still printed\n" << out;
  std::printf("controller stopped %.1f s after start (certificate lifetime 8 s), exit %d\n", ran, rc);
}

// ---- c. what discovery tells an outsider --------------------------------------------------------

// A raw Fast DDS listener (as an outsider would write it): every participant it discovers.
class Outsider final : public eprosima::fastdds::dds::DomainParticipantListener {
 public:
  struct Seen {
    std::string name;
    std::map<std::string, std::string> properties;
    std::map<std::string, std::string> identity_token;
  };
  void on_participant_discovery(eprosima::fastdds::dds::DomainParticipant*,
                                eprosima::fastrtps::rtps::ParticipantDiscoveryInfo&& info) override {
    if (info.status != eprosima::fastrtps::rtps::ParticipantDiscoveryInfo::DISCOVERED_PARTICIPANT) return;
    Seen s;
    s.name = info.info.m_participantName.to_string();
    for (const auto& p : info.info.m_properties) s.properties[p.first()] = p.second();
    for (const auto& p : info.info.identity_token_.properties()) s.identity_token[p.name()] = p.value();
    std::ostringstream guid;
    guid << info.info.m_guid.guidPrefix;
    const std::lock_guard<std::mutex> lock(mutex_);
    seen_[guid.str()] = s;
  }
  std::map<std::string, Seen> seen() const {
    const std::lock_guard<std::mutex> lock(mutex_);
    return seen_;
  }

 private:
  mutable std::mutex mutex_;
  std::map<std::string, Seen> seen_;
};

TEST(SecurityHardening, DiscoveryTellsAnOutsiderNoHostUserProcessOrSecureName) {
  const std::string& dir = material();
  constexpr int kDomain = 122;
  Outsider outsider;
  auto* factory = eprosima::fastdds::dds::DomainParticipantFactory::get_instance();
  eprosima::fastdds::dds::DomainParticipantQos qos;
  factory->get_participant_qos_from_profile("reflex_participant", qos);
  qos.name("outsider");
  auto* raw = factory->create_participant(kDomain, qos, &outsider, eprosima::fastdds::dds::StatusMask::none());
  ASSERT_NE(raw, nullptr);
  {
    auto vision = secureParticipant(dir, "vision", kDomain);
    auto plain = plainParticipant("plain_module", kDomain);
    const auto end = std::chrono::steady_clock::now() + 20s;
    while (outsider.seen().size() < 2 && std::chrono::steady_clock::now() < end) std::this_thread::sleep_for(50ms);
    const auto seen = outsider.seen();
    ASSERT_GE(seen.size(), 2u);
    int secure = 0, named_plain = 0;
    for (const auto& [guid, s] : seen) {
      std::string props;
      for (const auto& [k, v] : s.properties) props += k + "=" + v + "; ";
      for (const auto& [k, v] : s.properties) {
        EXPECT_EQ(k.find("fastdds.physical_data"), std::string::npos) << guid << " announces " << k << "=" << v;
      }
      if (!s.identity_token.empty()) {
        ++secure;
        EXPECT_EQ(s.name, "") << "a secure participant announces no name";
        // Still visible (README): the identity token Fast DDS needs for authentication.
        EXPECT_EQ(s.identity_token.count("dds.cert.sn"), 1u);
      } else if (s.name == "plain_module") {
        ++named_plain;  // positive control: the outsider does read names
      }
    }
    EXPECT_EQ(secure, 1);
    EXPECT_EQ(named_plain, 1);
  }
  factory->delete_participant(raw);
}

// ---- a. the writer of a sample -----------------------------------------------------------------

TEST(SecurityHardening, TheWriterGuidAuthenticatesTheCertificateSubjectNotTheHeader) {
  const std::string& dir = material();
  constexpr int kDomain = 123;
  auto vision = secureParticipant(dir, "vision", kDomain);
  auto player = secureParticipant(dir, "player", kDomain);
  auto behavior = secureParticipant(dir, "behavior", kDomain);
  EXPECT_TRUE(behavior->secure());
  EXPECT_EQ(behavior->identitySubject(), "CN=reflex.behavior");
  // The GUID prefix Fast DDS gave each secure participant starts with the bits of its subject.
  auto prefixOf = [](bus::Participant& p) {
    bus::GuidPrefix g{};
    const auto guid = p.native().guid();
    std::copy(std::begin(guid.guidPrefix.value), std::end(guid.guidPrefix.value), g.begin());
    return g;
  };
  const auto vision_bits = bus::subjectGuidBits("CN=reflex.vision"),
             player_bits = bus::subjectGuidBits("CN=reflex.player");
  EXPECT_TRUE(bus::prefixMatchesSubjectBits(prefixOf(*vision), vision_bits)) << bus::toString(prefixOf(*vision));
  EXPECT_FALSE(bus::prefixMatchesSubjectBits(prefixOf(*vision), player_bits));
  EXPECT_TRUE(bus::prefixMatchesSubjectBits(prefixOf(*player), player_bits)) << bus::toString(prefixOf(*player));
  EXPECT_FALSE(bus::prefixMatchesSubjectBits(prefixOf(*player), vision_bits));

  bus::WriterIdentities ids(*behavior, {"vision", "player", "controller"});
  EXPECT_TRUE(ids.authenticated());
  // A deep reader (keep last 256): both writers' frames are kept until taken.
  auto& reader = behavior->makeReader<msg::ObjectTargets>("reflex/object_targets", bus::kProfileRecord);
  auto& from_vision = vision->makeWriter<msg::ObjectTargets>();
  auto& from_player = player->makeWriter<msg::ObjectTargets>();
  // Three secure participants authenticate each other: seconds when idle, but a handshake took more
  // than 30 s in a full parallel test run (as in BehaviorTakesObjectsOnlyFromTheConfiguredIdentities).
  const bool reader_matched = reader.waitForWriters(2, 60s);
  const bool vision_matched = from_vision.waitForReaders(1, 60s);
  const bool player_matched = from_player.waitForReaders(1, 60s);
  ASSERT_TRUE(reader_matched && vision_matched && player_matched)
      << "not matched: the behavior's reader to both writers " << reader_matched << ", vision's writer "
      << vision_matched << ", player's writer " << player_matched;
  std::this_thread::sleep_for(500ms);
  msg::ObjectTargets o;
  o.frame_id("base_link");
  std::map<std::uint64_t, std::string> who;
  const auto end = std::chrono::steady_clock::now() + 10s;
  while (who.size() < 2 && std::chrono::steady_clock::now() < end) {
    o.image_index(1);
    from_vision.publish(o);
    o.image_index(2);
    o.header().source("vision");  // the player claims to be vision in the message
    from_player.write(o);
    msg::ObjectTargets in;
    bus::dds::SampleInfo info;
    reader.waitForData(100ms);
    while (reader.takeNext(in, &info)) {
      EXPECT_EQ(in.header().source(), "vision");
      const std::string id = ids.identify(info);
      if (who.count(in.image_index()) != 0) {
        EXPECT_EQ(who[in.image_index()], id);
      }
      who[in.image_index()] = id;
    }
  }
  ASSERT_EQ(who.size(), 2u);
  EXPECT_EQ(who[1], "vision");
  EXPECT_EQ(who[2], "player") << "the player is identified by its certificate, whatever Header.source says";
}

// reflex_behavior (pointing, secure) with a vision identity writing "cup" frames and a player
// identity writing "can" frames whose Header.source says "vision": by default only vision's frames
// are taken; with --object-source player only the player's. Counted in the exit stats.
TEST(SecurityHardening, BehaviorTakesObjectsOnlyFromTheConfiguredIdentities) {
  const std::string& dir = material();
  constexpr int kDomain = 124;
  const std::string bin = REFLEX_BIN_DIR, src = REFLEX_SOURCE_DIR;
  struct Stats {
    long accepted = -1, rejected_source = -1, frames = -1;
  };
  auto runBehavior = [&](const std::vector<std::string>& extra, const std::string& tag, long& vision_sent,
                         long& player_sent) {
    std::vector<std::string> argv = {bin + "/reflex_behavior",
                                     "--config",
                                     src + "/bringup/behavior/pointing.yaml",
                                     "--profiles",
                                     dir + "/profiles/behavior.xml",
                                     "--domain",
                                     std::to_string(kDomain),
                                     "--duration",
                                     "150",
                                     "--progress",
                                     "0"};
    argv.insert(argv.end(), extra.begin(), extra.end());
    const std::string log = ::testing::TempDir() + "hardening_behavior_" + tag + ".log";
    std::string output;
    {
      testing::ChildProcess behavior(argv, log);
      EXPECT_TRUE(behavior.started());
      auto vision = secureParticipant(dir, "vision", kDomain);
      auto player = secureParticipant(dir, "player", kDomain);
      auto& wv = vision->makeWriter<msg::ObjectTargets>();
      auto& wp = player->makeWriter<msg::ObjectTargets>();
      // Authentication handshakes of two new participants with the behavior's: seconds when idle, but
      // one took more than 25 s at the start of a full parallel test run (the behavior then ran on).
      const bool vision_matched = wv.waitForReaders(1, 50s);
      const bool player_matched = wp.waitForReaders(1, 50s);
      EXPECT_TRUE(vision_matched && player_matched)
          << "behavior did not match: vision " << vision_matched << ", player " << player_matched;
      std::this_thread::sleep_for(500ms);
      auto frame = [](const char* name, int tag, double y) {
        msg::ObjectTargets o;
        o.frame_id("base_link");
        msg::ObjectTarget t;
        t.name(name);
        t.tag_id(tag);
        t.position_base().x(0.42);
        t.position_base().y(y);
        t.position_base().z(0.95);
        t.confidence(0.9);
        o.objects().push_back(t);
        return o;
      };
      msg::ObjectTargets cup = frame("cup", 3, -0.15), can = frame("can", 4, 0.15);
      // The two writers take turns 25 ms apart: behavior's reader keeps only the newest frame
      // (keep last 1), so frames written at the same instant would replace each other.
      repeatFor(2500ms, 25ms, [&] {
        cup.capture_stamp_ns(bus::nowNs());
        wv.publish(cup);
        std::this_thread::sleep_for(25ms);
        can.header().source("vision");
        can.header().stamp_ns(bus::nowNs());
        can.header().seq(static_cast<std::uint64_t>(player_sent + 1));
        can.capture_stamp_ns(bus::nowNs());
        wp.write(can);
        ++vision_sent;
        ++player_sent;
      });
      std::this_thread::sleep_for(300ms);  // best-effort topic: the last frames arrive or are lost
      behavior.signal(SIGINT);
      EXPECT_EQ(behavior.wait(20s), 0);
    }
    output = readFile(log);
    Stats s;
    std::smatch m;
    if (std::regex_search(output, m, std::regex(R"(frames=(\d+) objects_accepted=(\d+) rejected_source=(\d+))"))) {
      s.frames = std::stol(m[1]);
      s.accepted = std::stol(m[2]);
      s.rejected_source = std::stol(m[3]);
    }
    return std::make_pair(s, output);
  };

  long vision_sent = 0, player_sent = 0;
  auto [def, out_def] = runBehavior({}, "default", vision_sent, player_sent);
  ASSERT_GE(def.frames, 0) << out_def;
  EXPECT_GT(vision_sent, 20);
  // Only vision's frames are taken (one object each); every player frame is refused. The topic is
  // best effort (keep-last 1), so a few frames of either may be lost, never mixed up.
  EXPECT_EQ(def.frames, def.accepted + def.rejected_source) << out_def;
  EXPECT_GT(def.accepted, vision_sent / 2) << out_def;
  EXPECT_LE(def.accepted, vision_sent) << out_def;
  EXPECT_GT(def.rejected_source, player_sent / 2) << out_def;
  EXPECT_LE(def.rejected_source, player_sent) << out_def;
  EXPECT_NE(out_def.find("written by 'player', not one of inputs.object_sources ('vision')"), std::string::npos)
      << out_def;
  EXPECT_NE(out_def.find("authenticated by DDS-Security"), std::string::npos) << out_def;
  std::printf("default: %ld vision + %ld player frames sent; behavior: frames=%ld accepted=%ld rejected_source=%ld\n",
              vision_sent, player_sent, def.frames, def.accepted, def.rejected_source);

  vision_sent = player_sent = 0;
  auto [rep, out_rep] = runBehavior({"--object-source", "player"}, "replay", vision_sent, player_sent);
  ASSERT_GE(rep.frames, 0) << out_rep;
  std::printf(
      "--object-source player: %ld vision + %ld player frames sent; behavior: frames=%ld accepted=%ld "
      "rejected_source=%ld\n",
      vision_sent, player_sent, rep.frames, rep.accepted, rep.rejected_source);
  EXPECT_EQ(rep.frames, rep.accepted + rep.rejected_source) << out_rep;
  EXPECT_GT(rep.accepted, player_sent / 2) << out_rep;
  EXPECT_LE(rep.accepted, player_sent) << out_rep;
  EXPECT_GT(rep.rejected_source, vision_sent / 2) << out_rep;
  EXPECT_LE(rep.rejected_source, vision_sent) << out_rep;
  EXPECT_NE(out_rep.find("written by 'vision', not one of inputs.object_sources ('player')"), std::string::npos)
      << out_rep;
}

// ---- f. a flood of bad samples -----------------------------------------------------------------

TEST(SecurityHardening, AFloodOfBadSamplesGivesTheControllerABoundedStderr) {
  constexpr double kSeconds = 6.0;
  bad_input::ControllerRun run(125, kSeconds, "flood");
  ASSERT_TRUE(run.started());
  auto& schema = run.source->makeWriter<msg::BodySchemaChange>();
  ASSERT_TRUE(run.waitMatched(schema));
  msg::BodySchemaChange c;
  c.operation(msg::SCHEMA_ATTACH);
  c.parent_link("l_hand");
  c.shape(msg::SHAPE_CAPSULE);
  c.point_b().z(-0.1);
  c.radius(-1.0);  // invalid: rejected, counted, one log line each before the fix
  c.enabled(true);
  int sent = 0;
  const auto end = std::chrono::steady_clock::now() + 3s;
  while (std::chrono::steady_clock::now() < end) {
    for (int k = 0; k < 50; ++k) {
      // At most 60 names: the reflex_behavior profile keeps 64 instances (keep last 1 each), so the
      // controller takes up to 60 bad segments per 5 ms cycle.
      c.segment_name("flood_" + std::to_string(sent++ % 60));
      schema.publish(c);
    }
    std::this_thread::sleep_for(5ms);
    run.drain();
  }
  bad_input::ExitSummary summary;
  EXPECT_EQ(run.finish(summary), 0) << run.output;
  ASSERT_TRUE(summary.found) << run.output;
  EXPECT_GT(summary.rejected, 1000) << "the flood reached the controller (" << sent << " sent)";
  long lines = 0;
  for (auto p = run.output.find("body-schema segment 'flood_"); p != std::string::npos;
       p = run.output.find("body-schema segment 'flood_", p + 1)) {
    ++lines;
  }
  const long bound = static_cast<long>((kSeconds + 2.0) * bus::LogLimiter::kDefaultLinesPerSecond);
  EXPECT_GT(lines, 0) << "the first rejections are still logged\n" << run.output;
  EXPECT_LE(lines, bound) << summary.rejected << " rejected samples printed " << lines << " lines";
  EXPECT_LT(run.output.size(), 40000u) << "stderr bytes";
  EXPECT_NE(run.output.find("similar lines suppressed]"), std::string::npos);
  std::printf("flood: %d sent, %ld rejected, %ld lines, %zu bytes of output\n", sent, summary.rejected, lines,
              run.output.size());
}

}  // namespace
}  // namespace reflex::security_test
