#include "cell/trajectory/planners.hpp"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "cell/testing/matchers.hpp"
#include "test_robots.hpp"

namespace cell::trajectory {
namespace {

using ::cell::testing::IsErrWith;
using ::cell::testing::IsOk;
using testing::deg;
using testing::jv;

// IBM 7545 encoder scales (digest 000 §2.1): counts per deg (J1, J2, R) and per mm (Z).
constexpr double kJ1CountsPerDeg = 872.2222;
constexpr double kJ2CountsPerDeg = 444.4444;
constexpr double kRCountsPerDeg = 227.5556;

ViaPointOptions thesis_options() {
  ViaPointOptions o;
  o.speed = testing::ibm7545_speeds();
  o.settle_s = 0.2;
  return o;
}

// Digest 000 §9.2 case 13: home -> image window takes 2.30 s (J2 dominates: 105 deg at
// 50 deg/s + 0.2 s).
TEST(ViaPoints, ThesisSegmentTimeHomeToWindow) {
  auto path = plan_via_points({jv({0, 0, 0, 0}), jv({deg(45), deg(105), 0, 0})}, thesis_options());
  ASSERT_THAT(path, IsOk());
  EXPECT_NEAR(path->duration_s(), 2.30, 1e-9);
}

// Digest 000 §9.2 case 13: Z 0 -> 200 mm at the window takes 2.20 s.
TEST(ViaPoints, ThesisSegmentTimeWindowDown) {
  auto path = plan_via_points({jv({deg(45), deg(105), 0, 0}), jv({deg(45), deg(105), 200, 0})},
                              thesis_options());
  ASSERT_THAT(path, IsOk());
  EXPECT_NEAR(path->duration_s(), 2.20, 1e-9);
}

// Digest 000 §9.2 case 13 and §5 pick profile: [window, Z 200] -> [IC, Z 200] -> [IC, Z 227.7]
// with the IC of case 9 (counts 41050, 33985) and R = -13241 counts (case 11): the traverse
// takes 1.03 s (R dominates: 0.83 s + 0.2 s), the descent 0.477 s.
TEST(ViaPoints, ThesisPickMoveSegmentsAndViaVelocity) {
  const double j1 = deg(41050 / kJ1CountsPerDeg);
  const double j2 = deg(33985 / kJ2CountsPerDeg);
  const double r = deg(-13241 / kRCountsPerDeg);
  const JointVector window = jv({deg(39249 / kJ1CountsPerDeg), deg(46662 / kJ2CountsPerDeg), 200, 0});
  const JointVector over = jv({j1, j2, 200, r});
  const JointVector down = jv({j1, j2, 227.7, r});
  auto path = plan_via_points({window, over, down}, thesis_options());
  ASSERT_THAT(path, IsOk());
  const auto& k = path->knots();
  ASSERT_EQ(k.size(), 3U);
  EXPECT_NEAR(k[1].t_s, 1.03, 0.005);
  EXPECT_NEAR(k[1].t_s, 58.187 / 70.0 + 0.2, 1e-3);
  EXPECT_NEAR(k[2].t_s - k[1].t_s, 0.477, 1e-9);
  // Via velocity: J1 and R move only in the first segment, Z only in the second. A zero slope
  // counts as "same sign" (cmp_sign), so the via velocity is half the moving segment's slope.
  const double t1 = k[1].t_s;
  EXPECT_NEAR(k[1].qd[0], 0.5 * (j1 - window[0]) / t1, 1e-12);
  EXPECT_NEAR(k[1].qd[3], 0.5 * r / t1, 1e-12);
  EXPECT_NEAR(k[1].qd[2], 0.5 * 27.7 / 0.477, 1e-12);
  EXPECT_EQ(k[0].qd.norm(), 0.0);
  EXPECT_EQ(k[2].qd.norm(), 0.0);
}

TEST(ViaPoints, OppositeSlopesGiveZeroViaVelocityAndSegmentsAreCraigCubics) {
  ViaPointOptions o;
  o.speed = jv({1.0});
  o.settle_s = 0.0;
  auto path = plan_via_points({jv({0}), jv({2}), jv({1})}, o);
  ASSERT_THAT(path, IsOk());
  EXPECT_EQ(path->knots()[1].qd[0], 0.0);
  // Segment 0: q0 = 0, q1 = 2, T = 2, v0 = v1 = 0 -> a2 = 3*2/4, a3 = -2*2/8 (Craig).
  const double a2 = 3.0 * 2 / 4;
  const double a3 = -2.0 * 2 / 8;
  for (double t = 0; t <= 2.0; t += 0.25) {
    EXPECT_NEAR(path->sample(t).q[0], a2 * t * t + a3 * t * t * t, 1e-12);
  }
}

TEST(ViaPoints, RejectsBadInput) {
  ViaPointOptions o;
  o.speed = jv({1.0, 0.0});
  EXPECT_THAT(plan_via_points({jv({0, 0}), jv({1, 1})}, o),
              IsErrWith(Errc::kInvalidArgument, "speed of joint 1 must be > 0"));
  o.speed = jv({1.0, 1.0});
  EXPECT_THAT(plan_via_points({jv({0, 0})}, o), IsErrWith(Errc::kInvalidArgument, "at least 2"));
  EXPECT_THAT(plan_via_points({jv({0, 0}), jv({1})}, o),
              IsErrWith(Errc::kInvalidArgument, "via point: 2 joints against 1"));
}

TEST(JointMove, IsSynchronisedWithinVelocityAndAccelerationLimits) {
  testing::Gantry g(500, 2000);
  g.limits.max_velocity[1] = 100;  // Y is slow: it sets the duration
  const JointVector q0 = jv({0, 0, 0});
  const JointVector q1 = jv({300, 200, -50});
  auto move = plan_joint_move(q0, q1, g.limits);
  ASSERT_THAT(move, IsOk());
  // Path parameter limits: speed min(500/300, 100/200, 500/50) = 0.5 /s (Y), acceleration
  // min(2000/300, 2000/200, 2000/50) = 6.67 /s^2 (X): T = 1/0.5 + 0.5/6.67 = 2.075 s.
  EXPECT_NEAR(move->duration_s(), 1.0 / 0.5 + 0.5 / (2000.0 / 300), 1e-9);
  for (double t = 0; t <= move->duration_s(); t += 0.001) {
    const JointSample s = move->sample(t);
    for (int j = 0; j < 3; ++j) {
      EXPECT_LE(std::abs(s.qd[j]), g.limits.max_velocity[j] + 1e-9);
      EXPECT_LE(std::abs(s.qdd[j]), g.limits.max_acceleration[j] + 1e-6);
    }
    // Straight line in joint space: every joint at the same fraction of its way.
    const double f = s.q[1] / 200.0;
    EXPECT_NEAR(s.q[0], 300 * f, 1e-9);
    EXPECT_NEAR(s.q[2], -50 * f, 1e-9);
  }
  EXPECT_TRUE(move->sample(move->duration_s()).q.isApprox(q1));
}

TEST(JointMove, RefusesATargetBeyondALimitNamingTheJoint) {
  testing::Gantry g;
  EXPECT_THAT(plan_joint_move(jv({0, 0, 0}), jv({0, 1200, 0}), g.limits),
              IsErrWith(Errc::kOutOfRange, "target: joint Y at 1200.00 mm is beyond its limit"));
  EXPECT_THAT(plan_joint_move(jv({0, 0, 0}), jv({0, 1, 0}), g.limits, 1.5),
              IsErrWith(Errc::kInvalidArgument, "speed_scale"));
}

TEST(LinearMove, ToolPointStaysOnTheLineWithinSpeedLimit) {
  testing::Gantry g;
  Eigen::Isometry3d goal = Eigen::Isometry3d::Identity();
  goal.translation() = Eigen::Vector3d(400, -300, 100);
  LinearMoveOptions o;
  o.max_speed_mm_s = 500;
  o.max_accel_mm_s2 = 4000;
  auto line = plan_linear_move(jv({0, 0, 0}), goal, g.forward(), g.inverse(), g.limits, o);
  ASSERT_THAT(line, IsOk());
  const Eigen::Vector3d dir = goal.translation().normalized();
  Eigen::Vector3d previous = Eigen::Vector3d::Zero();
  for (double t = 0; t <= line->duration_s(); t += 0.001) {
    const Eigen::Vector3d p = line->sample(t).q.head<3>();
    EXPECT_LT((p - p.dot(dir) * dir).norm(), 1e-6) << "t=" << t;
    EXPECT_LE((p - previous).norm() / 0.001, 500 * 1.01) << "t=" << t;
    previous = p;
  }
  EXPECT_LT((line->end().head<3>() - goal.translation()).norm(), 1e-9);
}

TEST(LinearMove, SlowsDownWhenAJointCannotKeepUp) {
  testing::Gantry g(100, 20000);  // joints limited to 100 mm/s
  Eigen::Isometry3d goal = Eigen::Isometry3d::Identity();
  goal.translation() = Eigen::Vector3d(200, 0, 0);
  LinearMoveOptions o;
  o.max_speed_mm_s = 1000;
  auto line = plan_linear_move(jv({0, 0, 0}), goal, g.forward(), g.inverse(), g.limits, o);
  ASSERT_THAT(line, IsOk());
  EXPECT_GE(line->duration_s(), 2.0);
  EXPECT_THAT(check_limits(*line, g.limits, 0.05), IsOk());
}

TEST(LinearMove, RefusesALineThatLeavesTheWorkspaceAndSaysWhere) {
  testing::Gantry g;
  Eigen::Isometry3d goal = Eigen::Isometry3d::Identity();
  goal.translation() = Eigen::Vector3d(1500, 0, 0);
  auto line = plan_linear_move(jv({0, 0, 0}), goal, g.forward(), g.inverse(), g.limits);
  EXPECT_THAT(line, IsErrWith(Errc::kOutOfRange, "straight line leaves the workspace"));
  EXPECT_THAT(line, IsErrWith(Errc::kOutOfRange, "outside the gantry's box"));
}

TEST(OffsetAlongToolZ, MovesAlongTheToolAxisNotTheBaseAxis) {
  Eigen::Isometry3d tool = Eigen::Isometry3d::Identity();
  tool.linear() = Eigen::AngleAxisd(std::numbers::pi, Eigen::Vector3d::UnitX()).toRotationMatrix();
  tool.translation() = Eigen::Vector3d(100, 0, 50);  // tool z points down
  const Eigen::Isometry3d above = offset_along_tool_z(tool, -30);
  EXPECT_TRUE(above.translation().isApprox(Eigen::Vector3d(100, 0, 80)));
}

}  // namespace
}  // namespace cell::trajectory
