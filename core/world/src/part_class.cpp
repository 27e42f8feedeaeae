#include "cell/world/part_class.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <numbers>
#include <utility>

#include "cell/geometry/pose.hpp"
#include "cell/world/footprint.hpp"
#include "checks.hpp"

namespace cell::world {
namespace {

constexpr double kSqrt3 = 1.7320508075688772;
constexpr int kDiscSides = 32;         // disc outline: circumscribed 32-gon (0.5 % larger)
constexpr double kPlanarTolMm = 0.01;  // mesh face planarity
constexpr double kFitTolMm = 1e-6;     // DIP pin rows vs body length

Error invalid(const std::string& name, const std::string& what) {
  return Error{Errc::kInvalidArgument, fmt::format("part class '{}': {}", name, what)};
}

using detail::finite_positive;

/// Closed box mesh [x0, x1] x [y0, y1] x [z0, z1], faces counter-clockwise from outside.
Mesh box_mesh(double x0, double x1, double y0, double y1, double z0, double z1) {
  Mesh m;
  m.vertices = {{x0, y0, z0}, {x1, y0, z0}, {x1, y1, z0}, {x0, y1, z0},
                {x0, y0, z1}, {x1, y0, z1}, {x1, y1, z1}, {x0, y1, z1}};
  m.faces = {{0, 3, 2, 1},   // bottom (-z)
             {4, 5, 6, 7},   // top (+z)
             {0, 1, 5, 4},   // y0 (-y)
             {2, 3, 7, 6},   // y1 (+y)
             {1, 2, 6, 5},   // x1 (+x)
             {3, 0, 4, 7}};  // x0 (-x)
  return m;
}

/// Digest 003 App. V body b3: a column x 0..20, y -30..0, z 0..140 with an arm x 20..60 at
/// z 50..90 (faces f1..f8 of the thesis's model). Its holes h1 (z = 25) and h2 (z = 115),
/// radius 5 along x, are not meshed. The L-shaped side faces are split into convex polygons
/// that share the vertices at x = 20 (no T-junctions).
Mesh rapt_b3_mesh() {
  Mesh m;
  // y = 0 side (+y), then y = -30 side (-y): the same 10 points.
  const double ys[2] = {0.0, -30.0};
  for (const double y : ys) {
    m.vertices.insert(m.vertices.end(), {{0, y, 0},      // 0 / 8
                                         {20, y, 0},     // 1 / 9
                                         {20, y, 50},    // 2 / 10
                                         {60, y, 50},    // 3 / 11
                                         {60, y, 90},    // 4 / 12
                                         {20, y, 90},    // 5 / 13
                                         {20, y, 140},   // 6 / 14
                                         {0, y, 140}});  // 7 / 15
  }
  // Indices 0..7 are the y = 0 points, 8..15 the y = -30 ones. Each face counter-clockwise
  // seen from outside (checked by Mesh::validate: closed, consistently oriented, convex faces).
  m.faces = {
      {0, 7, 6, 5, 2, 1},      // y = 0 column (normal +y), through the arm's corners 2 and 5
      {2, 5, 4, 3},            // y = 0 arm (normal +y)
      {8, 9, 10, 13, 14, 15},  // y = -30 column (normal -y)
      {10, 11, 12, 13},        // y = -30 arm (normal -y)
      {0, 1, 9, 8},            // bottom z = 0 (normal -z)
      {7, 15, 14, 6},          // top z = 140 (normal +z)
      {0, 8, 15, 7},           // x = 0 (normal -x)
      {1, 2, 10, 9},           // x = 20 below the arm (normal +x)
      {5, 6, 14, 13},          // x = 20 above the arm (normal +x)
      {2, 3, 11, 10},          // arm bottom z = 50 (normal -z)
      {5, 13, 12, 4},          // arm top z = 90 (normal +z)
      {3, 4, 12, 11},          // arm end x = 60 (normal +x)
  };
  return m;
}

/// Outline of an upright prism shape in its part frame, counter-clockwise.
std::vector<Eigen::Vector2d> prism_outline(const PartClass& c) {
  const double hl = c.length_mm / 2.0;
  const double hw = c.width_mm / 2.0;
  switch (c.shape) {
    case Shape::kDip: {
      // Convex hull of the body and the lead rows (octagon when the leads stick out).
      const int per_row = c.dip.pins / 2;
      const double lead_x = (per_row - 1) * c.dip.pitch_mm / 2.0 + c.dip.shoulder_width_mm / 2.0;
      const double lead_y = c.dip.lead_span_mm() / 2.0;
      std::vector<Eigen::Vector2d> pts = {{-hl, -hw}, {hl, -hw}, {hl, hw}, {-hl, hw}};
      if (lead_y > hw) {
        pts.insert(pts.end(),
                   {{-lead_x, -lead_y}, {lead_x, -lead_y}, {lead_x, lead_y}, {-lead_x, lead_y}});
      }
      return convex_hull(std::move(pts));
    }
    case Shape::kDisc: {
      std::vector<Eigen::Vector2d> pts;
      const double r = hl / std::cos(std::numbers::pi / kDiscSides);
      for (int i = 0; i < kDiscSides; ++i) {
        const double a = 2.0 * std::numbers::pi * i / kDiscSides;
        pts.emplace_back(r * std::cos(a), r * std::sin(a));
      }
      return pts;
    }
    case Shape::kTriangle: {
      // Centroid at the origin, one side along x at y = -h/3, apex on +y.
      const double h = c.length_mm * kSqrt3 / 2.0;
      return {{-hl, -h / 3.0}, {hl, -h / 3.0}, {0.0, 2.0 * h / 3.0}};
    }
    default:
      return {{-hl, -hw}, {hl, -hw}, {hl, hw}, {-hl, hw}};
  }
}

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

Result<Shape> shape_from_string(std::string_view text) {
  for (const Shape s : {Shape::kDip, Shape::kRectangle, Shape::kSquare, Shape::kDisc,
                        Shape::kTriangle, Shape::kBox, Shape::kPolyhedron}) {
    if (to_string(s) == text) {
      return s;
    }
  }
  return Error{Errc::kInvalidArgument,
               fmt::format("unknown shape '{}' (known: dip, rectangle, square, disc, triangle, "
                           "box, polyhedron)",
                           text)};
}

Eigen::Vector2d DipPackage::pin_centre(int pin) const noexcept {
  if (pins <= 0 || pin < 1 || pin > pins) {
    return Eigen::Vector2d::Zero();
  }
  const int per_row = pins / 2;
  const double x0 = -(per_row - 1) * pitch_mm / 2.0;
  if (pin <= per_row) {
    return {x0 + (pin - 1) * pitch_mm, -row_spacing_mm / 2.0};
  }
  return {x0 + (pins - pin) * pitch_mm, row_spacing_mm / 2.0};
}

Status Mesh::validate() const {
  if (vertices.size() < 4 || faces.size() < 4) {
    return Error{Errc::kInvalidArgument,
                 fmt::format("mesh: a closed polyhedron needs at least 4 vertices and 4 faces, "
                             "got {} and {}",
                             vertices.size(), faces.size())};
  }
  for (std::size_t i = 0; i < vertices.size(); ++i) {
    if (!vertices[i].allFinite()) {
      return Error{Errc::kInvalidArgument, fmt::format("mesh: vertex {} is not finite", i)};
    }
  }
  // Every directed edge once, and its reverse once: a closed, consistently oriented surface.
  std::map<std::pair<std::uint32_t, std::uint32_t>, int> edges;
  double volume6 = 0.0;  // 6 x signed volume (divergence theorem, fan triangles)
  for (std::size_t f = 0; f < faces.size(); ++f) {
    const auto& face = faces[f];
    if (face.size() < 3) {
      return Error{Errc::kInvalidArgument,
                   fmt::format("mesh: face {} has {} vertices, needs at least 3", f, face.size())};
    }
    for (const std::uint32_t index : face) {
      if (index >= vertices.size()) {
        return Error{
            Errc::kInvalidArgument,
            fmt::format("mesh: face {} uses vertex {}, there are {}", f, index, vertices.size())};
      }
    }
    Eigen::Vector3d normal = Eigen::Vector3d::Zero();  // Newell's method
    for (std::size_t i = 0; i < face.size(); ++i) {
      const Eigen::Vector3d& a = vertices[face[i]];
      const Eigen::Vector3d& b = vertices[face[(i + 1) % face.size()]];
      normal += a.cross(b);
      ++edges[{face[i], face[(i + 1) % face.size()]}];
    }
    if (normal.norm() < 1e-12) {
      return Error{Errc::kInvalidArgument, fmt::format("mesh: face {} has no area", f)};
    }
    normal.normalize();
    const Eigen::Vector3d& p0 = vertices[face[0]];
    for (std::size_t i = 1; i < face.size(); ++i) {
      const double off = std::abs(normal.dot(vertices[face[i]] - p0));
      if (off > kPlanarTolMm) {
        return Error{Errc::kInvalidArgument,
                     fmt::format("mesh: face {} is not planar (vertex {} is {:.3f} mm off)", f,
                                 face[i], off)};
      }
    }
    for (std::size_t i = 1; i + 1 < face.size(); ++i) {  // fan triangles of the face
      volume6 += p0.dot(vertices[face[i]].cross(vertices[face[i + 1]]));
    }
    // Convexity: every turn has the same sense as the face normal (collinear points allowed).
    for (std::size_t i = 0; i < face.size(); ++i) {
      const Eigen::Vector3d& a = vertices[face[i]];
      const Eigen::Vector3d& b = vertices[face[(i + 1) % face.size()]];
      const Eigen::Vector3d& c = vertices[face[(i + 2) % face.size()]];
      if ((b - a).cross(c - b).dot(normal) < -1e-9) {
        return Error{Errc::kInvalidArgument, fmt::format("mesh: face {} is not convex at vertex {}",
                                                         f, face[(i + 1) % face.size()])};
      }
    }
  }
  for (const auto& [edge, count] : edges) {
    const auto reverse = edges.find({edge.second, edge.first});
    if (count != 1 || reverse == edges.end() || reverse->second != 1) {
      return Error{Errc::kInvalidArgument,
                   fmt::format("mesh: edge {}-{} is not shared by exactly two faces in opposite "
                               "directions (the surface is open or inconsistently oriented)",
                               edge.first, edge.second)};
    }
  }
  if (volume6 <= 0.0) {
    return Error{Errc::kInvalidArgument,
                 "mesh: faces are clockwise seen from outside (negative volume)"};
  }
  return ok_status();
}

Status PartClass::validate() const {
  if (name.empty()) {
    return Error{Errc::kInvalidArgument, "part class: empty name"};
  }
  if (!finite_positive(length_mm)) {
    return invalid(name, fmt::format("length_mm must be > 0, got {}", length_mm));
  }
  if (shape != Shape::kDisc && shape != Shape::kTriangle && !finite_positive(width_mm)) {
    return invalid(name, fmt::format("width_mm must be > 0, got {}", width_mm));
  }
  if (!finite_positive(height_mm)) {
    return invalid(name, fmt::format("height_mm must be > 0, got {}", height_mm));
  }
  if (!(reflectance >= 0.0 && reflectance <= 1.0)) {
    return invalid(name, fmt::format("reflectance must be in [0, 1], got {}", reflectance));
  }
  if ((shape == Shape::kSquare || shape == Shape::kDisc) && std::abs(length_mm - width_mm) > 1e-9) {
    return invalid(name, fmt::format("a {} needs length_mm == width_mm, got {} and {}",
                                     to_string(shape), length_mm, width_mm));
  }
  if (yaw_symmetry < 0 || yaw_symmetry > 64) {
    return invalid(name, fmt::format("yaw_symmetry must be 0..64, got {}", yaw_symmetry));
  }
  if (grasp_yaws_rad.empty()) {
    return invalid(name, "grasp_yaws_rad is empty: a part needs at least one grasp yaw");
  }
  for (std::size_t i = 0; i < grasp_yaws_rad.size(); ++i) {
    if (!std::isfinite(grasp_yaws_rad[i])) {
      return invalid(name,
                     fmt::format("grasp_yaws_rad[{}] is not finite, got {}", i, grasp_yaws_rad[i]));
    }
  }
  if (shape == Shape::kDip) {
    const DipPackage& d = dip;
    if (d.pins < 4 || d.pins > 64 || d.pins % 2 != 0) {
      return invalid(name, fmt::format("a DIP needs an even pin count 4..64, got {}", d.pins));
    }
    if (!finite_positive(d.pitch_mm) || !finite_positive(d.row_spacing_mm) ||
        !finite_positive(d.lead_width_mm) || !finite_positive(d.shoulder_width_mm) ||
        !finite_positive(d.lead_thickness_mm) || !(d.standoff_mm >= 0.0) ||
        !finite_positive(d.body_thickness_mm)) {
      return invalid(name, "DIP package dimensions must be > 0 (standoff >= 0)");
    }
    const int per_row = d.pins / 2;  // even, checked above
    const double rows = (per_row - 1) * d.pitch_mm + d.shoulder_width_mm;
    if (rows > length_mm + kFitTolMm) {
      return invalid(name, fmt::format("{} pins at {} mm pitch need a body of at least {:.2f} mm, "
                                       "length_mm is {}",
                                       d.pins, d.pitch_mm, rows, length_mm));
    }
    if (d.row_spacing_mm < width_mm * 0.5) {
      return invalid(name, fmt::format("row_spacing_mm {} is narrower than half the body width {}",
                                       d.row_spacing_mm, width_mm));
    }
  } else if (dip.pins != 0) {
    return invalid(name,
                   fmt::format("only a DIP has pins, got {} on a {}", dip.pins, to_string(shape)));
  }
  if (shape == Shape::kPolyhedron) {
    if (auto s = mesh.validate(); !s) {
      return invalid(name, s.error().message);
    }
  }
  if (auto s = geometry::check_rigid(part_T_grasp, "part_T_grasp"); !s) {
    return invalid(name, s.error().message);
  }
  if (auto s = geometry::check_rigid(part_T_model, "part_T_model"); !s) {
    return invalid(name, s.error().message);
  }
  return ok_status();
}

void PartClass::finalize() {
  hull_points.clear();
  if (shape == Shape::kPolyhedron) {
    hull_points = mesh.vertices;
    std::vector<Eigen::Vector2d> projected;
    projected.reserve(mesh.vertices.size());
    for (const auto& v : mesh.vertices) {
      projected.emplace_back(v.x(), v.y());
    }
    footprint = convex_hull(std::move(projected));
    return;
  }
  if (shape == Shape::kTriangle) {
    width_mm = length_mm * kSqrt3 / 2.0;
  }
  if (shape == Shape::kSquare || shape == Shape::kDisc) {
    width_mm = length_mm;
  }
  footprint = prism_outline(*this);
  for (const auto& p : footprint) {
    hull_points.emplace_back(p.x(), p.y(), 0.0);
    hull_points.emplace_back(p.x(), p.y(), height_mm);
  }
}

PartClass make_dip(std::string name,
                   int pins,
                   double length_mm,
                   double width_mm,
                   double row_spacing_mm,
                   std::string description) {
  PartClass c;
  c.name = std::move(name);
  c.description = std::move(description);
  c.shape = Shape::kDip;
  c.length_mm = length_mm;
  c.width_mm = width_mm;
  c.dip.pins = pins;
  c.dip.row_spacing_mm = row_spacing_mm;
  // JEDEC MS-011 (0.6"): A2 0.150" nominal; MS-001 (0.3"): 0.130".
  c.dip.body_thickness_mm = row_spacing_mm >= 15.0 ? 3.81 : 3.30;
  c.height_mm = c.dip.standoff_mm + c.dip.body_thickness_mm;
  c.reflectance = 0.1;  // black epoxy (digest 000 §3: black ICs on a white matte table)
  c.yaw_symmetry = 2;
  c.part_T_grasp = Eigen::Isometry3d(Eigen::Translation3d(0.0, 0.0, c.height_mm));
  // A parallel-jaw gripper takes it across the body (fingers closing along y) or on its ends
  // (along x): config/vision.yaml's "across" and "ends" grasps (digest 002 §3).
  c.grasp_yaws_rad = {0.0, std::numbers::pi / 2.0};
  c.finalize();
  return c;
}

PartClass make_prism(std::string name,
                     Shape shape,
                     double length_mm,
                     double width_mm,
                     double height_mm,
                     double reflectance,
                     std::string description) {
  PartClass c;
  c.name = std::move(name);
  c.description = std::move(description);
  c.shape = shape;
  c.length_mm = length_mm;
  c.width_mm = width_mm;
  c.height_mm = height_mm;
  c.reflectance = reflectance;
  switch (shape) {
    case Shape::kSquare:
      c.yaw_symmetry = 4;
      break;
    case Shape::kDisc:
      c.yaw_symmetry = 0;
      break;
    case Shape::kTriangle:
      c.yaw_symmetry = 3;
      break;
    case Shape::kBox:
      c.yaw_symmetry = std::abs(length_mm - width_mm) < 1e-9 ? 4 : 2;
      break;
    default:
      c.yaw_symmetry = 2;
      break;
  }
  // Symmetry 2 (a rectangle, an oblong box): taken across it or along it, as a DIP.
  c.grasp_yaws_rad = c.yaw_symmetry == 2 ? std::vector<double>{0.0, std::numbers::pi / 2.0}
                                         : std::vector<double>{0.0};
  c.part_T_grasp = Eigen::Isometry3d(Eigen::Translation3d(0.0, 0.0, height_mm));
  c.finalize();
  return c;
}

PartClass make_polyhedron(std::string name,
                          const Mesh& mesh_model,
                          double reflectance,
                          std::string description) {
  PartClass c;
  c.name = std::move(name);
  c.description = std::move(description);
  c.shape = Shape::kPolyhedron;
  c.reflectance = reflectance;
  c.yaw_symmetry = 1;
  Eigen::Vector3d lo = Eigen::Vector3d::Constant(std::numeric_limits<double>::infinity());
  Eigen::Vector3d hi = Eigen::Vector3d::Constant(-std::numeric_limits<double>::infinity());
  for (const auto& v : mesh_model.vertices) {
    lo = lo.cwiseMin(v);
    hi = hi.cwiseMax(v);
  }
  if (mesh_model.vertices.empty()) {
    lo.setZero();
    hi.setZero();
  }
  const Eigen::Vector3d base((lo.x() + hi.x()) / 2.0, (lo.y() + hi.y()) / 2.0, lo.z());
  c.part_T_model = Eigen::Isometry3d(Eigen::Translation3d(-base));
  c.mesh.faces = mesh_model.faces;
  for (const auto& v : mesh_model.vertices) {
    c.mesh.vertices.push_back(v - base);
  }
  c.length_mm = hi.x() - lo.x();
  c.width_mm = hi.y() - lo.y();
  c.height_mm = hi.z() - lo.z();
  c.part_T_grasp = Eigen::Isometry3d(Eigen::Translation3d(0.0, 0.0, c.height_mm));
  c.finalize();
  return c;
}

Catalogue Catalogue::standard() {
  Catalogue cat;
  auto add = [&](PartClass c) {
    // The built-in entries are constants: a failure here is a programming error in this file,
    // caught by catalogue_test (EveryBuiltInClassIsValid).
    (void)cat.add(std::move(c));
  };
  // DIP ICs: nominal body sizes of JEDEC MS-001 (0.3" rows) and MS-011 (0.6" rows); 22 pins
  // use the 0.4" package. Length along the pin rows, width the body without leads.
  constexpr double k3 = 7.62;
  constexpr double k4 = 10.16;
  constexpr double k6 = 15.24;
  add(make_dip("dip8", 8, 9.27, 6.35, k3, "DIP-8, 0.3 in (JEDEC MS-001)"));
  add(make_dip("dip14", 14, 19.05, 6.35, k3, "DIP-14, 0.3 in (JEDEC MS-001)"));
  add(make_dip("dip16", 16, 19.30, 6.35, k3, "DIP-16, 0.3 in (JEDEC MS-001)"));
  add(make_dip("dip18", 18, 22.86, 6.35, k3, "DIP-18, 0.3 in (JEDEC MS-001)"));
  add(make_dip("dip20", 20, 26.16, 6.35, k3, "DIP-20, 0.3 in (JEDEC MS-001)"));
  add(make_dip("dip22", 22, 27.94, 8.89, k4, "DIP-22, 0.4 in"));
  add(make_dip("dip24n", 24, 31.75, 6.35, k3, "DIP-24 skinny, 0.3 in (JEDEC MS-001)"));
  add(make_dip("dip28n", 28, 35.56, 6.35, k3, "DIP-28 skinny, 0.3 in (JEDEC MS-001)"));
  add(make_dip("dip24", 24, 31.75, 13.72, k6, "DIP-24, 0.6 in (JEDEC MS-011)"));
  add(make_dip("dip28", 28, 36.83, 13.72, k6, "DIP-28, 0.6 in (JEDEC MS-011)"));
  add(make_dip("dip32", 32, 41.91, 13.72, k6, "DIP-32, 0.6 in (JEDEC MS-011)"));
  add(make_dip("dip40", 40, 52.07, 13.72, k6, "DIP-40, 0.6 in (JEDEC MS-011)"));
  // The thesis's own ICs (digest 000 §3, §7): the 14-pin "6x19 mm" package and the "7x30 mm"
  // ICs of which ~15 fit the image window. The thesis gives no pin count for the 7x30 one;
  // 24 pins at 2.54 mm is what a 30 mm, 0.3 in body carries.
  add(make_dip("ic_6x19", 14, 19.0, 6.0, k3, "thesis 14-pin 6 x 19 mm IC (digest 000 §3)"));
  add(make_dip("ic_7x30", 24, 30.0, 7.0, k3, "thesis 7 x 30 mm IC (digest 000 §7), 24 pins"));
  // Generic flat shapes (the thesis's chapter 2 classes; a scene may define its own sizes) and
  // a box. Black on the white table, like the ICs.
  add(make_prism("rectangle", Shape::kRectangle, 40.0, 20.0, 5.0, 0.1, "flat rectangle"));
  add(make_prism("square", Shape::kSquare, 20.0, 20.0, 5.0, 0.1, "flat square"));
  add(make_prism("disc", Shape::kDisc, 20.0, 20.0, 5.0, 0.1, "flat disc, 20 mm diameter"));
  add(make_prism("triangle", Shape::kTriangle, 25.0, 0.0, 5.0, 0.1,
                 "flat equilateral triangle, 25 mm side"));
  add(make_prism("box", Shape::kBox, 40.0, 30.0, 20.0, 0.5, "box 40 x 30 x 20 mm"));
  // RAPT blocks (digest 003 §6.1, Appendix V; §6.2, Appendix VI), meshed from the thesis's
  // point lists; cylindrical features (b1's shaft s1, b2's hole h1, b3's holes h1, h2) are not
  // meshed. part_T_model maps the thesis's body frame into the part frame.
  add(make_polyhedron("rapt_b1", box_mesh(0, 20, -20, 0, 0, 30), 0.6,
                      "RAPT App. V body b1: 20 x 20 x 30 mm block (shaft s1 not meshed)"));
  add(make_polyhedron("rapt_b2", box_mesh(0, 25, -30, 0, 0, 50), 0.6,
                      "RAPT App. V body b2: 25 x 30 x 50 mm block (hole h1 not meshed)"));
  add(make_polyhedron("rapt_b3", rapt_b3_mesh(), 0.6,
                      "RAPT App. V body b3: 20 x 30 x 140 mm column with a 40 mm arm at "
                      "z 50..90 (holes not meshed)"));
  {
    // App. VI: the gripper's outer case, x 0..72, y +-27.5, z +-81.5, resting on its face
    // x = 0 (the thesis's table is the plane x = 0 with x vertical). Model x -> part z,
    // model z -> part x: part_T_model = Trans * rotation below.
    Eigen::Matrix3d part_R_model;  // columns: model x -> part z, y -> y, z -> part -x
    part_R_model << 0, 0, -1,      //
        0, 1, 0,                   //
        1, 0, 0;
    Mesh model = box_mesh(0, 72, -27.5, 27.5, -81.5, 81.5);
    Mesh turned = model;
    for (auto& v : turned.vertices) {
      v = part_R_model * v;
    }
    PartClass c = make_polyhedron("rapt_case", turned, 0.4,
                                  "RAPT App. VI body 'box': the gripper case, 72 x 55 x 163 mm, "
                                  "lying on its face x = 0");
    Eigen::Isometry3d rot = Eigen::Isometry3d::Identity();
    rot.linear() = part_R_model;
    c.part_T_model = c.part_T_model * rot;
    add(std::move(c));
  }
  return cat;
}

Status Catalogue::add(PartClass cls) {
  cls.finalize();
  CELL_TRY(cls.validate());
  if (classes_.contains(cls.name)) {
    return Error{Errc::kInvalidArgument, fmt::format("part class '{}' is defined twice", cls.name)};
  }
  auto name = cls.name;
  classes_.emplace(std::move(name), std::make_shared<const PartClass>(std::move(cls)));
  return ok_status();
}

std::shared_ptr<const PartClass> Catalogue::find(std::string_view name) const {
  const auto it = classes_.find(name);
  return it == classes_.end() ? nullptr : it->second;
}

std::vector<std::string> Catalogue::names() const {
  std::vector<std::string> out;
  out.reserve(classes_.size());
  for (const auto& [name, cls] : classes_) {
    out.push_back(name);
  }
  return out;
}

std::string Catalogue::list() const {
  std::string out;
  for (const auto& [name, cls] : classes_) {
    out += (out.empty() ? "" : ", ") + name;
  }
  return out;
}

}  // namespace cell::world
