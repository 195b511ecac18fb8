// DDS-Security: the material made by bringup/security/make_security.sh, used by
// real Fast DDS participants. Authentication (PKI-DH), access control per topic (signed governance
// and permissions) and encryption (AES-GCM-GMAC):
//  - secure modules exchange samples (the positive control every negative test needs);
//  - a participant without credentials receives nothing from a secure writer, and what it writes
//    is never taken by a secure reader;
//  - an identity from another CA (the intruder) is refused both ways;
//  - a module cannot create a writer (or reader) its permissions do not grant;
//  - tampered or mismatched permissions stop the participant from being created;
//  - the script is idempotent.
// Domains 96..99 (the security tests use 96..110).
#include "security_support.hpp"

#include <gtest/gtest.h>

#include <cstdio>
#include <vector>

namespace reflex::security_test {
namespace {

using namespace std::chrono_literals;

class Security : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = makeSecurityMaterial("unit");
    loadProfiles(dir_);
  }
  static std::string dir_;
};
std::string Security::dir_;

TEST_F(Security, ScriptMakesEveryFileAndTheSignaturesVerify) {
  for (const char* id : {"vision", "behavior", "controller", "recorder", "player", "robot", "intruder"}) {
    for (const char* f : {"cert.pem", "key.pem", "permissions.xml", "permissions.p7s"}) {
      EXPECT_FALSE(readFile(dir_ + "/" + id + "/" + f).empty()) << id << "/" << f;
    }
    EXPECT_FALSE(readFile(dir_ + "/profiles/" + std::string(id) + ".xml").empty()) << id;
  }
  // openssl, independently of Fast DDS: each certificate is signed by its own CA and not by the other.
  auto ok = [](const std::string& cmd) { return std::system((cmd + " > /dev/null 2>&1").c_str()) == 0; };
  EXPECT_TRUE(ok("openssl verify -CAfile " + dir_ + "/ca/ca.cert.pem " + dir_ + "/controller/cert.pem"));
  EXPECT_FALSE(ok("openssl verify -CAfile " + dir_ + "/ca/ca.cert.pem " + dir_ + "/intruder/cert.pem"));
  EXPECT_TRUE(ok("openssl verify -CAfile " + dir_ + "/intruder_ca/ca.cert.pem " + dir_ + "/intruder/cert.pem"));
  EXPECT_TRUE(ok("openssl smime -verify -in " + dir_ + "/governance.p7s -CAfile " + dir_ + "/ca/ca.cert.pem"));
  EXPECT_TRUE(ok("openssl smime -verify -in " + dir_ + "/vision/permissions.p7s -CAfile " + dir_ + "/ca/ca.cert.pem"));
  // The governance refuses unauthenticated participants and encrypts topic data.
  const std::string gov = readFile(dir_ + "/governance.xml");
  EXPECT_NE(gov.find("<allow_unauthenticated_participants>false<"), std::string::npos);
  EXPECT_NE(gov.find("<data_protection_kind>ENCRYPT<"), std::string::npos);
  // Vision's permissions grant exactly object targets + heartbeat for publishing.
  const std::string perm = readFile(dir_ + "/vision/permissions.xml");
  EXPECT_NE(perm.find("<topic>reflex/object_targets</topic>"), std::string::npos);
  EXPECT_EQ(perm.find("<topic>reflex/hand_targets</topic>"), std::string::npos);
  // Private keys are readable by the owner only.
  EXPECT_TRUE(ok("test \"$(stat -c %a " + dir_ + "/vision/key.pem)\" = 600"));
}

TEST_F(Security, ScriptIsIdempotent) {
  const std::string cert = readFile(dir_ + "/behavior/cert.pem");
  const std::string key = readFile(dir_ + "/behavior/key.pem");
  const std::string perm = readFile(dir_ + "/behavior/permissions.p7s");
  const std::string gov = readFile(dir_ + "/governance.p7s");
  ASSERT_EQ(std::system((kScript + " '" + dir_ + "' > /dev/null 2>&1").c_str()), 0);
  EXPECT_EQ(readFile(dir_ + "/behavior/cert.pem"), cert);
  EXPECT_EQ(readFile(dir_ + "/behavior/key.pem"), key);
  EXPECT_EQ(readFile(dir_ + "/behavior/permissions.p7s"), perm) << "unchanged permissions are not re-signed";
  EXPECT_EQ(readFile(dir_ + "/governance.p7s"), gov);
}

