#include "cell/rapt/lsq.hpp"

#include <ceres/ceres.h>
#include <fmt/format.h>

#include <cmath>
#include <limits>
#include <memory>

namespace cell::rapt {

std::string LsqReport::brief() const {
  return fmt::format(
      "rms {:.4g} (was {:.4g}) over {} end points, {} free parameters; {:.4g} mm / "
      "{:.4g} deg from the symbolic solution",
      final_rms, initial_rms, residual_count, free_parameters, shift_mm, shift_rad * 180.0 / M_PI);
}

namespace {

using Eigen::Matrix3d;
using Eigen::Vector2d;
using Eigen::Vector3d;

/// The pose family left by the INVIOLATEs: R = Rot(axis, x0) * R0, t = t0 + x1 e1 + x2 e2.
struct Family {
  Vector3d axis = Vector3d::UnitZ();
  Vector3d e1 = Vector3d::UnitX();
  Vector3d e2 = Vector3d::UnitY();
  Matrix3d r0 = Matrix3d::Identity();
  Vector3d t0 = Vector3d::Zero();
  int free = 3;
  std::vector<int> constant;  ///< parameter indices held fixed

  Pose at(const double* x) const {
    Pose p = Pose::Identity();
    p.linear() = Eigen::AngleAxisd(x[0], axis).toRotationMatrix() * r0;
    p.translation() = t0 + x[1] * e1 + x[2] * e2;
    return p;
  }
};

/// Signed distances of a LOOK's two measured end points from the image of the model edge line.
struct EdgeLineResidual {
  Family family;
  std::array<Vector3d, 2> q;  ///< edge end points, body frame
  Matrix3d r_cw;              ///< camera_T_world rotation
  Vector3d centre;            ///< lens centre, world
  double focus = 1.0;
  std::array<Vector2d, 2> m;  ///< measured end points

