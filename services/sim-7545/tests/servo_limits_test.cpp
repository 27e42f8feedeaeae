// The limits the 7545's joints can follow (servo_limits.hpp): the shipped robot file against
// the shipped joint model and PD gains, and the derivation against the closed form.
#include "servo_limits.hpp"

#include <fmt/format.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <regex>
#include <sstream>

#include "cell/dpr7545/registers.hpp"
#include "cell/testing/env.hpp"
#include "cell/testing/matchers.hpp"

namespace cell::sim7545 {
namespace {

using ::cell::testing::IsOk;

std::string source(const std::string& relative) {
  return cell::testing::source_dir() + "/" + relative;
}

const std::string kRobot = "config/robots/ibm7545.yaml";
const std::string kSim = "config/sim-7545.yaml";
const std::string kGateway = "config/gateway-ibm7545-dpr.yaml";

// Every joint of the shipped robot file, at its speed and acceleration limits, keeps the
// torque word within 60 % of its range under the shipped gains and joint model; and its
// acceleration limit is the derived one (rounded down, not 5 % short of it): a value the
// cell's own models determine, not a guess.
TEST(ServoLimits, TheShippedRobotFileHasTheDerivedLimitsWithFortyPercentInReserve) {
  auto judged = judge_robot_limits(source(kRobot), source(kSim), source(kGateway), kDefaultMargin);
  ASSERT_THAT(judged, IsOk());
  ASSERT_EQ(judged->size(), 4U);
  for (const JointJudgement& j : *judged) {
    EXPECT_TRUE(j.ok) << j.joint << ": peak " << j.at_file_limits.peak_dac << " DAC units against "
                      << j.derived.usable_dac;
    EXPECT_LE(j.speed_counts_s, j.derived.speed_ceiling_counts_s) << j.joint;
    EXPECT_LE(j.accel_counts_s2, j.derived.accel_counts_s2) << j.joint;
    EXPECT_GE(j.accel_counts_s2, 0.95 * j.derived.accel_counts_s2)
        << j.joint << ": " << j.accel_counts_s2 / j.counts_per_unit << " " << j.unit
        << "/s^2 in the file, " << j.derived.accel_counts_s2 / j.counts_per_unit
        << " derived: put the derived value in the file (cell-sim-7545 limits)";
  }
}

/// The shipped robot file with J1's speed and acceleration rewritten, in a temporary file.
class RobotFileRewrite {
 public:
  RobotFileRewrite() {
    std::ifstream in(source(kRobot));
    std::stringstream text;
    text << in.rdbuf();
    text_ = text.str();
  }
  ~RobotFileRewrite() {
    std::error_code ec;
    std::filesystem::remove(path_, ec);
  }
  const std::string& j1(double speed_deg_s, double accel_deg_s2) {
    std::string s = std::regex_replace(text_, std::regex("max_speed_deg_s: 45\\.0"),
                                       fmt::format("max_speed_deg_s: {}", speed_deg_s),
                                       std::regex_constants::format_first_only);
    s = std::regex_replace(s, std::regex("max_accel_deg_s2: [0-9.]+"),
                           fmt::format("max_accel_deg_s2: {}", accel_deg_s2),
                           std::regex_constants::format_first_only);
    std::ofstream(path_) << s;
    return path_;
  }

