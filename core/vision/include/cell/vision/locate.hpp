#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <memory>
#include <opencv2/core.hpp>
#include <string>
#include <string_view>
#include <vector>

#include "cell/common/result.hpp"
#include "cell/vision/classes.hpp"
#include "cell/vision/grip.hpp"
#include "cell/vision/pixel_mapper.hpp"
#include "cell/vision/thesis.hpp"

/// Localisation of flat parts in grey images: dark parts (DIP ICs, rectangles, squares, discs,
/// triangles) on a bright table, with their class, centre, orientation, corners, size, a
/// quality figure, their pose in the robot's base frame and a clear-grip verdict.
///
/// Two pipelines:
/// - **fast** (production): threshold (fixed, or adaptive to the lighting gradient: a fraction
///   of a per-block background level), run-length components, and per component the boundary
///   located to a fraction of a pixel where the image crosses it along rows and columns (the
///   area between the bright and dark plateaus: exact for the area-sampling of a camera
///   pixel). Only crossings with clean table on one side and part body on the other are kept,
///   so IC leads, glints and neighbours do not bias the outline. The crossings are mapped to
///   the plane frame (pixel_mapper.hpp: undistortion, and parallax: a side whose wall faces the
///   camera is seen by its bottom edge, the others by the top face's edge) and fitted with the
///   shape's model: a rectangle (two pairs of parallel lines sharing one direction; trimmed
///   least squares), a circle, or a triangle. Blobs whose outline no single model explains are
///   split (a stricter threshold, then erosion) and the pieces flagged `touching`; what cannot
///   be split is reported as one `unknown` detection with quality 0, never silently merged.
/// - **thesis** (reference): the AVRS algorithm (thesis.hpp), its results turned into the same
///   Detection.
///
/// Conventions. Pixels (u, v): u right, v down, (0, 0) the centre of the top-left pixel, in the
/// image as taken (distorted). `center_px` is where the centre of the part's TOP face appears
/// (as render::PartTruth). Angles in the image: atan2(dv, du) of the part's major axis (a
/// triangle's first side), folded to its symmetry: [0, pi) rectangles, [0, pi/2) squares,
/// [0, 2 pi / 3) triangles, 0 circles. Sizes: length along the major axis, width across.
namespace cell::vision {

enum class Pipeline : std::uint8_t { kFast, kThesis };

/// "fast" / "thesis".
std::string_view to_string(Pipeline pipeline) noexcept;
/// Inverse of to_string. Errors: kInvalidArgument naming the text and the choices.
Result<Pipeline> pipeline_from_string(std::string_view text);

/// How dark pixels are told from the table.
enum class ThresholdMode : std::uint8_t {
  kFixed,     ///< grey < fixed_threshold (the thesis: 150)
  kAdaptive,  ///< grey < adaptive_ratio * the local table level (robust to lighting gradients)
};

/// "fixed" / "adaptive".
std::string_view to_string(ThresholdMode mode) noexcept;

struct SegmentationOptions {
  ThresholdMode mode = ThresholdMode::kAdaptive;
  int fixed_threshold = 150;
  /// Dark is below this fraction of the table level; the level is estimated per block of
  /// block_px x block_px from a sparse sample of its brightest pixels (so dark parts do not
  /// pull it down) and taken as the brightest of the 3 x 3 blocks around.
  double adaptive_ratio = 0.55;
  int block_px = 64;  ///< a power of two
  /// Blobs of fewer pixels are dirt, dropped (the thesis drops groups of <= 11 skeleton px).
  int min_area_px = 40;

  /// Ok, or kInvalidArgument naming the option and value.
  Status validate() const;
};

/// Options of the locator.
struct LocateOptions {
  Pipeline pipeline = Pipeline::kFast;
  SegmentationOptions segmentation;
  ThesisOptions thesis;
  /// Classes are matched by size when the mapping is metric: within max(class_tolerance_mm,
  /// class_tolerance_rel * size) on both length and width.
  ClassCatalogue classes = ClassCatalogue::standard();
  double class_tolerance_mm = 0.45;
  double class_tolerance_rel = 0.04;
  /// Heights assumed for the parallax before a class is known (and for parts matching none).
  double default_top_mm = 3.81;
  double default_base_mm = 0.51;
  /// Half-width of the sub-pixel crossing windows [px] (>= 2).
  int edge_window_px = 3;
  /// Outline crossings are measured on every n-th row and column (1: all). 2 halves the work
  /// for an accuracy still far below 0.1 px (an IC side keeps 15-50 crossings).
  int crossing_stride = 2;
  /// A fit whose RMS exceeds this, or that leaves much of the blob unexplained, is not one
  /// part: the blob is split or reported as touching parts [px].
  double max_fit_rms_px = 0.35;
  /// Blobs touching the image border are incomplete: left out (counted in the report).
  bool drop_border_parts = true;
  /// Grasp models for the clear-grip test, per class (none: every grip is not tested).
  std::vector<GraspModel> grasps;

