#include "reflex/bus/security.hpp"

#include <openssl/bio.h>
#include <openssl/err.h>
#include <openssl/evp.h>
#include <openssl/pem.h>
#include <openssl/pkcs7.h>
#include <openssl/x509.h>
#include <openssl/x509_vfy.h>

#include <sys/stat.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <ctime>
#include <fstream>
#include <iomanip>
#include <iterator>
#include <memory>
#include <sstream>

#include "reflex/bus/error.hpp"

namespace reflex::bus {

namespace {

using Clock = std::chrono::system_clock;

// RAII for the OpenSSL objects used here.
struct BioFree {
  void operator()(BIO* b) const { BIO_free(b); }
};
struct X509Free {
  void operator()(X509* x) const { X509_free(x); }
};
struct KeyFree {
  void operator()(EVP_PKEY* k) const { EVP_PKEY_free(k); }
};
struct StoreFree {
  void operator()(X509_STORE* s) const { X509_STORE_free(s); }
};
struct StoreCtxFree {
  void operator()(X509_STORE_CTX* c) const { X509_STORE_CTX_free(c); }
};
struct Pkcs7Free {
  void operator()(PKCS7* p) const { PKCS7_free(p); }
};
struct NameFree {
  void operator()(X509_NAME* n) const { X509_NAME_free(n); }
};
using Bio = std::unique_ptr<BIO, BioFree>;
using Cert = std::unique_ptr<X509, X509Free>;
using Key = std::unique_ptr<EVP_PKEY, KeyFree>;
using Store = std::unique_ptr<X509_STORE, StoreFree>;
using StoreCtx = std::unique_ptr<X509_STORE_CTX, StoreCtxFree>;
using Pkcs7 = std::unique_ptr<PKCS7, Pkcs7Free>;
using Name = std::unique_ptr<X509_NAME, NameFree>;

const char* const kPrefixAuth = "dds.sec.auth.builtin.PKI-DH.";
const char* const kPrefixAccess = "dds.sec.access.builtin.Access-Permissions.";

// The last OpenSSL error as text (and the queue cleared), for messages.
std::string sslError() {
  const unsigned long e = ERR_get_error();
  ERR_clear_error();
  if (e == 0) return "no detail from OpenSSL";
  char buf[256];
  ERR_error_string_n(e, buf, sizeof(buf));
  return buf;
}

// One file of the material: its property, path and contents.
struct File {
  std::string property, path, text;
  std::string where() const { return property + " file '" + path + "'"; }
};

File readMaterial(const std::string& property, const std::string& path) {
  File f{property, path, ""};
  if (path.empty()) throw BusError("DDS-Security: property " + property + " is missing from the participant profile");
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0) {
    throw BusError("DDS-Security: " + f.where() + ": " + (errno == ENOENT ? "missing" : std::strerror(errno)));
  }
  if (!S_ISREG(st.st_mode)) throw BusError("DDS-Security: " + f.where() + ": not a regular file");
  std::ifstream in(path, std::ios::binary);
  if (!in) throw BusError("DDS-Security: " + f.where() + ": cannot be read (" + std::strerror(errno) + ")");
  f.text.assign(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
  if (in.bad()) throw BusError("DDS-Security: " + f.where() + ": read error");
  if (f.text.empty()) throw BusError("DDS-Security: " + f.where() + ": empty");
  return f;
}

Bio memBio(const std::string& text) {
  Bio b(BIO_new_mem_buf(text.data(), static_cast<int>(text.size())));
  if (!b) throw BusError("DDS-Security: OpenSSL cannot allocate a buffer");
  return b;
}

Cert parseCert(const File& f) {
  Bio b = memBio(f.text);
  Cert c(PEM_read_bio_X509(b.get(), nullptr, nullptr, nullptr));
  if (!c) throw BusError("DDS-Security: " + f.where() + ": not a PEM certificate (" + sslError() + ")");
  return c;
}

Clock::time_point toTimePoint(const ASN1_TIME* t) {
  std::tm tm{};
  if (ASN1_TIME_to_tm(t, &tm) != 1) return Clock::time_point::min();
  return Clock::from_time_t(timegm(&tm));
}

std::string nameText(const X509_NAME* name) {
  Bio b(BIO_new(BIO_s_mem()));
  X509_NAME_print_ex(b.get(), name, 0, XN_FLAG_RFC2253 & ~ASN1_STRFLGS_ESC_MSB);
  char* data = nullptr;
  const long n = BIO_get_mem_data(b.get(), &data);
  return std::string(data, static_cast<std::size_t>(n > 0 ? n : 0));
}

// Validity window of a certificate at `now`; returns its notAfter.
Clock::time_point checkCertTimes(const File& f, X509* cert, Clock::time_point now) {
  const Clock::time_point not_before = toTimePoint(X509_get0_notBefore(cert));
  const Clock::time_point not_after = toTimePoint(X509_get0_notAfter(cert));
  if (now < not_before) {
    throw BusError("DDS-Security: " + f.where() + ": certificate '" + nameText(X509_get_subject_name(cert)) +
                   "' is not valid before " + formatUtc(not_before));
  }
  if (now >= not_after) {
    throw BusError("DDS-Security: " + f.where() + ": certificate '" + nameText(X509_get_subject_name(cert)) +
                   "' expired at " + formatUtc(not_after));
  }
  return not_after;
}

Store storeWith(X509* ca) {
  Store s(X509_STORE_new());
  if (!s || X509_STORE_add_cert(s.get(), ca) != 1)
    throw BusError("DDS-Security: OpenSSL cannot build a certificate store");
  return s;
}

// Verifies the S/MIME signature of a signed document against the permissions CA; returns the
// signed content (the text/plain header removed).
std::string verifySigned(const File& f, const File& ca_file, X509* ca) {
  Bio in = memBio(f.text);
  BIO* content_raw = nullptr;
  Pkcs7 p7(SMIME_read_PKCS7(in.get(), &content_raw));
  Bio content(content_raw);
  if (!p7) throw BusError("DDS-Security: " + f.where() + ": not an S/MIME signed document (" + sslError() + ")");
  Store store = storeWith(ca);
  Bio out(BIO_new(BIO_s_mem()));
  if (PKCS7_verify(p7.get(), nullptr, store.get(), content.get(), out.get(), PKCS7_TEXT) != 1) {
    throw BusError("DDS-Security: " + f.where() + ": bad signature: it does not verify against the permissions CA '" +
                   ca_file.path + "' (edited after signing, or signed by another CA: " + sslError() + ")");
  }
  char* data = nullptr;
  const long n = BIO_get_mem_data(out.get(), &data);
  return std::string(data, static_cast<std::size_t>(n > 0 ? n : 0));
}

std::string trim(const std::string& s) {
  const auto b = s.find_first_not_of(" \t\r\n");
  if (b == std::string::npos) return "";
  const auto e = s.find_last_not_of(" \t\r\n");
  return s.substr(b, e - b + 1);
}

// The text of the first <tag>...</tag> inside `text` from `from`, or "" (the permissions documents
// are flat enough for this: Reflex writes them, and a signed document cannot be changed).
std::string element(const std::string& text, const std::string& tag, std::size_t from = 0,
                    std::size_t to = std::string::npos) {
  const std::string open = "<" + tag + ">", close = "</" + tag + ">";
  const auto b = text.find(open, from);
  if (b == std::string::npos || b >= to) return "";
  const auto e = text.find(close, b);
  if (e == std::string::npos || e > to) return "";
  return trim(text.substr(b + open.size(), e - b - open.size()));
}

// Attribute set of a distinguished name in either "CN=a,O=b" or "/O=b/CN=a" form, keys upper-cased,
// sorted: equal sets mean the same name for the grants Reflex writes.
std::vector<std::string> nameParts(const std::string& dn) {
  std::vector<std::string> parts;
  std::string cur;
  for (char c : dn) {
    if (c == ',' || c == '/') {
      if (!trim(cur).empty()) parts.push_back(trim(cur));
      cur.clear();
    } else {
      cur += c;
    }
  }
  if (!trim(cur).empty()) parts.push_back(trim(cur));
  for (auto& p : parts) {
    const auto eq = p.find('=');
    if (eq == std::string::npos) continue;
    std::string key = trim(p.substr(0, eq));
    for (auto& ch : key) ch = static_cast<char>(std::toupper(static_cast<unsigned char>(ch)));
    p = key + "=" + trim(p.substr(eq + 1));
  }
  std::sort(parts.begin(), parts.end());
  return parts;
}

// "2026-11-30T00:00:00" (UTC; a trailing Z allowed), as used in <validity>.
bool parseIsoUtc(const std::string& text, Clock::time_point& out) {
  std::tm tm{};
  std::istringstream in(text);
  in >> std::get_time(&tm, "%Y-%m-%dT%H:%M:%S");
  if (in.fail()) return false;
  std::string rest;
  in >> rest;
  if (!rest.empty() && rest != "Z") return false;
  out = Clock::from_time_t(timegm(&tm));
  return true;
}

std::string stripFileUri(const std::string& property, const std::string& value) {
  if (value.rfind("file://", 0) != 0) {
    throw BusError("DDS-Security: property " + property + " = '" + value +
                   "' is not a file:// URI (the only form reflex::bus checks and Reflex deploys)");
  }
  return value.substr(7);
}

}  // namespace

std::string formatUtc(Clock::time_point t) {
  const std::time_t tt = Clock::to_time_t(t);
  std::tm tm{};
  gmtime_r(&tt, &tm);
  char buf[64];
  std::strftime(buf, sizeof(buf), "%Y-%m-%d %H:%M:%S UTC", &tm);
  return buf;
}

SecurityMaterial securityMaterialOf(const std::vector<std::pair<std::string, std::string>>& properties) {
  SecurityMaterial m;
  for (const auto& [name, value] : properties) {
    if (name == "dds.sec.auth.plugin") m.enabled = !value.empty();
    if (name == "dds.sec.access.plugin") m.access_control = !value.empty();
  }
  if (!m.enabled) return m;
  const std::string auth = kPrefixAuth, access = kPrefixAccess;
  for (const auto& [name, value] : properties) {
    if (name == auth + "identity_ca") m.identity_ca = stripFileUri(name, value);
    if (name == auth + "identity_certificate") m.identity_certificate = stripFileUri(name, value);
    if (name == auth + "private_key") m.private_key = stripFileUri(name, value);
    if (name == access + "permissions_ca") m.permissions_ca = stripFileUri(name, value);
    if (name == access + "governance") m.governance = stripFileUri(name, value);
    if (name == access + "permissions") m.permissions = stripFileUri(name, value);
  }
  return m;
}

SecurityCheck checkSecurityMaterial(const SecurityMaterial& m, Clock::time_point now) {
  const std::string auth = kPrefixAuth, access = kPrefixAccess;
  SecurityCheck result;
  result.valid_until = Clock::time_point::max();
  auto until = [&](Clock::time_point t, const std::string& what) {
    if (t < result.valid_until) {
      result.valid_until = t;
      result.valid_until_what = what;
    }
  };

  // Identity: CA, certificate (signed by the CA, in its validity window), private key of it.
  const File ca_file = readMaterial(auth + "identity_ca", m.identity_ca);
  const Cert ca = parseCert(ca_file);
  until(checkCertTimes(ca_file, ca.get(), now), "identity CA '" + ca_file.path + "'");
  const File cert_file = readMaterial(auth + "identity_certificate", m.identity_certificate);
  const Cert cert = parseCert(cert_file);
  result.subject = nameText(X509_get_subject_name(cert.get()));
  until(checkCertTimes(cert_file, cert.get(), now), "identity certificate '" + cert_file.path + "'");
  {
    Store store = storeWith(ca.get());
    StoreCtx ctx(X509_STORE_CTX_new());
    if (!ctx || X509_STORE_CTX_init(ctx.get(), store.get(), cert.get(), nullptr) != 1) {
      throw BusError("DDS-Security: OpenSSL cannot set up a certificate check");
    }
    X509_STORE_CTX_set_flags(ctx.get(), X509_V_FLAG_NO_CHECK_TIME);  // times are checked above, with dates
    if (X509_verify_cert(ctx.get()) != 1) {
      throw BusError("DDS-Security: " + cert_file.where() + ": certificate '" + result.subject +
                     "' does not verify against the identity CA '" + ca_file.path + "' (" +
                     X509_verify_cert_error_string(X509_STORE_CTX_get_error(ctx.get())) + ")");
    }
  }
  const File key_file = readMaterial(auth + "private_key", m.private_key);
  {
    // The same rule as make_security.sh: a private key that group or others can read may have been
    // copied; it is refused, not used.
    struct stat st {};
    if (::stat(key_file.path.c_str(), &st) == 0 && (st.st_mode & 077) != 0) {
      char mode[8];
      std::snprintf(mode, sizeof(mode), "%04o", static_cast<unsigned>(st.st_mode & 07777));
      throw BusError("DDS-Security: " + key_file.where() + ": readable by group or others (mode " + mode +
                     "): refused, as bringup/security/make_security.sh refuses it; a key others could read may "
                     "have been copied: make new material (make_security.sh --force), or, knowing nobody else "
                     "read it, chmod 600 it");
    }
  }
  {
    Bio b = memBio(key_file.text);
    Key key(PEM_read_bio_PrivateKey(b.get(), nullptr, nullptr, nullptr));
    if (!key)
      throw BusError("DDS-Security: " + key_file.where() + ": not a PEM private key without password (" + sslError() +
                     ")");
    if (X509_check_private_key(cert.get(), key.get()) != 1) {
      ERR_clear_error();
      throw BusError("DDS-Security: " + key_file.where() + ": not the private key of the identity certificate '" +
                     cert_file.path + "'");
    }
  }

  // Access control (when configured): governance and permissions signed by the permissions CA.
  if (!m.access_control) return result;
  const File pca_file = readMaterial(access + "permissions_ca", m.permissions_ca);
  const Cert pca = parseCert(pca_file);
  until(checkCertTimes(pca_file, pca.get(), now), "permissions CA '" + pca_file.path + "'");
  const File gov_file = readMaterial(access + "governance", m.governance);
  const std::string governance = verifySigned(gov_file, pca_file, pca.get());
  if (governance.find("<domain_access_rules>") == std::string::npos) {
    throw BusError("DDS-Security: " + gov_file.where() + ": the signed document holds no <domain_access_rules>");
  }
  const File perm_file = readMaterial(access + "permissions", m.permissions);
  const std::string permissions = verifySigned(perm_file, pca_file, pca.get());

  // The grant of this certificate's subject, and its validity.
  const std::vector<std::string> subject_parts = nameParts(result.subject);
  std::string subjects_seen;
  for (std::size_t pos = permissions.find("<grant"); pos != std::string::npos;
       pos = permissions.find("<grant", pos + 1)) {
    const std::size_t end = permissions.find("</grant>", pos);
    const std::string subject = element(permissions, "subject_name", pos, end);
    subjects_seen += (subjects_seen.empty() ? "'" : ", '") + subject + "'";
    if (nameParts(subject) != subject_parts) continue;
    const std::string nb = element(permissions, "not_before", pos, end),
                      na = element(permissions, "not_after", pos, end);
    Clock::time_point t_nb, t_na;
    if (!parseIsoUtc(nb, t_nb) || !parseIsoUtc(na, t_na)) {
      throw BusError("DDS-Security: " + perm_file.where() + ": grant of '" + subject + "': validity '" + nb + "' .. '" +
                     na + "' is not YYYY-MM-DDTHH:MM:SS (UTC)");
    }
    if (now < t_nb) {
      throw BusError("DDS-Security: " + perm_file.where() + ": grant of '" + subject + "' is not valid before " +
                     formatUtc(t_nb));
    }
    if (now >= t_na) {
      throw BusError("DDS-Security: " + perm_file.where() + ": grant of '" + subject + "' expired at " +
                     formatUtc(t_na));
    }
    until(t_na, "permissions grant of '" + subject + "' in '" + perm_file.path + "'");
    return result;
  }
  throw BusError("DDS-Security: " + perm_file.where() + ": no grant for the identity certificate's subject '" +
                 result.subject + "' (grants for: " + (subjects_seen.empty() ? "none" : subjects_seen) +
                 "): certificate '" + cert_file.path + "' and permissions do not belong together");
}

std::string toString(const GuidPrefix& prefix) {
  static const char* const hex = "0123456789abcdef";
  std::string s;
  for (std::size_t i = 0; i < prefix.size(); ++i) {
    if (i > 0) s += '.';
    s += hex[prefix[i] >> 4];
    s += hex[prefix[i] & 0xF];
  }
  return s;
}

std::string identitySubject(const std::string& name) { return "CN=reflex." + name; }

std::array<std::uint8_t, 6> subjectGuidBits(const std::string& subject) {
  // RFC 2253 lists the most specific attribute first; the DER name holds them in the other order.
  std::vector<std::pair<std::string, std::string>> attrs;
  std::string cur;
  auto flush = [&] {
    const std::string p = trim(cur);
    cur.clear();
    if (p.empty()) return;
    const auto eq = p.find('=');
    if (eq == std::string::npos || eq == 0)
      throw BusError("subject name '" + subject + "': '" + p + "' is not KEY=VALUE");
    attrs.emplace_back(trim(p.substr(0, eq)), trim(p.substr(eq + 1)));
  };
  for (char c : subject) {
    if (c == ',')
      flush();
    else
      cur += c;
  }
  flush();
  if (attrs.empty()) throw BusError("empty subject name");
  Name name(X509_NAME_new());
  for (auto it = attrs.rbegin(); it != attrs.rend(); ++it) {
    if (X509_NAME_add_entry_by_txt(name.get(), it->first.c_str(), MBSTRING_UTF8,
                                   reinterpret_cast<const unsigned char*>(it->second.c_str()), -1, -1, 0) != 1) {
      throw BusError("subject name '" + subject + "': unknown attribute '" + it->first + "' (" + sslError() + ")");
    }
  }
  unsigned char md[EVP_MAX_MD_SIZE];
  unsigned int length = 0;
  if (X509_NAME_digest(name.get(), EVP_sha256(), md, &length) != 1 || length < 6) {
    throw BusError("subject name '" + subject + "': OpenSSL cannot hash it");
  }
  // The PKI-DH participant key (DDS-Security 1.1, 9.3.3): bit 0 set, bits 1..47 = SHA-256 bits 0..46.
  std::array<std::uint8_t, 6> bits{};
  bits[0] = static_cast<std::uint8_t>(0x80 | (md[0] >> 1));
  for (int i = 1; i < 6; ++i) bits[i] = static_cast<std::uint8_t>((md[i - 1] << 7) | (md[i] >> 1));
  return bits;
}

bool prefixMatchesSubjectBits(const GuidPrefix& prefix, const std::array<std::uint8_t, 6>& bits) {
  return std::equal(bits.begin(), bits.end(), prefix.begin());
}

}  // namespace reflex::bus
