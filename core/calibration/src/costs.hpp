#pragma once

// Ceres cost functors of the calibration solvers: the one place for templates (STYLE.md §3).
// Parameter blocks:
//   intrinsics[9] = fx, fy, cx, cy [px], k1, k2, p1, p2, k3 (render::CameraModel's lens)
//   pose[6]       = angle-axis rotation [rad] (3), translation [mm] (3) of a_T_b
//   planar[7]     = c_x, c_y [px/mm], d_t_c [mm], b_angl, angl_err [rad], link1, link2 [mm]
// Tests: tests/costs_test.cpp checks every Jacobian with ceres::GradientChecker.

#include <cmath>
#include <numbers>

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <ceres/autodiff_cost_function.h>
#include <ceres/rotation.h>

namespace cell::calibration::detail {

inline constexpr int kIntrinsicsSize = 9;
inline constexpr int kPoseSize = 6;
inline constexpr int kPlanarSize = 7;

/// out = a_T_b * p (pose as angle-axis + translation).
template <typename T>
void transform(const T* pose, const T* p, T* out) {
  ceres::AngleAxisRotatePoint(pose, p, out);
  out[0] += pose[3];
  out[1] += pose[4];
  out[2] += pose[5];
}

/// out = a_T_b^-1 * p.
template <typename T>
void inverse_transform(const T* pose, const T* p, T* out) {
  const T shifted[3] = {p[0] - pose[3], p[1] - pose[4], p[2] - pose[5]};
  const T back[3] = {-pose[0], -pose[1], -pose[2]};
  ceres::AngleAxisRotatePoint(back, shifted, out);
}

/// The pixel of a point in the camera frame (render/camera_model.hpp's formula). fy is
/// aspect * fx when aspect > 0 (fixed aspect ratio), else intrinsics[1].
template <typename T>
void project(const T* k, double aspect, const T* pc, T* uv) {
  const T x = pc[0] / pc[2];
  const T y = pc[1] / pc[2];
  const T r2 = x * x + y * y;
  const T radial = T(1.0) + r2 * (k[4] + r2 * (k[5] + r2 * k[8]));
  const T xd = x * radial + T(2.0) * k[6] * x * y + k[7] * (r2 + T(2.0) * x * x);
  const T yd = y * radial + k[6] * (r2 + T(2.0) * y * y) + T(2.0) * k[7] * x * y;
  const T fy = aspect > 0.0 ? T(aspect) * k[0] : k[1];
  uv[0] = k[0] * xd + k[2];
  uv[1] = fy * yd + k[3];
}

/// Residual [px] of one board corner: project(intrinsics, camera_T_board * P) - observed.
struct BoardReprojection {
  BoardReprojection(const Eigen::Vector2d& observed, const Eigen::Vector3d& point, double aspect)
      : u_(observed.x()), v_(observed.y()), x_(point.x()), y_(point.y()), z_(point.z()),
        aspect_(aspect) {}

  template <typename T>
  bool operator()(const T* intrinsics, const T* camera_T_board, T* residual) const {
    const T p[3] = {T(x_), T(y_), T(z_)};
    T pc[3];
    transform(camera_T_board, p, pc);
    T uv[2];
    project(intrinsics, aspect_, pc, uv);
    residual[0] = uv[0] - T(u_);
    residual[1] = uv[1] - T(v_);
    return true;
  }

  static ceres::CostFunction* create(const Eigen::Vector2d& observed, const Eigen::Vector3d& point,
                                     double aspect) {
    return new ceres::AutoDiffCostFunction<BoardReprojection, 2, kIntrinsicsSize, kPoseSize>(
        new BoardReprojection(observed, point, aspect));
  }

  double u_, v_, x_, y_, z_, aspect_;
};

/// A robot pose with a small correction: base_T_mount * exp(delta) (delta = angle-axis,
/// translation in the mount frame), applied as out = (base_T_mount * exp(delta))^-1 * p_base.
template <typename T>
void into_corrected_mount(const double* base_T_mount, const T* delta, const T* p_base, T* out) {
  const T pose[6] = {T(base_T_mount[0]), T(base_T_mount[1]), T(base_T_mount[2]),
                     T(base_T_mount[3]), T(base_T_mount[4]), T(base_T_mount[5])};
  T p_mount[3];
  inverse_transform(pose, p_base, p_mount);
  inverse_transform(delta, p_mount, out);
}

/// Eye-in-hand: a target fixed in the robot's base seen by a camera on the robot's mount frame.
/// Parameters: intrinsics, mount_T_camera, base_T_target, delta (the pose correction).
struct EyeInHandReprojection {
  EyeInHandReprojection(const Eigen::Vector2d& observed, const Eigen::Vector3d& point,
                        const double* base_T_mount_pose)
      : u_(observed.x()), v_(observed.y()), x_(point.x()), y_(point.y()), z_(point.z()) {
    for (int i = 0; i < 6; ++i) {
      mount_[i] = base_T_mount_pose[i];
    }
  }

