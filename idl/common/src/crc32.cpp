#include "reflex/common/crc32.hpp"

#include <array>

namespace reflex::common {

namespace {

constexpr std::uint32_t kCrcPoly = 0xEDB88320u;  // reflected: bit 31 is x^0, bit 0 is x^31

constexpr std::array<std::uint32_t, 256> makeCrcTable() {
  std::array<std::uint32_t, 256> table{};
  for (std::uint32_t i = 0; i < 256; ++i) {
    std::uint32_t c = i;
    for (int k = 0; k < 8; ++k) c = (c & 1u) ? (kCrcPoly ^ (c >> 1)) : (c >> 1);
    table[i] = c;
  }
  return table;
}
constexpr std::array<std::uint32_t, 256> kCrcTable = makeCrcTable();

/// a * b modulo the CRC-32 polynomial, both in the reflected bit order of the CRC register.
std::uint32_t mulModCrcPoly(std::uint32_t a, std::uint32_t b) noexcept {
  std::uint32_t product = 0;
  for (int i = 0; i < 32; ++i) {  // b holds (original b) * x^i
    if (a & (0x80000000u >> i)) product ^= b;
    b = (b & 1u) ? (b >> 1) ^ kCrcPoly : (b >> 1);
  }
  return product;
}

/// x^(8 n) modulo the CRC-32 polynomial: the factor that moves a CRC register past n zero bytes.
std::uint32_t xPow8n(std::uint64_t n) noexcept {
  static const std::array<std::uint32_t, 64> x_pow_2k = [] {  // x^(2^k)
    std::array<std::uint32_t, 64> t{};
    t[0] = 0x40000000u;  // x^1
    for (std::size_t k = 1; k < t.size(); ++k) t[k] = mulModCrcPoly(t[k - 1], t[k - 1]);
    return t;
  }();
  std::uint32_t result = 0x80000000u;  // x^0
  std::uint64_t bits = n;
  for (std::size_t k = 3; bits != 0 && k < x_pow_2k.size(); ++k, bits >>= 1)  // 8 n = n << 3
    if (bits & 1u) result = mulModCrcPoly(result, x_pow_2k[k]);
  return result;
}

}  // namespace

std::uint32_t crc32(const void* data, std::size_t size, std::uint32_t crc) noexcept {
  const auto* p = static_cast<const std::uint8_t*>(data);
  crc = ~crc;
  for (std::size_t i = 0; i < size; ++i) crc = kCrcTable[(crc ^ p[i]) & 0xFFu] ^ (crc >> 8);
  return ~crc;
}

std::uint32_t crc32Combine(std::uint32_t crc_a, std::uint32_t crc_b, std::uint64_t size_b) noexcept {
  // CRC-32 is affine in the message: the register after A, carried through |B| more bytes, is
  // crc_a * x^(8|B|) mod P; the init / final inversions of A and B cancel in the XOR.
  return mulModCrcPoly(crc_a, xPow8n(size_b)) ^ crc_b;
}

}  // namespace reflex::common
