// Reading an image file with a budget: the size in its header is checked BEFORE OpenCV decodes it
// (a 431 KB PNG of 20000 x 20000 pixels decodes to 5 GB; a width of 32768 or more aborts OpenCV), and
// images too small for the tag detector are refused (libapriltag crashes on images 1-2 px high).
#pragma once

#include <opencv2/core.hpp>

#include <optional>
#include <string>

namespace reflex::vision {

inline constexpr int kMinImageSide = 16;                ///< px: smaller images cannot hold a tag
inline constexpr int kMaxImageSide = 16384;             ///< px per side
inline constexpr long long kMaxImagePixels = 50000000;  ///< width x height

/// The width and height a PNG, JPEG or BMP file states in its header (nullopt for other formats or
/// a header this cannot read; then the decoded image is checked instead).
std::optional<cv::Size> imageFileHeaderSize(const std::string& path);

/// "" when width x height is within the limits above, else why not (naming `what` and the size).
std::string imageSizeProblem(const std::string& what, const cv::Size& size);

/// cv::imread(path, flags) after the header check, then the decoded size checked too. Throws
/// VisionError naming the file: not a regular file, beyond the budget, not decodable.
cv::Mat readImageWithinBudget(const std::string& path, int flags);

}  // namespace reflex::vision