  template <typename T>
  bool operator()(const T* intrinsics, const T* mount_T_camera, const T* base_T_target,
                  const T* delta, T* residual) const {
    const T p[3] = {T(x_), T(y_), T(z_)};
    T p_base[3];
    transform(base_T_target, p, p_base);
    T p_mount[3];
    into_corrected_mount(mount_, delta, p_base, p_mount);
    T pc[3];
    inverse_transform(mount_T_camera, p_mount, pc);
    T uv[2];
    project(intrinsics, 0.0, pc, uv);
    residual[0] = uv[0] - T(u_);
    residual[1] = uv[1] - T(v_);
    return true;
  }

  static ceres::CostFunction* create(const Eigen::Vector2d& observed, const Eigen::Vector3d& point,
                                     const double* base_T_mount_pose) {
    return new ceres::AutoDiffCostFunction<EyeInHandReprojection, 2, kIntrinsicsSize, kPoseSize,
                                           kPoseSize, kPoseSize>(
        new EyeInHandReprojection(observed, point, base_T_mount_pose));
  }

  double u_, v_, x_, y_, z_;
  double mount_[6];
};

/// Eye-to-hand: a target on the robot's mount frame seen by a camera fixed in the base.
/// Parameters: intrinsics, base_T_camera, mount_T_target, delta.
struct EyeToHandReprojection {
  EyeToHandReprojection(const Eigen::Vector2d& observed, const Eigen::Vector3d& point,
                        const double* base_T_mount_pose)
      : u_(observed.x()), v_(observed.y()), x_(point.x()), y_(point.y()), z_(point.z()) {
    for (int i = 0; i < 6; ++i) {
      mount_[i] = base_T_mount_pose[i];
    }
  }

  template <typename T>
  bool operator()(const T* intrinsics, const T* base_T_camera, const T* mount_T_target,
                  const T* delta, T* residual) const {
    const T p[3] = {T(x_), T(y_), T(z_)};
    T p_mount[3];
    transform(mount_T_target, p, p_mount);
    T p_corrected[3];
    transform(delta, p_mount, p_corrected);
    const T pose[6] = {T(mount_[0]), T(mount_[1]), T(mount_[2]), T(mount_[3]), T(mount_[4]),
                       T(mount_[5])};
    T p_base[3];
    transform(pose, p_corrected, p_base);
    T pc[3];
    inverse_transform(base_T_camera, p_base, pc);
    T uv[2];
    project(intrinsics, 0.0, pc, uv);
    residual[0] = uv[0] - T(u_);
    residual[1] = uv[1] - T(v_);
    return true;
  }

  static ceres::CostFunction* create(const Eigen::Vector2d& observed, const Eigen::Vector3d& point,
                                     const double* base_T_mount_pose) {
    return new ceres::AutoDiffCostFunction<EyeToHandReprojection, 2, kIntrinsicsSize, kPoseSize,
                                           kPoseSize, kPoseSize>(
        new EyeToHandReprojection(observed, point, base_T_mount_pose));
  }

  double u_, v_, x_, y_, z_;
  double mount_[6];
};

/// Prior on a robot pose correction: delta's rotation over sigma_rad, translation over
/// sigma_mm (dimensionless residuals, so they weigh against pixel residuals over sigma_px).
struct PoseCorrectionPrior {
  PoseCorrectionPrior(double sigma_rad, double sigma_mm, double sigma_px)
      : rot_weight_(sigma_px / sigma_rad), trans_weight_(sigma_px / sigma_mm) {}

  template <typename T>
  bool operator()(const T* delta, T* residual) const {
    for (int i = 0; i < 3; ++i) {
      residual[i] = T(rot_weight_) * delta[i];
      residual[i + 3] = T(trans_weight_) * delta[i + 3];
    }
    return true;
  }

  static ceres::CostFunction* create(double sigma_rad, double sigma_mm, double sigma_px) {
    return new ceres::AutoDiffCostFunction<PoseCorrectionPrior, 6, kPoseSize>(
        new PoseCorrectionPrior(sigma_rad, sigma_mm, sigma_px));
  }

