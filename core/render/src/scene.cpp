#include "cell/render/scene.hpp"

#include <cmath>

#include <fmt/format.h>

#include "cell/geometry/pose.hpp"

namespace cell::render {
namespace {

Error invalid(std::string message) { return Error{Errc::kInvalidArgument, std::move(message)}; }

bool positive(double v) { return std::isfinite(v) && v > 0.0; }

}  // namespace

std::string_view to_string(Shape shape) noexcept {
  switch (shape) {
    case Shape::kDip:
      return "dip";
    case Shape::kRectangle:
      return "rectangle";
    case Shape::kSquare:
      return "square";
    case Shape::kDisc:
      return "disc";
    case Shape::kTriangle:
      return "triangle";
    case Shape::kBox:
      return "box";
    case Shape::kPolyhedron:
      return "polyhedron";
  }
  return "unknown";
}

DipLeads DipLeads::standard_for_width(double width_mm) noexcept {
  DipLeads leads;
  leads.row_spacing_mm = width_mm > 10.0 ? 15.24 : (width_mm > 7.5 ? 10.16 : 7.62);
  return leads;
}

Status Part::validate() const {
  const std::string who = fmt::format("part '{}' ({})", id, to_string(shape));
  if (auto s = geometry::check_rigid(world_T_part, who + " world_T_part", 1e-6); !s) {
    return s;
  }
  if (!velocity_mm_s.allFinite()) {
    return invalid(who + ": velocity is not finite");
  }
  if (!(std::isfinite(reflectance) && reflectance >= 0.0 && reflectance <= 1.0)) {
    return invalid(fmt::format("{}: reflectance {} must be in [0, 1]", who, reflectance));
  }
  if (!(std::isfinite(height_mm) && height_mm >= 0.0)) {
    return invalid(fmt::format("{}: height_mm {} must be finite and >= 0", who, height_mm));
  }
  switch (shape) {
    case Shape::kDip:
      if (pins < 0 || pins % 2 != 0 || pins > 256) {
        return invalid(fmt::format("{}: pins {} must be even and in 0..256", who, pins));
      }
      if (!positive(leads.pitch_mm) || !positive(leads.row_spacing_mm) ||
          !positive(leads.shoulder_width_mm) || !(leads.lead_thickness_mm >= 0.0) ||
          !(leads.standoff_mm >= 0.0) || !(leads.standoff_mm < height_mm) ||
          !(leads.reflectance >= 0.0 && leads.reflectance <= 1.0)) {
        return invalid(fmt::format("{}: DIP package sizes must be > 0, the standoff {} mm below "
                                   "the height {} mm, lead reflectance in [0, 1]",
                                   who, leads.standoff_mm, height_mm));
      }
      [[fallthrough]];
    case Shape::kRectangle:
    case Shape::kBox:
      if (!positive(length_mm) || !positive(width_mm)) {
        return invalid(fmt::format("{}: length_mm {} and width_mm {} must be > 0", who,
                                   length_mm, width_mm));
      }
      break;
    case Shape::kSquare:
    case Shape::kDisc:
    case Shape::kTriangle:
      if (!positive(length_mm)) {
        return invalid(fmt::format("{}: length_mm {} must be > 0", who, length_mm));
      }
      break;
    case Shape::kPolyhedron: {
      if (mesh.vertices_mm.size() < 4 || mesh.faces.size() < 4) {
        return invalid(fmt::format("{}: mesh needs >= 4 vertices and >= 4 faces, has {} and {}",
                                   who, mesh.vertices_mm.size(), mesh.faces.size()));
      }
      for (std::size_t i = 0; i < mesh.vertices_mm.size(); ++i) {
        if (!mesh.vertices_mm[i].allFinite()) {
          return invalid(fmt::format("{}: mesh vertex {} is not finite", who, i));
        }
      }
      for (std::size_t f = 0; f < mesh.faces.size(); ++f) {
        if (mesh.faces[f].size() < 3) {
          return invalid(fmt::format("{}: mesh face {} has {} vertices (needs >= 3)", who, f,
                                     mesh.faces[f].size()));
        }
        for (const std::uint32_t index : mesh.faces[f]) {
          if (index >= mesh.vertices_mm.size()) {
            return invalid(fmt::format("{}: mesh face {} uses vertex {} of {}", who, f, index,
                                       mesh.vertices_mm.size()));
          }
        }
      }
      break;
    }
    default:
      return invalid(fmt::format("part '{}': unknown shape {}", id, static_cast<int>(shape)));
  }
  return ok_status();
}

Status Belt::validate() const {
  const std::string who = fmt::format("belt '{}'", id);
  if (!origin_mm.allFinite() || !direction.allFinite() || direction.norm() < 1e-9) {
    return invalid(who + ": origin and direction must be finite, direction non-zero");
  }
  if (!positive(length_mm) || !positive(width_mm)) {
    return invalid(fmt::format("{}: length_mm {} and width_mm {} must be > 0", who, length_mm,
                               width_mm));
  }
  if (!(std::isfinite(reflectance) && reflectance >= 0.0 && reflectance <= 1.0)) {
    return invalid(fmt::format("{}: reflectance {} must be in [0, 1]", who, reflectance));
  }
  return ok_status();
}

Status Chessboard::validate() const {
  const std::string who = fmt::format("chessboard '{}'", id);
  if (squares_x < 2 || squares_y < 2 || squares_x > 200 || squares_y > 200) {
    return invalid(fmt::format("{}: {} x {} squares: each side must be 2..200", who, squares_x,
                               squares_y));
  }
  if (!positive(square_mm) || !(std::isfinite(margin_mm) && margin_mm >= 0.0) ||
      !(std::isfinite(thickness_mm) && thickness_mm >= 0.0)) {
    return invalid(fmt::format("{}: square_mm {} must be > 0, margin_mm {} and thickness_mm {} "
                               ">= 0",
                               who, square_mm, margin_mm, thickness_mm));
  }
  for (const double r : {white_reflectance, black_reflectance}) {
    if (!(std::isfinite(r) && r >= 0.0 && r <= 1.0)) {
      return invalid(fmt::format("{}: reflectance {} must be in [0, 1]", who, r));
    }
  }
  return geometry::check_rigid(world_T_board, who + " world_T_board", 1e-6);
}

std::vector<Eigen::Vector3d> chessboard_corners(const Chessboard& board) {
  std::vector<Eigen::Vector3d> corners;
  if (board.squares_x < 2 || board.squares_y < 2) {
    return corners;
  }
  corners.reserve(static_cast<std::size_t>(board.squares_x - 1) *
                  static_cast<std::size_t>(board.squares_y - 1));
  for (int j = 1; j < board.squares_y; ++j) {
    for (int i = 1; i < board.squares_x; ++i) {
      corners.emplace_back(i * board.square_mm, j * board.square_mm, 0.0);
    }
  }
  return corners;
}

}  // namespace cell::render
