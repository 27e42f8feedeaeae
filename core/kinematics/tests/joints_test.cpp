#include "cell/kinematics/joints.hpp"

#include <cmath>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "cell/geometry/angles.hpp"
#include "cell/testing/matchers.hpp"

namespace cell::kinematics {
namespace {

using ::cell::testing::IsErrWith;
using ::cell::testing::IsOk;
using geometry::deg_to_rad;

std::vector<JointSpec> two_joints() {
  const JointSpec j2{.name = "j2",
                     .type = JointType::kRevolute,
                     .lower = 0.0,
                     .upper = deg_to_rad(135.0),
                     .max_speed = deg_to_rad(50.0),
                     .max_accel = deg_to_rad(200.0),
                     .counts_per_unit = 444.4444 * 180.0 / geometry::kPi};
  const JointSpec z{.name = "z",
                    .type = JointType::kPrismatic,
                    .lower = 0.0,
                    .upper = 250.0,
                    .max_speed = 100.0,
                    .max_accel = 400.0,
                    .counts_per_unit = 380.96};
  return {j2, z};
}

JointVector vec(std::initializer_list<double> values) {
  JointVector q(static_cast<Eigen::Index>(values.size()));
  Eigen::Index i = 0;
  for (const double v : values) {
    q(i++) = v;
  }
  return q;
}

TEST(CheckLimits, NamesTheJointItsValueAndLimitsInDisplayUnits) {
  const auto joints = two_joints();
  EXPECT_THAT(check_limits(joints, vec({deg_to_rad(100.0), 10.0})), IsOk());
  EXPECT_THAT(check_limits(joints, vec({deg_to_rad(137.2), 10.0})),
              IsErrWith(Errc::kOutOfRange,
                        "joint 'j2' = 137.200 deg is outside its limits [0.000, 135.000] deg"));
  EXPECT_THAT(check_limits(joints, vec({0.5, 251.0})),
              IsErrWith(Errc::kOutOfRange,
                        "joint 'z' = 251.000 mm is outside its limits [0.000, 250.000] mm"));
}

TEST(CheckLimits, AcceptsRoundingNoiseOnALimit) {
  const auto joints = two_joints();
  EXPECT_THAT(check_limits(joints, vec({-1e-12, 250.0 + 1e-12})), IsOk());
}

TEST(CheckLimits, RejectsWrongSizeAndNonFiniteValues) {
  const auto joints = two_joints();
  EXPECT_THAT(check_limits(joints, vec({0.1})),
              IsErrWith(Errc::kInvalidArgument, "joint vector has 1 entries, robot has 2 joints"));
  EXPECT_THAT(check_limits(joints, vec({0.1, std::nan("")})),
              IsErrWith(Errc::kInvalidArgument, "joint 'z' is not finite"));
}

TEST(Counts, RoundTripAndRoundToNearest) {
  const auto joints = two_joints();
  CountVector c(2);
  c << 46662, 86745;
  const auto q = from_counts(joints, c);
  ASSERT_THAT(q, IsOk());
  EXPECT_NEAR((*q)(1), 86745 / 380.96, 1e-12);
  const auto back = to_counts(joints, *q);
  ASSERT_THAT(back, IsOk());
  EXPECT_EQ(*back, c);
  const auto rounded = to_counts(joints, vec({0.0, 227.7}));
  ASSERT_THAT(rounded, IsOk());
  EXPECT_EQ((*rounded)(1), 86745);  // 86744.6
}

TEST(Counts, JointWithoutEncoderIsAnError) {
  auto joints = two_joints();
  joints[1].counts_per_unit = 0.0;
  EXPECT_THAT(to_counts(joints, vec({0.0, 1.0})),
              IsErrWith(Errc::kInvalidArgument, "joint 'z' has no encoder scale (counts_per_mm)"));
  CountVector c(2);
  c << 1, 1;
  EXPECT_THAT(from_counts(joints, c), IsErrWith(Errc::kInvalidArgument, "joint 'z'"));
}

TEST(FitRevolute, PicksTheInRangeEquivalentClosestToTheReference) {
  JointSpec r{"r", JointType::kRevolute, deg_to_rad(-360.0), deg_to_rad(360.0), 1.0};
  EXPECT_NEAR(fit_revolute(r, deg_to_rad(-60.0), deg_to_rad(290.0)), deg_to_rad(300.0), 1e-12);
  EXPECT_NEAR(fit_revolute(r, deg_to_rad(-60.0), deg_to_rad(-50.0)), deg_to_rad(-60.0), 1e-12);
  JointSpec j1{"j1", JointType::kRevolute, 0.0, deg_to_rad(200.0), 1.0};
  EXPECT_NEAR(fit_revolute(j1, deg_to_rad(-10.0), deg_to_rad(-10.0)), deg_to_rad(-10.0), 1e-12)
      << "no equivalent of -10 deg lies in [0, 200]: the nearest one is returned";
  EXPECT_NEAR(fit_revolute(j1, deg_to_rad(-170.0), deg_to_rad(-170.0)), deg_to_rad(190.0), 1e-12);
}

TEST(IkSolutions, NearestIsTheFastestMoveAtTheSpeedLimits) {
  const auto joints = two_joints();  // 50 deg/s and 100 mm/s
  IkSolutions all;
  IkSolution a;
  a.q = vec({deg_to_rad(10.0), 100.0});  // 0.2 s of J2, 1.0 s of Z
  a.branch = "a";
  IkSolution b;
  b.q = vec({deg_to_rad(60.0), 10.0});  // 1.2 s of J2, 0.1 s of Z
  b.branch = "b";
  IkSolution c = a;
  c.branch = "c";
  c.violated_joint = 0;
  all.push_back(c);
  all.push_back(a);
  all.push_back(b);
  const IkSolution* best = all.nearest(joints, vec({0.0, 0.0}));
  ASSERT_NE(best, nullptr);
  EXPECT_EQ(best->branch, "a");  // c is as close but breaks a limit
  EXPECT_NEAR(min_move_time(joints, vec({0.0, 0.0}), b.q), 1.2, 1e-12);
  EXPECT_EQ(all.find("b"), &all[2]);
  EXPECT_EQ(all.find("zz"), nullptr);
}

}  // namespace
}  // namespace cell::kinematics
