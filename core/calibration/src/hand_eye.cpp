#include "cell/calibration/hand_eye.hpp"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <limits>
#include <numbers>
#include <set>

#include <Eigen/SVD>
#include <ceres/ceres.h>
#include <fmt/format.h>
#include <opencv2/calib3d.hpp>
#include <opencv2/core/eigen.hpp>

#include "cell/calibration/intrinsics.hpp"
#include "cell/geometry/angles.hpp"
#include "costs.hpp"
#include "solver_util.hpp"

namespace cell::calibration {
namespace {

using detail::kIntrinsicsSize;
using detail::kPoseSize;
using Pose6 = std::array<double, kPoseSize>;

using geometry::kDeg;
constexpr double kSamePoseMm = 0.1;
constexpr double kSamePoseDeg = 0.01;
constexpr double kAxisMinAngleDeg = 1.0;  // relative rotations below this carry no axis
constexpr double kPlanarTiltDeg = 0.5;    // a SCARA's mount z is the base z to this

using detail::report_progress;

Eigen::Matrix3d average_rotation(const std::vector<Eigen::Matrix3d>& rotations) {
  Eigen::Matrix3d sum = Eigen::Matrix3d::Zero();
  for (const auto& r : rotations) {
    sum += r;
  }
  Eigen::JacobiSVD<Eigen::Matrix3d> svd(sum, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Matrix3d u = svd.matrixU();
  Eigen::Matrix3d out = u * svd.matrixV().transpose();
  if (out.determinant() < 0) {
    u.col(2) *= -1.0;
    out = u * svd.matrixV().transpose();
  }
  return out;
}

Eigen::Isometry3d average_pose(const std::vector<Eigen::Isometry3d>& poses) {
  std::vector<Eigen::Matrix3d> r;
  Eigen::Vector3d t = Eigen::Vector3d::Zero();
  for (const auto& p : poses) {
    r.push_back(p.linear());
    t += p.translation();
  }
  Eigen::Isometry3d out = Eigen::Isometry3d::Identity();
  out.linear() = average_rotation(r);
  out.translation() = t / static_cast<double>(poses.size());
  return out;
}

double yaw_of(const Eigen::Matrix3d& r) { return std::atan2(r(1, 0), r(0, 0)); }

double wrap(double a) { return std::remainder(a, 2.0 * std::numbers::pi); }

/// Camera-frame coordinates of target point p for sample pose a (the chain of the header).
Eigen::Vector3d predict_camera(HandEyeSetup setup, const Eigen::Isometry3d& x,
                               const Eigen::Isometry3d& target, const Eigen::Isometry3d& a,
                               const Eigen::Vector3d& p) {
  if (setup == HandEyeSetup::kEyeInHand) {
    return (a * x).inverse() * (target * p);
  }
  return x.inverse() * (a * (target * p));
}

/// Sum of squared pixel errors of one sample under the chain; infinity if a point cannot be
/// projected.
double sample_sum_sq(HandEyeSetup setup, const render::CameraModel& camera,
                     const Eigen::Isometry3d& x, const Eigen::Isometry3d& target,
                     const Eigen::Isometry3d& a, const BoardObservation& obs) {
  double sum = 0.0;
  for (std::size_t k = 0; k < obs.size(); ++k) {
    auto px = camera.project(predict_camera(setup, x, target, a, obs.object_points[k]));
    if (!px) {
      return std::numeric_limits<double>::infinity();
    }
    sum += (*px - obs.image_points[k]).squaredNorm();
  }
  return sum;
}

std::vector<cv::Mat> rotations_cv(const std::vector<Eigen::Isometry3d>& poses) {
  std::vector<cv::Mat> out;
  for (const auto& p : poses) {
    cv::Mat m;
    const Eigen::Matrix3d r = p.linear();
    cv::eigen2cv(r, m);
    out.push_back(m);
  }
  return out;
}

std::vector<cv::Mat> translations_cv(const std::vector<Eigen::Isometry3d>& poses) {
  std::vector<cv::Mat> out;
  for (const auto& p : poses) {
    cv::Mat m;
    const Eigen::Vector3d t = p.translation();
    cv::eigen2cv(t, m);
    out.push_back(m);
  }
  return out;
}

Eigen::Isometry3d pose_from_cv(const cv::Mat& r, const cv::Mat& t) {
  Eigen::Matrix3d rotation;
  Eigen::Vector3d translation;
  cv::cv2eigen(r, rotation);
  cv::cv2eigen(t, translation);
  Eigen::Isometry3d out = Eigen::Isometry3d::Identity();
  out.linear() = rotation;
  out.translation() = translation;
  return out;
}

/// OpenCV's closed forms. a: base_T_mount, c: camera_T_target, per sample.
Result<Eigen::Isometry3d> closed_form(const std::vector<Eigen::Isometry3d>& a,
                                      const std::vector<Eigen::Isometry3d>& c, HandEyeSetup setup,
                                      HandEyeMethod method) {
  if (a.size() < 3) {
    return Error{Errc::kInvalidArgument,
                 fmt::format("a hand-eye closed form needs 3 samples or more, got {}", a.size())};
  }
  try {
    cv::Mat r_out;
    cv::Mat t_out;
    Eigen::Isometry3d x;
    if (method == HandEyeMethod::kShah || method == HandEyeMethod::kLi) {
      // Robot-world: cTw = cTg * gTb * bTw. Eye-in-hand: w = target, g = mount.
      // Eye-to-hand: the roles swap: the target is the "camera", the camera the "world".
      std::vector<Eigen::Isometry3d> world2cam;
      std::vector<Eigen::Isometry3d> base2gripper;
      for (std::size_t i = 0; i < a.size(); ++i) {
        world2cam.push_back(setup == HandEyeSetup::kEyeInHand ? c[i] : c[i].inverse());
        base2gripper.push_back(a[i].inverse());
      }
      cv::Mat r_b2w;
      cv::Mat t_b2w;
      cv::calibrateRobotWorldHandEye(
          rotations_cv(world2cam), translations_cv(world2cam), rotations_cv(base2gripper),
          translations_cv(base2gripper), r_b2w, t_b2w, r_out, t_out,
          method == HandEyeMethod::kShah ? cv::CALIB_ROBOT_WORLD_HAND_EYE_SHAH
                                         : cv::CALIB_ROBOT_WORLD_HAND_EYE_LI);
      const Eigen::Isometry3d gripper2cam = pose_from_cv(r_out, t_out);
      const Eigen::Isometry3d base2world = pose_from_cv(r_b2w, t_b2w);
      x = setup == HandEyeSetup::kEyeInHand ? gripper2cam.inverse() : base2world.inverse();
    } else {
      std::vector<Eigen::Isometry3d> gripper2base;
      gripper2base.reserve(a.size());
      for (const auto& p : a) {
        gripper2base.push_back(setup == HandEyeSetup::kEyeInHand ? p : p.inverse());
      }
      cv::HandEyeCalibrationMethod m = cv::CALIB_HAND_EYE_TSAI;
      switch (method) {
        case HandEyeMethod::kPark:
          m = cv::CALIB_HAND_EYE_PARK;
          break;
        case HandEyeMethod::kHoraud:
          m = cv::CALIB_HAND_EYE_HORAUD;
          break;
        case HandEyeMethod::kAndreff:
          m = cv::CALIB_HAND_EYE_ANDREFF;
          break;
        case HandEyeMethod::kDaniilidis:
          m = cv::CALIB_HAND_EYE_DANIILIDIS;
          break;
        default:
          break;
      }
      cv::calibrateHandEye(rotations_cv(gripper2base), translations_cv(gripper2base),
                           rotations_cv(c), translations_cv(c), r_out, t_out, m);
      x = pose_from_cv(r_out, t_out);
    }
    if (!x.matrix().allFinite() ||
        !(x.linear().transpose() * x.linear()).isIdentity(1e-6)) {
      return Error{Errc::kOutOfRange,
                   fmt::format("OpenCV's {} returned no valid transform", to_string(method))};
    }
    return x;
  } catch (const cv::Exception& e) {
    return Error{Errc::kOutOfRange, fmt::format("OpenCV's {}: {}", to_string(method), e.what())};
  }
}

/// The planar closed form (header comment; derivation in README.md).
Result<std::pair<Eigen::Isometry3d, Eigen::Isometry3d>> planar_closed_form(
    const std::vector<Eigen::Isometry3d>& a, const std::vector<Eigen::Isometry3d>& c,
    HandEyeSetup setup, double target_z, bool level) {
  const std::size_t n = a.size();
  // The base z in the camera frame: a level target's normal, or else the axis of every
  // relative camera rotation, signed by the robot's relative yaw.
  Eigen::Vector3d g = Eigen::Vector3d::Zero();
  for (std::size_t i = 0; level && i < n; ++i) {
    g += c[i].linear().col(2);
  }
  for (std::size_t i = 0; !level && i < n; ++i) {
    for (std::size_t j = i + 1; j < n; ++j) {
      const double dyaw = setup == HandEyeSetup::kEyeInHand
                              ? wrap(yaw_of(a[j].linear()) - yaw_of(a[i].linear()))
                              : wrap(yaw_of(a[i].linear()) - yaw_of(a[j].linear()));
      const Eigen::AngleAxisd rel(c[i].linear() * c[j].linear().transpose());
      if (std::abs(dyaw) < 5.0 * kDeg || rel.angle() < 5.0 * kDeg) {
        continue;
      }
      g += (dyaw > 0 ? 1.0 : -1.0) * rel.axis() * std::sin(rel.angle());
    }
  }
  if (g.norm() < 1e-9) {
    return Error{Errc::kOutOfRange,
                 "planar hand-eye: no two poses turn the camera by 5 degrees or more about the "
                 "vertical"};
  }
  g.normalize();
  const Eigen::Matrix3d r_t =
      Eigen::Quaterniond::FromTwoVectors(g, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  Eigen::MatrixXd m = Eigen::MatrixXd::Zero(static_cast<Eigen::Index>(2 * n), 6);
  Eigen::VectorXd rhs(static_cast<Eigen::Index>(2 * n));
  for (std::size_t i = 0; i < n; ++i) {
    const Eigen::Vector3d q = r_t * c[i].translation();
    Eigen::Matrix2d mq;
    mq << q.x(), -q.y(), q.y(), q.x();
    const Eigen::Matrix2d rz = a[i].linear().topLeftCorner<2, 2>();
    const Eigen::Index row = static_cast<Eigen::Index>(2 * i);
    if (setup == HandEyeSetup::kEyeInHand) {
      // [p_xy | (c, s) | t_X,xy]: p - Rz M(q) (c, s) - Rz t = a
      m.block<2, 2>(row, 0) = Eigen::Matrix2d::Identity();
      m.block<2, 2>(row, 2) = -rz * mq;
      m.block<2, 2>(row, 4) = -rz;
    } else {
      // [(c, s) | t_X,xy | t_T,xy]: M(q) (c, s) + t_X - Rz t_T = a
      m.block<2, 2>(row, 0) = mq;
      m.block<2, 2>(row, 2) = Eigen::Matrix2d::Identity();
      m.block<2, 2>(row, 4) = -rz;
    }
    rhs.segment<2>(row) = a[i].translation().head<2>();
  }
  Eigen::JacobiSVD<Eigen::MatrixXd> svd(m, Eigen::ComputeThinU | Eigen::ComputeThinV);
  const auto& sv = svd.singularValues();
  if (sv(sv.size() - 1) < 1e-9 * sv(0)) {
    return Error{Errc::kOutOfRange,
                 "planar hand-eye: the poses do not determine the horizontal offsets (too little "
                 "rotation or translation between them)"};
  }
  const Eigen::VectorXd x = svd.solve(rhs);
  const Eigen::Vector2d cs = setup == HandEyeSetup::kEyeInHand ? Eigen::Vector2d(x(2), x(3))
                                                               : Eigen::Vector2d(x(0), x(1));
  const double psi = std::atan2(cs.y(), cs.x());
  Eigen::Isometry3d cam = Eigen::Isometry3d::Identity();
  cam.linear() = Eigen::AngleAxisd(psi, Eigen::Vector3d::UnitZ()).toRotationMatrix() * r_t;
  Eigen::Isometry3d target = Eigen::Isometry3d::Identity();
  std::vector<Eigen::Matrix3d> target_r;
  double z_sum = 0.0;
  for (std::size_t i = 0; i < n; ++i) {
    const Eigen::Vector3d rc = cam.linear() * c[i].translation();
    if (setup == HandEyeSetup::kEyeInHand) {
      target_r.push_back(a[i].linear() * cam.linear() * c[i].linear());
      z_sum += target_z - a[i].translation().z() - rc.z();
    } else {
      target_r.push_back(a[i].linear().transpose() * cam.linear() * c[i].linear());
      z_sum += a[i].translation().z() + target_z - rc.z();
    }
  }
  const double z = z_sum / static_cast<double>(n);
  target.linear() = average_rotation(target_r);
  if (level) {
    target.linear() = Eigen::AngleAxisd(yaw_of(target.linear()), Eigen::Vector3d::UnitZ())
                          .toRotationMatrix();
  }
  if (setup == HandEyeSetup::kEyeInHand) {
    cam.translation() = Eigen::Vector3d(x(4), x(5), z);
    target.translation() = Eigen::Vector3d(x(0), x(1), target_z);
  } else {
    cam.translation() = Eigen::Vector3d(x(2), x(3), z);
    target.translation() = Eigen::Vector3d(x(4), x(5), target_z);
  }
  return std::make_pair(cam, target);
}

struct Problem {
  std::array<double, kIntrinsicsSize> intrinsics{};
  Pose6 x{};
  Pose6 target{};
  std::vector<Pose6> mount;  // measured robot poses (constants)
  std::vector<Pose6> delta;  // their corrections
};

SolverSummary refine(Problem& p, const std::vector<const HandEyeSample*>& samples,
                     const HandEyeOptions& o, const render::CameraModel& camera, bool robust) {
  ceres::Problem problem;
  for (std::size_t s = 0; s < samples.size(); ++s) {
    const BoardObservation& obs = samples[s]->observation;
    for (std::size_t k = 0; k < obs.size(); ++k) {
      ceres::CostFunction* cost =
          o.setup == HandEyeSetup::kEyeInHand
              ? detail::EyeInHandReprojection::create(obs.image_points[k], obs.object_points[k],
                                                      p.mount[s].data())
              : detail::EyeToHandReprojection::create(obs.image_points[k], obs.object_points[k],
                                                      p.mount[s].data());
      problem.AddResidualBlock(cost, robust ? new ceres::HuberLoss(o.huber_px) : nullptr,
                               p.intrinsics.data(), p.x.data(), p.target.data(),
                               p.delta[s].data());
    }
    if (o.robot_rotation_sigma_deg > 0.0 && o.robot_translation_sigma_mm > 0.0) {
      // Robust too: a pose that does not belong to its image (a swapped sample) must not pull
      // the fit while it is found out.
      problem.AddResidualBlock(
          detail::PoseCorrectionPrior::create(o.robot_rotation_sigma_deg * kDeg,
                                              o.robot_translation_sigma_mm, o.pixel_sigma_px),
          robust ? new ceres::HuberLoss(3.0 * o.pixel_sigma_px) : nullptr, p.delta[s].data());
    } else {
      problem.SetParameterBlockConstant(p.delta[s].data());
    }
  }
  if (o.refine_intrinsics) {
    std::vector<int> fixed;
    const auto d = camera.distortion();
    if (d.k3 == 0.0) {
      fixed.push_back(8);
    }
    if (d.p1 == 0.0 && d.p2 == 0.0) {
      fixed.push_back(6);
      fixed.push_back(7);
    }
    if (!fixed.empty()) {
      problem.SetManifold(p.intrinsics.data(), new ceres::SubsetManifold(kIntrinsicsSize, fixed));
    }
  } else {
    problem.SetParameterBlockConstant(p.intrinsics.data());
  }
  if (o.planar) {
    // The known height; for a level target also its roll and pitch (angle-axis (0, 0, yaw)).
    problem.SetManifold(p.target.data(),
                        new ceres::SubsetManifold(kPoseSize, o.planar_target_level
                                                                 ? std::vector<int>{0, 1, 5}
                                                                 : std::vector<int>{5}));
  }
  ceres::Solver::Options so = detail::solver_options(o.max_iterations);
  so.linear_solver_type = ceres::DENSE_QR;
  ceres::Solver::Summary summary;
  ceres::Solve(so, &problem, &summary);
  return detail::condense(summary);
}

Eigen::Isometry3d corrected(const Pose6& mount, const Pose6& delta) {
  return detail::vector_to_pose(mount.data()) * detail::vector_to_pose(delta.data());
}

}  // namespace

std::string_view to_string(HandEyeSetup setup) noexcept {
  return setup == HandEyeSetup::kEyeInHand ? "eye_in_hand" : "eye_to_hand";
}

std::string_view to_string(HandEyeMethod method) noexcept {
  switch (method) {
    case HandEyeMethod::kTsai:
      return "tsai";
    case HandEyeMethod::kPark:
      return "park";
    case HandEyeMethod::kHoraud:
      return "horaud";
    case HandEyeMethod::kAndreff:
      return "andreff";
    case HandEyeMethod::kDaniilidis:
      return "daniilidis";
    case HandEyeMethod::kShah:
      return "shah";
    case HandEyeMethod::kLi:
      return "li";
  }
  return "unknown";
}

Status HandEyeOptions::validate() const {
  auto bad = [](const std::string& what) {
    return Error{Errc::kInvalidArgument, "hand-eye options: " + what};
  };
  if (planar && !std::isfinite(planar_target_z_mm)) {
    return bad("planar_target_z_mm must be finite");
  }
  if (!(pixel_sigma_px > 0.0) || !std::isfinite(pixel_sigma_px)) {
    return bad(fmt::format("pixel_sigma_px must be > 0, got {}", pixel_sigma_px));
  }
  if (!(robot_rotation_sigma_deg >= 0.0) || !(robot_translation_sigma_mm >= 0.0) ||
      !std::isfinite(robot_rotation_sigma_deg + robot_translation_sigma_mm)) {
    return bad(fmt::format("robot sigmas must be >= 0, got {} deg and {} mm",
                           robot_rotation_sigma_deg, robot_translation_sigma_mm));
  }
  if (!(huber_px > 0.0)) {
    return bad(fmt::format("huber_px must be > 0, got {}", huber_px));
  }
  if (!(min_rotation_deg > 0.0) || !(min_axis_spread_deg > 0.0)) {
    return bad("min_rotation_deg and min_axis_spread_deg must be > 0");
  }
  if (!(max_pair_gap_s > 0.0)) {
    return bad(fmt::format("max_pair_gap_s must be > 0, got {}", max_pair_gap_s));
  }
  if (!(outlier_factor > 1.0) || !(outlier_min_px >= 0.0)) {
    return bad("outlier_factor must be > 1 and outlier_min_px >= 0");
  }
  if (!(holdout_fraction >= 0.0 && holdout_fraction < 0.5) || min_holdout_samples < 0) {
    return bad(fmt::format("holdout_fraction must be in [0, 0.5), got {}", holdout_fraction));
  }
  if (min_fit_samples < 3) {
    return bad(fmt::format("min_fit_samples must be >= 3, got {}", min_fit_samples));
  }
  if (max_iterations < 1) {
    return bad("max_iterations must be >= 1");
  }
  return ok_status();
}

MotionSpread motion_spread(const std::vector<Eigen::Isometry3d>& base_T_mount) {
  MotionSpread s;
  std::vector<Eigen::Vector3d> axes;       // in the mount frame (eye-in-hand's AX = XB)
  std::vector<Eigen::Vector3d> base_axes;  // in the base frame (eye-to-hand's)
  std::vector<bool> duplicate(base_T_mount.size(), false);
  for (std::size_t i = 0; i < base_T_mount.size(); ++i) {
    s.max_tilt_deg = std::max(
        s.max_tilt_deg, std::acos(std::clamp(base_T_mount[i].linear()(2, 2), -1.0, 1.0)) / kDeg);
    for (std::size_t j = i + 1; j < base_T_mount.size(); ++j) {
      const Eigen::Isometry3d rel = base_T_mount[i].inverse() * base_T_mount[j];
      const Eigen::AngleAxisd aa(rel.linear());
      const double rot = aa.angle() / kDeg;
      const double dist = (base_T_mount[i].translation() - base_T_mount[j].translation()).norm();
      s.max_rotation_deg = std::max(s.max_rotation_deg, rot);
      s.max_translation_mm = std::max(s.max_translation_mm, dist);
      if (rot < kSamePoseDeg && rel.translation().norm() < kSamePoseMm) {
        duplicate[j] = true;
      }
      if (rot >= kAxisMinAngleDeg) {
        axes.push_back(aa.axis());
        base_axes.push_back(base_T_mount[i].linear() * aa.axis());
      }
    }
  }
  s.distinct_poses = static_cast<int>(std::count(duplicate.begin(), duplicate.end(), false));
  auto spread = [](const std::vector<Eigen::Vector3d>& v) {
    double out = 0.0;
    for (std::size_t i = 0; i < v.size(); ++i) {
      for (std::size_t j = i + 1; j < v.size(); ++j) {
        const double c = std::abs(v[i].dot(v[j]));
        out = std::max(out, std::acos(std::clamp(c, 0.0, 1.0)) / kDeg);
      }
    }
    return out;
  };
  s.axis_spread_deg = spread(axes);
  s.base_axis_spread_deg = spread(base_axes);
  return s;
}

Status check_motion(const MotionSpread& s, const HandEyeOptions& o) {
  if (s.distinct_poses < 2) {
    return Error{Errc::kOutOfRange,
                 fmt::format("the robot never moved: every pose is within {} mm and {} deg of the "
                             "first",
                             kSamePoseMm, kSamePoseDeg)};
  }
  if (o.planar && s.max_tilt_deg > kPlanarTiltDeg) {
    return Error{Errc::kOutOfRange,
                 fmt::format("the planar reduction needs rotations about the base z only, but a "
                             "mount z axis tilts {:.2f} deg from the base z",
                             s.max_tilt_deg)};
  }
  if (s.max_rotation_deg < o.min_rotation_deg) {
    return Error{Errc::kOutOfRange,
                 fmt::format("too little rotation: the poses differ by at most {:.2f} deg, at "
                             "least {} deg is needed ({} distinct poses)",
                             s.max_rotation_deg, o.min_rotation_deg, s.distinct_poses)};
  }
  const double axis_spread =
      o.setup == HandEyeSetup::kEyeInHand ? s.axis_spread_deg : s.base_axis_spread_deg;
  if (!o.planar && axis_spread < o.min_axis_spread_deg) {
    return Error{Errc::kOutOfRange,
                 fmt::format("near-parallel rotation axes: every relative rotation turns about the "
                             "same axis within {:.2f} deg, at least {} deg between axes is needed "
                             "(a SCARA turns about its base z only: use the planar reduction)",
                             axis_spread, o.min_axis_spread_deg)};
  }
  return ok_status();
}

std::string HandEyeReport::brief() const {
  const Eigen::Vector3d t = camera_extrinsics.translation();
  const Eigen::Vector3d rpy = camera_extrinsics.linear().eulerAngles(2, 1, 0);
  return fmt::format(
      "{} {}{}: xyz ({:.3f}, {:.3f}, {:.3f}) mm, ypr ({:.3f}, {:.3f}, {:.3f}) deg; RMS {:.3f} px "
      "over {} samples, hold-out {:.3f} px and {:.3f} mm over {}, {} rejected; robot corrections "
      "{:.4f} deg {:.4f} mm RMS; motion {:.1f} deg, axes {:.1f} deg apart; init {}; {} "
      "iterations",
      to_string(setup), setup == HandEyeSetup::kEyeInHand ? "mount_T_camera" : "base_T_camera",
      planar ? " (planar)" : "", t.x(), t.y(), t.z(), rpy[0] / kDeg, rpy[1] / kDeg,
      rpy[2] / kDeg, rms_px, samples_used, holdout_rms_px, holdout_mm, samples_held_out,
      samples_rejected, robot_rotation_rms_deg, robot_translation_rms_mm, motion.max_rotation_deg,
      motion.axis_spread_deg, init, solver.iterations);
}

Result<Eigen::Isometry3d> opencv_hand_eye(const std::vector<HandEyeSample>& samples,
                                          const render::CameraModel& camera, HandEyeSetup setup,
                                          HandEyeMethod method) {
  std::vector<Eigen::Isometry3d> a;
  std::vector<Eigen::Isometry3d> c;
  for (const HandEyeSample& s : samples) {
    if (!s.detection_error.empty()) {
      continue;
    }
    auto pose = solve_board_pose(camera, s.observation);
    if (pose) {
      a.push_back(s.base_T_mount);
      c.push_back(*pose);
    }
  }
  return closed_form(a, c, setup, method);
}

Result<HandEyeReport> calibrate_hand_eye(const std::vector<HandEyeSample>& samples,
                                         const render::CameraModel& camera,
                                         const HandEyeOptions& options,
                                         const ProgressFn& progress) {
  CELL_TRY(options.validate());
  const auto start = std::chrono::steady_clock::now();
  const HandEyeSetup setup = options.setup;
  HandEyeReport report;
  report.setup = setup;
  report.planar = options.planar;
  report.camera = camera;
  report.samples.resize(samples.size());
  std::vector<Eigen::Isometry3d> camera_T_target(samples.size(), Eigen::Isometry3d::Identity());
  std::vector<std::size_t> usable;
  std::set<std::string> ids;
  for (std::size_t i = 0; i < samples.size(); ++i) {
    const HandEyeSample& s = samples[i];
    ViewReport& r = report.samples[i];
    r.id = s.id;
    r.stamp_ns = s.stamp_ns;
    report_progress(progress, "pose", i + 1, samples.size(), s.id);
    const double gap_s =
        s.robot_stamp_ns == 0 ? 0.0 : std::abs(static_cast<double>(s.stamp_ns - s.robot_stamp_ns)) * 1e-9;
    const Eigen::Matrix3d rot = s.base_T_mount.linear();
    if (!ids.insert(s.id).second) {
      r.reason = fmt::format("sample id '{}' used twice", s.id);
    } else if (!s.detection_error.empty()) {
      r.reason = "target not found: " + s.detection_error;
    } else if (gap_s > options.max_pair_gap_s) {
      r.reason = fmt::format("its robot pose is {:.3f} s away from the exposure (at most {} s)",
                             gap_s, options.max_pair_gap_s);
    } else if (!s.base_T_mount.matrix().allFinite() ||
               !(rot.transpose() * rot).isIdentity(1e-6)) {
      r.reason = "its robot pose is not a finite rigid transform";
    } else if (s.observation.size() < 4 ||
               s.observation.image_points.size() != s.observation.object_points.size()) {
      r.reason = fmt::format("{} target corners, 4 or more needed", s.observation.size());
    } else {
      auto pose = solve_board_pose(camera, s.observation);
      if (!pose) {
        r.reason = "no target pose: " + pose.error().message;
      } else {
        camera_T_target[i] = *pose;
        usable.push_back(i);
      }
    }
  }
  auto split = detail::split_holdout(usable, samples.size(), options.min_fit_samples,
                                     options.min_holdout_samples, options.holdout_fraction,
                                     "samples");
  if (!split) {
    return std::move(split).error();
  }
  const std::vector<std::size_t>& fit_idx = split->fit;
  const std::vector<std::size_t>& hold_idx = split->held;
  const auto min_fit = static_cast<std::size_t>(options.min_fit_samples);
  std::vector<Eigen::Isometry3d> a_fit;
  std::vector<Eigen::Isometry3d> c_fit;
  for (const std::size_t i : fit_idx) {
    a_fit.push_back(samples[i].base_T_mount);
    c_fit.push_back(camera_T_target[i]);
  }
  report.motion = motion_spread(a_fit);
  CELL_TRY(check_motion(report.motion, options));

  // Closed forms: OpenCV's, every method, for the record; the chosen one (or the planar one)
  // starts the refinement.
  report_progress(progress, "init", 0, 0, "closed forms");
  for (const HandEyeMethod m : {HandEyeMethod::kTsai, HandEyeMethod::kPark, HandEyeMethod::kHoraud,
                                HandEyeMethod::kAndreff, HandEyeMethod::kDaniilidis,
                                HandEyeMethod::kShah, HandEyeMethod::kLi}) {
    MethodEstimate e;
    e.method = m;
    auto x = closed_form(a_fit, c_fit, setup, m);
    e.ok = x.has_value();
    if (x) {
      e.camera_extrinsics = *x;
    } else {
      e.error = x.error().message;
    }
    report.closed_forms.push_back(e);
  }
  Eigen::Isometry3d x0;
  Eigen::Isometry3d target0;
  if (options.planar) {
    auto planar = planar_closed_form(a_fit, c_fit, setup, options.planar_target_z_mm,
                                     options.planar_target_level);
    if (!planar) {
      return std::move(planar).error();
    }
    x0 = planar->first;
    target0 = planar->second;
    report.init = "planar";
  } else {
    const MethodEstimate& chosen = report.closed_forms[static_cast<std::size_t>(options.init)];
    if (!chosen.ok) {
      return Error{Errc::kOutOfRange, chosen.error};
    }
    x0 = chosen.camera_extrinsics;
    std::vector<Eigen::Isometry3d> targets;
    for (std::size_t k = 0; k < a_fit.size(); ++k) {
      targets.push_back(setup == HandEyeSetup::kEyeInHand ? a_fit[k] * x0 * c_fit[k]
                                                          : a_fit[k].inverse() * x0 * c_fit[k]);
    }
    target0 = average_pose(targets);
    report.init = std::string(to_string(options.init));
  }

  // Joint refinement.
  Problem p;
  p.intrinsics = {camera.fx_px(), camera.fy_px(), camera.cx_px(), camera.cy_px(),
                  camera.distortion().k1, camera.distortion().k2, camera.distortion().p1,
                  camera.distortion().p2, camera.distortion().k3};
  detail::pose_to_vector(x0, p.x.data());
  detail::pose_to_vector(target0, p.target.data());
  std::vector<const HandEyeSample*> fitted;
  std::vector<std::size_t> fitted_idx;
  for (const std::size_t i : fit_idx) {
    fitted.push_back(&samples[i]);
    fitted_idx.push_back(i);
    Pose6 m{};
    detail::pose_to_vector(samples[i].base_T_mount, m.data());
    p.mount.push_back(m);
    p.delta.push_back(Pose6{});
  }
  report_progress(progress, "solve", 1, 2, "robust joint refinement");
  SolverSummary summary = refine(p, fitted, options, camera, true);
  auto current_camera = [&]() {
    return render::CameraModel::create(camera.width_px(), camera.height_px(), p.intrinsics[0],
                                       p.intrinsics[1], p.intrinsics[2], p.intrinsics[3],
                                       {p.intrinsics[4], p.intrinsics[5], p.intrinsics[6],
                                        p.intrinsics[7], p.intrinsics[8]});
  };
  // Outlier samples (a pose that does not belong to its image) out, then least squares.
  {
    auto cam = current_camera();
    if (!cam) {
      return Error{Errc::kOutOfRange, "refined intrinsics are not valid: " + cam.error().message};
    }
    const Eigen::Isometry3d x = detail::vector_to_pose(p.x.data());
    const Eigen::Isometry3d target = detail::vector_to_pose(p.target.data());
    std::vector<double> rms(fitted.size());
    std::vector<double> chi2(fitted.size(), 0.0);
    const bool modelled = options.robot_rotation_sigma_deg > 0.0 &&
                          options.robot_translation_sigma_mm > 0.0;
    for (std::size_t s = 0; s < fitted.size(); ++s) {
      rms[s] = std::sqrt(sample_sum_sq(setup, *cam, x, target, corrected(p.mount[s], p.delta[s]),
                                       fitted[s]->observation) /
                         static_cast<double>(fitted[s]->observation.size()));
      if (modelled) {
        const Pose6& d = p.delta[s];
        const double sr = options.robot_rotation_sigma_deg * kDeg;
        const double st = options.robot_translation_sigma_mm;
        chi2[s] = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]) / (sr * sr) +
                  (d[3] * d[3] + d[4] * d[4] + d[5] * d[5]) / (st * st);
      }
    }
    // The correction a sample needs, in units of the robot's accuracy: chi-square with 6
    // degrees of freedom, beyond 40 (far past its 99.99 % point, 27.9) the pose is not this
    // image's.
    constexpr double kChi2Limit = 40.0;
    std::vector<double> sorted = rms;
    std::nth_element(sorted.begin(),
                     sorted.begin() + static_cast<std::ptrdiff_t>(sorted.size() / 2), sorted.end());
    const double limit = std::max(options.outlier_factor * sorted[sorted.size() / 2],
                                  options.outlier_min_px);
    std::vector<const HandEyeSample*> kept;
    std::vector<std::size_t> kept_idx;
    std::vector<Pose6> kept_mount;
    std::vector<Pose6> kept_delta;
    for (std::size_t s = 0; s < fitted.size(); ++s) {
      if (rms[s] > limit) {
        report.samples[fitted_idx[s]].reason =
            fmt::format("outlier: RMS {:.3f} px exceeds {:.3f} px ({} x the median sample RMS)",
                        rms[s], limit, options.outlier_factor);
        report.samples[fitted_idx[s]].rms_px = rms[s];
      } else if (chi2[s] > kChi2Limit) {
        const Pose6& d = p.delta[s];
        report.samples[fitted_idx[s]].reason = fmt::format(
            "outlier: its robot pose disagrees with its image by {:.3f} deg and {:.3f} mm (the "
            "robot is good to {} deg and {} mm per axis)",
            Eigen::Vector3d(d[0], d[1], d[2]).norm() / kDeg,
            Eigen::Vector3d(d[3], d[4], d[5]).norm(), options.robot_rotation_sigma_deg,
            options.robot_translation_sigma_mm);
        report.samples[fitted_idx[s]].rms_px = rms[s];
      } else {
        kept.push_back(fitted[s]);
        kept_idx.push_back(fitted_idx[s]);
        kept_mount.push_back(p.mount[s]);
        kept_delta.push_back(p.delta[s]);
      }
    }
    if (kept.size() < min_fit) {
      return Error{Errc::kInvalidArgument,
                   fmt::format("too few samples: after rejecting {} outlier samples only {} remain "
                               "to fit, {} needed",
                               fitted.size() - kept.size(), kept.size(), min_fit)};
    }
    fitted = std::move(kept);
    fitted_idx = std::move(kept_idx);
    p.mount = std::move(kept_mount);
    p.delta = std::move(kept_delta);
  }
  report_progress(progress, "solve", 2, 2, "least squares");
  const SolverSummary last = refine(p, fitted, options, camera, false);
  summary.iterations += last.iterations;
  summary.converged = last.converged;
  summary.termination = last.termination;
  summary.final_cost = last.final_cost;
  auto cam = current_camera();
  if (!cam) {
    return Error{Errc::kOutOfRange, "refined intrinsics are not valid: " + cam.error().message};
  }
  report.camera = *cam;
  report.camera_extrinsics = detail::vector_to_pose(p.x.data());
  report.target_pose = detail::vector_to_pose(p.target.data());

