#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "cell/common/result.hpp"
#include "cell/vision/classes.hpp"

/// The AVRS thesis's recognition algorithm (digest 000 §3; Bloch 1994 §2.1, §4.6-§4.8 and the
/// printed pat_rec.c / rec_corner.c), kept as the reference pipeline: faithful enough to
/// reproduce its behaviour, including its integer arithmetic, its grouping distance (parts
/// closer than epsilon merge) and its cost growing with the number of objects.
///
/// Where text and code differ we follow the code (it is what ran), and say so:
/// - epsilon <= 20 px (text 18), look-back of the last 66 pixels (132 ints; comments say 34
///   or 43), no row subsampling delta (text 4);
/// - skeleton merge when a pixel of one group lies within 20 px of one of the first 11 pixels
///   of the other (the loop bound `(p[i][1]-p[i][0]) > 20` ints; text "first 20 pixels");
/// - groups with 11 skeleton pixels or fewer are dirt (`p[3]-p[0] > 20` ints kept);
/// - corners: four passes for the farthest skeleton point from the box centre, strictly
///   farther, rejected if within 14 px of a corner already found (text: r = 1/2..2/3 width);
/// - parallax with the code's floor(x + (x0 - x) h / D + 0.5), the OCR's "+" read as "*";
/// - corner order of eq. 4.16 (the code's `t_l_m = i` slip corrected to what it means);
/// - only rows 1..480 are read (row 0 skipped, the frame buffer's 4 pages of rows 0-480);
/// - at most 30 partial groups and 20 objects; the code's unchecked buffers (10 KB per group,
///   60 KB of pixels) are not reproduced: we never overflow, we report what the thesis lost.
/// The shape tests for circles, squares and triangles are Chapter 2's theory (not in the
/// printed code): eq. 2.14-2.16 and the triangle search of eq. 2.17-2.20. We read eq. 2.14's
/// "r = 1/3 of the width of the rectangle" as the external rectangle's, and add one test: a
/// circle's external rectangle is a square (the skeleton keeps only row ends, so a rectangle
/// near 0 degrees would otherwise pass eq. 2.14 on its short sides alone).
namespace cell::vision {

/// The thesis pipeline's constants (defaults: the printed code).
struct ThesisOptions {
  int threshold = 150;              ///< a pixel is an object pixel when its grey < threshold
  double epsilon_px = 20.0;         ///< grouping and merge distance (<=)
  int lookback_px = 66;             ///< recent pixels of a group checked when the last is far
  int merge_prefix_px = 11;         ///< first skeleton pixels of a group checked when merging
  int min_skeleton_px = 12;         ///< smaller skeleton groups are dirt
  int max_groups = 30;              ///< partial groups (p[30][5])
  int max_objects = 20;             ///< objects kept (fp[20][5])
  double corner_exclusion_px = 14;  ///< r of Algorithm 2.1 (code: rejected when <= 14)
  int first_row = 1;                ///< rows first_row..last_row are read
  int last_row = 480;
  /// Parallax (eq. 2.21): image centre, height of the part faces and of the camera [mm]. The
  /// code uses 8.5 mm (text 8) for its ICs; ours are 3.81 mm tall (core/world's DIPs).
  Eigen::Vector2i centre_px{255, 241};
  double part_height_mm = 3.81;
  double camera_height_mm = 420.0;
  /// The aspect factor of eq. 2.12, the code's c_y/c_x in mm/px (3.56/3.48 px/mm).
  double aspect = 3.56 / 3.48;
  /// Shape tests (Chapter 2): relative spread of the five radii below which a blob is a circle
  /// (eq. 2.14), relative difference of the sides below which it is a square (eq. 2.16), of
  /// opposite sides above which it is not a rectangle (eq. 2.13, discarded), and the distance of
  /// the triangle check point from a side within which it lies "on" it [px].
  double circle_spread = 0.06;
  double square_tolerance = 0.08;
  double rectangle_tolerance = 0.15;
  double triangle_line_px = 2.5;
  double triangle_corner_px = 3.0;  ///< "close to zero": a skeleton point at a box corner
  bool shape_tests = true;          ///< false: every object is a rectangle (the printed code)

