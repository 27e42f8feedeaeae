#include "cell/calibration/board.hpp"

#include <algorithm>
#include <array>
#include <charconv>
#include <cmath>
#include <utility>

#include <fmt/format.h>
#include <opencv2/aruco/charuco.hpp>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

namespace cell::calibration {
namespace {

constexpr std::array<std::pair<std::string_view, int>, 16> kDictionaries = {{
    {"DICT_4X4_50", cv::aruco::DICT_4X4_50},
    {"DICT_4X4_100", cv::aruco::DICT_4X4_100},
    {"DICT_4X4_250", cv::aruco::DICT_4X4_250},
    {"DICT_4X4_1000", cv::aruco::DICT_4X4_1000},
    {"DICT_5X5_50", cv::aruco::DICT_5X5_50},
    {"DICT_5X5_100", cv::aruco::DICT_5X5_100},
    {"DICT_5X5_250", cv::aruco::DICT_5X5_250},
    {"DICT_5X5_1000", cv::aruco::DICT_5X5_1000},
    {"DICT_6X6_50", cv::aruco::DICT_6X6_50},
    {"DICT_6X6_100", cv::aruco::DICT_6X6_100},
    {"DICT_6X6_250", cv::aruco::DICT_6X6_250},
    {"DICT_6X6_1000", cv::aruco::DICT_6X6_1000},
    {"DICT_7X7_50", cv::aruco::DICT_7X7_50},
    {"DICT_7X7_100", cv::aruco::DICT_7X7_100},
    {"DICT_7X7_250", cv::aruco::DICT_7X7_250},
    {"DICT_7X7_1000", cv::aruco::DICT_7X7_1000},
}};

/// Markers in a dictionary: the number after the last underscore.
int dictionary_size(std::string_view name) {
  const auto pos = name.rfind('_');
  int n = 0;
  std::from_chars(name.data() + pos + 1, name.data() + name.size(), n);
  return n;
}

int dictionary_id(std::string_view name) {
  for (const auto& [n, id] : kDictionaries) {
    if (n == name) {
      return id;
    }
  }
  return -1;
}

/// Mean grey inside the quadrilateral of four corners (shrunk to its middle half, so that the
/// sample stays inside the square whatever the lens does near its edges).
double quad_mean(const cv::Mat& image, const std::array<cv::Point2f, 4>& quad) {
  cv::Point2f centre(0.0F, 0.0F);
  for (const auto& p : quad) {
    centre += p * 0.25F;
  }
  std::array<cv::Point, 4> inner;
  for (std::size_t i = 0; i < 4; ++i) {
    const cv::Point2f p = centre + (quad[i] - centre) * 0.5F;
    inner[i] = cv::Point(static_cast<int>(std::lround(p.x)), static_cast<int>(std::lround(p.y)));
  }
  cv::Mat mask = cv::Mat::zeros(image.size(), CV_8UC1);
  cv::fillConvexPoly(mask, inner.data(), 4, cv::Scalar(255));
  return cv::mean(image, mask)[0];
}

int half_window(const std::vector<cv::Point2f>& corners, int columns, int rows,
                const DetectOptions& options) {
  if (options.subpixel_half_window_px > 0) {
    return options.subpixel_half_window_px;
  }
  auto corner = [&](int i, int j) -> const cv::Point2f& {
    return corners[static_cast<std::size_t>(i) +
                   static_cast<std::size_t>(columns) * static_cast<std::size_t>(j)];
  };
  double spacing = 1e9;
  for (int j = 0; j < rows; ++j) {
    for (int i = 0; i < columns; ++i) {
      const cv::Point2f& p = corner(i, j);
      if (i + 1 < columns) {
        spacing = std::min(spacing, cv::norm(corner(i + 1, j) - p));
      }
      if (j + 1 < rows) {
        spacing = std::min(spacing, cv::norm(corner(i, j + 1) - p));
      }
    }
  }
  return std::clamp(static_cast<int>(spacing * 0.4), 2, 11);
}

Result<BoardObservation> detect_chessboard(const cv::Mat& image, const BoardSpec& board,
                                           const DetectOptions& options) {
  const int c = board.columns;
  const int r = board.rows;
  std::vector<cv::Point2f> corners;
  const bool found = cv::findChessboardCorners(
      image, cv::Size(c, r), corners, cv::CALIB_CB_ADAPTIVE_THRESH | cv::CALIB_CB_NORMALIZE_IMAGE);
  if (!found || corners.size() != static_cast<std::size_t>(c) * static_cast<std::size_t>(r)) {
    return Error{Errc::kOutOfRange, fmt::format("no {} found", board.describe())};
  }
  const int w = half_window(corners, c, r, options);
  cv::cornerSubPix(image, corners, cv::Size(w, w), cv::Size(-1, -1),
                   cv::TermCriteria(cv::TermCriteria::EPS + cv::TermCriteria::COUNT, 60, 1e-5));
  auto at = [&](int i, int j) -> cv::Point2f& {
    return corners[static_cast<std::size_t>(i) +
                   static_cast<std::size_t>(c) * static_cast<std::size_t>(j)];
  };
  // Seen from its printed side, the board's x and y axes appear left-handed in (u, v) (its z
  // points back at the camera): a right-handed labelling is OpenCV's mirrored order.
  const cv::Point2f ex = at(1, 0) - at(0, 0);
  const cv::Point2f ey = at(0, 1) - at(0, 0);
  if (ex.x * ey.y - ex.y * ey.x > 0.0F) {
    for (int j = 0; j < r / 2; ++j) {
      for (int i = 0; i < c; ++i) {
        std::swap(at(i, j), at(i, r - 1 - j));
      }
    }
  }
  // 180 degrees: the square diagonal to corner 0 inside the pattern is square (1, 1), black.
  // Turned by 180 degrees it is square (c, r), white when c + r is odd.
  if (!board.is_symmetric()) {
    const double first = quad_mean(image, {at(0, 0), at(1, 0), at(1, 1), at(0, 1)});
    const double next = quad_mean(image, {at(1, 0), at(2 % c, 0), at(2 % c, 1), at(1, 1)});
    if (first > next) {
      std::reverse(corners.begin(), corners.end());
    }
  }
  BoardObservation obs;
  obs.width_px = image.cols;
  obs.height_px = image.rows;
  const std::vector<Eigen::Vector3d> points = board.object_points();
  for (int id = 0; id < c * r; ++id) {
    const cv::Point2f& p = corners[static_cast<std::size_t>(id)];
    obs.ids.push_back(id);
    obs.image_points.emplace_back(p.x, p.y);
    obs.object_points.push_back(points[static_cast<std::size_t>(id)]);
  }
  return obs;
}

Result<BoardObservation> detect_charuco(const cv::Mat& image, const BoardSpec& board,
                                        const DetectOptions& options) {
  const cv::Ptr<cv::aruco::Dictionary> dictionary =
      cv::aruco::getPredefinedDictionary(dictionary_id(board.dictionary));
  const cv::Ptr<cv::aruco::CharucoBoard> charuco = cv::aruco::CharucoBoard::create(
      board.columns + 1, board.rows + 1, static_cast<float>(board.square_mm),
      static_cast<float>(board.marker_mm), dictionary);
  cv::Ptr<cv::aruco::DetectorParameters> params = cv::aruco::DetectorParameters::create();
  params->cornerRefinementMethod = cv::aruco::CORNER_REFINE_SUBPIX;
  std::vector<std::vector<cv::Point2f>> marker_corners;
  std::vector<int> marker_ids;
  cv::aruco::detectMarkers(image, dictionary, marker_corners, marker_ids, params);
  if (marker_ids.empty()) {
    return Error{Errc::kOutOfRange, fmt::format("no {} found (no marker)", board.describe())};
  }
  std::vector<cv::Point2f> corners;
  std::vector<int> ids;
  cv::aruco::interpolateCornersCharuco(marker_corners, marker_ids, image, charuco, corners, ids);
  if (static_cast<int>(ids.size()) < options.min_charuco_corners) {
    return Error{Errc::kOutOfRange,
                 fmt::format("{}: only {} corners found, {} needed", board.describe(), ids.size(),
                             options.min_charuco_corners)};
  }
  const int w = options.subpixel_half_window_px > 0 ? options.subpixel_half_window_px : 3;
  cv::cornerSubPix(image, corners, cv::Size(w, w), cv::Size(-1, -1),
                   cv::TermCriteria(cv::TermCriteria::EPS + cv::TermCriteria::COUNT, 60, 1e-5));
  BoardObservation obs;
  obs.width_px = image.cols;
  obs.height_px = image.rows;
  for (std::size_t k = 0; k < ids.size(); ++k) {
    const int id = ids[k];
    if (id < 0 || id >= static_cast<int>(charuco->chessboardCorners.size())) {
      continue;
    }
    const cv::Point3f& q = charuco->chessboardCorners[static_cast<std::size_t>(id)];
    obs.ids.push_back(id);
    obs.image_points.emplace_back(corners[k].x, corners[k].y);
    obs.object_points.emplace_back(q.x, q.y, q.z);
  }
  return obs;
}

}  // namespace

Status BoardSpec::validate() const {
  if (columns < 2 || rows < 2 || columns > 64 || rows > 64) {
    return Error{Errc::kInvalidArgument,
                 fmt::format("board: {}x{} inner corners; each side needs 2..64", columns, rows)};
  }
  if (!std::isfinite(square_mm) || !(square_mm > 0.0)) {
    return Error{Errc::kInvalidArgument,
                 fmt::format("board: square_mm must be > 0, got {}", square_mm)};
  }
  if (kind == BoardKind::kCharuco) {
    if (!std::isfinite(marker_mm) || !(marker_mm > 0.0) || !(marker_mm < square_mm)) {
      return Error{Errc::kInvalidArgument,
                   fmt::format("board: a ChArUco marker_mm must be in (0, {}), got {}", square_mm,
                               marker_mm)};
    }
    if (dictionary_id(dictionary) < 0) {
      return Error{Errc::kInvalidArgument,
                   fmt::format("board: unknown ArUco dictionary '{}' (DICT_4X4_50 ... "
                               "DICT_7X7_1000)",
                               dictionary)};
    }
    const int markers = ((columns + 1) * (rows + 1)) / 2;
    if (markers > dictionary_size(dictionary)) {
      return Error{Errc::kInvalidArgument,
                   fmt::format("board: {}x{} ChArUco needs {} markers, {} has {}", columns, rows,
                               markers, dictionary, dictionary_size(dictionary))};
    }
  }
  return ok_status();
}

std::vector<Eigen::Vector3d> BoardSpec::object_points() const {
  std::vector<Eigen::Vector3d> points;
  points.reserve(static_cast<std::size_t>(corner_count()));
  for (int j = 0; j < rows; ++j) {
    for (int i = 0; i < columns; ++i) {
      points.emplace_back((i + 1) * square_mm, (j + 1) * square_mm, 0.0);
    }
  }
  return points;
}

bool BoardSpec::is_symmetric() const noexcept {
  return kind == BoardKind::kChessboard && (columns + rows) % 2 == 0;
}

std::string BoardSpec::describe() const {
  if (kind == BoardKind::kCharuco) {
    return fmt::format("ChArUco {}x{} inner corners, {} mm squares, {} mm {} markers", columns,
                       rows, square_mm, marker_mm, dictionary);
  }
  return fmt::format("chessboard {}x{} inner corners, {} mm squares", columns, rows, square_mm);
}

Status parse_board_size(std::string_view text, BoardSpec& spec) {
  const auto x = text.find_first_of("xX");
  int c = 0;
  int r = 0;
  bool ok = x != std::string_view::npos && x > 0 && x + 1 < text.size();
  if (ok) {
    const auto a = std::from_chars(text.data(), text.data() + x, c);
    const auto b = std::from_chars(text.data() + x + 1, text.data() + text.size(), r);
    ok = a.ec == std::errc() && a.ptr == text.data() + x && b.ec == std::errc() &&
         b.ptr == text.data() + text.size();
  }
  if (!ok) {
    return Error{Errc::kInvalidArgument,
                 fmt::format("board size '{}': expected COLUMNSxROWS of inner corners, e.g. 9x6",
                             text)};
  }
  spec.columns = c;
  spec.rows = r;
  return spec.validate();
}

Result<BoardObservation> detect_board(const cv::Mat& image, const BoardSpec& board,
                                      const DetectOptions& options) {
  CELL_TRY(board.validate());
  if (image.empty() || image.type() != CV_8UC1) {
    return Error{Errc::kInvalidArgument,
                 fmt::format("board detection needs an 8-bit grey image, got {} x {} of type {}",
                             image.cols, image.rows, image.type())};
  }
  try {
    return board.kind == BoardKind::kCharuco ? detect_charuco(image, board, options)
                                             : detect_chessboard(image, board, options);
  } catch (const cv::Exception& e) {
    return Error{Errc::kInvalidArgument, fmt::format("board detection: {}", e.what())};
  }
}

}  // namespace cell::calibration
