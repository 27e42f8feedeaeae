#pragma once

#include <array>
#include <atomic>
#include <chrono>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <thread>

#include "cell/dpr7545/dpr.hpp"
#include "cell/dpr7545/registers.hpp"
#include "cell/dpr7545/sim_control.hpp"
#include "cell/dpr7545/transport.hpp"
#include "cell/kinematics/robot_model.hpp"
#include "driver.hpp"
#include "drivers.hpp"

namespace cell::gateway {

/// Driver-side fault bits, above the slave's 16-bit error register (fault_bits carries both).
inline constexpr std::uint32_t kDprFaultSlaveSilent = 0x10000;    ///< no answer from the slave
inline constexpr std::uint32_t kDprFaultProcedureTimeout = 0x20000;  ///< homing/gripper/leave

/// `driver:` keys of the dpr7545 driver (config/gateway-ibm7545-dpr.yaml).
struct Dpr7545Options {
  enum class Transport : std::uint8_t { kShm, kPhysical };
  Transport transport = Transport::kShm;             ///< `transport: shm | physical`
  std::string shm_name = "/cell-dpr7545";            ///< `shm_name` (sim-7545's)
  std::string physical_device = "/dev/mem";          ///< `physical_device`
  std::uint64_t physical_base_address = dpr7545::kDefaultPhysicalBase;  ///< `physical_base_address`
  int sample_period_us = dpr7545::kDefaultSamplePeriodUs;  ///< `sample_period_us`, = 1/cycle_hz
  std::array<double, dpr7545::kJoints> kp = dpr7545::kDefaultKp;  ///< `kp` [DAC/count]
  std::array<double, dpr7545::kJoints> kv = dpr7545::kDefaultKv;  ///< `kv` [DAC/(count/s)]
  /// `handshake_timeout_us`: the most one cycle (read + write) waits for the slave in total.
  double handshake_timeout_us = 900.0;
  bool lock_memory = false;       ///< `lock_memory`: mlockall(MCL_CURRENT | MCL_FUTURE)
  double activate_timeout_s = 10.0;  ///< `activate_timeout_s`: segment and slave must appear
  double homing_timeout_s = 120.0;   ///< `homing_timeout_s`
  double gripper_timeout_s = 10.0;   ///< `gripper_timeout_s`
  /// `engage_speed_fraction`: when control mode starts away from the host's setpoint, the
  /// reference closes the gap at this fraction of each joint's speed limit (bumpless start).
  double engage_speed_fraction = 0.1;
  /// `homing_record`: the file (HomingRecord, homing_record.hpp) where the driver keeps what
  /// it knows of the board while the arm is homed, so that a gateway started after this one
  /// died re-attaches to the board without homing again. Relative to the working directory
  /// (the run directory under `cell up`). Empty: none (every start needs a homing).
  std::string homing_record;

