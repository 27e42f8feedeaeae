// Unit tests of the 7545 DPR codec against the digest's cases (digest 000 §2, §9.2).
#include "cell/dpr7545/codec.hpp"

#include <array>
#include <cmath>
#include <limits>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

namespace cell::dpr7545 {
namespace {

using ::testing::HasSubstr;

constexpr double kTs = 0.001;  // 1 ms: sample_period = 1000

// Digest 000 §9.2 case 14: e = 5, e_prev = 3 -> 2548 (0x9F4).
TEST(PdTorque, ThesisCaseFourteenInRange) {
  const double t = pd_torque(60.0, 0.1, kTs, 5.0, 3.0);
  EXPECT_DOUBLE_EQ(t, 2548.0);
  EXPECT_EQ(torque_word(t), 0x9F4);
  EXPECT_TRUE(torque_word_valid(torque_word(t)));
  EXPECT_EQ(torque_dac(torque_word(t)), 500);
}

// Digest 000 §9.2 case 14: e = 40, e_prev = 0 -> 8448, out of range: the slave aborts.
TEST(PdTorque, ThesisCaseFourteenOutOfRangeIsRejectedNotClamped) {
  const double t = pd_torque(60.0, 0.1, kTs, 40.0, 0.0);
  EXPECT_DOUBLE_EQ(t, 8448.0);
  const std::uint16_t w = torque_word(t);
  EXPECT_EQ(w, 0x2100);  // the master writes 8448 as is; it is not clamped to 0xFFF
  EXPECT_FALSE(torque_word_valid(w));
  const std::array<std::uint16_t, kJoints> words = {w, kTorqueZero, kTorqueZero, kTorqueZero};
  EXPECT_EQ(check_torques(words), kErrTorqueJ1);
}

TEST(PdTorque, ZeroErrorIsZeroVolts) {
  EXPECT_EQ(torque_word(pd_torque(60.0, 0.1, kTs, 0.0, 0.0)), kTorqueZero);
  // Negative error drives below 0x800: e = -2, e_prev = -2 -> 0x800 - 120.
  EXPECT_EQ(torque_word(pd_torque(60.0, 0.1, kTs, -2.0, -2.0)), 0x800 - 120);
}

TEST(TorqueWord, TruncatesTowardZeroLikeTheMastersIntCast) {
  EXPECT_EQ(torque_word(2548.9), 2548);
  EXPECT_EQ(torque_word(0.7), 0);
  EXPECT_EQ(torque_word(4095.99), 0xFFF);
}

// Digest 000 §9.2 case 6: a torque of 0x1000 or a negative torque -> 0x100 (J1).
TEST(TorqueWord, EveryOutOfRangeValueKeepsAnInvalidBitAndNeverWraps) {
  EXPECT_EQ(torque_word(4096.0), 0x1000);
  EXPECT_EQ(torque_word(-1.0), 0xFFFF);
  EXPECT_EQ(torque_word(-4096.0), 0xF000);
  EXPECT_EQ(torque_word(65536.0 + 100.0), 0xFFFF);   // a 16-bit wrap would give 0x0064
  EXPECT_EQ(torque_word(-40000.0), 0x8000);
  EXPECT_EQ(torque_word(std::numeric_limits<double>::quiet_NaN()), 0xFFFF);
  for (double t = -70000.0; t <= 70000.0; t += 7.25) {
    const std::uint16_t w = torque_word(t);
    const bool in_range = t >= 0.0 && t < 4096.0;
    EXPECT_EQ(torque_word_valid(w), in_range) << "torque " << t << " word " << w;
  }
}

TEST(CheckTorques, FlagsEachJointItsOwnBit) {
  const std::array<std::uint16_t, kJoints> words = {0x0FFF, 0x1000, 0x0000, 0xFFFF};
  EXPECT_EQ(check_torques(words), kErrTorqueJ2 | kErrTorqueR);
  const std::array<std::uint16_t, kJoints> ok = {0x000, 0x800, 0xFFF, 0x123};
  EXPECT_EQ(check_torques(ok), 0);
}

TEST(SignExtend24, FollowsTheSlaveCodeByteTwoRule) {
  EXPECT_EQ(sign_extend_24(0x000000), 0);
  EXPECT_EQ(sign_extend_24(0x02B03C), 176188);
  EXPECT_EQ(sign_extend_24(0xFFEEF7), -4361);  // J1's MIN 0xEEF7 in the negative region
  EXPECT_EQ(sign_extend_24(0xFF5F1D), -41187);
  EXPECT_EQ(sign_extend_24(0xFFFFFF), -1);
  EXPECT_EQ(sign_extend_24(0xFF0000), -65536);
  // Byte 2 is not 0xFF: positive per the slave code (the bit-23 rule would say negative).
  EXPECT_EQ(sign_extend_24(0xFE0000), 0xFE0000);
  EXPECT_EQ(sign_extend_24(0x800000), 0x800000);
  // Only the low 24 bits of the counter count.
  EXPECT_EQ(sign_extend_24(0xAB000010), 16);
}

TEST(SignExtend24, RoundTripsTheCounterOverTheRepresentableRange) {
  for (std::int64_t counts = -65536; counts < 0xFF0000; counts += 997) {
    EXPECT_EQ(sign_extend_24(to_counter_24(counts)), counts);
  }
  // The counter wraps like the hardware's 24-bit up/down counter.
  EXPECT_EQ(to_counter_24(-1), 0xFFFFFFU);
  EXPECT_EQ(to_counter_24(0x1000005), 5U);
}

// Digest 000 §9.2 case 4.
TEST(OverrunBits, ThesisCaseFourThresholds) {
  const auto bits = [](std::array<std::int32_t, kJoints> p) {
    return overrun_bits(p, kThesisOverrunLimits);
  };
  EXPECT_EQ(bits({-4362, 0, 0, 0}), 0x02);
  EXPECT_EQ(bits({176189, 0, 0, 0}), 0x01);
  EXPECT_EQ(bits({0, 0, 95622, 0}), 0x10);
  EXPECT_EQ(bits({0, 0, 0, -41188}), 0x80);
  // The limits themselves are inside.
  EXPECT_EQ(bits({-4361, -2222, -381, -41187}), 0);
  EXPECT_EQ(bits({176188, 60222, 95621, 41187}), 0);
  // One count beyond on every joint and side.
  EXPECT_EQ(bits({-4362, 60223, -382, 41188}), 0x02 | 0x04 | 0x20 | 0x40);
  EXPECT_EQ(bits({176189, -2223, 95622, -41188}), 0x01 | 0x08 | 0x10 | 0x80);
}

TEST(OverrunBits, BitLayoutMatchesTheErrorTable) {
  EXPECT_EQ(overrun_bit(0, true), kErrJ1PositiveOverrun);
  EXPECT_EQ(overrun_bit(0, false), kErrJ1NegativeOverrun);
  EXPECT_EQ(overrun_bit(1, true), kErrJ2PositiveOverrun);
  EXPECT_EQ(overrun_bit(2, false), kErrZNegativeOverrun);
  EXPECT_EQ(overrun_bit(3, true), kErrRPositiveOverrun);
  EXPECT_EQ(overrun_bit(3, false), kErrRNegativeOverrun);
  EXPECT_EQ(torque_error_bit(0), kErrTorqueJ1);
  EXPECT_EQ(torque_error_bit(3), kErrTorqueR);
}

// Digest 000 §9.2 case 5 (lighting half).
TEST(Lighting, ThesisCaseFiveLatchValues) {
  EXPECT_EQ(lighting_latch(true, false), 0b01);
  EXPECT_EQ(lighting_latch(false, true), 0b10);
  EXPECT_EQ(lighting_latch(true, true), 0b11);
  EXPECT_EQ(lighting_latch(false, false), 0b00);
  EXPECT_TRUE(halogen_on(0b01));
  EXPECT_FALSE(fluorescent_on(0b01));
  EXPECT_TRUE(fluorescent_on(0b10));
  EXPECT_FALSE(halogen_on(0b10));
  EXPECT_TRUE(halogen_on(0b11) && fluorescent_on(0b11));
  EXPECT_FALSE(halogen_on(0) || fluorescent_on(0));
}

TEST(DescribeErrors, NamesEveryBitWithItsValue) {
  EXPECT_EQ(describe_errors(0), "");
  EXPECT_EQ(describe_errors(0x0001), "J1 positive overrun (0x0001)");
  const std::string text = describe_errors(0x0080 | 0x0400 | 0x1000 | 0x2000);
  EXPECT_THAT(text, HasSubstr("R negative overrun (0x0080)"));
  EXPECT_THAT(text, HasSubstr("too much torque was applied to Z"));
  EXPECT_THAT(text, HasSubstr("master did not provide torques in time (0x1000)"));
  EXPECT_THAT(text, HasSubstr("master did not finish its loop in time (0x2000)"));
  EXPECT_THAT(describe_errors(0x4000), HasSubstr("unknown error bit (0x4000)"));
  for (int b = 0; b < 14; ++b) {
    EXPECT_FALSE(error_meaning(static_cast<std::uint16_t>(1U << b)).empty()) << b;
  }
}

TEST(Registers, OffsetsAreTheThesisMap) {
  EXPECT_EQ(reg::kSamplePeriod, 0x00U);
  EXPECT_EQ(reg::kTimingA, 0x02U);
  EXPECT_EQ(reg::kTimingB, 0x04U);
  EXPECT_EQ(reg::kCommand, 0x06U);
  EXPECT_EQ(reg::kError, 0x08U);
  EXPECT_EQ(position_offset(0), 0x10U);
  EXPECT_EQ(position_offset(3), 0x1CU);
  EXPECT_EQ(velocity_offset(3), 0x26U);
  EXPECT_EQ(reg::kGripper, 0x2AU);
  EXPECT_EQ(acceleration_offset(0), 0x30U);
  EXPECT_EQ(torque_offset(0), 0x40U);  // the code's address, not Table 5.1's 0x20
  EXPECT_EQ(torque_offset(3), 0x46U);
  EXPECT_EQ(kDprSize, 0x48U);
  EXPECT_EQ(kDefaultPhysicalBase + kLightingOffset, 0xC9000U);
  // Homing order Z, 1, 2, R with the FH macro's parameters (digest 000 §2.4).
  EXPECT_EQ(kHomingSequence[0].joint, Joint::kZ);
  EXPECT_EQ(kHomingSequence[0].negative_torque, 0x640);
  EXPECT_EQ(kHomingSequence[3].joint, Joint::kR);
  EXPECT_EQ(kHomingSequence[3].positive_torque, 0x920);
}

}  // namespace
}  // namespace cell::dpr7545
