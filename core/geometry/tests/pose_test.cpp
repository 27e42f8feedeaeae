#include "cell/geometry/pose.hpp"

#include <random>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "cell/geometry/angles.hpp"
#include "cell/testing/matchers.hpp"
#include "cell/testing/tolerances.hpp"

namespace cell::geometry {
namespace {

using ::cell::testing::IsErrWith;
using ::cell::testing::IsNearPose;
using ::cell::testing::IsOk;

using ::cell::testing::kTol;

TEST(Rpy, IsRzRyRxAboutFixedAxes) {
  const Rpy rpy{.roll = 0.3, .pitch = -0.4, .yaw = 1.1};
  const Eigen::Matrix3d expected =
      Eigen::AngleAxisd(1.1, Eigen::Vector3d::UnitZ()).toRotationMatrix() *
      Eigen::AngleAxisd(-0.4, Eigen::Vector3d::UnitY()).toRotationMatrix() *
      Eigen::AngleAxisd(0.3, Eigen::Vector3d::UnitX()).toRotationMatrix();
  EXPECT_TRUE(rotation_from_rpy(rpy).isApprox(expected, kTol));
  // Yaw 90 deg alone maps x onto y.
  EXPECT_TRUE((rotation_from_rpy({.yaw = kPi / 2}) * Eigen::Vector3d::UnitX())
                  .isApprox(Eigen::Vector3d::UnitY(), kTol));
}

TEST(Rpy, RoundTripsOverRandomRotations) {
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> angle(-kPi, kPi);
  std::uniform_real_distribution<double> half(-kPi / 2, kPi / 2);
  for (int i = 0; i < 2000; ++i) {
    const Rpy rpy{angle(rng), half(rng), angle(rng)};
    const Rpy back = rpy_from_rotation(rotation_from_rpy(rpy));
    EXPECT_NEAR(back.roll, rpy.roll, 1e-9);
    EXPECT_NEAR(back.pitch, rpy.pitch, 1e-9);
    EXPECT_NEAR(back.yaw, rpy.yaw, 1e-9);
  }
}

TEST(Rpy, GimbalLockPutsTheWholeTurnInYawAndStillReproducesTheRotation) {
  for (const double pitch : {kPi / 2, -kPi / 2}) {
    const Eigen::Matrix3d r = rotation_from_rpy({.roll = 0.7, .pitch = pitch, .yaw = -0.2});
    const Rpy back = rpy_from_rotation(r);
    EXPECT_DOUBLE_EQ(back.roll, 0.0);
    EXPECT_NEAR(back.pitch, pitch, 1e-12);
    EXPECT_TRUE(rotation_from_rpy(back).isApprox(r, 1e-12));
  }
}

// Digest 001 §4.5: Paul's RPY(phi, theta, psi) = Rot(z, phi) Rot(y, theta) Rot(x, psi).
TEST(PaulRpy, IsTheSameMatrixWithRollAndYawNamesSwapped) {
  const Eigen::Matrix3d paul = rotation_from_paul_rpy(0.5, 0.25, -1.0);
  const Eigen::Matrix3d expected =
      Eigen::AngleAxisd(0.5, Eigen::Vector3d::UnitZ()).toRotationMatrix() *
      Eigen::AngleAxisd(0.25, Eigen::Vector3d::UnitY()).toRotationMatrix() *
      Eigen::AngleAxisd(-1.0, Eigen::Vector3d::UnitX()).toRotationMatrix();
  EXPECT_TRUE(paul.isApprox(expected, kTol));
  EXPECT_TRUE(paul.isApprox(rotation_from_rpy({.roll = -1.0, .pitch = 0.25, .yaw = 0.5}), kTol));
}

TEST(VplusTrans, IsZyzEulerAndPitch180PointsTheToolDown) {
  const Eigen::Isometry3d down = vplus_trans(100, 50, 20, 0, kPi, 0);
  EXPECT_TRUE((down.linear() * Eigen::Vector3d::UnitZ()).isApprox(-Eigen::Vector3d::UnitZ(), kTol));
  EXPECT_TRUE(down.translation().isApprox(Eigen::Vector3d(100, 50, 20), kTol));
  const Eigen::Isometry3d t = vplus_trans(0, 0, 0, 0.3, 0.2, 0.1);
  const Eigen::Matrix3d expected =
      Eigen::AngleAxisd(0.3, Eigen::Vector3d::UnitZ()).toRotationMatrix() *
      Eigen::AngleAxisd(0.2, Eigen::Vector3d::UnitY()).toRotationMatrix() *
      Eigen::AngleAxisd(0.1, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  EXPECT_TRUE(t.linear().isApprox(expected, kTol));
}

TEST(Pose, CompositionChainsCancelAndInverseUndoes) {
  const Eigen::Isometry3d base_T_tool = make_pose({100, 200, 300}, {.roll = 0.1, .yaw = 0.5});
  const Eigen::Isometry3d tool_T_cam = make_pose({0, 50, 20}, {.pitch = 0.3});
  const Eigen::Isometry3d base_T_cam = base_T_tool * tool_T_cam;
  const Eigen::Vector3d p_cam(1, 2, 3);
  EXPECT_TRUE((base_T_cam * p_cam).isApprox(base_T_tool * (tool_T_cam * p_cam), kTol));
  EXPECT_THAT(base_T_cam * base_T_cam.inverse(), IsNearPose(Eigen::Isometry3d::Identity(), 1e-12));
}

// Digest 001 §8.2 case 11 uses "+2 cm along a": the offset is expressed in the tool frame.
TEST(Pose, TranslateInFrameMovesAlongTheFramesOwnAxes) {
  const Eigen::Isometry3d base_T_tool = make_pose({10, 0, 0}, {.pitch = kPi / 2});  // z -> +x
  const Eigen::Isometry3d moved = translate_in_frame(base_T_tool, {0, 0, 20});
  EXPECT_TRUE(moved.translation().isApprox(Eigen::Vector3d(30, 0, 0), kTol));
  EXPECT_TRUE(moved.linear().isApprox(base_T_tool.linear(), kTol));
}

TEST(Pose, CheckRigidNamesTheDefect) {
  Eigen::Isometry3d pose = make_pose({1, 2, 3}, {.yaw = 0.2});
  EXPECT_THAT(check_rigid(pose, "base_T_tool"), IsOk());
  pose.linear()(0, 0) = 1.5;
  EXPECT_THAT(check_rigid(pose, "base_T_tool"),
              IsErrWith(Errc::kInvalidArgument, "base_T_tool: rotation is not orthonormal"));
  Eigen::Isometry3d nan_pose = Eigen::Isometry3d::Identity();
  nan_pose.translation().x() = std::numeric_limits<double>::quiet_NaN();
  EXPECT_THAT(check_rigid(nan_pose, "target"), IsErrWith(Errc::kInvalidArgument, "non-finite"));
  Eigen::Isometry3d mirror = Eigen::Isometry3d::Identity();
  mirror.linear()(2, 2) = -1.0;
  EXPECT_THAT(check_rigid(mirror, "target"), IsErrWith(Errc::kInvalidArgument, "reflection"));
}

TEST(Pose, RotationDistanceIsAccurateForTinyAngles) {
  const Eigen::Matrix3d a = rotation_from_rpy({.roll = 0.2, .pitch = 0.1, .yaw = 0.3});
  const Eigen::Matrix3d b =
      a * Eigen::AngleAxisd(1e-10, Eigen::Vector3d::UnitX()).toRotationMatrix();
  EXPECT_NEAR(rotation_distance(a, b), 1e-10, 1e-15);
  EXPECT_NEAR(
      rotation_distance(a, a * Eigen::AngleAxisd(2.0, Eigen::Vector3d::UnitY()).toRotationMatrix()),
      2.0, 1e-12);
}

}  // namespace
}  // namespace cell::geometry
