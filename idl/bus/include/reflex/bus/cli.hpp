// The bus options every Reflex program that joins the bus takes, in one place: --domain, --profiles
// and --participant-profile, with one help text, one check and one error for a bad domain id.
// Header-only (the programs use CLI11; the bus library does not).
#pragma once

#include "reflex/bus/config.hpp"
#include "reflex/bus/error.hpp"
#include "reflex/common/shipped.hpp"

#include <CLI/CLI.hpp>

#include <optional>
#include <string>

namespace reflex::bus {

/// --domain / --profiles / --participant-profile as given on a command line.
struct BusOptions {
  std::string domain;    ///< as typed; empty: not given ($REFLEX_DOMAIN_ID, else 0)
  std::string profiles;  ///< empty: not given ($FASTRTPS_DEFAULT_PROFILES_FILE, else the shipped file)
  std::string participant_profile = "reflex_participant";

  /// Adds the options to `app`. `participant_note` (if not empty) is added to --participant-profile's
  /// help, e.g. why the program's default differs; with_participant_profile = false leaves that option
  /// out (a program whose participant profile is fixed). A --domain that parseDomainId refuses is a
  /// command-line error naming the value (exit 2 under runMain).
  void add(CLI::App& app, const std::string& participant_note = "", bool with_participant_profile = true) {
    app.add_option("--domain", domain,
                   "DDS domain id 0.." + std::to_string(kMaxDomainId) + " (default: $REFLEX_DOMAIN_ID, else 0)")
        ->check(CLI::Validator(
            [](std::string& text) {
              try {
                parseDomainId(text, "--domain");
                return std::string();
              } catch (const BusError& e) {
                return std::string(e.what());
              }
            },
            "DOMAIN"));
    app.add_option(
        "--profiles", profiles,
        "DDS QoS profiles XML (default: $FASTRTPS_DEFAULT_PROFILES_FILE, else " + common::defaultProfilesFile() + ")");
    if (with_participant_profile) {
      app.add_option("--participant-profile", participant_profile,
                     "participant profile in the profiles XML" +
                         (participant_note.empty() ? std::string() : " (" + participant_note + ")"))
          ->capture_default_str();
    }
  }

  /// The domain id given, or nothing (the bus then takes $REFLEX_DOMAIN_ID, else 0).
  std::optional<int> domainId() const {
    if (domain.empty()) return std::nullopt;
    return parseDomainId(domain, "--domain");
  }

  /// A participant configuration named `module` with what was given.
  BusConfig config(const std::string& module) const {
    BusConfig c;
    c.module_name = module;
    c.domain_id = domainId();
    c.profiles_file = profiles;
    c.participant_profile = participant_profile;
    return c;
  }
};

}  // namespace reflex::bus