TEST_F(Security, ScriptRejectsBadArguments) {
  EXPECT_NE(std::system((kScript + " --days abc /tmp/x > /dev/null 2>&1").c_str()), 0);
  EXPECT_NE(std::system((kScript + " --bogus > /dev/null 2>&1").c_str()), 0);
  EXPECT_NE(std::system((kScript + " --base-profiles /nonexistent.xml " + dir_ + " > /dev/null 2>&1").c_str()), 0);
  EXPECT_EQ(std::system((kScript + " --help > /dev/null 2>&1").c_str()), 0);
}

// Positive control: two secure modules with the right permissions talk, both directions.
TEST_F(Security, SecureModulesExchangeSamples) {
  constexpr int kDomain = 96;
  auto behavior = secureParticipant(dir_, "behavior", kDomain);
  auto controller = secureParticipant(dir_, "controller", kDomain);
  auto& targets_w = behavior->makeWriter<msg::HandTargets>();
  auto& targets_r = controller->makeReader<msg::HandTargets>();
  auto& joints_w = controller->makeWriter<msg::JointState>();
  auto& joints_r = behavior->makeReader<msg::JointState>();
  ASSERT_TRUE(targets_r.waitForWriters(1, 20s)) << "authentication + matching of the secure pair";
  ASSERT_TRUE(joints_r.waitForWriters(1, 20s));
  msg::HandTargets got;
  bool received = false;
  repeatFor(3000ms, 50ms, [&] {
    if (received) return;
    msg::HandTargets t = handTargets(0.3, 0.1, 0.9);
    targets_w.publish(t);
    received = targets_r.takeNext(got);
  });
  ASSERT_TRUE(received);
  EXPECT_EQ(got.header().source(), "behavior");
  EXPECT_DOUBLE_EQ(got.left().position_base().y(), 0.1);
  EXPECT_EQ(got.left().object_name(), "cup");

  msg::JointState js;
  js.names({"a", "b"});
  js.positions({0.5, -0.25});
  js.velocities({0.0, 0.0});
  msg::JointState js_got;
  received = false;
  repeatFor(3000ms, 20ms, [&] {
    if (received) return;
    joints_w.publish(js);
    received = joints_r.takeNext(js_got);
  });
  ASSERT_TRUE(received);
  EXPECT_EQ(js_got.positions(), js.positions());
}

TEST_F(Security, ParticipantWithoutCredentialsReceivesNothingAndIsNeverTaken) {
  constexpr int kDomain = 97;
  auto behavior = secureParticipant(dir_, "behavior", kDomain);
  auto controller = secureParticipant(dir_, "controller", kDomain);
  auto plain = plainParticipant("eavesdropper", kDomain);
  auto& secure_w = behavior->makeWriter<msg::HandTargets>();
  auto& secure_r = controller->makeReader<msg::HandTargets>();
  auto& plain_r = plain->makeReader<msg::HandTargets>();
  auto& plain_r_record = plain->makeReader<msg::JointState>("reflex/joint_state", bus::kProfileRecord);
  auto& plain_w = plain->makeWriter<msg::HandTargets>();
  auto& secure_joints = controller->makeWriter<msg::JointState>();
  ASSERT_TRUE(secure_r.waitForWriters(1, 20s)) << "the secure pair matches";

  std::vector<msg::HandTargets> secure_got, plain_got;
  std::vector<msg::JointState> plain_joints;
  msg::JointState js;
  js.names({"a"});
  js.positions({1.0});
  js.velocities({0.0});
  repeatFor(4000ms, 20ms, [&] {
    msg::HandTargets t = handTargets(0.3, 0.1, 0.9);
    secure_w.publish(t);
    msg::HandTargets forged = handTargets(0.3, -0.5, 0.2);  // what an attacker would send
    plain_w.publish(forged);
    secure_joints.publish(js);
    secure_r.takeAll(secure_got);
    plain_r.takeAll(plain_got);
    plain_r_record.takeAll(plain_joints);
  });
  ASSERT_FALSE(secure_got.empty()) << "positive control: the secure reader works";
  for (const auto& s : secure_got) EXPECT_EQ(s.header().source(), "behavior") << "a forged sample was taken";
  // The plain reader and writer share a participant, so they match each other (its own forged
  // samples come back): that is the positive control that the plain reader works.
  ASSERT_FALSE(plain_got.empty());
  for (const auto& s : plain_got) EXPECT_EQ(s.header().source(), "eavesdropper") << "a secure sample leaked";
  EXPECT_TRUE(plain_joints.empty()) << "the unauthenticated reader got joint states";
  EXPECT_EQ(plain_r.stats().matched_writers, 1) << "only its own writer";
  EXPECT_EQ(plain_w.stats().matched_readers, 1) << "only its own reader";
  EXPECT_EQ(secure_r.stats().matched_writers, 1) << "only the secure writer is matched";
}

