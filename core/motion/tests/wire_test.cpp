#include "cell/motion/wire.hpp"

#include <cmath>
#include <cstring>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "cell/testing/matchers.hpp"
#include "cell/testing/vectors.hpp"
#include "joint_vectors.hpp"

namespace cell::motion {
namespace {

using ::cell::testing::IsErrWith;
using ::cell::testing::IsOk;

using test::jv;

Plan sample_plan() {
  Plan plan;
  plan.trajectory = *trajectory::JointTrajectory::from_knots(
      {{0.0, jv({0, 0, 0, 0}), jv({0, 0, 0, 0})},
       {1.0, jv({0.5, 0.2, 10, -0.1}), jv({0.1, 0, 5, 0})},
       {2.5, jv({1.0, 0.4, 20, -0.2}), jv({0, 0, 0, 0})}});
  plan.events = {{1.0, true, 0.5}, {2.5, false, 0.2}};
  plan.alter_enabled = true;
  plan.alter_cumulative = true;
  plan.alter_world_frame = false;
  return plan;
}

TEST(Wire, TrajectoryRoundTripsThroughTheIdlStruct) {
  const Plan plan = sample_plan();
  TrajectoryWire wire;
  to_idl(plan, "ibm7545", "m1#1", "m1", wire);
  EXPECT_STREQ(wire.message.robot_id, "ibm7545");
  EXPECT_STREQ(wire.message.trajectory_id, "m1#1");
  auto back = from_idl(wire.message, 4);
  ASSERT_THAT(back, IsOk());
  ASSERT_EQ(back->trajectory.knots().size(), 3U);
  for (std::size_t i = 0; i < 3; ++i) {
    EXPECT_EQ(back->trajectory.knots()[i].t_s, plan.trajectory.knots()[i].t_s);
    EXPECT_EQ(back->trajectory.knots()[i].q, plan.trajectory.knots()[i].q);
    EXPECT_EQ(back->trajectory.knots()[i].qd, plan.trajectory.knots()[i].qd);
  }
  ASSERT_EQ(back->events.size(), 2U);
  EXPECT_TRUE(back->events[0].close);
  EXPECT_EQ(back->events[0].dwell_s, 0.5);
  EXPECT_FALSE(back->events[1].close);
  EXPECT_TRUE(back->alter_enabled);
  EXPECT_TRUE(back->alter_cumulative);
  EXPECT_FALSE(back->alter_world_frame);
}

TEST(Wire, MalformedTrajectoriesAreRefusedWithTheReason) {
  TrajectoryWire wire;
  to_idl(sample_plan(), "r", "t", "m", wire);
  EXPECT_THAT(from_idl(wire.message, 6),
              IsErrWith(Errc::kInvalidArgument, "knot 0 has 4 positions and 4 velocities; the "
                                                "robot has 6 joints"));
  wire.positions[1][2] = NAN;
  EXPECT_THAT(from_idl(wire.message, 4), IsErrWith(Errc::kInvalidArgument, "not a finite"));
  wire.positions[1][2] = 10;
  wire.knots[2].time_from_start_s = 0.5;
  EXPECT_THAT(from_idl(wire.message, 4), IsErrWith(Errc::kInvalidArgument, "must increase"));
  wire.knots[2].time_from_start_s = 2.5;
  // An enum value from a newer contract (or garbage from a broken peer).
  const int garbage = 9;
  std::memcpy(&wire.events[0].kind, &garbage, sizeof garbage);
  EXPECT_THAT(from_idl(wire.message, 4), IsErrWith(Errc::kInvalidArgument, "unknown kind 9"));
  wire.events[0].kind = cell_motion_EVENT_GRIPPER_CLOSE;
  wire.events[0].time_from_start_s = 7;
  EXPECT_THAT(from_idl(wire.message, 4), IsErrWith(Errc::kInvalidArgument, "outside"));
  cell_motion_Trajectory empty{};
  EXPECT_THAT(from_idl(empty, 4), IsErrWith(Errc::kInvalidArgument, "no knots"));
}

TEST(Wire, PosesConvertBothWaysAndRejectNonRotations) {
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  pose.linear() = Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, 2, 3).normalized()).toRotationMatrix();
  pose.translation() = Eigen::Vector3d(100, -20, 5);
  auto back = from_idl(to_idl(pose));
  ASSERT_THAT(back, IsOk());
  EXPECT_THAT(*back, ::cell::testing::IsNearPose(pose, 1e-12));
  cell_common_Pose bad = to_idl(pose);
  bad.orientation = {2.0, 0, 0, 0};
  EXPECT_THAT(from_idl(bad), IsErrWith(Errc::kInvalidArgument, "not a unit quaternion"));
  bad.orientation = {1.0, 0, 0, 0};
  bad.position_mm.x = INFINITY;
  EXPECT_THAT(from_idl(bad), IsErrWith(Errc::kInvalidArgument, "non-finite"));
}

}  // namespace
}  // namespace cell::motion
