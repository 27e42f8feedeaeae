#include "cell/render/camera_model.hpp"

#include <random>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <opencv2/calib3d.hpp>

#include "cell/testing/matchers.hpp"
#include "cell/testing/tolerances.hpp"

namespace cell::render {
namespace {

using ::cell::testing::IsErrWith;
using ::testing::HasSubstr;

using ::cell::testing::kTolPx;

// The 7545's true camera (config/cameras/ibm7545_eye.yaml): 512 x 484, 3.56 x 3.48 px/mm at
// 420 mm, with a lens the thesis never modelled.
CameraModel eye_camera() {
  return CameraModel::create(512, 484, 1502.3, 1455.9, 258.4, 237.2,
                             Distortion{-0.12, 0.08, 0.0006, -0.0004, 0.0})
      .value();
}

TEST(CameraModel, ProjectionMatchesCvProjectPoints) {
  const CameraModel camera = eye_camera();
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> xy(-90.0, 90.0);
  std::uniform_real_distribution<double> z(300.0, 600.0);
  std::vector<cv::Point3d> object;
  object.reserve(200);
  for (int i = 0; i < 200; ++i) {
    object.emplace_back(xy(rng), xy(rng), z(rng));
  }
  const cv::Mat k = (cv::Mat_<double>(3, 3) << camera.fx_px(), 0, camera.cx_px(), 0,
                     camera.fy_px(), camera.cy_px(), 0, 0, 1);
  const auto dist = camera.distortion().as_array();
  const cv::Mat d(1, 5, CV_64F, const_cast<double*>(dist.data()));
  std::vector<cv::Point2d> expected;
  cv::projectPoints(object, cv::Vec3d(0, 0, 0), cv::Vec3d(0, 0, 0), k, d, expected);
  for (std::size_t i = 0; i < object.size(); ++i) {
    const auto px = camera.project({object[i].x, object[i].y, object[i].z});
    ASSERT_TRUE(px) << px.error().message;
    EXPECT_NEAR(px->x(), expected[i].x, kTolPx);
    EXPECT_NEAR(px->y(), expected[i].y, kTolPx);
  }
}

TEST(CameraModel, UnprojectInvertsProjectOverTheWholeImage) {
  const CameraModel camera = eye_camera();
  for (double v = -0.5; v <= 483.5; v += 23.1) {
    for (double u = -0.5; u <= 511.5; u += 19.7) {
      const auto ray = camera.unproject({u, v});
      ASSERT_TRUE(ray) << ray.error().message;
      const auto back = camera.project(*ray * 420.0);
      ASSERT_TRUE(back) << back.error().message;
      EXPECT_NEAR(back->x(), u, kTolPx);
      EXPECT_NEAR(back->y(), v, kTolPx);
    }
  }
}

TEST(CameraModel, ImageBoundsHoldEveryPixelRay) {
  const CameraModel camera = eye_camera();
  const NormalisedBounds& b = camera.image_bounds();
  for (const Eigen::Vector2d& px : {Eigen::Vector2d(-0.5, -0.5), Eigen::Vector2d(511.5, 483.5),
                                   Eigen::Vector2d(256, 0), Eigen::Vector2d(0, 242)}) {
    const auto ray = camera.unproject(px);
    ASSERT_TRUE(ray);
    EXPECT_GE(ray->x(), b.x_min - 1e-12);
    EXPECT_LE(ray->x(), b.x_max + 1e-12);
    EXPECT_GE(ray->y(), b.y_min - 1e-12);
    EXPECT_LE(ray->y(), b.y_max + 1e-12);
  }
  // Barrel distortion: the undistorted field is wider than the pinhole's.
  EXPECT_LT(b.x_min, (-0.5 - camera.cx_px()) / camera.fx_px());
}

TEST(CameraModel, PointsBehindTheCameraHaveNoPixel) {
  const CameraModel camera = eye_camera();
  EXPECT_THAT(camera.project({0.0, 0.0, -10.0}),
              IsErrWith(Errc::kOutOfRange, "not in front of the camera"));
  EXPECT_THAT(camera.project({0.0, 0.0, 0.0}), IsErrWith(Errc::kOutOfRange, "not in front"));
  EXPECT_THAT(camera.project({5000.0, 0.0, 1.0}), IsErrWith(Errc::kOutOfRange, "lens's field"));
  EXPECT_THAT(camera.project({NAN, 0.0, 1.0}), IsErrWith(Errc::kInvalidArgument, "not finite"));
}

TEST(CameraModel, RejectsImpossibleParametersAndSaysWhich) {
  EXPECT_THAT(CameraModel::create(0, 484, 1500, 1500, 256, 242, {}),
              IsErrWith(Errc::kInvalidArgument, "camera size 0 x 484 px"));
  EXPECT_THAT(CameraModel::create(512, 484, -1500, 1500, 256, 242, {}),
              IsErrWith(Errc::kInvalidArgument, "fx = -1500"));
  EXPECT_THAT(CameraModel::create(512, 484, 1500, 1500, NAN, 242, {}),
              IsErrWith(Errc::kInvalidArgument, "principal point"));
  EXPECT_THAT(CameraModel::create(512, 484, 1500, 1500, 256, 242, Distortion{0, NAN, 0, 0, 0}),
              IsErrWith(Errc::kInvalidArgument, "distortion k2"));
  // So strong a barrel that the polynomial turns back before the image corners: no lens.
  const auto folded = CameraModel::create(512, 484, 300, 300, 256, 242, Distortion{-0.9, 0, 0, 0, 0});
  EXPECT_THAT(folded, IsErrWith(Errc::kInvalidArgument, "folds back inside the image"));
}

TEST(CameraModel, AnIdealPinholeIsItsOwnUndistortion) {
  const CameraModel camera = CameraModel::create(100, 80, 200, 210, 49.5, 39.5, {}).value();
  const auto px = camera.project({10.0, -4.0, 100.0});
  ASSERT_TRUE(px);
  EXPECT_NEAR(px->x(), 49.5 + 200 * 0.1, 1e-12);
  EXPECT_NEAR(px->y(), 39.5 - 210 * 0.04, 1e-12);
  EXPECT_TRUE(camera.distortion().is_zero());
}

}  // namespace
}  // namespace cell::render
