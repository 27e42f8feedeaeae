#pragma once

#include <Eigen/Geometry>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "cell/common/result.hpp"
#include "cell/world/part_class.hpp"

/// Scenes: what a world starts with (table, belts, parts, scatter generators), read strictly
/// from YAML (config/scenes/*.yaml; keys and units in core/world/README.md "Scene files").
///
/// **World frame**: the cell's fixed frame, z up, in mm; the floor is the plane z = 0 (parts that
/// fall off a belt or off the table come to rest there), the table top is the plane
/// z = table.height_mm over the table's rectangle. Robots' bases are placed in it by the
/// simulator's configuration (WorldOptions::robots), not by scenes.
namespace cell::world {

/// The work table: an axis-aligned rectangle of the world's x-y plane at height height_mm.
struct Table {
  double height_mm = 750.0;  ///< table top above the floor
  double x_min_mm = -600.0;
  double x_max_mm = 600.0;
  double y_min_mm = -150.0;
  double y_max_mm = 750.0;
  double reflectance = 0.9;  ///< white matte (digest 000 §3)

  /// True when (x, y) [mm] lies on the table top (edges included).
  bool contains(double x, double y) const noexcept {
    return x >= x_min_mm && x <= x_max_mm && y >= y_min_mm && y <= y_max_mm;
  }
};

/// A conveyor belt (digest 002): a rectangle of the x-y plane moving along `direction`.
///
/// Belt frame: origin at `origin_mm` (world; on the belt's centre line at its upstream end, at
/// the height of the belt surface), x along `direction` (the direction of travel for a
/// positive speed), z up. A point of the world is on the belt when 0 <= s <= length_mm and
/// |l| <= width_mm / 2, with s, l its coordinates along and across the belt.
struct BeltSpec {
  std::string id;  ///< "belt1": unique, no '/'
  Eigen::Vector3d origin_mm = Eigen::Vector3d::Zero();
  double direction_rad = 0.0;  ///< travel direction in the world x-y plane
  double length_mm = 1000.0;
  double width_mm = 300.0;
  double speed_mm_s = 0.0;       ///< signed: > 0 moves along direction
  double mm_per_count = 0.1;     ///< belt travel per encoder count (> 0)
  int encoder_sign = 1;          ///< +1: counts grow with travel; -1 (V+ sign)
  double photocell_at_mm = 0.0;  ///< beam position along the belt from origin
  double reflectance = 0.3;      ///< grey belt surface
  std::string where;             ///< "file:line:col" of its scene entry

  /// Unit vector of travel (world).
  Eigen::Vector3d direction() const noexcept;
  /// Ok, or kInvalidArgument naming the belt and the field (non-positive sizes or
  /// mm_per_count, photocell outside [0, length], sign not +-1, empty id or one with '/').
  Status validate() const;
};

/// One part of a scene (or of a spawn request).
struct PartPlacement {
  std::string id;          ///< "" = assigned by the world ("p1", "p2", ...)
  std::string class_name;  ///< key of the world's catalogue
  /// Planar placement (the usual): resting flat on whatever is below (x, y) [mm], yawed by
  /// `yaw` [rad] about the vertical. Used when `pose` is empty.
  double x_mm = 0.0;
  double y_mm = 0.0;
  double yaw = 0.0;
  /// Full pose world_T_part instead (e.g. a RAPT block lying on a side face): the part is put
  /// exactly there, supported by whatever is below its origin.
  std::optional<Eigen::Isometry3d> pose;
  std::string where;  ///< "file:line:col" for errors ("" for spawns)
};

/// A seeded scatter generator: `count` parts of `classes` at uniformly random positions and
/// yaws in a region, each at least `min_separation_mm` from every other part on its support.
/// Same spec and seed -> same parts (the generator is std::mt19937_64 with its own uniform
/// mapping, identical on every platform).
struct ScatterSpec {
  std::uint32_t count = 0;
  std::vector<std::string> classes;  ///< drawn uniformly; must be non-empty and known
  double x_min_mm = 0.0;             ///< region of the part origins
  double x_max_mm = 0.0;
  double y_min_mm = 0.0;
  double y_max_mm = 0.0;
  double yaw_min = -3.14159265358979323846;  ///< [rad]
  double yaw_max = 3.14159265358979323846;   ///< [rad]
  double min_separation_mm = 0.0;
  std::uint64_t seed = 1;
  std::uint32_t max_attempts_per_part = 200;
  std::string where;  ///< "file:line:col"

  /// Ok, or kInvalidArgument naming the field (empty classes, empty region, yaw_min > yaw_max,
  /// negative separation, zero attempts).
  Status validate() const;
};

/// A feeder that puts parts on a belt at a steady rate (a vibratory bowl or an upstream
/// machine): every `period_s` of world time, a part of one of `classes` (drawn uniformly) is
/// spawned `start_mm` along the belt from its upstream end, `lateral_mm` at most to either side
/// of the centre line and at a yaw in [yaw_min, yaw_max], all drawn from its own seeded
/// generator (same spec and seed: the same stream). A part that would overlap one still there
/// is not fed (counted as jammed). `count` > 0 stops the feeder after that many parts.
struct FeederSpec {
  std::string belt;
  std::vector<std::string> classes;
  double period_s = 1.0;
  double start_mm = 30.0;
  double lateral_mm = 0.0;
  double yaw_min = -3.14159265358979323846;  ///< [rad], about the vertical, world frame
  double yaw_max = 3.14159265358979323846;
  std::uint32_t count = 0;
  std::uint64_t seed = 1;
  std::string where;

  /// Ok, or kInvalidArgument naming the field (empty belt or classes, period <= 0, negative
  /// start or lateral, yaw_min > yaw_max).
  Status validate() const;
};

/// A whole scene as read from a file. Nothing is checked against geometry yet (overlaps, what
/// is under a part): World::create does that and names each part's `where`.
struct Scene {
  std::string name;    ///< `name:` or the file name
  std::string source;  ///< the file (or origin) it came from
  Table table;
  double min_separation_mm = 0.0;  ///< between any two parts placed by the scene
  std::vector<PartClass> classes;  ///< the scene's own classes (added to the catalogue)
  std::vector<BeltSpec> belts;
  std::vector<PartPlacement> parts;
  std::vector<ScatterSpec> scatter;  ///< run in order after `parts`
  std::vector<FeederSpec> feeders;   ///< run by World::step
};

/// Parses a scene from YAML text; `origin` names it in errors ("config/scenes/x.yaml",
/// "<request>"). Unknown classes are refused here against `catalogue` plus the scene's own
/// classes. Errors: kConfig, every problem at once, one per line, each "origin:line:col: ..."
/// (unknown keys, wrong types, bad values, unknown class naming the known ones, duplicate ids).
Result<Scene> parse_scene(const std::string& text,
                          const std::string& origin,
                          const Catalogue& catalogue);

/// Reads and parses a scene file (errors as parse_scene, or "path: cannot open: ...").
Result<Scene> load_scene_file(const std::string& path, const Catalogue& catalogue);

}  // namespace cell::world
