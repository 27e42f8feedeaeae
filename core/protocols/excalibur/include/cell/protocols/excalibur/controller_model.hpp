#pragma once

#include <cstdint>
#include <deque>
#include <limits>
#include <random>
#include <string>
#include <string_view>
#include <vector>

#include "cell/common/result.hpp"
#include "cell/protocols/excalibur/dialect.hpp"
#include "cell/protocols/excalibur/line_noise.hpp"

namespace cell::protocols::excalibur {

/// What the simulated controller is like. Angles are CONTROLLER angles q* [deg].
struct ControllerSettings {
  ControllerAngles lower_deg{};  ///< the controller's own joint limits
  ControllerAngles upper_deg{};
  ControllerAngles speed_deg_s{};  ///< peak joint speeds (analog servos)
  ControllerAngles initial_deg{};  ///< slave angles at power-up
  ControllerAngles master_deg{};   ///< master-arm angles (nobody moves the master arm here)
  /// Each move settles within +-accuracy_deg of its target, per joint, uniformly (the arm's
  /// electrical accuracy is +-0.30 deg, digest 001 §2.4).
  double accuracy_deg = 0.3;
  /// A systematic error added to every settled position (a miscalibrated joint: the thesis's
  /// A/D gain and zero errors, digest 001 §2.4). The queried angles show it.
  ControllerAngles bias_deg{};
  /// The controller checks its own tolerance (and reports "move not achieved (timeout)"). With
  /// false it trusts its servos, as in the thesis's calibration incident where only the host's
  /// position check saw the error.
  bool own_check = true;
  /// The 6809's slowness: a character that arrives sooner than this after the previous one is
  /// lost (overrun) and the line is answered with an overrun error. 0: keeps up with anything.
  double min_char_interval_s = 0.0;
  /// After each line the controller is busy (deaf) this long: characters arriving meanwhile
  /// are lost. The host's command delay must cover it.
  double busy_after_line_s = 0.0;
  double reply_delay_s = 0.0;   ///< a reply leaves this long after its command's terminator
  double gripper_time_s = 0.5;  ///< time to open or close the gripper
  /// Per accepted move: probability that the arm stops on the way and the controller reports
  /// "move not achieved (stopped)" (a random obstruction).
  double move_not_achieved_probability = 0.0;
  Mode power_up_mode = Mode::kHost;
  double teach_rate_hz = 10.0;       ///< teach sampling (digest 001 §1.1: 10 Hz)
  std::size_t teach_capacity = 800;  ///< 24 KB, about 80 s at 10 Hz
  std::uint64_t seed = 1;            ///< random settle errors, stops and noise

  /// Ok, or kInvalidArgument naming the first offending field and value.
  Status validate() const;
};

/// Counters of what the controller saw and did (since power-up).
struct ControllerCounters {
  std::uint64_t lines_in = 0;          ///< complete lines received (after noise)
  std::uint64_t commands_ok = 0;       ///< commands executed
  std::uint64_t errors_sent = 0;       ///< error replies (any reason)
  std::uint64_t overruns = 0;          ///< characters lost to the 6809's slowness
  std::uint64_t moves = 0;             ///< moves started
  std::uint64_t not_achieved = 0;      ///< "move not achieved" messages sent
  std::uint64_t line_errors_sent = 0;  ///< unsolicited line-error messages sent
  std::uint64_t resets = 0;
  std::uint64_t noise_faults_in = 0;   ///< faults injected into received lines
  std::uint64_t noise_faults_out = 0;  ///< faults injected into sent lines
};

/// A snapshot of the controller at a time.
struct ControllerStatus {
  ControllerAngles angles_deg{};  ///< true slave angles q*
  ControllerAngles target_deg{};  ///< last accepted move target
  Mode mode = Mode::kHost;
  bool moving = false;  ///< a host move is being achieved
  bool gripper_closed = false;
  bool gripper_moving = false;
  double tolerance_deg = 0.0;
  double timeout_s = 0.0;
  std::size_t taught_samples = 0;
  ControllerCounters counters;
  std::string last_rejected;  ///< the last line answered with an error, and why
};

/// The Excalibur controller's behaviour, as a pure state machine over time: bytes in (with the
/// window in which they arrived), lines out (each with the time it may leave). No I/O, no
/// clock: the caller passes monotonic times in seconds. The simulator runs it on a pty
/// (SimulatedController); tests drive it directly with exact times. Not thread-safe.
///
/// Behaviour (all in the dialect's syntax, so the simulator cannot drift from the driver):
///   - every command line gets exactly one reply: ok, joints, master, or error (syntax,
///     checksum, overrun, range, mode);
///   - a move in host mode is accepted (ok) and achieved by "analog servos": all joints start
///     and stop together, smoothstep profile, peak speeds speed_deg_s; the arm settles within
///     +-accuracy_deg; a target outside the controller's limits does not move the arm and sends
///     "move not achieved (limits)"; not within tolerance at the timeout: "(timeout)"; a random
///     stop: "(stopped)"; a new move replaces the one in progress;
///   - manual and teach modes: the slave follows the master arm (teach records 10 Hz samples);
///     playback replays them; moves are refused in these modes (error "mode");
///   - reset: back to power-up settings (mode, tolerance, timeout), motion stops, then "ready";
///   - a line longer than the buffer: unsolicited "line error (buffer full)".
class ControllerModel {
 public:
  /// `dialect` is copied. Starts powered up at `now_s` (a "ready" message is queued).
  ControllerModel(Dialect dialect, ControllerSettings settings, double now_s);

