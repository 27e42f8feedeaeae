#pragma once

#include <array>
#include <atomic>
#include <chrono>
#include <cstdint>
#include <memory>
#include <mutex>
#include <string>
#include <thread>

#include "cell/kinematics/robot_model.hpp"
#include "cell/protocols/excalibur/dialect.hpp"
#include "cell/protocols/excalibur/serial_port.hpp"
#include "driver.hpp"
#include "drivers.hpp"

namespace cell::gateway {

/// How the driver turns a trajectory's setpoints into controller moves.
enum class ExcaliburFollow : std::uint8_t {
  /// Streams via points at the link's pace: whenever the link is free, the newest setpoint
  /// (led by stream_lead_s along its velocity) is sent if it moved by more than
  /// stream_min_step_deg; the final target is always sent exactly and position-checked.
  kStream,
  /// Point to point: waits until the setpoint stops, then sends only that target.
  kFinal,
};

/// The driver's settings (the gateway config's `driver:` section; see parse_excalibur_driver).
struct ExcaliburDriverOptions {
  std::string device;  ///< serial port or pty symlink (absolute)
  int baud = 9600;
  bool emulate_baud = false;          ///< pace at the byte time of `baud` (a pty has no baud rate)
  double open_timeout_s = 10.0;       ///< on activate, retry opening the port this long
  double tolerance_rad = 0.0;         ///< position check and controller tolerance (0: dialect's)
  double controller_timeout_s = 0.0;  ///< the controller's move timeout (0: dialect's)
  double arrival_margin_s = 2.0;  ///< host gives up waiting for "in position" after timeout + this
  bool position_check = true;     ///< query and compare after each move (digest 001 §1.3 step 6)
  int max_attempts = 5;           ///< port resets + restores (after the first failure) before
                                  ///< an operator fault
  double idle_poll_s = 0.2;       ///< angle query period when nothing moves
  ExcaliburFollow follow = ExcaliburFollow::kStream;
  double stream_lead_s = 0.05;       ///< via points lead the setpoint by this much of its velocity
  double stream_min_step_deg = 0.2;  ///< smaller changes are not worth a via point
  bool query_while_moving = true;    ///< alternate moves and queries while streaming
  /// In position = within the tolerance and two readings in a row within this of each other
  /// (the arm has stopped: one passing through the tolerance band is not "arrived").
  double settle_deg = 0.02;
  double gripper_time_s = 0.5;  ///< the gripper's aperture is not fed back: assumed time
  protocols::excalibur::Mode mode = protocols::excalibur::Mode::kHost;  ///< set on activate
  /// SCHED_FIFO priority of the link's threads (the exchange thread, which paces every
  /// character, and the port's reader); 0: normal scheduling. On a loaded host a normal thread
  /// can be held off long enough that a reply misses its timeout and the link counts as lost.
  int realtime_priority = 0;
  /// How long past its reply time (the dialect's reply time plus the line's byte times) a reply
  /// is still waited for before the exchange counts as a line error. The host's kernel passes
  /// every line, of a serial port as of a pty, through a worker thread at normal priority: on a
  /// loaded host it arrives late, and a port reset for a reply that was only late cuts the next
  /// lines and desynchronises replies (a stale "ok" for a query). A late reply is taken and
  /// counted (stats().late_replies, a warning in the log). In a restore after a line error only
  /// each step's first try waits so long, so a dead link is still found within seconds.
  double host_latency_s = 1.0;
};

/// Fault bits of the Excalibur driver (JointState::fault_bits).
enum ExcaliburFault : std::uint32_t {
  kFaultMoveNotAchieved = 0x1,  ///< the controller said "move not achieved"
  kFaultPositionCheck = 0x2,    ///< the arm did not come within tolerance in time
  kFaultLink = 0x4,             ///< line errors persisted beyond max_attempts: operator needed
  kFaultRefused = 0x8,          ///< the controller refused a command (mode, range)
};

/// Counters for logs, tests and benchmarks. Read with stats(); thread-safe.
struct ExcaliburDriverStats {
  std::uint64_t exchanges = 0;  ///< commands answered
  std::uint64_t line_errors =
      0;                         ///< garbled, missing or unexpected replies, controller-seen errors
  std::uint64_t recoveries = 0;  ///< exchanges that succeeded after a port reset + restore
  std::uint64_t escalations = 0;     ///< operator faults for a persistent line error
  std::uint64_t moves_sent = 0;      ///< move commands accepted (via points and targets)
  std::uint64_t targets_done = 0;    ///< final targets confirmed in position
  std::uint64_t targets_failed = 0;  ///< final targets reported failed
  std::uint64_t resyncs = 0;         ///< reported state snapped to the queried angles
  std::uint64_t late_replies = 0;    ///< replies after their reply time, within host_latency_s
  double worst_reply_s = 0.0;        ///< the longest wait for a reply taken (write to reply)
};

/// The RSI Excalibur on its RS-232 ASCII link (digest 001 §1-2), in the dialect of
/// config/controllers/excalibur.yaml.
///
/// Threads. read()/write() run on the servo thread at the gateway's cycle and only exchange the
/// latest state and setpoint with the driver's own I/O thread under a short mutex: no
/// allocation, no serial I/O, no blocking beyond that lock. The I/O thread holds the serial
/// conversation: via points and targets (converted to the controller's angles on every
/// command, theta2* = theta2 - 30 deg, theta3* = theta3 + 150 deg), angle queries (converted
/// back), the position check, modes, tolerance, the gripper, unsolicited messages.
///
/// Following a trajectory. The controller interpolates with its own analog servos, and the link
/// carries a few commands per second (the thesis: the link is the bottleneck), so the driver
/// sends the setpoint stream at the link's pace, not at the cycle (ExcaliburFollow::kStream),
/// and always the exact final target. `busy` is true from the first changed setpoint until the
/// final target is confirmed (or reported failed), so the servo does not call a move finished
/// before the arm is.
///
/// Position check (digest 001 case 17): after the final target the driver queries the angles
/// until every joint is within the tolerance and the arm has settled (two readings agree within
/// settle_deg; then the reported state is the requested target: no resync) or until the
/// controller's timeout plus a margin has passed (then the state is
/// resynced to the queried angles and the move is reported failed). With the check off the
/// requested value is assumed.
///
/// Recovery (digest 001 §1.3): a line error (garbled or missing reply, an unexpected reply, the
/// controller reporting a checksum, syntax or overrun error, a line-error message) resets the
/// port (close, reopen, flush), restores the controller's exact state (reset, mode, tolerance,
/// timeout, the target in progress) and retries; after max_attempts it becomes an operator
/// fault (kFaultLink, through CycleStatus::kFault and the servo's fault event). A "move not
/// achieved" message fails the move: the state is resynced to the arm's angles and the fault
/// (kFaultMoveNotAchieved) is reported; RESET clears it and the failed target is never re-sent.
class ExcaliburDriver final : public RobotDriver {
 public:
  ExcaliburDriver(const kinematics::RobotModel& model,
                  std::shared_ptr<const protocols::excalibur::Dialect> dialect,
                  ExcaliburDriverOptions options,
                  std::chrono::nanoseconds cycle);
  ~ExcaliburDriver() override;

