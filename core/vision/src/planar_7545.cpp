#include "cell/vision/planar_7545.hpp"

#include <fmt/format.h>

#include <Eigen/LU>
#include <cmath>
#include <numbers>

#include "cell/geometry/angles.hpp"

namespace cell::vision {
namespace {

using geometry::kPi;

Status check_planar(const calibration::PlanarParameters& p) {
  if (!(p.c_x_px_per_mm > 0.0 && p.c_y_px_per_mm > 0.0 && std::isfinite(p.c_x_px_per_mm) &&
        std::isfinite(p.c_y_px_per_mm))) {
    return Error{Errc::kInvalidArgument,
                 fmt::format("planar model: c_x and c_y must be > 0 px/mm, got {} and {}",
                             p.c_x_px_per_mm, p.c_y_px_per_mm)};
  }
  for (double v :
       {p.ref_u_px, p.ref_v_px, p.d_t_c_mm, p.b_angl_rad, p.angl_err_rad, p.link1_mm, p.link2_mm}) {
    if (!std::isfinite(v)) {
      return Error{Errc::kInvalidArgument, "planar model: a parameter is not finite"};
    }
  }
  return ok_status();
}

}  // namespace

Eigen::Vector2d thesis_parallax(const Eigen::Vector2d& px,
                                const Eigen::Vector2d& centre_px,
                                double height_mm,
                                double camera_height_mm) noexcept {
  return px + (centre_px - px) * (height_mm / camera_height_mm);
}

Eigen::Vector2i thesis_parallax_int(const Eigen::Vector2i& px,
                                    const Eigen::Vector2i& centre_px,
                                    double height_mm,
                                    double camera_height_mm) noexcept {
  // rec_corner.c: edgp = floor(edgp + (y0 - edgp) * i_c_h / c_i_d + .5), per coordinate.
  Eigen::Vector2i out;
  for (int k = 0; k < 2; ++k) {
    out[k] = static_cast<int>(
        std::floor(px[k] + (centre_px[k] - px[k]) * height_mm / camera_height_mm + 0.5));
  }
  return out;
}

Result<Eigen::Vector2d> planar_pixel_to_base(const calibration::PlanarParameters& p,
                                             double j1_rad,
                                             double j2_rad,
                                             const Eigen::Vector2d& px) {
  CELL_TRY(check_planar(p));
  if (!(std::isfinite(j1_rad) && std::isfinite(j2_rad) && px.allFinite())) {
    return Error{Errc::kInvalidArgument, "planar model: joints or pixel not finite"};
  }
  // rec_po.c, in radians. Its c_x, c_y are mm/px (1/3.56, 1/3.48); ours are px/mm.
  const double mm_x = 1.0 / p.c_x_px_per_mm;
  const double mm_y = 1.0 / p.c_y_px_per_mm;
  const double theta = (kPi - p.b_angl_rad) - p.angl_err_rad;
  const double di = px.x() - p.ref_u_px;
  const double dj = px.y() - p.ref_v_px;
  const double gamma = (di == 0.0) ? theta + kPi / 2
                                   : theta + std::atan(mm_y * std::abs(dj) / (std::abs(di) * mm_x));
  const double d_c_ic = std::hypot(di * mm_x, dj * mm_y);
  const double d_t_c = p.d_t_c_mm;
  const double d_t_ic = std::sqrt(
      std::max(0.0, d_t_c * d_t_c + d_c_ic * d_c_ic - 2.0 * d_t_c * d_c_ic * std::cos(gamma)));
  const double jt = j1_rad + j2_rad;
  double x = p.link2_mm * std::cos(jt) + p.link1_mm * std::cos(j1_rad);
  double y = p.link2_mm * std::sin(jt) + p.link1_mm * std::sin(j1_rad);
  if (d_t_ic < 1e-12 || d_t_c <= 0.0) {
    return Eigen::Vector2d(x, y);  // the pixel sees the tool axis itself
  }
  const double c = (d_t_c * d_t_c + d_t_ic * d_t_ic - d_c_ic * d_c_ic) / (2.0 * d_t_ic * d_t_c);
  const double beta_1 = std::acos(std::clamp(c, -1.0, 1.0));
  const double phi = kPi - (p.b_angl_rad - beta_1) - jt;
  x += d_t_ic * std::cos(phi);
  y -= d_t_ic * std::sin(phi);
  return Eigen::Vector2d(x, y);
}

Result<Eigen::Vector2d> planar_base_to_pixel(const calibration::PlanarParameters& p,
                                             double j1_rad,
                                             double j2_rad,
                                             const Eigen::Vector2d& base_xy_mm) {
  CELL_TRY(check_planar(p));
  if (!base_xy_mm.allFinite()) {
    return Error{Errc::kInvalidArgument, "planar model: point not finite"};
  }
  Eigen::Vector2d px(p.center_u_px, p.center_v_px);
  constexpr double kStep = 1e-3;  // px, for the finite-difference Jacobian
  for (int iteration = 0; iteration < 50; ++iteration) {
    auto f = planar_pixel_to_base(p, j1_rad, j2_rad, px);
    if (!f) {
      return f.error();
    }
    const Eigen::Vector2d r = *f - base_xy_mm;
    if (r.norm() < 1e-10) {
      return px;
    }
    Eigen::Matrix2d jac;
    for (int k = 0; k < 2; ++k) {
      Eigen::Vector2d q = px;
      q[k] += kStep;
      auto fk = planar_pixel_to_base(p, j1_rad, j2_rad, q);
      if (!fk) {
        return fk.error();
      }
      jac.col(k) = (*fk - *f) / kStep;
    }
    if (std::abs(jac.determinant()) < 1e-12) {
      break;
    }
    Eigen::Vector2d step = jac.inverse() * r;
    if (step.norm() > 200.0) {
      step *= 200.0 / step.norm();
    }
    px -= step;
  }
  auto f = planar_pixel_to_base(p, j1_rad, j2_rad, px);
  if (f && (*f - base_xy_mm).norm() < 1e-7) {
    return px;
  }
  return Error{Errc::kOutOfRange,
               fmt::format("planar model: no pixel maps to ({:.2f}, {:.2f}) mm at J1 {:.2f} deg, "
                           "J2 {:.2f} deg (outside the model's image quadrant)",
                           base_xy_mm.x(), base_xy_mm.y(), j1_rad * 180 / kPi, j2_rad * 180 / kPi)};
}

double thesis_alpha_deg(const Eigen::Vector2d& c0,
                        const Eigen::Vector2d& c1,
                        const Eigen::Vector2d& c2,
                        const Eigen::Vector2d& c3,
                        double aspect) noexcept {
  constexpr double kDegPerRad = 180.0 / kPi;  // the code's `pi` variable is 180/pi
  double dy1 = (c0.y() - c1.y()) * aspect;
  const double dx1 = c0.x() - c1.x();
  double dy2 = (c2.y() - c3.y()) * aspect;
  const double dx2 = c2.x() - c3.x();
  if (dy1 == 0.0) {
    dy1 = 0.01;
  }
  if (dy2 == 0.0) {
    dy2 = 0.01;
  }
  const double a1 = std::atan(dx1 / dy1) * kDegPerRad;
  const double a2 = std::atan(dx2 / dy2) * kDegPerRad;
  const double temp = a1 - a2;
  if (temp > 150.0 || temp < -150.0) {
    return 90.0;
  }
  return (a1 + a2) / 2.0;
}

double thesis_roll_deg(double alpha_deg,
                       double j1_rad,
                       double j2_rad,
                       double angl_err_rad) noexcept {
  constexpr double kDegPerRad = 180.0 / kPi;
  double o = -(alpha_deg + (j1_rad + j2_rad) * kDegPerRad - 90.0 - angl_err_rad * kDegPerRad);
  if (o > 90.0) {
    o -= 180.0;
  }
  if (o < -90.0) {
    o += 180.0;
  }
  return o;
}

long thesis_roll_counts(double roll_deg) noexcept { return static_cast<long>(roll_deg * 227.5556); }

}  // namespace cell::vision