  /// Ok, or kConfig naming the key, value and rule (without file location).
  Status validate() const;
};

/// How closely the arm followed and how much of the torque word it took, over every exchange of
/// control mode since activation, joint by joint (J1, J2, Z, R). The following error is
/// |reference - encoder| in counts as the PD law saw it, from a histogram of 0.25-count bins
/// (p50 and p99 are bin upper edges; max is exact).
struct Dpr7545ServoStatistics {
  std::uint64_t exchanges = 0;
  /// Host setpoints that stepped further than a joint's top speed carries it in one exchange,
  /// closed at the engage speed instead (see write()).
  std::uint64_t steps_absorbed = 0;
  std::array<double, dpr7545::kJoints> error_p50_counts{};
  std::array<double, dpr7545::kJoints> error_p99_counts{};
  std::array<double, dpr7545::kJoints> error_max_counts{};
  /// max |torque word - 0x800| / 2047: 1.0 is the edge of the DAC's range (a torque fault).
  std::array<double, dpr7545::kJoints> torque_peak_fraction{};
};

/// What the driver counted since activation (read from another thread: relaxed atomics).
struct Dpr7545Counters {
  std::uint64_t periods = 0;             ///< handshakes completed
  std::uint64_t handshake_timeouts = 0;  ///< waits that ran out of the cycle's budget
  std::uint64_t slave_deadline_errors = 0;  ///< faults with 0x1000 or 0x2000 set
  std::uint64_t engages = 0;             ///< entries into control mode
  std::int64_t max_wait_ns = 0;          ///< longest time one cycle waited for the slave
  /// Largest |sampling instant - host cycle time| the setpoint was moved by (see write()).
  std::int64_t max_setpoint_skew_ns = 0;
  std::uint64_t rephases = 0;  ///< control mode restarted because its phase was bad
  /// Cycles whose handshake timed out while the simulator was not running at all (its process
  /// stalled: no board time passed, the arm stood still): not counted as link failures, up to
  /// kSimulatorSilentLimitNs of silence (simulator_stalled()). Always 0 on the real card.
  std::uint64_t simulator_stall_cycles = 0;
  std::int64_t max_simulator_silence_ns = 0;  ///< the longest such silence seen
  /// Time a procedure's timeout (engage, leave, homing, gripper) was held while the simulator
  /// stalled. Always 0 on the real card.
  std::int64_t procedure_stall_ns = 0;
};

/// The IBM 7545 master over the dual-port RAM (digest 000 §2): the gateway is the master, the
/// 80C196 slave (or sim-7545) does the I/O. Per sample, exactly as the thesis's
/// prop_deriv_control: read() waits for timing_A & 1 (saving the previous errors) and
/// timing_A & 2, reads the four positions (and velocities); write() computes the four PD
/// torques 0x800 + kp e + (kv / Ts)(e - e_prev) from the host's setpoint (e in counts), writes
/// them, sets timing_B = 1, waits until the slave clears timing_B or sets an error, and clears
/// timing_A.
///
/// Setpoint timing. The thesis's master consumed one path sample per slave period; the host
/// instead samples its trajectory at its own cycle time, which jitters against the slave's
/// sampling instant. At top speed (39 counts/ms on J1) half a millisecond of that jitter is a
/// 20-count error jump, enough to push the stiff PD word out of range. write() therefore
/// evaluates the setpoint at the sampling instant, q + qd (t_sample - now). The board samples on
/// its timer's exact grid, which track_sample follows from the period starts read() sees; a
/// simulator (sim-7545) publishes its sampling instants in its control block instead, since a
/// process's periods start with its scheduling jitter. (The D term keeps the thesis's kv / Ts.)
///
/// Units and signs: joints in rad / mm as the robot model has them; counts = value *
/// counts_per_unit * sign, where sign maps the model's conventions onto the 7545's counters
/// (J1, J2 counterclockwise, Z down, R clockwise positive: digest 000 §2.1, §5). With
/// config/robots/ibm7545.yaml (z_positive down, roll_positive clockwise) every sign is +1.
///
/// Errors and faults. Every bit of the error register faults the robot: overruns, torque out of
/// range (the PD word is never clamped: torque_word keeps an out-of-range value invalid and
/// the slave aborts), torques late (0x1000), loop late (0x2000); plus kDprFaultSlaveSilent
/// and kDprFaultProcedureTimeout. read() returns kFault with the bits (a slave error seen in
/// write() is reported by the next read(), since the host takes fault_bits from read()); the
/// slave has already zeroed its DACs; the driver writes 0x800 torques and leaves control
/// mode. The fault is latched until DriverCommand::kReset, which clears the error register and
/// restarts control mode (an overrun still present sets its bit again at once). A handshake
/// wait that runs out of the cycle's budget returns kRetry (counted).
///
/// Procedures across cycles (busy meanwhile): kHome and the gripper leave control mode
/// (command = 0, then two passes of the slave's idle loop seen through timing_A), write
/// command = 0x80 or the gripper register, and wait for the slave to clear it; then control
/// mode restarts. The slave looks at the gripper register only when idle (digest 000 §2.3),
/// hence the detour. Lighting writes the latch at 0xC9000 (window offset 0x1000) at once.
///
/// Re-attaching. The slave keeps counting while no master runs. With a homing_record, a driver
/// started after its predecessor died (kill -9, a crash: the slave faulted with torques late
/// and dropped the DACs) adopts the predecessor's homing, gripper and lights when the record
/// matches the board (homing_record_refusal: the same simulator, the counters within a
/// quarter second of full speed of the record, not a reset board), so the arm is held where
/// it stands once at rest, bumpless, and the job goes on without a homing. A record that does
/// not match is removed and logged with why: the robot must be homed, as without one.
///
/// Control mode starts only once the robot is homed (homed here or adopted), only
/// when read() is called periodically (the slave demands one exchange per sample from then
/// on), and only in a cycle that began on time (the slave anchors its period grid then: each
/// later cycle of ours finds the period start just after it wakes). If the first exchanges
/// show that the slave anchored late anyway (it was descheduled), the driver leaves control
/// mode and starts it again (counted as a rephase). It starts "bumpless": the reference begins at the measured position and closes the
/// gap to the host's setpoint at engage_speed_fraction of the speed limits.
///
/// Real time: read(), write() and the lighting/gains commands do not allocate; each cycle waits
/// at most handshake_timeout_us for the slave (spinning for 10 us, then 20 us sleeps).
/// Lifecycle calls may block: on_configure retries opening the segment and on_activate waits
/// for the slave's idle loop, up to activate_timeout_s together.
class Dpr7545Driver final : public RobotDriver {
 public:
  /// Opens the DPR transport (called by on_configure and, when the segment was replaced by a
  /// restarted simulator, by kReset).
  using TransportOpener = std::function<Result<std::unique_ptr<dpr7545::Transport>>()>;

