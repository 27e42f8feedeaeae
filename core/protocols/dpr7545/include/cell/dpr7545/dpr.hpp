#pragma once

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <span>

#include "cell/dpr7545/registers.hpp"

namespace cell::dpr7545 {

/// Typed access to the DPR registers and the lighting latch inside a transport's window
/// (transport.hpp). Both sides use it: the master (gateway driver) and the slave (sim-7545).
///
/// Memory ordering. The window is memory shared with another process (POSIX shared memory) or
/// with another processor (the physical card). Every access is a std::atomic_ref access of the
/// register's natural width (16-bit words, 8-bit latch), lock-free and address-free on every
/// platform we build for, hence valid across processes. Every load is `acquire` and every
/// store is `release`: the handshake of digest 000 §2.3 publishes data by writing a flag after
/// the data (slave: positions, then timing_A = 3; master: torques, then timing_B = 1), so a
/// release store of the flag orders the data stores before it, and an acquire load of the
/// flag orders the data loads after it. No access needs sequential consistency: neither side
/// relies on a store followed by a load of a *different* register being ordered (no Dekker
/// pattern). On x86 (TSO) acquire and release compile to plain moves and only restrain the
/// compiler; on the physical card the DPR is uncached ISA memory, so the moves reach the bus
/// in program order.
///
/// Positions are two words (low, then high), written by the slave in that order. A read after
/// the handshake's timing_A & 2 is consistent; outside the handshake (idle slave) use
/// position_consistent(), which re-reads until the high word is stable. Where the window is
/// 4-byte aligned (the shared-memory window of the simulated slave always is) the pair is one
/// 32-bit atomic access on both sides, never torn even when the simulator is preempted
/// between the words.
///
/// Not an owner: the window must outlive the Dpr. Every method is noexcept, allocation-free
/// and real-time safe; any number of threads may use one Dpr (each access is atomic).
class Dpr {
 public:
  /// Views `window`. Precondition (CELL_CHECK): at least kWindowSize bytes, 2-byte aligned.
  explicit Dpr(std::span<std::byte> window);

  /// Word at byte offset `offset` (even, < kDprSize), acquire.
  std::uint16_t load(std::size_t offset) const noexcept;
  /// Stores word `value` at byte offset `offset` (even, < kDprSize), release.
  void store(std::size_t offset, std::uint16_t value) const noexcept;

  std::uint16_t sample_period_us() const noexcept { return load(reg::kSamplePeriod); }
  std::uint16_t timing_a() const noexcept { return load(reg::kTimingA); }
  std::uint16_t timing_b() const noexcept { return load(reg::kTimingB); }
  std::uint16_t command() const noexcept { return load(reg::kCommand); }
  std::uint16_t error() const noexcept { return load(reg::kError); }
  std::uint16_t gripper() const noexcept { return load(reg::kGripper); }
  void set_sample_period_us(std::uint16_t v) const noexcept { store(reg::kSamplePeriod, v); }
  void set_timing_a(std::uint16_t v) const noexcept { store(reg::kTimingA, v); }
  void set_timing_b(std::uint16_t v) const noexcept { store(reg::kTimingB, v); }
  void set_command(std::uint16_t v) const noexcept { store(reg::kCommand, v); }
  void set_error(std::uint16_t v) const noexcept { store(reg::kError, v); }
  void set_gripper(std::uint16_t v) const noexcept { store(reg::kGripper, v); }

  /// Position dword of `joint` (0..3) in counts: low word, then high word. Consistent when
  /// read inside the handshake (after timing_A & 2).
  std::int32_t position(int joint) const noexcept;
  /// Position dword read outside the handshake (idle slave): two full reads that agree (at most
  /// 5 reads), so a concurrent slave write between its low and high word is not returned.
  std::int32_t position_consistent(int joint) const noexcept;
  /// Slave: writes the position dword, low word then high word.
  void set_position(int joint, std::int32_t counts) const noexcept;

  /// Velocity word of `joint`: POS - POS_last in counts per sample (16-bit, wraps).
  std::int16_t velocity(int joint) const noexcept;
  void set_velocity(int joint, std::int16_t counts_per_sample) const noexcept;
  /// Acceleration word of `joint`: VEL - VEL_last in counts per sample^2.
  std::int16_t acceleration(int joint) const noexcept;
  void set_acceleration(int joint, std::int16_t counts_per_sample2) const noexcept;
  /// Torque (DAC) word of `joint` as the master wrote it.
  std::uint16_t torque(int joint) const noexcept;
  void set_torque(int joint, std::uint16_t word) const noexcept;

  /// Writes the lighting latch byte (lighting_latch()), release.
  void write_lighting(std::uint8_t latch) const noexcept;
  /// Reads the latch byte back. Meaningful in the simulator only: the real latch is
  /// write-only (a read of 0xC9000 returns whatever the bus floats to).
  std::uint8_t read_lighting() const noexcept;

  /// The window this Dpr views.
  std::span<std::byte> window() const noexcept { return window_; }

 private:
  std::uint16_t* word(std::size_t offset) const noexcept;

  std::span<std::byte> window_;
};

}  // namespace cell::dpr7545
