#include "dpr7545_driver.hpp"

#include <sys/mman.h>
#include <sys/prctl.h>
#include <sys/resource.h>
#include <sys/types.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <csignal>
#include <cmath>
#include <condition_variable>
#include <ctime>
#include <filesystem>
#include <mutex>
#include <thread>
#include <utility>

#include <fmt/format.h>

#include "cell/common/log.hpp"
#include "cell/dpr7545/codec.hpp"
#include "cell/dpr7545/sim_control.hpp"
#include "homing_record.hpp"

namespace cell::gateway {
namespace {

namespace d = dpr7545;
using d::kJoints;

constexpr std::int64_t kSpinNs = 10'000;   // spin this long before sleeping
constexpr long kSleepNs = 20'000;          // then sleep in steps of this
constexpr int kEngageTimeoutPeriods = 50;  // the slave must enter control mode within this
constexpr int kLeaveTimeoutPeriods = 200;  // ... and return to its idle loop within this
constexpr int kRestReads = 20;  // idle reads without motion before control mode may start

void cpu_relax() noexcept {
#if defined(__x86_64__) || defined(__i386__)
  __builtin_ia32_pause();
#endif
}

std::size_t idx(int j) { return static_cast<std::size_t>(j); }

/// The servo thread's timer slack: 1 us instead of the default 50 us, so the short sleeps of
/// the handshake waits are short. Once per thread; prctl is a plain system call.
void tighten_timer_slack() noexcept {
  thread_local bool done = false;
  if (!done) {
    prctl(PR_SET_TIMERSLACK, 1000UL, 0UL, 0UL, 0UL);
    done = true;
  }
}

}  // namespace

Status Dpr7545Options::validate() const {
  if (sample_period_us < 100 || sample_period_us > 60000) {
    return Error{Errc::kConfig,
                 fmt::format("key 'driver.sample_period_us': must be in [100, 60000], got {}",
                             sample_period_us)};
  }
  for (int j = 0; j < kJoints; ++j) {
    if (!std::isfinite(kp[idx(j)]) || kp[idx(j)] < 0 || !std::isfinite(kv[idx(j)]) ||
        kv[idx(j)] < 0) {
      return Error{Errc::kConfig, fmt::format("key 'driver.kp'/'driver.kv': gains of joint {} "
                                              "must be finite and >= 0, got kp {} kv {}",
                                              d::kJointNames[idx(j)], kp[idx(j)], kv[idx(j)])};
    }
  }
  if (!(handshake_timeout_us >= 50 && handshake_timeout_us <= sample_period_us)) {
    return Error{Errc::kConfig,
                 fmt::format("key 'driver.handshake_timeout_us': must be in [50, "
                             "sample_period_us = {}] (a cycle never waits past its period), got {}",
                             sample_period_us, handshake_timeout_us)};
  }
  if (!(activate_timeout_s >= 0 && activate_timeout_s <= 600)) {
    return Error{Errc::kConfig, fmt::format("key 'driver.activate_timeout_s': must be in [0, "
                                            "600], got {}",
                                            activate_timeout_s)};
  }
  if (!(homing_timeout_s > 0) || !(gripper_timeout_s > 0)) {
    return Error{Errc::kConfig, "keys 'driver.homing_timeout_s', 'driver.gripper_timeout_s': "
                                "must be > 0"};
  }
  if (!(engage_speed_fraction > 0 && engage_speed_fraction <= 1)) {
    return Error{Errc::kConfig, fmt::format("key 'driver.engage_speed_fraction': must be in "
                                            "(0, 1], got {}",
                                            engage_speed_fraction)};
  }
  if (transport == Transport::kShm) {
    if (auto s = d::validate_shm_name(shm_name); !s) {
      return Error{Errc::kConfig, "key 'driver.shm_name': " + s.error().message};
    }
  }
  return ok_status();
}

Dpr7545Driver::Dpr7545Driver(const kinematics::RobotModel& model, Dpr7545Options options,
                             std::chrono::nanoseconds cycle, TransportOpener open)
    : model_(model),
      options_(std::move(options)),
      open_(std::move(open)),
      kp_(options_.kp),
      kv_(options_.kv),
      period_s_(options_.sample_period_us * 1e-6),
      period_ns_(static_cast<std::int64_t>(options_.sample_period_us) * 1000),
      budget_ns_(static_cast<std::int64_t>(options_.handshake_timeout_us * 1000.0)) {
  info_.name = "dpr7545";
  info_.dof = kJoints;
  info_.cycle = cycle;
  info_.max_setpoint_advance = 2 * cycle;  // a late cycle catches up one period, no more
  // Map the model's joint conventions onto the 7545's counters (J1, J2 counterclockwise, Z
  // down, R clockwise positive).
  const kinematics::ScaraModel* scara = model_.scara();
  for (int j = 0; j < kJoints; ++j) {
    const auto& spec = model_.joints()[idx(j)];
    double sign = 1.0;
    if (scara != nullptr && j == 2 && scara->z_direction == kinematics::ZDirection::kUp) {
      sign = -1.0;
    }
    if (scara != nullptr && j == 3 &&
        scara->roll_sense == kinematics::RotationSense::kCounterClockwise) {
      sign = -1.0;
    }
    counts_per_unit_[idx(j)] = sign * spec.counts_per_unit;
    engage_step_counts_[idx(j)] =
        options_.engage_speed_fraction * spec.max_speed * spec.counts_per_unit * period_s_;
    speed_counts_s_[idx(j)] = spec.max_speed * spec.counts_per_unit;
    accel_counts_s2_[idx(j)] = spec.max_accel * spec.counts_per_unit;
  }
  words_.fill(d::kTorqueZero);
}

Dpr7545Driver::~Dpr7545Driver() = default;

std::int64_t Dpr7545Driver::now_ns() const noexcept {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

template <typename Done>
bool Dpr7545Driver::wait(Done&& done, std::int64_t deadline_ns) noexcept {
  const std::int64_t start = now_ns();
  for (;;) {
    if (done()) {
      return true;
    }
    const std::int64_t t = now_ns();
    if (t >= deadline_ns) {
      return done();
    }
    if (t - start < kSpinNs) {
      for (int i = 0; i < 32; ++i) {
        cpu_relax();
      }
    } else {
      const timespec ts{0, std::min<long>(kSleepNs, static_cast<long>(deadline_ns - t))};
      nanosleep(&ts, nullptr);
    }
  }
}

Status Dpr7545Driver::on_configure() {
  const auto give_up = std::chrono::steady_clock::now() +
                       std::chrono::duration<double>(options_.activate_timeout_s);
  bool logged = false;
  for (;;) {
    auto t = open_();
    if (t) {
      transport_ = std::move(*t);
      dpr_ = std::make_unique<d::Dpr>(transport_->window());
      log::info("dpr7545", "DPR transport open", {{"transport", transport_->describe()}});
      return ok_status();
    }
    // Only a segment that does not exist yet is worth waiting for (the simulator may start
    // after the gateway); anything else is final.
    if (t.error().code != Errc::kNotReady || std::chrono::steady_clock::now() >= give_up) {
      return with_context(t.error(), "dpr7545 driver");
    }
    if (!logged) {
      log::info("dpr7545", "waiting for the DPR segment",
                {{"why", t.error().message},
                 {"timeout_s", fmt::format("{}", options_.activate_timeout_s)}});
      logged = true;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
}

Status Dpr7545Driver::on_activate() {
  if (!dpr_) {
    return Error{Errc::kNotReady, "dpr7545 driver: activate before configure"};
  }
  if (options_.lock_memory) {
    rlimit limit{};
    const bool unlimited = getrlimit(RLIMIT_MEMLOCK, &limit) == 0 &&
                           limit.rlim_cur == RLIM_INFINITY;
    if (geteuid() == 0 || unlimited) {
      if (mlockall(MCL_CURRENT | MCL_FUTURE) != 0) {
        log::warn("dpr7545", "mlockall failed; memory stays pageable",
                  {{"errno", std::to_string(errno)}});
      }
    } else {
      // MCL_FUTURE under a finite RLIMIT_MEMLOCK would make later allocations fail.
      log::warn("dpr7545", "lock_memory needs root or an unlimited RLIMIT_MEMLOCK; skipped");
    }
  }
  // Is the slave there? Its idle loop rewrites timing_A (get_robot_state) on every pass: clear
  // it and wait to see it written again.
  dpr_->set_sample_period_us(static_cast<std::uint16_t>(options_.sample_period_us));
  dpr_->set_timing_a(0);
  const std::int64_t deadline =
      now_ns() + static_cast<std::int64_t>(options_.activate_timeout_s * 1e9);
  bool alive = false;
  while (!alive && now_ns() < deadline) {
    alive = dpr_->timing_a() != 0;
    if (!alive) {
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
  }
  if (!alive) {
    return Error{Errc::kNotReady,
                 fmt::format("dpr7545 driver: the slave on {} did not run its idle loop within "
                             "{} s (not running, hung, or busy homing for another master)",
                             transport_->describe(), options_.activate_timeout_s)};
  }
  // Deadline and torque bits left by a previous master (a gateway that stopped mid-control)
  // are stale: clear them. Overrun bits are the arm's state: read() reports them.
  const std::uint16_t stale = dpr_->error() & static_cast<std::uint16_t>(~d::kErrOverrunMask);
  if (stale != 0) {
    log::warn("dpr7545", "clearing error bits left by a previous master",
              {{"bits", fmt::format("0x{:04x}", stale)}, {"meaning", d::describe_errors(stale)}});
    dpr_->set_error(static_cast<std::uint16_t>(dpr_->error() & d::kErrOverrunMask));
  }
  for (int j = 0; j < kJoints; ++j) {
    dpr_->set_torque(j, d::kTorqueZero);
  }
  dpr_->set_timing_b(0);
  // A simulator's control block (sim_control.hpp) tells the sampling instants; on the real
  // card the window holds no such block (the ISA hole reads 0xFF).
  adopt_window();
  phase_ = Phase::kIdle;
  homed_ = false;  // the counters may not be homed: home before moving, unless re-attached
  gripper_ = cell_robot_GRIPPER_UNKNOWN;
  lights_ = 0;
  latched_bits_ = 0;
  pending_bits_ = 0;
  periodic_reads_ = 0;
  for (int j = 0; j < kJoints; ++j) {
    position_[idx(j)] = dpr_->position_consistent(j);
  }
  recorded_gripper_.store(kNoRecord, std::memory_order_release);
  adopt_homing_record();
  dpr_->write_lighting(lights_);  // the latch is write-only: from a known (or adopted) state
  shared_lights_.store(lights_, std::memory_order_relaxed);
  JointState initial;
  fill_state(initial);  // the recorder's view
  recorder_ = std::jthread([this](const std::stop_token& stop) { record_homing(stop); });
  if (!homed_) {
    log::info("dpr7545", "slave answered; home the robot to start control mode",
              {{"transport", transport_->describe()},
               {"sample_period_us", std::to_string(options_.sample_period_us)}});
  }
  return ok_status();
}

void Dpr7545Driver::adopt_homing_record() {
  if (options_.homing_record.empty()) {
    return;
  }
  const std::string& path = options_.homing_record;
  auto record = load_homing_record(path);
  if (record && !record->has_value()) {
    return;  // none: the arm was never homed under a record, or its homing was void
  }
  std::string refusal;
  if (!record) {
    refusal = record.error().message;
  } else {
    std::array<double, kJoints> tolerance{};
    for (int j = 0; j < kJoints; ++j) {
      // A quarter second at full speed: one record period (0.1 s) of motion since the last
      // write, the coast after the slave dropped the torques, and margin.
      const auto& spec = model_.joints()[idx(j)];
      tolerance[idx(j)] = 0.25 * spec.max_speed * std::abs(counts_per_unit_[idx(j)]);
    }
    if (auto why = homing_record_refusal(**record, board_pid_, position_, tolerance)) {
      refusal = *why;
    }
  }
  if (!refusal.empty()) {
    std::error_code ec;
    std::filesystem::remove(path, ec);
    log::warn("dpr7545", "homing record not adopted: home the robot",
              {{"record", path}, {"why", refusal}});
    return;
  }
  const HomingRecord& r = **record;
  homed_ = true;
  using G = HomingRecord::Gripper;
  gripper_ = r.gripper == G::kOpen ? cell_robot_GRIPPER_OPEN
             : r.gripper == G::kClosed ? cell_robot_GRIPPER_CLOSED
             : r.gripper == G::kOpening ? cell_robot_GRIPPER_OPENING
             : r.gripper == G::kClosing ? cell_robot_GRIPPER_CLOSING
                                        : cell_robot_GRIPPER_UNKNOWN;
  recorded_gripper_.store(static_cast<int>(r.gripper), std::memory_order_release);
  lights_ = r.lights;
  // A gripper procedure under way when the predecessor died: the latch is as before it or as
  // the procedure leaves it. Completing it makes it known, and does what was asked, where it
  // was asked (the arm has not moved since: no master, no torque). Done here, before this
  // gateway serves, so that nobody's next move meets a busy robot.
  if (r.gripper == G::kOpening || r.gripper == G::kClosing) {
    complete_gripper(r.gripper == G::kClosing);
  }
  log::info("dpr7545", "re-attached to the board: its homing kept, the arm held where it stands",
            {{"record", path},
             {"counts", fmt::format("{}, {}, {}, {}", position_[0], position_[1], position_[2],
                                    position_[3])},
             {"gripper", gripper_name(r.gripper)}});
}

void Dpr7545Driver::complete_gripper(bool close) {
  const auto until = [&](auto&& done, double timeout_s) {
    const std::int64_t deadline = now_ns() + static_cast<std::int64_t>(timeout_s * 1e9);
    while (!done()) {
      if (now_ns() > deadline) {
        return false;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
    return true;
  };
  // The slave looks at the gripper register in its idle loop only: three passes of it seen
  // through timing_A, as when leaving control mode (begin_leave).
  bool idle = true;
  for (int pass = 0; pass < 3 && idle; ++pass) {
    dpr_->set_timing_a(0);
    idle = until([&] { return dpr_->timing_a() != 0; }, options_.activate_timeout_s);
  }
  if (idle) {
    dpr_->set_gripper(close ? d::kGripperClose : d::kGripperOpen);
  }
  if (!idle || !until([&] { return dpr_->gripper() == 0; }, options_.gripper_timeout_s)) {
    gripper_ = cell_robot_GRIPPER_UNKNOWN;
    log::warn("dpr7545", "the gripper procedure under way at the predecessor's death did not "
                         "complete: the gripper is unknown",
              {{"procedure", close ? "close" : "open"}});
    return;
  }
  gripper_ = close ? cell_robot_GRIPPER_CLOSED : cell_robot_GRIPPER_OPEN;
  log::info("dpr7545", "completed the gripper procedure under way at the predecessor's death",
            {{"procedure", close ? "close" : "open"}});
}

void Dpr7545Driver::record_homing(const std::stop_token& stop) {
  const std::string& path = options_.homing_record;
  std::optional<HomingRecord> written;
  bool warned = false;
  std::mutex m;
  std::condition_variable_any cv;
  // Polled every 5 ms, so that a gripper procedure waits at most that long for the record to
  // say "unknown" (gripper_recorded()); the positions are rewritten every record period.
  constexpr auto kPoll = std::chrono::milliseconds(5);
  auto next_positions = std::chrono::steady_clock::now();
  auto next_statistics = next_positions + kStatisticsLog;
  std::uint64_t logged_exchanges = 0;
  for (;;) {
    {
      std::unique_lock lock(m);
      cv.wait_for(lock, stop, kPoll, [] { return false; });
    }
    if (stop.stop_requested()) {
      return;  // a clean stop keeps the record: the board keeps its homing
    }
    if (std::chrono::steady_clock::now() >= next_statistics) {
      next_statistics += kStatisticsLog;
      if (exchanges_.load(std::memory_order_relaxed) != logged_exchanges) {
        logged_exchanges = log_statistics();
      }
    }
    if (path.empty()) {
      continue;
    }
    if (!shared_homed_.load(std::memory_order_relaxed)) {
      if (written || std::filesystem::exists(path)) {
        std::error_code ec;
        std::filesystem::remove(path, ec);  // homing started, or the board was replaced
        written.reset();
      }
      recorded_gripper_.store(kNoRecord, std::memory_order_release);
      continue;
    }
    const int g = shared_gripper_.load(std::memory_order_acquire);
    using G = HomingRecord::Gripper;
    const G gripper = g == cell_robot_GRIPPER_OPEN      ? G::kOpen
                      : g == cell_robot_GRIPPER_CLOSED  ? G::kClosed
                      : g == cell_robot_GRIPPER_OPENING ? G::kOpening
                      : g == cell_robot_GRIPPER_CLOSING ? G::kClosing
                                                        : G::kUnknown;
    const auto now = std::chrono::steady_clock::now();
    const bool gripper_changed = !written || written->gripper != gripper;
    if (!gripper_changed && now < next_positions) {
      continue;
    }
    next_positions = now + std::chrono::duration_cast<std::chrono::steady_clock::duration>(
                               std::chrono::duration<double>(kHomingRecordPeriodS));
    HomingRecord r;
    r.board_pid = board_pid_;
    for (int j = 0; j < kJoints; ++j) {
      r.counts[idx(j)] = shared_counts_[idx(j)].load(std::memory_order_relaxed);
    }
    r.gripper = gripper;
    r.lights = shared_lights_.load(std::memory_order_relaxed);
    if (written && written->counts == r.counts && written->gripper == r.gripper &&
        written->lights == r.lights && written->board_pid == r.board_pid) {
      continue;
    }
    if (auto s = save_homing_record(path, r); !s) {
      if (!warned) {
        log::warn("dpr7545", "cannot keep the homing record: a restarted gateway will home again",
                  {{"error", s.error().message}});
        warned = true;
      }
      std::error_code ec;
      std::filesystem::remove(path, ec);  // a stale record must not be adopted
      written.reset();
      recorded_gripper_.store(kNoRecord, std::memory_order_release);
      continue;
    }
    written = r;
    recorded_gripper_.store(static_cast<int>(gripper), std::memory_order_release);
  }
}

void Dpr7545Driver::account(const std::array<double, kJoints>& errors) noexcept {
  for (int j = 0; j < kJoints; ++j) {
    const auto i = idx(j);
    const double e = std::abs(errors[i]);
    const auto bin = std::min<std::size_t>(static_cast<std::size_t>(e * 4.0), kErrorBins - 1);
    error_bins_[i][bin].fetch_add(1, std::memory_order_relaxed);
    const auto quarters = static_cast<std::int32_t>(std::min(e * 4.0, 1e9));
    if (quarters > error_max_quarters_[i].load(std::memory_order_relaxed)) {
      error_max_quarters_[i].store(quarters, std::memory_order_relaxed);
    }
    const std::int32_t torque = std::abs(static_cast<std::int32_t>(words_[i]) -
                                         static_cast<std::int32_t>(d::kTorqueZero));
    if (torque > torque_peak_[i].load(std::memory_order_relaxed)) {
      torque_peak_[i].store(torque, std::memory_order_relaxed);
    }
  }
  exchanges_.fetch_add(1, std::memory_order_relaxed);
}

Dpr7545ServoStatistics Dpr7545Driver::statistics() const {
  Dpr7545ServoStatistics out;
  out.exchanges = exchanges_.load(std::memory_order_relaxed);
  out.steps_absorbed = steps_absorbed_.load(std::memory_order_relaxed);
  for (int j = 0; j < kJoints; ++j) {
    const auto i = idx(j);
    std::uint64_t total = 0;
    std::array<std::uint32_t, kErrorBins> bins{};
    for (std::size_t b = 0; b < kErrorBins; ++b) {
      bins[b] = error_bins_[i][b].load(std::memory_order_relaxed);
      total += bins[b];
    }
    const auto quantile = [&](double q) {
      const auto wanted = static_cast<std::uint64_t>(std::ceil(q * static_cast<double>(total)));
      std::uint64_t seen = 0;
      for (std::size_t b = 0; b < kErrorBins; ++b) {
        seen += bins[b];
        if (seen >= wanted && seen > 0) {
          return static_cast<double>(b + 1) * 0.25;
        }
      }
      return 0.0;
    };
    out.error_p50_counts[i] = quantile(0.5);
    out.error_p99_counts[i] = quantile(0.99);
    out.error_max_counts[i] = error_max_quarters_[i].load(std::memory_order_relaxed) * 0.25;
    out.torque_peak_fraction[i] =
        torque_peak_[i].load(std::memory_order_relaxed) /
        static_cast<double>(d::kTorqueMax - d::kTorqueZero);
  }
  return out;
}

bool Dpr7545Driver::gripper_recorded() const noexcept {
  if (options_.homing_record.empty()) {
    return true;
  }
  const int recorded = recorded_gripper_.load(std::memory_order_acquire);
  const auto under_way = procedure_ == Procedure::kGripperClose ? HomingRecord::Gripper::kClosing
                                                                : HomingRecord::Gripper::kOpening;
  return recorded == kNoRecord || recorded == static_cast<int>(under_way);
}

std::uint64_t Dpr7545Driver::log_statistics() const {
  const Dpr7545ServoStatistics st = statistics();
  const auto joints = [](const std::array<double, kJoints>& v, const char* format) {
    std::string text;
    for (int j = 0; j < kJoints; ++j) {
      text += fmt::format(fmt::runtime(format), v[idx(j)]);
      text += j + 1 < kJoints ? " " : "";
    }
    return text;
  };
  // Every field in the joints' order J1 J2 Z R (bench/table_soak.sh reads the last line).
  log::info("dpr7545", "servo statistics",
            {{"exchanges", std::to_string(st.exchanges)},
             {"setpoint_steps_absorbed", std::to_string(st.steps_absorbed)},
             {"simulator_stall_cycles",
              std::to_string(simulator_stalls_.load(std::memory_order_relaxed))},
             {"error_p50_counts", joints(st.error_p50_counts, "{:.2f}")},
             {"error_p99_counts", joints(st.error_p99_counts, "{:.2f}")},
             {"error_max_counts", joints(st.error_max_counts, "{:.2f}")},
             {"torque_peak_fraction", joints(st.torque_peak_fraction, "{:.3f}")}});
  return st.exchanges;
}

void Dpr7545Driver::adopt_window() noexcept {
  const d::SimControl control(transport_->window());
  if (control.valid()) {
    sim_clock_.emplace(control);
    board_pid_ = control.owner_pid();
  } else {
    sim_clock_.reset();
    board_pid_ = 0;
  }
  last_board_ns_ = 0;
  // A simulator that serves a late master within a grace is waited for as long: a period it
  // did not start is its own stall (DriverInfo::link_retries), up to the grace.
  const std::uint32_t grace_us = sim_clock_ ? sim_clock_->grace_us() : 0U;
  info_.link_retries = std::max(
      3, static_cast<int>(std::ceil(static_cast<double>(grace_us) / options_.sample_period_us)));
}

void Dpr7545Driver::stop_control() noexcept {
  if (!dpr_) {
    return;
  }
  for (int j = 0; j < kJoints; ++j) {
    dpr_->set_torque(j, d::kTorqueZero);
  }
  words_.fill(d::kTorqueZero);
  // Writing 0 ends control mode without error: the slave sees it while waiting for torques.
  dpr_->set_command(0);
  dpr_->set_timing_b(0);
  handshake_open_ = false;
}

void Dpr7545Driver::on_deactivate() noexcept {
  if (recorder_.joinable()) {
    recorder_.request_stop();
    recorder_.join();
  }
  if (exchanges_.load(std::memory_order_relaxed) > 0) {
    try {
      (void)log_statistics();
    } catch (...) {  // a log line is not worth an exception out of a noexcept stop
    }
  }
  if (phase_ == Phase::kControl || phase_ == Phase::kEngage) {
    stop_control();
  }
  phase_ = Phase::kOff;
  const Dpr7545Counters c = counters();
  log::info("dpr7545", "deactivated",
            {{"periods", std::to_string(c.periods)},
             {"handshake_timeouts", std::to_string(c.handshake_timeouts)},
             {"simulator_stall_cycles", std::to_string(c.simulator_stall_cycles)},
             {"max_simulator_silence_ms",
              fmt::format("{:.1f}", static_cast<double>(c.max_simulator_silence_ns) * 1e-6)},
             {"procedure_stall_ms",
              fmt::format("{:.1f}", static_cast<double>(c.procedure_stall_ns) * 1e-6)},
             {"slave_deadline_errors", std::to_string(c.slave_deadline_errors)},
             {"max_wait_us", fmt::format("{:.1f}", static_cast<double>(c.max_wait_ns) * 1e-3)}});
}

void Dpr7545Driver::on_cleanup() noexcept {
  dpr_.reset();
  transport_.reset();
}

bool Dpr7545Driver::ready_to_engage(Clock::time_point now) noexcept {
  // Control mode may start only when the host calls read() once per period, and only in a
  // cycle that began on time: the slave anchors its period grid when it sees the command,
  // and from then on each of our cycles waits for a period start at that phase. Anchored in
  // a late cycle, the grid would sit late in all our cycles and leave no margin. Our own
  // schedule is tracked like the slave's (track_sample): the earliest phase seen, drifting up
  // by at most 1 us per cycle.
  const std::int64_t t =
      std::chrono::duration_cast<std::chrono::nanoseconds>(now.time_since_epoch()).count();
  const std::int64_t dt = t - last_read_ns_;
  last_read_ns_ = t;
  if (dt > period_ns_ / 2 && dt < period_ns_ * 3 / 2) {
    periodic_reads_ = std::min(periodic_reads_ + 1, 1000);
  } else {
    periodic_reads_ = 0;
    cycle_phase_ns_ = t;
    return false;
  }
  const std::int64_t k = (t - cycle_phase_ns_ + period_ns_ / 2) / period_ns_;
  const std::int64_t predicted = cycle_phase_ns_ + k * period_ns_;
  const std::int64_t lateness = t - predicted;
  cycle_phase_ns_ = lateness < 0 ? t : predicted + std::min<std::int64_t>(lateness, 1000);
  constexpr std::int64_t kOnTimeNs = 150'000;
  return periodic_reads_ >= 3 && lateness < kOnTimeNs;
}

void Dpr7545Driver::read_idle(JointState& state) noexcept {
  bool moved = false;
  for (int j = 0; j < kJoints; ++j) {
    const std::int32_t p = dpr_->position_consistent(j);
    moved = moved || std::abs(p - position_[idx(j)]) > 1;
    velocity_counts_s_[idx(j)] = 0.0;
    position_[idx(j)] = p;
  }
  rest_reads_ = moved ? 0 : std::min(rest_reads_ + 1, kRestReads);
  fill_state(state);
}

void Dpr7545Driver::fill_state(JointState& state) const noexcept {
  state.q.resize(kJoints);
  state.qd.resize(kJoints);
  state.effort.resize(kJoints);
  for (int j = 0; j < kJoints; ++j) {
    state.q[j] = position_[idx(j)] / counts_per_unit_[idx(j)];
    state.qd[j] = velocity_counts_s_[idx(j)] / counts_per_unit_[idx(j)];
    state.effort[j] = words_[idx(j)];
  }
  state.gripper = gripper_;
  state.homed = homed_;
  for (int j = 0; j < kJoints; ++j) {
    shared_counts_[idx(j)].store(position_[idx(j)], std::memory_order_relaxed);
  }
  shared_homed_.store(homed_, std::memory_order_relaxed);
  shared_gripper_.store(gripper_, std::memory_order_relaxed);
  state.busy = phase_ == Phase::kLeave || phase_ == Phase::kHoming || phase_ == Phase::kGripper;
  state.fault_bits = phase_ == Phase::kFault ? latched_bits_ : 0;
  state.clock_advance_s = clock_advance_s_;
}

CycleStatus Dpr7545Driver::fault(std::uint32_t bits, JointState& state) noexcept {
  if ((bits & d::kErrDeadlineMask) != 0) {
    deadline_errors_.fetch_add(1, std::memory_order_relaxed);
  }
  fault_words_ = words_;
  stop_control();  // the slave zeroed its DACs already if it flagged the error itself
  if (phase_ == Phase::kHoming || phase_ == Phase::kGripper) {
    dpr_->set_gripper(0);
  }
  latched_bits_ |= bits;
  phase_ = Phase::kFault;
  procedure_ = Procedure::kNone;
  if (gripper_ == cell_robot_GRIPPER_OPENING || gripper_ == cell_robot_GRIPPER_CLOSING) {
    gripper_ = cell_robot_GRIPPER_UNKNOWN;
  }
  fill_state(state);
  return CycleStatus::kFault;
}

CycleStatus Dpr7545Driver::handshake_read(JointState& state, std::int64_t start) noexcept {
  std::uint16_t error = 0;
  std::uint16_t timing = 0;
  // Did the period start before we came? Then we only know its instant from the grid.
  const bool started_before = (dpr_->timing_a() & d::kTimingAStart) != 0;
  // Step 1: wait for the start of the slave's period; the previous errors are kept in error_.
  bool ok = wait(
      [&] {
        error = dpr_->error();
        timing = dpr_->timing_a();
        return error != 0 || (timing & d::kTimingAStart) != 0;
      },
      cycle_deadline_ns_);
  const std::int64_t seen = now_ns();
  if (ok && error == 0) {
    // Step 2: wait for the positions.
    ok = wait(
        [&] {
          error = dpr_->error();
          timing = dpr_->timing_a();
          return error != 0 || (timing & d::kTimingAPositions) != 0;
        },
        cycle_deadline_ns_);
  }
  if (error != 0) {
    return fault(error, state);
  }
  if (!ok) {
    timeouts_.fetch_add(1, std::memory_order_relaxed);
    fill_state(state);
    // The simulator's process did not run (a VM's CPU taken away, a host stalled): no board
    // time passed, its arm stood still, and so does the path (clock_advance_s_ stays 0). It
    // is counted and reported, not taken for a lost link: CI once faulted a job's arm with
    // "link to the controller failed 21 cycles in a row" while the slave simulator stalled.
    if (simulator_stalled(now_ns())) {
      simulator_stalls_.fetch_add(1, std::memory_order_relaxed);
      return CycleStatus::kOk;
    }
    return CycleStatus::kRetry;
  }
  clock_advance_s_ = -1.0;  // the host's clock, unless the simulator's board tells its own
  track_sample(seen, started_before);
  check_phase(started_before, seen - start);
  const bool have_velocities = (dpr_->timing_a() & d::kTimingAVelocities) != 0;
  for (int j = 0; j < kJoints; ++j) {
    const std::int32_t p = dpr_->position(j);
    const double per_sample =
        have_velocities ? static_cast<double>(dpr_->velocity(j))
                        : static_cast<double>(p - position_[idx(j)]);
    velocity_counts_s_[idx(j)] = fresh_engage_ ? 0.0 : per_sample / period_s_;
    position_[idx(j)] = p;
  }
  handshake_open_ = true;
  const std::int64_t waited = now_ns() - start;
  if (waited > max_wait_ns_.load(std::memory_order_relaxed)) {
    max_wait_ns_.store(waited, std::memory_order_relaxed);
  }
  fill_state(state);
  return CycleStatus::kOk;
}

void Dpr7545Driver::check_phase(bool started_before, std::int64_t waited_ns) noexcept {
  // The slave anchors its period grid when it notices command = control. If it noticed late
  // (it was descheduled, or our engaging read ran out of budget), its periods may start late in
  // our cycles, or just before them, leaving little margin for our own jitter. Judge the first
  // exchanges: a good phase has the period start shortly after we come.
  constexpr int kJudged = 8;
  if (phase_checks_ >= kJudged) {
    return;
  }
  if (started_before || waited_ns > period_ns_ / 2) {
    ++bad_phases_;
  }
  if (++phase_checks_ == kJudged && bad_phases_ * 2 >= kJudged) {
    rephase_ = true;  // write() leaves control mode at the end of this exchange; re-engage
  }
}

void Dpr7545Driver::track_sample(std::int64_t seen, bool started_before) noexcept {
  const std::int64_t previous = (fresh_engage_ ? 0 : last_sample_ns_);
  if (sim_clock_) {
    // A simulator says when it sampled (sim_control.hpp): its periods start with a process's
    // scheduling jitter, which no grid tracks. It also says what its board's clock read then:
    // the arm moved on that clock, one period per period, through the simulator's stalls and
    // a late master's (which it absorbed, and counted); the path follows it.
    const std::int64_t t = sim_clock_->sample_time_ns();
    sample_ns_ = t > 0 && t <= seen ? t : seen;
    const std::int64_t board = sim_clock_->board_time_ns();
    if (board > 0) {
      const std::int64_t gap =
          !fresh_engage_ && last_board_ns_ > 0 && board > last_board_ns_ ? board - last_board_ns_
                                                                          : period_ns_;
      last_board_ns_ = board;
      clock_advance_s_ = static_cast<double>(gap) * 1e-9;
      sample_gap_ns_ = gap;
      last_sample_ns_ = sample_ns_;
      return;
    }
  } else {
    // The board samples on its timer's grid, one exchange per period by construction (it
    // cannot start a period before the previous one's torques came, else it stops with 0x1000),
    // so this sample is one period after the last. We see its start a latency later (>= 0), or
    // not at all when we came after it. The estimate is pulled down at once by an earlier
    // sighting and up by at most kDriftNs per period (a slave clock slower than ours), so our
    // own wake-up latency never shifts it.
    constexpr std::int64_t kDriftNs = 2000;
    if (previous == 0) {
      sample_ns_ = seen;
    } else {
      const std::int64_t predicted = previous + period_ns_;
      if (seen < predicted) {
        sample_ns_ = seen;
      } else if (started_before) {
        sample_ns_ = predicted;
      } else {
        sample_ns_ = predicted + std::min(seen - predicted, kDriftNs);
      }
    }
  }
  sample_gap_ns_ = previous > 0 ? sample_ns_ - previous : period_ns_;
  last_sample_ns_ = sample_ns_;
}

void Dpr7545Driver::start_procedure() noexcept {
  switch (procedure_) {
    case Procedure::kHome:
      // find_home(): clear the error register, then command = find home.
      dpr_->set_error(0);
      dpr_->set_command(d::kCommandFindHome);
      phase_ = Phase::kHoming;
      break;
    case Procedure::kGripperOpen:
    case Procedure::kGripperClose:
      dpr_->set_gripper(procedure_ == Procedure::kGripperClose ? d::kGripperClose
                                                                : d::kGripperOpen);
      phase_ = Phase::kGripper;
      break;
    case Procedure::kNone:
      phase_ = Phase::kIdle;
      break;
  }
  phase_since_ns_ = now_ns();
}

CycleStatus Dpr7545Driver::read(Clock::time_point now, JointState& state) {
  const std::int64_t start = now_ns();
  const CycleStatus status = read_cycle(now, state);
  if (dpr_) {
    TraceEntry& e = trace_[trace_next_++ % kTraceCycles];
    e.start_ns = start;
    e.spent_ns = now_ns() - start;
    const std::int64_t alive = sim_clock_ ? sim_clock_->alive_ns() : 0;
    e.simulator_silent_ns = alive > 0 ? start - alive : -1;
    e.timing_a = dpr_->timing_a();
    e.timing_b = dpr_->timing_b();
    e.error = dpr_->error();
    e.command = dpr_->command();
    e.phase = static_cast<std::uint8_t>(phase_);
    e.status = static_cast<std::uint8_t>(status);
    e.exchanged = false;
  }
  // The simulator's stalls, reported as they end (at most a line per 5 s, with the count).
  const std::uint64_t stalls = simulator_stalls_.load(std::memory_order_relaxed);
  if (stalls != stalls_logged_ && handshake_open_ && start - stall_logged_ns_ > 5'000'000'000) {
    log::info("dpr7545", "the simulated board stalled (its process did not run): waited for, "
                         "not counted as a lost link",
              {{"stall_cycles", std::to_string(stalls - stalls_logged_)},
               {"simulator_stall_cycles", std::to_string(stalls)},
               {"max_simulator_silence_ms",
                fmt::format("{:.1f}", static_cast<double>(max_simulator_silence_ns_.load(
                                          std::memory_order_relaxed)) * 1e-6)}});
    stalls_logged_ = stalls;
    stall_logged_ns_ = start;
  }
  retries_in_a_row_ = status == CycleStatus::kRetry ? retries_in_a_row_ + 1 : 0;
  if (retries_in_a_row_ == info_.link_retries + 1) {
    log_link_trace("the link failed in every one of the last reads: the last reads");
  }
  // A torque word the slave rejected: what the PD law did in the exchanges before it, once
  // per fault (a fault that nothing explains cannot be fixed: the soak's faults said only the
  // last word).
  if (status == CycleStatus::kFault) {
    constexpr std::uint32_t kTorqueBits =
        d::kErrTorqueJ1 | d::kErrTorqueJ2 | d::kErrTorqueZ | d::kErrTorqueR;
    if ((latched_bits_ & kTorqueBits) != 0 && !fault_trace_logged_) {
      log_torque_trace(latched_bits_);
      fault_trace_logged_ = true;
    }
    // A late master the slave flagged past its grace: where this side's time went (a soak's
    // deadline faults on a quiet host said only the bit).
    if ((latched_bits_ & d::kErrDeadlineMask) != 0 && !fault_trace_logged_) {
      log_link_trace(fmt::format("the slave flagged a late master ({:#06x}): the last reads",
                                 latched_bits_ & d::kErrDeadlineMask));
      fault_trace_logged_ = true;
    }
  } else {
    fault_trace_logged_ = false;
  }
  return status;
}

void Dpr7545Driver::log_torque_trace(std::uint32_t bits) const {
  std::string text;
  const std::size_t n = std::min(trace_next_, kTraceCycles);
  const std::int64_t last = trace_[(trace_next_ - 1) % kTraceCycles].start_ns;
  // Newest first: the log cuts a long value at its end, and the last exchanges matter most.
  for (std::size_t k = 0; k < n; ++k) {
    const TraceEntry& e = trace_[(trace_next_ - 1 - k) % kTraceCycles];
    text += fmt::format("{}{:.3f}ms:{}/{}", k == 0 ? "" : "; ",
                        static_cast<double>(e.start_ns - last) * 1e-6, static_cast<int>(e.phase),
                        static_cast<int>(e.status));
    if (!e.exchanged) {
      text += " -";
      continue;
    }
    text += fmt::format(" gap={:.0f}us path={:.0f}us d={:.0f}us", e.sample_gap_us,
                        e.path_advance_us, e.derivative_us);
    for (int j = 0; j < kJoints; ++j) {
      const auto i = idx(j);
      text += fmt::format(" {}:{:.1f}/{:.1f}/{:.1f}/{:+d}", d::kJointNames[i], e.desired[i],
                          e.actual[i], e.offset[i], d::torque_dac(e.word[i]));
    }
  }
  log::warn("dpr7545", "a torque word was rejected: the last exchanges",
            {{"bits", fmt::format("{:#06x}", bits)},
             {"exchanges", text},
             {"legend", "newest first, start relative to the last read: phase/status(0 ok, "
                        "1 retry, 2 fault), sample gap, path advance (-1: host clock), D "
                        "interval; per joint reference/encoder/offset [counts]/DAC value "
                        "(+-2047 valid)"}});
}

void Dpr7545Driver::log_link_trace(std::string_view what) const {
  std::string text;
  const std::size_t n = std::min(trace_next_, kTraceCycles);
  const std::int64_t last = trace_[(trace_next_ - 1) % kTraceCycles].start_ns;
  // Newest first: the log cuts a long value at its end, and the last exchanges matter most.
  for (std::size_t k = 0; k < n; ++k) {
    const TraceEntry& e = trace_[(trace_next_ - 1 - k) % kTraceCycles];
    text += fmt::format("{}{:.3f}ms:{}/{}/{:.0f}us a={:#x} b={:#x} err={:#x} cmd={:#x} sim_silent={}",
                        k == 0 ? "" : "; ", static_cast<double>(e.start_ns - last) * 1e-6,
                        static_cast<int>(e.phase), static_cast<int>(e.status),
                        static_cast<double>(e.spent_ns) * 1e-3, e.timing_a, e.timing_b, e.error,
                        e.command,
                        e.simulator_silent_ns < 0
                            ? std::string("-")
                            : fmt::format("{:.1f}ms",
                                          static_cast<double>(e.simulator_silent_ns) * 1e-6));
  }
  log::warn("dpr7545", std::string(what),
            {{"retries_in_a_row", std::to_string(retries_in_a_row_)},
             {"reads", text},
             {"legend", "newest first, start relative to the last: phase/status(0 ok, 1 "
                        "retry, 2 fault)/time spent, registers after the read"}});
}

CycleStatus Dpr7545Driver::read_cycle(Clock::time_point now, JointState& state) {
  tighten_timer_slack();
  const std::int64_t start = now_ns();
  // The path moves only while the board controls the arm: 0 until an exchange of control mode
  // says how far the board's clock advanced (a simulator that publishes it), or -1 (the real
  // card's clock is not visible: the host's stands for it). Outside control mode (not yet
  // engaged after a homing, a gripper dwell, a fault) the arm follows no path, so the path
  // must not run on: a trajectory loaded just after a homing ran ~20 ms ahead before control
  // mode engaged, and met the arm at full speed (a J2 torque fault at 2810 deg/s^2).
  clock_advance_s_ = 0.0;
  cycle_deadline_ns_ = start + budget_ns_;
  handshake_open_ = false;
  const bool may_engage = ready_to_engage(now);
  if (!dpr_ || phase_ == Phase::kOff) {
    fill_state(state);
    return CycleStatus::kRetry;
  }
  if (pending_bits_ != 0) {  // an error the slave flagged during the last write()
    const std::uint32_t bits = std::exchange(pending_bits_, 0U);
    read_idle(state);
    return fault(bits | dpr_->error(), state);
  }
  // A procedure's time (engage, leave, homing, gripper) does not run while a simulated board's
  // process is stalled: its slave did not run, so it could not answer (a soak job faulted with
  // 0x20000 "did not finish in time" while the simulator stalled beside a second 1 kHz pair).
  // The real board never stalls; without a simulator's stamp nothing changes.
  const std::int64_t since_last_read = last_cycle_start_ns_ > 0 ? start - last_cycle_start_ns_ : 0;
  last_cycle_start_ns_ = start;
  if (since_last_read > 0 && phase_ != Phase::kControl && phase_ != Phase::kIdle &&
      phase_ != Phase::kFault && simulator_stalled(start)) {
    phase_since_ns_ += since_last_read;
    procedure_stall_ns_.fetch_add(since_last_read, std::memory_order_relaxed);
  }
  const auto elapsed_periods = [&] { return (start - phase_since_ns_) / period_ns_; };
  switch (phase_) {
    case Phase::kFault:
      read_idle(state);
      latched_bits_ |= dpr_->error();
      fill_state(state);
      return CycleStatus::kFault;

    case Phase::kIdle: {
      read_idle(state);
      if (const std::uint16_t error = dpr_->error(); error != 0) {
        return fault(error, state);
      }
      if (!homed_ || !may_engage || rest_reads_ < kRestReads) {
        return CycleStatus::kOk;
      }
      // Start control mode. The marker in timing_B tells when the slave has passed its
      // control_mode initialisation (registers.hpp, kTimingBEngageMarker).
      for (int j = 0; j < kJoints; ++j) {
        dpr_->set_torque(j, d::kTorqueZero);
      }
      words_.fill(d::kTorqueZero);
      dpr_->set_sample_period_us(static_cast<std::uint16_t>(options_.sample_period_us));
      dpr_->set_timing_b(d::kTimingBEngageMarker);
      dpr_->set_command(d::kCommandControl);
      phase_ = Phase::kEngage;
      phase_since_ns_ = start;
      [[fallthrough]];
    }
    case Phase::kEngage: {
      std::uint16_t error = 0;
      const bool entered = wait(
          [&] {
            error = dpr_->error();
            return error != 0 || dpr_->timing_b() == 0;
          },
          cycle_deadline_ns_);
      if (error != 0) {
        return fault(error, state);
      }
      if (!entered) {
        if (elapsed_periods() > kEngageTimeoutPeriods) {
          return fault(kDprFaultSlaveSilent, state);
        }
        read_idle(state);
        return CycleStatus::kOk;
      }
      phase_ = Phase::kControl;
      fresh_engage_ = true;
      last_sample_ns_ = 0;
      phase_checks_ = 0;
      bad_phases_ = 0;
      rephase_ = false;
      engages_.fetch_add(1, std::memory_order_relaxed);
      return handshake_read(state, start);
    }

    case Phase::kControl:
      return handshake_read(state, start);

    case Phase::kLeave: {
      read_idle(state);
      if (const std::uint16_t error = dpr_->error(); error != 0) {
        return fault(error, state);
      }
      // Three observations, each at least a cycle apart, of timing_A being rewritten after we
      // cleared it: the last one can only come from the idle loop, which runs after main_loop
      // cleared command and gripper. Only then may the procedure's register be written.
      if (leave_step_ >= 0 && dpr_->timing_a() != 0) {
        dpr_->set_timing_a(0);
        // A gripper procedure reaches the board only once the homing record says "unknown"
        // (the latch is write-only: a successor must never adopt a state it may have left).
        const bool gripper = procedure_ == Procedure::kGripperOpen ||
                             procedure_ == Procedure::kGripperClose;
        if (++leave_step_ >= 3 && (!gripper || gripper_recorded())) {
          start_procedure();
          fill_state(state);
          return CycleStatus::kOk;
        }
      }
      if (elapsed_periods() > kLeaveTimeoutPeriods) {
        return fault(kDprFaultProcedureTimeout, state);
      }
      return CycleStatus::kOk;
    }

    case Phase::kHoming: {
      read_idle(state);
      if (const std::uint16_t error = dpr_->error(); error != 0) {
        return fault(error, state);
      }
      if (dpr_->command() == 0) {  // the slave cleared it: homed
        homed_ = true;
        procedure_ = Procedure::kNone;
        phase_ = Phase::kIdle;
        fill_state(state);
        return CycleStatus::kOk;
      }
      if (static_cast<double>(start - phase_since_ns_) * 1e-9 > options_.homing_timeout_s) {
        return fault(kDprFaultProcedureTimeout, state);
      }
      return CycleStatus::kOk;
    }

    case Phase::kGripper: {
      read_idle(state);
      if (const std::uint16_t error = dpr_->error(); error != 0) {
        return fault(error, state);
      }
      if (dpr_->gripper() == 0) {  // latch written, dwell over
        gripper_ = procedure_ == Procedure::kGripperClose ? cell_robot_GRIPPER_CLOSED
                                                          : cell_robot_GRIPPER_OPEN;
        procedure_ = Procedure::kNone;
        phase_ = Phase::kIdle;
        fill_state(state);
        return CycleStatus::kOk;
      }
      if (static_cast<double>(start - phase_since_ns_) * 1e-9 > options_.gripper_timeout_s) {
        return fault(kDprFaultProcedureTimeout, state);
      }
      return CycleStatus::kOk;
    }

    case Phase::kOff:
      break;
  }
  fill_state(state);
  return CycleStatus::kRetry;
}

CycleStatus Dpr7545Driver::write(Clock::time_point now, const JointSetpoint& setpoint) {
  applied_valid_ = false;
  if (!handshake_open_) {
    return CycleStatus::kOk;  // no exchange this cycle (idle slave, procedure, retry)
  }
  handshake_open_ = false;
  const bool sized = setpoint.q.size() == kJoints;
  const bool with_rate = setpoint.qd.size() == kJoints;
  // The setpoint holds at `now` (the host's cycle time); move it to the sampling instant. On
  // the board's clock (clock_advance_s_ >= 0) the host's path already stands at the sample's
  // instant: it advanced by the board's clock, not the host's.
  const std::int64_t skew_ns =
      clock_advance_s_ >= 0.0
          ? 0
          : sample_ns_ - std::chrono::duration_cast<std::chrono::nanoseconds>(
                             now.time_since_epoch())
                             .count();
  const std::int64_t bounded_skew = std::clamp(skew_ns, -5 * period_ns_, 5 * period_ns_);
  if (std::abs(bounded_skew) > max_skew_ns_.load(std::memory_order_relaxed)) {
    max_skew_ns_.store(std::abs(bounded_skew), std::memory_order_relaxed);
  }
  const double skew_s = static_cast<double>(bounded_skew) * 1e-9;
  // The derivative's interval: the nominal Ts, as the thesis, while the samples come a period
  // apart, even when a simulator's came irregularly (a difference of one-count-quantised
  // positions over a short interval is noise, and dividing it by that interval would amplify
  // it out of the DAC range). After periods were missed (this host stalled past them, which the
  // board never does), the error's change spans the whole gap: over Ts it would be a kick of
  // gap / Ts times the damping, out of the DAC range after a stall of a few periods.
  const double derivative_s =
      sample_gap_ns_ > period_ns_ * 3 / 2
          ? static_cast<double>(std::min(sample_gap_ns_, 20 * period_ns_)) * 1e-9
          : period_s_;
  for (int j = 0; j < kJoints; ++j) {
    const auto i = idx(j);
    const double actual = position_[i];
    const double desired =
        sized ? (setpoint.q[j] + (with_rate ? setpoint.qd[j] * skew_s : 0.0)) * counts_per_unit_[i]
              : actual;
    if (fresh_engage_) {
      offset_[i] = actual - desired;  // bumpless: the reference starts where the arm is
    } else {
      // A host setpoint that steps further than the joint's top speed can carry it since the
      // last exchange is not a path: a trajectory that starts within the gateway's start
      // tolerance of the arm but not at the held setpoint (right after a homing, the arm still
      // settling onto its index, 61 counts of J1 at once), a hold re-seated at the measured
      // joints. The step goes into the offset, which closes it at the engage speed, as when
      // control mode starts: on this board a step of ~25 counts is a torque fault.
      // A path's step is the integral of its own rate over the gap (trapezoidal: exact for the
      // planners' piecewise-linear rates); what deviates from it by more than the joint's
      // acceleration limit allows over the gap is a step of the setpoint itself.
      const double gap_s = std::max(period_s_, static_cast<double>(sample_gap_ns_) * 1e-9);
      const double step = desired - last_desired_[i];
      const double rate = with_rate ? setpoint.qd[j] * counts_per_unit_[i] : 0.0;
      const double deviation =
          with_rate && have_last_desired_ ? step - 0.5 * (rate + last_rate_[i]) * gap_s : step;
      const double allowed = with_rate && have_last_desired_
                                 ? 2.0 + accel_counts_s2_[i] * gap_s * gap_s
                                 : 2.0 + 1.5 * speed_counts_s_[i] * gap_s;
      if (std::abs(deviation) > allowed) {
        offset_[i] -= deviation;
        steps_absorbed_.fetch_add(1, std::memory_order_relaxed);
      }
      last_rate_[i] = rate;
      offset_[i] = offset_[i] > 0 ? std::max(0.0, offset_[i] - engage_step_counts_[i])
                                  : std::min(0.0, offset_[i] + engage_step_counts_[i]);
    }
    last_desired_[i] = desired;
    if (fresh_engage_) {
      last_rate_[i] = with_rate ? setpoint.qd[j] * counts_per_unit_[i] : 0.0;
    }
    applied_[i] = desired + offset_[i];
    const double e = applied_[i] - actual;
    const double e_prev = fresh_engage_ ? e : error_[i];
    words_[i] = d::torque_word(d::pd_torque(kp_[i], kv_[i], derivative_s, e, e_prev));
    error_[i] = e;
  }
  if (!fresh_engage_) {
    account(error_);
  }
  if (trace_next_ > 0) {  // this cycle's entry (read() made it)
    TraceEntry& t = trace_[(trace_next_ - 1) % kTraceCycles];
    t.exchanged = true;
    for (int j = 0; j < kJoints; ++j) {
      const auto i = idx(j);
      t.desired[i] = static_cast<float>(last_desired_[i]);
      t.actual[i] = static_cast<float>(position_[i]);
      t.offset[i] = static_cast<float>(offset_[i]);
      t.word[i] = words_[i];
    }
    t.sample_gap_us = static_cast<float>(static_cast<double>(sample_gap_ns_) * 1e-3);
    t.path_advance_us = static_cast<float>(clock_advance_s_ < 0 ? -1.0 : clock_advance_s_ * 1e6);
    t.derivative_us = static_cast<float>(derivative_s * 1e6);
  }
  fresh_engage_ = false;
  have_last_desired_ = sized && with_rate;
  applied_valid_ = sized;
  for (int j = 0; j < kJoints; ++j) {
    dpr_->set_torque(j, words_[idx(j)]);
  }
  dpr_->set_timing_b(d::kTimingBTorquesReady);  // tell the slave that torques are ready
  std::uint16_t error = 0;
  const std::int64_t deadline = std::max(cycle_deadline_ns_, now_ns() + 100'000);
  const bool accepted = wait(
      [&] {
        error = dpr_->error();
        return error != 0 || (dpr_->timing_b() & d::kTimingBTorquesReady) == 0;
      },
      deadline);
  dpr_->set_timing_a(0);  // indicate end of sample period
  periods_.fetch_add(1, std::memory_order_relaxed);
  if (rephase_ && phase_ == Phase::kControl) {
    rephase_ = false;
    rephases_.fetch_add(1, std::memory_order_relaxed);
    (void)begin_leave(Procedure::kNone);  // back to idle, then engage in an on-time cycle
  }
  if (phase_ == Phase::kLeave && leave_step_ < 0) {
    // A procedure was requested during this exchange: end control mode at its boundary.
    stop_control();
    leave_step_ = 0;
  }
  if (error != 0) {
    pending_bits_ = error;  // reported with its bits by the next read()
    return CycleStatus::kRetry;
  }
  if (!accepted) {
    timeouts_.fetch_add(1, std::memory_order_relaxed);
    return CycleStatus::kRetry;
  }
  return CycleStatus::kOk;
}

bool Dpr7545Driver::applied_setpoint(JointVector& out) const noexcept {
  if (!applied_valid_) {
    return false;
  }
  out.resize(kJoints);
  for (int j = 0; j < kJoints; ++j) {
    out[j] = applied_[idx(j)] / counts_per_unit_[idx(j)];
  }
  return true;
}

bool Dpr7545Driver::home_joints(JointVector& out) const {
  out = JointVector::Zero(kJoints);  // find_home() zeroes every counter at its index pulse
  return true;
}

Status Dpr7545Driver::begin_leave(Procedure next) noexcept {
  procedure_ = next;
  const bool in_control = phase_ == Phase::kControl || phase_ == Phase::kEngage;
  phase_ = Phase::kLeave;
  phase_since_ns_ = now_ns();
  if (in_control && handshake_open_) {
    leave_step_ = -1;  // write() ends control mode once this exchange is complete
  } else {
    if (in_control) {
      stop_control();
    }
    leave_step_ = 0;
    dpr_->set_timing_a(0);  // the first of the idle-loop observations starts from 0
  }
  return ok_status();
}

Status Dpr7545Driver::command(DriverCommand command, const CommandArgs& args) {
  if (!dpr_) {
    return Error{Errc::kNotReady, "dpr7545 driver is not configured"};
  }
  const auto busy = [&]() -> Status {
    if (phase_ == Phase::kFault) {
      return Error{Errc::kNotReady, "the 7545 is in fault (" + describe_faults(latched_bits_) +
                                        "): reset first"};
    }
    if (phase_ == Phase::kLeave || phase_ == Phase::kHoming || phase_ == Phase::kGripper) {
      return Error{Errc::kNotReady, "the 7545 is busy (homing or gripper in progress)"};
    }
    return ok_status();
  };
  switch (command) {
    case DriverCommand::kHome:
      CELL_TRY(busy());
      homed_ = false;
      return begin_leave(Procedure::kHome);
    case DriverCommand::kGripperOpen:
    case DriverCommand::kGripperClose:
      CELL_TRY(busy());
      gripper_ = command == DriverCommand::kGripperClose ? cell_robot_GRIPPER_CLOSING
                                                         : cell_robot_GRIPPER_OPENING;
      shared_gripper_.store(gripper_, std::memory_order_release);
      return begin_leave(command == DriverCommand::kGripperClose ? Procedure::kGripperClose
                                                                 : Procedure::kGripperOpen);
    case DriverCommand::kLights:
      lights_ = d::lighting_latch(args.halogen_on, args.fluorescent_on);
      dpr_->write_lighting(lights_);
      shared_lights_.store(lights_, std::memory_order_relaxed);
      return ok_status();
    case DriverCommand::kSetGains:
      if (args.kp.size() != kJoints || args.kv.size() != kJoints) {
        return Error{Errc::kInvalidArgument,
                     fmt::format("the 7545 needs 4 kp and 4 kv values, got {} and {}",
                                 args.kp.size(), args.kv.size())};
      }
      for (int j = 0; j < kJoints; ++j) {
        if (!std::isfinite(args.kp[idx(j)]) || !std::isfinite(args.kv[idx(j)]) ||
            args.kp[idx(j)] < 0 || args.kv[idx(j)] < 0) {
          return Error{Errc::kInvalidArgument,
                       fmt::format("gains of joint {} must be finite and >= 0",
                                   d::kJointNames[idx(j)])};
        }
      }
      for (int j = 0; j < kJoints; ++j) {
        kp_[idx(j)] = args.kp[idx(j)];
        kv_[idx(j)] = args.kv[idx(j)];
      }
      return ok_status();
    case DriverCommand::kReset: {
      if (phase_ != Phase::kFault) {
        return ok_status();  // nothing latched
      }
      if (transport_->replaced()) {  // the simulator restarted: map its new segment
        auto t = open_();
        if (!t) {
          return with_context(t.error(), "reset: reopening the DPR");
        }
        dpr_.reset();
        transport_ = std::move(*t);
        dpr_ = std::make_unique<d::Dpr>(transport_->window());
        dpr_->set_sample_period_us(static_cast<std::uint16_t>(options_.sample_period_us));
        adopt_window();
        homed_ = false;
      }
      stop_control();
      dpr_->set_gripper(0);
      dpr_->set_error(0);  // clear the error semaphores
      latched_bits_ = 0;
      pending_bits_ = 0;
      offset_.fill(0.0);
      phase_ = Phase::kIdle;  // control mode restarts at the next periodic read (if homed)
      phase_since_ns_ = now_ns();
      return ok_status();
    }
    case DriverCommand::kSetMode:
    case DriverCommand::kSetTolerance:
      break;
  }
  return Error{Errc::kInvalidArgument, "the 7545 has no modes or position tolerance"};
}

bool Dpr7545Driver::supports(DriverCommand command) const noexcept {
  return command != DriverCommand::kSetMode && command != DriverCommand::kSetTolerance;
}

std::string Dpr7545Driver::describe_faults(std::uint32_t bits) const {
  std::string text = d::describe_errors(static_cast<std::uint16_t>(bits & 0xFFFFU));
  // For a torque fault, what the PD law computed in the exchange the slave rejected.
  for (int j = 0; j < kJoints; ++j) {
    if ((bits & d::torque_error_bit(j)) != 0) {
      text += fmt::format("; {}: position error {:.1f} counts gave PD word 0x{:04x}",
                          d::kJointNames[idx(j)], error_[idx(j)], fault_words_[idx(j)]);
    }
  }
  const auto add = [&](std::string_view what) {
    text += fmt::format("{}{}", text.empty() ? "" : "; ", what);
  };
  if ((bits & kDprFaultSlaveSilent) != 0) {
    add("the slave did not enter control mode (no answer on the DPR) (0x10000)");
  }
  if ((bits & kDprFaultProcedureTimeout) != 0) {
    add("homing, gripper or leaving control mode did not finish in time (0x20000)");
  }
  return text;
}

bool Dpr7545Driver::simulator_stalled(std::int64_t now) noexcept {
  if (!sim_clock_) {
    return false;
  }
  const std::int64_t alive = sim_clock_->alive_ns();
  if (alive <= 0) {
    return false;  // a simulator that does not stamp its liveness
  }
  const std::int64_t silent = now - alive;
  // Five periods: a running simulator sleeping to its next grid point is silent up to about
  // 2.6 ms on this 2-vCPU host (cell up's run, 16:04), which is jitter, not a stall.
  if (silent <= 5 * period_ns_ || silent > kSimulatorSilentLimitNs) {
    return false;  // it runs and did not answer, or it is hung: the link failed
  }
  if (board_pid_ != 0 && ::kill(static_cast<pid_t>(board_pid_), 0) != 0 && errno == ESRCH) {
    return false;  // its process is gone
  }
  if (silent > max_simulator_silence_ns_.load(std::memory_order_relaxed)) {
    max_simulator_silence_ns_.store(silent, std::memory_order_relaxed);
  }
  return true;
}

Dpr7545Counters Dpr7545Driver::counters() const noexcept {
  Dpr7545Counters c;
  c.periods = periods_.load(std::memory_order_relaxed);
  c.handshake_timeouts = timeouts_.load(std::memory_order_relaxed);
  c.slave_deadline_errors = deadline_errors_.load(std::memory_order_relaxed);
  c.engages = engages_.load(std::memory_order_relaxed);
  c.max_wait_ns = max_wait_ns_.load(std::memory_order_relaxed);
  c.max_setpoint_skew_ns = max_skew_ns_.load(std::memory_order_relaxed);
  c.rephases = rephases_.load(std::memory_order_relaxed);
  c.simulator_stall_cycles = simulator_stalls_.load(std::memory_order_relaxed);
  c.max_simulator_silence_ns = max_simulator_silence_ns_.load(std::memory_order_relaxed);
  c.procedure_stall_ns = procedure_stall_ns_.load(std::memory_order_relaxed);
  return c;
}

DriverFactory parse_dpr7545_driver(config::MapReader& section) {
  Dpr7545Options o;
  std::string transport = "shm";
  std::int64_t base = static_cast<std::int64_t>(o.physical_base_address);
  section.optional("transport", transport);
  section.optional("shm_name", o.shm_name);
  section.optional("physical_device", o.physical_device);
  section.optional("physical_base_address", base);
  section.optional("sample_period_us", o.sample_period_us);
  section.optional("kp", o.kp);
  section.optional("kv", o.kv);
  section.optional("handshake_timeout_us", o.handshake_timeout_us);
  section.optional("lock_memory", o.lock_memory);
  section.optional("activate_timeout_s", o.activate_timeout_s);
  section.optional("homing_timeout_s", o.homing_timeout_s);
  section.optional("gripper_timeout_s", o.gripper_timeout_s);
  section.optional("engage_speed_fraction", o.engage_speed_fraction);
  section.optional("homing_record", o.homing_record);
  if (transport == "shm") {
    o.transport = Dpr7545Options::Transport::kShm;
  } else if (transport == "physical") {
    o.transport = Dpr7545Options::Transport::kPhysical;
  } else {
    section.fail("transport", fmt::format("must be shm or physical, got '{}'", transport));
  }
  if (base < 0) {
    section.fail("physical_base_address", fmt::format("must be >= 0, got {}", base));
  }
  o.physical_base_address = static_cast<std::uint64_t>(std::max<std::int64_t>(base, 0));
  if (auto s = o.validate(); !s) {
    // validate() names the key as 'driver.<key>': record it at the section.
    section.fail("", s.error().message);
  }
  const std::string where = section.where("sample_period_us");
  return [o, where](const DriverSetup& setup) -> Result<std::unique_ptr<RobotDriver>> {
    const auto& model = setup.model;
    if (model.dof() != kJoints) {
      return Error{Errc::kConfig, fmt::format("{}: the dpr7545 driver drives 4 joints (J1, J2, "
                                              "Z, R); robot '{}' has {}",
                                              where, model.id(), model.dof())};
    }
    for (const auto& joint : model.joints()) {
      if (!(joint.counts_per_unit > 0)) {
        return Error{Errc::kConfig,
                     fmt::format("{}: robot '{}' joint '{}' has no encoder scale "
                                 "(counts_per_*): the DPR speaks encoder counts",
                                 where, model.id(), joint.name)};
      }
    }
    const auto period = std::chrono::nanoseconds(static_cast<std::int64_t>(o.sample_period_us) *
                                                 1000);
    if (std::abs((setup.cycle - period).count()) > 1000) {
      return Error{Errc::kConfig,
                   fmt::format("{}: driver.sample_period_us = {} does not match the gateway's "
                               "cycle ({} us): the slave needs exactly one exchange per sample",
                               where, o.sample_period_us,
                               static_cast<double>(setup.cycle.count()) * 1e-3)};
    }
    Dpr7545Driver::TransportOpener open;
    if (o.transport == Dpr7545Options::Transport::kShm) {
      open = [name = o.shm_name] { return dpr7545::open_shm(name); };
    } else {
      open = [device = o.physical_device, base = o.physical_base_address] {
        return dpr7545::open_physical(device, base);
      };
    }
    return std::unique_ptr<RobotDriver>(
        std::make_unique<Dpr7545Driver>(model, o, setup.cycle, std::move(open)));
  };
}

}  // namespace cell::gateway
