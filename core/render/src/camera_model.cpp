#include "cell/render/camera_model.hpp"

#include <algorithm>
#include <cmath>

#include <Eigen/LU>
#include <fmt/format.h>

namespace cell::render {
namespace {

constexpr double kRadiusCap = 4.0;     // ~76 degrees off axis: no lens of this cell sees wider
constexpr double kFoldMargin = 0.98;   // stay a little inside the fold of the polynomial
constexpr int kMaxNewtonSteps = 60;
constexpr double kNewtonTol = 1e-13;

bool finite(double v) noexcept { return std::isfinite(v); }

/// Smallest radius where d/dr [r (1 + k1 r^2 + k2 r^4 + k3 r^6)] <= 0, or kRadiusCap.
double fold_radius(const Distortion& d) noexcept {
  constexpr double kStep = 1e-3;
  for (double r = kStep; r <= kRadiusCap; r += kStep) {
    const double r2 = r * r;
    const double slope = 1.0 + 3.0 * d.k1 * r2 + 5.0 * d.k2 * r2 * r2 + 7.0 * d.k3 * r2 * r2 * r2;
    if (slope <= 0.0) {
      return (r - kStep) * kFoldMargin;
    }
  }
  return kRadiusCap;
}

}  // namespace

bool Distortion::is_zero() const noexcept {
  return k1 == 0.0 && k2 == 0.0 && p1 == 0.0 && p2 == 0.0 && k3 == 0.0;
}

Result<CameraModel> CameraModel::create(int width_px, int height_px, double fx_px, double fy_px,
                                        double cx_px, double cy_px,
                                        const Distortion& distortion) {
  constexpr int kMaxSize = 16384;
  if (width_px < 1 || width_px > kMaxSize || height_px < 1 || height_px > kMaxSize) {
    return Error{Errc::kInvalidArgument,
                 fmt::format("camera size {} x {} px: each side must be 1..{}", width_px,
                             height_px, kMaxSize)};
  }
  if (!finite(fx_px) || !finite(fy_px) || fx_px <= 0.0 || fy_px <= 0.0) {
    return Error{Errc::kInvalidArgument,
                 fmt::format("focal lengths fx = {}, fy = {} px: must be finite and > 0", fx_px,
                             fy_px)};
  }
  if (!finite(cx_px) || !finite(cy_px)) {
    return Error{Errc::kInvalidArgument,
                 fmt::format("principal point ({}, {}) px is not finite", cx_px, cy_px)};
  }
  const auto coeffs = distortion.as_array();
  static constexpr std::array<const char*, 5> kNames = {"k1", "k2", "p1", "p2", "k3"};
  for (std::size_t i = 0; i < coeffs.size(); ++i) {
    if (!finite(coeffs[i])) {
      return Error{Errc::kInvalidArgument,
                   fmt::format("distortion {} = {} is not finite", kNames[i], coeffs[i])};
    }
  }
  CameraModel m;
  m.width_px_ = width_px;
  m.height_px_ = height_px;
  m.fx_ = fx_px;
  m.fy_ = fy_px;
  m.cx_ = cx_px;
  m.cy_ = cy_px;
  m.distortion_ = distortion;
  m.max_ideal_radius_ = fold_radius(distortion);
  // The ideal rectangle holding the image: undistort the border of the pixel area, every
  // pixel or so. A border point the lens cannot produce means the polynomial folds inside
  // the image.
  NormalisedBounds b{1e300, -1e300, 1e300, -1e300};
  const double u_lo = -0.5;
  const double u_hi = width_px - 0.5;
  const double v_lo = -0.5;
  const double v_hi = height_px - 0.5;
  auto visit = [&](double u, double v) -> Status {
    const Eigen::Vector2d d((u - cx_px) / fx_px, (v - cy_px) / fy_px);
    auto ideal = m.undistort(d);
    if (!ideal) {
      return Error{Errc::kInvalidArgument,
                   fmt::format("distortion (k1 {}, k2 {}, p1 {}, p2 {}, k3 {}) folds back inside "
                               "the image: pixel ({:.1f}, {:.1f}) has no undistorted position",
                               distortion.k1, distortion.k2, distortion.p1, distortion.p2,
                               distortion.k3, u, v)};
    }
    b.x_min = std::min(b.x_min, ideal->x());
    b.x_max = std::max(b.x_max, ideal->x());
    b.y_min = std::min(b.y_min, ideal->y());
    b.y_max = std::max(b.y_max, ideal->y());
    return ok_status();
  };
  const int nu = width_px + 1;
  const int nv = height_px + 1;
  for (int i = 0; i <= nu; ++i) {
    const double u = u_lo + (u_hi - u_lo) * i / nu;
    CELL_TRY(visit(u, v_lo));
    CELL_TRY(visit(u, v_hi));
  }
  for (int j = 0; j <= nv; ++j) {
    const double v = v_lo + (v_hi - v_lo) * j / nv;
    CELL_TRY(visit(u_lo, v));
    CELL_TRY(visit(u_hi, v));
  }
  m.image_bounds_ = b;
  return m;
}

Eigen::Matrix3d CameraModel::camera_matrix() const noexcept {
  Eigen::Matrix3d k;
  k << fx_, 0.0, cx_, 0.0, fy_, cy_, 0.0, 0.0, 1.0;
  return k;
}

Eigen::Vector2d CameraModel::distort(const Eigen::Vector2d& ideal) const noexcept {
  const Distortion& d = distortion_;
  const double x = ideal.x();
  const double y = ideal.y();
  const double r2 = x * x + y * y;
  const double radial = 1.0 + r2 * (d.k1 + r2 * (d.k2 + r2 * d.k3));
  return {x * radial + 2.0 * d.p1 * x * y + d.p2 * (r2 + 2.0 * x * x),
          y * radial + d.p1 * (r2 + 2.0 * y * y) + 2.0 * d.p2 * x * y};
}

Result<Eigen::Vector2d> CameraModel::undistort(const Eigen::Vector2d& distorted) const {
  if (!distorted.allFinite()) {
    return Error{Errc::kInvalidArgument, "undistort: coordinates are not finite"};
  }
  if (distortion_.is_zero()) {
    return distorted;
  }
  const Distortion& d = distortion_;
  Eigen::Vector2d p = distorted;
  for (int step = 0; step < kMaxNewtonSteps; ++step) {
    const double x = p.x();
    const double y = p.y();
    const double r2 = x * x + y * y;
    const double radial = 1.0 + r2 * (d.k1 + r2 * (d.k2 + r2 * d.k3));
    const double dradial = d.k1 + r2 * (2.0 * d.k2 + 3.0 * d.k3 * r2);  // d radial / d r2
    const Eigen::Vector2d f = distort(p) - distorted;
    Eigen::Matrix2d j;
    j(0, 0) = radial + 2.0 * x * x * dradial + 2.0 * d.p1 * y + 6.0 * d.p2 * x;
    j(0, 1) = 2.0 * x * y * dradial + 2.0 * d.p1 * x + 2.0 * d.p2 * y;
    j(1, 0) = j(0, 1);
    j(1, 1) = radial + 2.0 * y * y * dradial + 6.0 * d.p1 * y + 2.0 * d.p2 * x;
    const double det = j.determinant();
    if (!(std::abs(det) > 1e-12)) {
      break;
    }
    const Eigen::Vector2d delta = j.inverse() * f;
    p -= delta;
    if (!p.allFinite() || p.norm() > 2.0 * kRadiusCap) {
      break;
    }
    if (delta.norm() < kNewtonTol) {
      if (p.norm() <= max_ideal_radius_ && (distort(p) - distorted).norm() < 1e-10) {
        return p;
      }
      break;
    }
  }
  return Error{Errc::kOutOfRange,
               fmt::format("normalised point ({:.6f}, {:.6f}) lies outside the lens's field",
                           distorted.x(), distorted.y())};
}

Eigen::Vector2d CameraModel::project_normalised(const Eigen::Vector2d& ideal) const noexcept {
  const Eigen::Vector2d d = distort(ideal);
  return {fx_ * d.x() + cx_, fy_ * d.y() + cy_};
}

Result<Eigen::Vector2d> CameraModel::project(const Eigen::Vector3d& p_camera) const {
  if (!p_camera.allFinite()) {
    return Error{Errc::kInvalidArgument, "project: point is not finite"};
  }
  if (!(p_camera.z() > 0.0)) {
    return Error{Errc::kOutOfRange,
                 fmt::format("point ({:.3f}, {:.3f}, {:.3f}) mm is not in front of the camera",
                             p_camera.x(), p_camera.y(), p_camera.z())};
  }
  const Eigen::Vector2d ideal(p_camera.x() / p_camera.z(), p_camera.y() / p_camera.z());
  if (ideal.norm() > max_ideal_radius_) {
    return Error{Errc::kOutOfRange,
                 fmt::format("point ({:.3f}, {:.3f}, {:.3f}) mm lies outside the lens's field",
                             p_camera.x(), p_camera.y(), p_camera.z())};
  }
  return project_normalised(ideal);
}

Result<Eigen::Vector3d> CameraModel::unproject(const Eigen::Vector2d& pixel) const {
  const Eigen::Vector2d d((pixel.x() - cx_) / fx_, (pixel.y() - cy_) / fy_);
  auto ideal = undistort(d);
  if (!ideal) {
    return std::move(ideal).error();
  }
  return Eigen::Vector3d(ideal->x(), ideal->y(), 1.0);
}

}  // namespace cell::render
