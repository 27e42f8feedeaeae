#include "cell/dpr7545/codec.hpp"

#include <cmath>

#include <fmt/format.h>

namespace cell::dpr7545 {

double pd_torque(double kp, double kv, double sample_period_s, double error_counts,
                 double previous_error_counts) noexcept {
  // Appendix B: kv1 = kv_1 / sample_per; t = 0x0800 + kp*e + kv1*(e - el).
  return static_cast<double>(kTorqueZero) + kp * error_counts +
         (kv / sample_period_s) * (error_counts - previous_error_counts);
}

std::uint16_t torque_word(double torque) noexcept {
  if (std::isnan(torque)) {
    return 0xFFFF;
  }
  // `(int)` truncates toward zero. The 16-bit DOS int would wrap a value beyond +-32767 (and a
  // wrapped value could land in the valid range); we saturate instead, so that every value
  // outside [0, 0xFFF] keeps a bit of 0xF000 set and the slave rejects it.
  const double t = std::trunc(torque);
  if (t < -32768.0) {
    return 0x8000;
  }
  if (t > 65535.0) {
    return 0xFFFF;
  }
  const auto value = static_cast<std::int32_t>(t);
  return static_cast<std::uint16_t>(static_cast<std::uint32_t>(value) & 0xFFFFU);
}

std::uint16_t check_torques(std::span<const std::uint16_t, kJoints> words) noexcept {
  std::uint16_t bits = 0;
  for (int j = 0; j < kJoints; ++j) {
    if (!torque_word_valid(words[static_cast<std::size_t>(j)])) {
      bits = static_cast<std::uint16_t>(bits | torque_error_bit(j));
    }
  }
  return bits;
}

std::uint16_t overrun_bits(std::span<const std::int32_t, kJoints> positions,
                           std::span<const OverrunLimits, kJoints> limits) noexcept {
  std::uint16_t bits = 0;
  for (int j = 0; j < kJoints; ++j) {
    const auto i = static_cast<std::size_t>(j);
    if (positions[i] < limits[i].min_counts) {
      bits = static_cast<std::uint16_t>(bits | overrun_bit(j, false));
    } else if (positions[i] > limits[i].max_counts) {
      bits = static_cast<std::uint16_t>(bits | overrun_bit(j, true));
    }
  }
  return bits;
}

std::string_view error_meaning(std::uint16_t bit) noexcept {
  switch (bit) {
    case kErrJ1PositiveOverrun:
      return "J1 positive overrun";
    case kErrJ1NegativeOverrun:
      return "J1 negative overrun";
    case kErrJ2PositiveOverrun:
      return "J2 positive overrun";
    case kErrJ2NegativeOverrun:
      return "J2 negative overrun";
    case kErrZPositiveOverrun:
      return "Z positive overrun";
    case kErrZNegativeOverrun:
      return "Z negative overrun";
    case kErrRPositiveOverrun:
      return "R positive overrun";
    case kErrRNegativeOverrun:
      return "R negative overrun";
    case kErrTorqueJ1:
      return "too much torque was applied to J1 (torque word out of range)";
    case kErrTorqueJ2:
      return "too much torque was applied to J2 (torque word out of range)";
    case kErrTorqueZ:
      return "too much torque was applied to Z (torque word out of range)";
    case kErrTorqueR:
      return "too much torque was applied to R (torque word out of range)";
    case kErrTorquesLate:
      return "torques late: the master did not provide torques in time";
    case kErrLoopLate:
      return "loop late: the master did not finish its loop in time";
    default:
      return {};
  }
}

std::string describe_errors(std::uint16_t bits) {
  std::string out;
  for (int b = 0; b < 16; ++b) {
    const auto bit = static_cast<std::uint16_t>(1U << b);
    if ((bits & bit) == 0) {
      continue;
    }
    const std::string_view meaning = error_meaning(bit);
    out += fmt::format("{}{} (0x{:04x})", out.empty() ? "" : "; ",
                       meaning.empty() ? std::string_view("unknown error bit") : meaning, bit);
  }
  return out;
}

}  // namespace cell::dpr7545
