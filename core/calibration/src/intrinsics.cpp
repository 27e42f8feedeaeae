#include "cell/calibration/intrinsics.hpp"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <limits>
#include <set>

#include <ceres/ceres.h>
#include <fmt/format.h>
#include <opencv2/calib3d.hpp>
#include <opencv2/core/eigen.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "costs.hpp"
#include "solver_util.hpp"

namespace cell::calibration {
namespace {

using detail::kIntrinsicsSize;
using detail::kPoseSize;
using Pose6 = std::array<double, kPoseSize>;

using detail::report_progress;

std::vector<int> constant_intrinsics(const IntrinsicsOptions& o) {
  std::vector<int> fixed;
  if (o.fix_aspect_ratio) {
    fixed.push_back(1);  // fy follows fx in the functor
  }
  if (o.fix_principal_point) {
    fixed.push_back(2);
    fixed.push_back(3);
  }
  switch (o.lens) {
    case LensModel::kNone:
      fixed.insert(fixed.end(), {4, 5, 6, 7, 8});
      break;
    case LensModel::kRadial2:
      fixed.insert(fixed.end(), {6, 7, 8});
      break;
    case LensModel::kRadialTangential:
      fixed.push_back(8);
      break;
    case LensModel::kFull:
      break;
  }
  return fixed;
}

struct Fit {
  std::array<double, kIntrinsicsSize> intrinsics{};
  std::vector<Pose6> poses;  // per fitted view
  double aspect = 0.0;       // > 0 when fixed
};

SolverSummary solve(const std::vector<const BoardView*>& views, Fit& fit,
                    const IntrinsicsOptions& options, bool robust) {
  ceres::Problem problem;
  for (std::size_t v = 0; v < views.size(); ++v) {
    const BoardObservation& obs = views[v]->observation;
    for (std::size_t k = 0; k < obs.size(); ++k) {
      problem.AddResidualBlock(
          detail::BoardReprojection::create(obs.image_points[k], obs.object_points[k], fit.aspect),
          robust ? new ceres::HuberLoss(options.huber_px) : nullptr, fit.intrinsics.data(),
          fit.poses[v].data());
    }
  }
  const std::vector<int> fixed = constant_intrinsics(options);
  if (!fixed.empty()) {
    problem.SetManifold(fit.intrinsics.data(), new ceres::SubsetManifold(kIntrinsicsSize, fixed));
  }
  ceres::Solver::Options so = detail::solver_options(options.max_iterations);
  so.linear_solver_type = ceres::DENSE_SCHUR;
  ceres::Solver::Summary summary;
  ceres::Solve(so, &problem, &summary);
  return detail::condense(summary);
}

render::Distortion lens_of(const std::array<double, kIntrinsicsSize>& k) {
  return render::Distortion{k[4], k[5], k[6], k[7], k[8]};
}

double point_rms(double sum_sq, std::size_t n) {
  return n == 0 ? 0.0 : std::sqrt(sum_sq / static_cast<double>(n));
}

/// Sum of squared Euclidean errors [px^2] of a view under intrinsics k and pose p.
double view_sum_sq(const std::array<double, kIntrinsicsSize>& k, double aspect, const Pose6& p,
                   const BoardObservation& obs) {
  double sum = 0.0;
  for (std::size_t i = 0; i < obs.size(); ++i) {
    const double pt[3] = {obs.object_points[i].x(), obs.object_points[i].y(),
                          obs.object_points[i].z()};
    double pc[3];
    detail::transform(p.data(), pt, pc);
    if (!(pc[2] > 0.0)) {
      return std::numeric_limits<double>::infinity();
    }
    double uv[2];
    detail::project(k.data(), aspect, pc, uv);
    sum += std::pow(uv[0] - obs.image_points[i].x(), 2) + std::pow(uv[1] - obs.image_points[i].y(), 2);
  }
  return sum;
}

std::vector<cv::Point3f> cv_object(const BoardObservation& obs) {
  std::vector<cv::Point3f> out;
  for (const auto& p : obs.object_points) {
    out.emplace_back(static_cast<float>(p.x()), static_cast<float>(p.y()),
                     static_cast<float>(p.z()));
  }
  return out;
}

std::vector<cv::Point2f> cv_image(const BoardObservation& obs) {
  std::vector<cv::Point2f> out;
  for (const auto& p : obs.image_points) {
    out.emplace_back(static_cast<float>(p.x()), static_cast<float>(p.y()));
  }
  return out;
}

}  // namespace

Status IntrinsicsOptions::validate() const {
  auto bad = [](const std::string& what) {
    return Error{Errc::kInvalidArgument, "intrinsics options: " + what};
  };
  if (fix_aspect_ratio && !(aspect_ratio >= 0.0 && std::isfinite(aspect_ratio))) {
    return bad(fmt::format("aspect_ratio must be >= 0 (0: from the closed form), got {}",
                           aspect_ratio));
  }
  if (principal_point_px && !principal_point_px->allFinite()) {
    return bad("principal_point_px must be finite");
  }
  if (!(huber_px > 0.0) || !std::isfinite(huber_px)) {
    return bad(fmt::format("huber_px must be > 0, got {}", huber_px));
  }
  if (!(outlier_factor > 1.0) || !std::isfinite(outlier_factor)) {
    return bad(fmt::format("outlier_factor must be > 1, got {}", outlier_factor));
  }
  if (!(outlier_min_px >= 0.0) || !std::isfinite(outlier_min_px)) {
    return bad(fmt::format("outlier_min_px must be >= 0, got {}", outlier_min_px));
  }
  if (!(holdout_fraction >= 0.0 && holdout_fraction < 0.5)) {
    return bad(fmt::format("holdout_fraction must be in [0, 0.5), got {}", holdout_fraction));
  }
  if (min_holdout_views < 0) {
    return bad(fmt::format("min_holdout_views must be >= 0, got {}", min_holdout_views));
  }
  if (min_fit_views < 3) {
    return bad(fmt::format("min_fit_views must be >= 3, got {}", min_fit_views));
  }
  if (min_corners_per_view < 4) {
    return bad(fmt::format("min_corners_per_view must be >= 4, got {}", min_corners_per_view));
  }
  if (max_iterations < 1) {
    return bad(fmt::format("max_iterations must be >= 1, got {}", max_iterations));
  }
  return ok_status();
}

std::string IntrinsicsReport::brief() const {
  const auto d = camera.distortion();
  return fmt::format(
      "fx {:.2f} fy {:.2f} cx {:.2f} cy {:.2f} px, k1 {:.5f} k2 {:.5f} p1 {:.6f} p2 {:.6f} k3 "
      "{:.5f} (1-sigma fx {:.2f} fy {:.2f} cx {:.2f} cy {:.2f} px); RMS {:.3f} px over {} views "
      "({} corners), hold-out {:.3f} px over {} views, {} rejected; {} iterations ({})",
      camera.fx_px(), camera.fy_px(), camera.cx_px(), camera.cy_px(), d.k1, d.k2, d.p1, d.p2,
      d.k3, sigma_px[0], sigma_px[1], sigma_px[2], sigma_px[3], rms_px, views_used, points_used,
      holdout_rms_px, views_held_out, views_rejected, solver.iterations,
      solver.converged ? "converged" : solver.termination);
}

Result<Eigen::Isometry3d> solve_board_pose(const render::CameraModel& camera,
                                           const BoardObservation& observation) {
  if (observation.size() < 4) {
    return Error{Errc::kInvalidArgument,
                 fmt::format("a board pose needs 4 corners or more, got {}", observation.size())};
  }
  try {
    cv::Mat k;
    cv::eigen2cv(camera.camera_matrix(), k);
    const auto d = camera.distortion().as_array();
    const cv::Mat dist(1, 5, CV_64F, const_cast<double*>(d.data()));
    cv::Mat rvec;
    cv::Mat tvec;
    if (!cv::solvePnP(cv_object(observation), cv_image(observation), k, dist, rvec, tvec, false,
                      cv::SOLVEPNP_ITERATIVE)) {
      return Error{Errc::kOutOfRange, "cv::solvePnP found no board pose"};
    }
    cv::Mat r;
    cv::Rodrigues(rvec, r);
    Eigen::Matrix3d rotation;
    cv::cv2eigen(r, rotation);
    Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
    pose.linear() = rotation;
    pose.translation() =
        Eigen::Vector3d(tvec.at<double>(0), tvec.at<double>(1), tvec.at<double>(2));
    if (!(pose.translation().z() > 0.0) || !pose.matrix().allFinite()) {
      return Error{Errc::kOutOfRange, "the board pose found lies behind the camera"};
    }
    return pose;
  } catch (const cv::Exception& e) {
    return Error{Errc::kOutOfRange, fmt::format("board pose: {}", e.what())};
  }
}

double reprojection_rms(const render::CameraModel& camera, const Eigen::Isometry3d& camera_T_board,
                        const BoardObservation& observation) {
  double sum = 0.0;
  for (std::size_t i = 0; i < observation.size(); ++i) {
    auto px = camera.project(camera_T_board * observation.object_points[i]);
    if (!px) {
      return std::numeric_limits<double>::infinity();
    }
    sum += (*px - observation.image_points[i]).squaredNorm();
  }
  return point_rms(sum, observation.size());
}

Result<IntrinsicsReport> calibrate_intrinsics(const std::vector<BoardView>& views, int width_px,
                                              int height_px, const IntrinsicsOptions& options,
                                              const ProgressFn& progress) {
  CELL_TRY(options.validate());
  if (width_px < 1 || height_px < 1 || width_px > 16384 || height_px > 16384) {
    return Error{Errc::kInvalidArgument,
                 fmt::format("image size {} x {} px is not in 1..16384", width_px, height_px)};
  }
  const auto start = std::chrono::steady_clock::now();
  IntrinsicsReport report;
  report.views.resize(views.size());
  report.camera_T_board.assign(views.size(), Eigen::Isometry3d::Identity());
  std::vector<std::size_t> usable;
  for (std::size_t i = 0; i < views.size(); ++i) {
    const BoardView& v = views[i];
    ViewReport& r = report.views[i];
    r.id = v.id;
    r.stamp_ns = v.stamp_ns;
    const BoardObservation& obs = v.observation;
    if (obs.width_px != width_px || obs.height_px != height_px) {
      r.reason = fmt::format("image size {} x {} px differs from the camera's {} x {} px",
                             obs.width_px, obs.height_px, width_px, height_px);
    } else if (static_cast<int>(obs.size()) < options.min_corners_per_view) {
      r.reason = fmt::format("{} corners, fewer than the {} a view needs", obs.size(),
                             options.min_corners_per_view);
    } else if (obs.image_points.size() != obs.size() || obs.object_points.size() != obs.size()) {
      r.reason = "corner ids, image points and board points differ in number";
    } else {
      bool finite = true;
      for (const auto& p : obs.image_points) {
        finite = finite && p.allFinite();
      }
      if (!finite) {
        r.reason = "a corner is not finite";
      } else {
        usable.push_back(i);
      }
    }
  }
  // Hold-out views: every result carries a figure on views the fit never saw.
  auto split = detail::split_holdout(usable, views.size(), options.min_fit_views,
                                     options.min_holdout_views, options.holdout_fraction, "views");
  if (!split) {
    return std::move(split).error();
  }
  const std::vector<std::size_t>& fit_idx = split->fit;
  const std::vector<std::size_t>& hold_idx = split->held;
  const auto min_fit = static_cast<std::size_t>(options.min_fit_views);

  // (1) Closed form.
  report_progress(progress, "init", 0, 0, "closed form (Zhang) and a pose per view");
  Fit fit;
  try {
    std::vector<std::vector<cv::Point3f>> object;
    std::vector<std::vector<cv::Point2f>> image;
    for (const std::size_t i : fit_idx) {
      object.push_back(cv_object(views[i].observation));
      image.push_back(cv_image(views[i].observation));
    }
    const double aspect_in = options.fix_aspect_ratio && options.aspect_ratio > 0.0
                                 ? 1.0 / options.aspect_ratio  // OpenCV: fx = fy * aspectRatio
                                 : 0.0;
    const cv::Mat k = cv::initCameraMatrix2D(object, image, cv::Size(width_px, height_px),
                                             aspect_in);
    fit.intrinsics = {k.at<double>(0, 0), k.at<double>(1, 1), k.at<double>(0, 2),
                      k.at<double>(1, 2), 0, 0, 0, 0, 0};
  } catch (const cv::Exception& e) {
    return Error{Errc::kOutOfRange, fmt::format("closed-form intrinsics failed: {}", e.what())};
  }
  if (options.fix_principal_point) {
    const Eigen::Vector2d c = options.principal_point_px.value_or(
        Eigen::Vector2d((width_px - 1) / 2.0, (height_px - 1) / 2.0));
    fit.intrinsics[2] = c.x();
    fit.intrinsics[3] = c.y();
  }
  if (options.fix_aspect_ratio) {
    fit.aspect = options.aspect_ratio > 0.0 ? options.aspect_ratio
                                            : fit.intrinsics[1] / fit.intrinsics[0];
    fit.intrinsics[1] = fit.aspect * fit.intrinsics[0];
  }
  if (!(fit.intrinsics[0] > 0.0) || !(fit.intrinsics[1] > 0.0) ||
      !std::isfinite(fit.intrinsics[0] + fit.intrinsics[1] + fit.intrinsics[2] +
                     fit.intrinsics[3])) {
    return Error{Errc::kOutOfRange,
                 "closed-form intrinsics are degenerate: the views do not tilt the board enough "
                 "(every view nearly parallel to the image plane)"};
  }
  auto pinhole = render::CameraModel::create(width_px, height_px, fit.intrinsics[0],
                                             fit.intrinsics[1], fit.intrinsics[2],
                                             fit.intrinsics[3], {});
  if (!pinhole) {
    return Error{Errc::kOutOfRange, "closed-form intrinsics: " + pinhole.error().message};
  }
  double init_sum = 0.0;
  std::size_t init_n = 0;
  for (const std::size_t i : fit_idx) {
    auto pose = solve_board_pose(*pinhole, views[i].observation);
    if (!pose) {
      return Error{Errc::kOutOfRange, fmt::format("view '{}': {}", views[i].id,
                                                  pose.error().message)};
    }
    Pose6 p{};
    detail::pose_to_vector(*pose, p.data());
    fit.poses.push_back(p);
    init_sum += view_sum_sq(fit.intrinsics, fit.aspect, p, views[i].observation);
    init_n += views[i].observation.size();
  }
  report.initial_rms_px = point_rms(init_sum, init_n);

  // (2) + (3) Robust bundle adjustment, outlier views out, again.
  std::vector<const BoardView*> fitted;
  fitted.reserve(fit_idx.size());
  for (const std::size_t i : fit_idx) {
    fitted.push_back(&views[i]);
  }
  std::vector<std::size_t> fitted_idx = fit_idx;
  report_progress(progress, "solve", 1, 3, "robust bundle adjustment over every view");
  SolverSummary summary = solve(fitted, fit, options, true);
  for (int round = 0; round < 3; ++round) {
    std::vector<double> rms(fitted.size());
    for (std::size_t v = 0; v < fitted.size(); ++v) {
      rms[v] = point_rms(view_sum_sq(fit.intrinsics, fit.aspect, fit.poses[v],
                                     fitted[v]->observation),
                         fitted[v]->observation.size());
    }
    std::vector<double> sorted = rms;
    std::nth_element(sorted.begin(), sorted.begin() + static_cast<std::ptrdiff_t>(sorted.size() / 2),
                     sorted.end());
    const double median = sorted[sorted.size() / 2];
    const double limit = std::max(options.outlier_factor * median, options.outlier_min_px);
    std::vector<const BoardView*> kept;
    std::vector<std::size_t> kept_idx;
    std::vector<Pose6> kept_poses;
    for (std::size_t v = 0; v < fitted.size(); ++v) {
      if (rms[v] > limit) {
        report.views[fitted_idx[v]].reason = fmt::format(
            "outlier: RMS {:.3f} px exceeds {:.3f} px ({} x the median view RMS {:.3f} px, at "
            "least {} px)",
            rms[v], limit, options.outlier_factor, median, options.outlier_min_px);
        report.views[fitted_idx[v]].rms_px = rms[v];
        report_progress(progress, "reject", v + 1, fitted.size(),
                        fmt::format("view '{}' rejected: {}", fitted[v]->id,
                                    report.views[fitted_idx[v]].reason));
      } else {
        kept.push_back(fitted[v]);
        kept_idx.push_back(fitted_idx[v]);
        kept_poses.push_back(fit.poses[v]);
      }
    }
    if (kept.size() == fitted.size()) {
      break;
    }
    if (kept.size() < min_fit) {
      return Error{Errc::kInvalidArgument,
                   fmt::format("too few views: after rejecting {} outlier views only {} remain to "
                               "fit, {} needed",
                               fitted_idx.size() - kept.size() + (views.size() - usable.size()),
                               kept.size(), min_fit)};
    }
    fitted = std::move(kept);
    fitted_idx = std::move(kept_idx);
    fit.poses = std::move(kept_poses);
    report_progress(progress, "solve", 2, 3, "robust bundle adjustment without the outliers");
    summary = solve(fitted, fit, options, true);
  }
  // Least squares proper on the inliers: the estimate the noise model calls for.
  report_progress(progress, "solve", 3, 3, "least squares over the inlier views");
  const SolverSummary last = solve(fitted, fit, options, false);
  summary.iterations += last.iterations;
  summary.converged = last.converged;
  summary.termination = last.termination;
  summary.final_cost = last.final_cost;

  auto camera = render::CameraModel::create(width_px, height_px, fit.intrinsics[0],
                                            fit.aspect > 0.0 ? fit.aspect * fit.intrinsics[0]
                                                             : fit.intrinsics[1],
                                            fit.intrinsics[2], fit.intrinsics[3],
                                            lens_of(fit.intrinsics));
  if (!camera) {
    return Error{Errc::kOutOfRange, "the fitted lens is not valid: " + camera.error().message};
  }
  report.camera = *camera;

  // Per-view figures and the overall RMS.
  double sum = 0.0;
  std::size_t n = 0;
  for (std::size_t v = 0; v < fitted.size(); ++v) {
    const double s = view_sum_sq(fit.intrinsics, fit.aspect, fit.poses[v], fitted[v]->observation);
    ViewReport& r = report.views[fitted_idx[v]];
    r.used = true;
    r.rms_px = point_rms(s, fitted[v]->observation.size());
    report.camera_T_board[fitted_idx[v]] = detail::vector_to_pose(fit.poses[v].data());
    sum += s;
    n += fitted[v]->observation.size();
  }
  report.rms_px = point_rms(sum, n);
  report.points_used = n;
  report.views_used = static_cast<int>(fitted.size());

  // Uncertainty of fx fy cx cy from the covariance, scaled by the residual variance.
  {
    ceres::Problem problem;
    std::vector<Pose6> poses = fit.poses;
    std::array<double, kIntrinsicsSize> k = fit.intrinsics;
    for (std::size_t v = 0; v < fitted.size(); ++v) {
      const BoardObservation& obs = fitted[v]->observation;
      for (std::size_t i = 0; i < obs.size(); ++i) {
        problem.AddResidualBlock(
            detail::BoardReprojection::create(obs.image_points[i], obs.object_points[i],
                                              fit.aspect),
            nullptr, k.data(), poses[v].data());
      }
    }
    const std::vector<int> fixed = constant_intrinsics(options);
    if (!fixed.empty()) {
      problem.SetManifold(k.data(), new ceres::SubsetManifold(kIntrinsicsSize, fixed));
    }
    ceres::Covariance::Options co;
    co.algorithm_type = ceres::DENSE_SVD;
    co.null_space_rank = -1;
    ceres::Covariance covariance(co);
    std::vector<std::pair<const double*, const double*>> blocks = {{k.data(), k.data()}};
    if (covariance.Compute(blocks, &problem)) {
      std::array<double, static_cast<std::size_t>(kIntrinsicsSize) * kIntrinsicsSize> c{};
      covariance.GetCovarianceBlock(k.data(), k.data(), c.data());
      const double dof = static_cast<double>(2 * n) -
                         static_cast<double>(kPoseSize * fitted.size() + kIntrinsicsSize -
                                             fixed.size());
      const double variance = dof > 0 ? sum / dof : 0.0;  // per coordinate
      for (int i = 0; i < 4; ++i) {
        report.sigma_px[i] =
            std::sqrt(std::max(0.0, c[static_cast<std::size_t>(i) * 10]) * variance);
      }
      if (fit.aspect > 0.0) {
        report.sigma_px[1] = fit.aspect * report.sigma_px[0];
      }
    }
  }

  // (4) Hold-out: each held-out view gets its pose from the fitted model alone.
  double hold_sum = 0.0;
  std::size_t hold_n = 0;
  std::size_t step = 0;
  for (const std::size_t i : hold_idx) {
    report_progress(progress, "holdout", ++step, hold_idx.size(),
                    fmt::format("view '{}'", views[i].id));
    ViewReport& r = report.views[i];
    r.held_out = true;
    auto pose = solve_board_pose(report.camera, views[i].observation);
    if (!pose) {
      r.held_out = false;
      r.reason = "held out, but no board pose with the fitted model: " + pose.error().message;
      continue;
    }
    report.camera_T_board[i] = *pose;
    r.rms_px = reprojection_rms(report.camera, *pose, views[i].observation);
    hold_sum += r.rms_px * r.rms_px * static_cast<double>(views[i].observation.size());
    hold_n += views[i].observation.size();
    ++report.views_held_out;
  }
  report.holdout_rms_px = point_rms(hold_sum, hold_n);
  for (const ViewReport& r : report.views) {
    if (!r.used && !r.held_out) {
      ++report.views_rejected;
    }
  }
  summary.time_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  report.solver = summary;
  return report;
}

Result<std::vector<std::string>> list_images(const std::string& directory) {
  static const std::set<std::string> kExtensions = {".png", ".jpg", ".jpeg", ".bmp", ".pgm",
                                                    ".ppm", ".tif", ".tiff"};
  std::error_code ec;
  if (!std::filesystem::is_directory(directory, ec)) {
    return Error{Errc::kIo, fmt::format("{}: not a readable directory{}", directory,
                                        ec ? ": " + ec.message() : "")};
  }
  std::vector<std::string> files;
  for (auto it = std::filesystem::directory_iterator(directory, ec);
       !ec && it != std::filesystem::directory_iterator(); it.increment(ec)) {
    if (!it->is_regular_file(ec)) {
      continue;
    }
    std::string ext = it->path().extension().string();
    std::transform(ext.begin(), ext.end(), ext.begin(),
                   [](unsigned char ch) { return static_cast<char>(std::tolower(ch)); });
    if (kExtensions.count(ext) != 0) {
      files.push_back(it->path().string());
    }
  }
  if (ec) {
    return Error{Errc::kIo, fmt::format("{}: cannot list: {}", directory, ec.message())};
  }
  std::sort(files.begin(), files.end());
  if (files.empty()) {
    return Error{Errc::kIo, fmt::format("{}: no image files (png, jpg, bmp, pgm, ppm, tif)",
                                        directory)};
  }
  return files;
}

Result<IntrinsicsReport> calibrate_intrinsics_from_directory(const std::string& directory,
                                                             const BoardSpec& board,
                                                             const IntrinsicsOptions& options,
                                                             const ProgressFn& progress) {
  CELL_TRY(board.validate());
  CELL_TRY(options.validate());
  auto files = list_images(directory);
  if (!files) {
    return std::move(files).error();
  }
  std::vector<BoardView> views;
  std::vector<ViewReport> rejected;
  int width = 0;
  int height = 0;
  std::string first_file;
  for (std::size_t i = 0; i < files->size(); ++i) {
    const std::string& file = (*files)[i];
    const std::string name = std::filesystem::path(file).filename().string();
    report_progress(progress, "detect", i + 1, files->size(), name);
    cv::Mat image;
    try {
      image = cv::imread(file, cv::IMREAD_GRAYSCALE);
    } catch (const cv::Exception& e) {
      image.release();
    }
    ViewReport r;
    r.id = name;
    if (image.empty()) {
      r.reason = "cannot read the image";
      rejected.push_back(r);
      continue;
    }
    if (width == 0) {
      width = image.cols;
      height = image.rows;
      first_file = name;
    } else if (image.cols != width || image.rows != height) {
      return Error{Errc::kInvalidArgument,
                   fmt::format("inconsistent image sizes in {}: {} is {} x {} px, {} is {} x {} "
                               "px (one camera at one resolution per calibration)",
                               directory, first_file, width, height, name, image.cols,
                               image.rows)};
    }
    auto obs = detect_board(image, board);
    if (!obs) {
      r.reason = obs.error().message;
      rejected.push_back(r);
      continue;
    }
    views.push_back(BoardView{name, 0, std::move(*obs)});
  }
  if (width == 0) {
    return Error{Errc::kInvalidArgument,
                 fmt::format("none of the {} image files of {} could be read", files->size(),
                             directory)};
  }
  if (views.empty()) {
    return Error{Errc::kInvalidArgument,
                 fmt::format("no {} found in any of the {} images of {}", board.describe(),
                             files->size(), directory)};
  }
  auto report = calibrate_intrinsics(views, width, height, options, progress);
  if (!report) {
    if (!rejected.empty()) {
      return with_context(std::move(report).error(),
                          fmt::format("{} ({} of {} images had no usable board)", directory,
                                      rejected.size(), files->size()));
    }
    return with_context(std::move(report).error(), directory);
  }
  // Put the images without a board back in file order.
  std::vector<ViewReport> all;
  std::vector<Eigen::Isometry3d> poses;
  std::size_t v = 0;
  std::size_t rj = 0;
  for (std::size_t i = 0; i < files->size(); ++i) {
    const std::string name = std::filesystem::path((*files)[i]).filename().string();
    if (rj < rejected.size() && rejected[rj].id == name) {
      all.push_back(rejected[rj++]);
      poses.push_back(Eigen::Isometry3d::Identity());
      ++report->views_rejected;
    } else if (v < report->views.size()) {
      all.push_back(report->views[v]);
      poses.push_back(report->camera_T_board[v]);
      ++v;
    }
  }
  report->views = std::move(all);
  report->camera_T_board = std::move(poses);
  return report;
}

}  // namespace cell::calibration
