#pragma once

#include <cstddef>
#include <cstdint>
#include <optional>
#include <span>
#include <string_view>

#include "cell/common/result.hpp"
#include "cell/dpr7545/registers.hpp"

/// The simulator-only control block of the shared-memory window. It does not exist on the real
/// card (the physical window at 0xC9800 is unused address space): it carries the owner's pid
/// (so a stale segment can be told from a live one), a one-slot mailbox through which a tool or
/// a test asks the running simulator to inject a fault (`cell-sim-7545 inject ...`), and the
/// instant the simulator sampled its encoders for the current period. The real board samples
/// on its timer's exact grid, which the master can track; a simulator is a process on a shared
/// machine whose sampling instants wander with its scheduling, so it says when it sampled.
///
/// Layout at kSimControlOffset (little-endian fields, std::atomic_ref access):
///   +0x00 magic 0x35343537 ("7545")   +0x04 owner pid
///   +0x08 request sequence            +0x0C acknowledged sequence
///   +0x10 fault kind (SimFault)       +0x14 joint (0..3)
///   +0x18 value (signed, counts)      +0x1C result of the last request (0 = done)
///   +0x20 sampling instant of the current period, CLOCK_MONOTONIC ns (int64), written before
///         timing_A = 1
///   +0x28 the board's clock at that sample, ns (int64), written before timing_A = 1: in
///         control mode it advances exactly one sample period per period, as the board's
///         timer does, whatever the simulator's scheduling. The simulated arm moves on this
///         clock; a period the simulator absorbed (its own stall, or a master late within its
///         grace) leaves the clock behind the host's by that much (services/sim-7545/README.md).
///   +0x30 the simulator's grace past each deadline, us (uint32; 0 = the board's own timing):
///         how late a master it serves, and so how long a master may wait for it (its own
///         stalls) before the link counts as lost
///   +0x38 the simulator's latest pass through any of its loops, CLOCK_MONOTONIC ns (int64): a
///         live simulator passes at least once a period. A master that waited for a period
///         start in vain while this stood still knows the simulator was not running (its
///         process was stalled: no board time passed, the arm stood still), which is not a
///         lost link; one that stands still for good is (services/gateway/README.md).
/// A requester writes kind/joint/value, then increments the request sequence (release); the
/// simulator takes it (acquire), acts, writes the result and sets the acknowledged sequence to
/// the request's. One requester at a time (the mailbox has one slot).
namespace cell::dpr7545 {

inline constexpr std::size_t kSimControlOffset = 0x1800;
inline constexpr std::uint32_t kSimControlMagic = 0x35343537;

/// A fault the simulator can inject (services/sim-7545/README.md).
enum class SimFault : std::uint32_t {
  kNone = 0,
  /// The slave stalls past the sample deadline before checking for torques: error 0x1000.
  kDeadlineMiss = 1,
  /// The slave stalls past the deadline after accepting torques, before seeing timing_A
  /// cleared: error 0x2000.
  kLoopLate = 2,
  /// The joint's encoder counter jumps by `value` counts (the arm does not move).
  kEncoderGlitch = 3,
  /// The joint's encoder counter is offset to one count beyond its overrun limit on the
  /// side of `value`'s sign (> 0 positive): the slave's overrun check trips.
  kOverrun = 4,
  /// Removes every encoder offset (an operator moved the joints back by hand).
  kClear = 5,
};

/// "deadline-miss", "loop-late", "encoder-glitch", "overrun", "clear" (the inject command's
/// spelling); "none" for kNone.
std::string_view to_string(SimFault fault) noexcept;
/// The fault spelled `name`. Errors: kInvalidArgument listing the valid names.
Result<SimFault> parse_sim_fault(std::string_view name);

/// One mailbox request.
struct SimRequest {
  SimFault fault = SimFault::kNone;
  int joint = 0;
  std::int32_t value = 0;
  std::uint32_t sequence = 0;
};

/// Accessor of the control block in a window (kWindowSize bytes, see transport.hpp). Not an
/// owner. Every method is noexcept and allocation-free.
class SimControl {
 public:
  /// Precondition (CELL_CHECK): window of at least kWindowSize bytes, 8-byte aligned.
  explicit SimControl(std::span<std::byte> window);

  /// Simulator: stamps the magic and the owner pid.
  void initialise(std::uint32_t owner_pid) const noexcept;
  /// True when the magic is present.
  bool valid() const noexcept;
  /// The recorded owner pid (0 when none).
  std::uint32_t owner_pid() const noexcept;

  /// Requester: posts a request; returns its sequence number.
  std::uint32_t post(SimFault fault, int joint, std::int32_t value) const noexcept;
  /// Requester: the result once the simulator acknowledged `sequence` (0 = done, else an
  /// errno-like code: 1 = bad joint, 2 = unknown fault), nullopt while pending.
  std::optional<std::uint32_t> result(std::uint32_t sequence) const noexcept;

  /// Simulator: the pending request, if any (its sequence differs from the acknowledged one).
  std::optional<SimRequest> pending() const noexcept;
  /// Simulator: acknowledges `request` with `result`.
  void acknowledge(const SimRequest& request, std::uint32_t result) const noexcept;

  /// Simulator: the CLOCK_MONOTONIC instant [ns] it sampled the encoders for the period it is
  /// about to announce (store before timing_A = 1; release).
  void set_sample_time_ns(std::int64_t t) const noexcept;
  /// Master: that instant (acquire; read after timing_A & 2). 0 before the first period.
  std::int64_t sample_time_ns() const noexcept;
  /// Simulator: the board's clock at that sample [ns] (store before timing_A = 1; release).
  void set_board_time_ns(std::int64_t t) const noexcept;
  /// Master: the board's clock at the current period's sample (acquire; read after
  /// timing_A & 2). 0 before the first period, and from a simulator that does not write it.
  std::int64_t board_time_ns() const noexcept;
  /// Simulator: its grace past each deadline [us] (SimConfig::deadline_slack_us).
  void set_grace_us(std::uint32_t us) const noexcept;
  /// Master: that grace; 0 when none (the board's own timing, or an older simulator).
  std::uint32_t grace_us() const noexcept;
  /// Simulator: it is running now, at CLOCK_MONOTONIC `t` [ns] (relaxed: a liveness stamp).
  void set_alive_ns(std::int64_t t) const noexcept;
  /// Master: the simulator's latest pass [ns]; 0 from a simulator that does not write it.
  std::int64_t alive_ns() const noexcept;

 private:
  std::uint32_t load(std::size_t field) const noexcept;
  void store(std::size_t field, std::uint32_t value) const noexcept;
  std::int64_t load64(std::size_t field) const noexcept;  ///< 8-aligned fields
  void store64(std::size_t field, std::int64_t value) const noexcept;

  std::byte* base_;
};

}  // namespace cell::dpr7545
