#include "cell/trajectory/alter.hpp"

#include <cmath>
#include <cstdio>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "cell/testing/matchers.hpp"
#include "cell/trajectory/executor.hpp"
#include "test_robots.hpp"

namespace cell::trajectory {
namespace {

using ::cell::testing::IsOk;
using testing::jv;

AlterCorrection dy(double mm, double stamp = 0.0) {
  AlterCorrection c;
  c.translation_mm = Eigen::Vector3d(0, mm, 0);
  c.stamp_s = stamp;
  return c;
}

// Digest 002 §6.2 T2: in total (non-cumulative) mode the second correction -108 replaces the
// first -100; it is not added (-208).
TEST(AlterState, TotalModeReplaces) {
  AlterState alter({.cumulative = false, .world_frame = true});
  alter.submit(dy(-100));
  alter.begin_cycle();
  EXPECT_DOUBLE_EQ(alter.effective_at(0).translation_mm.y(), -100.0);
  alter.submit(dy(-108));
  alter.begin_cycle();
  EXPECT_DOUBLE_EQ(alter.effective_at(0).translation_mm.y(), -108.0);
}

// Digest 002 §6.2 T2: in incremental mode (ALTON mode 3) the same motion is sent as -100 then
// -8.0 and accumulates to -108.
TEST(AlterState, CumulativeModeAccumulates) {
  AlterState alter({.cumulative = true, .world_frame = true});
  alter.submit(dy(-100));
  alter.begin_cycle();
  alter.submit(dy(-8));
  alter.begin_cycle();
  EXPECT_DOUBLE_EQ(alter.effective_at(0).translation_mm.y(), -108.0);
  alter.begin_cycle();  // no new correction this cycle: the sum stays
  EXPECT_DOUBLE_EQ(alter.effective_at(0).translation_mm.y(), -108.0);
}

// Digest 002 §6.2 T3: two ALTERs in one cycle (-100 then -104): the applied one is -104; in
// cumulative mode too only the last of the cycle is added.
TEST(AlterState, LastCorrectionInACycleWins) {
  AlterState total({.cumulative = false});
  total.submit(dy(-100));
  total.submit(dy(-104));
  total.begin_cycle();
  EXPECT_DOUBLE_EQ(total.effective_at(0).translation_mm.y(), -104.0);
  AlterState cumulative({.cumulative = true});
  cumulative.submit(dy(-2));
  cumulative.submit(dy(-4));
  cumulative.begin_cycle();
  EXPECT_DOUBLE_EQ(cumulative.effective_at(0).translation_mm.y(), -4.0);
  EXPECT_EQ(cumulative.cycles_with_correction(), 1U);
}

TEST(AlterState, WorldAndToolFramesDisplaceDifferently) {
  Eigen::Isometry3d tool = Eigen::Isometry3d::Identity();
  tool.linear() = Eigen::AngleAxisd(std::numbers::pi / 2, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  tool.translation() = Eigen::Vector3d(100, 50, 0);
  AlterCorrection c;
  c.translation_mm = Eigen::Vector3d(10, 0, 0);
  c.rotation_rad = Eigen::Vector3d(0, 0, 0.1);
  const Eigen::Isometry3d world = AlterState({.world_frame = true}).apply(tool, c);
  const Eigen::Isometry3d in_tool = AlterState({.world_frame = false}).apply(tool, c);
  EXPECT_TRUE(world.translation().isApprox(Eigen::Vector3d(110, 50, 0)));
  EXPECT_TRUE(in_tool.translation().isApprox(Eigen::Vector3d(100, 60, 0)));  // tool x = base y
  // Both rotate the tool by +0.1 rad about the (vertical) z axis without moving the tool point
  // sideways.
  EXPECT_NEAR(Eigen::AngleAxisd(tool.linear().transpose() * world.linear()).angle(), 0.1, 1e-12);
  EXPECT_NEAR(Eigen::AngleAxisd(tool.linear().transpose() * in_tool.linear()).angle(), 0.1, 1e-12);
}

TEST(AlterState, ExtrapolatesWithTheCorrectionRate) {
  AlterState alter;
  AlterCorrection c = dy(-100, 1.0);
  c.velocity_mm_s = Eigen::Vector3d(0, -2000, 0);
  alter.submit(c);
  alter.begin_cycle();
  EXPECT_NEAR(alter.effective_at(1.004).translation_mm.y(), -108.0, 1e-9);
}

// A sender that falls silent leaves the arm at most rate * horizon past its last correction.
TEST(AlterState, StopsExtrapolatingAfterTheHorizon) {
  AlterState alter;
  AlterCorrection c = dy(-100, 1.0);
  c.velocity_mm_s = Eigen::Vector3d(0, -500, 0);
  alter.submit(c);
  alter.begin_cycle();
  const double h = AlterState::kExtrapolationHorizonS;
  EXPECT_NEAR(alter.effective_at(1.0 + h / 2).translation_mm.y(), -100.0 - 500 * h / 2, 1e-9);
  EXPECT_NEAR(alter.effective_at(1.0 + h).translation_mm.y(), -100.0 - 500 * h, 1e-9);
  EXPECT_NEAR(alter.effective_at(3.0).translation_mm.y(), -100.0 - 500 * h, 1e-9);
}

// A sender near a limit gives the time left to it: the rate stays whole (no lag while
// following) and the extrapolation ends at the limit. Longer than the gateway's horizon, or 0:
// the gateway's horizon.
TEST(AlterState, TheSendersHorizonEndsTheExtrapolationAtItsLimit) {
  const double h = AlterState::kExtrapolationHorizonS;
  for (const double asked : {0.02, 0.0, 10 * h}) {
    SCOPED_TRACE(asked);
    AlterState alter;
    AlterCorrection c = dy(-100, 1.0);
    c.velocity_mm_s = Eigen::Vector3d(0, -2000, 0);
    c.horizon_s = asked;
    alter.submit(c);
    alter.begin_cycle();
    const double used = asked > 0 && asked < h ? asked : h;
    EXPECT_NEAR(alter.effective_at(1.0 + 0.01).translation_mm.y(), -100.0 - 20.0, 1e-9);
    EXPECT_NEAR(alter.effective_at(1.0 + used).translation_mm.y(), -100.0 - 2000 * used, 1e-9);
    EXPECT_NEAR(alter.effective_at(5.0).translation_mm.y(), -100.0 - 2000 * used, 1e-9);
  }
  // Cumulative mode keeps the horizon of the correction last added.
  AlterState cumulative({.cumulative = true, .world_frame = true});
  AlterCorrection c = dy(-10, 1.0);
  c.velocity_mm_s = Eigen::Vector3d(0, -1000, 0);
  c.horizon_s = 0.01;
  cumulative.submit(c);
  cumulative.begin_cycle();
  EXPECT_NEAR(cumulative.effective_at(2.0).translation_mm.y(), -10.0 - 10.0, 1e-9);
}

// At the end the robot rests at the planned destination plus the total correction (V+ ALTOFF).
TEST(TrajectoryExecutor, RestsAtDestinationPlusTotalCorrection) {
  testing::Gantry g;
  Eigen::Isometry3d goal = Eigen::Isometry3d::Identity();
  goal.translation() = Eigen::Vector3d(300, 100, 0);
  auto line = plan_linear_move(jv({0, 0, 0}), goal, g.forward(), g.inverse(), g.limits);
  ASSERT_THAT(line, IsOk());
  TrajectoryExecutor exec(g.forward(), g.inverse());
  exec.load(*line, 0.0, true, {.cumulative = false, .world_frame = true});
  JointSample out;
  double t = 0;
  for (; exec.step(t, out) != ExecState::kArrived; t += 0.001) {
    if (t > 0.1) {
      exec.submit_alter(dy(-25, t));
    }
    ASSERT_LT(t, 10.0);
  }
  exec.alter_off();
  exec.step(t + 0.5, out);
  EXPECT_NEAR(out.q[0], 300, 1e-9);
  EXPECT_NEAR(out.q[1], 75, 1e-9);
}

/// Belt tracking (conveyor chapter, digest 002 §1.3 and §2): a part rides a belt along -Y; the
/// encoder is latched when the part is located (the fix the digest recommends over V+'s late
/// read); the robot moves in a straight line to where the part was (part.loc) while a tracker
/// sends, every `cycle_s`, the total world-frame correction -mm_per_count * (pos - offset) and
/// its rate from the encoder. Returns the largest tool-to-part distance from arrival
/// ("stopped at planned location") through a 0.2 s gripper closure. With `limited`, the
/// executor keeps the gantry's joint limits, the tracking ends with ALTOFF, and `peak_accel`
/// gets the largest sampled acceleration over the whole path, ALTOFF's braking to rest included,
/// as a fraction of the limit.
double track_belt(double belt_mm_s,
                  double cycle_s,
                  bool rate_feed_forward,
                  bool limited = false,
                  double* peak_accel = nullptr) {
  constexpr double kMmPerCount = 50.0 * std::numbers::pi / (1024 * 4);  // digest 002 T9: 0.03835
  testing::Gantry gantry(4000, 40000, 5000);
  const Eigen::Vector3d part0(300, 800, 0);  // where vision located the part at t = 0
  auto part_at = [&](double t) -> Eigen::Vector3d { return part0 + Eigen::Vector3d(0, -belt_mm_s * t, 0); };
  auto count_at = [&](double t) { return std::floor(belt_mm_s * t / kMmPerCount); };
  const double offset = count_at(0.0);  // latched at exposure

  const double t_start = 0.08;  // vision processing and planning before the move starts
  Eigen::Isometry3d part_loc = Eigen::Isometry3d::Identity();
  part_loc.translation() = part0;
  LinearMoveOptions options;
  options.max_speed_mm_s = 1500;
  options.max_accel_mm_s2 = 15000;
  auto line = plan_linear_move(jv({0, 0, 100}), part_loc, gantry.forward(), gantry.inverse(),
                               gantry.limits, options);
  EXPECT_THAT(line, IsOk());
  TrajectoryExecutor exec(gantry.forward(), gantry.inverse(),
                          limited ? gantry.limits : JointLimits{});
  exec.load(*line, t_start, true, {.cumulative = false, .world_frame = true});

  std::vector<JointVector> path;  // every setpoint, 1 ms apart
  double next_cycle = t_start;
  double last_count = count_at(t_start - 4 * cycle_s);
  double last_count_t = t_start - 4 * cycle_s;
  double worst = 0;
  double arrived_at = -1;
  JointSample out;
  for (double t = t_start; t < t_start + 5.0; t += 0.001) {
    if (t >= next_cycle - 1e-12) {
      const double pos = count_at(t);
      AlterCorrection c;
      c.translation_mm = Eigen::Vector3d(0, -kMmPerCount * (pos - offset), 0);
      if (rate_feed_forward) {  // rate from the encoder over the last few cycles
        c.velocity_mm_s =
            Eigen::Vector3d(0, -kMmPerCount * (pos - last_count) / (t - last_count_t), 0);
      }
      c.stamp_s = t;
      exec.submit_alter(c);
      last_count = count_at(t - 3 * cycle_s);
      last_count_t = t - 3 * cycle_s;
      next_cycle += cycle_s;
    }
    const ExecState state = exec.step(t, out);
    path.push_back(out.q);
    EXPECT_NE(state, ExecState::kFailed) << exec.failure().message;
    if (state == ExecState::kArrived && arrived_at < 0) {
      arrived_at = t;
    }
    if (arrived_at >= 0) {
      worst = std::max(worst, (out.q.head<3>() - part_at(t)).norm());
      if (t > arrived_at + 0.2) {
        break;
      }
    }
  }
  EXPECT_GT(arrived_at, 0) << "never arrived";
  if (limited) {
    // ALTOFF at belt speed: the arm brakes at its limits and rests where braking ends.
    exec.alter_off();
    double t = arrived_at + 0.201;
    int braking = 0;
    for (; exec.step(t, out) == ExecState::kMoving && braking < 2000; t += 0.001, ++braking) {
      path.push_back(out.q);
    }
    path.push_back(out.q);
    const double v = belt_mm_s;
    const double a = gantry.limits.max_acceleration[1];
    EXPECT_NEAR(braking * 0.001, v / a, 0.003) << "braked at its limit from belt speed";
    double peak = 0;
    for (std::size_t k = 2; k < path.size(); ++k) {
      const JointVector accel = (path[k] - 2 * path[k - 1] + path[k - 2]) / 1e-6;
      peak =
          std::max(peak, accel.cwiseAbs().cwiseQuotient(gantry.limits.max_acceleration).maxCoeff());
    }
    if (peak_accel != nullptr) {
      *peak_accel = peak;
    }
  }
  std::printf("belt %.0f mm/s, cycle %.0f ms, rate %s: worst tool-to-part %.4f mm\n", belt_mm_s,
              cycle_s * 1e3, rate_feed_forward ? "on" : "off", worst);
  return worst;
}

TEST(AlterTracking, ToolStaysOnAPartMovingAtHalfAMetrePerSecond) {
  EXPECT_LT(track_belt(500, 0.004, true), 0.1);
  EXPECT_LT(track_belt(500, 0.016, true), 0.1);
}

TEST(AlterTracking, ToolStaysOnAPartMovingAtTwoMetresPerSecond) {
  EXPECT_LT(track_belt(2000, 0.004, true), 0.1);
  EXPECT_LT(track_belt(2000, 0.016, true), 0.1);
}

// With the joint limits the setpoints keep them on the whole path, ALTOFF at 2 m/s included
// (the gantry's 40 m/s^2 brake it in 0.05 s instead of stopping it in one cycle), and where the
// altered path is within them the tool is still on the part.
TEST(AlterTracking, WithJointLimitsEverySampleKeepsThemAndAltoffBrakesToRest) {
  for (const double belt : {500.0, 2000.0}) {
    double peak = 1e9;
    EXPECT_LT(track_belt(belt, 0.004, true, true, &peak), 0.1) << belt << " mm/s";
    EXPECT_LE(peak, 1.01) << belt << " mm/s: peak acceleration / limit";
  }
}

// A path loaded while the setpoints still move (here right after ALTOFF, the arm braking from
// 0.5 m/s of tracking) is joined with bounded acceleration, not a step to its start at rest;
// the executor says kMoving until the setpoints are on the path, and it ends where the path does.
TEST(TrajectoryExecutor, WithLimitsAPathLoadedWhileMovingIsJoinedWithinThem) {
  const testing::Gantry g(2000, 10000);
  TrajectoryExecutor exec(g.forward(), g.inverse(), g.limits);
  auto hold = JointTrajectory::from_knots({Knot{0.0, jv({0, 0, 0}), jv({0, 0, 0})}});
  ASSERT_THAT(hold, IsOk());
  exec.load(*hold, 0.0, true, {.cumulative = false, .world_frame = true});
  std::vector<JointVector> path;
  JointSample out;
  double t = 0;
  for (; t < 0.5; t += 0.001) {  // tracking a part at 0.5 m/s along +y (met at t = 0.1 s)
    AlterCorrection c = dy(std::max(0.0, 500 * (t - 0.1)), t);
    c.velocity_mm_s = Eigen::Vector3d(0, t >= 0.1 ? 500 : 0, 0);
    exec.submit_alter(c);
    exec.step(t, out);
    path.push_back(out.q);
  }
  EXPECT_NEAR(out.qd[1], 500, 1e-6);
  exec.alter_off();
  // The depart: planned from where the arm was when ALTOFF was sent, 30 mm up (z).
  Eigen::Isometry3d up = g.forward()(out.q);
  up.translation().z() += 30;
  auto depart = plan_linear_move(out.q, up, g.forward(), g.inverse(), g.limits);
  ASSERT_THAT(depart, IsOk());
  exec.load(*depart, t, false, {});
  int moving = 0;
  for (; exec.step(t, out) == ExecState::kMoving && moving < 3000; t += 0.001, ++moving) {
    path.push_back(out.q);
  }
  path.push_back(out.q);
  double peak = 0;
  for (std::size_t k = 2; k < path.size(); ++k) {
    const JointVector accel = (path[k] - 2 * path[k - 1] + path[k - 2]) / 1e-6;
    peak = std::max(peak, accel.cwiseAbs().cwiseQuotient(g.limits.max_acceleration).maxCoeff());
  }
  EXPECT_LE(peak, 1.01);
  EXPECT_LT((out.q - depart->end()).norm(), 1e-9);
  EXPECT_GT(exec.limited_cycles(), 10U);  // the 0.1 s meeting step and the join
}

// Without the rate, corrections lag by up to one cycle, as in V+ (digest 002 §2.3: 32 mm per
// 16 ms cycle at 2 m/s): the feed-forward is what makes the 0.1 mm above possible.
TEST(AlterTracking, WithoutRateFeedForwardTheOneCycleLagShows) {
  EXPECT_GT(track_belt(2000, 0.016, false), 5.0);
}

}  // namespace
}  // namespace cell::trajectory
