// Reading module and process configuration from YAML, with errors that say where.
//
// The behavior layer reads through the project's one YAML reader (reflex/common/yaml_reader.hpp): a
// ConfigNode is a YAML value plus its origin (file and key path, e.g. "modules[0].config"); every
// getter validates kind and range and throws ConfigError in the one format
// "FILE:LINE:COL: KEY.PATH: PROBLEM (value 'V', expected E)", so that a bad value is found without
// reading code. Unknown keys are errors too (rejectUnknown): a typo never silently falls back to a default.
#pragma once

#include "reflex/common/yaml_reader.hpp"

namespace reflex::modules {

/// Every set-up error of the behavior layer (configuration, unknown module, robot links).
using ConfigError = common::ConfigError;
using ConfigNode = common::ConfigNode;
using common::yamlText;

}  // namespace reflex::modules
