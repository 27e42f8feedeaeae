#include "cell/calibration/planar_model.hpp"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <numbers>
#include <set>

#include <ceres/ceres.h>
#include <fmt/format.h>

#include "cell/calibration/pixel_mapping.hpp"
#include "cell/geometry/angles.hpp"
#include "costs.hpp"
#include "solver_util.hpp"

namespace cell::calibration {
namespace {

constexpr double kPi = std::numbers::pi;
using geometry::kDeg;

Eigen::Vector2d unit(double a) { return {std::cos(a), std::sin(a)}; }

double wrap_2pi(double a) {
  a = std::fmod(a, 2.0 * kPi);
  return a < 0.0 ? a + 2.0 * kPi : a;
}

std::array<double, detail::kPlanarSize> to_vector(const PlanarParameters& p) {
  return {p.c_x_px_per_mm, p.c_y_px_per_mm, p.d_t_c_mm, p.b_angl_rad, p.angl_err_rad,
          p.link1_mm,      p.link2_mm};
}

PlanarParameters from_vector(const PlanarParameters& base,
                             const std::array<double, detail::kPlanarSize>& v) {
  PlanarParameters p = base;
  p.c_x_px_per_mm = v[0];
  p.c_y_px_per_mm = v[1];
  p.d_t_c_mm = v[2];
  p.b_angl_rad = wrap_2pi(v[3]);
  p.angl_err_rad = std::remainder(v[4], 2.0 * kPi);
  p.link1_mm = v[5];
  p.link2_mm = v[6];
  return p;
}

Eigen::Vector2d board_to_base(const Eigen::Vector3d& pose, const Eigen::Vector2d& q) {
  const double c = std::cos(pose.z());
  const double s = std::sin(pose.z());
  return {pose.x() + c * q.x() - s * q.y(), pose.y() + s * q.x() + c * q.y()};
}

}  // namespace

Eigen::Vector2d planar_end_effector(const PlanarParameters& p, double j1, double j2) {
  return p.link1_mm * unit(j1) + p.link2_mm * unit(j1 + j2);
}

Eigen::Vector2d planar_pixel_to_base(const PlanarParameters& p, double j1, double j2,
                                     const Eigen::Vector2d& pixel_in, double height_mm) {
  Eigen::Vector2d pixel = pixel_in;
  if (height_mm != 0.0 && p.camera_height_mm > 0.0) {
    // Eq. 2.21/2.22: toward the image centre by h / d_ct.
    const Eigen::Vector2d centre(p.center_u_px, p.center_v_px);
    pixel += (centre - pixel) * (height_mm / p.camera_height_mm);
  }
  const double lambda = j1 + j2;
  const Eigen::Vector2d e = planar_end_effector(p, j1, j2);
  const Eigen::Vector2d r = e + p.d_t_c_mm * unit(lambda + kPi + p.b_angl_rad);
  const double omega = lambda + kPi - p.angl_err_rad;
  const Eigen::Vector2d ei = unit(omega);
  const Eigen::Vector2d ej(std::sin(omega), -std::cos(omega));
  return r + ((pixel.x() - p.ref_u_px) / p.c_x_px_per_mm) * ei +
         ((pixel.y() - p.ref_v_px) / p.c_y_px_per_mm) * ej;
}

Eigen::Vector2d planar_base_to_pixel(const PlanarParameters& p, double j1, double j2,
                                     const Eigen::Vector2d& point) {
  const auto v = to_vector(p);
  double uv[2];
  detail::planar_project(v.data(), p.ref_u_px, p.ref_v_px, j1, j2, point.x(), point.y(), uv);
  return {uv[0], uv[1]};
}

Result<TwoStageResult> two_stage_calibration(const PlanarParameters& p,
                                             const std::vector<TwoStageReading>& readings) {
  if (readings.empty()) {
    return Error{Errc::kInvalidArgument, "two-stage calibration: no readings"};
  }
  TwoStageResult out;
  Eigen::Vector2d dir_sum = Eigen::Vector2d::Zero();
  double d_sum = 0.0;
  double d_min = 1e300;
  double d_max = -1e300;
  std::vector<double> angles;
  for (std::size_t i = 0; i < readings.size(); ++i) {
    const TwoStageReading& r = readings[i];
    if (!std::isfinite(r.j1_rad) || !std::isfinite(r.j2_rad) || !r.stage2_mm.allFinite()) {
      return Error{Errc::kInvalidArgument,
                   fmt::format("two-stage reading {}: a value is not finite", i + 1)};
    }
    // Stage 1: A on the Ref_Point pixel with the elbow at (J1, J2); stage 2: E over A.
    const Eigen::Vector2d e1 = planar_end_effector(p, r.j1_rad, r.j2_rad);
    const Eigen::Vector2d d = r.stage2_mm - e1;
    const double dist = d.norm();
    if (dist < 1e-6) {
      return Error{Errc::kInvalidArgument,
                   fmt::format("two-stage reading {}: stage 2's point ({:.2f}, {:.2f}) mm is the "
                               "stage-1 end-effector itself",
                               i + 1, r.stage2_mm.x(), r.stage2_mm.y())};
    }
    // The angle from tip->elbow to tip->A, counter-clockwise (no atan of a ratio: no sign trap).
    const double b = wrap_2pi(std::atan2(d.y(), d.x()) - (r.j1_rad + r.j2_rad + kPi));
    angles.push_back(b);
    dir_sum += unit(b);
    d_sum += dist;
    d_min = std::min(d_min, dist);
    d_max = std::max(d_max, dist);
  }
  out.readings = static_cast<int>(readings.size());
  out.d_t_c_mm = d_sum / static_cast<double>(readings.size());
  out.b_angl_rad = wrap_2pi(std::atan2(dir_sum.y(), dir_sum.x()));
  out.d_t_c_spread_mm = d_max - d_min;
  double spread = 0.0;
  for (const double a : angles) {
    spread = std::max(spread, std::abs(std::remainder(a - out.b_angl_rad, 2.0 * kPi)));
  }
  out.b_angl_spread_rad = 2.0 * spread;
  return out;
}

Status PlanarOptions::validate() const {
  if (!(huber_px > 0.0)) {
    return Error{Errc::kInvalidArgument,
                 fmt::format("planar options: huber_px must be > 0, got {}", huber_px)};
  }
  if (!(holdout_fraction >= 0.0 && holdout_fraction < 0.5) || min_holdout_views < 0) {
    return Error{Errc::kInvalidArgument,
                 fmt::format("planar options: holdout_fraction must be in [0, 0.5), got {}",
                             holdout_fraction)};
  }
  if (min_fit_views < 1 || max_iterations < 1) {
    return Error{Errc::kInvalidArgument, "planar options: min_fit_views and max_iterations >= 1"};
  }
  return ok_status();
}

std::string PlanarReport::brief() const {
  const PlanarParameters& p = parameters;
  return fmt::format(
      "c_x {:.4f} c_y {:.4f} px/mm, d_t_c {:.3f} mm, b_angl {:.3f} deg, angl_err {:.3f} deg, "
      "link_1 {:.3f} link_2 {:.3f} mm; RMS {:.3f} px over {} views, hold-out {:.3f} px and {:.3f} "
      "mm over {}; {} iterations",
      p.c_x_px_per_mm, p.c_y_px_per_mm, p.d_t_c_mm, p.b_angl_rad / kDeg, p.angl_err_rad / kDeg,
      p.link1_mm, p.link2_mm, rms_px, views_used, holdout_rms_px, holdout_mm, views_held_out,
      solver.iterations);
}

Result<PlanarReport> refine_planar(const PlanarParameters& initial,
                                   const std::vector<PlanarView>& views,
                                   const PlanarOptions& options, const ProgressFn& progress) {
  CELL_TRY(options.validate());
  if (!(initial.c_x_px_per_mm > 0.0) || !(initial.c_y_px_per_mm > 0.0) ||
      !(initial.link1_mm > 0.0) || !(initial.link2_mm > 0.0)) {
    return Error{Errc::kInvalidArgument,
                 "planar refinement: the initial scales and link lengths must be > 0"};
  }
  const auto start = std::chrono::steady_clock::now();
  PlanarReport report;
  report.views.resize(views.size());
  std::vector<std::size_t> usable;
  for (std::size_t i = 0; i < views.size(); ++i) {
    report.views[i].id = views[i].id;
    if (views[i].pixels.size() != views[i].target_points_mm.size() || views[i].pixels.empty()) {
      report.views[i].reason = fmt::format("{} pixels for {} target points", views[i].pixels.size(),
                                           views[i].target_points_mm.size());
    } else if (!std::isfinite(views[i].j1_rad) || !std::isfinite(views[i].j2_rad)) {
      report.views[i].reason = "joints are not finite";
    } else {
      usable.push_back(i);
    }
  }
  auto split = detail::split_holdout(usable, views.size(), options.min_fit_views,
                                     options.min_holdout_views, options.holdout_fraction, "views");
  if (!split) {
    return std::move(split).error();
  }
  const std::vector<std::size_t>& fit_idx = split->fit;
  const std::vector<std::size_t>& hold_idx = split->held;
  auto params = to_vector(initial);
  // The target's pose from the initial model: a 2-D rigid fit of its points to where the
  // model maps their pixels, over the fitted views.
  std::array<double, 3> target{0.0, 0.0, 0.0};
  if (!options.target_in_base) {
    Eigen::Vector2d mean_q = Eigen::Vector2d::Zero();
    Eigen::Vector2d mean_p = Eigen::Vector2d::Zero();
    std::size_t n = 0;
    for (const std::size_t i : fit_idx) {
      for (std::size_t k = 0; k < views[i].pixels.size(); ++k) {
        mean_q += views[i].target_points_mm[k];
        mean_p += planar_pixel_to_base(initial, views[i].j1_rad, views[i].j2_rad,
                                       views[i].pixels[k]);
        ++n;
      }
    }
    mean_q /= static_cast<double>(n);
    mean_p /= static_cast<double>(n);
    double sxx = 0.0;
    double sxy = 0.0;
    for (const std::size_t i : fit_idx) {
      for (std::size_t k = 0; k < views[i].pixels.size(); ++k) {
        const Eigen::Vector2d q = views[i].target_points_mm[k] - mean_q;
        const Eigen::Vector2d p = planar_pixel_to_base(initial, views[i].j1_rad, views[i].j2_rad,
                                                       views[i].pixels[k]) -
                                  mean_p;
        sxx += q.dot(p);
        sxy += q.x() * p.y() - q.y() * p.x();
      }
    }
    const double yaw = std::atan2(sxy, sxx);
    const Eigen::Vector2d t = mean_p - Eigen::Rotation2Dd(yaw) * mean_q;
    target = {t.x(), t.y(), yaw};
  }
  auto solve = [&](bool robust) {
    ceres::Problem problem;
    for (const std::size_t i : fit_idx) {
      for (std::size_t k = 0; k < views[i].pixels.size(); ++k) {
        ceres::LossFunction* loss = robust ? new ceres::HuberLoss(options.huber_px) : nullptr;
        if (options.target_in_base) {
          problem.AddResidualBlock(
              detail::PlanarPointReprojection::create(views[i].pixels[k],
                                                      views[i].target_points_mm[k],
                                                      views[i].j1_rad, views[i].j2_rad,
                                                      initial.ref_u_px, initial.ref_v_px),
              loss, params.data());
        } else {
          problem.AddResidualBlock(
              detail::PlanarReprojection::create(views[i].pixels[k], views[i].target_points_mm[k],
                                                 views[i].j1_rad, views[i].j2_rad,
                                                 initial.ref_u_px, initial.ref_v_px),
              loss, params.data(), target.data());
        }
      }
    }
    if (!options.refine_links) {
      problem.SetManifold(params.data(), new ceres::SubsetManifold(detail::kPlanarSize, {5, 6}));
    }
    ceres::Solver::Options so = detail::solver_options(options.max_iterations);
    so.linear_solver_type = ceres::DENSE_QR;
    ceres::Solver::Summary summary;
    ceres::Solve(so, &problem, &summary);
    return detail::condense(summary);
  };
  if (progress) {
    progress("solve", 1, 2, "robust least squares over every parameter");
  }
  SolverSummary summary = solve(true);
  if (progress) {
    progress("solve", 2, 2, "least squares");
  }
  const SolverSummary last = solve(false);
  summary.iterations += last.iterations;
  summary.converged = last.converged;
  summary.termination = last.termination;
  summary.final_cost = last.final_cost;
  if (!(params[0] > 0.0) || !(params[1] > 0.0)) {
    return Error{Errc::kOutOfRange, "planar refinement left a pixel scale <= 0: the views do not "
                                    "determine the model"};
  }
  report.parameters = from_vector(initial, params);
  report.target_pose = Eigen::Vector3d(target[0], target[1], target[2]);
  auto base_point = [&](const PlanarView& v, std::size_t k) {
    return options.target_in_base ? v.target_points_mm[k]
                                  : board_to_base(report.target_pose, v.target_points_mm[k]);
  };
  double sum = 0.0;
  std::size_t n = 0;
  for (const std::size_t i : fit_idx) {
    double s = 0.0;
    for (std::size_t k = 0; k < views[i].pixels.size(); ++k) {
      s += (planar_base_to_pixel(report.parameters, views[i].j1_rad, views[i].j2_rad,
                                 base_point(views[i], k)) -
            views[i].pixels[k])
               .squaredNorm();
    }
    report.views[i].used = true;
    report.views[i].rms_px = std::sqrt(s / static_cast<double>(views[i].pixels.size()));
    sum += s;
    n += views[i].pixels.size();
  }
  report.rms_px = std::sqrt(sum / static_cast<double>(n));
  report.views_used = static_cast<int>(fit_idx.size());
  double hold_px = 0.0;
  double hold_mm = 0.0;
  std::size_t hold_n = 0;
  for (const std::size_t i : hold_idx) {
    double s = 0.0;
    for (std::size_t k = 0; k < views[i].pixels.size(); ++k) {
      s += (planar_base_to_pixel(report.parameters, views[i].j1_rad, views[i].j2_rad,
                                 base_point(views[i], k)) -
            views[i].pixels[k])
               .squaredNorm();
      hold_mm += (planar_pixel_to_base(report.parameters, views[i].j1_rad, views[i].j2_rad,
                                       views[i].pixels[k]) -
                  base_point(views[i], k))
                     .squaredNorm();
    }
    report.views[i].held_out = true;
    report.views[i].rms_px = std::sqrt(s / static_cast<double>(views[i].pixels.size()));
    hold_px += s;
    hold_n += views[i].pixels.size();
  }
  report.views_held_out = static_cast<int>(hold_idx.size());
  report.holdout_rms_px = hold_n > 0 ? std::sqrt(hold_px / static_cast<double>(hold_n)) : 0.0;
  report.holdout_mm = hold_n > 0 ? std::sqrt(hold_mm / static_cast<double>(hold_n)) : 0.0;
  summary.time_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  report.solver = summary;
  return report;
}

Result<PlanarParameters> planar_from_pinhole(const CameraCalibration& calibration,
                                             const Eigen::Vector2d& ref_px,
                                             double link1_mm,
                                             double link2_mm) {
  CELL_TRY(calibration.validate());
  if (calibration.model != ModelType::kPinhole || calibration.mounting != Mounting::kEyeInHand ||
      calibration.mount_frame != render::MountFrame::kLink2) {
    return Error{Errc::kInvalidArgument,
                 fmt::format("camera '{}': the planar model comes from a pinhole camera on a "
                             "SCARA's link 2",
                             calibration.camera_id)};
  }
  if (!(link1_mm > 0.0) || !(link2_mm > 0.0)) {
    return Error{Errc::kInvalidArgument, "planar model: link lengths must be > 0"};
  }
  auto model = calibration.camera_model();
  if (!model) {
    return std::move(model).error();
  }
  // Lens-free copy: the planar model has none.
  auto ideal = render::CameraModel::create(
      calibration.width_px, calibration.height_px, calibration.pinhole.fx_px,
      calibration.pinhole.fy_px, calibration.pinhole.cx_px, calibration.pinhole.cy_px, {});
  if (!ideal) {
    return std::move(ideal).error();
  }
  // The elbow at (0, 0): link 2 along +x, the mount frame at (l1 + l2, 0, 0) (its origin at
  // the flange height with Z = 0, which the 7545's base frame puts at z = 0).
  Eigen::Isometry3d mount = Eigen::Isometry3d::Identity();
  mount.translation() = Eigen::Vector3d(link1_mm + link2_mm, 0.0, 0.0);
  const Eigen::Isometry3d base_T_cam = mount * calibration.extrinsics;
  const double plane = calibration.working_plane_z_mm;
  auto r = pixel_to_plane(*ideal, base_T_cam, ref_px, plane);
  auto ri = pixel_to_plane(*ideal, base_T_cam, ref_px + Eigen::Vector2d(10.0, 0.0), plane);
  auto centre = pixel_to_plane(*ideal, base_T_cam,
                               {calibration.pinhole.cx_px, calibration.pinhole.cy_px}, plane);
  if (!r || !ri || !centre) {
    return Error{Errc::kInvalidArgument,
                 fmt::format("camera '{}': the working plane z = {} mm is not in view",
                             calibration.camera_id, plane)};
  }
  PlanarParameters p;
  const double height = base_T_cam.translation().z() - plane;
  p.camera_height_mm = height;
  p.c_x_px_per_mm = calibration.pinhole.fx_px / height;
  p.c_y_px_per_mm = calibration.pinhole.fy_px / height;
  p.ref_u_px = ref_px.x();
  p.ref_v_px = ref_px.y();
  p.center_u_px = calibration.pinhole.cx_px;
  p.center_v_px = calibration.pinhole.cy_px;
  p.link1_mm = link1_mm;
  p.link2_mm = link2_mm;
  const Eigen::Vector2d e(link1_mm + link2_mm, 0.0);
  const Eigen::Vector2d d = r->head<2>() - e;
  p.d_t_c_mm = d.norm();
  p.b_angl_rad = wrap_2pi(std::atan2(d.y(), d.x()) - kPi);
  const Eigen::Vector2d ei = (ri->head<2>() - r->head<2>()).normalized();
  p.angl_err_rad = std::remainder(kPi - std::atan2(ei.y(), ei.x()), 2.0 * kPi);
  return p;
}

}  // namespace cell::calibration