  /// Feeds bytes that arrived in the window (window_start_s, now_s]. Bytes that cannot all have
  /// arrived at the 6809's pace within that window are lost (the earliest ones), and so are
  /// bytes that arrived while it was busy: the generous reading, so a slow caller never causes
  /// false overruns. Per-byte noise applies here, per-line noise at each terminator.
  void receive(std::string_view bytes, double window_start_s, double now_s);

  /// Advances motion, arrival checks, timeouts, teach and playback to `now_s`.
  void advance(double now_s);

  /// Pops the next line due at `now_s` (terminator included, output noise applied); false when
  /// nothing is due.
  bool pop_output(double now_s, std::string& line);

  /// The next time at which advance/pop_output has something to do without new input
  /// (+infinity when nothing is pending).
  double next_event_s() const noexcept;

  /// True slave angles at `now_s` (advance first for events before it).
  ControllerAngles angles(double now_s) const noexcept;
  ControllerStatus status(double now_s) const;

  void set_noise(const NoiseSettings& noise) noexcept;
  void set_move_not_achieved_probability(double p) noexcept;
  /// The time every later reply leaves after its command (clamped to [0, 10) s): a slow
  /// controller, or a host that delivers its lines late.
  void set_reply_delay(double seconds) noexcept;
  const ControllerSettings& settings() const noexcept { return settings_; }
  const Dialect& dialect() const noexcept { return dialect_; }

 private:
  struct Segment {
    ControllerAngles from{};
    ControllerAngles to{};
    double t0 = 0.0;
    double duration = 0.0;
  };
  struct Outgoing {
    double at = 0.0;
    std::string line;
  };

  void feed(char c, double now);
  void end_line(double now);
  void process_line(const std::string& text, bool overrun, double now);
  void execute(const Command& command, double now);
  void reply(const Message& message, double now);
  void send_unsolicited(const Message& message, double now);
  void queue(const Message& message, double at);
  void start_segment(const ControllerAngles& to, double now);
  void freeze(double t);
  void start_move(const ControllerAngles& target, double now);
  ControllerAngles with_settle_error(const ControllerAngles& target);
  static ControllerAngles position(const Segment& s, double t) noexcept;
  double segment_end() const noexcept { return segment_.t0 + segment_.duration; }

  Dialect dialect_;
  ControllerSettings settings_;
  std::mt19937_64 rng_;
  LineNoise noise_in_;
  LineNoise noise_out_;

  // Input framing.
  std::string line_;
  bool line_overrun_ = false;
  bool line_overlong_ = false;
  double earliest_next_s_ = -std::numeric_limits<double>::infinity();
  double deaf_until_s_ = -std::numeric_limits<double>::infinity();

  // Output.
  std::deque<Outgoing> out_;
  std::string scratch_;

  // Controller state.
  Mode mode_ = Mode::kHost;
  double tolerance_deg_ = 1.0;
  double timeout_s_ = 10.0;
  Segment segment_;
  ControllerAngles target_{};
  bool move_active_ = false;
  double move_deadline_s_ = 0.0;
  double stop_at_s_ = std::numeric_limits<double>::infinity();
  double resettle_at_s_ = std::numeric_limits<double>::infinity();
  bool gripper_closed_ = false;
  bool gripper_moving_ = false;
  double gripper_done_s_ = 0.0;
  std::vector<ControllerAngles> taught_;
  std::size_t playback_index_ = 0;
  double next_sample_s_ = std::numeric_limits<double>::infinity();
  double last_advance_s_ = 0.0;
  ControllerCounters counters_;
  std::string last_rejected_;
};

}  // namespace cell::protocols::excalibur
