#include "cell/vision/image.hpp"

#include <fmt/format.h>

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <vector>

#include "support.hpp"

namespace cell::vision {
namespace {

using detail::invalid;

enum class Format { kUnknown, kPng, kJpeg, kBmp, kPnm, kTiff };

Format sniff(std::span<const std::uint8_t> b) {
  auto starts = [&](std::initializer_list<std::uint8_t> magic) {
    if (b.size() < magic.size()) {
      return false;
    }
    std::size_t i = 0;
    for (std::uint8_t m : magic) {
      if (b[i++] != m) {
        return false;
      }
    }
    return true;
  };
  if (starts({0x89, 'P', 'N', 'G', 0x0D, 0x0A, 0x1A, 0x0A})) {
    return Format::kPng;
  }
  if (starts({0xFF, 0xD8, 0xFF})) {
    return Format::kJpeg;
  }
  if (starts({'B', 'M'})) {
    return Format::kBmp;
  }
  if (b.size() >= 2 && b[0] == 'P' && b[1] >= '1' && b[1] <= '6') {
    return Format::kPnm;
  }
  if (starts({'I', 'I', 0x2A, 0x00}) || starts({'M', 'M', 0x00, 0x2A})) {
    return Format::kTiff;
  }
  return Format::kUnknown;
}

/// A PNG ends with an IEND chunk; libpng decodes a truncated file partially with a warning.
bool png_complete(std::span<const std::uint8_t> b) {
  static constexpr std::uint8_t kIend[] = {'I', 'E', 'N', 'D', 0xAE, 0x42, 0x60, 0x82};
  if (b.size() < 20) {
    return false;
  }
  for (std::size_t i = 0; i < 8; ++i) {
    if (b[b.size() - 8 + i] != kIend[i]) {
      return false;
    }
  }
  return true;
}

/// A JPEG ends with the EOI marker (libjpeg pads a truncated file with grey and warns).
bool jpeg_complete(std::span<const std::uint8_t> b) {
  // Trailing padding after EOI is allowed by some writers: look at the last 64 bytes.
  const std::size_t from = b.size() > 64 ? b.size() - 64 : 0;
  for (std::size_t i = b.size(); i-- > from + 1;) {
    if (b[i - 1] == 0xFF && b[i] == 0xD9) {
      return true;
    }
  }
  return false;
}

}  // namespace

Result<cv::Mat> image_from_raw(std::uint32_t width_px,
                               std::uint32_t height_px,
                               std::uint32_t step_bytes,
                               std::string_view encoding,
                               std::span<const std::uint8_t> data) {
  if (width_px == 0 || height_px == 0 || width_px > kMaxImageSide || height_px > kMaxImageSide) {
    return invalid(
        fmt::format("image size {} x {} px is not in 1..{}", width_px, height_px, kMaxImageSide));
  }
  std::size_t bpp = 0;
  if (encoding == "mono8") {
    bpp = 1;
  } else if (encoding == "rgb8") {
    bpp = 3;
  } else {
    return invalid(fmt::format("image encoding '{}' is not supported (mono8 or rgb8)", encoding));
  }
  const std::size_t row = static_cast<std::size_t>(width_px) * bpp;
  if (step_bytes < row) {
    return invalid(fmt::format("image step {} bytes is less than a {} row's {} bytes", step_bytes,
                               encoding, row));
  }
  const std::size_t needed = static_cast<std::size_t>(height_px - 1) * step_bytes + row;
  if (data.size() < needed) {
    return invalid(fmt::format("image data truncated: {} of {} bytes for {} x {} {} (step {})",
                               data.size(), needed, width_px, height_px, encoding, step_bytes));
  }
  const int w = static_cast<int>(width_px);
  const int h = static_cast<int>(height_px);
  cv::Mat out(h, w, CV_8UC1);
  if (bpp == 1) {
    for (int y = 0; y < h; ++y) {
      std::memcpy(out.ptr(y), data.data() + static_cast<std::size_t>(y) * step_bytes, row);
    }
  } else {
    const cv::Mat rgb(h, w, CV_8UC3, const_cast<std::uint8_t*>(data.data()), step_bytes);
    cv::cvtColor(rgb, out, cv::COLOR_RGB2GRAY);
  }
  return out;
}

Result<cv::Mat> decode_image(std::span<const std::uint8_t> bytes, const std::string& origin) {
  if (bytes.empty()) {
    return invalid(fmt::format("{}: empty file (0 bytes), not an image", origin));
  }
  const Format format = sniff(bytes);
  if (format == Format::kUnknown) {
    return invalid(
        fmt::format("{}: not an image (no PNG, JPEG, BMP, PGM/PPM or TIFF signature "
                    "in its first bytes)",
                    origin));
  }
  if (format == Format::kPng && !png_complete(bytes)) {
    return invalid(fmt::format("{}: truncated PNG ({} bytes, no IEND chunk at the end)", origin,
                               bytes.size()));
  }
  if (format == Format::kJpeg && !jpeg_complete(bytes)) {
    return invalid(
        fmt::format("{}: truncated JPEG ({} bytes, no end-of-image marker)", origin, bytes.size()));
  }
  cv::Mat decoded;
  try {
    const cv::Mat buffer(1, static_cast<int>(bytes.size()), CV_8UC1,
                         const_cast<std::uint8_t*>(bytes.data()));
    decoded = cv::imdecode(buffer, cv::IMREAD_ANYDEPTH | cv::IMREAD_ANYCOLOR);
  } catch (const cv::Exception& e) {
    return invalid(fmt::format("{}: cannot be decoded: {}", origin, e.what()));
  }
  if (decoded.empty()) {
    return invalid(fmt::format("{}: cannot be decoded (truncated or corrupt, {} bytes)", origin,
                               bytes.size()));
  }
  if (decoded.rows == 0 || decoded.cols == 0 || decoded.rows > kMaxImageSide ||
      decoded.cols > kMaxImageSide) {
    return invalid(fmt::format("{}: image size {} x {} px is not in 1..{}", origin, decoded.cols,
                               decoded.rows, kMaxImageSide));
  }
  cv::Mat grey;
  try {
    if (decoded.channels() == 3) {
      cv::cvtColor(decoded, grey, cv::COLOR_BGR2GRAY);
    } else if (decoded.channels() == 4) {
      cv::cvtColor(decoded, grey, cv::COLOR_BGRA2GRAY);
    } else {
      grey = decoded;
    }
    if (grey.depth() == CV_16U) {
      grey.convertTo(grey, CV_8U, 1.0 / 257.0);
    } else if (grey.depth() != CV_8U) {
      return invalid(
          fmt::format("{}: unsupported pixel depth (8 or 16 bit grey or colour)", origin));
    }
  } catch (const cv::Exception& e) {
    return invalid(fmt::format("{}: cannot be converted to grey: {}", origin, e.what()));
  }
  return grey.isContinuous() ? grey : grey.clone();
}

Result<cv::Mat> load_image_file(const std::string& path) {
  std::error_code ec;
  if (std::filesystem::is_directory(path, ec)) {
    return Error{Errc::kIo, fmt::format("{}: is a directory, not an image file", path)};
  }
  std::ifstream in(path, std::ios::binary);
  if (!in) {
    return Error{Errc::kIo, fmt::format("{}: cannot open: {}", path, std::strerror(errno))};
  }
  std::vector<std::uint8_t> bytes((std::istreambuf_iterator<char>(in)),
                                  std::istreambuf_iterator<char>());
  if (in.bad()) {
    return Error{Errc::kIo, fmt::format("{}: read failed: {}", path, std::strerror(errno))};
  }
  return decode_image(bytes, path);
}

}  // namespace cell::vision
