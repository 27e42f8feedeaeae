#pragma once

#include <optional>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

/// Sub-pixel measurements on rendered images, independent of the renderer's internals: they
/// read only pixel values. Used to check that what the renderer draws sits where the camera
/// model says.
namespace cell::render::testing {

/// A straight line through `point` along unit `direction` [px].
struct Line2 {
  Eigen::Vector2d point;
  Eigen::Vector2d direction;
};

/// Fits the edge of a dark region against a bright one near the predicted segment p0 -> p1
/// (pixels), the dark side being toward `inside` (a point inside the dark region). Per pixel
/// row (or column, for edges closer to horizontal) crossing the middle 70 % of the segment, the
/// edge position is found by the area method: with exact-coverage anti-aliasing a pixel's value
/// is linear in the dark fraction it holds, so within a window across the edge the dark length
/// is the sum of the fractions (B - I) / (B - D), B and D read at the window's bright and dark
/// ends. A least-squares line through these positions is returned; nullopt when fewer than 5
/// rows were usable.
std::optional<Line2> fit_edge(const cv::Mat& image, const Eigen::Vector2d& p0,
                              const Eigen::Vector2d& p1, const Eigen::Vector2d& inside,
                              int half_window = 4);

/// Intersection of two lines (they must not be parallel).
Eigen::Vector2d intersect(const Line2& a, const Line2& b);

/// Corners of a dark convex polygon measured from the image: each edge fitted with fit_edge
/// near the predicted corners `predicted` (in order), then adjacent edges intersected. Corner i
/// is the intersection of edges (i-1, i) and (i, i+1). Empty when an edge could not be fitted.
std::vector<Eigen::Vector2d> measure_polygon_corners(const cv::Mat& image,
                                                     const std::vector<Eigen::Vector2d>& predicted,
                                                     int half_window = 4);

/// Width [px] of a dark-to-bright ramp along image row `row` between columns [c0, c1): the
/// contrast (difference of the values at the two ends) over the ramp's slope, fitted by least
/// squares to the pixels between 20 % and 80 % of the contrast (or, when fewer than 3 are, the
/// steepest step between neighbours). A linear ramp of width d (an edge moving d px during the
/// exposure) gives d; a sharp edge gives 1 to 2, depending on where it falls in its pixel.
double ramp_width_px(const cv::Mat& image, int row, int c0, int c1);

}  // namespace cell::render::testing
