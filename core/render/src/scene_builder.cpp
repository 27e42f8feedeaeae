#include "scene_builder.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>

namespace cell::render::detail {
namespace {

/// Newell's normal of a planar ring (unit; zero for a degenerate ring).
Eigen::Vector3d newell_normal(const Eigen::Vector3d* ring, int n) {
  Eigen::Vector3d normal = Eigen::Vector3d::Zero();
  for (int i = 0, j = n - 1; i < n; j = i++) {
    const Eigen::Vector3d& a = ring[j];
    const Eigen::Vector3d& b = ring[i];
    normal.x() += (a.y() - b.y()) * (a.z() + b.z());
    normal.y() += (a.z() - b.z()) * (a.x() + b.x());
    normal.z() += (a.x() - b.x()) * (a.y() + b.y());
  }
  const double len = normal.norm();
  return len > 0.0 ? Eigen::Vector3d(normal / len) : Eigen::Vector3d::Zero();
}

}  // namespace

std::vector<Eigen::Vector2d> footprint(const Part& part, int disc_segments) {
  std::vector<Eigen::Vector2d> fp;
  const double l = part.length_mm;
  switch (part.shape) {
    case Shape::kDip:
    case Shape::kRectangle:
    case Shape::kBox: {
      const double w = part.width_mm;
      fp = {{-l / 2, -w / 2}, {l / 2, -w / 2}, {l / 2, w / 2}, {-l / 2, w / 2}};
      break;
    }
    case Shape::kSquare:
      fp = {{-l / 2, -l / 2}, {l / 2, -l / 2}, {l / 2, l / 2}, {-l / 2, l / 2}};
      break;
    case Shape::kTriangle: {
      const double h = l * std::sqrt(3.0) / 2.0;
      fp = {{-l / 2, -h / 3}, {l / 2, -h / 3}, {0.0, 2 * h / 3}};
      break;
    }
    case Shape::kDisc: {
      const int n = std::max(disc_segments, 8);
      fp.reserve(static_cast<std::size_t>(n));
      for (int i = 0; i < n; ++i) {
        const double a = 2.0 * std::numbers::pi * i / n;
        fp.emplace_back(0.5 * l * std::cos(a), 0.5 * l * std::sin(a));
      }
      break;
    }
    case Shape::kPolyhedron:
      break;
  }
  return fp;
}

void SceneGeometry::begin(const LightField& light, double grey_per_radiance, double focal_px,
                          double table_reflectance) {
  light_ = &light;
  grey_ = grey_per_radiance;
  focal_px_ = focal_px;
  table_reflectance_ = std::max(table_reflectance, 1e-3);
  vertices.clear();
  faces.clear();
  bodies.clear();
}

void SceneGeometry::open_body(double depth_mm, const Eigen::Vector3d& velocity, bool modulate) {
  BodyRecord body;
  body.first_face = static_cast<std::uint32_t>(faces.size());
  body.depth_mm = depth_mm;
  body.velocity_mm_s = velocity;
  body.modulate = modulate;
  bodies.push_back(body);
}

void SceneGeometry::close_body() {
  BodyRecord& body = bodies.back();
  body.face_count = static_cast<std::uint32_t>(faces.size()) - body.first_face;
  if (body.face_count == 0) {
    bodies.pop_back();
  }
}

double SceneGeometry::lambert(double reflectance, const Eigen::Vector3d& c,
                              const Eigen::Vector3d& n) const {
  return grey_ * reflectance * light_->irradiance(c, n);
}

template <typename ShadeFn>
void SceneGeometry::add_face(const Eigen::Vector3d* ring, int n, std::uint16_t layer,
                             ShadeFn&& shade_of) {
  if (n < 3) {
    return;
  }
  const Eigen::Vector3d normal = newell_normal(ring, n);
  Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
  for (int i = 0; i < n; ++i) {
    centroid += ring[i];
  }
  centroid /= n;
  // Back faces (and faces seen edge-on) are never drawn: bodies are closed and convex, and
  // single-sided faces (leads, belts) are only seen from their front.
  if (normal.dot(light_->camera_position() - centroid) <= 0.0) {
    return;
  }
  FaceRecord face;
  face.first = static_cast<std::uint32_t>(vertices.size());
  face.count = static_cast<std::uint32_t>(n);
  face.layer = layer;
  face.shade = static_cast<float>(shade_of(centroid, normal));
  vertices.insert(vertices.end(), ring, ring + n);
  faces.push_back(face);
}

void SceneGeometry::add_prism(const Eigen::Isometry3d& world_T_part,
                              const std::vector<Eigen::Vector2d>& fp, double z0, double z1,
                              double reflectance, std::uint16_t layer) {
  const int n = static_cast<int>(fp.size());
  auto shade = [&](const Eigen::Vector3d& c, const Eigen::Vector3d& nrm) {
    return lambert(reflectance, c, nrm);
  };
  ring_.resize(static_cast<std::size_t>(n));
  for (int i = 0; i < n; ++i) {  // top, counter-clockwise from +z: normal up
    ring_[static_cast<std::size_t>(i)] = world_T_part * Eigen::Vector3d(fp[i].x(), fp[i].y(), z1);
  }
  add_face(ring_.data(), n, layer, shade);
  if (!(z1 > z0)) {
    return;  // a flat sticker: its top face only
  }
  for (int i = 0; i < n; ++i) {  // bottom, reversed: normal down
    const auto& p = fp[static_cast<std::size_t>(n - 1 - i)];
    ring_[static_cast<std::size_t>(i)] = world_T_part * Eigen::Vector3d(p.x(), p.y(), z0);
  }
  add_face(ring_.data(), n, layer, shade);
  std::array<Eigen::Vector3d, 4> quad;
  for (int i = 0; i < n; ++i) {  // sides: (a0, b0, b1, a1), outward for a CCW footprint
    const auto& a = fp[static_cast<std::size_t>(i)];
    const auto& b = fp[static_cast<std::size_t>((i + 1) % n)];
    quad[0] = world_T_part * Eigen::Vector3d(a.x(), a.y(), z0);
    quad[1] = world_T_part * Eigen::Vector3d(b.x(), b.y(), z0);
    quad[2] = world_T_part * Eigen::Vector3d(b.x(), b.y(), z1);
    quad[3] = world_T_part * Eigen::Vector3d(a.x(), a.y(), z1);
    add_face(quad.data(), 4, layer, shade);
  }
}

void SceneGeometry::add_dip_leads(const Part& part) {
  const DipLeads& leads = part.leads;
  const int per_side = part.pins / 2;
  const double w = part.width_mm;
  const double reach_y = 0.5 * (leads.row_spacing_mm + leads.lead_thickness_mm);
  if (per_side <= 0 || reach_y <= 0.5 * w) {
    return;  // no leads, or leads hidden under the body
  }
  const double l = part.length_mm;
  double pitch = leads.pitch_mm;
  double lead_w = leads.shoulder_width_mm;
  if (per_side > 1 && (per_side - 1) * pitch + lead_w > l) {  // squeeze into the body length
    pitch = (l - lead_w) / (per_side - 1);
    lead_w = std::min(lead_w, 0.8 * pitch);
  }
  // The shoulders leave the body at mid-body height.
  const double z = leads.standoff_mm + 0.5 * (part.height_mm - leads.standoff_mm);
  const Eigen::Vector3d axis_world = part.world_T_part.linear() * Eigen::Vector3d::UnitY();
  // Each lead seen from above: dull flanks either side of a glossy crest that catches the
  // lights (a rounded lead: see LightField::cylinder_highlight).
  static constexpr std::array<double, 4> kStripes = {0.0, 0.25, 0.75, 1.0};
  std::array<Eigen::Vector3d, 4> quad;
  for (int side = 0; side < 2; ++side) {
    const double y0 = side == 0 ? 0.5 * w : -reach_y;
    const double y1 = side == 0 ? reach_y : -0.5 * w;
    for (int k = 0; k < per_side; ++k) {
      const double xc = (k - 0.5 * (per_side - 1)) * pitch;
      for (std::size_t s = 0; s + 1 < kStripes.size(); ++s) {
        const double xa = xc - lead_w / 2 + kStripes[s] * lead_w;
        const double xb = xc - lead_w / 2 + kStripes[s + 1] * lead_w;
        quad[0] = part.world_T_part * Eigen::Vector3d(xa, y0, z);
        quad[1] = part.world_T_part * Eigen::Vector3d(xb, y0, z);
        quad[2] = part.world_T_part * Eigen::Vector3d(xb, y1, z);
        quad[3] = part.world_T_part * Eigen::Vector3d(xa, y1, z);
        const bool crest = s == 1;
        add_face(quad.data(), 4, 0, [&](const Eigen::Vector3d& c, const Eigen::Vector3d& n) {
          double g = lambert(leads.reflectance, c, n);
          if (crest) {
            g += grey_ * light_->cylinder_highlight(c, axis_world);
          }
          return g;
        });
      }
    }
  }
}

void SceneGeometry::add_polyhedron(const Part& part) {
  const Mesh& mesh = part.mesh;
  // Convex bodies: every vertex on the inner side of every face plane. Their front faces never
  // overlap, so they accumulate as one seamless layer; other bodies are painted face by face.
  double size = 0.0;
  for (const auto& v : mesh.vertices_mm) {
    size = std::max(size, v.norm());
  }
  const double tol = 1e-6 * std::max(size, 1.0);
  bool convex = true;
  for (const auto& face : mesh.faces) {
    ring_.clear();
    for (const std::uint32_t index : face) {
      ring_.push_back(mesh.vertices_mm[index]);
    }
    const Eigen::Vector3d n = newell_normal(ring_.data(), static_cast<int>(ring_.size()));
    for (const auto& v : mesh.vertices_mm) {
      if (n.dot(v - ring_.front()) > tol) {
        convex = false;
        break;
      }
    }
    if (!convex) {
      break;
    }
  }
  const auto first = static_cast<std::uint32_t>(faces.size());
  for (const auto& face : mesh.faces) {
    ring_.clear();
    for (const std::uint32_t index : face) {
      ring_.push_back(part.world_T_part * mesh.vertices_mm[index]);
    }
    add_face(ring_.data(), static_cast<int>(ring_.size()), 0,
             [&](const Eigen::Vector3d& c, const Eigen::Vector3d& n) {
               return lambert(part.reflectance, c, n);
             });
  }
  if (convex) {
    return;
  }
  // Far to near by face centroid; each face its own layer.
  const Eigen::Vector3d eye = light_->camera_position();
  auto distance = [&](const FaceRecord& f) {
    Eigen::Vector3d c = Eigen::Vector3d::Zero();
    for (std::uint32_t i = 0; i < f.count; ++i) {
      c += vertices[f.first + i];
    }
    return (c / f.count - eye).norm();
  };
  std::stable_sort(faces.begin() + first, faces.end(),
                   [&](const FaceRecord& a, const FaceRecord& b) {
                     return distance(a) > distance(b);
                   });
  std::uint16_t layer = 0;
  for (auto it = faces.begin() + first; it != faces.end(); ++it) {
    it->layer = layer;
    if (layer < 0xFFFF) {
      ++layer;
    }
  }
}

void SceneGeometry::add_belt(const Belt& belt) {
  const Eigen::Vector3d dir = belt.direction.normalized();
  Eigen::Vector3d lateral = Eigen::Vector3d::UnitZ().cross(dir);
  if (lateral.norm() < 1e-9) {
    return;  // a vertical belt is not a conveyor this renderer knows
  }
  lateral.normalize();
  const Eigen::Vector3d a = belt.origin_mm - lateral * (belt.width_mm / 2);
  const Eigen::Vector3d b = belt.origin_mm + lateral * (belt.width_mm / 2);
  const Eigen::Vector3d along = dir * belt.length_mm;
  // Counter-clockwise seen from above (a is on the right-hand side of the travel).
  const std::array<Eigen::Vector3d, 4> quad = {a, a + along, b + along, b};
  open_body(1e300, Eigen::Vector3d::Zero(), true);
  const double ratio = belt.reflectance / table_reflectance_;
  add_face(quad.data(), 4, 0, [&](const Eigen::Vector3d&, const Eigen::Vector3d&) {
    return ratio;
  });
  close_body();
}

void SceneGeometry::add_part(const Part& part) {
  const Eigen::Vector3d top_centre =
      part.world_T_part * Eigen::Vector3d(0.0, 0.0, 0.5 * part.height_mm);
  const double depth = (top_centre - light_->camera_position()).norm();
  open_body(depth, part.velocity_mm_s, false);
  switch (part.shape) {
    case Shape::kPolyhedron:
      add_polyhedron(part);
      break;
    case Shape::kDisc: {
      // Segments so that the chord's sagitta stays below 0.01 px: r (1 - cos(pi / n)).
      const double r_px = focal_px_ * 0.5 * part.length_mm / std::max(depth, 1.0);
      const double n = std::numbers::pi / std::sqrt(2.0 * 0.01 / std::max(r_px, 1e-3));
      const int segments = static_cast<int>(std::clamp(std::ceil(n), 16.0, 720.0));
      add_prism(part.world_T_part, footprint(part, segments), 0.0, part.height_mm,
                part.reflectance, 0);
      break;
    }
    case Shape::kDip:
      add_dip_leads(part);
      add_prism(part.world_T_part, footprint(part, 0), part.leads.standoff_mm, part.height_mm,
                part.reflectance, 1);
      break;
    default:
      add_prism(part.world_T_part, footprint(part, 0), 0.0, part.height_mm, part.reflectance, 0);
      break;
  }
  close_body();
}

void SceneGeometry::add_chessboard(const Chessboard& board) {
  const double s = board.square_mm;
  const double m = board.margin_mm;
  const double xs = board.squares_x * s;
  const double ys = board.squares_y * s;
  const Eigen::Isometry3d& w_T_b = board.world_T_board;
  const Eigen::Vector3d centre = w_T_b * Eigen::Vector3d(xs / 2, ys / 2, 0.0);
  open_body((centre - light_->camera_position()).norm(), Eigen::Vector3d::Zero(), false);
  std::array<Eigen::Vector3d, 4> quad;
  auto rect = [&](double x0, double y0, double x1, double y1, double z, double reflectance,
                  bool front) {
    if (!(x1 > x0) || !(y1 > y0)) {
      return;
    }
    quad[0] = w_T_b * Eigen::Vector3d(x0, y0, z);
    quad[1] = w_T_b * Eigen::Vector3d(x1, y0, z);
    quad[2] = w_T_b * Eigen::Vector3d(x1, y1, z);
    quad[3] = w_T_b * Eigen::Vector3d(x0, y1, z);
    if (!front) {
      std::swap(quad[1], quad[3]);
    }
    add_face(quad.data(), 4, 0, [&](const Eigen::Vector3d& c, const Eigen::Vector3d& n) {
      return lambert(reflectance, c, n);
    });
  };
  // Printed face: the squares and the four margin strips tile it without overlap.
  for (int j = 0; j < board.squares_y; ++j) {
    for (int i = 0; i < board.squares_x; ++i) {
      const bool black = (i + j) % 2 == 0;
      rect(i * s, j * s, (i + 1) * s, (j + 1) * s, 0.0,
           black ? board.black_reflectance : board.white_reflectance, true);
    }
  }
  rect(-m, -m, xs + m, 0.0, 0.0, board.white_reflectance, true);
  rect(-m, ys, xs + m, ys + m, 0.0, board.white_reflectance, true);
  rect(-m, 0.0, 0.0, ys, 0.0, board.white_reflectance, true);
  rect(xs, 0.0, xs + m, ys, 0.0, board.white_reflectance, true);
  // The board's back and edges (grey), seen when the camera is behind or beside it.
  const double t = board.thickness_mm;
  constexpr double kBoardGrey = 0.5;
  rect(-m, -m, xs + m, ys + m, -t, kBoardGrey, false);
  if (t > 0.0) {
    const std::vector<Eigen::Vector2d> outline = {
        {-m, -m}, {xs + m, -m}, {xs + m, ys + m}, {-m, ys + m}};
    for (int i = 0; i < 4; ++i) {
      const auto& a = outline[static_cast<std::size_t>(i)];
      const auto& b = outline[static_cast<std::size_t>((i + 1) % 4)];
      quad[0] = w_T_b * Eigen::Vector3d(a.x(), a.y(), -t);
      quad[1] = w_T_b * Eigen::Vector3d(b.x(), b.y(), -t);
      quad[2] = w_T_b * Eigen::Vector3d(b.x(), b.y(), 0.0);
      quad[3] = w_T_b * Eigen::Vector3d(a.x(), a.y(), 0.0);
      add_face(quad.data(), 4, 0, [&](const Eigen::Vector3d& c, const Eigen::Vector3d& n) {
        return lambert(kBoardGrey, c, n);
      });
    }
  }
  close_body();
}

}  // namespace cell::render::detail