TEST_F(Security, IntruderFromAnotherCaIsRefusedBothWays) {
  constexpr int kDomain = 98;
  auto behavior = secureParticipant(dir_, "behavior", kDomain);
  auto controller = secureParticipant(dir_, "controller", kDomain);
  // The intruder holds a well-formed identity, governance and permissions granting every topic,
  // all signed by its own CA: its participant is created, but no Reflex module authenticates it.
  auto intruder = secureParticipant(dir_, "intruder", kDomain);
  auto& secure_w = behavior->makeWriter<msg::HandTargets>();
  auto& secure_r = controller->makeReader<msg::HandTargets>();
  auto& intruder_w = intruder->makeWriter<msg::HandTargets>();
  auto& intruder_r = intruder->makeReader<msg::HandTargets>();
  ASSERT_TRUE(secure_r.waitForWriters(1, 20s));

  std::vector<msg::HandTargets> secure_got, intruder_got;
  repeatFor(4000ms, 20ms, [&] {
    msg::HandTargets t = handTargets(0.3, 0.1, 0.9);
    secure_w.publish(t);
    msg::HandTargets forged = handTargets(0.3, -0.5, 0.2);
    intruder_w.publish(forged);
    secure_r.takeAll(secure_got);
    intruder_r.takeAll(intruder_got);
  });
  ASSERT_FALSE(secure_got.empty()) << "positive control";
  for (const auto& s : secure_got) EXPECT_EQ(s.header().source(), "behavior");
  // Its own writer and reader match inside its participant (positive control of its reader).
  ASSERT_FALSE(intruder_got.empty());
  for (const auto& s : intruder_got) EXPECT_EQ(s.header().source(), "intruder") << "a secure sample leaked";
  EXPECT_EQ(intruder_r.stats().matched_writers, 1) << "only its own writer";
  EXPECT_EQ(intruder_w.stats().matched_readers, 1) << "only its own reader";
  EXPECT_EQ(secure_r.stats().matched_writers, 1);
}

