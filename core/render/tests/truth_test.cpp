#include "cell/render/truth.hpp"

#include <cmath>
#include <numbers>

#include <gtest/gtest.h>

#include "cell/testing/tolerances.hpp"
#include "test_cameras.hpp"

namespace cell::render {
namespace {

using ::cell::testing::kTolPx;

using testing::looking_down;
using testing::pinhole;

Part rectangle(const std::string& id, double x, double y, double yaw) {
  Part p;
  p.id = id;
  p.class_name = "rectangle";
  p.shape = Shape::kRectangle;
  p.length_mm = 30.0;
  p.width_mm = 7.0;  // digest 000 §7: 7 x 30 mm ICs
  p.height_mm = 4.0;
  p.world_T_part.translation() = Eigen::Vector3d(x, y, 0.0);
  p.world_T_part.linear() = Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  return p;
}

// Under a camera looking straight down the top face is 416 mm away: its scale is f / 416.
TEST(GroundTruth, CentreAngleAndCornersOfARotatedPart) {
  const CameraModel camera = pinhole();
  Scene scene;
  const double yaw = 0.5;
  scene.parts.push_back(rectangle("p1", 10.0, 20.0, yaw));
  const auto truth = ground_truth(scene, camera, looking_down({0.0, 0.0, 420.0}));
  ASSERT_EQ(truth.size(), 1U);
  const PartTruth& t = truth.front();
  EXPECT_EQ(t.part_id, "p1");
  EXPECT_EQ(t.class_name, "rectangle");
  const double sx = camera.fx_px() / 416.0;
  const double sy = camera.fy_px() / 416.0;
  EXPECT_NEAR(t.center_px.x(), 255.0 + 10.0 * sx, kTolPx);
  EXPECT_NEAR(t.center_px.y(), 241.0 - 20.0 * sy, kTolPx);  // world +y is image -v
  // The part's x axis (cos yaw, sin yaw) appears as (sx cos, -sy sin): the angle turns the
  // other way on screen, where v points down.
  EXPECT_NEAR(t.angle_rad, std::atan2(-sy * std::sin(yaw), sx * std::cos(yaw)), 1e-12);
  ASSERT_EQ(t.corners_px.size(), 4U);
  const Eigen::Vector2d first = Eigen::Rotation2Dd(yaw) * Eigen::Vector2d(-15.0, -3.5);
  EXPECT_NEAR(t.corners_px[0].x(), 255.0 + (10.0 + first.x()) * sx, kTolPx);
  EXPECT_NEAR(t.corners_px[0].y(), 241.0 - (20.0 + first.y()) * sy, kTolPx);
  EXPECT_DOUBLE_EQ(t.visible_fraction, 1.0);
}

TEST(GroundTruth, PartsAtTheBorderCountTheirVisibleFraction) {
  const CameraModel camera = pinhole();
  Scene scene;
  // The image's right border, u = 511.5, lies at x = 256.5 / sx mm: centre the part on it.
  const double border_x = 256.5 / (camera.fx_px() / 416.0);
  scene.parts.push_back(rectangle("half", border_x, 0.0, 0.0));
  scene.parts.push_back(rectangle("gone", 400.0, 0.0, 0.0));
  const auto truth = ground_truth(scene, camera, looking_down({0.0, 0.0, 420.0}));
  ASSERT_EQ(truth.size(), 1U);
  EXPECT_EQ(truth.front().part_id, "half");
  EXPECT_NEAR(truth.front().visible_fraction, 0.5, 1.0 / 24.0);
}

TEST(GroundTruth, TrianglesHaveThreeCornersDiscsNone) {
  const CameraModel camera = pinhole();
  Scene scene;
  Part tri = rectangle("t", 0.0, 0.0, 0.0);
  tri.shape = Shape::kTriangle;
  tri.length_mm = 20.0;
  Part disc = rectangle("d", 40.0, 0.0, 0.0);
  disc.shape = Shape::kDisc;
  disc.length_mm = 15.0;
  scene.parts = {tri, disc};
  const auto truth = ground_truth(scene, camera, looking_down({0.0, 0.0, 420.0}));
  ASSERT_EQ(truth.size(), 2U);
  EXPECT_EQ(truth[0].corners_px.size(), 3U);
  // The triangle's centroid is its frame origin.
  Eigen::Vector2d mean = Eigen::Vector2d::Zero();
  for (const auto& c : truth[0].corners_px) {
    mean += c / 3.0;
  }
  EXPECT_NEAR((mean - truth[0].center_px).norm(), 0.0, 1e-9);
  EXPECT_TRUE(truth[1].corners_px.empty());
}

TEST(GroundTruth, InvalidPartsAreLeftOutAsTheRendererLeavesThem) {
  Scene scene;
  Part bad = rectangle("bad", 0.0, 0.0, 0.0);
  bad.length_mm = -3.0;
  scene.parts.push_back(bad);
  EXPECT_TRUE(ground_truth(scene, pinhole(), looking_down({0.0, 0.0, 420.0})).empty());
}

}  // namespace
}  // namespace cell::render
