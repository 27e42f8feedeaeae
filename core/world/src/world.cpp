#include "cell/world/world.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <random>
#include <set>

#include "cell/geometry/angles.hpp"
#include "cell/geometry/pose.hpp"
#include "checks.hpp"

namespace cell::world {
namespace {

using detail::kMaxCoordinateMm;
using geometry::rad_to_deg;

// A part released this far below a surface was pushed into it (a tool driven a little too
// deep): it comes to rest on that surface rather than falling through to the one beneath.
constexpr double kSupportEpsMm = 50.0;
constexpr double kFloorHeightMm = 0.0;    // the world's floor (scene.hpp)
constexpr double kUprightCos = 1.0 - 1e-9;
constexpr double kGridCellMm = 50.0;

bool closed_like(GripperState g) {
  return g == GripperState::kClosed || g == GripperState::kClosing;
}
bool open_like(GripperState g) { return g == GripperState::kOpen || g == GripperState::kOpening; }

/// Yaw of a frame's x axis projected on the world x-y plane [rad].
double yaw_of(const Eigen::Matrix3d& r) { return std::atan2(r(1, 0), r(0, 0)); }

/// Angle folded by an n-fold symmetry into [-pi/n, pi/n] (n = 0: any angle is 0).
double fold(double angle, int symmetry) {
  if (symmetry <= 0) {
    return 0.0;
  }
  return std::remainder(angle, 2.0 * std::numbers::pi / symmetry);
}

/// The tool's yaw error from the part's nearest grasp [rad]: over the class's grasp yaws g,
/// the smallest fold(tool_yaw - (grasp_yaw + g), yaw_symmetry) in magnitude (signed).
double grasp_yaw_error(double tool_yaw, double grasp_yaw, const PartClass& cls) {
  double best = std::numeric_limits<double>::infinity();
  for (const double g : cls.grasp_yaws_rad) {
    const double e = fold(tool_yaw - (grasp_yaw + g), cls.yaw_symmetry);
    if (std::abs(e) < std::abs(best)) {
      best = e;
    }
  }
  return std::isfinite(best) ? best : fold(tool_yaw - grasp_yaw, cls.yaw_symmetry);
}

/// Uniform double in [a, b) from 53 random bits: the same sequence on every platform
/// (std::uniform_real_distribution is implementation-defined).
double uniform(std::mt19937_64& rng, double a, double b) {
  const double unit = static_cast<double>(rng() >> 11) * 0x1.0p-53;
  return a + (b - a) * unit;
}

Footprint footprint_of(const PartClass& cls, const Eigen::Isometry3d& world_T_part) {
  if (world_T_part.linear()(2, 2) > kUprightCos) {
    return place_footprint(cls.footprint, world_T_part.translation().x(),
                           world_T_part.translation().y(), yaw_of(world_T_part.linear()));
  }
  return project_footprint(cls.hull_points, world_T_part);
}

Eigen::Isometry3d planar(double x, double y, double z, double yaw) {
  Eigen::Isometry3d t = Eigen::Isometry3d::Identity();
  t.linear() = Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  t.translation() = Eigen::Vector3d(x, y, z);
  return t;
}

std::string describe_conflict(const Part& part, const Part& other, double min_separation_mm) {
  const std::string other_where = other.where.empty() ? "" : ", declared at " + other.where;
  if (intersects(part.footprint, other.footprint)) {
    return fmt::format("part '{}' ({}) overlaps part '{}' ({}{})", part.id, part.cls->name,
                       other.id, other.cls->name, other_where);
  }
  return fmt::format(
      "part '{}' ({}) is {:.2f} mm from part '{}' ({}{}), closer than "
      "min_separation_mm {}",
      part.id, part.cls->name, distance(part.footprint, other.footprint), other.id, other.cls->name,
      other_where, min_separation_mm);
}

}  // namespace

std::string Support::name() const {
  switch (kind) {
    case Kind::kTable:
      return "table";
    case Kind::kBelt:
      return "belt/" + id;
    case Kind::kRobot:
      return "robot/" + id;
    case Kind::kFloor:
      return "floor";
  }
  return "unknown";
}

std::string_view to_string(WorldEvent::Kind kind) noexcept {
  switch (kind) {
    case WorldEvent::Kind::kPhotocell:
      return "photocell";
    case WorldEvent::Kind::kAttached:
      return "attached";
    case WorldEvent::Kind::kMissed:
      return "missed";
    case WorldEvent::Kind::kReleased:
      return "released";
    case WorldEvent::Kind::kFellOffBelt:
      return "fell_off_belt";
    case WorldEvent::Kind::kFed:
      return "fed";
  }
  return "unknown";
}

Status WorldOptions::validate() const {
  auto positive = [](double v) { return std::isfinite(v) && v > 0.0; };
  if (!positive(capture_tolerance_mm)) {
    return Error{Errc::kInvalidArgument,
                 fmt::format("capture_tolerance_mm must be > 0, got {}", capture_tolerance_mm)};
  }
  if (!positive(capture_yaw_tolerance) || capture_yaw_tolerance > std::numbers::pi) {
    return Error{Errc::kInvalidArgument, "capture yaw tolerance must be in (0, 180] deg"};
  }
  if (!positive(capture_tilt_tolerance) || capture_tilt_tolerance > std::numbers::pi / 2) {
    return Error{Errc::kInvalidArgument, "capture tilt tolerance must be in (0, 90] deg"};
  }
  std::set<std::string> ids;
  for (const auto& r : robots) {
    if (r.robot_id.empty()) {
      return Error{Errc::kInvalidArgument, "robots: a robot id is empty"};
    }
    if (!ids.insert(r.robot_id).second) {
      return Error{Errc::kInvalidArgument,
                   fmt::format("robots: robot '{}' is mounted twice", r.robot_id)};
    }
    CELL_TRY(geometry::check_rigid(r.world_T_base, "world_T_base of " + r.robot_id));
  }
  return ok_status();
}

Result<World> World::create(const Scene& scene,
                            const Catalogue& catalogue,
                            const WorldOptions& options) {
  if (auto s = options.validate(); !s) {
    return Error{Errc::kConfig, s.error().message};
  }
  World w;
  w.catalogue_ = catalogue;
  w.options_ = options;
  w.scene_name_ = scene.name;
  w.table_ = scene.table;
  w.min_separation_mm_ = scene.min_separation_mm;
  std::vector<std::string> errors;
  for (const auto& cls : scene.classes) {
    if (auto s = w.catalogue_.add(cls); !s) {
      errors.push_back(fmt::format("{}: {}", scene.source, s.error().message));
    }
  }
  for (const auto& spec : scene.belts) {
    if (auto s = spec.validate(); !s) {
      errors.push_back(fmt::format("{}: {}", spec.where, s.error().message));
      continue;
    }
    if (w.find_belt(spec.id) != nullptr) {
      errors.push_back(fmt::format("{}: belt '{}' is defined twice", spec.where, spec.id));
      continue;
    }
    Belt belt;
    belt.spec = spec;
    w.belts_.push_back(std::move(belt));
  }
  for (const auto& r : options.robots) {
    w.robots_.push_back(RobotSlot{r, std::nullopt, GripperState::kUnknown});
  }
  // Ids given in the scene are reserved before any is assigned, so that "p3" given explicitly
  // further down never clashes with an assigned one.
  for (const auto& p : scene.parts) {
    if (!p.id.empty()) {
      w.reserved_ids_.insert(p.id);
    }
  }
  FootprintGrid grid(kGridCellMm);
  for (const auto& placement : scene.parts) {
    auto part = w.make_part(placement);
    if (!part) {
      errors.push_back(fmt::format("{}: {}", placement.where, part.error().message));
      continue;
    }
    part->where = placement.where;
    if (part->id.empty()) {
      part->id = w.next_id();
    }
    const Part* conflict = nullptr;
    grid.for_each_candidate(part->footprint, scene.min_separation_mm, [&](std::size_t i) {
      const Part& other = w.parts_[i];
      if (conflict == nullptr && other.support == part->support &&
          too_close(part->footprint, other.footprint, scene.min_separation_mm)) {
        conflict = &other;
      }
    });
    if (conflict != nullptr) {
      errors.push_back(fmt::format("{}: {}", placement.where,
                                   describe_conflict(*part, *conflict, scene.min_separation_mm)));
      continue;
    }
    grid.insert(w.parts_.size(), part->footprint);
    w.parts_.push_back(std::move(*part));
  }
  w.reserved_ids_.clear();
  if (!errors.empty()) {
    // Scatter generators run against the scene's parts: report the parts' problems first.
    std::string message;
    for (const auto& e : errors) {
      message += (message.empty() ? "" : "\n") + e;
    }
    return Error{Errc::kConfig, message};
  }
  for (const auto& spec : scene.scatter) {
    if (auto placed = w.scatter(spec); !placed) {
      errors.push_back(fmt::format("{}: {}", spec.where, placed.error().message));
    }
  }
  if (!errors.empty()) {
    std::string message;
    for (const auto& e : errors) {
      message += (message.empty() ? "" : "\n") + e;
    }
    return Error{Errc::kConfig, message};
  }
  if (!scene.scatter.empty()) {
    w.default_scatter_ = scene.scatter.front();
    w.default_scatter_.count = 0;
  } else {
    ScatterSpec& d = w.default_scatter_;
    constexpr double kMarginMm = 30.0;
    d.x_min_mm = w.table_.x_min_mm + kMarginMm;
    d.x_max_mm = std::max(d.x_min_mm + 1.0, w.table_.x_max_mm - kMarginMm);
    d.y_min_mm = w.table_.y_min_mm + kMarginMm;
    d.y_max_mm = std::max(d.y_min_mm + 1.0, w.table_.y_max_mm - kMarginMm);
    d.min_separation_mm = scene.min_separation_mm;
    d.classes = {"dip14"};
    d.where = scene.source;
  }
  for (const auto& f : scene.feeders) {
    if (w.find_belt(f.belt) == nullptr) {
      errors.push_back(fmt::format("{}: feeder: unknown belt '{}'", f.where, f.belt));
      continue;
    }
    FeederState state;
    state.spec = f;
    state.next_s = f.period_s;
    state.rng.seed(f.seed);
    w.feeders_.push_back(std::move(state));
  }
  if (!errors.empty()) {
    std::string message;
    for (const auto& e : errors) {
      message += (message.empty() ? "" : "\n") + e;
    }
    return Error{Errc::kConfig, message};
  }
  w.seq_ = 1;
  return w;
}

std::pair<std::uint32_t, std::uint64_t> World::feeder_counts(std::string_view belt_id) const {
  for (const auto& f : feeders_) {
    if (f.spec.belt == belt_id) {
      return {f.fed, f.jammed};
    }
  }
  return {0, 0};
}

void World::step_feeders(std::vector<WorldEvent>& events) {
  for (FeederState& f : feeders_) {
    while (time_s_ >= f.next_s && (f.spec.count == 0 || f.fed < f.spec.count)) {
      f.next_s += f.spec.period_s;
      const Belt* belt = find_belt(f.spec.belt);
      if (belt == nullptr) {
        break;
      }
      const std::size_t k =
          static_cast<std::size_t>(uniform(f.rng, 0.0, static_cast<double>(f.spec.classes.size())));
      const double lateral = uniform(f.rng, -f.spec.lateral_mm, f.spec.lateral_mm);
      const double yaw = uniform(f.rng, f.spec.yaw_min, f.spec.yaw_max);
      const Eigen::Vector3d dir = belt->spec.direction();
      const Eigen::Vector3d across(-dir.y(), dir.x(), 0.0);
      const Eigen::Vector3d at = belt->spec.origin_mm + dir * f.spec.start_mm + across * lateral;
      PartPlacement p;
      p.class_name = f.spec.classes[std::min(k, f.spec.classes.size() - 1)];
      p.x_mm = at.x();
      p.y_mm = at.y();
      p.yaw = yaw;
      WorldEvent e;
      e.kind = WorldEvent::Kind::kFed;
      e.time_s = time_s_;
      e.belt_id = f.spec.belt;
      auto id = spawn(p, min_separation_mm_);
      if (id) {
        ++f.fed;
        e.part_id = *id;
        e.detail = fmt::format("{} fed onto {}", p.class_name, f.spec.belt);
      } else {
        ++f.jammed;
        e.detail = fmt::format("jammed: {}", id.error().message);
      }
      events.push_back(std::move(e));
    }
  }
}

std::string World::next_id() {
  for (;;) {
    std::string id = fmt::format("p{}", next_auto_id_++);
    if (find(id) == nullptr && !reserved_ids_.contains(id)) {
      return id;
    }
  }
}

const Part* World::find(std::string_view part_id) const noexcept {
  for (const auto& p : parts_) {
    if (p.id == part_id) {
      return &p;
    }
  }
  return nullptr;
}

const Belt* World::find_belt(std::string_view belt_id) const noexcept {
  for (const auto& b : belts_) {
    if (b.spec.id == belt_id) {
      return &b;
    }
  }
  return nullptr;
}

std::optional<Eigen::Isometry3d> World::world_T_tool(std::string_view robot_id) const {
  for (const auto& r : robots_) {
    if (r.mount.robot_id == robot_id) {
      return r.world_T_tool;
    }
  }
  return std::nullopt;
}

std::pair<Support, double> World::support_below(double x, double y, double z) const {
  Support best{Support::Kind::kFloor, ""};
  double best_height = kFloorHeightMm;
  auto consider = [&](Support s, double h) {
    if (h <= z + kSupportEpsMm && h > best_height) {
      best = std::move(s);
      best_height = h;
    }
  };
  if (table_.contains(x, y)) {
    consider(Support{Support::Kind::kTable, ""}, table_.height_mm);
  }
  for (const auto& b : belts_) {
    const Eigen::Vector2d rel(x - b.spec.origin_mm.x(), y - b.spec.origin_mm.y());
    const Eigen::Vector2d dir(std::cos(b.spec.direction_rad), std::sin(b.spec.direction_rad));
    const double s = rel.dot(dir);
    const double l = rel.x() * -dir.y() + rel.y() * dir.x();
    if (s >= 0.0 && s <= b.spec.length_mm && std::abs(l) <= b.spec.width_mm / 2.0) {
      consider(Support{Support::Kind::kBelt, b.spec.id}, b.spec.origin_mm.z());
    }
  }
  return {best, best_height};
}

Result<Part> World::make_part(const PartPlacement& placement) const {
  auto cls = catalogue_.find(placement.class_name);
  if (cls == nullptr) {
    return Error{Errc::kInvalidArgument, fmt::format("unknown part class '{}' (known: {})",
                                                     placement.class_name, catalogue_.list())};
  }
  Part part;
  part.cls = cls;
  if (!placement.id.empty()) {
    if (placement.id.find_first_of("/ \t") != std::string::npos) {
      return Error{Errc::kInvalidArgument,
                   fmt::format("part id '{}' must not contain '/' or blanks", placement.id)};
    }
    if (find(placement.id) != nullptr) {
      return Error{Errc::kInvalidArgument,
                   fmt::format("part id '{}' is already in the world", placement.id)};
    }
    part.id = placement.id;
  }
  Eigen::Isometry3d world_T_part;
  if (placement.pose) {
    CELL_TRY(geometry::check_rigid(*placement.pose, "world_T_part"));
    const Eigen::Vector3d t = placement.pose->translation();
    if (t.cwiseAbs().maxCoeff() > kMaxCoordinateMm) {
      return Error{Errc::kOutOfRange, fmt::format("part position ({:.1f}, {:.1f}, {:.1f}) mm is "
                                                  "beyond +-{} mm",
                                                  t.x(), t.y(), t.z(), kMaxCoordinateMm)};
    }
    world_T_part = *placement.pose;
    const auto [support, height] = support_below(t.x(), t.y(), t.z());
    part.support = support;
  } else {
    const double x = placement.x_mm;
    const double y = placement.y_mm;
    if (!std::isfinite(x) || !std::isfinite(y) || !std::isfinite(placement.yaw)) {
      return Error{Errc::kInvalidArgument, "part x, y and yaw must be finite"};
    }
    if (std::abs(x) > kMaxCoordinateMm || std::abs(y) > kMaxCoordinateMm) {
      return Error{Errc::kOutOfRange, fmt::format("part position ({:.1f}, {:.1f}) mm is beyond "
                                                  "+-{} mm",
                                                  x, y, kMaxCoordinateMm)};
    }
    const auto [support, height] = support_below(x, y, std::numeric_limits<double>::infinity());
    part.support = support;
    world_T_part = planar(x, y, height, geometry::wrap_to_pi(placement.yaw));
  }
  part.support_name = part.support.name();
  part.world_T_part = world_T_part;
  part.footprint = footprint_of(*cls, world_T_part);
  return part;
}

void World::set_pose(Part& part, const Eigen::Isometry3d& world_T_part) {
  part.world_T_part = world_T_part;
  part.footprint = footprint_of(*part.cls, world_T_part);
}

void World::set_support(Part& part, Support support) {
  part.support = std::move(support);
  part.support_name = part.support.name();
}

std::ptrdiff_t World::find_conflict(const Footprint& footprint,
                                    const Support& support,
                                    double min_separation_mm,
                                    std::ptrdiff_t ignore) const {
  for (std::size_t i = 0; i < parts_.size(); ++i) {
    if (static_cast<std::ptrdiff_t>(i) == ignore || !(parts_[i].support == support)) {
      continue;
    }
    if (too_close(footprint, parts_[i].footprint, min_separation_mm)) {
      return static_cast<std::ptrdiff_t>(i);
    }
  }
  return -1;
}

Result<std::string> World::spawn(const PartPlacement& placement, double min_separation_mm) {
  if (!(min_separation_mm >= 0.0) || !std::isfinite(min_separation_mm)) {
    return Error{Errc::kInvalidArgument,
                 fmt::format("min_separation_mm must be >= 0, got {}", min_separation_mm)};
  }
  auto part = make_part(placement);
  if (!part) {
    return std::move(part).error();
  }
  if (part->id.empty()) {
    part->id = next_id();
  }
  if (part->support.kind != Support::Kind::kRobot) {
    const std::ptrdiff_t conflict =
        find_conflict(part->footprint, part->support, min_separation_mm);
    if (conflict >= 0) {
      return Error{Errc::kOutOfRange,
                   fmt::format("{} on the {}",
                               describe_conflict(*part, parts_[static_cast<std::size_t>(conflict)],
                                                 min_separation_mm),
                               part->support_name)};
    }
  }
  std::string id = part->id;
  parts_.push_back(std::move(*part));
  ++seq_;
  return id;
}

Status World::remove(std::string_view part_id) {
  const auto it =
      std::find_if(parts_.begin(), parts_.end(), [&](const Part& p) { return p.id == part_id; });
  if (it == parts_.end()) {
    return Error{Errc::kInvalidArgument, fmt::format("no part '{}' in the world", part_id)};
  }
  parts_.erase(it);
  ++seq_;
  return ok_status();
}

Status World::set_belt_speed(std::string_view belt_id, double speed_mm_s) {
  for (auto& b : belts_) {
    if (b.spec.id == belt_id) {
      if (!std::isfinite(speed_mm_s) || std::abs(speed_mm_s) > 1e5) {
        return Error{Errc::kInvalidArgument,
                     fmt::format("belt '{}': speed must be finite and within +-100000 mm/s, "
                                 "got {}",
                                 belt_id, speed_mm_s)};
      }
      b.spec.speed_mm_s = speed_mm_s;
      return ok_status();
    }
  }
  std::string known;
  for (const auto& b : belts_) {
    known += (known.empty() ? "" : ", ") + b.spec.id;
  }
  return Error{Errc::kInvalidArgument, fmt::format("no belt '{}' in the world (belts: {})", belt_id,
                                                   known.empty() ? "none" : known)};
}

Result<std::vector<std::string>> World::scatter(const ScatterSpec& spec) {
  CELL_TRY(spec.validate());
  std::vector<std::shared_ptr<const PartClass>> classes;
  double largest = 0.0;
  for (const auto& name : spec.classes) {
    auto cls = catalogue_.find(name);
    if (cls == nullptr) {
      return Error{
          Errc::kInvalidArgument,
          fmt::format("scatter: unknown part class '{}' (known: {})", name, catalogue_.list())};
    }
    largest = std::max({largest, cls->length_mm, cls->width_mm});
    classes.push_back(std::move(cls));
  }
  // Broad phase over the parts already there and the ones placed so far.
  FootprintGrid grid(std::max(kGridCellMm, largest + spec.min_separation_mm));
  for (std::size_t i = 0; i < parts_.size(); ++i) {
    grid.insert(i, parts_[i].footprint);
  }
  std::vector<Part> staged;
  staged.reserve(spec.count);
  std::mt19937_64 rng(spec.seed);
  for (std::uint32_t n = 0; n < spec.count; ++n) {
    bool placed = false;
    for (std::uint32_t attempt = 0; attempt < spec.max_attempts_per_part && !placed; ++attempt) {
      const auto& cls = classes[static_cast<std::size_t>(rng() % classes.size())];
      PartPlacement p;
      p.class_name = cls->name;
      p.x_mm = uniform(rng, spec.x_min_mm, spec.x_max_mm);
      p.y_mm = uniform(rng, spec.y_min_mm, spec.y_max_mm);
      p.yaw = uniform(rng, spec.yaw_min, spec.yaw_max);
      auto part = make_part(p);
      if (!part) {
        continue;
      }
      // The whole footprint on the support its origin found (no part hanging off an edge).
      bool on_support = true;
      for (const auto& corner : part->footprint.points) {
        if (!(support_below(corner.x(), corner.y(), std::numeric_limits<double>::infinity())
                  .first == part->support)) {
          on_support = false;
          break;
        }
      }
      if (!on_support) {
        continue;
      }
      bool clash = false;
      grid.for_each_candidate(part->footprint, spec.min_separation_mm, [&](std::size_t i) {
        const Part& other = i < parts_.size() ? parts_[i] : staged[i - parts_.size()];
        clash = clash || (other.support == part->support &&
                          too_close(part->footprint, other.footprint, spec.min_separation_mm));
      });
      if (clash) {
        continue;
      }
      grid.insert(parts_.size() + staged.size(), part->footprint);
      part->where = spec.where;
      staged.push_back(std::move(*part));
      placed = true;
    }
    if (!placed) {
      return Error{
          Errc::kOutOfRange,
          fmt::format("scatter: placed {} of {} parts; part {} found no free spot in "
                      "{} attempts in x [{}, {}] y [{}, {}] mm with min_separation_mm "
                      "{} (ask for fewer parts, a larger region or a smaller "
                      "separation)",
                      n, spec.count, n + 1, spec.max_attempts_per_part, spec.x_min_mm,
                      spec.x_max_mm, spec.y_min_mm, spec.y_max_mm, spec.min_separation_mm)};
    }
  }
  std::vector<std::string> ids;
  ids.reserve(staged.size());
  for (auto& part : staged) {
    part.id = next_id();
    ids.push_back(part.id);
    parts_.push_back(std::move(part));
  }
  if (!ids.empty()) {
    ++seq_;
  }
  return ids;
}

void World::step(double dt_s, std::vector<WorldEvent>& events) {
  if (!(dt_s > 0.0) || !std::isfinite(dt_s)) {
    return;
  }
  for (std::size_t i = 0; i < belts_.size(); ++i) {
    step_belt(i, dt_s, events);
  }
  time_s_ += dt_s;
  step_feeders(events);
}

void World::step_belt(std::size_t belt_index, double dt_s, std::vector<WorldEvent>& events) {
  Belt& belt = belts_[belt_index];
  const BeltSpec& spec = belt.spec;
  const double d = spec.speed_mm_s * dt_s;  // travel this step, signed
  const Eigen::Vector2d o(spec.origin_mm.x(), spec.origin_mm.y());
  const Eigen::Vector2d dir(std::cos(spec.direction_rad), std::sin(spec.direction_rad));
  const double pc = spec.photocell_at_mm;
  auto count_at = [&](double travel) {
    return static_cast<std::int64_t>(spec.encoder_sign) *
           static_cast<std::int64_t>(std::floor(travel / spec.mm_per_count));
  };

  // 1. The beam: which parts cover it now, and where each part's leading and trailing edges
  //    cross it during this step (in belt travel from the step's start).
  crossings_.clear();
  int covering = 0;
  const Part* first_covering = nullptr;
  for (std::size_t i = 0; i < parts_.size(); ++i) {
    const Part& part = parts_[i];
    if (part.support.kind != Support::Kind::kBelt || part.support.id != spec.id) {
      continue;
    }
    double lo = std::numeric_limits<double>::infinity();
    double hi = -lo;
    for (const auto& p : part.footprint.points) {
      const double s = (p - o).dot(dir);
      lo = std::min(lo, s);
      hi = std::max(hi, s);
    }
    if (lo <= pc && pc <= hi) {
      ++covering;
      first_covering = first_covering == nullptr ? &part : first_covering;
    }
    if (d > 0.0) {
      if (hi < pc && hi + d >= pc) {
        crossings_.push_back({pc - hi, +1, i});
      }
      if (lo <= pc && lo + d > pc) {
        crossings_.push_back({pc - lo, -1, i});
      }
    } else if (d < 0.0) {
      if (lo > pc && lo + d <= pc) {
        crossings_.push_back({lo - pc, +1, i});
      }
      if (hi >= pc && hi + d < pc) {
        crossings_.push_back({hi - pc, -1, i});
      }
    }
  }
  auto edge = [&](bool blocked, double offset, const std::string& part_id) {
    const double travel = belt.travel_mm + (d >= 0.0 ? offset : -offset);
    WorldEvent e;
    e.kind = WorldEvent::Kind::kPhotocell;
    e.time_s = time_s_ + (spec.speed_mm_s != 0.0 ? offset / std::abs(spec.speed_mm_s) : 0.0);
    e.part_id = part_id;
    e.belt_id = spec.id;
    e.blocked = blocked;
    e.encoder_count = count_at(travel);
    e.detail = fmt::format("photocell of belt '{}' {} by part '{}' at count {}", spec.id,
                           blocked ? "blocked" : "cleared", part_id, e.encoder_count);
    events.push_back(std::move(e));
    belt.photocell_blocked = blocked;
  };
  // A part put on or taken off the beam since the last step (spawn, drop, pick, remove).
  if ((covering > 0) != belt.photocell_blocked) {
    edge(covering > 0, 0.0, first_covering != nullptr ? first_covering->id : std::string());
  }
  // Entries before exits at the same travel: parts touching end to end keep the beam blocked.
  std::sort(crossings_.begin(), crossings_.end(), [](const Crossing& a, const Crossing& b) {
    if (a.offset != b.offset) {
      return a.offset < b.offset;
    }
    if (a.delta != b.delta) {
      return a.delta > b.delta;
    }
    return a.part < b.part;
  });
  for (const Crossing& c : crossings_) {
    covering += c.delta;
    if ((covering > 0) != belt.photocell_blocked) {
      edge(covering > 0, c.offset, parts_[c.part].id);
    }
  }

  // 2. The belt and what it carries move.
  belt.travel_mm += d;
  belt.encoder_count = count_at(belt.travel_mm);
  if (d == 0.0) {
    return;
  }
  const Eigen::Vector3d shift = spec.direction() * d;
  for (auto& part : parts_) {
    if (part.support.kind != Support::Kind::kBelt || part.support.id != spec.id) {
      continue;
    }
    part.world_T_part.pretranslate(shift);
    part.footprint.translate(shift.head<2>());
    // 3. Past either end: the part tips off and comes to rest on what is below (the floor,
    //    or the table where it reaches under the belt's end), flat, keeping its yaw.
    const Eigen::Vector3d t = part.world_T_part.translation();
    const double s = (Eigen::Vector2d(t.x(), t.y()) - o).dot(dir);
    if (s < 0.0 || s > spec.length_mm) {
      drop(part);
      ++seq_;
      WorldEvent e;
      e.kind = WorldEvent::Kind::kFellOffBelt;
      e.time_s = time_s_ + dt_s;
      e.part_id = part.id;
      e.belt_id = spec.id;
      e.support = part.support_name;
      e.detail = fmt::format(
          "part '{}' fell off the {} end of belt '{}' onto the {} at ({:.1f}, "
          "{:.1f}) mm",
          part.id, s < 0.0 ? "upstream" : "downstream", spec.id, part.support_name,
          part.world_T_part.translation().x(), part.world_T_part.translation().y());
      events.push_back(std::move(e));
    }
  }
}

void World::drop(Part& part) {
  const Eigen::Vector3d t = part.world_T_part.translation();
  const double yaw = yaw_of(part.world_T_part.linear());
  const auto [support, height] = support_below(t.x(), t.y(), t.z());
  set_pose(part, planar(t.x(), t.y(), height, yaw));
  set_support(part, support);
}

Status World::update_robot(std::string_view robot_id,
                           const Eigen::Isometry3d& base_T_tool,
                           GripperState gripper,
                           std::vector<WorldEvent>& events,
                           double age_s) {
  if (!(std::abs(age_s) <= kMaxAgeS)) {
    return Error{Errc::kInvalidArgument,
                 fmt::format("the robot state's age {} s is outside +-{} s of the world's time",
                             age_s, kMaxAgeS)};
  }
  auto it = std::find_if(robots_.begin(), robots_.end(),
                         [&](const RobotSlot& r) { return r.mount.robot_id == robot_id; });
  if (it == robots_.end()) {
    std::string known;
    for (const auto& r : robots_) {
      known += (known.empty() ? "" : ", ") + r.mount.robot_id;
    }
    return Error{Errc::kInvalidArgument,
                 fmt::format("robot '{}' has no mount in the world (mounted: {})", robot_id,
                             known.empty() ? "none" : known)};
  }
  CELL_TRY(geometry::check_rigid(base_T_tool, "base_T_tool"));
  RobotSlot& robot = *it;
  const Eigen::Isometry3d world_T_tool = robot.mount.world_T_base * base_T_tool;
  if (world_T_tool.translation().cwiseAbs().maxCoeff() > kMaxCoordinateMm) {
    return Error{Errc::kOutOfRange, "base_T_tool puts the tool beyond 1 km"};
  }
  robot.world_T_tool = world_T_tool;
  for (auto& part : parts_) {
    if (part.support.kind == Support::Kind::kRobot && part.support.id == robot_id) {
      set_pose(part, world_T_tool * part.tool_T_part);
    }
  }
  if (gripper == GripperState::kUnknown) {
    return ok_status();
  }
  const GripperState before = robot.gripper;
  robot.gripper = gripper;
  if (before == GripperState::kUnknown) {
    return ok_status();  // first observation: nothing is known to have changed
  }
  if (closed_like(gripper) && !closed_like(before)) {
    capture(robot, age_s, events);
  } else if (open_like(gripper) && !open_like(before)) {
    release(robot, events);
  }
  return ok_status();
}

Eigen::Vector3d World::support_velocity(const Part& part) const {
  const Belt* belt =
      part.support.kind == Support::Kind::kBelt ? find_belt(part.support.id) : nullptr;
  if (belt == nullptr) {
    return Eigen::Vector3d::Zero();
  }
  return belt->spec.speed_mm_s * Eigen::Vector3d(std::cos(belt->spec.direction_rad),
                                                 std::sin(belt->spec.direction_rad), 0.0);
}

void World::capture(RobotSlot& robot, double age_s, std::vector<WorldEvent>& events) {
  const Eigen::Isometry3d& tool = *robot.world_T_tool;
  const Eigen::Vector3d p = tool.translation();
  const std::string& robot_id = robot.mount.robot_id;
  WorldEvent e;
  e.time_s = time_s_;
  e.robot_id = robot_id;
  const double tilt = std::acos(std::min(1.0, std::abs(tool.linear()(2, 2))));
  if (tilt > options_.capture_tilt_tolerance) {
    e.kind = WorldEvent::Kind::kMissed;
    e.detail = fmt::format(
        "gripper of '{}' closed with its axis {:.1f} deg from the vertical "
        "(tolerance {:.1f} deg): nothing taken",
        robot_id, rad_to_deg(tilt), rad_to_deg(options_.capture_tilt_tolerance));
    events.push_back(std::move(e));
    return;
  }
  const double tool_yaw = yaw_of(tool.linear());
  std::ptrdiff_t best = -1;
  double best_distance = std::numeric_limits<double>::infinity();
  Eigen::Vector3d best_offset = Eigen::Vector3d::Zero();  // grasp point - tool point
  const Part* nearest = nullptr;
  double nearest_distance = std::numeric_limits<double>::infinity();
  Eigen::Vector3d nearest_offset = Eigen::Vector3d::Zero();  // grasp point - tool point
  double nearest_yaw_error = 0.0;
  for (std::size_t i = 0; i < parts_.size(); ++i) {
    const Part& part = parts_[i];
    if (part.support.kind == Support::Kind::kRobot) {
      continue;
    }
    // Where the grasp point was at the observation's instant.
    const Eigen::Isometry3d grasp =
        Eigen::Translation3d(-age_s * support_velocity(part)) * part.world_T_grasp();
    const double dist = (grasp.translation() - p).norm();
    const double yaw_error = grasp_yaw_error(tool_yaw, yaw_of(grasp.linear()), *part.cls);
    if (dist < nearest_distance) {
      nearest = &part;
      nearest_distance = dist;
      nearest_offset = grasp.translation() - p;
      nearest_yaw_error = yaw_error;
    }
    if (dist <= options_.capture_tolerance_mm &&
        std::abs(yaw_error) <= options_.capture_yaw_tolerance && dist < best_distance) {
      best = static_cast<std::ptrdiff_t>(i);
      best_distance = dist;
      best_offset = grasp.translation() - p;
    }
  }
  if (best < 0) {
    e.kind = WorldEvent::Kind::kMissed;
    if (nearest == nullptr) {
      e.detail = fmt::format(
          "gripper of '{}' closed at ({:.2f}, {:.2f}, {:.2f}) mm: no part in "
          "the world",
          robot_id, p.x(), p.y(), p.z());
    } else {
      e.part_id = nearest->id;
      e.detail = fmt::format(
          "gripper of '{}' closed at ({:.2f}, {:.2f}, {:.2f}) mm on nothing: the nearest grasp "
          "point, of part '{}', is {:.2f} mm away (tolerance {:.2f} mm; from the tool: {:.2f}, "
          "{:.2f}, {:.2f} mm in the world) and {:.1f} deg off in yaw (tolerance {:.1f} deg)",
          robot_id, p.x(), p.y(), p.z(), nearest->id, nearest_distance,
          options_.capture_tolerance_mm, nearest_offset.x(), nearest_offset.y(),
          nearest_offset.z(), rad_to_deg(nearest_yaw_error),
          rad_to_deg(options_.capture_yaw_tolerance));
    }
    events.push_back(std::move(e));
    return;
  }
  Part& part = parts_[static_cast<std::size_t>(best)];
  // Held as it was at the observation's instant; from now on it moves with the tool.
  part.tool_T_part =
      tool.inverse() * Eigen::Translation3d(-age_s * support_velocity(part)) * part.world_T_part;
  const std::string from = part.support_name;
  set_support(part, Support{Support::Kind::kRobot, robot_id});
  ++seq_;
  e.kind = WorldEvent::Kind::kAttached;
  e.part_id = part.id;
  e.support = part.support_name;
  e.detail = fmt::format(
      "gripper of '{}' took part '{}' from the {} ({:.2f} mm from its grasp "
      "point; from the tool: {:.2f}, {:.2f}, {:.2f} mm in the world)",
      robot_id, part.id, from, best_distance, best_offset.x(), best_offset.y(), best_offset.z());
  events.push_back(std::move(e));
}

void World::release(RobotSlot& robot, std::vector<WorldEvent>& events) {
  const std::string& robot_id = robot.mount.robot_id;
  for (auto& part : parts_) {
    if (part.support.kind != Support::Kind::kRobot || part.support.id != robot_id) {
      continue;
    }
    drop(part);
    ++seq_;
    WorldEvent e;
    e.kind = WorldEvent::Kind::kReleased;
    e.time_s = time_s_;
    e.part_id = part.id;
    e.robot_id = robot_id;
    e.support = part.support_name;
    const Eigen::Vector3d t = part.world_T_part.translation();
    e.detail = fmt::format(
        "gripper of '{}' released part '{}' onto the {} at ({:.2f}, {:.2f}, "
        "{:.2f}) mm, yaw {:.1f} deg",
        robot_id, part.id, part.support_name, t.x(), t.y(), t.z(),
        rad_to_deg(yaw_of(part.world_T_part.linear())));
    events.push_back(std::move(e));
  }
}

}  // namespace cell::world
