#pragma once

#include <array>
#include <cstdint>
#include <span>
#include <string>
#include <string_view>

#include "cell/dpr7545/registers.hpp"

/// Pure functions of the 7545 DPR protocol shared by the master (gateway driver) and the
/// slave (sim-7545), so that the simulator cannot drift from its driver. No state, no
/// allocation except describe_errors. All are thread-safe and, except describe_errors,
/// real-time safe.
namespace cell::dpr7545 {

/// The master's PD law (digest 000 §2.3/§5, Appendix B `prop_deriv_control`):
///   0x800 + kp * e + (kv / Ts) * (e - e_prev)
/// with e = desired - actual position in encoder counts and Ts the sample period in seconds.
/// Returns the unclamped value (it may lie outside the DAC range: see torque_word).
/// Digest 000 §9.2 case 14: kp 60, kv 0.1, Ts 1 ms, e 5, e_prev 3 -> 2548 (0x9F4).
double pd_torque(double kp, double kv, double sample_period_s, double error_counts,
                 double previous_error_counts) noexcept;

/// The master's `(int)` conversion of a PD value to the 16-bit word it writes: truncation
/// toward zero, then saturation to the int16/uint16 range so that a value out of the DAC range
/// can never wrap into 0x000..0xFFF. A value outside [0, 0xFFF] therefore always yields a word
/// with `word & 0xF000 != 0`, which the slave rejects: out of range aborts, it never clamps.
/// NaN yields 0xFFFF (rejected).
std::uint16_t torque_word(double torque) noexcept;

/// True when the slave accepts `word` (`word & 0xF000 == 0`).
constexpr bool torque_word_valid(std::uint16_t word) noexcept {
  return (word & kTorqueInvalidMask) == 0;
}

/// The slave's `check_torques`: the torque-error bits (0x100 << j) of the invalid words.
std::uint16_t check_torques(std::span<const std::uint16_t, kJoints> words) noexcept;

/// Signed DAC value of a valid torque word (word - 0x800), e.g. 0x9F4 -> +500.
constexpr int torque_dac(std::uint16_t word) noexcept {
  return static_cast<int>(word) - static_cast<int>(kTorqueZero);
}

/// The 24-bit up/down counter value of a position in counts (two's complement, mod 2^24).
constexpr std::uint32_t to_counter_24(std::int64_t counts) noexcept {
  return static_cast<std::uint32_t>(static_cast<std::uint64_t>(counts) & 0xFFFFFFU);
}

/// The slave's sign extension of a 24-bit counter (`get_robot_state`): byte 3 becomes 0xFF
/// when byte 2 is exactly 0xFF, else 0x00. We follow the slave code, not the general
/// bit-23 rule: counters 0x800000..0xFEFFFF read as large positive values (which the overrun
/// check then flags), and only -65536..-1 read as negative. Every overrun limit of the 7545
/// lies within that range (digest 000 §2.1).
constexpr std::int32_t sign_extend_24(std::uint32_t counter) noexcept {
  const std::uint32_t c = counter & 0xFFFFFFU;
  return ((c >> 16) & 0xFFU) == 0xFFU ? static_cast<std::int32_t>(c | 0xFF000000U)
                                       : static_cast<std::int32_t>(c);
}

/// A joint's overrun thresholds in counts (the slave's OVERRUN macro), inclusive: a position
/// equal to min or max is fine, one count beyond sets the bit.
struct OverrunLimits {
  std::int32_t min_counts = 0;
  std::int32_t max_counts = 0;
};

/// The thesis's thresholds (digest 000 §2.1): J1 -4361..176188, J2 -2222..60222,
/// Z -381..95621, R -41187..41187. (config/robots/ibm7545.yaml carries the same as
/// overrun_counts; simulators read them from there.)
inline constexpr std::array<OverrunLimits, kJoints> kThesisOverrunLimits = {{
    {-4361, 176188},
    {-2222, 60222},
    {-381, 95621},
    {-41187, 41187},
}};

/// The slave's `overrun_check`: the overrun byte for four sign-extended positions.
/// Digest 000 §9.2 case 4: J1 at -4362 -> 0x02, J1 at 176189 -> 0x01, Z at 95622 -> 0x10,
/// R at -41188 -> 0x80. (The macro compares the low word against MIN in the 0xFFFF high-word
/// region and the (high, low) pair against MSB:MAX elsewhere; over the range sign_extend_24
/// produces, that is exactly `pos < min` / `pos > max`.)
std::uint16_t overrun_bits(std::span<const std::int32_t, kJoints> positions,
                           std::span<const OverrunLimits, kJoints> limits) noexcept;

/// Lighting latch byte for the two lamp groups (Table 3.3): D0 halogen, D1 fluorescent.
/// Digest 000 §9.2 case 5: 0b01 halogen, 0b10 fluorescent, 0b11 both, 0 both off.
constexpr std::uint8_t lighting_latch(bool halogen_on, bool fluorescent_on) noexcept {
  return static_cast<std::uint8_t>((halogen_on ? kLightHalogen : 0U) |
                                   (fluorescent_on ? kLightFluorescent : 0U));
}
/// Halogen state of a latch byte.
constexpr bool halogen_on(std::uint8_t latch) noexcept { return (latch & kLightHalogen) != 0; }
/// Fluorescent state of a latch byte.
constexpr bool fluorescent_on(std::uint8_t latch) noexcept {
  return (latch & kLightFluorescent) != 0;
}

/// Meaning of one error bit as the thesis's display_errors prints it, e.g. 0x0001 ->
/// "J1 positive overrun", 0x1000 -> "torques late: the master did not provide torques in
/// time"; "" for a bit the slave never sets.
std::string_view error_meaning(std::uint16_t bit) noexcept;

/// Every set bit with its meaning, "; "-separated, each followed by its value in hex:
/// "J1 positive overrun (0x0001); torques late: ... (0x1000)". Empty for 0. Allocates.
std::string describe_errors(std::uint16_t bits);

}  // namespace cell::dpr7545