  /// `model` must outlive the driver (the gateway owns both). Preconditions (checked by the
  /// factory): 4 joints with encoder scales; options validated; cycle == sample period.
  Dpr7545Driver(const kinematics::RobotModel& model, Dpr7545Options options,
                std::chrono::nanoseconds cycle, TransportOpener open);
  ~Dpr7545Driver() override;

  Status on_configure() override;
  Status on_activate() override;
  void on_deactivate() noexcept override;
  void on_cleanup() noexcept override;
  CycleStatus read(Clock::time_point now, JointState& state) override;
  CycleStatus write(Clock::time_point now, const JointSetpoint& setpoint) override;
  bool applied_setpoint(JointVector& out) const noexcept override;
  bool home_joints(JointVector& out) const override;
  Status command(DriverCommand command, const CommandArgs& args) override;
  bool supports(DriverCommand command) const noexcept override;
  std::string describe_faults(std::uint32_t bits) const override;
  const DriverInfo& info() const noexcept override { return info_; }

  /// A simulator silent this long is hung or gone: its missing periods count as link failures.
  static constexpr std::int64_t kSimulatorSilentLimitNs = 1'000'000'000;
  /// Counters since activation (thread-safe snapshot).
  Dpr7545Counters counters() const noexcept;
  /// Following error and torque statistics since activation (thread-safe snapshot).
  Dpr7545ServoStatistics statistics() const;
  /// Current PD gains (servo thread only).
  const std::array<double, dpr7545::kJoints>& kp() const noexcept { return kp_; }
  const std::array<double, dpr7545::kJoints>& kv() const noexcept { return kv_; }

 private:
  enum class Phase : std::uint8_t { kOff, kIdle, kEngage, kControl, kLeave, kHoming, kGripper,
                                    kFault };
  enum class Procedure : std::uint8_t { kNone, kHome, kGripperOpen, kGripperClose };

