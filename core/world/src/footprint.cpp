#include "cell/world/footprint.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace cell::world {
namespace {

double cross(const Eigen::Vector2d& o, const Eigen::Vector2d& a, const Eigen::Vector2d& b) {
  return (a.x() - o.x()) * (b.y() - o.y()) - (a.y() - o.y()) * (b.x() - o.x());
}

/// True when no edge normal of `a` separates the two polygons.
bool no_separating_axis(const Footprint& a, const Footprint& b) noexcept {
  const std::size_t n = a.points.size();
  for (std::size_t i = 0; i < n; ++i) {
    const Eigen::Vector2d& p = a.points[i];
    const Eigen::Vector2d& q = a.points[(i + 1) % n];
    const Eigen::Vector2d axis(q.y() - p.y(), p.x() - q.x());  // outward for CCW
    double a_max = -std::numeric_limits<double>::infinity();
    for (const auto& v : a.points) {
      a_max = std::max(a_max, axis.dot(v));
    }
    double b_min = std::numeric_limits<double>::infinity();
    for (const auto& v : b.points) {
      b_min = std::min(b_min, axis.dot(v));
    }
    if (b_min > a_max) {
      return false;
    }
  }
  return true;
}

double point_segment_distance(const Eigen::Vector2d& p,
                              const Eigen::Vector2d& a,
                              const Eigen::Vector2d& b) noexcept {
  const Eigen::Vector2d ab = b - a;
  const double len2 = ab.squaredNorm();
  double t = len2 > 0.0 ? (p - a).dot(ab) / len2 : 0.0;
  t = std::clamp(t, 0.0, 1.0);
  return (a + t * ab - p).norm();
}

}  // namespace

void Footprint::update_bounds() noexcept {
  if (points.empty()) {
    min.setZero();
    max.setZero();
    return;
  }
  min = points.front();
  max = points.front();
  for (const auto& p : points) {
    min = min.cwiseMin(p);
    max = max.cwiseMax(p);
  }
}

void Footprint::translate(const Eigen::Vector2d& offset) noexcept {
  for (auto& p : points) {
    p += offset;
  }
  min += offset;
  max += offset;
}

std::vector<Eigen::Vector2d> convex_hull(std::vector<Eigen::Vector2d> points) {
  std::sort(points.begin(), points.end(), [](const Eigen::Vector2d& a, const Eigen::Vector2d& b) {
    return a.x() < b.x() || (a.x() == b.x() && a.y() < b.y());
  });
  points.erase(std::unique(points.begin(), points.end()), points.end());
  if (points.size() < 3) {
    return points;
  }
  std::vector<Eigen::Vector2d> hull(2 * points.size());
  std::size_t k = 0;
  for (const auto& p : points) {  // lower hull
    while (k >= 2 && cross(hull[k - 2], hull[k - 1], p) <= 0.0) {
      --k;
    }
    hull[k++] = p;
  }
  const std::size_t lower = k + 1;
  for (std::size_t i = points.size() - 1; i-- > 0;) {  // upper hull
    while (k >= lower && cross(hull[k - 2], hull[k - 1], points[i]) <= 0.0) {
      --k;
    }
    hull[k++] = points[i];
  }
  hull.resize(k - 1);
  return hull;
}

Footprint project_footprint(const std::vector<Eigen::Vector3d>& hull_part,
                            const Eigen::Isometry3d& world_T_part) {
  std::vector<Eigen::Vector2d> projected;
  projected.reserve(hull_part.size());
  for (const auto& p : hull_part) {
    const Eigen::Vector3d w = world_T_part * p;
    projected.emplace_back(w.x(), w.y());
  }
  Footprint f;
  f.points = convex_hull(std::move(projected));
  f.update_bounds();
  return f;
}

Footprint place_footprint(const std::vector<Eigen::Vector2d>& outline_part,
                          double x,
                          double y,
                          double yaw) {
  const double c = std::cos(yaw);
  const double s = std::sin(yaw);
  Footprint f;
  f.points.reserve(outline_part.size());
  for (const auto& p : outline_part) {
    f.points.emplace_back(x + c * p.x() - s * p.y(), y + s * p.x() + c * p.y());
  }
  f.update_bounds();
  return f;
}

