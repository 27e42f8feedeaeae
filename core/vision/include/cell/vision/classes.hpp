#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "cell/common/result.hpp"

/// Part classes as vision sees them: a shape seen from above and its size, plus the heights that
/// matter for parallax (the top face, and the lowest edge of the body's walls). Built from the
/// cell's part catalogue (core/world: the real DIP package sizes) and extended from config.
///
/// Units: mm. Heights are above the plane the part rests on (the calibration's working plane).
namespace cell::vision {

/// The outline family of a flat part seen from above.
enum class ShapeKind : std::uint8_t {
  kRectangle,  ///< rectangles and DIP IC bodies (2-fold symmetric)
  kSquare,     ///< 4-fold symmetric
  kCircle,     ///< discs (any rotation)
  kTriangle,   ///< equilateral triangles (3-fold symmetric)
  kUnknown,    ///< a blob that fits none of the above (or several parts that could not be split)
};

/// "rectangle", "square", "circle", "triangle", "unknown".
std::string_view to_string(ShapeKind shape) noexcept;

/// Rotational symmetry order of a shape: 2, 4, 0 (any rotation: circles), 3; 1 for kUnknown.
int symmetry_order(ShapeKind shape) noexcept;

/// One class vision can recognise.
struct PartSpec {
  std::string name;  ///< "dip14", "ic_7x30", "rectangle", ...
  ShapeKind shape = ShapeKind::kRectangle;
  /// Rectangle/square: body length and width (leads excluded); circle: diameter (both);
  /// triangle: side (length) and height (width).
  double length_mm = 0.0;
  double width_mm = 0.0;
  double top_mm = 0.0;  ///< height of the top face above the working plane
  double base_mm =
      0.0;       ///< height of the bottom edge of the walls (a DIP's standoff; 0 for prisms)
  int pins = 0;  ///< DIP lead count (informative; vision classifies by size)

  /// Ok, or kInvalidArgument naming the class and the field: sizes not finite and > 0, a
  /// square or circle with length != width, base_mm outside [0, top_mm).
  Status validate() const;
};

/// How a measured outline matched a class.
struct ClassMatch {
  const PartSpec* spec = nullptr;
  /// Largest size deviation over the tolerance, 0 (exact) .. 1 (at the tolerance).
  double score = 1.0;
};

/// The classes vision knows. Copyable; classify() is const and thread-safe.
class ClassCatalogue {
 public:
  /// Every flat class of core/world's standard catalogue (dip8 .. dip40, ic_6x19, ic_7x30,
  /// rectangle, square, disc, triangle; boxes and polyhedra are not flat parts and are left
  /// out), with their real sizes and heights.
  static ClassCatalogue standard();

  /// An empty catalogue (vision then reports shapes only).
  ClassCatalogue() = default;

  /// Adds a class (replacing one of the same name). Errors: kInvalidArgument from validate().
  Status add(PartSpec spec);

  /// The class whose size is nearest to (length_mm, width_mm) among those of `shape`, if it
  /// lies within the tolerance on both sizes: |d| <= max(tolerance_mm, tolerance_rel * size).
  /// Squares also match rectangles of equal sides and vice versa when the aspect is near 1.
  std::optional<ClassMatch> classify(ShapeKind shape,
                                     double length_mm,
                                     double width_mm,
                                     double tolerance_mm,
                                     double tolerance_rel) const;

  /// The class called `name`, or nullptr.
  const PartSpec* find(std::string_view name) const noexcept;

  const std::vector<PartSpec>& specs() const noexcept { return specs_; }
  bool empty() const noexcept { return specs_.empty(); }

 private:
  std::vector<PartSpec> specs_;
};

}  // namespace cell::vision
