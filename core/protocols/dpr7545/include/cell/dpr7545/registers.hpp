#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <string_view>

/// The IBM 7545 master/slave dual-port-RAM (DPR) contract of the AVRS thesis (Bloch 1994):
/// register offsets, bit meanings and the constants of the slave's code. Digest 000 §2 is the
/// reference; where the digest leaves a doubt the seed's Appendix B (master C) and Appendix C
/// (slave 80C196 assembly) decide, and each such place says which was followed.
///
/// Every register is a little-endian 16-bit word at an even byte offset; positions are two
/// words (low word first). Offsets are bytes from the start of the DPR (master 0xC8000,
/// slave 0xE000). Header-only constants: no allocation, usable anywhere.
namespace cell::dpr7545 {

/// Number of joints of the 7545 and order of every per-joint register: J1, J2, Z, R.
inline constexpr int kJoints = 4;

/// Joint index in register order.
enum class Joint : std::uint8_t { kJ1 = 0, kJ2 = 1, kZ = 2, kR = 3 };

/// Short joint names in register order, as the thesis prints them ("1", "2", "z", "r").
inline constexpr std::array<std::string_view, kJoints> kJointNames = {"J1", "J2", "Z", "R"};

/// Register byte offsets (digest 000 §2.2, Table 5.1 and the slave code).
namespace reg {
inline constexpr std::size_t kSamplePeriod = 0x00;  ///< word, master writes: period in us
inline constexpr std::size_t kTimingA = 0x02;       ///< word, handshake (see kTimingA* bits)
inline constexpr std::size_t kTimingB = 0x04;       ///< word, handshake (see kTimingB* bits)
inline constexpr std::size_t kCommand = 0x06;       ///< word, kCommandControl / kCommandFindHome
inline constexpr std::size_t kError = 0x08;         ///< word, error bits (kErr*)
inline constexpr std::size_t kPosition = 0x10;      ///< 4 x dword: J1 0x10, J2 0x14, Z 0x18, R 0x1C
inline constexpr std::size_t kVelocity = 0x20;      ///< 4 x word (slave code only): counts/sample
inline constexpr std::size_t kGripper = 0x2A;       ///< word, kGripperOpen / kGripperClose
inline constexpr std::size_t kAcceleration = 0x30;  ///< 4 x word (slave code only)
/// 4 x word: torque (DAC) words. Table 5.1 says 0x20, which would collide with the
/// velocities; the slave code (`LD TOR,#0E040H`) and the master's `t_1 = ...8040` put them at
/// 0x40. Digest 000 §2.2: we follow the code.
inline constexpr std::size_t kTorque = 0x40;
}  // namespace reg

/// Byte offset of joint `joint`'s position dword (low word at the offset, high word at +2).
constexpr std::size_t position_offset(int joint) noexcept {
  return reg::kPosition + 4 * static_cast<std::size_t>(joint);
}
/// Byte offset of joint `joint`'s velocity word.
constexpr std::size_t velocity_offset(int joint) noexcept {
  return reg::kVelocity + 2 * static_cast<std::size_t>(joint);
}
/// Byte offset of joint `joint`'s acceleration word.
constexpr std::size_t acceleration_offset(int joint) noexcept {
  return reg::kAcceleration + 2 * static_cast<std::size_t>(joint);
}
/// Byte offset of joint `joint`'s torque word.
constexpr std::size_t torque_offset(int joint) noexcept {
  return reg::kTorque + 2 * static_cast<std::size_t>(joint);
}

/// Bytes the register map spans (0x00 .. 0x47).
inline constexpr std::size_t kDprSize = 0x48;

/// The memory window both transports expose: the interface card decodes 0x0C8xxx to the DPR
/// and 0x0C9xxx to the lighting latch (digest 000 §1.1), so a window of 8 KiB from 0xC8000
/// holds the DPR at offset 0 and the latch at kLightingOffset. The simulator's shared-memory
/// segment mirrors this layout exactly (plus a simulator-only block, sim_control.hpp).
inline constexpr std::size_t kWindowSize = 0x2000;
/// Offset of the lighting latch (0xC9000 - 0xC8000). An 8-bit write-only D flip-flop on the
/// real card (Table 3.3); reading it back is meaningful in the simulator only.
inline constexpr std::size_t kLightingOffset = 0x1000;
/// Physical base address of the DPR on the master's ISA bus.
inline constexpr std::uint64_t kDefaultPhysicalBase = 0xC8000;

// --- command register (digest 000 §2.3) -----------------------------------------------------
/// Control mode: the slave runs its per-sample I/O loop (`BBS TEMP1,0,control_mode`). Writing
/// 0 ends control mode without error.
inline constexpr std::uint16_t kCommandControl = 0x0001;
/// Find home (bit 7): the slave homes Z, J1, J2, R, then clears the register.
inline constexpr std::uint16_t kCommandFindHome = 0x0080;

// --- gripper register ------------------------------------------------------------------------
/// Open the gripper (bit 0); the slave clears the register when done.
inline constexpr std::uint16_t kGripperOpen = 0x0001;
/// Close the gripper (bit 7); the slave clears the register when done.
inline constexpr std::uint16_t kGripperClose = 0x0080;
/// Slave's gripper latch (address 0xF000 on the slave): D0 = 1 energises the relay and
/// CLOSES the gripper, D0 = 0 opens it (Table 3.4; its caption wrongly says "lighting").
inline constexpr std::uint8_t kGripperLatchClosed = 0x01;

// --- timing_A / timing_B handshake bits (digest 000 §2.3 table) ------------------------------
inline constexpr std::uint16_t kTimingAStart = 0x0001;          ///< slave: period started
inline constexpr std::uint16_t kTimingAPositions = 0x0002;      ///< slave: positions written
inline constexpr std::uint16_t kTimingAVelocities = 0x0004;     ///< slave: velocities written
inline constexpr std::uint16_t kTimingAAccelerations = 0x0008;  ///< slave: accelerations written
/// The values the slave writes in sequence: 1, 3, 7, 0xF. The master writes 0 to end a period.
inline constexpr std::uint16_t kTimingAAll = 0x000F;
/// timing_B bit 0: master says "torques ready"; the slave writes 0 when it accepted them.
inline constexpr std::uint16_t kTimingBTorquesReady = 0x0001;
/// Driver extension (not in the thesis): the master sets this bit of timing_B before writing
/// command = control, and the slave's control_mode entry (`ST 0,[TIMING_B]`) clears it. The
/// master thus knows when the slave has passed its initialisation and that the next
/// timing_A & 1 belongs to a real period, not to the idle loop's stale 0xF (a race the
/// thesis's master leaves open). The slave only ever tests bit 0, so the marker is inert.
inline constexpr std::uint16_t kTimingBEngageMarker = 0x8000;

// --- error register (digest 000 §2.3 table; master's display_errors) -------------------------
inline constexpr std::uint16_t kErrJ1PositiveOverrun = 0x0001;
inline constexpr std::uint16_t kErrJ1NegativeOverrun = 0x0002;
inline constexpr std::uint16_t kErrJ2PositiveOverrun = 0x0004;
inline constexpr std::uint16_t kErrJ2NegativeOverrun = 0x0008;
inline constexpr std::uint16_t kErrZPositiveOverrun = 0x0010;
inline constexpr std::uint16_t kErrZNegativeOverrun = 0x0020;
inline constexpr std::uint16_t kErrRPositiveOverrun = 0x0040;
inline constexpr std::uint16_t kErrRNegativeOverrun = 0x0080;
inline constexpr std::uint16_t kErrTorqueJ1 = 0x0100;  ///< "too much torque was applied to joint 1"
inline constexpr std::uint16_t kErrTorqueJ2 = 0x0200;
inline constexpr std::uint16_t kErrTorqueZ = 0x0400;
inline constexpr std::uint16_t kErrTorqueR = 0x0800;
inline constexpr std::uint16_t kErrTorquesLate = 0x1000;  ///< "PS/2 did not provide torques in time"
inline constexpr std::uint16_t kErrLoopLate = 0x2000;     ///< "PS/2 did not finish its loop in time"
/// The overrun byte, which the slave's overrun_check rewrites on every pass.
inline constexpr std::uint16_t kErrOverrunMask = 0x00FF;
inline constexpr std::uint16_t kErrTorqueMask = 0x0F00;
inline constexpr std::uint16_t kErrDeadlineMask = 0x3000;

/// Overrun bit of a joint: positive 0x01 << 2j, negative 0x02 << 2j.
constexpr std::uint16_t overrun_bit(int joint, bool positive) noexcept {
  return static_cast<std::uint16_t>((positive ? 0x01U : 0x02U) << (2 * joint));
}
/// Torque-out-of-range bit of a joint: 0x100 << j.
constexpr std::uint16_t torque_error_bit(int joint) noexcept {
  return static_cast<std::uint16_t>(0x100U << joint);
}

// --- torque words (digest 000 §2.3) -----------------------------------------------------------
/// 12-bit offset-binary DAC word for 0 V (`zero_dacs` writes it whenever the slave is idle).
inline constexpr std::uint16_t kTorqueZero = 0x0800;
/// Largest valid torque word; the slave rejects any word with `torque & 0xF000 != 0`.
inline constexpr std::uint16_t kTorqueMax = 0x0FFF;
inline constexpr std::uint16_t kTorqueInvalidMask = 0xF000;

// --- sample period ----------------------------------------------------------------------------
/// The master writes 1000 (1 ms) into sample_period before each move (`*sample_timer=1000`).
inline constexpr std::uint16_t kDefaultSamplePeriodUs = 1000;

// --- lighting latch (digest 000 §2.5, Table 3.3) ----------------------------------------------
inline constexpr std::uint8_t kLightHalogen = 0x01;      ///< D0
inline constexpr std::uint8_t kLightFluorescent = 0x02;  ///< D1

// --- PD gains of the thesis (digest 000 §5) ---------------------------------------------------
/// kp per joint (J1, J2, Z, R) in DAC units per encoder count.
inline constexpr std::array<double, kJoints> kDefaultKp = {60.0, 60.0, 55.0, 60.0};
/// kv per joint in DAC units per (count/s); the master uses kv / Ts = 100 per count of
/// error change per sample at Ts = 1 ms. (The OCR duplicates kv_2 where kv_Z should be.)
inline constexpr std::array<double, kJoints> kDefaultKv = {0.1, 0.1, 0.1, 0.1};

// --- homing (digest 000 §2.4, the slave's FH macro) -------------------------------------------
/// One FH invocation: `FH joint, +torque, -torque, home_bit, index_bit`. Bits are of the
/// slave's limit/index sensor port at 0xB000.
struct HomingStep {
  Joint joint;
  std::uint16_t positive_torque;  ///< DAC word driving away from the home sensor
  std::uint16_t negative_torque;  ///< DAC word driving toward the home sensor
  int home_bit;
  int index_bit;
};

/// The slave homes in this order: Z, 1, 2, R (`find_home_mode`).
inline constexpr std::array<HomingStep, kJoints> kHomingSequence = {{
    {Joint::kZ, 0x900, 0x640, 4, 0},
    {Joint::kJ1, 0x900, 0x700, 7, 2},
    {Joint::kJ2, 0x900, 0x700, 6, 1},
    {Joint::kR, 0x920, 0x6A0, 5, 3},
}};

}  // namespace cell::dpr7545
