#pragma once

#include <array>
#include <atomic>
#include <cstdint>
#include <mutex>
#include <span>

#include "cell/dpr7545/codec.hpp"
#include "cell/dpr7545/dpr.hpp"
#include "cell/dpr7545/sim_control.hpp"
#include "joint_model.hpp"

namespace cell::sim7545 {

/// What the slave program needs besides its DPR window.
struct SlaveOptions {
  std::array<JointPlant, dpr7545::kJoints> plants = SimConfig::default_plants();
  /// Physical position of each joint at power-up [counts from home].
  std::array<double, dpr7545::kJoints> initial_counts{};
  /// The OVERRUN macro's thresholds (from the robot model's overrun_counts).
  std::array<dpr7545::OverrunLimits, dpr7545::kJoints> limits = dpr7545::kThesisOverrunLimits;
  double idle_poll_s = 100e-6;  ///< idle loop pass period
  double delay_s = 0.25;        ///< the `delay` routine
  double deadline_slack_s = 0.0;  ///< grace past each deadline (SimConfig::deadline_slack_us)
  bool fault_injection = true;  ///< serve the simulator mailbox
  double deadline_miss_after_s = 0.0;  ///< > 0: one injected deadline miss this long into control
};

/// What the slave is doing.
enum class SlaveMode : std::uint8_t { kIdle, kControl, kHoming, kGripper };

/// A copy of the slave's state for publication (the truth the world simulator and tests see).
struct SlaveSnapshot {
  std::array<double, dpr7545::kJoints> position_counts{};  ///< physical, from home
  std::array<double, dpr7545::kJoints> velocity_counts_s{};
  std::array<std::int32_t, dpr7545::kJoints> encoder{};     ///< what the slave reads
  std::array<std::uint16_t, dpr7545::kJoints> dac{};        ///< DAC words output
  SlaveMode mode = SlaveMode::kIdle;
  std::uint16_t error = 0;
  bool homed = false;           ///< homing completed: counters relate to the physical home
  bool gripper_closed = false;  ///< the gripper latch (0xF000) D0
  std::uint8_t lights = 0;      ///< the lighting latch (0xC9000)
  std::uint16_t sample_period_us = 0;
  std::uint64_t periods = 0;          ///< control periods run
  std::uint64_t deadline_errors = 0;  ///< times the slave set 0x1000 or 0x2000
  /// Periods whose master finished past the board's deadline but within deadline_slack_s
  /// (the board of Appendix C would have set 0x1000 or 0x2000).
  std::uint64_t late_served = 0;
  std::uint64_t stalls_absorbed = 0;  ///< waits in which this process itself was not running
  double late_max_us = 0.0;           ///< worst lateness of a period start since the last take
  /// How far the board's clock (the one the arm moves on) is behind the host's [s]: the time
  /// of every stall and late master the simulator absorbed in control mode. 0 on a host that
  /// kept every period.
  double absorbed_s = 0.0;
};

/// The 80C196 slave program of Appendix C (`slave.a96`), run against a DPR window and four
/// JointModels: main_loop / wait_for_command, control_mode with the per-sample handshake and
/// its checks (overrun, torque range, deadlines 0x1000 and 0x2000), find_home_mode (the FH
/// macro for Z, 1, 2, R), the gripper mode (delay, latch, delay) and the lighting latch
/// (read from the window at kLightingOffset). Digest 000 §2.3-§2.5.
///
/// Timing: TIMER2 becomes CLOCK_MONOTONIC. The control loop keeps a grid of sample periods
/// anchored when it enters control mode (`CLR TIMER2`); each period's deadlines (torques by
/// the end of the period, timing_A cleared by the end of the period) are measured from the
/// moment this program actually announces the period (timing_A = 1), and the master's flags
/// are tested before the deadline, so that the simulator's own scheduling delay is never
/// charged to the master; a wait in which this process itself was not running for more than
/// kOwnStallNs (a stalled machine) moves the deadline by that time (absorb_own_stall).
/// The sample period is read from the DPR each period (a value below 100 us, or 0, is taken
/// as 1000 us, the master's).
///
/// Physics: the joints advance on the board's clock, the DAC word held since torque_out
/// (zero-order hold). Outside control mode that clock runs with the host's. In control mode it
/// advances exactly one sample period per period, as the board's timer does: a period that
/// started late (this process stalled) or whose master was late within the grace
/// (deadline_slack_s) costs the arm no motion under held torques that the board would never
/// have applied. The board would have flagged such a master; the simulator serves it and
/// counts it (late_served, stalls_absorbed), and its clock falls behind the host's by the time
/// absorbed (SlaveSnapshot::absorbed_s). The encoders are read when the period starts; that
/// instant and the board's clock are published in the control block (sim_control.hpp) for the
/// master, whose path follows the board's clock. run() runs on one thread; snapshot() may be
/// called from any other.
class Slave {
 public:
  /// `window`: kWindowSize bytes (transport.hpp), must outlive the Slave.
  Slave(std::span<std::byte> window, const SlaveOptions& options);

