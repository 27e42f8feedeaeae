#pragma once

#include <array>
#include <string>
#include <vector>

#include "cell/common/result.hpp"
#include "sim_config.hpp"

namespace cell::sim7545 {

/// The master's PD law (digest 000 §2.3): word = 0x800 + kp e + (kv / Ts) (e - e_prev), with e
/// the setpoint minus the encoder count, sampled every `period_s` and held until the next
/// sample. The thesis: kp 60 (55 for Z), kv 0.1, Ts 1 ms (config/gateway-ibm7545-dpr.yaml).
struct PdLaw {
  double kp = 60.0;
  double kv = 0.1;
  double period_s = 0.001;
};

/// The four joints' laws (J1, J2, Z, R) of a dpr7545 gateway config: driver.kp, driver.kv
/// (4 values each) and driver.sample_period_us. Errors (kConfig) name the file and the key.
Result<std::array<PdLaw, dpr7545::kJoints>> load_pd_laws(const std::string& gateway_config);

/// How one joint's closed loop (PdLaw + JointModel, encoder quantised to counts) followed the
/// worst-case reference of a speed and an acceleration limit (see simulate_follow).
struct FollowResult {
  double peak_dac = 0.0;           ///< largest |torque word - 0x800| the law asked for
  double peak_error_counts = 0.0;  ///< largest |setpoint - encoder|
};

/// What a joint can be asked to do with the torque word inside (1 - margin) of its range.
/// Counts and seconds.
struct FollowableLimits {
  double usable_dac = 0.0;  ///< (1 - margin) x 2047: the DAC range kept for the plan
  /// The speed whose friction and viscous torque alone use the usable range: no plan may
  /// go faster, whatever its acceleration. (usable - coulomb) x g / b.
  double speed_ceiling_counts_s = 0.0;
  /// At the given speed: the largest acceleration whose worst-case reference stays inside
  /// usable_dac (0 when even the speed does not fit).
  double accel_counts_s2 = 0.0;
  FollowResult at_limits;  ///< the worst case at (speed, accel_counts_s2)
};

/// Runs the worst case that a plan within |v| <= speed and |a| <= accel can ask of a joint
/// through the PD law and the plant, and returns what the law asked for. The reference, in
/// acceleration phases (each a step, as at a trapezoid's corners and the cubic via-point
/// joins, where the acceleration jumps):
///   1. from rest +a up to +v, cruise 0.1 s: the top demand (a + b v) / g + coulomb, and the
///      drop to b v / g + coulomb at full speed;
///   2. -a down through 0 to -v (the friction turns over), cruise 0.1 s, +a back to rest;
///   3. -a to -v/2, +a to +v/2, -a to rest: acceleration jumps of 2a at half speed (a cubic
///      via point between a braking and an accelerating segment).
/// The plant starts at rest on a count; the result is deterministic. Precondition: speed > 0,
/// accel > 0, law.period_s > 0.
FollowResult simulate_follow(const JointPlant& plant,
                             const PdLaw& law,
                             double speed_counts_s,
                             double accel_counts_s2);

/// The limits a joint can follow at `speed_counts_s` with `margin` (0.3: 30 %) of the torque
/// word's range kept in reserve: the largest acceleration up to which simulate_follow's peak
/// fits at every 0.5 % step from full speed in 10 s (the peak is not monotonic in it: the
/// encoder's one-count quantisation through the derivative term). Memoised per process.
FollowableLimits derive_limits(const JointPlant& plant,
                               const PdLaw& law,
                               double speed_counts_s,
                               double margin);

/// One joint of a robot file judged against its plant and PD law (counts and seconds inside;
/// `unit` is "deg" or "mm" for the messages).
struct JointJudgement {
  std::string joint;
  std::string unit;
  double counts_per_unit = 0.0;  ///< per deg or per mm
  double speed_counts_s = 0.0;   ///< the robot file's max speed
  double accel_counts_s2 = 0.0;  ///< the robot file's max acceleration
  FollowableLimits derived;      ///< at the robot file's speed
  FollowResult at_file_limits;   ///< the worst case at the robot file's speed and acceleration
  /// at_file_limits.peak_dac <= derived.usable_dac, and the file's acceleration not above the
  /// derived one
  bool ok = false;
};

/// Judges every joint of `robot_config` (speeds, accelerations, counts_per_deg / _mm) against
/// the plants of `sim_config` and the laws of `gateway_config`, with `margin` of the torque
/// word's range in reserve. Errors: the configs' own (kConfig, kNotFound), or kInvalidArgument
/// when the robot has no encoder scale or not 4 joints.
Result<std::vector<JointJudgement>> judge_robot_limits(const std::string& robot_config,
                                                       const std::string& sim_config,
                                                       const std::string& gateway_config,
                                                       double margin);

/// The share of the torque word's range the robot file's limits keep in reserve: 30 % for the
/// worst case of a plan (the figure) and 10 % for this kind of host's late exchanges.
/// At 0.3 alone the first ramp of a table job on a loaded 2-core host overflowed J2's word
/// (153 % of its range after 4 handshake timeouts in 18 periods; tests/crash, 2026-12-07).
inline constexpr double kDefaultMargin = 0.4;

/// `cell-sim-7545 limits [--robot F] [--sim F] [--gateway F] [--margin 0.4]`: prints the
/// derivation, joint by joint, and whether the robot file's limits fit. Exit codes: 0 every
/// joint fits, 1 one does not (or a config failed to load), 2 usage error.
int run_limits(int argc, char** argv);

}  // namespace cell::sim7545
