#include "cell/geometry/pose2.hpp"

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

using ::cell::testing::kTolMm;
using ::cell::testing::kTolRad;

// Digest 002 §6.2 T1: part.loc = to.cam[1] : vis.loc : grip.part.
TEST(Pose2, VplusCompoundTransformReproducesDigestT1) {
  const Pose2 to_cam = Pose2::from_deg(400, -100, 90);
  const Pose2 vis_loc = Pose2::from_deg(50, 20, 30);
  const Pose2 grip_part = Pose2::from_deg(10, 0, 0);
  const Pose2 part_loc = to_cam * vis_loc * grip_part;
  EXPECT_NEAR(part_loc.x, 375.000, 5e-4);
  EXPECT_NEAR(part_loc.y, -41.340, 5e-4);
  EXPECT_NEAR(rad_to_deg(part_loc.rz), 120.0, 1e-9);
  // Exact values: -41.340 is -50 + 10 sin(120 deg).
  EXPECT_NEAR(part_loc.x, 375.0, kTolMm);
  EXPECT_NEAR(part_loc.y, -50.0 + 10.0 * std::sin(deg_to_rad(120.0)), kTolMm);
}

TEST(Pose2, CompositionIsAssociativeAndMatches3d) {
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<double> mm(-500, 500);
  std::uniform_real_distribution<double> rad(-kPi, kPi);
  for (int i = 0; i < 500; ++i) {
    const Pose2 a{mm(rng), mm(rng), rad(rng)};
    const Pose2 b{mm(rng), mm(rng), rad(rng)};
    const Pose2 c{mm(rng), mm(rng), rad(rng)};
    const Pose2 left = (a * b) * c;
    const Pose2 right = a * (b * c);
    EXPECT_NEAR(left.x, right.x, kTolMm);
    EXPECT_NEAR(left.y, right.y, kTolMm);
    EXPECT_NEAR(wrap_to_pi(left.rz - right.rz), 0.0, kTolRad);
    EXPECT_THAT(to_3d(a * b), IsNearPose(to_3d(a) * to_3d(b), kTolMm));
  }
}

TEST(Pose2, InverseUndoesComposition) {
  const Pose2 a = Pose2::from_deg(120, -35, 170);
  const Pose2 id = inverse(a) * a;
  EXPECT_NEAR(id.x, 0.0, kTolMm);
  EXPECT_NEAR(id.y, 0.0, kTolMm);
  EXPECT_NEAR(id.rz, 0.0, kTolRad);
  const Eigen::Vector2d p(3, 4);
  EXPECT_TRUE(transform_point(inverse(a), transform_point(a, p)).isApprox(p, 1e-12));
}

TEST(Pose2, TransformPointMatchesComposeWithAPureTranslation) {
  const Pose2 a = Pose2::from_deg(400, -100, 90);
  const Eigen::Vector2d p = transform_point(a, {50, 20});
  EXPECT_NEAR(p.x(), 380.0, kTolMm);
  EXPECT_NEAR(p.y(), -50.0, kTolMm);
}

TEST(Pose2, From3dDropsHeightAndRejectsTilt) {
  const Pose2 a = Pose2::from_deg(1, 2, -45);
  const auto back = from_3d(to_3d(a, 77.0));
  ASSERT_THAT(back, IsOk());
  EXPECT_NEAR(back->x, 1.0, kTolMm);
  EXPECT_NEAR(back->y, 2.0, kTolMm);
  EXPECT_NEAR(back->rz, a.rz, kTolRad);
  Eigen::Isometry3d tilted = to_3d(a);
  tilted.rotate(Eigen::AngleAxisd(deg_to_rad(2.0), Eigen::Vector3d::UnitX()));
  EXPECT_THAT(from_3d(tilted), IsErrWith(Errc::kInvalidArgument, "tilted 2.000000 deg"));
}

}  // namespace
}  // namespace cell::geometry