  /// The program: initialisation, then main_loop until `stop` is set; zeroes the DACs on the
  /// way out. Blocking; call on the slave's thread.
  void run(const std::atomic<bool>& stop);

  /// The latest state (thread-safe; resets late_max_us).
  SlaveSnapshot take_snapshot();

  /// Tests: the next period of control mode, this process stalls for `ns` after announcing the
  /// period and before its positions, as a descheduled process would (thread-safe).
  void stall_next_period(std::int64_t ns) noexcept {
    stall_next_period_ns_.store(ns, std::memory_order_relaxed);
  }

  /// The limit/index sensor port at 0xB000 as the FH macro reads it: home bits (4 Z, 7 J1,
  /// 6 J2, 5 R) are active low, index bits (0 Z, 2 J1, 1 J2, 3 R) read 1 when an index pulse
  /// passed since the previous read. Slave thread only.
  std::uint8_t read_sensor_port() noexcept;

 private:
  bool stopping() const noexcept { return stop_->load(std::memory_order_relaxed); }
  void wait_for_command();
  void control_mode();
  /// One look of a handshake wait: now; a gap since `last_look_ns` longer than kOwnStallNs
  /// (this process was descheduled) is added to `deadline_ns` and counted.
  std::int64_t absorb_own_stall(std::int64_t& last_look_ns, std::int64_t& deadline_ns) noexcept;
  /// A wait step spins or sleeps 20 us; its wake-up on this kind of machine takes up to a few
  /// hundred microseconds (bench/servo): a longer gap is a stall, not a step.
  static constexpr std::int64_t kOwnStallNs = 400'000;
  void find_home_mode();
  void gripper_mode(bool close);
  void get_robot_state() noexcept;
  void overrun_check() noexcept;
  void zero_dacs() noexcept;
  void delay();
  void advance_to(std::int64_t t_ns) noexcept;
  /// The board's clock now, outside control mode (the host's, less the time absorbed).
  std::int64_t board_now() const noexcept;
  void set_error_bits(std::uint16_t bits) noexcept;
  void service_mailbox() noexcept;
  void publish() noexcept;
  std::int64_t period_ns() const noexcept;
  /// Polls (advancing the physics and serving the mailbox) until `done` or stop; false on stop.
  template <typename Done>
  bool idle_wait(Done&& done);

  dpr7545::Dpr dpr_;
  dpr7545::SimControl control_;
  SlaveOptions options_;
  std::array<JointModel, dpr7545::kJoints> joints_;
  const std::atomic<bool>* stop_ = nullptr;

  std::array<std::int32_t, dpr7545::kJoints> pos_{};
  std::array<std::int32_t, dpr7545::kJoints> pos_last_{};
  std::array<std::int16_t, dpr7545::kJoints> vel_{};
  std::array<std::uint16_t, dpr7545::kJoints> dac_{};
  std::array<std::uint64_t, dpr7545::kJoints> index_seen_{};
  std::int64_t t_phys_ns_ = 0;  ///< the board's clock up to which the joints have moved
  std::int64_t absorbed_ns_ = 0;  ///< the host's clock minus the board's (SlaveSnapshot)
  SlaveMode mode_ = SlaveMode::kIdle;
  bool homed_ = false;
  bool gripper_closed_ = false;
  bool arm_deadline_miss_ = false;
  std::atomic<std::int64_t> stall_next_period_ns_{0};
  bool arm_loop_late_ = false;
  bool auto_miss_done_ = false;
  std::int64_t control_since_ns_ = -1;
  std::uint64_t periods_ = 0;
  std::uint64_t deadline_errors_ = 0;
  std::uint64_t late_served_ = 0;
  std::uint64_t stalls_absorbed_ = 0;
  double late_max_us_ = 0.0;

  std::mutex mutex_;  // guards snapshot_
  SlaveSnapshot snapshot_;
};

}  // namespace cell::sim7545
