#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <string_view>

#include "cell/common/result.hpp"
#include "cell/config/yaml.hpp"

/// The ASCII dialect of the RSI Excalibur controller (Motorola 6809, RS-232C; digest 001 §2).
///
/// The thesis names the controller's host functions (move to joint angles, query joint angles,
/// read the master arm, set the mode, set the accuracy tolerance, a controller timeout) and says
/// that the controller sends unsolicited messages at any time ("move not achieved", line
/// errors), but it gives NO syntax: no mnemonics, terminators, number format or checksum. The
/// syntax therefore lives in a file (config/controllers/excalibur.yaml) that a site adapts to
/// its controller's manual without recompiling: command and reply templates with named
/// placeholders, the line terminators, the number format, the checksum, the error codes, the
/// pacing delays and the reply timeout. The shipped file is a plausible design, marked as such.
///
/// Everything here is a pure function of its arguments over text lines (no I/O, no clock):
/// the gateway's driver and the controller simulator link the same code, so the simulator
/// cannot drift from the driver. A `Dialect` is immutable after loading: share it freely across
/// threads. Angles on the wire are the CONTROLLER's angles q* in degrees (theta2 = theta2* + 30,
/// theta3 = theta3* - 150; conversion in angles.hpp).
namespace cell::protocols::excalibur {

/// Number of joints the controller serves.
inline constexpr std::size_t kJointCount = 6;

/// Controller joint angles q* [deg], theta1*..theta6*, as they travel on the wire.
using ControllerAngles = std::array<double, kJointCount>;

/// The controller's operating modes (digest 001 §2.1).
enum class Mode : std::uint8_t {
  kHost,      ///< the host computer commands the arm
  kManual,    ///< the master arm drives the slave
  kTeach,     ///< master-arm motions are stored in the controller (10 Hz, 24 KB)
  kPlayback,  ///< the taught path is played back
};
inline constexpr std::size_t kModes = 4;

/// "host", "manual", "teach" or "playback" (the dialect file's keys).
std::string_view to_string(Mode mode) noexcept;

/// Host -> controller commands.
enum class CommandKind : std::uint8_t {
  kMoveJoints,    ///< move to joint angles (controller interpolates with its analog servos)
  kQueryJoints,   ///< ask for the slave arm's joint angles
  kReadMaster,    ///< ask for the master arm's joint angles
  kSetMode,       ///< host / manual / teach / playback
  kSetTolerance,  ///< accuracy tolerance of the controller's own position check [deg]
  kSetTimeout,    ///< how long the controller tries to achieve a move [s]
  kReset,         ///< controller reset: clears its input, stops, back to power-up settings
  kGripperOpen,   ///< optional in a dialect (the thesis lists no host gripper command)
  kGripperClose,  ///< optional in a dialect
};
inline constexpr std::size_t kCommandKinds = 9;

/// The dialect file's key of a command, e.g. "move_joints".
std::string_view to_string(CommandKind kind) noexcept;

/// One command with its arguments (only those of `kind` are meaningful).
struct Command {
  CommandKind kind = CommandKind::kQueryJoints;
  ControllerAngles angles_deg{};  ///< kMoveJoints: target q* [deg]
  Mode mode = Mode::kHost;        ///< kSetMode
  double tolerance_deg = 0.0;     ///< kSetTolerance
  double timeout_s = 0.0;         ///< kSetTimeout
};

/// Controller -> host messages: replies (exactly one per command) and unsolicited messages.
enum class MessageKind : std::uint8_t {
  kOk,               ///< reply: command accepted
  kJoints,           ///< reply to kQueryJoints: slave angles q* [deg]
  kMaster,           ///< reply to kReadMaster: master-arm angles [deg]
  kError,            ///< reply: command refused, with an error code
  kMoveNotAchieved,  ///< unsolicited: the last move was not achieved, with a reason code
  kLineError,        ///< unsolicited: the controller detected a communication error
  kReady,            ///< unsolicited: the controller (re)started: power-up settings
};
inline constexpr std::size_t kMessageKinds = 7;

/// The dialect file's key of a message, e.g. "move_not_achieved".
std::string_view to_string(MessageKind kind) noexcept;

/// True for the kinds the controller sends on its own, at any time.
constexpr bool is_unsolicited(MessageKind kind) noexcept {
  return kind == MessageKind::kMoveNotAchieved || kind == MessageKind::kLineError ||
         kind == MessageKind::kReady;
}

/// What an error reply (kError) means. The numeric codes are the dialect's (`error_codes`).
enum class ErrorReason : std::uint8_t {
  kSyntax,    ///< the line did not parse (garbled): a line error
  kChecksum,  ///< the line's checksum was wrong: a line error
  kOverrun,   ///< characters arrived faster than the controller can take them: a line error
  kRange,     ///< a value outside what the controller accepts (tolerance, timeout)
  kMode,      ///< not allowed in the current mode (a move while the master arm drives)
};
inline constexpr std::size_t kErrorReasons = 5;

/// Why a move was not achieved (`move_not_achieved_codes`).
enum class NotAchievedReason : std::uint8_t {
  kLimits,   ///< target outside the controller's own joint limits: the arm did not move
  kTimeout,  ///< not within tolerance when the controller's timeout expired
  kStopped,  ///< motion stopped on the way (obstruction, servo fault)
};
inline constexpr std::size_t kNotAchievedReasons = 3;

/// What a controller-detected line error was (`line_error_codes`).
enum class LineErrorReason : std::uint8_t {
  kOverrun,     ///< characters lost (the 6809 could not keep up)
  kBufferFull,  ///< a line longer than the controller's buffer, discarded
};
inline constexpr std::size_t kLineErrorReasons = 2;

/// Snake-case names used as keys in the dialect file ("syntax", "limits", "overrun", ...).
std::string_view to_string(ErrorReason reason) noexcept;
std::string_view to_string(NotAchievedReason reason) noexcept;
std::string_view to_string(LineErrorReason reason) noexcept;

/// True for error reasons that mean the line was damaged in transit (the host then resets the
/// port and restores the controller's state, digest 001 §1.3).
constexpr bool is_line_error(ErrorReason reason) noexcept {
  return reason == ErrorReason::kSyntax || reason == ErrorReason::kChecksum ||
         reason == ErrorReason::kOverrun;
}

/// One parsed controller message.
struct Message {
  MessageKind kind = MessageKind::kOk;
  ControllerAngles angles_deg{};  ///< kJoints, kMaster
  int code = 0;                   ///< kError, kMoveNotAchieved, kLineError: the wire code
};

/// How a line is protected. The shipped dialect uses CRC-16 (the thesis gives no checksum; a
/// site whose controller has none sets `none` and relies on the position check).
enum class ChecksumKind : std::uint8_t {
  kNone,
  kXor8,   ///< XOR of the body's bytes, 2 hex digits
  kSum8,   ///< sum of the body's bytes mod 256, 2 hex digits
  kCrc16,  ///< CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF) of the body, 4 hex digits
};

/// The checksum of `body` (0 for kNone). Pure, allocation-free.
std::uint16_t checksum(ChecksumKind kind, std::string_view body) noexcept;

/// Line framing.
struct Framing {
  std::string host_terminator = "\r";          ///< appended to every host line
  std::string controller_terminator = "\r\n";  ///< appended to every controller line
  std::string end_chars = "\r\n";   ///< any of these ends a received line; empty lines ignored
  std::size_t max_line_chars = 80;  ///< longer lines are garbage (controller buffer size)
  /// Lines starting with this are unsolicited even when damaged (so a garbled "move not
  /// achieved" is never taken for a reply). Empty: classify by the templates' mnemonics only.
  std::string unsolicited_prefix = "!";
  ChecksumKind checksum = ChecksumKind::kNone;
  char checksum_separator = '*';  ///< body, separator, hex digits
};

/// Number format on the wire.
struct NumberFormat {
  int angle_decimals = 2;      ///< decimals of joint angles [deg]
  int tolerance_decimals = 2;  ///< decimals of the tolerance [deg]
  int timeout_decimals = 1;    ///< decimals of the timeout [s]
  bool plus_sign = false;      ///< write "+10.00" rather than "10.00"
  /// Received numbers must carry exactly the configured decimals (catches dropped digits).
  bool strict_decimals = true;
  double max_abs_angle_deg = 999.99;  ///< largest |angle| the field holds
};

/// Host-side pacing and timing (the 6809 cannot keep up with its baud rate, digest 001 §1.4).
struct Timing {
  double char_delay_s = 0.0;     ///< extra delay after every character the host sends
  double command_delay_s = 0.0;  ///< quiet time after a reply before the next command
  /// Time the controller may take to start answering; the host's reply timeout is this plus
  /// the byte time of the command and of the longest reply at the link's baud rate.
  double reply_timeout_s = 0.2;
};

/// Controller facts the host must know.
struct ControllerDefaults {
  double tolerance_deg = 1.0;  ///< power-up tolerance (digest 001 §2.2: 1.0 deg)
  double timeout_s = 10.0;     ///< power-up move timeout
  double min_tolerance_deg = 0.05;
  double max_tolerance_deg = 20.0;
  double min_timeout_s = 0.5;
  double max_timeout_s = 120.0;
};

namespace detail {
class LineTemplate;
}  // namespace detail

/// A loaded dialect: immutable, shareable across threads. All format/parse methods are pure
/// and thread-safe; they allocate only the output string (format into a reserved string to
/// avoid that) and error messages.
class Dialect {
 public:
  /// Loads and validates a dialect file. Errors: kConfig with every problem at once, each
  /// "file:line:col: key 'a.b': what" (unknown keys, a template using a placeholder its command
  /// does not have or missing one it needs, templates that parse as each other, bad numbers).
  static Result<Dialect> load(const std::string& path);
  /// As load, from a parsed document (its path names the errors).
  static Result<Dialect> parse(const config::Document& doc);

