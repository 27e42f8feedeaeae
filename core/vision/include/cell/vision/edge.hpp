#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <opencv2/core.hpp>

#include "cell/common/result.hpp"

/// Edge measurement for RAPT's LOOK (digest 003 §2.3, §5): the window suggester proposes a
/// search window around a predicted image edge; the edge finder measures the edge in it.
///
/// Pixels (u, v) as everywhere in the cell: u to the right, v down, (0, 0) the centre of the
/// top-left pixel.
namespace cell::vision {

/// A search window: a rectangle given by three vertices, p1 -> p2 the short side across the
/// edge, p1 -> p3 the long side along it (the fourth vertex is p2 + p3 - p1).
struct EdgeWindow {
  Eigen::Vector2d p1 = Eigen::Vector2d::Zero();
  Eigen::Vector2d p2 = Eigen::Vector2d::Zero();
  Eigen::Vector2d p3 = Eigen::Vector2d::Zero();
  double half_width_px = 0.0;  ///< half of the short side: the tolerance across the edge
  /// True when both ends were cut back by the tolerance (part of the edge is then inside the
  /// window whatever the error within the tolerance); false when the edge is shorter than
  /// twice the tolerance and the window is the middle of the predicted edge only.
  bool guaranteed = true;
  bool clipped = false;  ///< shortened to keep the whole cross-section inside the image

  Eigen::Vector2d p4() const { return p2 + p3 - p1; }
  /// Unit vector along the edge (p1 -> p3) and across it (p1 -> p2).
  Eigen::Vector2d along() const;
  Eigen::Vector2d across() const;
  double length_px() const { return (p3 - p1).norm(); }
};

/// The window suggester for a predicted edge `start` -> `end` [px] and a tolerance
/// `tolerance_px` (how far the real edge may lie from the prediction, the RAPT tolerance
/// projected into the image): the short side spans +-tolerance across the edge, the long side
/// the predicted edge shortened by the tolerance at both ends (digest 003 §2.3: "sized so that
/// part of the edge is guaranteed to fall inside it"); then it is clipped to the image so that
/// its whole cross-section stays inside, at least `min_length_px` long.
/// Errors (kInvalidArgument): non-finite input, coincident end points, a tolerance not > 0;
/// (kOutOfRange): the edge entirely outside the image, or no part of the window with its whole
/// cross-section inside it ("abolished": a long side lies outside).
Result<EdgeWindow> suggest_window(const Eigen::Vector2d& start,
                                  const Eigen::Vector2d& end,
                                  double tolerance_px,
                                  int width_px,
                                  int height_px,
                                  double min_length_px = 6.0);

/// Wong's high-pass weight (digest 003 eq. 5.7) of pixel (u, v) on a 3 x 3 window with top row
/// a b c, middle g i h, bottom d e f: |a + b + c - d - e - f| + |c + h + f - a - g - d|.
/// Precondition: 1 <= u < cols - 1, 1 <= v < rows - 1 (a CV_8UC1 image).
int wong_weight(const cv::Mat& image, int u, int v) noexcept;

/// Options of the edge finder.
struct EdgeFinderOptions {
  /// A candidate end point's weight must reach this fraction of the window's largest weight
  /// and at least `min_weight` (on a 0..255 image a clean step of contrast C weighs 3C).
  double weight_fraction = 0.35;
  int min_weight = 60;
  /// How far inward from each short side candidates are looked for [px].
  double end_search_px = 4.0;
  /// Half-width of the cross profiles the sub-pixel refinement reads [px].
  int profile_half_px = 4;
  /// Edge points further than this from the first line fit are dropped before the final fit.
  double outlier_px = 1.0;

  /// Ok, or kInvalidArgument naming the option.
  Status validate() const;
};

/// A measured edge.
struct EdgeMeasurement {
  Eigen::Vector2d start_px = Eigen::Vector2d::Zero();  ///< end points of the measured segment
  Eigen::Vector2d end_px = Eigen::Vector2d::Zero();    ///< (ordered as the prediction's)
  double residual_px = 0.0;  ///< RMS distance of the edge points from the fitted line
  int point_count = 0;       ///< edge points in the final fit
  double mean_weight = 0.0;  ///< average Wong weight along the chosen pair
};

/// The edge finder (digest 003 §2.3, after the thesis's Vision Box program, with a sub-pixel
/// stage the 8080 did not have): weights every window pixel with wong_weight; searches inward
/// from the two short sides for candidate end points (weights above the threshold, local
/// maxima across the edge); picks the pair whose connecting pixels have the heaviest average
/// weight; then, every pixel along that pair, locates the edge across it to a fraction of a
/// pixel (the area under the grey profile between its bright and dark plateaus) and fits a
/// line (least squares, one pass of outlier removal). The end points returned are those of
/// the edge points' extent along the fitted line.
/// Errors (kInvalidArgument): an image that is not a non-empty CV_8UC1, bad options;
/// (kOutOfRange): no edge in the window ("no candidate end point within 4 px of the window's
/// start"), too few edge points to fit (fewer than 4).
Result<EdgeMeasurement> find_edge(const cv::Mat& image,
                                  const EdgeWindow& window,
                                  const EdgeFinderOptions& options = {});

}  // namespace cell::vision
