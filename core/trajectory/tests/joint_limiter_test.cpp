#include "cell/trajectory/joint_limiter.hpp"

#include <cmath>
#include <vector>

#include <gtest/gtest.h>

#include "test_robots.hpp"

namespace cell::trajectory {
namespace {

using testing::Gantry;
using testing::jv;

constexpr double kDt = 0.001;  // the 7545's servo period

/// The output's sampled speed and acceleration, as the arm's drive sees them: first and
/// second differences of the positions, at most over the run.
struct Sampled {
  std::vector<JointVector> q;
  JointVector peak_speed;
  JointVector peak_accel;
  void add(const JointVector& p) {
    q.push_back(p);
    const auto n = q.size();
    if (peak_speed.size() == 0) {
      peak_speed = JointVector::Zero(p.size());
      peak_accel = JointVector::Zero(p.size());
    }
    if (n >= 2) {
      peak_speed = peak_speed.cwiseMax((q[n - 1] - q[n - 2]).cwiseAbs() / kDt);
    }
    if (n >= 3) {
      peak_accel =
          peak_accel.cwiseMax((q[n - 1] - 2 * q[n - 2] + q[n - 3]).cwiseAbs() / (kDt * kDt));
    }
  }
};

/// A gantry's limiter (100 mm/s, 1000 mm/s^2) at rest at the origin, its samples recorded.
struct AtRest {
  static constexpr double kVMax = 100.0;
  static constexpr double kAMax = 1000.0;
  Gantry gantry{kVMax, kAMax};
  JointLimiter limiter{gantry.limits};
  Sampled s;
  AtRest() {
    limiter.reset(jv({0, 0, 0}), jv({0, 0, 0}));
    s.add(limiter.q());
  }
  /// The samples kept the bounds.
  void expect_within_bounds() const {
    EXPECT_LE(s.peak_accel.maxCoeff(), kAMax * (1 + 1e-9));
    EXPECT_LE(s.peak_speed.maxCoeff(), kVMax * (1 + 1e-9));
  }
};

// A reference within the bounds (a sine whose speed and acceleration peak at 80 % of them) is
// the output, to rounding, from the first step on: the limiter changes nothing it need not.
TEST(JointLimiter, AReferenceWithinTheBoundsIsTheOutput) {
  const Gantry g(100.0, 1000.0);  // mm/s, mm/s^2
  JointLimiter limiter(g.limits);
  const double w = 0.8 * 1000.0 / (0.8 * 100.0);  // a w^2 = 0.8 a_max with A w = 0.8 v_max
  const double amp = 0.8 * 100.0 / w;
  auto ref = [&](double t) { return jv({amp * std::sin(w * t), -amp * std::sin(w * t), 0.0}); };
  auto ref_v = [&](double t) {
    return jv({amp * w * std::cos(w * t), -amp * w * std::cos(w * t), 0.0});
  };
  limiter.reset(ref(0), ref_v(0));
  double worst = 0;
  for (int k = 1; k <= 3000; ++k) {
    const double t = k * kDt;
    EXPECT_FALSE(limiter.step(ref(t), ref_v(t), kDt)) << "step " << k;
    worst = std::max(worst, (limiter.q() - ref(t)).cwiseAbs().maxCoeff());
  }
  EXPECT_LT(worst, 1e-9);
  EXPECT_EQ(limiter.limited_steps(), 0U);
}

// A step of the reference (a path that starts 50 mm away, or a correction that jumps) is
// joined at the bounds: the sampled acceleration and speed stay within them, the output
// overshoots by less than one cycle's acceleration distance a dt^2 (the braking curve's steps
// are whole cycles; the distance left is not: 0.12 um here), and it arrives within a few
// cycles of the time-optimal bang-bang profile.
TEST(JointLimiter, AStepIsJoinedAtTheBoundsInTheTimeOptimalTimeWithoutOvershoot) {
  AtRest arm;
  JointLimiter& limiter = arm.limiter;
  const JointVector target = jv({50.0, -5.0, 0.0});
  int arrived = -1;
  double overshoot = 0;
  for (int k = 1; k <= 2000; ++k) {
    const bool limited = limiter.step(target, JointVector::Zero(3), kDt);
    arm.s.add(limiter.q());
    overshoot = std::max({overshoot, limiter.q()[0] - 50.0, -5.0 - limiter.q()[1]});
    if (!limited && arrived < 0) {
      arrived = k;
    }
    if (arrived >= 0) {
      EXPECT_FALSE(limited) << "step " << k << ": left the target after reaching it";
    }
  }
  arm.expect_within_bounds();
  EXPECT_LT(overshoot, AtRest::kAMax * kDt * kDt);
  // X: accelerate to 100 mm/s in 0.1 s (5 mm), cruise 40 mm (0.4 s), brake 0.1 s: 0.6 s.
  ASSERT_GT(arrived, 0);
  EXPECT_NEAR(arrived * kDt, 0.6, 0.005);
  EXPECT_NEAR(limiter.q()[0], 50.0, 1e-9);
  EXPECT_NEAR(limiter.qd()[0], 0.0, 1e-9);
}

// A reference moving at twice the speed bound is followed at the bound, lagging; when it
// stops, the output catches up and rests on it, every sample within the bounds.
TEST(JointLimiter, AReferenceFasterThanTheArmIsFollowedAtTheBoundAndCaughtWhenItStops) {
  AtRest arm;
  JointLimiter& limiter = arm.limiter;
  constexpr double v_max = AtRest::kVMax;
  double lag = 0;
  for (int k = 1; k <= 2000; ++k) {
    const double t = k * kDt;
    const bool moving = t <= 0.5;
    const double r = 2 * v_max * std::min(t, 0.5);
    limiter.step(jv({r, 0, 0}), jv({moving ? 2 * v_max : 0.0, 0, 0}), kDt);
    arm.s.add(limiter.q());
    lag = std::max(lag, r - limiter.q()[0]);
  }
  arm.expect_within_bounds();
  EXPECT_GT(lag, 45.0);  // half of the reference's 100 mm, and the start's 5 mm
  EXPECT_NEAR(limiter.q()[0], 100.0, 1e-9);
  EXPECT_GT(limiter.limited_steps(), 500U);
}

// The stopping point is where braking at the bound from the present speed ends, exactly: a
// reference resting there is reached with no overshoot, decelerating at the bound throughout.
TEST(JointLimiter, BrakingToTheStoppingPointEndsThereAtRest) {
  const double a_max = 1000.0;
  const Gantry g(500.0, a_max);
  JointLimiter limiter(g.limits);
  Sampled s;
  limiter.reset(jv({0, 0, 0}), jv({300.0, -120.0, 0}));
  s.add(limiter.q() - limiter.qd() * kDt);  // the sample before, at that speed
  s.add(limiter.q());
  const JointVector rest = limiter.stopping_point(kDt);
  EXPECT_NEAR(rest[0], 300.0 * 300.0 / (2 * a_max) + 300.0 * kDt / 2, 1e-12);
  int steps = 0;
  while (limiter.qd().cwiseAbs().maxCoeff() > 1e-9 && steps < 1000) {
    limiter.step(rest, JointVector::Zero(3), kDt);
    s.add(limiter.q());
    EXPECT_LE(limiter.q()[0], rest[0] + 1e-9);
    ++steps;
  }
  EXPECT_LE(s.peak_accel.maxCoeff(), a_max * (1 + 1e-9));
  EXPECT_NEAR(steps * kDt, 0.301, 0.002);  // 300 mm/s at 1000 mm/s^2, and the step at speed
  EXPECT_NEAR((limiter.q() - rest).cwiseAbs().maxCoeff(), 0.0, 1e-9);
}

// Without bounds the limiter is the reference.
TEST(JointLimiter, WithoutBoundsTheOutputIsTheReference) {
  JointLimiter limiter;
  EXPECT_FALSE(limiter.bounded());
  limiter.reset(jv({0, 0}), jv({0, 0}));
  EXPECT_FALSE(limiter.step(jv({100, -3}), jv({5, 0}), kDt));
  EXPECT_EQ(limiter.q(), jv({100, -3}));
  EXPECT_EQ(limiter.qd(), jv({5, 0}));
}

}  // namespace
}  // namespace cell::trajectory
