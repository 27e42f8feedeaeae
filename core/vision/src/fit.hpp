#pragma once

#include <Eigen/Core>
#include <array>
#include <optional>
#include <vector>

/// Geometric fits of the fast pipeline (internal): lines, pairs of parallel lines sharing a
/// direction, circles, in any 2-D frame. Least squares in the total (orthogonal) sense.
namespace cell::vision::detail {

/// A line n . p = d, n a unit vector (the outward normal of a polygon side).
struct Line2 {
  Eigen::Vector2d n = Eigen::Vector2d::UnitX();
  double d = 0.0;

  double distance(const Eigen::Vector2d& p) const { return n.dot(p) - d; }
};

/// Intersection of two lines; nullopt when (nearly) parallel.
std::optional<Eigen::Vector2d> intersect(const Line2& a, const Line2& b);

/// The total-least-squares line through `points` with its normal on the side of `outward`
/// (n . outward > 0); nullopt for fewer than 2 points.
std::optional<Line2> fit_line(const std::vector<Eigen::Vector2d>& points,
                              const Eigen::Vector2d& outward);

/// Four sides of a rectangle (or, with orthogonal = false, a parallelogram): sides 0 and 2
/// share a direction u (their normals are -+ u rotated by 90 deg), sides 1 and 3 share the
/// perpendicular one (orthogonal) or their own. Least squares over every side's points, each
/// side's offset through its points' mean. `outward[k]` orients side k's normal. nullopt when a
/// side has fewer than 2 points (orthogonal: fewer than 1 point on a side, or no direction).
std::optional<std::array<Line2, 4>> fit_quad(
    const std::array<std::vector<Eigen::Vector2d>, 4>& sides,
    const std::array<Eigen::Vector2d, 4>& outward,
    bool orthogonal);

struct Circle2 {
  Eigen::Vector2d c = Eigen::Vector2d::Zero();
  double r = 0.0;
};

/// Circle through `points`: the algebraic (Kasa) fit refined by Gauss-Newton on the geometric
/// distances. nullopt for fewer than 3 points or a degenerate set.
std::optional<Circle2> fit_circle(const std::vector<Eigen::Vector2d>& points);

/// Signed area of a polygon (positive counter-clockwise in a right-handed frame).
double signed_area(const std::vector<Eigen::Vector2d>& polygon);

/// Median of |values| (destroys the order of `values`); 0 for an empty vector.
double median_abs(std::vector<double>& values);

}  // namespace cell::vision::detail