  Dialect(Dialect&&) noexcept;
  Dialect& operator=(Dialect&&) noexcept;
  Dialect(const Dialect&);
  Dialect& operator=(const Dialect&);
  ~Dialect();

  /// The dialect's name (key `dialect`), for logs.
  const std::string& name() const noexcept { return name_; }
  const Framing& framing() const noexcept { return framing_; }
  const NumberFormat& numbers() const noexcept { return numbers_; }
  const Timing& timing() const noexcept { return timing_; }
  const ControllerDefaults& defaults() const noexcept { return defaults_; }
  /// Whether the dialect has this command (gripper commands are optional).
  bool has(CommandKind kind) const noexcept;

  // --- host side -------------------------------------------------------------------------

  /// Writes `command` as one line into `out` (replacing its content): body plus checksum,
  /// WITHOUT the terminator. Errors: kInvalidArgument for a non-finite value or one that does
  /// not fit the field (|angle| > max_abs_angle_deg), kNotReady when the dialect lacks the
  /// command (e.g. no gripper). Does not allocate when `out` has enough capacity.
  Status format(const Command& command, std::string& out) const;
  /// As format, returning a new string.
  Result<std::string> format(const Command& command) const;

  /// Parses one received line (terminator removed). Errors: kProtocol naming what is wrong and
  /// where, with the line quoted and non-printable bytes escaped: a non-printable byte, a
  /// missing or wrong checksum, an unknown mnemonic, a malformed number ("expected a number
  /// with 2 decimals for q3 at column 17, got '1x.5'"), trailing characters.
  Result<Message> parse(std::string_view line) const;

