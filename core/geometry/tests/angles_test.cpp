#include "cell/geometry/angles.hpp"
#include "cell/testing/tolerances.hpp"

#include <cmath>
#include <limits>

#include <gtest/gtest.h>

namespace cell::geometry {
namespace {

using ::cell::testing::kTolRad;

TEST(Angles, DegreesAndRadiansConvertBothWays) {
  EXPECT_NEAR(deg_to_rad(180.0), kPi, kTolRad);
  EXPECT_NEAR(deg_to_rad(-30.0), -kPi / 6.0, kTolRad);
  EXPECT_NEAR(rad_to_deg(kPi / 2.0), 90.0, 1e-12);
  EXPECT_NEAR(rad_to_deg(deg_to_rad(123.456)), 123.456, 1e-12);
}

TEST(Angles, WrapToPiIsHalfOpenAtMinusPi) {
  EXPECT_DOUBLE_EQ(wrap_to_pi(kPi), kPi);
  EXPECT_DOUBLE_EQ(wrap_to_pi(-kPi), kPi);
  EXPECT_NEAR(wrap_to_pi(3.0 * kPi), kPi, kTolRad);
  EXPECT_NEAR(wrap_to_pi(-3.0 * kPi), kPi, kTolRad);
  EXPECT_NEAR(wrap_to_pi(2.0 * kPi + 0.25), 0.25, kTolRad);
  EXPECT_NEAR(wrap_to_pi(-kPi - 0.25), kPi - 0.25, kTolRad);
  EXPECT_NEAR(wrap_to_pi(deg_to_rad(350.0)), deg_to_rad(-10.0), kTolRad);
  EXPECT_DOUBLE_EQ(wrap_to_pi(0.0), 0.0);
}

TEST(Angles, WrapToPiKeepsNanAsNan) {
  EXPECT_TRUE(std::isnan(wrap_to_pi(std::numeric_limits<double>::quiet_NaN())));
}

// Digest 000 §5 (orientation): the 7545 code folds the IC angle into [-90, 90] by +-180 deg.
TEST(Angles, FoldHalfTurnGivesTheSymmetricGripAngle) {
  EXPECT_NEAR(rad_to_deg(fold_half_turn(deg_to_rad(-148.18))), 31.82, 1e-9);
  EXPECT_NEAR(rad_to_deg(fold_half_turn(deg_to_rad(100.0))), -80.0, 1e-9);
  EXPECT_NEAR(rad_to_deg(fold_half_turn(deg_to_rad(-58.19))), -58.19, 1e-9);
  EXPECT_NEAR(fold_half_turn(kPi / 2.0), kPi / 2.0, kTolRad);
  EXPECT_NEAR(fold_half_turn(-kPi / 2.0), kPi / 2.0, kTolRad);
}

TEST(Angles, NearestEquivalentUnwrapsTowardTheReference) {
  EXPECT_NEAR(nearest_equivalent(deg_to_rad(-170.0), deg_to_rad(175.0)), deg_to_rad(190.0),
              kTolRad);
  EXPECT_NEAR(nearest_equivalent(0.1, 4.0 * kPi), 4.0 * kPi + 0.1, 1e-12);
  EXPECT_NEAR(nearest_equivalent(0.1, 0.0), 0.1, kTolRad);
}

}  // namespace
}  // namespace cell::geometry
