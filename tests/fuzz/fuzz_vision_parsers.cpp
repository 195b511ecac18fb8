// libFuzzer targets for the session files read by vision/ (one executable per parser, chosen with
// the REFLEX_FUZZ_PARSER definition, see CMakeLists.txt):
//   1 camera_info YAML   parseCameraInfo      (left.yaml / right.yaml)
//   2 camera mount YAML  parseCameraMount     (camera_mount.yaml)
//   3 object map YAML    parseObjectMap       (objects.yaml)
//   4 timestamps CSV     loadTimestamps       (timestamps.csv, via a file)
//   5 ground truth CSV   loadGroundTruth      (ground_truth.csv, via a file)
// Documented reaction to bad input: reflex::vision::VisionError.
#include "fuzz_util.hpp"

#include "reflex/vision/calibration.hpp"
#include "reflex/vision/error.hpp"
#include "reflex/vision/object_map.hpp"
#include "reflex/vision/session.hpp"

#ifndef REFLEX_FUZZ_PARSER
#error "REFLEX_FUZZ_PARSER must be defined (1..5)"
#endif

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace reflex::vision;
  using reflex::fuzz::asText;
  using reflex::fuzz::expectOnly;
#if REFLEX_FUZZ_PARSER == 1
  expectOnly<VisionError>("parseCameraInfo", [&] { (void)parseCameraInfo(asText(data, size), "fuzz.yaml"); });
#elif REFLEX_FUZZ_PARSER == 2
  expectOnly<VisionError>("parseCameraMount", [&] { (void)parseCameraMount(asText(data, size), "fuzz.yaml"); });
#elif REFLEX_FUZZ_PARSER == 3
  expectOnly<VisionError>("parseObjectMap", [&] { (void)parseObjectMap(asText(data, size), "fuzz.yaml"); });
#elif REFLEX_FUZZ_PARSER == 4
  const std::string& path = reflex::fuzz::writeTemp(data, size, ".timestamps.csv");
  expectOnly<VisionError>("loadTimestamps", [&] { (void)loadTimestamps(path); });
#elif REFLEX_FUZZ_PARSER == 5
  const std::string& path = reflex::fuzz::writeTemp(data, size, ".ground_truth.csv");
  expectOnly<VisionError>("loadGroundTruth", [&] { (void)loadGroundTruth(path); });
#else
#error "REFLEX_FUZZ_PARSER out of range"
#endif
  return 0;
}
