// CRC-32 (IEEE 802.3 / zlib / MCAP: reflected polynomial 0xEDB88320, initial and final xor 0xFFFFFFFF),
// the project's one implementation: the .rfx and MCAP recordings, the controller's robot state file.
#pragma once

#include <cstddef>
#include <cstdint>

namespace reflex::common {

/// CRC-32 of `size` bytes, continuing from `crc` (the CRC of the bytes before; 0 to start).
/// crc32("123456789", 9) == 0xCBF43926. Table-driven, no allocation.
std::uint32_t crc32(const void* data, std::size_t size, std::uint32_t crc = 0) noexcept;

/// The CRC-32 of A followed by B from crc32(A), crc32(B) and |B|, without the bytes:
/// crc32Combine(crc32(A), crc32(B), |B|) == crc32(A || B). O(log |B|).
std::uint32_t crc32Combine(std::uint32_t crc_a, std::uint32_t crc_b, std::uint64_t size_b) noexcept;

}  // namespace reflex::common