  /// Checks the options against the dialect (tolerance and timeout within the controller's
  /// ranges). Errors: kConfig.
  Status on_configure() override;
  /// Opens the port (retrying for open_timeout_s: the simulator may start later), restores the
  /// controller (reset, mode, tolerance, timeout), reads the angles, starts the I/O thread.
  /// Errors: kIo (no port), kProtocol (the controller does not answer properly).
  Status on_activate() override;
  void on_deactivate() noexcept override;
  void on_cleanup() noexcept override;
  CycleStatus read(Clock::time_point now, JointState& state) override;
  CycleStatus write(Clock::time_point now, const JointSetpoint& setpoint) override;
  /// Queues a command for the I/O thread; the gripper state and faults change at once.
  /// Errors: kInvalidArgument (no lights, no gains, a mode the controller does not have, a
  /// tolerance outside its range), kNotReady (queue full, gripper absent from the dialect).
  Status command(DriverCommand command, const CommandArgs& args) override;
  Status check(DriverCommand command, const CommandArgs& args) const override;
  bool supports(DriverCommand command) const noexcept override;
  std::string describe_faults(std::uint32_t bits) const override;
  const DriverInfo& info() const noexcept override { return info_; }

  ExcaliburDriverStats stats() const;

 private:
  struct Queued {
    DriverCommand command = DriverCommand::kReset;
    protocols::excalibur::Mode mode = protocols::excalibur::Mode::kHost;
    double tolerance_deg = 0.0;
  };
  /// State shared between the servo thread and the I/O thread (guarded by mutex_).
  struct Shared {
    JointVector setpoint_q;
    JointVector setpoint_qd;
    JointVector handled;  ///< the last target the I/O thread finished (done or failed)
    JointVector q;        ///< reported joints
    JointVector qd;
    cell_robot_GripperState gripper = cell_robot_GRIPPER_UNKNOWN;
    bool gripper_moving = false;
    Clock::time_point gripper_done{};
    bool busy = false;
    std::uint32_t fault_bits = 0;
    bool host_mode = true;
    std::array<Queued, 16> queue{};
    std::size_t queue_head = 0;
    std::size_t queue_size = 0;
  };
  enum class Outcome : std::uint8_t { kOk, kLineError, kRefused, kStopped };
  struct Exchange {
    Outcome outcome = Outcome::kOk;
    protocols::excalibur::Message message;
    std::string error;
  };

