#include "cell/trajectory/joint_trajectory.hpp"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "cell/testing/matchers.hpp"
#include "test_robots.hpp"

namespace cell::trajectory {
namespace {

using ::cell::testing::IsErrWith;
using ::cell::testing::IsOk;
using testing::jv;

constexpr double kTol = 1e-9;

TEST(JointTrajectory, HermiteSegmentReproducesAnyCubicExactly) {
  // q(t) = 1 + 2t - 3t^2 + 0.5t^3 on [0, 2]: knots at 0 and 2 with the cubic's values and slopes.
  auto q = [](double t) { return 1 + 2 * t - 3 * t * t + 0.5 * t * t * t; };
  auto qd = [](double t) { return 2 - 6 * t + 1.5 * t * t; };
  auto qdd = [](double t) { return -6 + 3 * t; };
  auto traj = JointTrajectory::from_knots({{0.0, jv({q(0)}), jv({qd(0)})},
                                           {2.0, jv({q(2)}), jv({qd(2)})}});
  ASSERT_THAT(traj, IsOk());
  for (double t = 0; t < 2.0; t += 0.05) {
    const JointSample s = traj->sample(t);
    EXPECT_NEAR(s.q[0], q(t), kTol) << "t=" << t;
    EXPECT_NEAR(s.qd[0], qd(t), kTol) << "t=" << t;
    EXPECT_NEAR(s.qdd[0], qdd(t), kTol) << "t=" << t;
  }
  EXPECT_NEAR(traj->sample(5.0).q[0], q(2), kTol);  // holds the end
  EXPECT_EQ(traj->sample(5.0).qd[0], 0.0);
}

TEST(JointTrajectory, RejectsMalformedKnotsAndSaysWhich) {
  EXPECT_THAT(JointTrajectory::from_knots({}), IsErrWith(Errc::kInvalidArgument, "at least one"));
  EXPECT_THAT(JointTrajectory::from_knots({{0.0, jv({0, 0}), jv({0, 0})},
                                           {0.0, jv({1, 0}), jv({0, 0})}}),
              IsErrWith(Errc::kInvalidArgument, "knot 1 at 0 s follows 0 s"));
  EXPECT_THAT(JointTrajectory::from_knots({{0.0, jv({0, 0}), jv({0, 0})},
                                           {1.0, jv({1}), jv({0})}}),
              IsErrWith(Errc::kInvalidArgument, "knot 1 has 1 positions"));
  EXPECT_THAT(JointTrajectory::from_knots({{0.0, jv({0, NAN}), jv({0, 0})}}),
              IsErrWith(Errc::kInvalidArgument, "knot 0 joint 1 is not a finite number"));
  EXPECT_THAT(JointTrajectory::from_knots({{0.5, jv({0}), jv({0})}}),
              IsErrWith(Errc::kInvalidArgument, "first knot must be at t = 0"));
}

TEST(CheckLimits, FindsAnOvershootBetweenKnots) {
  testing::Gantry g;
  // Both knots inside [-1000, 1000] but the start velocity makes the cubic bulge past 1000.
  auto traj = JointTrajectory::from_knots({{0.0, jv({900, 0, 0}), jv({2000, 0, 0})},
                                           {1.0, jv({990, 0, 0}), jv({0, 0, 0})}});
  ASSERT_THAT(traj, IsOk());
  const Status s = check_limits(*traj, g.limits);
  EXPECT_THAT(s, IsErrWith(Errc::kOutOfRange, "segment 0"));
  EXPECT_THAT(s, IsErrWith(Errc::kOutOfRange, "joint X at 1"));
  EXPECT_THAT(s, IsErrWith(Errc::kOutOfRange, "beyond its limit [-1000.00 mm, 1000.00 mm]"));
}

// An arm that sagged 0.5 mm past its lower limit (torques off after a fault) may be led back
// in, but a path from there never goes farther out than it started.
TEST(CheckLimits, AStartOutsideALimitMayLeadBackInButNeverFartherOut) {
  testing::Gantry g;
  auto back_in = JointTrajectory::from_knots({{0.0, jv({-1000.5, 0, 0}), jv({0, 0, 0})},
                                              {1.0, jv({-900, 0, 0}), jv({0, 0, 0})}});
  ASSERT_THAT(back_in, IsOk());
  EXPECT_THAT(check_limits(*back_in, g.limits), IsOk());
  auto farther = JointTrajectory::from_knots({{0.0, jv({-1000.5, 0, 0}), jv({0, 0, 0})},
                                              {1.0, jv({-1001, 0, 0}), jv({0, 0, 0})}});
  ASSERT_THAT(farther, IsOk());
  EXPECT_THAT(check_limits(*farther, g.limits),
              IsErrWith(Errc::kOutOfRange, "joint X at -1001.00 mm beyond its limit"));
  // Other joints keep their limits: the widening is per joint.
  auto other = JointTrajectory::from_knots({{0.0, jv({-1000.5, 0, 0}), jv({0, 0, 0})},
                                            {1.0, jv({-900, 1001, 0}), jv({0, 0, 0})}});
  ASSERT_THAT(other, IsOk());
  EXPECT_THAT(check_limits(*other, g.limits), IsErrWith(Errc::kOutOfRange, "joint Y"));
}

TEST(JointTrajectory, TimeScalingKeepsThePathAndDividesAccelerationsBySquare) {
  testing::Gantry g(2500, 1000);
  auto traj = JointTrajectory::from_knots({{0.0, jv({0, 0, 0}), jv({0, 0, 0})},
                                           {1.0, jv({1000, 0, 0}), jv({0, 0, 0})}});
  ASSERT_THAT(traj, IsOk());
  // A rest-to-rest cubic over 1000 mm in 1 s: 6 * 1000 / 1^2 = 6000 mm/s^2 at its ends.
  EXPECT_NEAR(peak_acceleration_ratio(*traj, g.limits), 6.0, 1e-9);
  const JointTrajectory slow = traj->time_scaled(2.0);
  EXPECT_NEAR(slow.duration_s(), 2.0, 1e-12);
  EXPECT_NEAR(peak_acceleration_ratio(slow, g.limits), 1.5, 1e-9);
  for (double u = 0; u <= 1.0; u += 0.1) {
    EXPECT_NEAR(slow.sample(2.0 * u).q[0], traj->sample(u).q[0], 1e-9);
    EXPECT_NEAR(slow.sample(2.0 * u).qd[0], traj->sample(u).qd[0] / 2.0, 1e-9);
  }
}

TEST(CheckLimits, FindsExcessSpeedAndNamesTheJointInDegrees) {
  JointLimits limits;
  limits.names = {"J1"};
  limits.prismatic = {false};
  limits.lower = jv({-3});
  limits.upper = jv({3});
  limits.max_velocity = jv({testing::deg(45)});
  limits.max_acceleration = jv({10});
  auto traj = JointTrajectory::from_knots({{0.0, jv({0}), jv({0})}, {1.0, jv({1}), jv({0})}});
  ASSERT_THAT(traj, IsOk());
  // Peak speed of the cubic is 1.5 rad/s = 85.9 deg/s > 45 deg/s.
  EXPECT_THAT(check_limits(*traj, limits),
              IsErrWith(Errc::kOutOfRange, "joint J1 speed 85.94 deg/s exceeds its limit 45.00 deg/s"));
}

TEST(JointTrajectory, ThenJoinsContinuousTrajectories) {
  auto a = JointTrajectory::from_knots({{0.0, jv({0}), jv({0})}, {1.0, jv({1}), jv({0})}});
  auto b = JointTrajectory::from_knots({{0.0, jv({1}), jv({0})}, {2.0, jv({3}), jv({0})}});
  auto c = JointTrajectory::from_knots({{0.0, jv({5}), jv({0})}, {2.0, jv({3}), jv({0})}});
  ASSERT_TRUE(a && b && c);
  auto ab = a->then(*b);
  ASSERT_THAT(ab, IsOk());
  EXPECT_DOUBLE_EQ(ab->duration_s(), 3.0);
  EXPECT_NEAR(ab->sample(2.0).q[0], 2.0, kTol);
  EXPECT_THAT(a->then(*c), IsErrWith(Errc::kInvalidArgument, "ends at 1 but the next starts at 5"));
}

}  // namespace
}  // namespace cell::trajectory