  /// Ok, or kInvalidArgument naming the option.
  Status validate() const;
};

/// A pixel (i, j) = (column, row), as the thesis stores them.
using ThesisPixel = Eigen::Vector2i;

/// One object found by the thesis pipeline.
struct ThesisObject {
  ShapeKind shape = ShapeKind::kRectangle;
  int skeleton_px = 0;            ///< skeleton pixels of its group
  Eigen::Vector2i box_min{0, 0};  ///< external rectangle (eq. 2.3-2.6)
  Eigen::Vector2i box_max{0, 0};
  Eigen::Vector2i box_centre{0, 0};  ///< eq. 2.8, integer division
  /// Corners as found on the skeleton (rectangles: 4, in eq. 4.16 order after correction;
  /// triangles: 3), before and after the parallax correction, integers.
  std::vector<ThesisPixel> corners_raw;
  std::vector<ThesisPixel> corners;
  /// The centre (eq. 2.11): mean of the corrected corners, integer division: the table point
  /// under the part's centre, which the thesis maps to the robot.
  Eigen::Vector2i centre{0, 0};
  /// The same mean of the uncorrected corners: where the top face's centre is in the image.
  Eigen::Vector2i centre_raw{0, 0};
  double alpha_deg = 0.0;  ///< eq. 2.12 (rectangles and squares); 0 otherwise
  double radius_px = 0.0;  ///< circles: the mean of the five radii
};

/// What happened in one run (the thesis printed n, n_ics and fn_ics).
struct ThesisReport {
  int object_pixels = 0;    ///< n / 2
  int partial_groups = 0;   ///< n_ics
  int dropped_pixels = 0;   ///< pixels that needed a 31st group (the code overflowed here)
  int dirt_groups = 0;      ///< skeleton groups of min_skeleton_px - 1 pixels or fewer
  int not_rectangles = 0;   ///< discarded by eq. 2.13
  int dropped_objects = 0;  ///< beyond max_objects
};

/// The whole pipeline on a CV_8UC1 image. Errors: kInvalidArgument for another image type or
/// bad options.
Result<std::vector<ThesisObject>> thesis_locate(const cv::Mat& image,
                                                const ThesisOptions& options,
                                                ThesisReport* report = nullptr);

// ---- the stages, exposed for tests ----

/// Object pixels in raster order (rows first_row..last_row, columns left to right).
std::vector<ThesisPixel> thesis_object_pixels(const cv::Mat& image, const ThesisOptions& options);

/// Grouping into partial groups (digest 000 §3 steps 1-4, the code's look-back). Each group
/// holds its pixels in arrival order.
std::vector<std::vector<ThesisPixel>> thesis_group(const std::vector<ThesisPixel>& pixels,
                                                   const ThesisOptions& options,
                                                   int* dropped_pixels = nullptr);

/// The skeleton of a group: the first and last pixel of each row of the group (pixels that
/// start or end a run of equal rows in the group's list).
std::vector<ThesisPixel> thesis_skeleton(const std::vector<ThesisPixel>& group);

/// Merges skeleton groups (in place; merged groups become empty) and drops dirt; returns the
/// objects' skeletons in group order, at most max_objects.
std::vector<std::vector<ThesisPixel>> thesis_merge(std::vector<std::vector<ThesisPixel>> skeletons,
                                                   const ThesisOptions& options,
                                                   ThesisReport* report = nullptr);

/// Algorithm 2.1: `count` farthest skeleton points from `centre`, each strictly farther than
/// the previous candidates and more than `exclusion_px` from the corners already found.
std::vector<ThesisPixel> thesis_farthest_points(const std::vector<ThesisPixel>& skeleton,
                                                const Eigen::Vector2i& centre,
                                                int count,
                                                double exclusion_px);

/// Eq. 4.16 order: slot 0 the corner of largest row j, slot 3 the farthest from it, slot 2 the
/// nearest, slot 1 the remaining one (along the long side from slot 0).
std::array<ThesisPixel, 4> thesis_order_corners(const std::vector<ThesisPixel>& corners);

/// Eq. 2.17-2.20: the triangle test on a skeleton with external box [box_min, box_max]; the
/// three corners when the skeleton is a triangle.
std::optional<std::array<ThesisPixel, 3>> thesis_triangle(const std::vector<ThesisPixel>& skeleton,
                                                          const Eigen::Vector2i& box_min,
                                                          const Eigen::Vector2i& box_max,
                                                          const ThesisOptions& options);

}  // namespace cell::vision
