#include "cell/render/camera_file.hpp"

#include <cmath>
#include <numbers>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "cell/geometry/angles.hpp"
#include "cell/kinematics/robot_config.hpp"
#include "cell/render/mount.hpp"
#include "cell/testing/env.hpp"
#include "cell/testing/matchers.hpp"

namespace cell::render {
namespace {

using ::cell::testing::IsErrWith;
using ::testing::HasSubstr;

using geometry::kDeg;

std::string shipped(const std::string& name) {
  return cell::testing::source_dir() + "/config/cameras/" + name;
}

kinematics::RobotModel robot(const std::string& id) {
  return kinematics::load_robot(cell::testing::source_dir() + "/config/robots/" + id + ".yaml")
      .value();
}

/// The SCARA's link-2 frame at joints (J1, J2): on the R axis at the flange height (Z = 0),
/// x along link 2 (digest 000 §5: link_1 400 mm, link_2 250 mm).
Eigen::Isometry3d base_T_link2(double j1, double j2) {
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  pose.translation() = Eigen::Vector3d(400.0 * std::cos(j1) + 250.0 * std::cos(j1 + j2),
                                       400.0 * std::sin(j1) + 250.0 * std::sin(j1 + j2), 0.0);
  pose.linear() = Eigen::AngleAxisd(j1 + j2, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  return pose;
}

/// Where pixel `px` of `setup` sees the table top (z = 750 mm).
Eigen::Vector2d on_table(const CameraSetup& setup, const Eigen::Isometry3d& world_T_camera,
                         const Eigen::Vector2d& px) {
  const Eigen::Vector3d ray = world_T_camera.linear() * setup.model.unproject(px).value();
  const Eigen::Vector3d o = world_T_camera.translation();
  const double t = (750.0 - o.z()) / ray.z();
  return (o + t * ray).head<2>();
}

TEST(CameraFile, TheSeventyFiveFortyFiveCameraSeesTheThesisWindow) {
  const auto camera = load_camera(shipped("ibm7545_eye.yaml"));
  ASSERT_TRUE(camera) << camera.error().message;
  EXPECT_EQ(camera->id, "ibm7545_eye");
  EXPECT_EQ(camera->mount, MountKind::kEyeInHand);
  EXPECT_EQ(camera->robot.robot_id, "ibm7545");
  EXPECT_EQ(camera->robot.frame, MountFrame::kLink2);
  EXPECT_EQ(camera->lights_robot_id, "ibm7545");
  EXPECT_EQ(camera->nominal.model.width_px(), 512);
  EXPECT_EQ(camera->nominal.model.height_px(), 484);
  // Digest 000 §9.2 case 9: at the grab pose (45 deg, 105 deg) the centre pixel (255, 241)
  // sees (134.39, 501.25) mm, 420 mm below the camera.
  const Eigen::Isometry3d link2 = base_T_link2(45.0 * kDeg, 105.0 * kDeg);
  const Eigen::Isometry3d nominal = camera->world_T_camera(camera->nominal, link2);
  const Eigen::Vector2d centre = on_table(camera->nominal, nominal, {255.0, 241.0});
  EXPECT_NEAR(centre.x(), 134.39, 0.1);
  EXPECT_NEAR(centre.y(), 501.25, 0.1);
  EXPECT_NEAR(nominal.translation().z() - 750.0, 420.0, 1e-9);
  // 3.56 px/mm along i, 3.48 px/mm along j (digest 000 §4), i parallel to link 2 (150 deg).
  const Eigen::Vector2d di = on_table(camera->nominal, nominal, {255.0 + 35.6, 241.0}) - centre;
  const Eigen::Vector2d dj = on_table(camera->nominal, nominal, {255.0, 241.0 + 34.8}) - centre;
  EXPECT_NEAR(di.norm(), 10.0, 1e-6);
  EXPECT_NEAR(dj.norm(), 10.0, 1e-6);
  EXPECT_NEAR(std::abs(std::cos(std::atan2(di.y(), di.x()) - 150.0 * kDeg)), 1.0, 1e-9);
  // The Ref_Point corner (3, 457) is the image corner nearest the tool (digest 000 §4).
  const Eigen::Vector2d tool = link2.translation().head<2>();
  double nearest = 1e9;
  Eigen::Vector2d nearest_corner;
  for (const Eigen::Vector2d& corner : {Eigen::Vector2d(3, 457), Eigen::Vector2d(508, 457),
                                       Eigen::Vector2d(3, 3), Eigen::Vector2d(508, 3)}) {
    const double d = (on_table(camera->nominal, nominal, corner) - tool).norm();
    if (d < nearest) {
      nearest = d;
      nearest_corner = corner;
    }
  }
  EXPECT_EQ(nearest_corner, Eigen::Vector2d(3, 457));
  // The truth differs by a few mm and a degree or two: calibration has work to do.
  const Eigen::Isometry3d truth = camera->world_T_camera(camera->truth, link2);
  const double offset_mm = (truth.translation() - nominal.translation()).norm();
  const double turn_deg =
      Eigen::AngleAxisd(nominal.linear().transpose() * truth.linear()).angle() / kDeg;
  EXPECT_GT(offset_mm, 2.0);
  EXPECT_LT(offset_mm, 10.0);
  EXPECT_GT(turn_deg, 1.0);
  EXPECT_LT(turn_deg, 3.0);
  EXPECT_FALSE(camera->truth.model.distortion().is_zero());
  EXPECT_TRUE(camera->nominal.model.distortion().is_zero());
}

TEST(CameraFile, TheBeltCameraSeesTheWholeBeltAtHalfAMillimetrePerPixel) {
  const auto camera = load_camera(shipped("belt_cam.yaml"));
  ASSERT_TRUE(camera) << camera.error().message;
  EXPECT_EQ(camera->mount, MountKind::kFixed);
  EXPECT_EQ(camera->nominal.model.width_px(), 1024);
  EXPECT_DOUBLE_EQ(camera->exposure_s, 0.0002);
  EXPECT_TRUE(camera->lights_robot_id.empty());
  const Eigen::Isometry3d pose = camera->world_T_camera(camera->nominal, {});
  const Eigen::Vector3d ray = pose.linear() * camera->nominal.model.unproject({511.5, 511.5}).value();
  const Eigen::Vector3d hit = pose.translation() + (760.0 - pose.translation().z()) / ray.z() * ray;
  EXPECT_NEAR(hit.x(), 1350.0, 1e-9);
  EXPECT_NEAR(hit.y(), 100.0, 1e-9);
  // Image u runs along the belt's travel (world -y): blur along the rows.
  EXPECT_NEAR((pose.linear().col(0) - Eigen::Vector3d(0, -1, 0)).norm(), 0.0, 1e-12);
  const Eigen::Isometry3d truth = camera->world_T_camera(camera->truth, {});
  const double offset_mm = (truth.translation() - pose.translation()).norm();
  EXPECT_GT(offset_mm, 2.0);
  EXPECT_LT(offset_mm, 10.0);
}

TEST(CameraMount, TheLinkTwoFrameTurnsWithTheArmNotWithRollOrZ) {
  const kinematics::RobotModel ibm = robot("ibm7545");
  kinematics::JointVector q(4);
  const Eigen::Isometry3d expected = base_T_link2(45.0 * kDeg, 105.0 * kDeg);
  for (const double z : {0.0, 120.0}) {
    for (const double r : {0.0, 1.1, -2.0}) {
      q << 45.0 * kDeg, 105.0 * kDeg, z, r;
      const auto link2 = base_T_mount(ibm, MountFrame::kLink2, q);
      ASSERT_TRUE(link2) << link2.error().message;
      EXPECT_THAT(*link2, cell::testing::IsNearPose(expected, 1e-9));
    }
  }
  q << 45.0 * kDeg, 105.0 * kDeg, 120.0, 1.1;
  const auto tool = base_T_mount(ibm, MountFrame::kTool, q);
  ASSERT_TRUE(tool);
  EXPECT_THAT(*tool, cell::testing::IsNearPose(ibm.forward(q).value(), 1e-12));
  EXPECT_THAT(base_T_mount(ibm, MountFrame::kLink2, kinematics::JointVector(2)),
              cell::testing::IsErr(Errc::kInvalidArgument));
  const kinematics::RobotModel excalibur = robot("excalibur");
  EXPECT_THAT(base_T_mount(excalibur, MountFrame::kLink2, kinematics::JointVector::Zero(6)),
              IsErrWith(Errc::kInvalidArgument, "only a SCARA has a link-2 camera mount"));
}

TEST(CameraFile, ErrorsNameTheFileTheLineAndTheKey) {
  const std::string text =
      "id: c\nwidth_px: 512\nheight_px: 484\nmount: {kind: fixd}\n"
      "nominal: {fx_px: -3, fy_px: 1, cx_px: 0, cy_px: 0,\n"
      "          world_T_camera: {xyz_mm: [0, 0, 0], rpy_deg: [0, 0, 0]}}\n"
      "truth: {fx_px: 1, fy_px: 1, cx_px: 0, cy_px: 0}\n"
      "lighting: {ambient: -1}\nlense: 3\n";
  const auto doc = config::load_string(text, "cameras/c.yaml");
  ASSERT_TRUE(doc);
  const auto camera = parse_camera(*doc);
  ASSERT_FALSE(camera);
  EXPECT_EQ(camera.error().code, Errc::kConfig);
  const std::string& m = camera.error().message;
  EXPECT_THAT(m, HasSubstr("cameras/c.yaml:4"));
  EXPECT_THAT(m, HasSubstr("must be fixed or eye_in_hand, got 'fixd'"));
  EXPECT_THAT(m, HasSubstr("fx = -3"));
  EXPECT_THAT(m, HasSubstr("truth.world_T_camera"));
  EXPECT_THAT(m, HasSubstr("ambient = -1"));
  EXPECT_THAT(m, HasSubstr("lense"));
  EXPECT_THAT(load_camera("/nonexistent/cam.yaml"), IsErrWith(Errc::kConfig, "cannot open"));
}

}  // namespace
}  // namespace cell::render