// What Fast DDS 2.9 actually does for a topic the permissions do not grant: the access-control
// plugin refuses the local endpoint, create_datawriter / create_datareader return null, and
// reflex::bus turns that into a BusError naming the topic.
TEST_F(Security, ModuleCannotCreateEndpointsItsPermissionsDoNotGrant) {
  constexpr int kDomain = 99;
  auto vision = secureParticipant(dir_, "vision", kDomain);
  EXPECT_NO_THROW(vision->makeWriter<msg::ObjectTargets>()) << "granted";
  EXPECT_NO_THROW(vision->makeWriter<msg::Heartbeat>()) << "granted";
  try {
    vision->makeWriter<msg::HandTargets>();
    ADD_FAILURE() << "vision created a hand-targets writer";
  } catch (const bus::BusError& e) {
    // Named as what it is: a permission refusal, not a QoS problem.
    EXPECT_NE(std::string(e.what()).find("DDS-Security refused the DataWriter of topic 'reflex/hand_targets'"),
              std::string::npos)
        << e.what();
    EXPECT_NE(std::string(e.what()).find("grant no publish rule"), std::string::npos) << e.what();
  }
  try {
    vision->makeReader<msg::RobotState>();
    ADD_FAILURE() << "vision created a robot-state reader";
  } catch (const bus::BusError& e) {
    EXPECT_NE(std::string(e.what()).find("DDS-Security refused the DataReader of topic 'reflex/robot_state'"),
              std::string::npos)
        << e.what();
  }
  EXPECT_THROW(vision->makeWriter<msg::JointState>(), bus::BusError);
  EXPECT_THROW(vision->makeReader<msg::JointState>(), bus::BusError) << "vision may not read joint state";

  auto controller = secureParticipant(dir_, "controller", kDomain);
  EXPECT_NO_THROW(controller->makeWriter<msg::JointState>());
  EXPECT_NO_THROW(controller->makeWriter<msg::ControlStatus>());
  EXPECT_NO_THROW(controller->makeReader<msg::HandTargets>());
  EXPECT_THROW(controller->makeWriter<msg::HandTargets>(), bus::BusError);
  EXPECT_THROW(controller->makeWriter<msg::ObjectTargets>(), bus::BusError);

  // With a robot over DDS: the controller commands it and reads its state; only the robot identity
  // writes the state (and reads the commands).
  EXPECT_NO_THROW(controller->makeWriter<msg::JointCommand>());
  EXPECT_NO_THROW(controller->makeReader<msg::RobotState>());
  EXPECT_THROW(controller->makeWriter<msg::RobotState>(), bus::BusError);
  auto robot = secureParticipant(dir_, "robot", kDomain);
  EXPECT_NO_THROW(robot->makeWriter<msg::RobotState>());
  EXPECT_NO_THROW(robot->makeWriter<msg::RobotContacts>());
  EXPECT_NO_THROW(robot->makeReader<msg::JointCommand>());
  EXPECT_THROW(robot->makeWriter<msg::JointCommand>(), bus::BusError);
  EXPECT_THROW(robot->makeWriter<msg::HandTargets>(), bus::BusError);

  auto behavior = secureParticipant(dir_, "behavior", kDomain);
  EXPECT_THROW(behavior->makeWriter<msg::RobotState>(), bus::BusError) << "only the robot writes its state";
  EXPECT_NO_THROW(behavior->makeWriter<msg::HandTargets>());
  EXPECT_NO_THROW(behavior->makeWriter<msg::MotionPriority>());
  EXPECT_NO_THROW(behavior->makeWriter<msg::BodySchemaChange>());
  EXPECT_NO_THROW(behavior->makeWriter<msg::WalkCommand>());
  EXPECT_NO_THROW(behavior->makeReader<msg::ObjectTargets>());
  EXPECT_THROW(behavior->makeWriter<msg::JointState>(), bus::BusError);
  EXPECT_THROW(behavior->makeWriter<msg::ObjectTargets>(), bus::BusError);

  auto recorder = secureParticipant(dir_, "recorder", kDomain);
  EXPECT_NO_THROW(recorder->makeReader<msg::JointState>("reflex/joint_state", bus::kProfileRecord));
  EXPECT_NO_THROW(recorder->makeReader<msg::HandTargets>("reflex/hand_targets", bus::kProfileRecord));
  EXPECT_THROW(recorder->makeWriter<msg::HandTargets>(), bus::BusError) << "the recorder only listens";
  EXPECT_THROW(recorder->makeWriter<msg::JointState>(), bus::BusError);

  // The player (reflex_play) republishes observations only: never a command to the controller,
  // never a heartbeat in another module's name, and it reads nothing.
  auto player = secureParticipant(dir_, "player", kDomain);
  EXPECT_NO_THROW(player->makeWriter<msg::ObjectTargets>());
  EXPECT_NO_THROW(player->makeWriter<msg::JointState>());
  EXPECT_NO_THROW(player->makeWriter<msg::ControlStatus>());
  for (const char* topic : {"reflex/hand_targets", "reflex/motion_priority", "reflex/body_schema",
                            "reflex/walk_command", "reflex/heartbeat"}) {
    try {
      if (std::string(topic) == "reflex/hand_targets") player->makeWriter<msg::HandTargets>();
      if (std::string(topic) == "reflex/motion_priority") player->makeWriter<msg::MotionPriority>();
      if (std::string(topic) == "reflex/body_schema") player->makeWriter<msg::BodySchemaChange>();
      if (std::string(topic) == "reflex/walk_command") player->makeWriter<msg::WalkCommand>();
      if (std::string(topic) == "reflex/heartbeat") player->makeWriter<msg::Heartbeat>();
      ADD_FAILURE() << "the player created a writer of " << topic;
    } catch (const bus::BusError& e) {
      EXPECT_NE(std::string(e.what()).find(topic), std::string::npos) << e.what();
    }
  }
  EXPECT_THROW(player->makeReader<msg::ObjectTargets>("reflex/object_targets", bus::kProfileRecord), bus::BusError)
      << "the player reads nothing";
  EXPECT_THROW(player->makeReader<msg::Heartbeat>(), bus::BusError);
}

