// Helpers of the DDS-Security tests: run bringup/security/make_security.sh into a fresh temporary
// folder once per test program, and make participants with a given identity (or none).
#pragma once

#include <reflex/bus/bus.hpp>

#include <fastdds/dds/domain/DomainParticipantFactory.hpp>

#include <gtest/gtest.h>

#include <chrono>
#include <cstdlib>
#include <fstream>
#include <iterator>
#include <memory>
#include <stdexcept>
#include <string>
#include <thread>

namespace reflex::security_test {

inline const std::string kBaseProfiles = std::string(REFLEX_SOURCE_DIR) + "/bringup/dds/reflex_profiles.xml";
inline const std::string kScript = std::string(REFLEX_SOURCE_DIR) + "/bringup/security/make_security.sh";

inline std::string readFile(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
}

inline void writeFile(const std::string& path, const std::string& text) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out << text;
  if (!out) throw std::runtime_error("cannot write '" + path + "'");
}

/// Runs the script into a new temporary folder and returns the folder (throws on failure).
inline std::string makeSecurityMaterial(const std::string& tag) {
  std::string templ = ::testing::TempDir() + "reflex_sec_" + tag + "_XXXXXX";
  if (mkdtemp(templ.data()) == nullptr) throw std::runtime_error("mkdtemp failed for '" + templ + "'");
  const std::string cmd = kScript + " '" + templ + "' > '" + templ + ".log' 2>&1";
  const int rc = std::system(cmd.c_str());
  if (rc != 0) {
    throw std::runtime_error("'" + cmd + "' failed (" + std::to_string(rc) + "): " + readFile(templ + ".log"));
  }
  return templ;
}

/// Loads the plain QoS profiles and the secure participant profiles of every identity (process-wide).
inline void loadProfiles(const std::string& dir) {
  auto* factory = eprosima::fastdds::dds::DomainParticipantFactory::get_instance();
  using eprosima::fastrtps::types::ReturnCode_t;
  if (factory->load_XML_profiles_file(kBaseProfiles) != ReturnCode_t::RETCODE_OK ||
      factory->load_XML_profiles_file(dir + "/profiles/participants.xml") != ReturnCode_t::RETCODE_OK) {
    throw std::runtime_error("cannot load the profiles of '" + dir + "'");
  }
}

/// A participant with the identity `identity` (vision, behavior, controller, recorder, intruder).
inline std::unique_ptr<bus::Participant> secureParticipant(const std::string& dir, const std::string& identity,
                                                           int domain) {
  bus::BusConfig config;
  config.module_name = identity;
  config.domain_id = domain;
  config.profiles_file = dir + "/profiles/participants.xml";
  config.participant_profile = "reflex_secure_" + identity;
  return std::make_unique<bus::Participant>(config);
}

/// A participant without any credentials (the plain default profile).
inline std::unique_ptr<bus::Participant> plainParticipant(const std::string& name, int domain) {
  bus::BusConfig config;
  config.module_name = name;
  config.domain_id = domain;
  config.profiles_file = kBaseProfiles;
  config.participant_profile = "reflex_participant";
  return std::make_unique<bus::Participant>(config);
}

inline msg::HandTargets handTargets(double x, double y, double z) {
  msg::HandTargets t;
  t.left().status(msg::TARGET_GIVEN);
  t.left().position_base().x(x);
  t.left().position_base().y(y);
  t.left().position_base().z(z);
  t.left().object_name("cup");
  t.right().status(msg::TARGET_NONE);
  return t;
}

/// Repeats `fn` every `period` for `duration` (publishing loops of the tests).
template <class Fn>
void repeatFor(std::chrono::milliseconds duration, std::chrono::milliseconds period, Fn fn) {
  const auto end = std::chrono::steady_clock::now() + duration;
  while (std::chrono::steady_clock::now() < end) {
    fn();
    std::this_thread::sleep_for(period);
  }
}

}  // namespace reflex::security_test
