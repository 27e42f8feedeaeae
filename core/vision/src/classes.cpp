#include "cell/vision/classes.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>

#include "cell/world/part_class.hpp"

namespace cell::vision {

std::string_view to_string(ShapeKind shape) noexcept {
  switch (shape) {
    case ShapeKind::kRectangle:
      return "rectangle";
    case ShapeKind::kSquare:
      return "square";
    case ShapeKind::kCircle:
      return "circle";
    case ShapeKind::kTriangle:
      return "triangle";
    case ShapeKind::kUnknown:
      return "unknown";
  }
  return "unknown";
}

int symmetry_order(ShapeKind shape) noexcept {
  switch (shape) {
    case ShapeKind::kRectangle:
      return 2;
    case ShapeKind::kSquare:
      return 4;
    case ShapeKind::kCircle:
      return 0;
    case ShapeKind::kTriangle:
      return 3;
    case ShapeKind::kUnknown:
      return 1;
  }
  return 1;
}

Status PartSpec::validate() const {
  auto bad = [&](const std::string& what) {
    return Error{Errc::kInvalidArgument, fmt::format("class '{}': {}", name, what)};
  };
  if (name.empty()) {
    return Error{Errc::kInvalidArgument, "a class needs a name"};
  }
  if (shape == ShapeKind::kUnknown) {
    return bad("shape must be rectangle, square, circle or triangle");
  }
  for (const auto& [key, v] : {std::pair{"length_mm", length_mm}, std::pair{"width_mm", width_mm},
                               std::pair{"top_mm", top_mm}}) {
    if (!(std::isfinite(v) && v > 0.0)) {
      return bad(fmt::format("{} must be finite and > 0, got {}", key, v));
    }
  }
  if ((shape == ShapeKind::kSquare || shape == ShapeKind::kCircle) &&
      std::abs(length_mm - width_mm) > 1e-9) {
    return bad(fmt::format("a {} has length_mm == width_mm, got {} and {}", to_string(shape),
                           length_mm, width_mm));
  }
  if (!(std::isfinite(base_mm) && base_mm >= 0.0 && base_mm < top_mm)) {
    return bad(fmt::format("base_mm must be in [0, top_mm = {}), got {}", top_mm, base_mm));
  }
  if (pins < 0) {
    return bad(fmt::format("pins must be >= 0, got {}", pins));
  }
  return ok_status();
}

ClassCatalogue ClassCatalogue::standard() {
  ClassCatalogue out;
  const world::Catalogue world = world::Catalogue::standard();
  for (const std::string& name : world.names()) {
    const auto cls = world.find(name);
    PartSpec spec;
    spec.name = name;
    spec.length_mm = cls->length_mm;
    spec.width_mm = cls->width_mm;
    spec.top_mm = cls->height_mm;
    switch (cls->shape) {
      case world::Shape::kDip:
        spec.shape = ShapeKind::kRectangle;
        spec.base_mm = cls->dip.standoff_mm;  // the body's walls end there; the leads are below
        spec.pins = cls->dip.pins;
        break;
      case world::Shape::kRectangle:
        spec.shape = ShapeKind::kRectangle;
        break;
      case world::Shape::kSquare:
        spec.shape = ShapeKind::kSquare;
        spec.width_mm = spec.length_mm;
        break;
      case world::Shape::kDisc:
        spec.shape = ShapeKind::kCircle;
        spec.width_mm = spec.length_mm;
        break;
      case world::Shape::kTriangle:
        spec.shape = ShapeKind::kTriangle;
        spec.width_mm = spec.length_mm * std::sqrt(3.0) / 2.0;
        break;
      case world::Shape::kBox:
      case world::Shape::kPolyhedron:
        continue;  // not flat parts: vision's 2-D models do not describe them
    }
    // Built-in values come from core/world's checked catalogue; a failure is a programming
    // error there, caught by vision_test (Classes.StandardCatalogueHasTheWorldsFlatClasses).
    (void)out.add(std::move(spec));
  }
  return out;
}

Status ClassCatalogue::add(PartSpec spec) {
  CELL_TRY(spec.validate());
  for (PartSpec& existing : specs_) {
    if (existing.name == spec.name) {
      existing = std::move(spec);
      return ok_status();
    }
  }
  specs_.push_back(std::move(spec));
  return ok_status();
}

std::optional<ClassMatch> ClassCatalogue::classify(ShapeKind shape,
                                                   double length_mm,
                                                   double width_mm,
                                                   double tolerance_mm,
                                                   double tolerance_rel) const {
  if (!(std::isfinite(length_mm) && std::isfinite(width_mm))) {
    return std::nullopt;
  }
  // A square is a rectangle whose sides happen to agree: let the sizes decide between them.
  auto compatible = [&](ShapeKind candidate) {
    if (candidate == shape) {
      return true;
    }
    const bool quad = (shape == ShapeKind::kRectangle || shape == ShapeKind::kSquare);
    const bool cand_quad = (candidate == ShapeKind::kRectangle || candidate == ShapeKind::kSquare);
    return quad && cand_quad;
  };
  std::optional<ClassMatch> best;
  double best_distance = 0.0;
  for (const PartSpec& spec : specs_) {
    if (!compatible(spec.shape)) {
      continue;
    }
    const double tol_l = std::max(tolerance_mm, tolerance_rel * spec.length_mm);
    const double tol_w = std::max(tolerance_mm, tolerance_rel * spec.width_mm);
    const double el = std::abs(length_mm - spec.length_mm) / tol_l;
    const double ew = std::abs(width_mm - spec.width_mm) / tol_w;
    if (el > 1.0 || ew > 1.0) {
      continue;
    }
    const double distance = std::hypot(el, ew);
    if (!best || distance < best_distance) {
      best = ClassMatch{&spec, std::max(el, ew)};
      best_distance = distance;
    }
  }
  return best;
}

const PartSpec* ClassCatalogue::find(std::string_view name) const noexcept {
  for (const PartSpec& spec : specs_) {
    if (spec.name == name) {
      return &spec;
    }
  }
  return nullptr;
}

}  // namespace cell::vision
