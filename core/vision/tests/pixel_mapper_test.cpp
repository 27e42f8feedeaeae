// Pixels to the working plane and the robot base with pinhole calibrations.
#include "cell/vision/pixel_mapper.hpp"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <random>

#include "cell/render/mount.hpp"
#include "cell/render/truth.hpp"
#include "cell/testing/matchers.hpp"
#include "scenes.hpp"

namespace cell::vision {
namespace {

using ::cell::testing::IsErr;
using ::cell::testing::IsErrWith;
using ::testing::HasSubstr;
using vision::testing::Cell;

constexpr double kMapTolMm = 1e-3;

Eigen::Isometry3d camera_pose(const Cell& cell, const std::vector<double>& joints) {
  kinematics::JointVector q(4);
  for (int i = 0; i < 4; ++i) {
    q[i] = joints[static_cast<std::size_t>(i)];
  }
  const auto mount = render::base_T_mount(cell.robot(), cell.camera().robot.frame, q).value();
  return cell.camera().world_T_camera(cell.camera().truth, mount);
}

// With the true calibration, a world point seen through the true camera maps back onto itself:
// undistortion (the grid), the eye-in-hand pose at the joints and the height of the surface.
TEST(PixelMapper, TrueCalibrationMapsPixelsBackToTheirWorldPoints) {
  const Cell& cell = Cell::get();
  const auto joints = cell.aligned_joints();
  const PixelMapper mapper = cell.mapper(cell.true_calibration(), joints);
  ASSERT_TRUE(mapper.metric());
  ASSERT_TRUE(mapper.world());
  const Eigen::Isometry3d w_T_c = camera_pose(cell, joints);
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> dx(-60.0, 60.0);
  std::uniform_real_distribution<double> dh(0.0, 8.0);
  const Eigen::Vector3d centre = w_T_c.translation();
  int checked = 0;
  for (int i = 0; i < 500; ++i) {
    const double h = dh(rng);
    const Eigen::Vector3d p_world(centre.x() + dx(rng), centre.y() + dx(rng), 750.0 + h);
    const auto px = render::project_world(cell.camera().truth.model, w_T_c, p_world);
    if (!px || px->x() < 0 || px->y() < 0 || px->x() > 511 || px->y() > 483) {
      continue;
    }
    const auto xy = mapper.to_plane(*px, h);
    ASSERT_TRUE(xy) << xy.error().message;
    const Eigen::Vector3d p_base = cell.world_T_base().inverse() * p_world;
    EXPECT_NEAR(xy->x(), p_base.x(), kMapTolMm);
    EXPECT_NEAR(xy->y(), p_base.y(), kMapTolMm);
    const auto back = mapper.to_pixel(*xy, h);
    ASSERT_TRUE(back);
    EXPECT_NEAR((*back - *px).norm(), 0.0, 2e-3);  // the grid's bilinear error, in pixels
    ++checked;
  }
  EXPECT_GT(checked, 300);
}

// A vertical wall: its top and bottom edges appear at different pixels (parallax) but map to
// the same plane point once each is given its height.
TEST(PixelMapper, AWallsTopAndBottomMapToTheSamePoint) {
  const Cell& cell = Cell::get();
  const auto joints = cell.aligned_joints();
  const PixelMapper mapper = cell.mapper(cell.true_calibration(), joints);
  const Eigen::Isometry3d w_T_c = camera_pose(cell, joints);
  const Eigen::Vector3d foot(w_T_c.translation().x() + 55.0, w_T_c.translation().y() - 45.0,
                             750.51);
  const auto bottom = render::project_world(cell.camera().truth.model, w_T_c, foot);
  const auto top =
      render::project_world(cell.camera().truth.model, w_T_c, foot + Eigen::Vector3d(0, 0, 3.3));
  ASSERT_TRUE(bottom && top);
  EXPECT_GT((*top - *bottom).norm(), 1.0);  // a pixel and more apart
  const auto a = mapper.to_plane(*bottom, 0.51);
  const auto b = mapper.to_plane(*top, 3.81);
  ASSERT_TRUE(a && b);
  EXPECT_NEAR((*a - *b).norm(), 0.0, kMapTolMm);
  // The nadir: the point under the camera.
  const Eigen::Vector3d camera_base = cell.world_T_base().inverse() * w_T_c.translation();
  EXPECT_NEAR((mapper.nadir() - camera_base.head<2>()).norm(), 0.0, 1e-9);
  EXPECT_NEAR(mapper.camera_height_mm(), w_T_c.translation().z() - 750.0, 1e-9);
}

TEST(PixelMapper, RebindSharesTheGridAndFollowsTheJoints) {
  const Cell& cell = Cell::get();
  const PixelMapper a = cell.mapper(cell.true_calibration(), cell.aligned_joints());
  const auto b = a.rebind(&cell.robot(), cell.grab_joints());
  ASSERT_TRUE(b);
  const PixelMapper c = cell.mapper(cell.true_calibration(), cell.grab_joints());
  const auto pb = b->to_plane({100.0, 200.0}, 3.81);
  const auto pc = c.to_plane({100.0, 200.0}, 3.81);
  ASSERT_TRUE(pb && pc);
  EXPECT_NEAR((*pb - *pc).norm(), 0.0, 1e-12);
  const auto pa = a.to_plane({100.0, 200.0}, 3.81);
  EXPECT_GT((*pa - *pb).norm(), 10.0);  // another pose, another place
}

TEST(PixelMapper, ALinkTwoCameraWithoutJointsKeepsSizesButNotTheRobotPose) {
  const Cell& cell = Cell::get();
  const auto m = PixelMapper::create(cell.true_calibration(), &cell.robot(), {});
  ASSERT_TRUE(m) << m.error().message;
  EXPECT_TRUE(m->metric());
  EXPECT_FALSE(m->world());
  EXPECT_THAT(m->describe(), HasSubstr("no joints at exposure"));
  EXPECT_THAT(m->to_base({0, 0}, 0), IsErr(Errc::kNotReady));
  // Distances on the plane are what the posed mapper gives.
  const PixelMapper posed = cell.mapper(cell.true_calibration(), cell.aligned_joints());
  const double d0 = (*m->to_plane({100, 100}, 0) - *m->to_plane({400, 300}, 0)).norm();
  const double d1 = (*posed.to_plane({100, 100}, 0) - *posed.to_plane({400, 300}, 0)).norm();
  EXPECT_NEAR(d0, d1, 1e-9);
}

TEST(PixelMapper, AToolCameraWithoutJointsFallsBackToTheIdealImage) {
  const Cell& cell = Cell::get();
  auto c = cell.true_calibration();
  c.mount_frame = render::MountFrame::kTool;
  const auto m = PixelMapper::create(c, &cell.robot(), {});
  ASSERT_TRUE(m) << m.error().message;
  EXPECT_FALSE(m->metric());
  EXPECT_THAT(m->describe(), HasSubstr("ideal image only"));
  // Ideal pixels: the distortion removed, near the principal point nearly unchanged.
  const auto q = m->to_plane({c.pinhole.cx_px, c.pinhole.cy_px}, 0.0);
  ASSERT_TRUE(q);
  EXPECT_NEAR(q->x(), c.pinhole.cx_px, 2e-3);  // the undistortion grid's bilinear error
  const auto corner = m->to_plane({0.0, 0.0}, 0.0);
  EXPECT_GT((*corner - Eigen::Vector2d(0, 0)).norm(), 0.5);  // barrel distortion undone
}

TEST(PixelMapper, RefusesWrongJointsAndForeignRobots) {
  const Cell& cell = Cell::get();
  EXPECT_THAT(PixelMapper::create(cell.true_calibration(), &cell.robot(), std::vector<double>{0.1}),
              IsErrWith(Errc::kInvalidArgument, "1 joints at exposure"));
  EXPECT_THAT(PixelMapper::create(cell.true_calibration(), &cell.robot(),
                                  std::vector<double>{0.1, NAN, 0.0, 0.0}),
              IsErrWith(Errc::kInvalidArgument, "not finite"));
  auto c = cell.true_calibration();
  c.robot_id = "excalibur";
  EXPECT_THAT(PixelMapper::create(c, &cell.robot(), cell.aligned_joints()),
              IsErrWith(Errc::kInvalidArgument, "refers to robot 'excalibur', not 'ibm7545'"));
}

TEST(PixelMapper, RefusesACameraThatDoesNotLookAtItsPlane) {
  calibration::CameraCalibration c;
  c.camera_id = "up";
  c.robot_id = "scara_picker";
  c.model = calibration::ModelType::kPinhole;
  c.mounting = calibration::Mounting::kFixed;
  c.width_px = 640;
  c.height_px = 480;
  c.pinhole.fx_px = c.pinhole.fy_px = 800;
  c.pinhole.cx_px = 320;
  c.pinhole.cy_px = 240;
  c.extrinsics = Eigen::Isometry3d::Identity();  // z up: looking at the sky
  c.extrinsics.translation() = Eigen::Vector3d(0, 0, 500);
  EXPECT_THAT(PixelMapper::create(c, nullptr, {}),
              IsErrWith(Errc::kOutOfRange, "does not look down at its working plane"));
}

TEST(PixelMapper, WithoutCalibrationPixelsArePlanePoints) {
  const PixelMapper m;
  EXPECT_FALSE(m.metric());
  EXPECT_FALSE(m.world());
  const auto q = m.to_plane({12.5, 40.25}, 3.0);
  ASSERT_TRUE(q);
  EXPECT_EQ(*q, Eigen::Vector2d(12.5, 40.25));
  EXPECT_THAT(m.rebind(nullptr, {}), IsErr(Errc::kNotReady));
}

}  // namespace
}  // namespace cell::vision
