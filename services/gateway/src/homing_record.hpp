#pragma once

#include <array>
#include <cstdint>
#include <optional>
#include <string>

#include "cell/common/result.hpp"
#include "cell/dpr7545/registers.hpp"

namespace cell::gateway {

/// What a DPR 7545 master knew about its board, kept in a file so that a master started after
/// the previous one died (kill -9, a crash) can take the arm over where it stands instead of
/// homing it again. The 7545's encoder counters are the slave's: they keep counting while no
/// master runs, so the homing survives the master as long as the board was not reset.
///
/// Written by the driver's recorder thread (not the servo thread) every
/// kHomingRecordPeriodS while the arm is homed, removed when a homing starts. JSON:
///   {"version": 1, "board_pid": N, "counts": [J1, J2, Z, R], "gripper": "open"|"closed"|
///    "opening"|"closing"|"unknown", "lights": L}
struct HomingRecord {
  /// The simulator's pid from its control block (sim_control.hpp); 0 on the real card, which
  /// has no such block. A simulator started again is a new board, unhomed.
  std::uint32_t board_pid = 0;
  std::array<std::int32_t, dpr7545::kJoints> counts{};  ///< encoder counts when written
  /// The gripper (the relay's latch is write-only: the master remembers it): as last completed,
  /// or the procedure under way (written before the board is given it: the latch is then
  /// either as before or as the procedure leaves it; a successor completes the procedure).
  enum class Gripper : std::uint8_t { kUnknown, kOpen, kClosed, kOpening, kClosing };
  Gripper gripper = Gripper::kUnknown;
  std::uint8_t lights = 0;  ///< the lighting latch as last written (write-only as well)
};

/// "open", "closed", "opening", "closing" or "unknown".
const char* gripper_name(HomingRecord::Gripper gripper) noexcept;

/// How often the recorder rewrites the record while the arm is homed [s].
inline constexpr double kHomingRecordPeriodS = 0.1;

/// The record at `path`, nullopt when there is none. Errors: kIo (unreadable) or
/// kInvalidArgument (malformed), naming the file and what is wrong: such a record is never
/// adopted.
Result<std::optional<HomingRecord>> load_homing_record(const std::string& path);

/// Writes `record` to `path` atomically (a temporary file beside it, then rename), creating
/// the directory. Errors: kIo naming the path.
Status save_homing_record(const std::string& path, const HomingRecord& record);

/// Whether a record may be adopted for the board as read now: `board_pid` its control block's
/// owner (0: the real card), `counts` its counters. The rule:
///   - a simulator's record names that simulator (its pid);
///   - the counters are within `tolerance_counts` of the record, joint by joint (the arm moved
///     at most that far since the last write: one record period at full speed and its coast
///     after the slave dropped the torques);
///   - counters that all read 0 while the record's do not are a board that was reset.
/// nullopt when adoptable, else the reason (for the log).
std::optional<std::string> homing_record_refusal(
    const HomingRecord& record, std::uint32_t board_pid,
    const std::array<std::int32_t, dpr7545::kJoints>& counts,
    const std::array<double, dpr7545::kJoints>& tolerance_counts);

}  // namespace cell::gateway
