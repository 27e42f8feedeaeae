#include "cell/vision/pixel_mapper.hpp"

#include <fmt/format.h>

#include <cmath>
#include <numbers>
#include <vector>

#include "cell/render/mount.hpp"
#include "cell/vision/planar_7545.hpp"
#include "support.hpp"

namespace cell::vision {

/// Normalised ideal coordinates of every pixel of a regular grid (kStep px) covering the image
/// with a margin, so that undistortion is a bilinear lookup. The lens is smooth: over 8 px the
/// bilinear error is below 0.002 px for the cell's lenses (test
/// PixelMapper.TrueCalibrationMapsPixelsBackToTheirWorldPoints).
struct PixelMapper::Grid {
  static constexpr int kStep = 8;
  static constexpr int kMargin = 16;
  int cols = 0;
  int rows = 0;
  double u0 = 0.0;
  double v0 = 0.0;
  std::vector<Eigen::Vector2d> ideal;  // row-major
  std::vector<unsigned char> valid;
};

namespace {

using detail::invalid;

std::string calibration_name(const calibration::CameraCalibration& c) {
  if (!c.version.empty()) {
    return fmt::format("calibration {}", c.version);
  }
  return c.source.empty() ? std::string("calibration (no version)") : c.source;
}

}  // namespace

PixelMapper::PixelMapper() : description_("none: pixels (no calibration)") {}

Result<PixelMapper> PixelMapper::create(const calibration::CameraCalibration& calibration,
                                        const kinematics::RobotModel* robot,
                                        std::span<const double> joints) {
  CELL_TRY(calibration.validate());
  PixelMapper m;
  m.calibration_ = calibration;
  m.width_px_ = calibration.width_px;
  m.height_px_ = calibration.height_px;
  if (calibration.model == calibration::ModelType::kPinhole) {
    auto camera = calibration.camera_model();
    if (!camera) {
      return camera.error();
    }
    m.camera_ = *camera;
    if (!m.camera_.distortion().is_zero()) {
      auto grid = std::make_shared<Grid>();
      grid->u0 = -Grid::kMargin;
      grid->v0 = -Grid::kMargin;
      grid->cols = (m.width_px_ + 2 * Grid::kMargin) / Grid::kStep + 2;
      grid->rows = (m.height_px_ + 2 * Grid::kMargin) / Grid::kStep + 2;
      grid->ideal.resize(static_cast<std::size_t>(grid->cols) *
                         static_cast<std::size_t>(grid->rows));
      grid->valid.resize(grid->ideal.size());
      const double fx = m.camera_.fx_px();
      const double fy = m.camera_.fy_px();
      for (int r = 0; r < grid->rows; ++r) {
        for (int c = 0; c < grid->cols; ++c) {
          const Eigen::Vector2d px(grid->u0 + c * Grid::kStep, grid->v0 + r * Grid::kStep);
          const Eigen::Vector2d distorted((px.x() - m.camera_.cx_px()) / fx,
                                          (px.y() - m.camera_.cy_px()) / fy);
          const auto ideal = m.camera_.undistort(distorted);
          const auto i = static_cast<std::size_t>(r) * static_cast<std::size_t>(grid->cols) +
                         static_cast<std::size_t>(c);
          grid->valid[i] = ideal ? 1 : 0;
          grid->ideal[i] = ideal ? *ideal : Eigen::Vector2d::Zero();
        }
      }
      m.grid_ = std::move(grid);
    }
  }
  CELL_TRY(m.bind(robot, joints));
  return m;
}

Result<PixelMapper> PixelMapper::rebind(const kinematics::RobotModel* robot,
                                        std::span<const double> joints) const {
  if (!calibration_) {
    return Error{Errc::kNotReady, "the identity mapping has no calibration to rebind"};
  }
  PixelMapper m = *this;
  CELL_TRY(m.bind(robot, joints));
  return m;
}

Status PixelMapper::bind(const kinematics::RobotModel* robot, std::span<const double> joints) {
  const calibration::CameraCalibration& c = *calibration_;
  const std::string name = calibration_name(c);
  for (double q : joints) {
    if (!std::isfinite(q)) {
      return invalid(fmt::format("camera '{}': a joint at exposure is not finite", c.camera_id));
    }
  }
  if (robot != nullptr && !c.robot_id.empty() && robot->id() != c.robot_id) {
    return invalid(fmt::format("camera '{}': its calibration refers to robot '{}', not '{}'",
                               c.camera_id, c.robot_id, robot->id()));
  }
  robot_id_ = c.robot_id;
  world_ = false;
  if (c.model == calibration::ModelType::kPlanar7545) {
    kind_ = Kind::kPlanar;
    const auto& p = c.planar;
    if (!(p.camera_height_mm > 0.0)) {
      return invalid(
          fmt::format("camera '{}': the planar model needs camera_height_mm > 0", c.camera_id));
    }
    nadir_ = Eigen::Vector2d::Zero();
    camera_height_mm_ = p.camera_height_mm;
    if (joints.size() >= 2) {
      j1_rad_ = joints[0];
      j2_rad_ = joints[1];
      world_ = true;
      description_ =
          fmt::format("planar_7545 (thesis model, {}), J1 {:.3f} J2 {:.3f} deg", name,
                      j1_rad_ * 180.0 / std::numbers::pi, j2_rad_ * 180.0 / std::numbers::pi);
    } else {
      description_ = fmt::format("planar_7545 ({}): image only, no joints at exposure", name);
    }
    return ok_status();
  }
  // Pinhole: place the camera over the working plane.
  Eigen::Isometry3d base_T_camera = c.extrinsics;
  bool placed = true;
  std::string how;
  if (c.mounting == calibration::Mounting::kEyeInHand) {
    const std::string frame(render::to_string(c.mount_frame));
    if (robot == nullptr) {
      placed = false;
      how = fmt::format("eye-in-hand on '{}' but its robot model is not loaded", c.robot_id);
    } else {
      kinematics::JointVector q = kinematics::JointVector::Zero(robot->dof());
      const bool have_joints = !joints.empty();
      if (have_joints) {
        if (static_cast<int>(joints.size()) != robot->dof()) {
          return invalid(fmt::format("camera '{}': {} joints at exposure for robot '{}' with {}",
                                     c.camera_id, joints.size(), robot->id(), robot->dof()));
        }
        for (int i = 0; i < robot->dof(); ++i) {
          q[i] = joints[static_cast<std::size_t>(i)];
        }
      } else if (c.mount_frame != render::MountFrame::kLink2) {
        placed = false;
        how = fmt::format("eye-in-hand on '{}' ({}) with no joints at exposure", c.robot_id, frame);
      }
      if (placed) {
        auto base_T_mount = render::base_T_mount(*robot, c.mount_frame, q);
        if (!base_T_mount) {
          return base_T_mount.error();
        }
        base_T_camera = *base_T_mount * c.extrinsics;
        world_ = have_joints;
        how = have_joints ? fmt::format("eye-in-hand on '{}' ({})", c.robot_id, frame)
                          : fmt::format(
                                "eye-in-hand on '{}' ({}), no joints at exposure: sizes and "
                                "parallax right, no robot pose",
                                c.robot_id, frame);
      }
    }
  } else {
    world_ = true;
    how = fmt::format("fixed, base of '{}'", c.robot_id);
  }
  if (!placed) {
    kind_ = Kind::kPinholeIdeal;
    world_ = false;
    camera_height_mm_ = 0.0;
    description_ = fmt::format("pinhole ({}): ideal image only, {}", name, how);
    return ok_status();
  }
  kind_ = Kind::kPinhole;
  Eigen::Isometry3d plane_T_base = Eigen::Isometry3d::Identity();
  plane_T_base.translation().z() = -c.working_plane_z_mm;
  plane_T_camera_ = plane_T_base * base_T_camera;
  camera_T_plane_ = plane_T_camera_.inverse();
  const Eigen::Vector3d axis = plane_T_camera_.linear().col(2);
  const double height = plane_T_camera_.translation().z();
  if (!(axis.z() < -1e-3) || !(height > 0.0)) {
    return Error{Errc::kOutOfRange,
                 fmt::format("camera '{}' does not look down at its working plane z = {} mm "
                             "(camera {:.1f} mm above it, axis z {:.3f})",
                             c.camera_id, c.working_plane_z_mm, height, axis.z())};
  }
  nadir_ = plane_T_camera_.translation().head<2>();
  camera_height_mm_ = height;
  description_ =
      fmt::format("pinhole {} ({}), camera {:.1f} mm above the plane", how, name, height);
  return ok_status();
}

Result<Eigen::Vector2d> PixelMapper::undistort_normalised(const Eigen::Vector2d& px) const {
  const double fx = camera_.fx_px();
  const double fy = camera_.fy_px();
  Eigen::Vector2d distorted((px.x() - camera_.cx_px()) / fx, (px.y() - camera_.cy_px()) / fy);
  if (!grid_) {
    return distorted;  // no lens model: ideal = distorted
  }
  const Grid& g = *grid_;
  const double gx = (px.x() - g.u0) / Grid::kStep;
  const double gy = (px.y() - g.v0) / Grid::kStep;
  const int c0 = static_cast<int>(std::floor(gx));
  const int r0 = static_cast<int>(std::floor(gy));
  if (c0 < 0 || r0 < 0 || c0 + 1 >= g.cols || r0 + 1 >= g.rows) {
    return camera_.undistort(distorted);  // beyond the grid: Newton
  }
  const auto at = [&](int r, int c) {
    return static_cast<std::size_t>(r) * static_cast<std::size_t>(g.cols) +
           static_cast<std::size_t>(c);
  };
  const std::size_t i00 = at(r0, c0);
  const std::size_t i01 = at(r0, c0 + 1);
  const std::size_t i10 = at(r0 + 1, c0);
  const std::size_t i11 = at(r0 + 1, c0 + 1);
  if (!(g.valid[i00] && g.valid[i01] && g.valid[i10] && g.valid[i11])) {
    return camera_.undistort(distorted);
  }
  const double tx = gx - c0;
  const double ty = gy - r0;
  return (1 - ty) * ((1 - tx) * g.ideal[i00] + tx * g.ideal[i01]) +
         ty * ((1 - tx) * g.ideal[i10] + tx * g.ideal[i11]);
}

Result<Eigen::Vector2d> PixelMapper::to_plane(const Eigen::Vector2d& px, double height_mm) const {
  switch (kind_) {
    case Kind::kNone:
      return px;
    case Kind::kPinholeIdeal: {
      auto n = undistort_normalised(px);
      if (!n) {
        return n.error();
      }
      return Eigen::Vector2d(n->x() * camera_.fx_px() + camera_.cx_px(),
                             n->y() * camera_.fy_px() + camera_.cy_px());
    }
    case Kind::kPinhole: {
      auto n = undistort_normalised(px);
      if (!n) {
        return n.error();
      }
      const Eigen::Vector3d ray = plane_T_camera_.linear() * Eigen::Vector3d(n->x(), n->y(), 1.0);
      const Eigen::Vector3d& o = plane_T_camera_.translation();
      if (!(ray.z() < -1e-12)) {
        return Error{Errc::kOutOfRange, "pixel's ray does not go down to the plane"};
      }
      const double s = (height_mm - o.z()) / ray.z();
      if (!(s > 0.0)) {
        return Error{Errc::kOutOfRange, "plane behind the camera"};
      }
      return Eigen::Vector2d(o.x() + s * ray.x(), o.y() + s * ray.y());
    }
    case Kind::kPlanar: {
      const auto& p = calibration_->planar;
      const Eigen::Vector2d c(p.center_u_px, p.center_v_px);
      const Eigen::Vector2d table = c + (px - c) * (1.0 - height_mm / p.camera_height_mm);
      return Eigen::Vector2d((table.x() - c.x()) / p.c_x_px_per_mm,
                             (table.y() - c.y()) / p.c_y_px_per_mm);
    }
  }
  return px;
}

Result<PixelMapper::PlaneLine> PixelMapper::plane_line(const Eigen::Vector2d& px) const {
  PlaneLine line;
  switch (kind_) {
    case Kind::kNone:
    case Kind::kPinholeIdeal: {
      auto q = to_plane(px, 0.0);
      if (!q) {
        return q.error();
      }
      line.a = *q;
      return line;
    }
    case Kind::kPinhole: {
      auto n = undistort_normalised(px);
      if (!n) {
        return n.error();
      }
      const Eigen::Vector3d ray = plane_T_camera_.linear() * Eigen::Vector3d(n->x(), n->y(), 1.0);
      const Eigen::Vector3d& o = plane_T_camera_.translation();
      if (!(ray.z() < -1e-12)) {
        return Error{Errc::kOutOfRange, "pixel's ray does not go down to the plane"};
      }
      // o + ((h - o.z) / ray.z) ray = (o - o.z / ray.z ray) + h (ray / ray.z)
      line.b = ray.head<2>() / ray.z();
      line.a = o.head<2>() - o.z() * line.b;
      return line;
    }
    case Kind::kPlanar: {
      const auto& p = calibration_->planar;
      const Eigen::Vector2d c(p.center_u_px, p.center_v_px);
      const Eigen::Vector2d d((px.x() - c.x()) / p.c_x_px_per_mm,
                              (px.y() - c.y()) / p.c_y_px_per_mm);
      line.a = d;
      line.b = -d / p.camera_height_mm;
      return line;
    }
  }
  return line;
}

Result<Eigen::Vector2d> PixelMapper::to_pixel(const Eigen::Vector2d& xy, double height_mm) const {
  switch (kind_) {
    case Kind::kNone:
      return xy;
    case Kind::kPinholeIdeal: {
      const Eigen::Vector2d n((xy.x() - camera_.cx_px()) / camera_.fx_px(),
                              (xy.y() - camera_.cy_px()) / camera_.fy_px());
      if (!(n.norm() < camera_.max_ideal_radius())) {
        return Error{Errc::kOutOfRange, "outside the lens's field"};
      }
      return camera_.project_normalised(n);
    }
    case Kind::kPinhole:
      return camera_.project(camera_T_plane_ * Eigen::Vector3d(xy.x(), xy.y(), height_mm));
    case Kind::kPlanar: {
      const auto& p = calibration_->planar;
      const Eigen::Vector2d c(p.center_u_px, p.center_v_px);
      const Eigen::Vector2d table =
          c + Eigen::Vector2d(xy.x() * p.c_x_px_per_mm, xy.y() * p.c_y_px_per_mm);
      const double k = 1.0 - height_mm / p.camera_height_mm;
      if (!(k > 0.0)) {
        return Error{Errc::kOutOfRange, "surface above the camera"};
      }
      return Eigen::Vector2d(c + (table - c) / k);
    }
  }
  return xy;
}

double PixelMapper::scale_at(const Eigen::Vector2d& px, double height_mm) const {
  const auto a = to_plane(px, height_mm);
  const auto b = to_plane(px + Eigen::Vector2d(1.0, 0.0), height_mm);
  const auto c = to_plane(px + Eigen::Vector2d(0.0, 1.0), height_mm);
  if (!a || !b || !c) {
    return 1.0;
  }
  return 0.5 * ((*b - *a).norm() + (*c - *a).norm());
}

Result<BasePose2> PixelMapper::to_base(const Eigen::Vector2d& xy, double rz_rad) const {
  if (!world_) {
    return Error{Errc::kNotReady, "no robot pose: " + description_};
  }
  if (kind_ == Kind::kPinhole) {
    return BasePose2{xy.x(), xy.y(), rz_rad};
  }
  // Planar: the plane frame is the table-level image in mm; the thesis's formulas do the rest.
  const auto& p = calibration_->planar;
  const Eigen::Vector2d c(p.center_u_px, p.center_v_px);
  auto pixel_of = [&](const Eigen::Vector2d& q) {
    return Eigen::Vector2d(c + Eigen::Vector2d(q.x() * p.c_x_px_per_mm, q.y() * p.c_y_px_per_mm));
  };
  constexpr double kArm = 5.0;  // mm along the direction, for its image in the base frame
  auto a = planar_pixel_to_base(p, j1_rad_, j2_rad_, pixel_of(xy));
  auto b = planar_pixel_to_base(
      p, j1_rad_, j2_rad_,
      pixel_of(xy + kArm * Eigen::Vector2d(std::cos(rz_rad), std::sin(rz_rad))));
  if (!a) {
    return a.error();
  }
  if (!b) {
    return b.error();
  }
  const Eigen::Vector2d d = *b - *a;
  return BasePose2{a->x(), a->y(), std::atan2(d.y(), d.x())};
}

}  // namespace cell::vision
