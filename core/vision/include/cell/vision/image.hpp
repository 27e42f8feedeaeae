#pragma once

#include <cstdint>
#include <opencv2/core.hpp>
#include <span>
#include <string>
#include <string_view>

#include "cell/common/result.hpp"

/// Getting a grey image vision can trust: from a bus sample's raw fields or from a file, with
/// every malformation named instead of crashing (wrong size, wrong encoding, truncated data,
/// an empty or non-image file).
namespace cell::vision {

/// Largest image side accepted [px] (as render::CameraModel).
inline constexpr int kMaxImageSide = 16384;

/// A continuous CV_8UC1 copy of raw image data as the `Image` topic carries it: `encoding`
/// "mono8" (1 byte per pixel) or "rgb8" (3, converted to grey with OpenCV's weights), rows
/// `step_bytes` apart (>= width * bytes per pixel). Errors (kInvalidArgument, naming the
/// field, expected and actual values): a side of 0 or above kMaxImageSide, an unknown
/// encoding, a step too small for the width, data shorter than (height - 1) * step + width *
/// bytes per pixel ("truncated: 1000 of 247808 bytes").
Result<cv::Mat> image_from_raw(std::uint32_t width_px,
                               std::uint32_t height_px,
                               std::uint32_t step_bytes,
                               std::string_view encoding,
                               std::span<const std::uint8_t> data);

/// Decodes an image file's bytes (PNG, JPEG, BMP, PGM/PPM, TIFF) to CV_8UC1 (colour converted
/// to grey, 16-bit scaled to 8). Errors (kInvalidArgument, `origin` naming the file): empty
/// data, an unrecognised format ("not an image"), a truncated file (PNG without its IEND
/// chunk, JPEG without its end marker, or any file the decoder cannot finish), an image of
/// zero size.
Result<cv::Mat> decode_image(std::span<const std::uint8_t> bytes, const std::string& origin);

/// Reads and decodes a file (decode_image). Errors: kIo when it cannot be read (naming the
/// path and the system's reason), or decode_image's errors.
Result<cv::Mat> load_image_file(const std::string& path);

}  // namespace cell::vision