  /// True when a received line is (or, damaged, was meant to be) unsolicited: it starts with
  /// framing().unsolicited_prefix or with the mnemonic of an unsolicited template. Used by the
  /// serial reader to route lines before parsing.
  bool looks_unsolicited(std::string_view line) const noexcept;

  /// The reason of an error reply's wire code into `out`; false when the code is unknown.
  bool error_reason(int code, ErrorReason& out) const noexcept;
  /// "checksum error (code 2)", "unknown error code 9": meaning of an error reply's code.
  std::string describe_error(int code) const;
  /// Meaning of a "move not achieved" code.
  bool not_achieved_reason(int code, NotAchievedReason& out) const noexcept;
  std::string describe_not_achieved(int code) const;
  /// Meaning of a controller line-error code.
  std::string describe_line_error(int code) const;

  /// Wire code of a reason (for the simulator).
  int code_of(ErrorReason reason) const noexcept;
  int code_of(NotAchievedReason reason) const noexcept;
  int code_of(LineErrorReason reason) const noexcept;

  /// Longest line (body + checksum + terminator) the host can send / the controller can send,
  /// in characters: with the baud rate, this bounds an exchange's transmission time.
  std::size_t longest_command_chars() const noexcept { return longest_command_; }
  std::size_t longest_message_chars() const noexcept { return longest_message_; }

  // --- controller side (the simulator) --------------------------------------------------

  /// Parses a received command line (terminator removed). Errors: kProtocol as parse(), and
  /// the reason the controller answers with is put into `reason` (syntax or checksum).
  Result<Command> parse_command(std::string_view line, ErrorReason& reason) const;
  /// Writes a controller message as one line (body plus checksum, WITHOUT terminator).
  /// Errors: kInvalidArgument for a value that does not fit.
  Status format(const Message& message, std::string& out) const;
  Result<std::string> format(const Message& message) const;

 private:
  Dialect();

  std::string name_;
  Framing framing_;
  NumberFormat numbers_;
  Timing timing_;
  ControllerDefaults defaults_;
  std::array<std::string, kModes> mode_words_;
  std::array<std::unique_ptr<detail::LineTemplate>, kCommandKinds> commands_;
  std::array<std::unique_ptr<detail::LineTemplate>, kMessageKinds> messages_;
  std::array<int, kErrorReasons> error_codes_{};
  std::array<int, kNotAchievedReasons> not_achieved_codes_{};
  std::array<int, kLineErrorReasons> line_error_codes_{};
  std::size_t longest_command_ = 0;
  std::size_t longest_message_ = 0;

  friend class DialectBuilder;
};

/// A line for people: printable ASCII as is, everything else escaped ("\r", "\x07"), quoted.
std::string quote_line(std::string_view line);

}  // namespace cell::protocols::excalibur
