#include "cell/geometry/rapt.hpp"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "cell/geometry/angles.hpp"
#include "cell/geometry/pose.hpp"
#include "cell/testing/matchers.hpp"
#include "cell/testing/tolerances.hpp"

namespace cell::geometry {
namespace {

using ::cell::testing::IsErrWith;
using ::cell::testing::IsNearPose;
using ::cell::testing::IsOk;

using ::cell::testing::kTol;

// A body written the thesis's way (digest 003 §1.4): rows 1-3 are the body's X, Y, Z axes in the
// world, row 4 (a41, a42, a43) is its position. This body is turned 90 deg about the world Z and
// sits at (10, 20, 30): its X axis points along world +Y, its Y axis along world -X.
Eigen::Matrix4d thesis_body() {
  Eigen::Matrix4d m;
  m << 0, 1, 0, 0,  //
      -1, 0, 0, 0,  //
      0, 0, 1, 0,   //
      10, 20, 30, 1;
  return m;
}

TEST(Rapt, RowVectorMatrixIsTheTransposeOfTheColumnVectorPose) {
  const auto world_T_body = from_row_major_rapt(thesis_body());
  ASSERT_THAT(world_T_body, IsOk());
  EXPECT_TRUE(world_T_body->translation().isApprox(Eigen::Vector3d(10, 20, 30), kTol));
  EXPECT_TRUE(
      (world_T_body->linear() * Eigen::Vector3d::UnitX()).isApprox(Eigen::Vector3d::UnitY(), kTol));
  EXPECT_TRUE(to_row_major_rapt(*world_T_body).isApprox(thesis_body(), kTol));
}

// Eq. 5.3: a homogeneous row vector maps as P_w = P_c ** C.
TEST(Rapt, PointsMapAsRowVectorTimesMatrix) {
  const Eigen::RowVector4d p_local(1, 0, 0, 1);
  const Eigen::RowVector4d p_world = p_local * thesis_body();
  EXPECT_TRUE(p_world.isApprox(Eigen::RowVector4d(10, 21, 30, 1), kTol));
  const Eigen::Isometry3d world_T_body = *from_row_major_rapt(thesis_body());
  EXPECT_TRUE(
      (world_T_body * Eigen::Vector3d(1, 0, 0)).isApprox(p_world.head<3>().transpose(), kTol));
  // Eq. 5.4: P_c = P_w ** C^-1.
  EXPECT_TRUE((p_world * thesis_body().inverse()).isApprox(p_local, kTol));
}

// §1.4: a feature's world pose is f ** p; in column-vector form world_T_body * body_T_feature.
TEST(Rapt, FeatureTimesBodyReversesIntoColumnVectorComposition) {
  const Eigen::Isometry3d body_T_feature = make_pose({5, 0, 0}, {.pitch = kPi / 2});
  const Eigen::Matrix4d f = to_row_major_rapt(body_T_feature);
  const Eigen::Matrix4d p = thesis_body();
  const auto world_T_feature = from_row_major_rapt(f * p);
  ASSERT_THAT(world_T_feature, IsOk());
  EXPECT_THAT(*world_T_feature, IsNearPose(*from_row_major_rapt(p) * body_T_feature, 1e-12));
}

// Digest 003 port pitfall: PV = FM ** PN becomes world_T_PV = world_T_PN * FM (FM in the body's
// nominal frame). A 2 mm shift along the body's own X moves the body along world +Y here.
TEST(Rapt, ModifyingFactorActsInTheNominalBodyFrame) {
  const Eigen::Matrix4d fm = to_row_major_rapt(make_pose({2, 0, 0}, {}));
  const Eigen::Matrix4d pv = fm * thesis_body();
  const Eigen::Isometry3d world_T_pv = *from_row_major_rapt(pv);
  EXPECT_TRUE(world_T_pv.translation().isApprox(Eigen::Vector3d(10, 22, 30), kTol));
}

// Eq. 3.2: M is the rotation about Y that brings +X to -X; applying it twice is the identity.
TEST(Rapt, AgainstMatrixOfEquation32) {
  const Eigen::Matrix4d m = to_row_major_rapt(make_pose({0, 0, 0}, {.pitch = kPi}));
  EXPECT_TRUE((Eigen::RowVector4d(1, 0, 0, 0) * m).isApprox(Eigen::RowVector4d(-1, 0, 0, 0), kTol));
  EXPECT_TRUE((m * m).isApprox(Eigen::Matrix4d::Identity(), kTol));
}

TEST(Rapt, RejectsAColumnVectorMatrixAndSaysWhy) {
  const Eigen::Matrix4d column_form = thesis_body().transpose();
  EXPECT_THAT(from_row_major_rapt(column_form), IsErrWith(Errc::kInvalidArgument, "a14 must be 0"));
  Eigen::Matrix4d scaled = thesis_body();
  scaled(3, 3) = 2.0;
  EXPECT_THAT(from_row_major_rapt(scaled), IsErrWith(Errc::kInvalidArgument, "a44 must be 1"));
  Eigen::Matrix4d sheared = thesis_body();
  sheared(0, 1) = 0.5;
  EXPECT_THAT(from_row_major_rapt(sheared), IsErrWith(Errc::kInvalidArgument, "not a rotation"));
}

}  // namespace
}  // namespace cell::geometry
