#include "reflex/vision/image_file.hpp"

#include "reflex/common/files.hpp"
#include "reflex/vision/error.hpp"

#include <opencv2/imgcodecs.hpp>

#include <array>
#include <cstdint>
#include <fstream>

namespace reflex::vision {
namespace {

std::uint32_t be32(const unsigned char* p) {
  return (std::uint32_t(p[0]) << 24) | (std::uint32_t(p[1]) << 16) | (std::uint32_t(p[2]) << 8) | p[3];
}
std::uint32_t le32(const unsigned char* p) {
  return (std::uint32_t(p[3]) << 24) | (std::uint32_t(p[2]) << 16) | (std::uint32_t(p[1]) << 8) | p[0];
}

}  // namespace

std::optional<cv::Size> imageFileHeaderSize(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::array<unsigned char, 32> h{};
  if (!in.read(reinterpret_cast<char*>(h.data()), 26) && in.gcount() < 26) return std::nullopt;
  // PNG: signature, then the IHDR chunk (width, height: big-endian 32-bit).
  static const unsigned char kPng[8] = {0x89, 'P', 'N', 'G', 0x0D, 0x0A, 0x1A, 0x0A};
  if (std::equal(kPng, kPng + 8, h.begin()) && h[12] == 'I' && h[13] == 'H' && h[14] == 'D' && h[15] == 'R') {
    const std::uint32_t w = be32(&h[16]), ht = be32(&h[20]);
    if (w > 0x7fffffffu || ht > 0x7fffffffu) return cv::Size(0x7fffffff, 0x7fffffff);
    return cv::Size(static_cast<int>(w), static_cast<int>(ht));
  }
  // BMP: "BM", the info header's width and height (little-endian, height negative when top-down).
  if (h[0] == 'B' && h[1] == 'M') {
    const auto w = static_cast<std::int32_t>(le32(&h[18]));
    const auto ht = static_cast<std::int32_t>(le32(&h[22]));
    const long long aw = w < 0 ? -static_cast<long long>(w) : w, ah = ht < 0 ? -static_cast<long long>(ht) : ht;
    return cv::Size(static_cast<int>(std::min<long long>(aw, 0x7fffffff)),
                    static_cast<int>(std::min<long long>(ah, 0x7fffffff)));
  }
  // JPEG: markers up to a start of frame (SOF0..SOF15 but DHT C4, JPG C8, DAC CC): height, width.
  if (h[0] == 0xFF && h[1] == 0xD8) {
    in.clear();
    in.seekg(2);
    for (int guard = 0; guard < 10000; ++guard) {
      unsigned char m[4];
      if (!in.read(reinterpret_cast<char*>(m), 4)) return std::nullopt;
      if (m[0] != 0xFF) return std::nullopt;
      const int marker = m[1];
      const int len = (m[2] << 8) | m[3];
      if (marker >= 0xC0 && marker <= 0xCF && marker != 0xC4 && marker != 0xC8 && marker != 0xCC) {
        unsigned char f[5];
        if (!in.read(reinterpret_cast<char*>(f), 5)) return std::nullopt;
        return cv::Size((f[3] << 8) | f[4], (f[1] << 8) | f[2]);
      }
      if (len < 2) return std::nullopt;
      in.seekg(len - 2, std::ios::cur);
    }
  }
  return std::nullopt;
}

std::string imageSizeProblem(const std::string& what, const cv::Size& size) {
  const std::string dims = std::to_string(size.width) + "x" + std::to_string(size.height);
  if (size.width < kMinImageSide || size.height < kMinImageSide)
    return what + " is " + dims + " px: smaller than " + std::to_string(kMinImageSide) +
           " px a side, too small to hold a tag";
  if (size.width > kMaxImageSide || size.height > kMaxImageSide ||
      static_cast<long long>(size.width) * size.height > kMaxImagePixels)
    return what + " is " + dims + " px: more than " + std::to_string(kMaxImageSide) + " px a side or " +
           std::to_string(kMaxImagePixels / 1000000) + " megapixels, refused before decoding";
  return "";
}

cv::Mat readImageWithinBudget(const std::string& path, int flags) {
  if (const std::string why = common::inputFileProblem(path); !why.empty()) throw VisionError("image " + why);
  if (const auto size = imageFileHeaderSize(path))
    if (const std::string why = imageSizeProblem("image '" + path + "'", *size); !why.empty()) throw VisionError(why);
  cv::Mat m = cv::imread(path, flags);
  if (m.empty()) throw VisionError("cannot read image '" + path + "' (not an image OpenCV can decode)");
  if (const std::string why = imageSizeProblem("image '" + path + "'", m.size()); !why.empty()) throw VisionError(why);
  return m;
}

}  // namespace reflex::vision