  std::int64_t now_ns() const noexcept;
  template <typename Done>
  bool wait(Done&& done, std::int64_t deadline_ns) noexcept;
  void read_idle(JointState& state) noexcept;
  void fill_state(JointState& state) const noexcept;
  CycleStatus fault(std::uint32_t bits, JointState& state) noexcept;
  bool ready_to_engage(Clock::time_point now) noexcept;
  CycleStatus handshake_read(JointState& state, std::int64_t start) noexcept;
  CycleStatus read_cycle(Clock::time_point now, JointState& state);
  /// The link's flight recorder: the last kTraceCycles reads (when, phase, outcome, the
  /// registers as they were left), written to the log once when as many reads in a row as
  /// the servo tolerates failed (it then faults on a lost link): what each side was doing.
  struct TraceEntry {
    std::int64_t start_ns = 0;
    std::int64_t spent_ns = 0;
    std::int64_t simulator_silent_ns = -1;  ///< -1: no simulator's liveness stamp
    std::uint16_t timing_a = 0;
    std::uint16_t timing_b = 0;
    std::uint16_t error = 0;
    std::uint16_t command = 0;
    std::uint8_t phase = 0;
    std::uint8_t status = 0;
    // The exchange's PD step (write()), per joint J1 J2 Z R [counts, DAC words]; `exchanged`
    // false when no torques went out in this cycle.
    bool exchanged = false;
    std::array<float, dpr7545::kJoints> desired{};  ///< the host's reference at the sample
    std::array<float, dpr7545::kJoints> actual{};   ///< the encoder
    std::array<float, dpr7545::kJoints> offset{};   ///< bumpless offset still being closed
    std::array<std::uint16_t, dpr7545::kJoints> word{};
    float sample_gap_us = 0;    ///< board (or host) time since the last sample
    float path_advance_us = 0;  ///< how far the path moved this cycle (-1: the host's clock)
    float derivative_us = 0;    ///< the D term's interval
  };
  static constexpr std::size_t kTraceCycles = 40;
  void log_link_trace(std::string_view what) const;
  /// The last exchanges' PD steps, logged once when the slave rejects a torque word.
  void log_torque_trace(std::uint32_t bits) const;
  bool fault_trace_logged_ = false;
  std::array<TraceEntry, kTraceCycles> trace_{};
  std::size_t trace_next_ = 0;
  int retries_in_a_row_ = 0;
  std::uint64_t stalls_logged_ = 0;      ///< simulator_stalls_ at the last "stalled" line
  std::int64_t stall_logged_ns_ = 0;     ///< when that line was written (at most one per 5 s)
  /// True when a simulated board's process did not run at all for more than five periods
  /// before `now` (its control block's liveness stamp), but less than
  /// kSimulatorSilentLimitNs, and its process exists: a period it did not start is its own
  /// stall, not a lost link. The real card (no control block): always false.
  bool simulator_stalled(std::int64_t now) noexcept;
  void track_sample(std::int64_t seen, bool started_before) noexcept;
  void check_phase(bool started_before, std::int64_t waited_ns) noexcept;
  void start_procedure() noexcept;
  Status begin_leave(Procedure next) noexcept;
  void stop_control() noexcept;
  /// Reads the window's simulator control block, if any: its clocks (sim_clock_) and its
  /// grace, which sets info_.link_retries. After the transport is (re)opened.
  void adopt_window() noexcept;
  /// on_activate: adopts the homing record when it matches the board (see the class comment).
  void adopt_homing_record();
  /// on_activate, after adopting a record with a gripper procedure under way: runs it to its
  /// end on the slave's idle loop (blocking, up to gripper_timeout_s).
  void complete_gripper(bool close);
  /// The recorder thread: rewrites the homing record while homed, removes it otherwise, and
  /// logs the servo's statistics every kStatisticsLogS while control mode exchanges.
  void record_homing(const std::stop_token& stop);
  /// Logs statistics() as one "servo statistics" line; returns its exchanges.
  std::uint64_t log_statistics() const;
  static constexpr std::chrono::seconds kStatisticsLog{30};
  /// Adds one exchange's errors and words to the statistics (servo thread; no allocation).
  void account(const std::array<double, dpr7545::kJoints>& errors) noexcept;
  /// True when the record on disk names the gripper procedure under way (procedure_) as under
  /// way, or there is none: the procedure may reach the board, and a successor that adopts the
  /// record completes it. Always true without a homing record.
  bool gripper_recorded() const noexcept;

  const kinematics::RobotModel& model_;
  Dpr7545Options options_;
  TransportOpener open_;
  DriverInfo info_;
  std::unique_ptr<dpr7545::Transport> transport_;
  std::unique_ptr<dpr7545::Dpr> dpr_;

  std::array<double, dpr7545::kJoints> counts_per_unit_{};  ///< signed (see the class comment)
  std::array<double, dpr7545::kJoints> engage_step_counts_{};  ///< per sample
  std::array<double, dpr7545::kJoints> speed_counts_s_{};      ///< top speed, counts/s
  std::array<double, dpr7545::kJoints> accel_counts_s2_{};     ///< acceleration limit
  std::array<double, dpr7545::kJoints> last_desired_{};  ///< the host's setpoint last exchange
  std::array<double, dpr7545::kJoints> last_rate_{};     ///< ... and its rate, counts/s
  bool have_last_desired_ = false;
  std::array<double, dpr7545::kJoints> kp_{};
  std::array<double, dpr7545::kJoints> kv_{};
  double period_s_;
  std::int64_t period_ns_;
  std::int64_t budget_ns_;