bool intersects(const Footprint& a, const Footprint& b) noexcept {
  if (a.points.empty() || b.points.empty()) {
    return false;
  }
  if (a.max.x() < b.min.x() || b.max.x() < a.min.x() || a.max.y() < b.min.y() ||
      b.max.y() < a.min.y()) {
    return false;
  }
  if (a.points.size() < 3 || b.points.size() < 3) {
    return distance(a, b) == 0.0;
  }
  return no_separating_axis(a, b) && no_separating_axis(b, a);
}

double distance(const Footprint& a, const Footprint& b) noexcept {
  if (a.points.empty() || b.points.empty()) {
    return std::numeric_limits<double>::infinity();
  }
  if (a.points.size() >= 3 && b.points.size() >= 3 && intersects(a, b)) {
    return 0.0;
  }
  // Disjoint convex polygons: the closest pair involves a vertex of one and an edge of the
  // other.
  double best = std::numeric_limits<double>::infinity();
  auto scan = [&best](const Footprint& p, const Footprint& q) {
    const std::size_t m = q.points.size();
    for (const auto& v : p.points) {
      for (std::size_t i = 0; i < m; ++i) {
        best = std::min(best, point_segment_distance(v, q.points[i], q.points[(i + 1) % m]));
      }
    }
  };
  scan(a, b);
  scan(b, a);
  return best;
}

bool too_close(const Footprint& a, const Footprint& b, double min_separation_mm) noexcept {
  if (a.points.empty() || b.points.empty()) {
    return false;
  }
  const double m = std::max(0.0, min_separation_mm);
  if (a.max.x() + m < b.min.x() || b.max.x() + m < a.min.x() || a.max.y() + m < b.min.y() ||
      b.max.y() + m < a.min.y()) {
    return false;
  }
  if (intersects(a, b)) {
    return true;
  }
  return m > 0.0 && distance(a, b) < m;
}

bool contains(const Footprint& f, const Eigen::Vector2d& p) noexcept {
  const std::size_t n = f.points.size();
  if (n < 3) {
    return false;
  }
  for (std::size_t i = 0; i < n; ++i) {
    if (cross(f.points[i], f.points[(i + 1) % n], p) < 0.0) {
      return false;
    }
  }
  return true;
}

FootprintGrid::FootprintGrid(double cell_mm)
    : cell_mm_(std::isfinite(cell_mm) && cell_mm > 0.0 ? cell_mm : 50.0) {}

FootprintGrid::Range FootprintGrid::cells(const Footprint& footprint,
                                          double margin_mm) const noexcept {
  // Clamped so that absurd coordinates cannot overflow the conversion (callers keep parts
  // within +-1e6 mm; the clamp only keeps this function defined for anything).
  auto cell = [this](double v) {
    const double c = std::floor(v / cell_mm_);
    return static_cast<std::int64_t>(std::clamp(std::isfinite(c) ? c : 0.0, -1e9, 1e9));
  };
  return Range{cell(footprint.min.x() - margin_mm), cell(footprint.min.y() - margin_mm),
               cell(footprint.max.x() + margin_mm), cell(footprint.max.y() + margin_mm)};
}

void FootprintGrid::insert(std::size_t index, const Footprint& footprint, double margin_mm) {
  all_.push_back(index);
  const Range r = cells(footprint, margin_mm);
  if (oversized(r)) {
    oversize_.push_back(index);
    return;
  }
  for (std::int64_t cx = r.x0; cx <= r.x1; ++cx) {
    for (std::int64_t cy = r.y0; cy <= r.y1; ++cy) {
      cells_[key(cx, cy)].push_back(index);
    }
  }
}

void FootprintGrid::clear() noexcept {
  cells_.clear();
  oversize_.clear();
  all_.clear();
  seen_.clear();
  stamp_ = 0;
}

}  // namespace cell::world
