// The OMG IDL text of idl/*.idl for MCAP schemas, generated at build time into the build tree by
// cmake/idl_schemas.cmake (see there for what "self-contained" means).
#pragma once

#include <vector>

namespace reflex::record {

struct IdlSchemaFile {
  const char* file;                ///< e.g. "control.idl"
  std::vector<const char*> types;  ///< fully qualified struct names it declares, e.g. "reflex::msg::JointState"
  const char* text;                ///< its text with included files inlined and preprocessor lines removed
};

/// Every IDL file of idl/ (REFLEX_IDL_FILES), in that order.
const std::vector<IdlSchemaFile>& idlSchemaFiles();

}  // namespace reflex::record