  Phase phase_ = Phase::kOff;
  Procedure procedure_ = Procedure::kNone;
  int leave_step_ = 0;
  std::int64_t phase_since_ns_ = 0;
  std::int64_t cycle_deadline_ns_ = 0;
  std::int64_t sample_ns_ = 0;       ///< when the slave sampled this period's positions
  std::int64_t last_sample_ns_ = 0;
  /// The board's clock between this exchange's sample and the previous one's [ns]: one
  /// period on the board (and a simulator that publishes its clock), else the sampling
  /// instants' gap on the host's clock.
  std::int64_t sample_gap_ns_ = 0;
  /// A simulator's control block, which tells the sampling instants (empty on the real card).
  std::optional<dpr7545::SimControl> sim_clock_;
  std::int64_t last_board_ns_ = 0;  ///< the simulator's board clock at the last sample (0: none)
  /// JointState::clock_advance_s of this cycle: the board's clock since the previous cycle
  /// (0 without a control-mode exchange), or -1 when the board's clock is not known (the real
  /// card, in an exchange).
  double clock_advance_s_ = -1.0;
  bool handshake_open_ = false;
  bool fresh_engage_ = false;
  bool homed_ = false;
  std::uint32_t latched_bits_ = 0;
  std::uint32_t pending_bits_ = 0;  ///< seen in write(), reported by the next read()
  cell_robot_GripperState gripper_ = cell_robot_GRIPPER_UNKNOWN;
  std::uint8_t lights_ = 0;
  std::int64_t last_read_ns_ = 0;
  std::int64_t last_cycle_start_ns_ = 0;  ///< read_cycle's previous start (procedure clocks)
  std::int64_t cycle_phase_ns_ = 0;  ///< the host's own cycle grid, as tracked
  int periodic_reads_ = 0;
  int phase_checks_ = 0;  ///< exchanges judged since control mode started
  int bad_phases_ = 0;
  bool rephase_ = false;

  std::array<std::int32_t, dpr7545::kJoints> position_{};
  std::array<double, dpr7545::kJoints> velocity_counts_s_{};
  std::array<double, dpr7545::kJoints> error_{};
  std::array<double, dpr7545::kJoints> offset_{};
  /// The PD loop's reference of the last exchange [counts] (desired + offset_), valid while
  /// applied_valid_.
  std::array<double, dpr7545::kJoints> applied_{};
  bool applied_valid_ = false;
  std::array<std::uint16_t, dpr7545::kJoints> words_{};
  /// The words of the exchange that faulted (words_ is zeroed by stop_control), for
  /// describe_faults.
  std::array<std::uint16_t, dpr7545::kJoints> fault_words_{};
  /// Idle reads in a row in which no joint moved by more than a count: control mode starts
  /// only on an arm at rest (after a fault the arm coasts with its DACs at 0 V; engaging the
  /// stiff PD on a moving joint saturates its D term and the slave aborts with 0x100 << j).
  int rest_reads_ = 0;

  std::atomic<std::uint64_t> periods_{0};
  std::atomic<std::uint64_t> timeouts_{0};
  std::atomic<std::uint64_t> simulator_stalls_{0};
  std::atomic<std::int64_t> max_simulator_silence_ns_{0};
  std::atomic<std::int64_t> procedure_stall_ns_{0};
  std::atomic<std::uint64_t> deadline_errors_{0};
  std::atomic<std::uint64_t> engages_{0};
  std::atomic<std::int64_t> max_wait_ns_{0};
  std::atomic<std::int64_t> max_skew_ns_{0};
  std::atomic<std::uint64_t> rephases_{0};

  // What the recorder thread reads (fill_state() writes them on the servo thread).
  mutable std::array<std::atomic<std::int32_t>, dpr7545::kJoints> shared_counts_{};
  mutable std::atomic<bool> shared_homed_{false};
  mutable std::atomic<int> shared_gripper_{cell_robot_GRIPPER_UNKNOWN};
  std::atomic<std::uint8_t> shared_lights_{0};
  /// The gripper state the record on disk names (HomingRecord::Gripper as int), kNoRecord when
  /// there is none (set by the recorder; see gripper_recorded()).
  static constexpr int kNoRecord = -1;
  std::atomic<int> recorded_gripper_{kNoRecord};
  std::uint32_t board_pid_ = 0;  ///< the simulator's pid (its control block); 0: the real card
  std::jthread recorder_;

  static constexpr std::size_t kErrorBins = 512;  ///< 0.25 count each: up to 128 counts
  std::array<std::array<std::atomic<std::uint32_t>, kErrorBins>, dpr7545::kJoints> error_bins_{};
  std::array<std::atomic<std::int32_t>, dpr7545::kJoints> error_max_quarters_{};
  std::array<std::atomic<std::int32_t>, dpr7545::kJoints> torque_peak_{};
  std::atomic<std::uint64_t> exchanges_{0};
  std::atomic<std::uint64_t> steps_absorbed_{0};
};

/// `driver: {kind: dpr7545, transport: shm, shm_name: /cell-dpr7545, sample_period_us: 1000,
/// kp: [60, 60, 55, 60], kv: [0.1, 0.1, 0.1, 0.1], ...}` (Dpr7545Options lists every key).
DriverFactory parse_dpr7545_driver(config::MapReader& section);

}  // namespace cell::gateway
