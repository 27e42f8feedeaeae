#pragma once

#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "cell/common/result.hpp"

/// Calibration targets and their detection in an image: a chessboard (OpenCV's inner-corner
/// pattern) or a ChArUco board (OpenCV contrib's aruco module, which Debian ships).
///
/// Board frame (the same as render::Chessboard's): origin at the outer corner of square (0, 0),
/// x along the columns, y along the rows, z out of the printed face; the printed face is z = 0.
/// A chessboard of `columns` x `rows` INNER corners has (columns + 1) x (rows + 1) squares;
/// square (i, j) is black when i + j is even, and inner corner (i, j), i = 0..columns-1,
/// j = 0..rows-1, lies at ((i + 1) s, (j + 1) s, 0) with s = square_mm. Corner ids are
/// i + columns * j (row by row, x fastest), the order render::chessboard_corners uses.
///
/// Pixels: u right, v down, (0, 0) at the centre of the top-left pixel (OpenCV's convention).
namespace cell::calibration {

enum class BoardKind : std::uint8_t { kChessboard, kCharuco };

/// A calibration target. Immutable value; validate() before use.
struct BoardSpec {
  BoardKind kind = BoardKind::kChessboard;
  int columns = 9;         ///< inner corners along x (chessboard: OpenCV pattern width)
  int rows = 6;            ///< inner corners along y
  double square_mm = 25.0;
  double marker_mm = 0.0;  ///< ChArUco only: marker side (< square_mm)
  std::string dictionary = "DICT_4X4_50";  ///< ChArUco only: an OpenCV predefined dictionary

  /// Ok, or kInvalidArgument naming the field: at least 2 x 2 inner corners (at most 64 per
  /// side), square_mm finite and > 0, for ChArUco a marker in (0, square_mm) and a known
  /// dictionary with enough markers for the board.
  Status validate() const;

  /// Inner corners in all.
  int corner_count() const noexcept { return columns * rows; }

  /// The inner corners in the board frame [mm], indexed by corner id.
  std::vector<Eigen::Vector3d> object_points() const;

  /// True when the board looks the same turned by 180 degrees (columns + rows even: the two
  /// colour parities coincide), so that a detection cannot tell its origin from the opposite
  /// corner. Such boards are fine for intrinsics; hand-eye needs an asymmetric one.
  bool is_symmetric() const noexcept;

  /// "chessboard 9x6 inner corners, 25 mm squares" (for messages and sources).
  std::string describe() const;
};

/// Parses "9x6" (inner corners, columns x rows) into `spec`. Errors: kInvalidArgument quoting
/// the text and the expected form.
Status parse_board_size(std::string_view text, BoardSpec& spec);

/// One detection: corner ids (into BoardSpec::object_points) and their sub-pixel positions.
struct BoardObservation {
  std::vector<int> ids;
  std::vector<Eigen::Vector2d> image_points;   ///< [px]
  std::vector<Eigen::Vector3d> object_points;  ///< [mm], board frame, same order
  int width_px = 0;   ///< size of the image it came from
  int height_px = 0;

  std::size_t size() const noexcept { return ids.size(); }
};

struct DetectOptions {
  /// cv::cornerSubPix half window [px]; 0 picks one from the detected square size (a third
  /// of the smallest square side in the image, in 2..11 px).
  int subpixel_half_window_px = 0;
  /// ChArUco: fewest interpolated corners that make a usable view.
  int min_charuco_corners = 6;
};

/// Finds `board` in an 8-bit grey image. Chessboard: cv::findChessboardCorners (adaptive
/// threshold, normalised), every inner corner required, then cv::cornerSubPix; the 180 degree
/// ambiguity of OpenCV's ordering is resolved by the colour of the first square when the board
/// is asymmetric (see is_symmetric). ChArUco: marker detection, corner interpolation and
/// sub-pixel refinement; a partial view is fine.
/// Errors: kInvalidArgument for an empty or non-8-bit image or a bad spec; kOutOfRange "no
/// <board> found" (or too few ChArUco corners). cv::Exception is converted, never thrown.
/// Thread-safe (no shared state).
Result<BoardObservation> detect_board(const cv::Mat& image, const BoardSpec& board,
                                      const DetectOptions& options = {});

}  // namespace cell::calibration
