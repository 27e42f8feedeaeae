// Intrinsics on the world simulator's renders, checked against the TRUE cameras of
// config/cameras/ and against cv::calibrateCamera on the very same corners.
#include "cell/calibration/intrinsics.hpp"

#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <iostream>
#include <random>

#include <Eigen/SVD>
#include <fmt/format.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgcodecs.hpp>

#include "cell/testing/matchers.hpp"
#include "sim_views.hpp"

namespace cell::calibration {
namespace {

using ::cell::testing::IsErrWith;
using ::cell::testing::IsOk;
using ::testing::HasSubstr;
using testing::camera_file;
using testing::intrinsics_views;

constexpr double kNoisePx = 0.2;        // Gaussian, per coordinate, added to every detected corner
constexpr double kFocalTolRel = 0.002;  // the issue: fx, fy within 0.2 %
constexpr double kCentreTolPx = 1.0;    // cx, cy within 1 px
constexpr double kRmsFactor = 1.2;      // RMS within 1.2 x the noise
constexpr std::uint64_t kSeed = 7;

struct Errors {
  double fx_rel, fy_rel, cx_px, cy_px;
};

Errors errors_against(const render::CameraModel& truth, double fx, double fy, double cx,
                      double cy) {
  return {std::abs(fx - truth.fx_px()) / truth.fx_px(), std::abs(fy - truth.fy_px()) / truth.fy_px(),
          std::abs(cx - truth.cx_px()), std::abs(cy - truth.cy_px())};
}

/// What matters downstream: the viewing ray of every pixel. For a 17 x 17 grid of pixels, the
/// fitted model's rays turned by the best rotation onto the truth's (a rotation of the camera
/// frame is the extrinsics' business) and projected through the truth: worst pixel error.
double max_ray_error_px(const render::CameraModel& truth, const render::CameraModel& fit) {
  std::vector<Eigen::Vector2d> pixels;
  std::vector<Eigen::Vector3d> rt;
  std::vector<Eigen::Vector3d> rf;
  for (int i = 0; i <= 16; ++i) {
    for (int j = 0; j <= 16; ++j) {
      const Eigen::Vector2d px((truth.width_px() - 1) * i / 16.0, (truth.height_px() - 1) * j / 16.0);
      auto a = truth.unproject(px);
      auto b = fit.unproject(px);
      if (a && b) {
        pixels.push_back(px);
        rt.push_back(a->normalized());
        rf.push_back(b->normalized());
      }
    }
  }
  Eigen::Matrix3d h = Eigen::Matrix3d::Zero();
  for (std::size_t k = 0; k < rt.size(); ++k) {
    h += rf[k] * rt[k].transpose();
  }
  Eigen::JacobiSVD<Eigen::Matrix3d> svd(h, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Matrix3d r = svd.matrixV() * svd.matrixU().transpose();
  if (r.determinant() < 0) {
    Eigen::Matrix3d v = svd.matrixV();
    v.col(2) *= -1.0;
    r = v * svd.matrixU().transpose();
  }
  double worst = 0.0;
  for (std::size_t k = 0; k < rt.size(); ++k) {
    auto px = truth.project(r * rf[k]);
    worst = std::max(worst, px ? (*px - pixels[k]).norm() : 1e9);
  }
  return worst;
}

/// cv::calibrateCamera on the views the report fitted (same corners), with `flags`.
struct OpenCvResult {
  render::CameraModel camera;
  double rms_px = 0.0;
};
OpenCvResult opencv_calibrate(const std::vector<BoardView>& views, const IntrinsicsReport& report,
                              int width, int height, int flags) {
  std::vector<std::vector<cv::Point3f>> object;
  std::vector<std::vector<cv::Point2f>> image;
  for (std::size_t i = 0; i < views.size(); ++i) {
    if (!report.views[i].used) {
      continue;
    }
    std::vector<cv::Point3f> o;
    std::vector<cv::Point2f> m;
    for (std::size_t k = 0; k < views[i].observation.size(); ++k) {
      const auto& p = views[i].observation.object_points[k];
      const auto& q = views[i].observation.image_points[k];
      o.emplace_back(static_cast<float>(p.x()), static_cast<float>(p.y()), 0.0F);
      m.emplace_back(static_cast<float>(q.x()), static_cast<float>(q.y()));
    }
    object.push_back(o);
    image.push_back(m);
  }
  cv::Mat k;
  cv::Mat d;
  std::vector<cv::Mat> rvecs;
  std::vector<cv::Mat> tvecs;
  const double rms =
      cv::calibrateCamera(object, image, cv::Size(width, height), k, d, rvecs, tvecs, flags);
  auto camera = render::CameraModel::create(
      width, height, k.at<double>(0, 0), k.at<double>(1, 1), k.at<double>(0, 2),
      k.at<double>(1, 2),
      {d.at<double>(0), d.at<double>(1), d.at<double>(2), d.at<double>(3), d.at<double>(4)});
  EXPECT_TRUE(camera) << camera.error().message;
  return {camera.value_or(render::CameraModel{}), rms};
}

std::string describe(const std::string& who, const render::CameraModel& c,
                     const render::CameraModel& truth, double rms, double ray) {
  const Errors e = errors_against(truth, c.fx_px(), c.fy_px(), c.cx_px(), c.cy_px());
  return fmt::format("{}: fx {:.2f} fy {:.2f} cx {:.2f} cy {:.2f} px (errors {:.3f} % {:.3f} % "
                     "{:.2f} {:.2f} px), RMS {:.4f} px, worst ray {:.3f} px",
                     who, c.fx_px(), c.fy_px(), c.cx_px(), c.cy_px(), 100 * e.fx_rel,
                     100 * e.fy_rel, e.cx_px, e.cy_px, rms, ray);
}

BoardSpec board(int columns, int rows, double square_mm) {
  BoardSpec spec;
  spec.columns = columns;
  spec.rows = rows;
  spec.square_mm = square_mm;
  return spec;
}

// The issue's must-hold on the belt camera (1024 x 1024, a mild barrel lens): 20 views with
// 0.2 px noise; fx, fy within 0.2 %, cx, cy within 1 px, RMS within 1.2 x the noise; at least
// as accurate as cv::calibrateCamera on the same corners (with its default five coefficients,
// and with k3 fixed as here, where the two optimise the same objective and tie).
// The board fills the field (25 x 17 inner corners of 15 mm, an A2 print): on a 28 degree lens
// the principal point trades with tangential distortion at second order in the field angle,
// and Ceres's covariance puts its 1-sigma at 0.9 px even so (bench/calibration: trials).
TEST(Intrinsics, BeltCameraMeetsTheIssueBoundsAndMatchesOpenCv) {
  const render::CameraDescription camera = camera_file("belt_cam.yaml");
  const render::CameraModel& truth = camera.truth.model;
  const std::vector<BoardView> views =
      intrinsics_views(camera, board(25, 17, 15.0), 20, 1000.0, kNoisePx, kSeed);
  ASSERT_EQ(views.size(), 20U);
  auto report = calibrate_intrinsics(views, truth.width_px(), truth.height_px());
  ASSERT_THAT(report, IsOk());
  EXPECT_EQ(report->views_used + report->views_held_out, 20);
  EXPECT_EQ(report->views_rejected, 0);
  EXPECT_EQ(report->views_held_out, 4);
  const render::CameraModel& fit = report->camera;
  const Errors mine = errors_against(truth, fit.fx_px(), fit.fy_px(), fit.cx_px(), fit.cy_px());
  EXPECT_LT(mine.fx_rel, kFocalTolRel) << report->brief();
  EXPECT_LT(mine.fy_rel, kFocalTolRel) << report->brief();
  EXPECT_LT(mine.cx_px, kCentreTolPx) << report->brief();
  EXPECT_LT(mine.cy_px, kCentreTolPx) << report->brief();
  // The noise's own RMS in the report's convention (per point: sigma * sqrt 2).
  const double noise_rms = kNoisePx * std::sqrt(2.0);
  EXPECT_LT(report->rms_px, kRmsFactor * noise_rms) << report->brief();
  EXPECT_GT(report->rms_px, 0.9 * noise_rms) << "a fit below the noise is over-fitting";
  EXPECT_LT(report->holdout_rms_px, kRmsFactor * noise_rms) << report->brief();
  const double ray = max_ray_error_px(truth, fit);
  EXPECT_LT(ray, 0.3);

  const OpenCvResult cv5 = opencv_calibrate(views, *report, truth.width_px(), truth.height_px(), 0);
  const OpenCvResult cv4 = opencv_calibrate(views, *report, truth.width_px(), truth.height_px(),
                                            cv::CALIB_FIX_K3);
  for (const OpenCvResult* other : {&cv5, &cv4}) {
    const render::CameraModel& c = other->camera;
    const Errors theirs = errors_against(truth, c.fx_px(), c.fy_px(), c.cx_px(), c.cy_px());
    constexpr double kTieRel = 1e-6;  // the same objective: equal to rounding
    constexpr double kTiePx = 1e-3;
    EXPECT_LE(mine.fx_rel, theirs.fx_rel + kTieRel);
    EXPECT_LE(mine.fy_rel, theirs.fy_rel + kTieRel);
    EXPECT_LE(mine.cx_px, theirs.cx_px + kTiePx);
    EXPECT_LE(mine.cy_px, theirs.cy_px + kTiePx);
    EXPECT_LE(ray, max_ray_error_px(truth, c) + kTiePx);
  }
  std::cout << describe("ceres", fit, truth, report->rms_px, ray) << "\n"
            << describe("opencv (5 coeffs)", cv5.camera, truth, cv5.rms_px,
                        max_ray_error_px(truth, cv5.camera))
            << "\n"
            << describe("opencv (k3 fixed)", cv4.camera, truth, cv4.rms_px,
                        max_ray_error_px(truth, cv4.camera))
            << "\n  " << report->brief() << "\n";
}

// The 7545's camera: 512 x 484 behind a 20 degree lens with barrel distortion and non-square
// pixels. fx and fy meet the issue's 0.2 %; its principal point cannot be had to 1 px from 20
// views at 0.2 px noise by any estimator (Ceres's covariance gives 1-sigma about 3 px: the
// Cramer-Rao bound of this geometry), so the test holds it to the reported uncertainty, and
// holds what vision needs, the ray of every pixel, to a fraction of a pixel.
TEST(Intrinsics, EyeInHandCameraMeetsTheFocalBoundsAndItsOwnUncertainty) {
  const render::CameraDescription camera = camera_file("ibm7545_eye.yaml");
  const render::CameraModel& truth = camera.truth.model;
  const std::vector<BoardView> views =
      intrinsics_views(camera, board(17, 12, 6.0), 20, 420.0, kNoisePx, kSeed);
  ASSERT_EQ(views.size(), 20U);
  auto report = calibrate_intrinsics(views, truth.width_px(), truth.height_px());
  ASSERT_THAT(report, IsOk());
  const render::CameraModel& fit = report->camera;
  const Errors mine = errors_against(truth, fit.fx_px(), fit.fy_px(), fit.cx_px(), fit.cy_px());
  EXPECT_LT(mine.fx_rel, kFocalTolRel) << report->brief();
  EXPECT_LT(mine.fy_rel, kFocalTolRel) << report->brief();
  EXPECT_GT(report->sigma_px[2], 0.0);
  EXPECT_LT(mine.cx_px, 3.0 * report->sigma_px[2]) << report->brief();
  EXPECT_LT(mine.cy_px, 3.0 * report->sigma_px[3]) << report->brief();
  const double noise_rms = kNoisePx * std::sqrt(2.0);
  EXPECT_LT(report->rms_px, kRmsFactor * noise_rms) << report->brief();
  EXPECT_LT(report->holdout_rms_px, kRmsFactor * noise_rms) << report->brief();
  const double ray = max_ray_error_px(truth, fit);
  EXPECT_LT(ray, 1.0);
  const OpenCvResult cv5 = opencv_calibrate(views, *report, truth.width_px(), truth.height_px(), 0);
  EXPECT_LE(ray, max_ray_error_px(truth, cv5.camera) + 1e-3);
  std::cout << describe("ceres", fit, truth, report->rms_px, ray) << "\n"
            << describe("opencv (5 coeffs)", cv5.camera, truth, cv5.rms_px,
                        max_ray_error_px(truth, cv5.camera))
            << "\n  " << report->brief() << "\n";
}

// Variants: a known principal point or aspect ratio held fixed is kept exactly, and helps.
TEST(Intrinsics, FixedPrincipalPointAndFixedAspectRatioAreHeld) {
  const render::CameraDescription camera = camera_file("ibm7545_eye.yaml");
  const render::CameraModel& truth = camera.truth.model;
  const std::vector<BoardView> views =
      intrinsics_views(camera, board(17, 12, 6.0), 12, 420.0, kNoisePx, kSeed + 1);
  IntrinsicsOptions fixed_pp;
  fixed_pp.fix_principal_point = true;
  fixed_pp.principal_point_px = Eigen::Vector2d(truth.cx_px(), truth.cy_px());
  auto a = calibrate_intrinsics(views, truth.width_px(), truth.height_px(), fixed_pp);
  ASSERT_THAT(a, IsOk());
  EXPECT_EQ(a->camera.cx_px(), truth.cx_px());
  EXPECT_EQ(a->camera.cy_px(), truth.cy_px());
  EXPECT_LT(std::abs(a->camera.fx_px() - truth.fx_px()) / truth.fx_px(), kFocalTolRel);
  EXPECT_EQ(a->sigma_px[2], 0.0);  // held, not estimated

  IntrinsicsOptions fixed_aspect;
  fixed_aspect.fix_aspect_ratio = true;
  fixed_aspect.aspect_ratio = truth.fy_px() / truth.fx_px();
  auto b = calibrate_intrinsics(views, truth.width_px(), truth.height_px(), fixed_aspect);
  ASSERT_THAT(b, IsOk());
  EXPECT_NEAR(b->camera.fy_px() / b->camera.fx_px(), fixed_aspect.aspect_ratio, 1e-12);
  EXPECT_LT(std::abs(b->camera.fy_px() - truth.fy_px()) / truth.fy_px(), kFocalTolRel);

  IntrinsicsOptions ideal;
  ideal.lens = LensModel::kNone;
  auto c = calibrate_intrinsics(views, truth.width_px(), truth.height_px(), ideal);
  ASSERT_THAT(c, IsOk());
  EXPECT_TRUE(c->camera.distortion().is_zero());
  // No lens model for a lens with k1 = -0.12: focal length and poses absorb most of it in the
  // residuals, not in the rays at the edge of the field.
  auto full = calibrate_intrinsics(views, truth.width_px(), truth.height_px());
  ASSERT_THAT(full, IsOk());
  EXPECT_EQ(c->views_rejected, 0) << c->brief();
  EXPECT_EQ(full->views_rejected, 0) << full->brief();
  EXPECT_GT(c->rms_px, full->rms_px);
  EXPECT_GT(max_ray_error_px(truth, c->camera), 2.0 * max_ray_error_px(truth, full->camera));
}

// A view whose board moved during the exposure (every corner of one half smeared by 4 px) is
// rejected with its RMS and the limit, and the result stays on the truth; OpenCV, which has
// no rejection, takes the bad view in and drifts.
TEST(Intrinsics, AnOutlierViewIsRejectedWithTheReason) {
  const render::CameraDescription camera = camera_file("belt_cam.yaml");
  const render::CameraModel& truth = camera.truth.model;
  std::vector<BoardView> views =
      intrinsics_views(camera, board(25, 17, 15.0), 20, 1000.0, kNoisePx, kSeed);
  ASSERT_EQ(views.size(), 20U);
  BoardObservation& bad = views[5].observation;
  for (std::size_t k = 0; k < bad.size(); ++k) {
    if (bad.object_points[k].x() > 200.0) {
      bad.image_points[k] += Eigen::Vector2d(4.0, -3.0);
    }
  }
  auto report = calibrate_intrinsics(views, truth.width_px(), truth.height_px());
  ASSERT_THAT(report, IsOk());
  EXPECT_FALSE(report->views[5].used);
  EXPECT_FALSE(report->views[5].held_out);
  EXPECT_THAT(report->views[5].reason, HasSubstr("outlier: RMS"));
  EXPECT_THAT(report->views[5].reason, HasSubstr("median view RMS"));
  EXPECT_EQ(report->views_rejected, 1);
  EXPECT_EQ(report->views_used, 15);
  const render::CameraModel& fit = report->camera;
  EXPECT_LT(std::abs(fit.fx_px() - truth.fx_px()) / truth.fx_px(), kFocalTolRel);
  EXPECT_LT(std::abs(fit.cx_px() - truth.cx_px()), kCentreTolPx);
  EXPECT_LT(report->rms_px, kRmsFactor * kNoisePx * std::sqrt(2.0));
  // OpenCV on every fitted view plus the bad one.
  IntrinsicsReport with_bad = *report;
  with_bad.views[5].used = true;
  const OpenCvResult cv5 =
      opencv_calibrate(views, with_bad, truth.width_px(), truth.height_px(), cv::CALIB_FIX_K3);
  EXPECT_GT(max_ray_error_px(truth, cv5.camera), max_ray_error_px(truth, fit));
  EXPECT_GT(cv5.rms_px, 1.3 * report->rms_px);
}

TEST(Intrinsics, TooFewViewsIsAClearError) {
  const render::CameraDescription camera = camera_file("ibm7545_eye.yaml");
  const std::vector<BoardView> views =
      intrinsics_views(camera, board(9, 6, 10.0), 4, 420.0, kNoisePx, kSeed);
  ASSERT_EQ(views.size(), 4U);
  auto r = calibrate_intrinsics(views, 512, 484);
  EXPECT_THAT(r, IsErrWith(Errc::kInvalidArgument, "too few views: 4 given, 4 usable"));
  EXPECT_THAT(r, IsErrWith(Errc::kInvalidArgument, "7 needed (5 to fit and 2 to hold out)"));
  EXPECT_THAT(calibrate_intrinsics({}, 512, 484),
              IsErrWith(Errc::kInvalidArgument, "too few views: 0 given"));
}

TEST(Intrinsics, ViewsOfAnotherSizeAreRejectedNotFitted) {
  const render::CameraDescription camera = camera_file("ibm7545_eye.yaml");
  std::vector<BoardView> views =
      intrinsics_views(camera, board(9, 6, 10.0), 10, 420.0, kNoisePx, kSeed);
  views[3].observation.width_px = 640;
  views[3].observation.height_px = 480;
  auto r = calibrate_intrinsics(views, 512, 484);
  ASSERT_THAT(r, IsOk());
  EXPECT_THAT(r->views[3].reason, HasSubstr("640 x 480 px differs from the camera's 512 x 484"));
  EXPECT_EQ(r->views_rejected, 1);
}

TEST(IntrinsicsOptions, ValidateNamesTheOption) {
  IntrinsicsOptions o;
  o.huber_px = 0.0;
  EXPECT_THAT(o.validate(), IsErrWith(Errc::kInvalidArgument, "huber_px must be > 0, got 0"));
  o = {};
  o.holdout_fraction = 0.7;
  EXPECT_THAT(o.validate(), IsErrWith(Errc::kInvalidArgument, "holdout_fraction"));
  o = {};
  o.min_fit_views = 2;
  EXPECT_THAT(o.validate(), IsErrWith(Errc::kInvalidArgument, "min_fit_views must be >= 3"));
}

// Images on disk: the command line's and the service's path.
class IntrinsicsDirectoryTest : public ::testing::Test {
 protected:
  IntrinsicsDirectoryTest()
      : dir_(std::filesystem::temp_directory_path() /
             fmt::format("calib-intrinsics-{}-{}", ::getpid(), counter_++)) {
    std::filesystem::create_directories(dir_);
  }
  ~IntrinsicsDirectoryTest() override {
    std::error_code ec;
    std::filesystem::remove_all(dir_, ec);
  }
  /// Renders `count` views of `spec` through the 7545 camera's truth into the directory.
  void write_views(const BoardSpec& spec, int count, const std::string& prefix) {
    const render::CameraDescription camera = camera_file("ibm7545_eye.yaml");
    for (int i = 0; i < count; ++i) {
      const double tilt = (i % 2 == 0 ? 1 : -1) * (0.3 + 0.05 * i);
      const Eigen::Isometry3d camera_T_board = testing::board_facing_camera(
          spec, Eigen::Vector3d(8.0 * (i % 3 - 1), 6.0 * (i % 2), 400.0 + 8 * i), 0.1 * i, tilt,
          -0.6 * tilt);
      render::Scene scene;
      scene.table_height_mm = -5000.0;
      scene.lights.fluorescent_on = false;
      scene.targets.push_back(testing::chessboard_target(spec, camera_T_board));
      render::Lighting lighting = camera.lighting;
      lighting.ambient = 0.7;
      const cv::Mat image = testing::render_view(camera.truth.model, lighting, scene,
                                                 Eigen::Isometry3d::Identity(), 1.0, i);
      cv::imwrite((dir_ / fmt::format("{}{:02d}.png", prefix, i)).string(), image);
    }
  }
  std::string dir() const { return dir_.string(); }

  static inline int counter_ = 0;
  std::filesystem::path dir_;
};

TEST_F(IntrinsicsDirectoryTest, CalibratesFromFilesAndReportsImagesWithoutTheBoard) {
  write_views(board(9, 6, 10.0), 9, "view");
  cv::imwrite((dir_ / "view04b_blank.png").string(), cv::Mat(484, 512, CV_8UC1, cv::Scalar(30)));
  std::vector<std::string> stages;
  auto r = calibrate_intrinsics_from_directory(
      dir(), board(9, 6, 10.0), {},
      [&](std::string_view stage, std::size_t, std::size_t, std::string_view) {
        stages.emplace_back(stage);
      });
  ASSERT_THAT(r, IsOk());
  ASSERT_EQ(r->views.size(), 10U);
  EXPECT_EQ(r->views[5].id, "view04b_blank.png");
  EXPECT_THAT(r->views[5].reason, HasSubstr("no chessboard 9x6"));
  EXPECT_EQ(r->views_rejected, 1);
  EXPECT_EQ(r->views_used + r->views_held_out, 9);
  EXPECT_GT(r->holdout_rms_px, 0.0);
  EXPECT_EQ(std::count(stages.begin(), stages.end(), "detect"), 10);
  EXPECT_NE(std::find(stages.begin(), stages.end(), "holdout"), stages.end());
}

TEST_F(IntrinsicsDirectoryTest, ADirectoryWithNoBoardSaysSo) {
  for (int i = 0; i < 3; ++i) {
    cv::imwrite((dir_ / fmt::format("empty{}.png", i)).string(),
                cv::Mat(484, 512, CV_8UC1, cv::Scalar(40 + 50 * i)));
  }
  EXPECT_THAT(calibrate_intrinsics_from_directory(dir(), board(9, 6, 10.0)),
              IsErrWith(Errc::kInvalidArgument,
                        "no chessboard 9x6 inner corners, 10 mm squares found in any of the 3 "
                        "images of " + dir()));
}

TEST_F(IntrinsicsDirectoryTest, InconsistentImageSizesAreAClearError) {
  write_views(board(9, 6, 10.0), 3, "a");
  cv::imwrite((dir_ / "b_small.png").string(), cv::Mat(480, 640, CV_8UC1, cv::Scalar(90)));
  EXPECT_THAT(calibrate_intrinsics_from_directory(dir(), board(9, 6, 10.0)),
              IsErrWith(Errc::kInvalidArgument,
                        "inconsistent image sizes in " + dir() +
                            ": a00.png is 512 x 484 px, b_small.png is 640 x 480 px"));
}

TEST_F(IntrinsicsDirectoryTest, AnEmptyOrMissingDirectoryIsAnIoError) {
  EXPECT_THAT(calibrate_intrinsics_from_directory(dir(), board(9, 6, 10.0)),
              IsErrWith(Errc::kIo, "no image files"));
  EXPECT_THAT(calibrate_intrinsics_from_directory(dir() + "/nope", board(9, 6, 10.0)),
              IsErrWith(Errc::kIo, "not a readable directory"));
}

TEST_F(IntrinsicsDirectoryTest, TooFewViewsFromFilesCountsTheImages) {
  write_views(board(9, 6, 10.0), 4, "v");
  auto r = calibrate_intrinsics_from_directory(dir(), board(9, 6, 10.0));
  EXPECT_THAT(r, IsErrWith(Errc::kInvalidArgument, "too few views: 4 given"));
}

}  // namespace
}  // namespace cell::calibration