 private:
  std::string text_;
  std::string path_ = (std::filesystem::temp_directory_path() /
                       fmt::format("cell-servo-limits-{}.yaml", ::getpid()))
                          .string();
};

// A robot file asking J1 for more than its loop can follow is caught: an acceleration 30 %
// beyond the derived one, and a speed beyond the ceiling. And the file as it was before the
// limits were derived (J1 at 180 deg/s^2, "full speed in 0.25 s", a placeholder) is caught as
// not the derived value.
TEST(ServoLimits, ARobotFileBeyondWhatJ1CanFollowOrShortOfItIsCaught) {
  auto judged = judge_robot_limits(source(kRobot), source(kSim), source(kGateway), kDefaultMargin);
  ASSERT_THAT(judged, IsOk());
  const JointJudgement& j1 = judged->front();
  RobotFileRewrite file;
  const double c = j1.counts_per_unit;
  auto sharp = judge_robot_limits(file.j1(45.0, 1.3 * j1.derived.accel_counts_s2 / c),
                                  source(kSim), source(kGateway), kDefaultMargin);
  ASSERT_THAT(sharp, IsOk());
  EXPECT_FALSE(sharp->front().ok) << sharp->front().at_file_limits.peak_dac;
  EXPECT_TRUE((*sharp)[1].ok);
  auto fast = judge_robot_limits(file.j1(1.05 * j1.derived.speed_ceiling_counts_s / c, 10.0),
                                 source(kSim), source(kGateway), kDefaultMargin);
  ASSERT_THAT(fast, IsOk());
  EXPECT_FALSE(fast->front().ok) << fast->front().at_file_limits.peak_dac;
  auto placeholder = judge_robot_limits(file.j1(45.0, 180.0), source(kSim), source(kGateway), kDefaultMargin);
  ASSERT_THAT(placeholder, IsOk());
  const JointJudgement& old = placeholder->front();
  EXPECT_TRUE(old.ok);  // it fits: it only wastes the arm
  EXPECT_LT(old.accel_counts_s2, 0.95 * old.derived.accel_counts_s2)
      << "180 deg/s^2 would pass for the derived value";
}

// The simulated worst case against the closed form: in steady following the law must supply
// (a + b v) / g + coulomb; the peak lies above it by the transients of the acceleration steps
// and the encoder's one-count quantisation through the derivative (kv / Ts per count), never
// below it, and the steady error is that torque over kp.
TEST(ServoLimits, TheWorstCaseMatchesTheClosedFormOfTheSteadyDemand) {
  const JointPlant plant = SimConfig::default_plants()[0];
  const PdLaw law{60.0, 0.1, 0.001};
  const double v = 39'250.0;  // J1 at 45 deg/s
  for (const double a : {20'000.0, 200'000.0, 1'000'000.0}) {
    const FollowResult r = simulate_follow(plant, law, v, a);
    const double steady =
        (a + plant.viscous_per_s * v) / plant.accel_per_dac_counts_s2 + plant.coulomb_dac;
    EXPECT_GE(r.peak_dac, steady) << a;
    EXPECT_LE(r.peak_dac, steady * 1.3 + 2 * law.kv / law.period_s) << a;
    EXPECT_NEAR(r.peak_error_counts, r.peak_dac / law.kp, 0.25 * r.peak_dac / law.kp) << a;
  }
  const FollowableLimits lim = derive_limits(plant, law, v, 0.3);
  EXPECT_NEAR(lim.usable_dac, 0.7 * 2047, 1e-9);
  EXPECT_NEAR(
      lim.speed_ceiling_counts_s,
      (lim.usable_dac - plant.coulomb_dac) * plant.accel_per_dac_counts_s2 / plant.viscous_per_s,
      1e-6);
  EXPECT_LE(lim.at_limits.peak_dac, lim.usable_dac);
  // The next step up of the scan does not fit.
  EXPECT_GT(simulate_follow(plant, law, v, lim.accel_counts_s2 * 1.005).peak_dac, lim.usable_dac);
  // Every step below fits (the peak is not monotonic: the scan guarantees this, a bisection
  // would not).
  for (double a = lim.accel_counts_s2; a > lim.accel_counts_s2 / 2; a /= 1.005) {
    EXPECT_LE(simulate_follow(plant, law, v, a).peak_dac, lim.usable_dac) << a;
  }
}

TEST(ServoLimits, AGatewayConfigWithoutFourGainsIsAClearError) {
  const auto path = std::filesystem::temp_directory_path() /
                    fmt::format("cell-servo-limits-gw-{}.yaml", ::getpid());
  std::ofstream(path) << "driver: {kind: dpr7545, kp: [60, 60], kv: [0.1, 0.1, 0.1, 0.1]}\n";
  auto laws = load_pd_laws(path.string());
  ASSERT_FALSE(laws);
  EXPECT_THAT(laws.error().message, ::testing::HasSubstr("'driver.kp' and 'driver.kv' must be "
                                                         "lists of 4 numbers"));
  std::filesystem::remove(path);
}

}  // namespace
}  // namespace cell::sim7545
