#include "reflex/common/shipped.hpp"
#include "reflex/bus/config.hpp"

#include <cerrno>
#include <cstdlib>

#include "reflex/bus/error.hpp"

namespace reflex::bus {

int parseDomainId(const std::string& text, const std::string& origin) {
  const std::string where = " (from " + origin + ")";
  if (text.empty()) {
    throw BusError("empty DDS domain id" + where + "; expected an integer in [0, " + std::to_string(kMaxDomainId) +
                   "]");
  }
  errno = 0;
  char* end = nullptr;
  const long value = std::strtol(text.c_str(), &end, 10);
  if (errno != 0 || end == text.c_str() || *end != '\0' || value < 0 || value > kMaxDomainId) {
    throw BusError("bad DDS domain id '" + text + "'" + where + "; expected an integer in [0, " +
                   std::to_string(kMaxDomainId) + "]");
  }
  return static_cast<int>(value);
}

int resolveDomainId(const std::optional<int>& configured) {
  if (configured) {
    if (*configured < 0 || *configured > kMaxDomainId) {
      throw BusError("bad DDS domain id '" + std::to_string(*configured) +
                     "' (from the configuration); expected an integer in [0, " + std::to_string(kMaxDomainId) + "]");
    }
    return *configured;
  }
  if (const char* env = std::getenv("REFLEX_DOMAIN_ID")) {
    return parseDomainId(env, "environment variable REFLEX_DOMAIN_ID");
  }
  return 0;
}

std::string resolveProfilesFile(const std::string& configured) {
  if (!configured.empty()) return configured;
  if (const char* env = std::getenv("FASTRTPS_DEFAULT_PROFILES_FILE"); env && *env) return env;
  return reflex::common::defaultProfilesFile();
}

}  // namespace reflex::bus
