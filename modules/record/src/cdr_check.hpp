// A check of a recorded sample's XCDR1 lengths against its IDL type, before the type support decodes
// it. fastcdr sizes a sequence from the count it reads (vector::resize) and only requires one byte
// per element to be left, so a JointState payload whose name count claims 16 M strings made 16 M
// std::string objects (512 MB) before failing. Here every sequence count and string length is
// compared with the bytes actually left -- a count must fit remaining / (smallest encoding of one
// element): 4 bytes for a string, the struct's fields for a struct -- and every sequence with its
// IDL bound (`sequence<string, 64>`: part of the type, idl/README.md), without allocating. The types
// come from the IDL text of the MCAP schemas (idl_schemas.hpp), so they follow idl/*.idl.
//
// Supported IDL: modules, structs, enums, the integer / floating / boolean / char / octet types,
// string, sequence<T> and sequence<T, N>, fixed arrays, @annotations. A type using anything else
// (unions, typedefs, long double, ...) is not checked ("" for it): the type support alone decides.
// Private to modules/record.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>

namespace reflex::record {

/// "" if the lengths in `bytes` (the 4-byte encapsulation header first) fit: every string length and
/// sequence count of a sample of `type_name` ("reflex::msg::JointState") within the bytes left and
/// every sequence within its IDL bound. Else the first problem, naming the field and its byte offset
/// in the payload: "names: 16777216 elements claimed, sequence<string, 64>". An unknown type, or an
/// encapsulation other than plain CDR (LE / BE), gives "" (not checked here). Never allocates more
/// than the schema tables (built once); never throws.
std::string cdrLengthProblem(const std::string& type_name, const std::uint8_t* bytes, std::size_t size) noexcept;

}  // namespace reflex::record
