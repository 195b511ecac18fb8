// A malformed sample on the wire: a rogue participant registers the type name
// "reflex::msg::HandTargets" with its own type support and writes raw bytes to reflex/hand_targets —
// a bad CDR encapsulation header, a truncated body, a string length far beyond the payload, and
// random bytes. The real reflex_controller must not crash (its takes run inside the 5 ms loop) and
// must keep its 200 Hz. Domain 110.
#include "controller_run.hpp"

#include <fastdds/dds/publisher/Publisher.hpp>
#include <fastdds/dds/publisher/qos/DataWriterQos.hpp>
#include <fastdds/dds/topic/TopicDataType.hpp>
#include <fastdds/dds/topic/Topic.hpp>

#include <cstring>
#include <random>

namespace reflex::bad_input {
namespace {

namespace dds = eprosima::fastdds::dds;

// Type support that writes the bytes of a std::vector<uint8_t> as the serialized payload, as is.
class RawBytesType final : public dds::TopicDataType {
 public:
  explicit RawBytesType(const std::string& type_name) {
    setName(type_name.c_str());
    m_typeSize = 8192;
    m_isGetKeyDefined = false;
  }
  bool serialize(void* data, eprosima::fastrtps::rtps::SerializedPayload_t* payload) override {
    const auto& bytes = *static_cast<std::vector<std::uint8_t>*>(data);
    if (bytes.size() > payload->max_size) return false;
    if (!bytes.empty()) std::memcpy(payload->data, bytes.data(), bytes.size());  // data() may be null
    payload->length = static_cast<std::uint32_t>(bytes.size());
    return true;
  }
  bool deserialize(eprosima::fastrtps::rtps::SerializedPayload_t*, void*) override { return false; }
  std::function<std::uint32_t()> getSerializedSizeProvider(void* data) override {
    return [data] { return static_cast<std::uint32_t>(static_cast<std::vector<std::uint8_t>*>(data)->size()); };
  }
  void* createData() override { return new std::vector<std::uint8_t>(); }
  void deleteData(void* data) override { delete static_cast<std::vector<std::uint8_t>*>(data); }
  bool getKey(void*, eprosima::fastrtps::rtps::InstanceHandle_t*, bool) override { return false; }
};

TEST(MalformedSamples, RawBytesOnTheHandTargetsTopicNeverCrashTheController) {
  ControllerRun run(110, 7.0, "malformed");
  ASSERT_TRUE(run.started());
  // The rogue writer lives in its own participant (native Fast DDS API, same QoS profile).
  auto& p = run.source->native();
  dds::TypeSupport type(new RawBytesType("reflex::msg::HandTargets"));
  ASSERT_EQ(type.register_type(&p), eprosima::fastrtps::types::ReturnCode_t::RETCODE_OK);
  dds::Topic* topic = p.create_topic("reflex/hand_targets", "reflex::msg::HandTargets", dds::TOPIC_QOS_DEFAULT);
  ASSERT_NE(topic, nullptr);
  dds::Publisher* pub = p.create_publisher(dds::PUBLISHER_QOS_DEFAULT);
  ASSERT_NE(pub, nullptr);
  dds::DataWriter* writer = pub->create_datawriter_with_profile(topic, bus::kProfileBehavior);
  ASSERT_NE(writer, nullptr);
  ASSERT_TRUE(run.status->waitForWriters(1, 15s));
  std::this_thread::sleep_for(1000ms);  // the controller's reader matches the rogue writer

  std::vector<std::vector<std::uint8_t>> samples = {
      {0x02, 0x00, 0x00, 0x00, 1, 2, 3, 4},              // bad encapsulation (first byte non-zero)
      {0x00, 0x07, 0x00, 0x00, 1, 2, 3, 4},              // unknown representation id
      {0x00, 0x01, 0x00, 0x00},                          // header only: body missing
      {0x00, 0x01, 0x00, 0x00, 0xff, 0xff, 0xff, 0x7f},  // truncated inside the header fields
      {},                                                // empty payload
  };
  // A little-endian header whose source string claims 2^31 bytes.
  std::vector<std::uint8_t> long_string = {0x00, 0x01, 0x00, 0x00};
  for (int i = 0; i < 16; ++i) long_string.push_back(0);
  for (std::uint8_t b : {0x00, 0x00, 0x00, 0x80}) long_string.push_back(b);
  samples.push_back(long_string);
  std::mt19937 rng(110);
  for (int i = 0; i < 40; ++i) {
    std::vector<std::uint8_t> r = {0x00, 0x01, 0x00, 0x00};
    const int n = static_cast<int>(rng() % 200);
    for (int k = 0; k < n; ++k) r.push_back(static_cast<std::uint8_t>(rng()));
    samples.push_back(r);
  }
  run.drain();
  run.statuses.clear();
  run.pumpCount(static_cast<int>(samples.size()), 30ms,
                [&](int k) { writer->write(&samples[static_cast<std::size_t>(k)]); });
  run.pump(1000ms, 50ms, [](int) {});
  EXPECT_GT(run.statuses.size(), 0.75 * 200.0 * (0.03 * samples.size() + 1.0)) << "the controller kept publishing";
  run.expectSafeAndFinite();

  ExitSummary s;
  const int rc = run.finish(s);
  EXPECT_EQ(rc, 0) << "the controller died (exit/signal " << rc << "):\n" << run.output;
  EXPECT_TRUE(s.found) << run.output;
}

}  // namespace
}  // namespace reflex::bad_input