  double sum = 0.0;
  std::size_t n = 0;
  double rot_sq = 0.0;
  double trans_sq = 0.0;
  for (std::size_t s = 0; s < fitted.size(); ++s) {
    const double ss = sample_sum_sq(setup, report.camera, report.camera_extrinsics,
                                    report.target_pose, corrected(p.mount[s], p.delta[s]),
                                    fitted[s]->observation);
    ViewReport& r = report.samples[fitted_idx[s]];
    r.used = true;
    r.rms_px = std::sqrt(ss / static_cast<double>(fitted[s]->observation.size()));
    sum += ss;
    n += fitted[s]->observation.size();
    rot_sq += Eigen::Vector3d(p.delta[s][0], p.delta[s][1], p.delta[s][2]).squaredNorm();
    trans_sq += Eigen::Vector3d(p.delta[s][3], p.delta[s][4], p.delta[s][5]).squaredNorm();
  }
  report.samples_used = static_cast<int>(fitted.size());
  report.rms_px = n > 0 ? std::sqrt(sum / static_cast<double>(n)) : 0.0;
  report.robot_rotation_rms_deg = std::sqrt(rot_sq / static_cast<double>(fitted.size())) / kDeg;
  report.robot_translation_rms_mm = std::sqrt(trans_sq / static_cast<double>(fitted.size()));

