// Type support for recording, replaying and exporting the Reflex topics. One TopicCodec per topic
// type of idl/ (reflex::bus::TopicTraits), found by DDS type name or by default topic name.
// Samples are (de)serialized with the type's Fast DDS TopicDataType (fastddsgen PubSubType), so a
// recording holds exactly the XCDR1 bytes that travel on the wire.
//
// To support a new topic type: add one line to the table in codecs.cpp (it needs a TopicTraits
// specialization) and its CSV columns (csvColumns / csvRow overloads there).
#pragma once

#include "reflex/record/record_file.hpp"

#include <cstdint>
#include <functional>
#include <memory>
#include <ostream>
#include <string>
#include <vector>

namespace reflex::bus {
class Participant;
namespace detail {
class ReaderBase;
}
}  // namespace reflex::bus

namespace reflex::record {

/// Publishes recorded payloads of one topic (made by TopicCodec::makePublisher).
class SamplePublisher {
 public:
  virtual ~SamplePublisher() = default;
  /// Deserializes `payload` and writes the sample with its header untouched, except that with
  /// `shift_ns` != 0 every time stamp of the sample (header.stamp_ns, and capture_stamp_ns of object
  /// targets) is moved by shift_ns. False if the payload does not deserialize or the write fails.
  virtual bool publish(const std::vector<std::uint8_t>& payload, std::int64_t shift_ns) = 0;
  /// Number of matched readers now.
  virtual int matchedReaders() const = 0;
};

/// Options of the CSV export of one topic.
struct CsvContext {
  std::int64_t t0_ns = 0;  ///< receive time that becomes t = 0 (first record of the file)
};

class TopicCodec {
 public:
  virtual ~TopicCodec() = default;
  /// DDS type name, e.g. "reflex::msg::ControlStatus".
  virtual const std::string& typeName() const = 0;
  /// Short name, e.g. "ControlStatus".
  virtual std::string shortName() const = 0;
  /// Default topic of the type (TopicTraits<T>::kTopicName).
  virtual const char* defaultTopic() const = 0;
  /// QoS profile of the type's writers and readers (TopicTraits<T>::kProfile).
  virtual const char* defaultProfile() const = 0;
  /// True if writers of this type keep the current state for late joiners (transient local).
  virtual bool isState() const = 0;

  /// Makes a reader of `topic` with the data_reader profile `profile` on `bus`; every valid sample
  /// is serialized and handed to `sink` (from bus.run()). Returns the reader (owned by `bus`).
  /// Throws as Participant::makeReader.
  virtual bus::detail::ReaderBase& subscribe(bus::Participant& bus, const std::string& topic,
                                             const std::string& profile,
                                             std::function<void(RecordEntry&&)> sink) const = 0;
  /// Makes a writer of `topic` with the data_writer profile `profile`. Throws as makeWriter.
  virtual std::unique_ptr<SamplePublisher> makePublisher(bus::Participant& bus, const std::string& topic,
                                                         const std::string& profile) const = 0;

  /// Writes the CSV header line for this type (columns may depend on the first sample, e.g. joint
  /// names). Throws RecordError if `first` does not deserialize (then nothing is written).
  virtual void writeCsvHeader(std::ostream& out, const RecordEntry& first) const = 0;
  /// Writes the CSV row(s) of one record (object targets: one row per object). Throws RecordError
  /// naming the topic and the reason if the payload does not deserialize as this type (then nothing is
  /// written). A sample's lengths are checked against its bytes before anything is allocated.
  virtual void writeCsvRows(std::ostream& out, const RecordEntry& entry, const CsvContext& ctx) const = 0;
  /// One-line human-readable summary of a sample (for `reflex_record info --print`).
  virtual std::string summary(const RecordEntry& entry) const = 0;
};

/// Every known codec (one per topic type of idl/).
const std::vector<const TopicCodec*>& allCodecs();
/// The codec of a DDS type name ("reflex::msg::HandTargets") or short name ("HandTargets");
/// nullptr if unknown.
const TopicCodec* findCodecByType(const std::string& type_name);
/// The codec whose default topic is `topic`; nullptr if none.
const TopicCodec* findCodecByTopic(const std::string& topic);

/// A topic to record: its name and codec. Parsed from "reflex/joint_state" (a default topic) or
/// "NAME:TYPE" (any topic name, TYPE a DDS or short type name). Throws RecordError quoting the
/// text if the topic or type is unknown.
struct TopicSpec {
  std::string topic;
  const TopicCodec* codec = nullptr;
};
TopicSpec parseTopicSpec(const std::string& text);

/// Quotes a CSV field if needed (comma, quote, newline).
std::string csvField(const std::string& s);

/// A topic (or type) name from a file as the tools print it: every control byte (below 0x20, 0x7F) and
/// the backslash written as \xNN, so a name cannot move the cursor, clear the terminal or pass for
/// two lines, and two different names never print alike. "reflex/a\tb" -> "reflex/a\x09b".
std::string printableName(const std::string& name);

}  // namespace reflex::record
