#pragma once
// reflex::vision error type. Every setup error (calibration, object map, session folder, camera,
// detector options) throws VisionError with a message that quotes the bad value and the file or
// option it came from. Per-frame problems during a run never throw: they are returned as a status.
#include "reflex/common/error.hpp"
#include <stdexcept>
#include <string>

namespace reflex::vision {

class VisionError : public reflex::Error {
 public:
  explicit VisionError(const std::string& what) : reflex::Error(what) {}
};

}  // namespace reflex::vision
