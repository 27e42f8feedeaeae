#pragma once

#include <cstdint>

#include "sim_config.hpp"

namespace cell::sim7545 {

/// One joint of the simulated 7545 as the slave sees it: a DAC word in, a 24-bit encoder
/// counter, a home sensor and index pulses out. Units: encoder counts, seconds, DAC units.
///
/// Dynamics: a = g * u - b * v - c * sign(v), with u = word - 0x800 the DAC value, g the
/// acceleration per DAC unit, b viscous damping (the motor's back-EMF through a voltage
/// amplifier) and c = g * coulomb_dac Coulomb friction, which also holds the joint at rest
/// while |g * u| <= c (stiction). Integrated by semi-implicit Euler in sub-steps of at most
/// 100 us (stable: b * h <= 0.025 for every default).
///
/// Choice of the defaults (g = 4000 counts/s^2 per DAC unit; b = 100, 180, 100, 250 /s for
/// J1, J2, Z, R; c = 30 DAC units). The thesis's gains are kp = 60 DAC units per count and
/// kv / Ts = 100 DAC units per count of change per 1 ms sample, with the error in counts: a
/// very stiff loop (34 counts of error fill the DAC range). With the master sampling every
/// 1 ms and the new word held until the next sample, the discrete closed loop
///   x'' = g (kp e + kv e') - b x'
/// is stable only for g below about 11,000; the kv term alone damps it best near g = 4000
/// (zeta 0.24, natural frequency 100 Hz). The viscous term adds the rest: zeta 0.36 (J1, Z)
/// to 0.55 (R) at about 100 Hz, settling in under 10 ms. b is bounded by the DAC range: at a
/// joint's top speed v (config/robots/ibm7545.yaml), b v / g is the torque needed to keep
/// moving, and b makes it about 1000 DAC units (half the range) for every joint, leaving the
/// other half for acceleration (a / g: 75 DAC units at the cubic paths' peak 300,000
/// counts/s^2) and friction. The steady-state following error at top speed is then about
/// 1000 / kp = 17 counts (0.02 deg on J1, 0.04 mm on Z). Friction c = 30 is below kp x 1
/// count (55 for Z): any error of a whole count overcomes it, so the loop comes to rest on the
/// setpoint's own count (a 7545 at home rests on 0, its J1/J2 soft limit, not one count below).
///
/// Positions: `position()` is the physical position in counts from home (the index pulse that
/// the homing sequence finds). The encoder counter reads round(position - zero) + offset mod
/// 2^24, where zero is set at power-up (the counter resets wherever the arm is) and by homing,
/// and offset models injected encoder faults. Mechanical stops lie at the overrun limits
/// widened by 2 % of the range: the joint stops dead there.
///
/// Not thread-safe; allocation-free; owned by the slave's thread.
class JointModel {
 public:
  /// `initial_counts`: physical position at power-up; `overrun`: the slave's limits (the
  /// mechanical stops lie beyond them).
  JointModel(const JointPlant& plant, double initial_counts, std::int32_t overrun_min,
             std::int32_t overrun_max);

  /// Advances `dt_s` seconds with DAC word `word` applied (an invalid word is never output:
  /// the slave rejects it before torque_out).
  void advance(std::uint16_t word, double dt_s) noexcept;

  /// Physical position [counts from home] and velocity [counts/s].
  double position() const noexcept { return position_; }
  double velocity() const noexcept { return velocity_; }

  /// The encoder count (unbounded) and the 24-bit counter register the slave reads.
  std::int64_t encoder_counts() const noexcept;
  std::uint32_t counter_24() const noexcept;

  /// Home sensor state: active (true) below home_edge_counts.
  bool home_active() const noexcept { return position_ < plant_.home_edge_counts; }
  /// Index pulses passed so far (monotonic) and the position of the last one.
  std::uint64_t index_pulses() const noexcept { return index_pulses_; }
  double last_index_position() const noexcept { return last_index_; }

  /// Power-up: the counter reads 0 at the current position.
  void reset_counter_here() noexcept;
  /// Homing: the counter reads 0 at `position` (the index pulse's, latched by the hardware).
  void reset_counter_at(double position) noexcept;
  /// Encoder faults: adds `counts` to the counter (the arm does not move).
  void add_encoder_offset(std::int64_t counts) noexcept { offset_ += counts; }
  /// Sets the injected offset so that the counter reads `counts` (overrun injection).
  void force_encoder_counts(std::int64_t counts) noexcept;
  /// Removes every injected offset.
  void clear_encoder_offset() noexcept { offset_ = 0; }

 private:
  JointPlant plant_;
  double position_;
  double velocity_ = 0.0;
  double zero_ = 0.0;
  std::int64_t offset_ = 0;
  double stop_min_;
  double stop_max_;
  std::uint64_t index_pulses_ = 0;
  double last_index_ = 0.0;
};

}  // namespace cell::sim7545
