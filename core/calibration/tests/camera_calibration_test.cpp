#include "cell/calibration/camera_calibration.hpp"

#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <numbers>

#include <fmt/format.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "cell/geometry/angles.hpp"
#include "cell/geometry/pose.hpp"
#include "cell/testing/env.hpp"
#include "cell/testing/matchers.hpp"

namespace cell::calibration {
namespace {

using ::cell::testing::IsErrWith;
using ::cell::testing::IsOk;
using ::testing::HasSubstr;

using geometry::kDeg;

render::CameraDescription camera(const std::string& name) {
  auto c = render::load_camera(cell::testing::source_dir() + "/config/cameras/" + name);
  EXPECT_THAT(c, IsOk());
  return *c;
}

CameraCalibration sample_pinhole() {
  CameraCalibration c;
  c.camera_id = "belt_cam";
  c.version = "2026-12-01T10:00:00Z#2";
  c.created_utc = "2026-12-01T10:00:00Z";
  c.source = "intrinsics: 20 views";
  c.model = ModelType::kPinhole;
  c.mounting = Mounting::kFixed;
  c.robot_id = "scara_picker";
  c.width_px = 1024;
  c.height_px = 1024;
  c.pinhole = {2006.123456789, 2004.1, 515.2, 508.9, {-0.05, 0.02, 0.0003, 0.0002, 0.001}};
  c.extrinsics = geometry::make_pose(Eigen::Vector3d(350.1, 100.2, 800.3),
                                     geometry::Rpy{179.2 * kDeg, 0.6 * kDeg, -89.0 * kDeg});
  c.working_plane_z_mm = -200.0;
  c.quality = {0.21, 0.25, 0.08, 20};
  return c;
}

std::string temp_path(const std::string& name) {
  return fmt::format("/tmp/cell-calib-test-{}-{}", ::getpid(), name);
}

TEST(CameraCalibrationFile, PinholeRoundTripsToTheLastBit) {
  const CameraCalibration c = sample_pinhole();
  const std::string path = temp_path("pinhole.yaml");
  ASSERT_THAT(save_camera_calibration(c, path), IsOk());
  auto back = load_camera_calibration(path);
  ASSERT_THAT(back, IsOk());
  EXPECT_EQ(back->camera_id, c.camera_id);
  EXPECT_EQ(back->version, c.version);
  EXPECT_EQ(back->source, c.source);
  EXPECT_EQ(back->robot_id, "scara_picker");
  EXPECT_EQ(back->mounting, Mounting::kFixed);
  EXPECT_EQ(back->pinhole.fx_px, c.pinhole.fx_px);
  EXPECT_EQ(back->pinhole.distortion.k3, 0.001);
  // The pose goes through rpy in degrees: exact to rounding.
  EXPECT_TRUE(back->extrinsics.isApprox(c.extrinsics, 1e-13));
  EXPECT_EQ(back->quality.sample_count, 20U);
  EXPECT_EQ(back->quality.holdout_rms_px, 0.25);
  std::filesystem::remove(path);
}

TEST(CameraCalibrationFile, PlanarRoundTripsWithAnglesInDegreesInTheFile) {
  CameraCalibration c;
  c.camera_id = "ibm7545_eye";
  c.model = ModelType::kPlanar7545;
  c.mounting = Mounting::kEyeInHand;
  c.mount_frame = render::MountFrame::kLink2;
  c.robot_id = "ibm7545";
  c.width_px = 512;
  c.height_px = 484;
  c.working_plane_z_mm = -231.51;
  // Digest 000 §4: c_x = 3.56, c_y = 3.48 px/mm, Ref_Point (3, 457), angl_err = 1.8 deg.
  c.planar = {3.56, 3.48, 3.0, 457.0, 255.0, 241.0, 118.6, 0.3, 1.8 * kDeg, 400.0, 250.0, 420.0};
  const std::string text = format_camera_calibration(c);
  EXPECT_THAT(text, HasSubstr("angl_err_deg: 1.8"));
  EXPECT_THAT(text, HasSubstr("mount_frame: link2"));
  auto back = parse_camera_calibration(text, "<text>");
  ASSERT_THAT(back, IsOk());
  EXPECT_EQ(back->model, ModelType::kPlanar7545);
  EXPECT_EQ(back->mount_frame, render::MountFrame::kLink2);
  EXPECT_NEAR(back->planar.angl_err_rad, 1.8 * kDeg, 1e-15);
  EXPECT_EQ(back->planar.ref_v_px, 457.0);
  EXPECT_EQ(back->planar.camera_height_mm, 420.0);
}

TEST(CameraCalibrationFile, ErrorsNameTheLineAndTheKeyAndAreAllReported) {
  const std::string text =
      "camera_id: c\nmodel: fisheye\nmounting: fixed\nrobot_id: r\nwidth_px: 10\n"
      "height_px: 10\nworking_plane_z_mm: 0\ncolour: red\n";
  auto c = parse_camera_calibration(text, "cal.yaml");
  ASSERT_FALSE(c);
  EXPECT_EQ(c.error().code, Errc::kConfig);
  EXPECT_THAT(c.error().message, HasSubstr("cal.yaml:2:"));
  EXPECT_THAT(c.error().message, HasSubstr("pinhole or planar_7545, got 'fisheye'"));
  EXPECT_THAT(c.error().message, HasSubstr("colour"));
}

TEST(CameraCalibrationFile, AMissingFileSaysWhich) {
  EXPECT_THAT(load_camera_calibration("/nonexistent/cal.yaml"),
              IsErrWith(Errc::kConfig, "/nonexistent/cal.yaml"));
}

TEST(CameraCalibration, ValidateNamesTheBadField) {
  CameraCalibration c = sample_pinhole();
  c.pinhole.fx_px = -1;
  EXPECT_THAT(c.validate(), IsErrWith(Errc::kInvalidArgument, "fx"));
  c = sample_pinhole();
  c.extrinsics.matrix()(0, 0) = 2.0;
  EXPECT_THAT(c.validate(), IsErrWith(Errc::kInvalidArgument, "rigid"));
  c = sample_pinhole();
  c.robot_id.clear();
  EXPECT_THAT(c.validate(), IsErrWith(Errc::kInvalidArgument, "robot_id"));
  EXPECT_THAT(save_camera_calibration(c, temp_path("bad.yaml")),
              IsErrWith(Errc::kInvalidArgument, "robot_id"));
  EXPECT_FALSE(std::filesystem::exists(temp_path("bad.yaml")));
}

TEST(CameraCalibrationIdl, RoundTripsAndRefusesMalformedSamples) {
  const CameraCalibration c = sample_pinhole();
  IdlHolder holder;
  cell_calibration_CameraCalibration m = to_idl(c, holder, 123);
  EXPECT_EQ(m.header.stamp_ns, 123);
  auto back = from_idl(m);
  ASSERT_THAT(back, IsOk());
  EXPECT_EQ(back->pinhole.cy_px, 508.9);
  EXPECT_EQ(back->pinhole.distortion.p2, 0.0002);
  EXPECT_TRUE(back->extrinsics.isApprox(c.extrinsics, 1e-12));
  EXPECT_EQ(back->version, c.version);

  cell_calibration_CameraCalibration bad = m;
  bad.distortion._length = 3;
  EXPECT_THAT(from_idl(bad), IsErrWith(Errc::kInvalidArgument, "3 coefficients"));
  bad = m;
  std::memset(&bad.model, 0x07, 1);  // a value no enumerator has, as a malformed sample may
  EXPECT_THAT(from_idl(bad), IsErrWith(Errc::kInvalidArgument, "unknown model type"));
  bad = m;
  bad.mounting = cell_calibration_MOUNT_EYE_IN_HAND;
  EXPECT_THAT(from_idl(bad), IsErrWith(Errc::kInvalidArgument, "mount_frame"));
  bad = m;
  bad.extrinsics.orientation.w = NAN;
  EXPECT_THAT(from_idl(bad), IsErrWith(Errc::kInvalidArgument, "extrinsics"));
}

// The belt camera's nominal: config/cameras/belt_cam.yaml's world_T_camera expressed in the
// picker's base (config/sim-world.yaml: the picker's base at (1000, 0, 960) mm).
TEST(NominalCalibration, FixedCameraIsExpressedInTheRobotsBase) {
  const render::CameraDescription belt = camera("belt_cam.yaml");
  const Eigen::Isometry3d world_T_base(Eigen::Translation3d(1000.0, 0.0, 960.0));
  auto c = nominal_calibration(belt, "scara_picker", world_T_base, -200.0);
  ASSERT_THAT(c, IsOk());
  EXPECT_EQ(c->mounting, Mounting::kFixed);
  EXPECT_EQ(c->robot_id, "scara_picker");
  EXPECT_EQ(c->pinhole.fx_px, 2000.0);
  EXPECT_NEAR(c->extrinsics.translation().x(), 350.0, 1e-9);
  EXPECT_NEAR(c->extrinsics.translation().z(), 800.0, 1e-9);
  EXPECT_THAT(nominal_calibration(belt, "", world_T_base, 0.0),
              IsErrWith(Errc::kInvalidArgument, "needs the robot"));
}

TEST(NominalCalibration, EyeInHandKeepsItsMountFrame) {
  const render::CameraDescription eye = camera("ibm7545_eye.yaml");
  auto c = nominal_calibration(eye, "", Eigen::Isometry3d::Identity(), -231.51);
  ASSERT_THAT(c, IsOk());
  EXPECT_EQ(c->mounting, Mounting::kEyeInHand);
  EXPECT_EQ(c->mount_frame, render::MountFrame::kLink2);
  EXPECT_EQ(c->robot_id, "ibm7545");
  EXPECT_EQ(c->pinhole.fy_px, 1461.6);
  EXPECT_NEAR(c->extrinsics.translation().z(), 188.49, 1e-9);
}

}  // namespace
}  // namespace cell::calibration
