#include "cell/world/scene.hpp"

#include <fmt/format.h>

#include <array>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <numbers>
#include <set>
#include <sstream>
#include <vector>

#include "cell/config/yaml.hpp"
#include "cell/geometry/angles.hpp"
#include "cell/geometry/pose.hpp"
#include "checks.hpp"

namespace cell::world {
namespace {

using geometry::deg_to_rad;

using detail::finite_positive;
using detail::kMaxCoordinateMm;

void check_range(config::MapReader& r, const char* key, const std::array<double, 2>& range) {
  if (!(range[0] < range[1])) {
    r.fail(key, fmt::format("must be [min, max] with min < max, got [{}, {}]", range[0], range[1]));
  } else if (std::abs(range[0]) > kMaxCoordinateMm || std::abs(range[1]) > kMaxCoordinateMm) {
    r.fail(key, fmt::format("must lie within +-{} mm", kMaxCoordinateMm));
  }
}

void read_table(config::MapReader& root, Table& table) {
  config::MapReader t = root.child("table", false);
  std::array<double, 2> x{table.x_min_mm, table.x_max_mm};
  std::array<double, 2> y{table.y_min_mm, table.y_max_mm};
  t.optional("height_mm", table.height_mm);
  t.optional("x_mm", x);
  t.optional("y_mm", y);
  t.optional("reflectance", table.reflectance);
  if (!(table.height_mm >= 0.0 && table.height_mm <= 1e4)) {
    t.fail("height_mm", fmt::format("must be in [0, 10000] mm, got {}", table.height_mm));
  }
  if (!(table.reflectance >= 0.0 && table.reflectance <= 1.0)) {
    t.fail("reflectance", fmt::format("must be in [0, 1], got {}", table.reflectance));
  }
  check_range(t, "x_mm", x);
  check_range(t, "y_mm", y);
  table.x_min_mm = x[0];
  table.x_max_mm = x[1];
  table.y_min_mm = y[0];
  table.y_max_mm = y[1];
  root.absorb(t);
}

/// One entry of `classes:`.
void read_class(config::MapReader& r,
                const Catalogue& catalogue,
                const std::vector<PartClass>& earlier,
                std::vector<PartClass>& out) {
  std::string name;
  std::string shape_text;
  std::string description;
  r.required("name", name);
  r.required("shape", shape_text);
  r.optional("description", description);
  auto give_up = [&r]() {  // the other keys are not "unknown" on top of the real error
    for (const char* key :
         {"length_mm", "width_mm", "height_mm", "reflectance", "pins", "row_spacing_mm",
          "yaw_symmetry", "grasp_xyz_mm", "grasp_yaws_deg", "mesh"}) {
      (void)r.has(key);
    }
  };
  const auto shape = shape_from_string(shape_text);
  if (!shape) {
    r.fail("shape", shape.error().message);
    give_up();
    return;
  }
  if (!name.empty() && catalogue.find(name) != nullptr) {
    r.fail("name", fmt::format("class '{}' is already in the catalogue", name));
  }
  for (const auto& c : earlier) {
    if (c.name == name) {
      r.fail("name", fmt::format("class '{}' is defined twice", name));
    }
  }
  double length = 0.0;
  double width = 0.0;
  double height = 0.0;
  PartClass cls;
  if (*shape == Shape::kPolyhedron) {
    config::MapReader m = r.child("mesh");
    std::vector<std::array<double, 3>> vertices;
    std::vector<std::vector<std::uint32_t>> faces;
    m.required("vertices_mm", vertices);
    m.required("faces", faces);
    r.absorb(m);
    Mesh mesh;
    for (const auto& v : vertices) {
      mesh.vertices.emplace_back(v[0], v[1], v[2]);
    }
    mesh.faces = faces;
    if (auto s = mesh.validate(); !s) {
      r.fail("mesh", s.error().message);
      give_up();
      return;
    }
    double reflectance = 0.6;
    r.optional("reflectance", reflectance);
    cls = make_polyhedron(name, mesh, reflectance, description);
  } else if (*shape == Shape::kDip) {
    int pins = 0;
    r.required("pins", pins);
    r.required("length_mm", length);
    r.required("width_mm", width);
    double row_spacing = width > 10.0 ? 15.24 : 7.62;
    r.optional("row_spacing_mm", row_spacing);
    cls = make_dip(name, pins, length, width, row_spacing, description);
    r.optional("reflectance", cls.reflectance);
  } else {
    r.required("length_mm", length);
    if (*shape == Shape::kRectangle || *shape == Shape::kBox) {
      r.required("width_mm", width);
    } else {
      width = length;
    }
    r.required("height_mm", height);
    double reflectance = *shape == Shape::kBox ? 0.5 : 0.1;
    r.optional("reflectance", reflectance);
    cls = make_prism(name, *shape, length, width, height, reflectance, description);
  }
  r.optional("yaw_symmetry", cls.yaw_symmetry);
  if (r.has("grasp_xyz_mm")) {
    std::array<double, 3> grasp{};
    r.required("grasp_xyz_mm", grasp);
    cls.part_T_grasp = Eigen::Isometry3d(Eigen::Translation3d(grasp[0], grasp[1], grasp[2]));
  }
  if (r.has("grasp_yaws_deg")) {
    // Left as the NaN when the value is not a list of finite numbers (the reader said so).
    std::vector<double> yaws_deg = {std::numeric_limits<double>::quiet_NaN()};
    r.required("grasp_yaws_deg", yaws_deg);
    if (yaws_deg.empty()) {
      r.fail("grasp_yaws_deg", "must list at least one yaw [deg], e.g. [0, 90]");
    } else if (std::isfinite(yaws_deg[0])) {
      cls.grasp_yaws_rad.clear();
      for (const double yaw_deg : yaws_deg) {
        cls.grasp_yaws_rad.push_back(deg_to_rad(yaw_deg));
      }
    }
  }
  cls.finalize();
  if (auto s = cls.validate(); !s) {
    r.fail("", s.error().message);
    return;
  }
  out.push_back(std::move(cls));
}

void read_belt(config::MapReader& r, std::vector<BeltSpec>& belts) {
  BeltSpec b;
  std::array<double, 3> origin{0, 0, 0};
  double direction_deg = 0.0;
  r.required("id", b.id);
  r.required("origin_mm", origin);
  r.optional("direction_deg", direction_deg);
  r.required("length_mm", b.length_mm);
  r.required("width_mm", b.width_mm);
  r.optional("speed_mm_s", b.speed_mm_s);
  r.optional("encoder_sign", b.encoder_sign);
  r.optional("photocell_at_mm", b.photocell_at_mm);
  r.optional("reflectance", b.reflectance);
  // Encoder scale: mm_per_count directly, or counts_per_rev of a roller of roller_diameter_mm
  // with x1/x2/x4 quadrature decoding (digest 002 §6.2 T9: 1024 ppr on a 50 mm roller).
  const bool direct = r.has("mm_per_count");
  const bool roller = r.has("counts_per_rev") || r.has("roller_diameter_mm");
  if (direct == roller) {
    r.fail("", "give either mm_per_count, or counts_per_rev with roller_diameter_mm");
  } else if (direct) {
    r.required("mm_per_count", b.mm_per_count);
  } else {
    std::uint32_t counts_per_rev = 0;
    double diameter = 0.0;
    std::uint32_t quadrature = 1;
    r.required("counts_per_rev", counts_per_rev);
    r.required("roller_diameter_mm", diameter);
    r.optional("quadrature", quadrature);
    if (quadrature != 1 && quadrature != 2 && quadrature != 4) {
      r.fail("quadrature", fmt::format("must be 1, 2 or 4, got {}", quadrature));
    } else if (counts_per_rev == 0 || !finite_positive(diameter)) {
      r.fail("counts_per_rev", "counts_per_rev and roller_diameter_mm must be > 0");
    } else {
      b.mm_per_count = std::numbers::pi * diameter /
                       (static_cast<double>(counts_per_rev) * static_cast<double>(quadrature));
    }
  }
  b.origin_mm = Eigen::Vector3d(origin[0], origin[1], origin[2]);
  b.direction_rad = deg_to_rad(direction_deg);
  b.where = r.where("");
  if (!b.origin_mm.allFinite() || b.origin_mm.cwiseAbs().maxCoeff() > kMaxCoordinateMm) {
    r.fail("origin_mm", fmt::format("must lie within +-{} mm", kMaxCoordinateMm));
  }
  if (auto s = b.validate(); !s) {
    r.fail("", s.error().message);
  }
  for (const auto& other : belts) {
    if (other.id == b.id) {
      r.fail("id", fmt::format("belt '{}' is defined twice", b.id));
    }
  }
  belts.push_back(std::move(b));
}

void read_part(config::MapReader& r,
               const Catalogue& catalogue,
               const std::vector<PartClass>& scene_classes,
               std::set<std::string>& ids,
               std::vector<PartPlacement>& parts) {
  PartPlacement p;
  r.optional("id", p.id);
  r.required("class", p.class_name);
  p.where = r.where("");
  if (!p.class_name.empty() && catalogue.find(p.class_name) == nullptr) {
    bool known = false;
    std::string scene_names;
    for (const auto& c : scene_classes) {
      known = known || c.name == p.class_name;
      scene_names += ", " + c.name;
    }
    if (!known) {
      r.fail("class", fmt::format("unknown part class '{}' (known: {}{})", p.class_name,
                                  catalogue.list(), scene_names));
    }
  }
  if (!p.id.empty()) {
    if (p.id.find_first_of("/ \t") != std::string::npos) {
      r.fail("id", fmt::format("part id '{}' must not contain '/' or blanks", p.id));
    } else if (!ids.insert(p.id).second) {
      r.fail("id", fmt::format("part id '{}' is used twice", p.id));
    }
  }
  const bool planar = r.has("x_mm") || r.has("y_mm") || r.has("yaw_deg");
  const bool full = r.has("pose");
  if (planar == full) {
    r.fail("", "give either x_mm, y_mm (and yaw_deg), or pose: {xyz_mm, rpy_deg}");
  } else if (planar) {
    r.required("x_mm", p.x_mm);
    r.required("y_mm", p.y_mm);
    r.optional_deg("yaw_deg", p.yaw);
    if (std::abs(p.x_mm) > kMaxCoordinateMm || std::abs(p.y_mm) > kMaxCoordinateMm) {
      r.fail("", fmt::format("x_mm and y_mm must lie within +-{} mm", kMaxCoordinateMm));
    }
  } else {
    config::MapReader pose = r.child("pose");
    std::array<double, 3> xyz{0, 0, 0};
    std::array<double, 3> rpy_deg{0, 0, 0};
    pose.required("xyz_mm", xyz);
    pose.optional("rpy_deg", rpy_deg);
    r.absorb(pose);
    const Eigen::Vector3d t(xyz[0], xyz[1], xyz[2]);
    if (t.cwiseAbs().maxCoeff() > kMaxCoordinateMm) {
      r.fail("pose", fmt::format("xyz_mm must lie within +-{} mm", kMaxCoordinateMm));
    }
    p.pose = geometry::make_pose(
        t, geometry::Rpy{deg_to_rad(rpy_deg[0]), deg_to_rad(rpy_deg[1]), deg_to_rad(rpy_deg[2])});
  }
  parts.push_back(std::move(p));
}

void read_feeder(config::MapReader& r, const Catalogue& catalogue,
                 const std::vector<PartClass>& scene_classes, std::vector<FeederSpec>& out) {
  FeederSpec f;
  std::array<double, 2> yaw_deg{-180.0, 180.0};
  std::int64_t seed = 1;
  r.required("belt", f.belt);
  r.required("classes", f.classes);
  r.required("period_s", f.period_s);
  r.optional("start_mm", f.start_mm);
  r.optional("lateral_mm", f.lateral_mm);
  r.optional("yaw_deg", yaw_deg);
  r.optional("count", f.count);
  r.optional("seed", seed);
  if (seed < 0) {
    r.fail("seed", fmt::format("must be >= 0, got {}", seed));
  }
  f.seed = static_cast<std::uint64_t>(seed);
  f.yaw_min = deg_to_rad(yaw_deg[0]);
  f.yaw_max = deg_to_rad(yaw_deg[1]);
  f.where = r.where("");
  for (const auto& name : f.classes) {
    bool known = catalogue.find(name) != nullptr;
    for (const auto& c : scene_classes) {
      known = known || c.name == name;
    }
    if (!known) {
      r.fail("classes", fmt::format("unknown part class '{}' (known: {})", name, catalogue.list()));
    }
  }
  if (auto st = f.validate(); !st) {
    r.fail("", st.error().message);
  }
  out.push_back(std::move(f));
}

void read_scatter(config::MapReader& r,
                  const Catalogue& catalogue,
                  const std::vector<PartClass>& scene_classes,
                  std::vector<ScatterSpec>& out) {
  ScatterSpec s;
  std::array<double, 2> x{0, 0};
  std::array<double, 2> y{0, 0};
  std::array<double, 2> yaw_deg{-180.0, 180.0};
  std::int64_t seed = 1;
  r.required("count", s.count);
  r.required("classes", s.classes);
  r.required("x_mm", x);
  r.required("y_mm", y);
  r.optional("yaw_deg", yaw_deg);
  r.optional("min_separation_mm", s.min_separation_mm);
  r.optional("seed", seed);
  r.optional("max_attempts_per_part", s.max_attempts_per_part);
  if (seed < 0) {
    r.fail("seed", fmt::format("must be >= 0, got {}", seed));
  }
  s.seed = static_cast<std::uint64_t>(seed);
  s.x_min_mm = x[0];
  s.x_max_mm = x[1];
  s.y_min_mm = y[0];
  s.y_max_mm = y[1];
  s.yaw_min = deg_to_rad(yaw_deg[0]);
  s.yaw_max = deg_to_rad(yaw_deg[1]);
  s.where = r.where("");
  check_range(r, "x_mm", x);
  check_range(r, "y_mm", y);
  for (const auto& name : s.classes) {
    bool known = catalogue.find(name) != nullptr;
    for (const auto& c : scene_classes) {
      known = known || c.name == name;
    }
    if (!known) {
      r.fail("classes", fmt::format("unknown part class '{}' (known: {})", name, catalogue.list()));
    }
  }
  if (auto st = s.validate(); !st) {
    r.fail("", st.error().message);
  }
  out.push_back(std::move(s));
}

}  // namespace

Eigen::Vector3d BeltSpec::direction() const noexcept {
  return {std::cos(direction_rad), std::sin(direction_rad), 0.0};
}

Status BeltSpec::validate() const {
  auto bad = [this](const std::string& what) {
    return Error{Errc::kInvalidArgument, fmt::format("belt '{}': {}", id, what)};
  };
  if (id.empty() || id.find_first_of("/ \t") != std::string::npos) {
    return bad("id must be non-empty without '/' or blanks");
  }
  if (!finite_positive(length_mm) || !finite_positive(width_mm)) {
    return bad(
        fmt::format("length_mm and width_mm must be > 0, got {} and {}", length_mm, width_mm));
  }
  if (!finite_positive(mm_per_count)) {
    return bad(fmt::format("mm_per_count must be > 0, got {}", mm_per_count));
  }
  if (!std::isfinite(speed_mm_s) || std::abs(speed_mm_s) > 1e5) {
    return bad(fmt::format("speed_mm_s must be finite and within +-100000, got {}", speed_mm_s));
  }
  if (encoder_sign != 1 && encoder_sign != -1) {
    return bad(fmt::format("encoder_sign must be 1 or -1, got {}", encoder_sign));
  }
  if (!(photocell_at_mm >= 0.0 && photocell_at_mm <= length_mm)) {
    return bad(fmt::format("photocell_at_mm must be in [0, length_mm = {}], got {}", length_mm,
                           photocell_at_mm));
  }
  if (!std::isfinite(direction_rad) || !origin_mm.allFinite()) {
    return bad("origin and direction must be finite");
  }
  if (!(reflectance >= 0.0 && reflectance <= 1.0)) {
    return bad(fmt::format("reflectance must be in [0, 1], got {}", reflectance));
  }
  return ok_status();
}

Status FeederSpec::validate() const {
  auto bad = [](const std::string& what) {
    return Error{Errc::kInvalidArgument, "feeder: " + what};
  };
  if (belt.empty()) {
    return bad("belt is empty");
  }
  if (classes.empty()) {
    return bad("classes must name at least one part class");
  }
  if (!(period_s > 0.0) || !std::isfinite(period_s)) {
    return bad(fmt::format("period_s must be > 0, got {}", period_s));
  }
  if (!(start_mm >= 0.0) || !std::isfinite(start_mm) || !(lateral_mm >= 0.0) ||
      !std::isfinite(lateral_mm)) {
    return bad("start_mm and lateral_mm must be >= 0");
  }
  if (!(yaw_min <= yaw_max) || !std::isfinite(yaw_min) || !std::isfinite(yaw_max)) {
    return bad("yaw range must be [min, max] with min <= max");
  }
  return ok_status();
}

Status ScatterSpec::validate() const {
  auto bad = [](const std::string& what) {
    return Error{Errc::kInvalidArgument, "scatter: " + what};
  };
  if (classes.empty()) {
    return bad("classes must name at least one part class");
  }
  if (count > 100000) {
    return bad(fmt::format("count must be <= 100000, got {}", count));
  }
  if (!(x_min_mm < x_max_mm && y_min_mm < y_max_mm) || !std::isfinite(x_min_mm) ||
      !std::isfinite(x_max_mm) || !std::isfinite(y_min_mm) || !std::isfinite(y_max_mm)) {
    return bad(fmt::format("the region x [{}, {}] y [{}, {}] mm is empty", x_min_mm, x_max_mm,
                           y_min_mm, y_max_mm));
  }
  if (!(yaw_min <= yaw_max) || !std::isfinite(yaw_min) || !std::isfinite(yaw_max)) {
    return bad("yaw range must be [min, max] with min <= max");
  }
  if (!(min_separation_mm >= 0.0 && min_separation_mm < 1e4)) {
    return bad(fmt::format("min_separation_mm must be in [0, 10000), got {}", min_separation_mm));
  }
  if (max_attempts_per_part == 0 || max_attempts_per_part > 100000) {
    return bad("max_attempts_per_part must be 1..100000");
  }
  return ok_status();
}

Result<Scene> parse_scene(const std::string& text,
                          const std::string& origin,
                          const Catalogue& catalogue) {
  auto doc = config::load_string(text, origin);
  if (!doc) {
    return std::move(doc).error();
  }
  Scene scene;
  scene.source = origin;
  scene.name = std::filesystem::path(origin).stem().string();
  config::MapReader root(*doc, doc->root, "");
  root.optional("name", scene.name);
  read_table(root, scene.table);
  root.optional("min_separation_mm", scene.min_separation_mm);
  if (!(scene.min_separation_mm >= 0.0 && scene.min_separation_mm < 1e4)) {
    root.fail("min_separation_mm",
              fmt::format("must be in [0, 10000) mm, got {}", scene.min_separation_mm));
  }
  const auto classes = root.sequence("classes", false);
  for (std::size_t i = 0; i < classes.size(); ++i) {
    config::MapReader r = root.element(classes[i], fmt::format("classes[{}]", i));
    read_class(r, catalogue, scene.classes, scene.classes);
    root.absorb(r);
  }
  const auto belts = root.sequence("belts", false);
  for (std::size_t i = 0; i < belts.size(); ++i) {
    config::MapReader r = root.element(belts[i], fmt::format("belts[{}]", i));
    read_belt(r, scene.belts);
    root.absorb(r);
  }
  std::set<std::string> ids;
  const auto parts = root.sequence("parts", false);
  for (std::size_t i = 0; i < parts.size(); ++i) {
    config::MapReader r = root.element(parts[i], fmt::format("parts[{}]", i));
    read_part(r, catalogue, scene.classes, ids, scene.parts);
    root.absorb(r);
  }
  const auto feeders = root.sequence("feeders", false);
  for (std::size_t i = 0; i < feeders.size(); ++i) {
    config::MapReader r = root.element(feeders[i], fmt::format("feeders[{}]", i));
    read_feeder(r, catalogue, scene.classes, scene.feeders);
    root.absorb(r);
  }
  const auto scatter = root.sequence("scatter", false);
  for (std::size_t i = 0; i < scatter.size(); ++i) {
    config::MapReader r = root.element(scatter[i], fmt::format("scatter[{}]", i));
    read_scatter(r, catalogue, scene.classes, scene.scatter);
    root.absorb(r);
  }
  CELL_TRY(root.finish());
  return scene;
}

Result<Scene> load_scene_file(const std::string& path, const Catalogue& catalogue) {
  std::ifstream in(path);
  if (!in) {
    return Error{Errc::kConfig, fmt::format("{}: cannot open: {}", path, std::strerror(errno))};
  }
  std::stringstream buffer;
  buffer << in.rdbuf();
  return parse_scene(buffer.str(), path, catalogue);
}

}  // namespace cell::world
