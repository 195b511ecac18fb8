// Every setup error of reflex::bus is a BusError whose message names what failed (domain 46):
// unknown participant / writer / reader profile (with the profiles file), malformed and missing
// profiles files (with their path), a topic name reused with another type (with the topic and both
// type names), bad domain ids (with the value and where it came from), a second StopOnSignal.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <reflex/bus/participant.hpp>
#include <reflex/bus/signals.hpp>

#include <cstdio>
#include <cstdlib>
#include <fstream>

#include "bus_test_util.hpp"

namespace reflex::bus::test {
namespace {

using ::testing::HasSubstr;
constexpr int kDomain = 46;

// Runs `fn`, expects a BusError, returns its message.
template <class Fn>
std::string busErrorOf(Fn&& fn) {
  try {
    fn();
  } catch (const BusError& e) {
    return e.what();
  } catch (const std::exception& e) {
    ADD_FAILURE() << "expected a BusError, got another exception: " << e.what();
    return {};
  }
  ADD_FAILURE() << "expected a BusError, nothing was thrown";
  return {};
}

std::string tempFile(const std::string& name, const std::string& content) {
  const std::string path = ::testing::TempDir() + name;
  std::ofstream(path) << content;
  return path;
}

TEST(SetupErrors, UnknownParticipantProfile) {
  const std::string msg = busErrorOf([] { Participant bus(testConfig("e", kDomain, "no_such_participant")); });
  EXPECT_THAT(msg, HasSubstr("'no_such_participant'"));
  EXPECT_THAT(msg, HasSubstr(kProfilesFile));
}

TEST(SetupErrors, UnknownWriterAndReaderProfiles) {
  Participant bus(testConfig("e", kDomain));
  std::string msg =
      busErrorOf([&] { bus.makeWriter<msg::JointState>("reflex/joint_state", "no_such_writer_profile"); });
  EXPECT_THAT(msg, HasSubstr("'no_such_writer_profile'"));
  EXPECT_THAT(msg, HasSubstr("'reflex/joint_state'"));
  EXPECT_THAT(msg, HasSubstr(kProfilesFile));
  msg = busErrorOf([&] { bus.makeReader<msg::HandTargets>("reflex/hand_targets", "no_such_reader_profile"); });
  EXPECT_THAT(msg, HasSubstr("'no_such_reader_profile'"));
  EXPECT_THAT(msg, HasSubstr("'reflex/hand_targets'"));
  // reflex_record exists only as a data_reader profile: as a writer profile it is unknown.
  msg = busErrorOf([&] { bus.makeWriter<msg::JointState>("reflex/joint_state", kProfileRecord); });
  EXPECT_THAT(msg, HasSubstr("'reflex_record'"));
  // The participant is still fine after the failures.
  auto& w = bus.makeWriter<msg::JointState>();
  EXPECT_EQ(w.topicName(), "reflex/joint_state");
}

TEST(SetupErrors, MalformedProfilesFile) {
  const std::string path = tempFile("reflex_bad_profiles.xml",
                                    "<?xml version=\"1.0\"?>\n<dds><profiles><participant profile_name=\"x\">"
                                    "<rtps><name>oops</rtps></participant>\n");
  BusConfig c = testConfig("e", kDomain);
  c.profiles_file = path;
  const std::string msg = busErrorOf([&] { Participant bus(c); });
  EXPECT_THAT(msg, HasSubstr(path));
  EXPECT_THAT(msg, HasSubstr("malformed"));
  EXPECT_THAT(msg, HasSubstr("bus configuration"));
}

TEST(SetupErrors, MissingProfilesFileFromConfigurationOrEnvironment) {
  const std::string path = ::testing::TempDir() + "reflex_no_such_profiles.xml";
  std::remove(path.c_str());
  BusConfig c = testConfig("e", kDomain);
  c.profiles_file = path;
  std::string msg = busErrorOf([&] { Participant bus(c); });
  EXPECT_THAT(msg, HasSubstr(path));
  EXPECT_THAT(msg, HasSubstr("cannot open"));

  c.profiles_file.clear();
  ::setenv("FASTRTPS_DEFAULT_PROFILES_FILE", path.c_str(), 1);
  msg = busErrorOf([&] { Participant bus(c); });
  ::unsetenv("FASTRTPS_DEFAULT_PROFILES_FILE");
  EXPECT_THAT(msg, HasSubstr(path));
  EXPECT_THAT(msg, HasSubstr("FASTRTPS_DEFAULT_PROFILES_FILE"));
}

TEST(SetupErrors, TopicNameReusedWithAnotherType) {
  Participant bus(testConfig("e", kDomain));
  bus.makeWriter<msg::JointState>("reflex/shared_name", kProfileState);
  const std::string msg = busErrorOf([&] { bus.makeReader<msg::ControlStatus>("reflex/shared_name", kProfileState); });
  EXPECT_THAT(msg, HasSubstr("'reflex/shared_name'"));
  EXPECT_THAT(msg, HasSubstr("reflex::msg::JointState"));
  EXPECT_THAT(msg, HasSubstr("reflex::msg::ControlStatus"));
  // The same type on the same name is fine (a second reader of the existing topic).
  auto& r = bus.makeReader<msg::JointState>("reflex/shared_name", kProfileState);
  EXPECT_EQ(r.topicName(), "reflex/shared_name");
}

TEST(SetupErrors, BadDomainIds) {
  BusConfig c = testConfig("e", -1);
  std::string msg = busErrorOf([&] { Participant bus(c); });
  EXPECT_THAT(msg, HasSubstr("'-1'"));
  EXPECT_THAT(msg, HasSubstr("configuration"));
  c.domain_id = 233;
  EXPECT_THAT(busErrorOf([&] { Participant bus(c); }), HasSubstr("'233'"));

  c.domain_id.reset();
  for (const char* bad : {"4x2", "", "-3", "99999999999999999999", "233"}) {
    ::setenv("REFLEX_DOMAIN_ID", bad, 1);
    msg = busErrorOf([&] { Participant bus(c); });
    EXPECT_THAT(msg, HasSubstr("REFLEX_DOMAIN_ID")) << bad;
    if (*bad) {
      EXPECT_THAT(msg, HasSubstr(std::string("'") + bad + "'"));
    }
  }
  ::unsetenv("REFLEX_DOMAIN_ID");
  EXPECT_THAT(busErrorOf([] { parseDomainId("seven", "--domain"); }), HasSubstr("'seven' (from --domain)"));
}

TEST(SetupErrors, EmptyModuleNameAndBadTimerPeriod) {
  EXPECT_THAT(busErrorOf([] { Participant bus(testConfig("", kDomain)); }), HasSubstr("module name"));
  Participant bus(testConfig("e", kDomain));
  EXPECT_THAT(busErrorOf([&] { bus.every(std::chrono::nanoseconds(0), [] {}); }), HasSubstr("0 ns"));
}

TEST(SetupErrors, OnlyOneStopOnSignalAtATime) {
  Participant bus(testConfig("e", kDomain));
  {
    StopOnSignal first(bus);
    EXPECT_THAT(busErrorOf([&] { StopOnSignal second(bus); }), HasSubstr("already exists"));
  }
  StopOnSignal again(bus);  // the first one was removed: installing anew is fine
  EXPECT_EQ(again.lastSignal(), 0);
}

}  // namespace
}  // namespace reflex::bus::test