  void io_loop();
  /// One command and its reply. `patient`: a reply late by up to host_latency_s is taken
  /// (every exchange but a restore's).
  Exchange exchange_once(const protocols::excalibur::Command& command,
                         protocols::excalibur::MessageKind expected, bool patient = true);
  void note_late_reply(std::string_view command, double waited_s);
  /// exchange_once, and on a line error: port reset + restore + retry, up to max_attempts,
  /// then escalate.
  Exchange transact(const protocols::excalibur::Command& command,
                    protocols::excalibur::MessageKind expected);
  bool reset_and_restore(std::string& why);
  /// The controller's state after a reset (mode, tolerance, timeout, the move under way).
  /// `patient`: its replies may be late by host_latency_s (on activation and RESET); else only
  /// each step's first try waits for a late reply (after a line error, where a dead link must
  /// be found within seconds).
  bool restore(std::string& why, bool patient);
  void escalate(const std::string& why);
  /// Reports a failure: fault bit and text, busy off, the target never re-sent. `resync`: query
  /// the angles and report them; `hold`: then command the arm to stay there.
  void fail(std::uint32_t bit, const std::string& why, bool resync, bool hold = false);
  void handle_unsolicited();
  void run_queued();
  /// One step of host-mode work; true when more work is due at once.
  bool step_host(Clock::time_point now);
  void poll(Clock::time_point now, bool follow_arm);
  bool query(JointVector& q_out, std::string& why);
  bool send_move(const JointVector& q);
  void complete(const JointVector& target);
  void set_reported(const JointVector& q, Clock::time_point now);
  protocols::excalibur::Command move_command(const JointVector& q) const;
  JointVector lead(const JointVector& q, const JointVector& qd) const;
  bool stopping() const noexcept { return stop_.load(std::memory_order_relaxed); }

  const kinematics::RobotModel& model_;
  std::shared_ptr<const protocols::excalibur::Dialect> dialect_;
  ExcaliburDriverOptions options_;
  DriverInfo info_;
  double tolerance_deg_ = 1.0;
  double timeout_s_ = 10.0;
  double reply_timeout_s_ = 0.2;

  std::unique_ptr<protocols::excalibur::SerialPort> port_;
  std::thread io_;
  std::atomic<bool> stop_{false};

  mutable std::mutex mutex_;  // guards shared_, fault_text_
  Shared shared_;
  std::string fault_text_;

  // I/O thread only.
  protocols::excalibur::Mode mode_ = protocols::excalibur::Mode::kHost;
  JointVector last_sent_;
  bool active_ = false;      ///< a target was sent and is not finished
  bool final_sent_ = false;  ///< the target in last_sent_ is the stationary setpoint
  Clock::time_point final_sent_at_{};
  Clock::time_point last_move_at_{};  ///< when the controller accepted the last move
  JointVector previous_;  ///< the last reading while waiting for the target
  bool have_previous_ = false;
  Clock::time_point next_poll_{};
  JointVector measured_;
  Clock::time_point measured_at_{};
  int ready_expected_ = 0;  ///< "ready" messages our own resets will cause
  bool link_down_ = false;  ///< escalated: retried every second, fault until RESET
  Clock::time_point next_relink_{};
  Clock::time_point reported_at_{};  ///< guarded by mutex_ (with shared_)
  std::string line_buffer_;

  std::atomic<std::uint64_t> exchanges_{0};
  std::atomic<std::uint64_t> line_errors_{0};
  std::atomic<std::uint64_t> recoveries_{0};
  std::atomic<std::uint64_t> escalations_{0};
  std::atomic<std::uint64_t> moves_sent_{0};
  std::atomic<std::uint64_t> targets_done_{0};
  std::atomic<std::uint64_t> targets_failed_{0};
  std::atomic<std::uint64_t> resyncs_{0};
  std::atomic<std::uint64_t> late_replies_{0};
  std::atomic<double> worst_reply_s_{0.0};
  std::uint64_t late_logged_ = 0;        ///< late_replies_ at the last warning (io thread)
  Clock::time_point late_logged_at_{};  ///< the last warning about late replies (io thread)
};

/// `driver: {kind: excalibur, device: run/excalibur.pty, dialect:
/// config/controllers/excalibur.yaml,
///  baud: 9600, emulate_baud: false, open_timeout_s: 10, tolerance_deg: 1.0,
///  controller_timeout_s: 10, arrival_margin_s: 2, position_check: true, max_attempts: 5,
///  idle_poll_s: 0.2, follow: stream, stream_lead_s: 0.05, stream_min_step_deg: 0.2,
///  query_while_moving: true, settle_deg: 0.02, gripper_time_s: 0.5, mode: host}`. Relative paths
///  are resolved
/// against CELL_HOME. The dialect file is loaded here, so its errors are config errors.
DriverFactory parse_excalibur_driver(config::MapReader& section);

}  // namespace cell::gateway
