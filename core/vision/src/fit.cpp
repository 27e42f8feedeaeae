#include "fit.hpp"

#include <Eigen/LU>
#include <algorithm>
#include <cmath>

#include "support.hpp"

namespace cell::vision::detail {
namespace {

/// Direction of largest spread of a 2 x 2 scatter matrix [a b; b c]: the angle
/// 0.5 atan2(2b, a - c) (closed form of the symmetric 2 x 2 eigenproblem).
Eigen::Vector2d principal(const Eigen::Matrix2d& s) {
  const double t = 0.5 * std::atan2(2.0 * s(0, 1), s(0, 0) - s(1, 1));
  return Eigen::Vector2d(std::cos(t), std::sin(t));
}

}  // namespace

std::optional<Eigen::Vector2d> intersect(const Line2& a, const Line2& b) {
  Eigen::Matrix2d m;
  m << a.n.x(), a.n.y(), b.n.x(), b.n.y();
  const double det = m.determinant();
  if (std::abs(det) < 1e-9) {
    return std::nullopt;
  }
  return Eigen::Vector2d(m.inverse() * Eigen::Vector2d(a.d, b.d));
}

std::optional<Line2> fit_line(const std::vector<Eigen::Vector2d>& points,
                              const Eigen::Vector2d& outward) {
  if (points.size() < 2) {
    return std::nullopt;
  }
  Eigen::Vector2d mean = Eigen::Vector2d::Zero();
  for (const auto& p : points) {
    mean += p;
  }
  mean /= static_cast<double>(points.size());
  Eigen::Matrix2d s = Eigen::Matrix2d::Zero();
  for (const auto& p : points) {
    const Eigen::Vector2d d = p - mean;
    s += d * d.transpose();
  }
  Line2 line;
  line.n = perp(principal(s));
  if (line.n.dot(outward) < 0.0) {
    line.n = -line.n;
  }
  line.d = line.n.dot(mean);
  return line;
}

std::optional<std::array<Line2, 4>> fit_quad(
    const std::array<std::vector<Eigen::Vector2d>, 4>& sides,
    const std::array<Eigen::Vector2d, 4>& outward,
    bool orthogonal) {
  std::array<Eigen::Vector2d, 4> mean;
  std::array<Eigen::Matrix2d, 4> scatter;
  for (std::size_t k = 0; k < 4; ++k) {
    if (sides[k].empty()) {
      return std::nullopt;
    }
    mean[k] = Eigen::Vector2d::Zero();
    for (const auto& p : sides[k]) {
      mean[k] += p;
    }
    mean[k] /= static_cast<double>(sides[k].size());
    scatter[k] = Eigen::Matrix2d::Zero();
    for (const auto& p : sides[k]) {
      const Eigen::Vector2d d = p - mean[k];
      scatter[k] += d * d.transpose();
    }
  }
  // Side k's direction is that of the pair it belongs to; the short pair's scatter turned by
  // 90 degrees joins the long pair's when the two directions are tied.
  Eigen::Matrix2d rot;
  rot << 0, -1, 1, 0;
  std::array<Eigen::Vector2d, 2> dir;
  if (orthogonal) {
    const Eigen::Matrix2d s =
        scatter[0] + scatter[2] + rot * (scatter[1] + scatter[3]) * rot.transpose();
    dir[0] = principal(s);
    dir[1] = perp(dir[0]);
  } else {
    if (sides[0].size() + sides[2].size() < 3 || sides[1].size() + sides[3].size() < 3) {
      return std::nullopt;
    }
    dir[0] = principal(scatter[0] + scatter[2]);
    dir[1] = principal(scatter[1] + scatter[3]);
  }
  std::array<Line2, 4> out;
  for (std::size_t k = 0; k < 4; ++k) {
    Line2 line;
    line.n = perp(dir[k % 2]);
    if (line.n.dot(outward[k]) < 0.0) {
      line.n = -line.n;
    }
    line.d = line.n.dot(mean[k]);
    out[k] = line;
  }
  return out;
}

std::optional<Circle2> fit_circle(const std::vector<Eigen::Vector2d>& points) {
  if (points.size() < 3) {
    return std::nullopt;
  }
  // Kasa: x^2 + y^2 + D x + E y + F = 0, about the centroid for conditioning.
  Eigen::Vector2d m = Eigen::Vector2d::Zero();
  for (const auto& p : points) {
    m += p;
  }
  m /= static_cast<double>(points.size());
  Eigen::Matrix3d a = Eigen::Matrix3d::Zero();
  Eigen::Vector3d b = Eigen::Vector3d::Zero();
  for (const auto& p : points) {
    const Eigen::Vector2d q = p - m;
    const Eigen::Vector3d row(q.x(), q.y(), 1.0);
    const double rhs = -(q.x() * q.x() + q.y() * q.y());
    a += row * row.transpose();
    b += row * rhs;
  }
  if (std::abs(a.determinant()) < 1e-12) {
    return std::nullopt;
  }
  const Eigen::Vector3d x = a.inverse() * b;
  Circle2 c;
  c.c = m + Eigen::Vector2d(-x[0] / 2.0, -x[1] / 2.0);
  const double r2 = (x[0] * x[0] + x[1] * x[1]) / 4.0 - x[2];
  if (!(r2 > 0.0)) {
    return std::nullopt;
  }
  c.r = std::sqrt(r2);
  // Gauss-Newton on r_i = |p_i - c| - r.
  for (int it = 0; it < 5; ++it) {
    Eigen::Matrix3d jtj = Eigen::Matrix3d::Zero();
    Eigen::Vector3d jtr = Eigen::Vector3d::Zero();
    for (const auto& p : points) {
      const Eigen::Vector2d d = p - c.c;
      const double dist = d.norm();
      if (dist < 1e-12) {
        continue;
      }
      const Eigen::Vector3d j(-d.x() / dist, -d.y() / dist, -1.0);
      const double r = dist - c.r;
      jtj += j * j.transpose();
      jtr += j * r;
    }
    if (std::abs(jtj.determinant()) < 1e-15) {
      break;
    }
    const Eigen::Vector3d step = jtj.inverse() * jtr;
    c.c -= step.head<2>();
    c.r -= step[2];
    if (step.norm() < 1e-10) {
      break;
    }
  }
  if (!(c.r > 0.0) || !c.c.allFinite()) {
    return std::nullopt;
  }
  return c;
}

double signed_area(const std::vector<Eigen::Vector2d>& polygon) {
  double a = 0.0;
  for (std::size_t i = 0; i < polygon.size(); ++i) {
    const auto& p = polygon[i];
    const auto& q = polygon[(i + 1) % polygon.size()];
    a += p.x() * q.y() - q.x() * p.y();
  }
  return 0.5 * a;
}

double median_abs(std::vector<double>& values) {
  if (values.empty()) {
    return 0.0;
  }
  for (double& v : values) {
    v = std::abs(v);
  }
  const auto mid = values.begin() + static_cast<std::ptrdiff_t>(values.size() / 2);
  std::nth_element(values.begin(), mid, values.end());
  return *mid;
}

}  // namespace cell::vision::detail