  double rot_weight_, trans_weight_;
};

/// The planar 7545 model in vector form (planar_model.hpp), as a template for Ceres: the pixel
/// at which the model sees the base-frame table point (px, py) with the elbow at (j1, j2).
/// Ref_Point (ref_u, ref_v) is fixed (the operator chooses it). Returns false when the pixel
/// scales are not positive.
template <typename T>
bool planar_project(const T* planar, double ref_u, double ref_v, double j1, double j2,
                    const T& px, const T& py, T* uv) {
  using std::cos;
  using std::sin;
  const T& c_x = planar[0];
  const T& c_y = planar[1];
  const T& d_t_c = planar[2];
  const T& b_angl = planar[3];
  const T& angl_err = planar[4];
  const T& link1 = planar[5];
  const T& link2 = planar[6];
  if (!(c_x > T(0.0)) || !(c_y > T(0.0))) {
    return false;
  }
  const double lambda = j1 + j2;  // link 2's heading
  const T ex = link1 * cos(j1) + link2 * cos(lambda);
  const T ey = link1 * sin(j1) + link2 * sin(lambda);
  // Ref_Point's table point: d_t_c from the tool along tip->elbow turned by b_angl.
  const T psi = T(lambda + std::numbers::pi) + b_angl;
  const T rx = ex + d_t_c * cos(psi);
  const T ry = ey + d_t_c * sin(psi);
  // Image axes on the table: i along link 2 reversed, turned by -angl_err; j a quarter turn
  // clockwise from i (looking down, the image is mirrored).
  const T omega = T(lambda + std::numbers::pi) - angl_err;
  const T dx = px - rx;
  const T dy = py - ry;
  const T along_i = cos(omega) * dx + sin(omega) * dy;
  const T along_j = sin(omega) * dx - cos(omega) * dy;
  uv[0] = T(ref_u) + c_x * along_i;
  uv[1] = T(ref_v) + c_y * along_j;
  return true;
}

/// Residual [px] of one board corner seen through the planar model: the board lies flat on
/// the table at (x, y, yaw) in the base frame. Parameters: planar[7], board[3].
struct PlanarReprojection {
  PlanarReprojection(const Eigen::Vector2d& observed, const Eigen::Vector2d& board_point,
                     double j1_rad, double j2_rad, double ref_u_px, double ref_v_px)
      : u_(observed.x()), v_(observed.y()), bx_(board_point.x()), by_(board_point.y()),
        j1_(j1_rad), j2_(j2_rad), ref_u_(ref_u_px), ref_v_(ref_v_px) {}

  template <typename T>
  bool operator()(const T* planar, const T* board, T* residual) const {
    using std::cos;
    using std::sin;
    const T px = board[0] + cos(board[2]) * T(bx_) - sin(board[2]) * T(by_);
    const T py = board[1] + sin(board[2]) * T(bx_) + cos(board[2]) * T(by_);
    T uv[2];
    if (!planar_project(planar, ref_u_, ref_v_, j1_, j2_, px, py, uv)) {
      return false;
    }
    residual[0] = uv[0] - T(u_);
    residual[1] = uv[1] - T(v_);
    return true;
  }

  static ceres::CostFunction* create(const Eigen::Vector2d& observed,
                                     const Eigen::Vector2d& board_point, double j1_rad,
                                     double j2_rad, double ref_u_px, double ref_v_px) {
    return new ceres::AutoDiffCostFunction<PlanarReprojection, 2, kPlanarSize, 3>(
        new PlanarReprojection(observed, board_point, j1_rad, j2_rad, ref_u_px, ref_v_px));
  }

  double u_, v_, bx_, by_, j1_, j2_, ref_u_, ref_v_;
};

/// Residual [px] of one observation of a known table point (a touched or placed marker):
/// Parameters: planar[7].
struct PlanarPointReprojection {
  PlanarPointReprojection(const Eigen::Vector2d& observed, const Eigen::Vector2d& point_base,
                          double j1_rad, double j2_rad, double ref_u_px, double ref_v_px)
      : u_(observed.x()), v_(observed.y()), px_(point_base.x()), py_(point_base.y()),
        j1_(j1_rad), j2_(j2_rad), ref_u_(ref_u_px), ref_v_(ref_v_px) {}

  template <typename T>
  bool operator()(const T* planar, T* residual) const {
    T uv[2];
    if (!planar_project(planar, ref_u_, ref_v_, j1_, j2_, T(px_), T(py_), uv)) {
      return false;
    }
    residual[0] = uv[0] - T(u_);
    residual[1] = uv[1] - T(v_);
    return true;
  }

  static ceres::CostFunction* create(const Eigen::Vector2d& observed,
                                     const Eigen::Vector2d& point_base, double j1_rad,
                                     double j2_rad, double ref_u_px, double ref_v_px) {
    return new ceres::AutoDiffCostFunction<PlanarPointReprojection, 2, kPlanarSize>(
        new PlanarPointReprojection(observed, point_base, j1_rad, j2_rad, ref_u_px, ref_v_px));
  }

  double u_, v_, px_, py_, j1_, j2_, ref_u_, ref_v_;
};

/// Pose <-> 6-vector (angle-axis, translation).
inline void pose_to_vector(const Eigen::Isometry3d& pose, double* out) {
  const Eigen::AngleAxisd aa(pose.linear());
  const Eigen::Vector3d r = aa.axis() * aa.angle();
  out[0] = r.x();
  out[1] = r.y();
  out[2] = r.z();
  out[3] = pose.translation().x();
  out[4] = pose.translation().y();
  out[5] = pose.translation().z();
}

inline Eigen::Isometry3d vector_to_pose(const double* v) {
  const Eigen::Vector3d r(v[0], v[1], v[2]);
  const double angle = r.norm();
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  if (angle > 0.0) {
    pose.linear() = Eigen::AngleAxisd(angle, r / angle).toRotationMatrix();
  }
  pose.translation() = Eigen::Vector3d(v[3], v[4], v[5]);
  return pose;
}

}  // namespace cell::calibration::detail
