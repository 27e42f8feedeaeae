// The simulated joint: the thesis's PD gains servo it stably and well damped at 1 ms, friction
// holds it, the encoder is quantised and wraps at 24 bits, index pulses fall at home.
#include "joint_model.hpp"

#include <algorithm>
#include <cmath>

#include <gtest/gtest.h>

#include "cell/dpr7545/codec.hpp"

namespace cell::sim7545 {
namespace {

using dpr7545::kThesisOverrunLimits;

constexpr double kTs = 0.001;

JointModel j1(double initial_counts = 0.0) {
  return JointModel(SimConfig::default_plants()[0], initial_counts,
                    kThesisOverrunLimits[0].min_counts, kThesisOverrunLimits[0].max_counts);
}

/// Runs the master's PD law against `joint` toward `reference(k)` for `n` samples; returns the
/// largest |error| seen after `settle` samples, and fails the test if a word left the range.
template <typename Ref>
double servo(JointModel& joint, double kp, int n, Ref reference, int settle = 0) {
  double e_prev = reference(0) - static_cast<double>(joint.encoder_counts());
  double worst = 0.0;
  for (int k = 0; k < n; ++k) {
    const double e = reference(k) - static_cast<double>(joint.encoder_counts());
    const std::uint16_t word = dpr7545::torque_word(dpr7545::pd_torque(kp, 0.1, kTs, e, e_prev));
    EXPECT_TRUE(dpr7545::torque_word_valid(word)) << "sample " << k << " error " << e;
    e_prev = e;
    if (k >= settle) {
      worst = std::max(worst, std::abs(e));
    }
    joint.advance(word, kTs);
  }
  return worst;
}

// The closed loop the simulator offers the gateway: a small step (inside the DAC range) settles
// within a count in 20 ms, with moderate overshoot: stable and well damped at Ts = 1 ms.
TEST(JointModel, ThesisGainsGiveAStableWellDampedStep) {
  for (int j = 0; j < 4; ++j) {
    const auto plant = SimConfig::default_plants()[static_cast<std::size_t>(j)];
    JointModel joint(plant, 0.0, -100000, 100000);
    const double kp = dpr7545::kDefaultKp[static_cast<std::size_t>(j)];
    double peak = 0.0;
    double e_prev = 0.0;
    constexpr double kStep = 10.0;  // 10 counts: kp*e + kv/Ts*de = 1600 < 2047
    for (int k = 0; k < 200; ++k) {
      const double e = kStep - static_cast<double>(joint.encoder_counts());
      const auto word = dpr7545::torque_word(dpr7545::pd_torque(kp, 0.1, kTs, e, e_prev));
      ASSERT_TRUE(dpr7545::torque_word_valid(word));
      e_prev = e;
      joint.advance(word, kTs);
      peak = std::max(peak, joint.position());
      if (k >= 20) {
        EXPECT_LE(std::abs(joint.position() - kStep), 1.5) << "joint " << j << " sample " << k;
      }
    }
    EXPECT_LT(peak - kStep, 0.6 * kStep) << "joint " << j << " overshoot";
  }
}

// Tracking the top speed of J1 (45 deg/s = 39,250 counts/s) costs about 1000 DAC units of
// viscous torque: the following error stays well inside the DAC range (34 counts).
TEST(JointModel, TopSpeedRampIsTrackedInsideTheDacRange) {
  JointModel joint = j1();
  constexpr double kSpeed = 39250.0;  // counts/s
  const double worst = servo(
      joint, 60.0, 1500,
      [](int k) {  // smooth start: 0.25 s quadratic blend to full speed, then constant
        const double t = k * kTs;
        return t < 0.25 ? kSpeed * t * t / 0.5 : kSpeed * (t - 0.125);
      },
      0);
  EXPECT_LT(worst, 25.0);
  EXPECT_GT(worst, 10.0);  // a real PD loop without feed-forward lags: 1000 / kp = 17 counts
}

// Friction below kp x 1 count: the PD loop always comes to rest on the setpoint's own count,
// from either side (so a 7545 at home reads exactly 0, its J1/J2 lower soft limit).
TEST(JointModel, PdLoopRestsOnTheSetpointsCount) {
  for (const double start : {-20.0, -3.0, 2.6, 18.0}) {
    JointModel joint = j1(start);
    joint.reset_counter_at(0.0);
    (void)servo(joint, 60.0, 300, [](int) { return 0.0; });
    EXPECT_EQ(joint.encoder_counts(), 0) << "from " << start;
  }
}

TEST(JointModel, CoulombFrictionHoldsAgainstSmallTorques) {
  JointModel joint = j1(100.0);
  joint.advance(dpr7545::kTorqueZero + 25, 0.5);  // below the 30 DAC units of friction
  EXPECT_DOUBLE_EQ(joint.position(), 100.0);
  joint.advance(dpr7545::kTorqueZero + 200, 0.1);
  EXPECT_GT(joint.position(), 100.0);
  joint.advance(dpr7545::kTorqueZero, 0.5);  // coasts to a stop
  EXPECT_DOUBLE_EQ(joint.velocity(), 0.0);
}

TEST(JointModel, EncoderIsQuantisedAndResetsAtPowerUp) {
  JointModel joint = j1(5000.4);
  EXPECT_EQ(joint.encoder_counts(), 0);  // the counter reads 0 wherever the arm powers up
  joint.reset_counter_at(0.0);
  EXPECT_EQ(joint.encoder_counts(), 5000);
  joint.reset_counter_at(5001.0);
  EXPECT_EQ(joint.encoder_counts(), -1);
  EXPECT_EQ(joint.counter_24(), 0xFFFFFFU);  // the 24-bit up/down counter wraps
  EXPECT_EQ(dpr7545::sign_extend_24(joint.counter_24()), -1);
}

TEST(JointModel, InjectedOffsetsMoveTheCounterNotTheArm) {
  JointModel joint = j1(0.0);
  joint.add_encoder_offset(500);
  EXPECT_EQ(joint.encoder_counts(), 500);
  EXPECT_DOUBLE_EQ(joint.position(), 0.0);
  joint.force_encoder_counts(176189);
  EXPECT_EQ(joint.encoder_counts(), 176189);
  joint.clear_encoder_offset();
  EXPECT_EQ(joint.encoder_counts(), 0);
}

TEST(JointModel, IndexPulsesFallOnMultiplesOfTheSpacingAndHomeSensorBelowItsEdge) {
  JointModel joint = j1(2500.0);  // spacing 2000, home edge 1000
  EXPECT_FALSE(joint.home_active());
  const auto pulses = joint.index_pulses();
  joint.advance(dpr7545::kTorqueZero - 400, 0.2);  // drive negative
  EXPECT_LT(joint.position(), 0.0);
  EXPECT_TRUE(joint.home_active());
  EXPECT_GE(joint.index_pulses(), pulses + 2);  // crossed 2000 and 0
  EXPECT_EQ(std::fmod(joint.last_index_position(), 2000.0), 0.0);
}

TEST(JointModel, MechanicalStopsLieJustBeyondTheOverrunLimits) {
  JointModel joint = j1(0.0);
  joint.advance(dpr7545::kTorqueZero - 2000, 3.0);  // full negative torque for 3 s
  EXPECT_LT(joint.position(), kThesisOverrunLimits[0].min_counts);
  EXPECT_GT(joint.position(), kThesisOverrunLimits[0].min_counts - 5000);
}

}  // namespace
}  // namespace cell::sim7545