  /// Ok, or kInvalidArgument naming the option and value (every nested option checked).
  Status validate() const;
};

/// A clear grasp style of a detection in the robot's base frame: where the tool goes and its
/// yaw there. The cell's parallel grippers close their fingers along the tool's y axis
/// (ClearGrasp in grip.hpp: tool yaw = grasp.angle - pi/2, tool point = G).
struct BaseGrasp {
  int style = -1;    ///< index of the style in the class's GraspModel::styles
  std::string name;  ///< its name ("across", "ends", ...)
  /// G and the tool yaw mapped by PixelMapper::to_base like Detection::base_pose: x, y [mm],
  /// rz [rad] as mapped, NOT folded to the part's symmetry (a picker adds symmetric copies).
  BasePose2 tool;
};

/// One part found in an image.
struct Detection {
  std::string class_name;  ///< catalogue class ("dip14") or, with no match, the shape name
  ShapeKind shape = ShapeKind::kRectangle;
  Eigen::Vector2d center_px = Eigen::Vector2d::Zero();  ///< top-face centre in the image
  double angle_rad = 0.0;                               ///< folded to the symmetry (above)
  std::vector<Eigen::Vector2d> corners_px;              ///< top face: 4 (3 triangles, 0 circles)
  double length_px = 0.0;
  double width_px = 0.0;
  /// Size in mm and pose in the plane frame (metric mappings only).
  bool metric = false;
  double length_mm = 0.0;
  double width_mm = 0.0;
  Eigen::Vector2d center_plane = Eigen::Vector2d::Zero();
  double angle_plane_rad = 0.0;
  /// Pose in the robot's base frame (PixelMapper::world() mappings only): x, y of the part's
  /// frame origin (footprint centre) and its major axis rz, folded to the symmetry about 0.
  bool has_base_pose = false;
  BasePose2 base_pose;
  double quality = 0.0;     ///< 0 (unreliable) .. 1: coverage of the outline, fit residual, class
  bool touching = false;    ///< split from a blob shared with other parts
  double fit_rms_px = 0.0;  ///< RMS distance of the edge samples from the fitted outline
  int edge_samples = 0;     ///< sub-pixel crossings in the final fit (fast pipeline)
  GripResult grip;          ///< its `clear` grasps are in the plane frame
  /// grip.clear in the robot's base frame, in style order: filled when the grip was tested,
  /// found clear styles and the detection has a base pose (else empty). A style whose grasp
  /// point the planar model cannot map (outside its quadrant) is left out.
  std::vector<BaseGrasp> base_grasps;
};

/// Per-frame figures.
struct LocateReport {
  Pipeline pipeline = Pipeline::kFast;
  std::string mapping;  ///< PixelMapper::describe()
  int blobs = 0;        ///< dark components above min_area_px
  int dirt = 0;         ///< components below it
  int at_border = 0;    ///< left out: touching the image border
  int split = 0;        ///< blobs separated into several parts
  int unresolved = 0;   ///< blobs reported as `unknown` (could not be explained)
  ThesisReport thesis;  ///< thesis pipeline only
};

struct LocateResult {
  std::vector<Detection> detections;
  LocateReport report;
};

/// The locator: options, plus scratch buffers reused across frames (a frame does not allocate
/// once warmed up, apart from its results). One thread at a time; one Locator per thread.
class Locator {
 public:
  /// Errors: kInvalidArgument from options.validate().
  static Result<Locator> create(LocateOptions options);

  Locator(Locator&&) noexcept;
  Locator& operator=(Locator&&) noexcept;
  ~Locator();

  const LocateOptions& options() const noexcept;

  /// Finds the parts in `image` (CV_8UC1, continuous or not) with the pipeline of the options,
  /// mapping with `mapper`. An image with no parts gives an empty list. Errors
  /// (kInvalidArgument): an empty image or another type, or an image whose size differs from the
  /// calibration's ("image is 640 x 480 px but the calibration of 'x' is for 512 x 484").
  Result<LocateResult> locate(const cv::Mat& image, const PixelMapper& mapper);

  /// As locate() with another pipeline than the options'.
  Result<LocateResult> locate(const cv::Mat& image, const PixelMapper& mapper, Pipeline pipeline);

 private:
  struct Impl;
  explicit Locator(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

/// Folds an angle to [0, 2 pi / order) (order 0: 0; order 1: (-pi, pi]).
double fold_angle(double angle_rad, int order) noexcept;

/// Folds to (-pi / order, pi / order] (order 0: 0; order 1: (-pi, pi]): for robot rotations.
double fold_angle_centred(double angle_rad, int order) noexcept;

/// The smallest difference between two angles of a shape of symmetry `order` [rad], >= 0.
double angle_error(double a_rad, double b_rad, int order) noexcept;

}  // namespace cell::vision