// Editing a signed permissions document (here: granting vision the hand targets) breaks its
// signature; the participant is then not created at all.
TEST_F(Security, TamperedPermissionsStopTheParticipant) {
  const std::string p7s = readFile(dir_ + "/vision/permissions.p7s");
  const std::string granted = "<topic>reflex/object_targets</topic>";
  std::string tampered = p7s;
  const auto pos = tampered.find(granted);
  ASSERT_NE(pos, std::string::npos);
  tampered.replace(pos, granted.size(), "<topic>reflex/hand_targets</topic>  ");
  const std::string bad_dir = dir_ + "/tampered";
  ASSERT_EQ(std::system(("mkdir -p '" + bad_dir + "'").c_str()), 0);
  writeFile(bad_dir + "/permissions.p7s", tampered);
  // A profile equal to vision's with the tampered permissions, and one with behavior's (valid)
  // permissions for vision's certificate (subject mismatch).
  std::string profile = readFile(dir_ + "/profiles/participants.xml");
  const auto start = profile.find("<participant profile_name=\"reflex_secure_vision\">");
  const auto end = profile.find("</participant>", start) + std::string("</participant>").size();
  ASSERT_NE(start, std::string::npos);
  std::string vision_profile = profile.substr(start, end - start);
  auto replaceAll = [](std::string s, const std::string& a, const std::string& b) {
    for (auto p = s.find(a); p != std::string::npos; p = s.find(a, p + b.size())) s.replace(p, a.size(), b);
    return s;
  };
  const std::string tampered_profile =
      replaceAll(replaceAll(vision_profile, "reflex_secure_vision", "reflex_tampered_vision"),
                 dir_ + "/vision/permissions.p7s", bad_dir + "/permissions.p7s");
  const std::string mismatched_profile =
      replaceAll(replaceAll(vision_profile, "reflex_secure_vision", "reflex_mismatched_vision"),
                 dir_ + "/vision/permissions.p7s", dir_ + "/behavior/permissions.p7s");
  const std::string file = bad_dir + "/profiles.xml";
  writeFile(file,
            "<?xml version=\"1.0\"?>\n<dds xmlns=\"http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles\">"
            "<profiles>" +
                tampered_profile + mismatched_profile + "</profiles></dds>\n");
  bus::BusConfig config;
  config.module_name = "vision";
  config.domain_id = 99;
  config.profiles_file = file;
  config.participant_profile = "reflex_tampered_vision";
  EXPECT_THROW(bus::Participant{config}, bus::BusError);
  config.participant_profile = "reflex_mismatched_vision";
  EXPECT_THROW(bus::Participant{config}, bus::BusError);
}

}  // namespace
}  // namespace reflex::security_test