  template <typename T>
  bool operator()(const T* x, T* residual) const {
    using V3 = Eigen::Matrix<T, 3, 1>;
    using M3 = Eigen::Matrix<T, 3, 3>;
    const V3 a = family.axis.cast<T>();
    M3 k;
    k << T(0), -a.z(), a.y(), a.z(), T(0), -a.x(), -a.y(), a.x(), T(0);
    const M3 rot =
        (M3::Identity() + sin(x[0]) * k + (T(1) - cos(x[0])) * k * k) * family.r0.cast<T>();
    const V3 t = family.t0.cast<T>() + x[1] * family.e1.cast<T>() + x[2] * family.e2.cast<T>();
    T img[2][2];
    for (int j = 0; j < 2; ++j) {
      const V3 p = rot * q[static_cast<std::size_t>(j)].cast<T>() + t;
      const V3 c = r_cw.cast<T>() * (p - centre.cast<T>());
      img[j][0] = T(focus) * c.y() / c.x();
      img[j][1] = T(focus) * c.z() / c.x();
    }
    const T dy = img[1][0] - img[0][0];
    const T dz = img[1][1] - img[0][1];
    const T len = sqrt(dy * dy + dz * dz);
    for (int j = 0; j < 2; ++j) {
      const auto& mj = m[static_cast<std::size_t>(j)];
      residual[j] = (dy * (T(mj.y()) - img[0][1]) - dz * (T(mj.x()) - img[0][0])) / len;
    }
    return true;
  }
};

}  // namespace

Result<LsqReport> least_squares(const Program& program,
                                const CompiledPackage& package,
                                const RouteInputs& inputs,
                                const Pose& initial) {
  const Package& pk = program.packages[static_cast<std::size_t>(package.index)];
  // The freedom the INVIOLATEs leave, from their actual reference normals.
  std::vector<Vector3d> normals;
  for (std::size_t i = 0; i < pk.inviolates.size() && i < inputs.world_T_reference.size(); ++i) {
    const Feature& ref = program.feature(pk.inviolates[i].reference);
    const Vector3d n = (inputs.world_T_reference[i] * ref.body_T_feature).linear().col(0);
    Vector3d u = n;
    for (const Vector3d& b : normals) {
      u -= u.dot(b) * b;
    }
    if (u.norm() > 1e-6) {
      normals.push_back(u.normalized());
    }
  }
  Family fam;
  fam.r0 = initial.linear();
  fam.t0 = initial.translation();
  if (normals.size() == 1) {
    fam.axis = normals[0];
    fam.e1 = any_perpendicular(fam.axis);
    fam.e2 = fam.axis.cross(fam.e1);
    fam.free = 3;
  } else if (normals.size() == 2) {
    fam.e1 = normals[0].cross(normals[1]).normalized();
    fam.free = 1;
    fam.constant = {0, 2};
  } else {
    fam.free = 0;
    fam.constant = {0, 1, 2};
  }
  LsqReport report;
  report.free_parameters = fam.free;
  report.residuals.assign(pk.looks.size(), {std::numeric_limits<double>::quiet_NaN(),
                                            std::numeric_limits<double>::quiet_NaN()});
  double x[3] = {0.0, 0.0, 0.0};
  ceres::Problem problem;
  std::vector<std::pair<std::size_t, ceres::ResidualBlockId>> blocks;
  for (std::size_t k = 0; k < pk.looks.size(); ++k) {
    if (k >= inputs.readings.size() || !inputs.readings[k] || k >= inputs.cameras.size()) {
      continue;
    }
    const Feature& edge = program.feature(pk.looks[k].edge);
    const auto [q1, q2] = edge.edge_end_points();
    const CameraModel& cam = inputs.cameras[k];
    for (const Vector3d& q : {q1, q2}) {
      const Vector3d c = cam.world_T_camera.inverse() * (initial * q);
      if (!(c.x() > 1e-9)) {
        return Error{
            Errc::kInvalidArgument,
            fmt::format("LOOK/{} at {}: the edge is behind the camera at the symbolic "
                        "solution",
                        program.feature_name(pk.looks[k].edge), to_string(pk.looks[k].loc))};
      }
    }
    auto* functor = new EdgeLineResidual{fam,
                                         {q1, q2},
                                         cam.world_T_camera.linear().transpose(),
                                         cam.world_T_camera.translation(),
                                         cam.focus,
                                         {inputs.readings[k]->first, inputs.readings[k]->second}};
    blocks.emplace_back(
        k, problem.AddResidualBlock(
               new ceres::AutoDiffCostFunction<EdgeLineResidual, 2, 3>(functor), nullptr, x));
  }
  if (blocks.empty()) {
    return Error{Errc::kInvalidArgument,
                 fmt::format("COMBINE at {}: no LOOK has a reading", to_string(pk.loc))};
  }
  report.residual_count = static_cast<int>(2 * blocks.size());
  auto rms = [&](double* max_abs) {
    double sum = 0.0;
    double worst = 0.0;
    for (const auto& [k, id] : blocks) {
      double r[2];
      double cost = 0.0;
      problem.EvaluateResidualBlock(id, false, &cost, r, nullptr);
      report.residuals[k] = {r[0], r[1]};
      sum += r[0] * r[0] + r[1] * r[1];
      worst = std::max({worst, std::abs(r[0]), std::abs(r[1])});
    }
    if (max_abs != nullptr) {
      *max_abs = worst;
    }
    return std::sqrt(sum / static_cast<double>(2 * blocks.size()));
  };
  report.initial_rms = rms(nullptr);
  if (!fam.constant.empty() && fam.free > 0) {
    problem.SetManifold(x, new ceres::SubsetManifold(3, fam.constant));
  }
  if (fam.free > 0) {
    ceres::Solver::Options options;
    options.linear_solver_type = ceres::DENSE_QR;
    options.max_num_iterations = 100;
    options.function_tolerance = 1e-14;
    options.gradient_tolerance = 1e-14;
    options.parameter_tolerance = 1e-14;
    options.logging_type = ceres::SILENT;
    ceres::Solver::Summary summary;
    ceres::Solve(options, &problem, &summary);
    report.iterations = static_cast<int>(summary.iterations.size());
    report.converged = summary.termination_type == ceres::CONVERGENCE;
    report.message = summary.message;
  } else {
    report.converged = true;
    report.message = "three independent INVIOLATEs fix the body; residuals only";
  }
  report.final_rms = rms(&report.max_abs);
  report.verified = fam.at(x);
  report.shift_mm = (report.verified.translation() - initial.translation()).norm();
  report.shift_rad = rotation_angle(initial.linear(), report.verified.linear());
  return report;
}

}  // namespace cell::rapt
