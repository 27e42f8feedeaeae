#pragma once

#include <Eigen/Geometry>
#include <cstddef>
#include <cstdint>
#include <unordered_map>
#include <vector>

/// Footprints: the outline of a part seen from above, as a convex polygon in the world's x-y
/// plane [mm], and the overlap rules of scenes and spawns (footprints intersecting, or closer
/// than a minimum separation). Pure functions; no allocation beyond the returned vectors.
namespace cell::world {

/// A convex polygon, counter-clockwise, plus its axis-aligned bounding box [mm].
struct Footprint {
  std::vector<Eigen::Vector2d> points;
  Eigen::Vector2d min = Eigen::Vector2d::Zero();
  Eigen::Vector2d max = Eigen::Vector2d::Zero();

  /// Recomputes min/max from points.
  void update_bounds() noexcept;
  /// Moves every point (and the bounds) by `offset`.
  void translate(const Eigen::Vector2d& offset) noexcept;
};

/// Convex hull (Andrew's monotone chain) of `points`, counter-clockwise, collinear points
/// dropped. Fewer than 3 distinct points give a degenerate hull of 1 or 2 points.
std::vector<Eigen::Vector2d> convex_hull(std::vector<Eigen::Vector2d> points);

/// The footprint of hull points `hull_part` (part frame, 3-D) placed at `world_T_part`:
/// the convex hull of their projection on the world x-y plane.
Footprint project_footprint(const std::vector<Eigen::Vector3d>& hull_part,
                            const Eigen::Isometry3d& world_T_part);

/// The footprint of an upright part: planar outline `outline_part` (part frame, CCW) turned by
/// `yaw` [rad] and moved to (x, y) [mm]. Cheaper than project_footprint; same result for a
/// part whose z axis is vertical.
Footprint place_footprint(const std::vector<Eigen::Vector2d>& outline_part,
                          double x,
                          double y,
                          double yaw);

/// True when the two convex polygons share at least one point (separating axis test).
bool intersects(const Footprint& a, const Footprint& b) noexcept;

/// Smallest distance between the two convex polygons [mm]; 0 when they intersect.
double distance(const Footprint& a, const Footprint& b) noexcept;

/// True when `a` and `b` intersect or are closer than `min_separation_mm`.
bool too_close(const Footprint& a, const Footprint& b, double min_separation_mm) noexcept;

/// True when `p` lies inside or on the convex polygon `f`.
bool contains(const Footprint& f, const Eigen::Vector2d& p) noexcept;

/// A uniform grid over footprint bounding boxes for the overlap broad phase: inserting n
/// footprints and querying one costs O(1) each for parts smaller than a cell, against the
/// O(n) of checking every pair (bench/world compares both). Stores indices, not footprints:
/// the caller keeps the footprints alive and unchanged while the grid is used. Not thread-safe.
class FootprintGrid {
 public:
  /// `cell_mm` > 0: the grid pitch; about the largest part's size plus the separation is best.
  explicit FootprintGrid(double cell_mm);

  /// Registers footprint number `index` with bounds [min, max] grown by `margin_mm`.
  void insert(std::size_t index, const Footprint& footprint, double margin_mm = 0.0);

  /// Calls fn(index) once for each registered footprint whose (grown) cells meet the bounds of
  /// `footprint` grown by `margin_mm`: a superset of the footprints within margin_mm.
  template <typename Fn>
  void for_each_candidate(const Footprint& footprint, double margin_mm, Fn&& fn) {
    ++stamp_;
    auto visit = [&](std::size_t index) {
      if (seen_.size() <= index) {
        seen_.resize(index + 1, 0);
      }
      if (seen_[index] != stamp_) {
        seen_[index] = stamp_;
        fn(index);
      }
    };
    const Range r = cells(footprint, margin_mm);
    if (oversized(r)) {  // a query wider than the grid is worth: everything is a candidate
      for (const std::size_t index : all_) {
        visit(index);
      }
      return;
    }
    for (const std::size_t index : oversize_) {
      visit(index);
    }
    for (std::int64_t cx = r.x0; cx <= r.x1; ++cx) {
      for (std::int64_t cy = r.y0; cy <= r.y1; ++cy) {
        const auto it = cells_.find(key(cx, cy));
        if (it == cells_.end()) {
          continue;
        }
        for (const std::size_t index : it->second) {
          visit(index);
        }
      }
    }
  }

  /// Forgets every footprint.
  void clear() noexcept;

 private:
  struct Range {
    std::int64_t x0, y0, x1, y1;
  };
  Range cells(const Footprint& footprint, double margin_mm) const noexcept;
  /// Wider or taller than kMaxSide cells: kept in oversize_ instead of the cells.
  static bool oversized(const Range& r) noexcept {
    return (r.x1 - r.x0 + 1) > kMaxSide || (r.y1 - r.y0 + 1) > kMaxSide;
  }
  static constexpr std::int64_t kMaxSide = 64;
  static std::uint64_t key(std::int64_t cx, std::int64_t cy) noexcept {
    return (static_cast<std::uint64_t>(cx) << 32) ^ (static_cast<std::uint64_t>(cy) & 0xffffffffU);
  }

  double cell_mm_;
  std::unordered_map<std::uint64_t, std::vector<std::size_t>> cells_;
  std::vector<std::size_t> oversize_;  // registered footprints spanning too many cells
  std::vector<std::size_t> all_;       // every registered index
  std::vector<std::uint64_t> seen_;
  std::uint64_t stamp_ = 0;
};

}  // namespace cell::world
