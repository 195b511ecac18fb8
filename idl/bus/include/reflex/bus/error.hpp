// reflex::bus errors. Every setup failure of the bus layer (configuration, profiles file, profile
// name, topic, entity creation) throws BusError with a message that names what failed and where
// the bad value came from. The data path (publish / take) never throws: it returns a status.
#pragma once

#include "reflex/common/error.hpp"
#include <stdexcept>
#include <string>

namespace reflex::bus {

class BusError : public reflex::Error {
 public:
  using reflex::Error::Error;
};

}  // namespace reflex::bus