  // Hold-out: the robot pose as measured, the calibration as fitted.
  double hold_sum = 0.0;
  std::size_t hold_n = 0;
  double mm_sq = 0.0;
  std::size_t step = 0;
  const bool modelled =
      options.robot_rotation_sigma_deg > 0.0 && options.robot_translation_sigma_mm > 0.0;
  for (const std::size_t i : hold_idx) {
    report_progress(progress, "holdout", ++step, hold_idx.size(), samples[i].id);
    const BoardObservation& obs = samples[i].observation;
    ViewReport& r = report.samples[i];
    if (modelled) {
      // The correction this pose would need with the calibration as fitted: a pose that does
      // not belong to its image is left out of the hold-out figure, and named.
      Problem one = p;
      one.mount.assign(1, Pose6{});
      one.delta.assign(1, Pose6{});
      detail::pose_to_vector(samples[i].base_T_mount, one.mount[0].data());
      ceres::Problem problem;
      for (std::size_t k = 0; k < obs.size(); ++k) {
        ceres::CostFunction* cost =
            setup == HandEyeSetup::kEyeInHand
                ? detail::EyeInHandReprojection::create(obs.image_points[k], obs.object_points[k],
                                                        one.mount[0].data())
                : detail::EyeToHandReprojection::create(obs.image_points[k], obs.object_points[k],
                                                        one.mount[0].data());
        problem.AddResidualBlock(cost, nullptr, one.intrinsics.data(), one.x.data(),
                                 one.target.data(), one.delta[0].data());
      }
      problem.AddResidualBlock(
          detail::PoseCorrectionPrior::create(options.robot_rotation_sigma_deg * kDeg,
                                              options.robot_translation_sigma_mm,
                                              options.pixel_sigma_px),
          nullptr, one.delta[0].data());
      problem.SetParameterBlockConstant(one.intrinsics.data());
      problem.SetParameterBlockConstant(one.x.data());
      problem.SetParameterBlockConstant(one.target.data());
      ceres::Solver::Options so = detail::solver_options(50);
      so.linear_solver_type = ceres::DENSE_QR;
      ceres::Solver::Summary summary_one;
      ceres::Solve(so, &problem, &summary_one);
      const Pose6& d = one.delta[0];
      const double sr = options.robot_rotation_sigma_deg * kDeg;
      const double st = options.robot_translation_sigma_mm;
      const double chi2 = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]) / (sr * sr) +
                          (d[3] * d[3] + d[4] * d[4] + d[5] * d[5]) / (st * st);
      if (chi2 > 40.0) {
        r.reason = fmt::format(
            "held out, but its robot pose disagrees with its image by {:.3f} deg and {:.3f} mm "
            "(the robot is good to {} deg and {} mm per axis)",
            Eigen::Vector3d(d[0], d[1], d[2]).norm() / kDeg,
            Eigen::Vector3d(d[3], d[4], d[5]).norm(), options.robot_rotation_sigma_deg,
            options.robot_translation_sigma_mm);
        continue;
      }
    }
    r.held_out = true;
    const double ss = sample_sum_sq(setup, report.camera, report.camera_extrinsics,
                                    report.target_pose, samples[i].base_T_mount, obs);
    r.rms_px = std::sqrt(ss / static_cast<double>(obs.size()));
    hold_sum += ss;
    hold_n += obs.size();
    Eigen::Vector3d centre = Eigen::Vector3d::Zero();
    for (const auto& q : obs.object_points) {
      centre += q;
    }
    centre /= static_cast<double>(obs.size());
    auto measured_pose = solve_board_pose(report.camera, obs);
    const Eigen::Vector3d measured = (measured_pose ? *measured_pose : camera_T_target[i]) * centre;
    const Eigen::Vector3d predicted = predict_camera(setup, report.camera_extrinsics,
                                                     report.target_pose,
                                                     samples[i].base_T_mount, centre);
    mm_sq += (measured - predicted).squaredNorm();
    ++report.samples_held_out;
  }
  report.holdout_rms_px = hold_n > 0 ? std::sqrt(hold_sum / static_cast<double>(hold_n)) : 0.0;
  report.holdout_mm = report.samples_held_out > 0
                          ? std::sqrt(mm_sq / report.samples_held_out)
                          : 0.0;
  for (const ViewReport& r : report.samples) {
    if (!r.used && !r.held_out) {
      ++report.samples_rejected;
    }
  }
  summary.time_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  report.solver = summary;
  return report;
}

}  // namespace cell::calibration
