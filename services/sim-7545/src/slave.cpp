#include "slave.hpp"

#include <sys/prctl.h>

#include <algorithm>
#include <cmath>
#include <ctime>

namespace cell::sim7545 {
namespace {

using dpr7545::kJoints;

std::int64_t now_ns() noexcept {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

void sleep_until_ns(std::int64_t t) noexcept {
  const timespec ts{static_cast<time_t>(t / 1'000'000'000), static_cast<long>(t % 1'000'000'000)};
  while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr) == EINTR) {
  }
}

void cpu_relax() noexcept {
#if defined(__x86_64__) || defined(__i386__)
  __builtin_ia32_pause();
#endif
}

/// One step of a bounded wait for the other side: a few microseconds of spinning, then short
/// sleeps (the machine has 2 cores shared with the master and everything else).
void wait_step(std::int64_t since_ns) noexcept {
  if (now_ns() - since_ns < 10'000) {
    for (int i = 0; i < 64; ++i) {
      cpu_relax();
    }
    return;
  }
  const timespec ts{0, 20'000};
  nanosleep(&ts, nullptr);
}

std::array<JointModel, kJoints> make_joints(const SlaveOptions& o) {
  return {JointModel(o.plants[0], o.initial_counts[0], o.limits[0].min_counts,
                     o.limits[0].max_counts),
          JointModel(o.plants[1], o.initial_counts[1], o.limits[1].min_counts,
                     o.limits[1].max_counts),
          JointModel(o.plants[2], o.initial_counts[2], o.limits[2].min_counts,
                     o.limits[2].max_counts),
          JointModel(o.plants[3], o.initial_counts[3], o.limits[3].min_counts,
                     o.limits[3].max_counts)};
}

// The FH macro's sensor bits per joint (digest 000 §2.4), indexed by joint.
constexpr std::array<int, kJoints> kHomeBit = {7, 6, 4, 5};
constexpr std::array<int, kJoints> kIndexBit = {2, 1, 0, 3};

}  // namespace

Slave::Slave(std::span<std::byte> window, const SlaveOptions& options)
    : dpr_(window), control_(window), options_(options), joints_(make_joints(options)) {
  dac_.fill(dpr7545::kTorqueZero);
  for (int j = 0; j < kJoints; ++j) {
    index_seen_[static_cast<std::size_t>(j)] = joints_[static_cast<std::size_t>(j)].index_pulses();
  }
  publish();
}

std::int64_t Slave::period_ns() const noexcept {
  const std::uint16_t us = dpr_.sample_period_us();
  return static_cast<std::int64_t>(us < 100 ? dpr7545::kDefaultSamplePeriodUs : us) * 1000;
}

void Slave::advance_to(std::int64_t t_ns) noexcept {
  if (t_ns <= t_phys_ns_) {
    return;
  }
  const double dt = static_cast<double>(t_ns - t_phys_ns_) * 1e-9;
  for (int j = 0; j < kJoints; ++j) {
    const auto i = static_cast<std::size_t>(j);
    joints_[i].advance(dac_[i], dt);
  }
  t_phys_ns_ = t_ns;
}

std::int64_t Slave::board_now() const noexcept { return now_ns() - absorbed_ns_; }

void Slave::zero_dacs() noexcept { dac_.fill(dpr7545::kTorqueZero); }

void Slave::set_error_bits(std::uint16_t bits) noexcept {
  // LD TEMP1,[ERROR]; OR TEMP1,#bits; ST TEMP1,[ERROR]
  dpr_.set_error(static_cast<std::uint16_t>(dpr_.error() | bits));
}

void Slave::get_robot_state() noexcept {
  for (int j = 0; j < kJoints; ++j) {
    const auto i = static_cast<std::size_t>(j);
    pos_last_[i] = pos_[i];
    pos_[i] = dpr7545::sign_extend_24(joints_[i].counter_24());
    dpr_.set_position(j, pos_[i]);
  }
  dpr_.set_timing_a(0x0003);  // positions saved
  std::array<std::int16_t, kJoints> vel_last = vel_;
  for (int j = 0; j < kJoints; ++j) {
    const auto i = static_cast<std::size_t>(j);
    vel_[i] = static_cast<std::int16_t>(pos_[i] - pos_last_[i]);
    dpr_.set_velocity(j, vel_[i]);
  }
  dpr_.set_timing_a(0x0007);  // velocities ready
  for (int j = 0; j < kJoints; ++j) {
    const auto i = static_cast<std::size_t>(j);
    dpr_.set_acceleration(j, static_cast<std::int16_t>(vel_[i] - vel_last[i]));
  }
  dpr_.set_timing_a(0x000F);  // accelerations saved
}

void Slave::overrun_check() noexcept {
  const std::uint16_t bits = dpr7545::overrun_bits(pos_, options_.limits);
  // STB TEMP1, TEMP2: the low byte of error is rewritten on every pass.
  dpr_.set_error(static_cast<std::uint16_t>((dpr_.error() & 0xFF00U) | bits));
}

std::uint8_t Slave::read_sensor_port() noexcept {
  std::uint8_t port = 0;
  for (int j = 0; j < kJoints; ++j) {
    const auto i = static_cast<std::size_t>(j);
    if (!joints_[i].home_active()) {
      port = static_cast<std::uint8_t>(port | (1U << kHomeBit[i]));  // active low
    }
    if (joints_[i].index_pulses() != index_seen_[i]) {
      port = static_cast<std::uint8_t>(port | (1U << kIndexBit[i]));
      index_seen_[i] = joints_[i].index_pulses();
    }
  }
  return port;
}

void Slave::service_mailbox() noexcept {
  if (options_.deadline_miss_after_s > 0 && !auto_miss_done_ && mode_ == SlaveMode::kControl &&
      control_since_ns_ >= 0 &&
      static_cast<double>(now_ns() - control_since_ns_) * 1e-9 >= options_.deadline_miss_after_s) {
    arm_deadline_miss_ = true;
    auto_miss_done_ = true;
  }
  const auto request = control_.pending();
  if (!request) {
    return;
  }
  std::uint32_t result = 0;
  const bool joint_ok = request->joint >= 0 && request->joint < kJoints;
  const auto j = static_cast<std::size_t>(joint_ok ? request->joint : 0);
  if (!options_.fault_injection) {
    result = 4;
  } else {
    switch (request->fault) {
      case dpr7545::SimFault::kDeadlineMiss:
      case dpr7545::SimFault::kLoopLate:
        if (mode_ != SlaveMode::kControl) {
          result = 3;
        } else if (request->fault == dpr7545::SimFault::kDeadlineMiss) {
          arm_deadline_miss_ = true;
        } else {
          arm_loop_late_ = true;
        }
        break;
      case dpr7545::SimFault::kEncoderGlitch:
        if (!joint_ok) {
          result = 1;
        } else {
          joints_[j].add_encoder_offset(request->value);
        }
        break;
      case dpr7545::SimFault::kOverrun:
        if (!joint_ok) {
          result = 1;
        } else {
          const auto& limits = options_.limits[j];
          joints_[j].force_encoder_counts(request->value > 0
                                              ? std::int64_t{limits.max_counts} + 1
                                              : std::int64_t{limits.min_counts} - 1);
        }
        break;
      case dpr7545::SimFault::kClear:
        for (auto& joint : joints_) {
          joint.clear_encoder_offset();
        }
        break;
      default:
        result = 2;
        break;
    }
  }
  control_.acknowledge(*request, result);
}

void Slave::publish() noexcept {
  control_.set_alive_ns(now_ns());  // every loop passes here at least once a period
  std::unique_lock lock(mutex_, std::try_to_lock);
  if (!lock.owns_lock()) {
    return;  // the publisher is copying: the next pass publishes
  }
  for (int j = 0; j < kJoints; ++j) {
    const auto i = static_cast<std::size_t>(j);
    snapshot_.position_counts[i] = joints_[i].position();
    snapshot_.velocity_counts_s[i] = joints_[i].velocity();
    snapshot_.encoder[i] = pos_[i];
    snapshot_.dac[i] = dac_[i];
  }
  snapshot_.mode = mode_;
  snapshot_.error = dpr_.error();
  snapshot_.homed = homed_;
  snapshot_.gripper_closed = gripper_closed_;
  snapshot_.lights = dpr_.read_lighting();
  snapshot_.sample_period_us = dpr_.sample_period_us();
  snapshot_.periods = periods_;
  snapshot_.deadline_errors = deadline_errors_;
  snapshot_.late_served = late_served_;
  snapshot_.stalls_absorbed = stalls_absorbed_;
  snapshot_.late_max_us = std::max(snapshot_.late_max_us, late_max_us_);
  snapshot_.absorbed_s = static_cast<double>(absorbed_ns_) * 1e-9;
  late_max_us_ = 0.0;
}

SlaveSnapshot Slave::take_snapshot() {
  std::lock_guard lock(mutex_);
  SlaveSnapshot s = snapshot_;
  snapshot_.late_max_us = 0.0;
  return s;
}

template <typename Done>
bool Slave::idle_wait(Done&& done) {
  const auto poll = static_cast<std::int64_t>(options_.idle_poll_s * 1e9);
  for (;;) {
    if (stopping()) {
      return false;
    }
    advance_to(board_now());
    service_mailbox();
    publish();
    if (done()) {
      return true;
    }
    sleep_until_ns(now_ns() + poll);
  }
}

void Slave::run(const std::atomic<bool>& stop) {
  stop_ = &stop;
  prctl(PR_SET_TIMERSLACK, 1000UL, 0UL, 0UL, 0UL);  // 1 us: the handshake polls in 20 us steps
  // Initialisation (cseg at 2080h): clear the error register, software-reset the counters
  // (done by the JointModels: they read 0 where the arm is at power-up), open the gripper.
  dpr_.set_error(0);
  gripper_closed_ = false;
  t_phys_ns_ = board_now();
  control_.set_grace_us(static_cast<std::uint32_t>(std::clamp(
      options_.deadline_slack_s * 1e6, 0.0, static_cast<double>(UINT32_MAX))));
  while (!stopping()) {
    // main_loop
    dpr_.set_command(0);
    dpr_.set_gripper(0);
    mode_ = SlaveMode::kIdle;
    wait_for_command();
  }
  zero_dacs();
  publish();
}

void Slave::wait_for_command() {
  const auto poll = static_cast<std::int64_t>(options_.idle_poll_s * 1e9);
  for (;;) {
    if (stopping()) {
      return;
    }
    advance_to(board_now());  // the arm moved with the DACs as they were until now
    zero_dacs();
    get_robot_state();
    overrun_check();
    service_mailbox();
    publish();
    if (dpr_.error() != 0) {  // keep waiting until it's corrected
      sleep_until_ns(now_ns() + poll);
      continue;
    }
    const std::uint16_t command = dpr_.command();
    if ((command & dpr7545::kCommandControl) != 0) {
      control_mode();
      return;
    }
    if ((command & dpr7545::kCommandFindHome) != 0) {
      find_home_mode();
      return;
    }
    const std::uint16_t gripper = dpr_.gripper();
    if ((gripper & dpr7545::kGripperOpen) != 0) {
      gripper_mode(false);
      return;
    }
    if ((gripper & dpr7545::kGripperClose) != 0) {
      gripper_mode(true);
      return;
    }
    sleep_until_ns(now_ns() + poll);
  }
}

std::int64_t Slave::absorb_own_stall(std::int64_t& last_look_ns, std::int64_t& deadline_ns) noexcept {
  // The board this simulates never stops, but this process can: when it was not running for
  // longer than a wait step can take (the machine, or this thread's CPU, was taken away), no
  // simulated time passed for the deadline either, so the master gets that time back. A master
  // that is late while this process runs is still flagged, as the board would.
  const std::int64_t now = now_ns();
  control_.set_alive_ns(now);
  const std::int64_t gap = now - last_look_ns;
  last_look_ns = now;
  if (gap > kOwnStallNs) {
    deadline_ns += gap;
    ++stalls_absorbed_;
  }
  return now;
}

void Slave::control_mode() {
  std::int64_t grid = now_ns();  // CLR TIMER2
  std::int64_t board = board_now();
  advance_to(board);
  dpr_.set_timing_a(0);  // clear the timing registers
  dpr_.set_timing_b(0);
  mode_ = SlaveMode::kControl;
  if (control_since_ns_ < 0) {
    control_since_ns_ = grid;
  }
  for (;;) {
    if (stopping()) {
      return;
    }
    const std::int64_t start = now_ns();
    // The encoders are read now, when the period starts, after exactly one period of the
    // board's clock under the torques of the last (the board's timer does not stall with this
    // process, nor wait for a late master). The host's instant and the board's are published
    // in the simulator's control block: the master's path follows the board's clock, so this
    // process's scheduling does not turn into position error (the real board samples on its
    // timer's exact grid, which the master tracks instead).
    advance_to(board);
    control_.set_alive_ns(start);
    control_.set_sample_time_ns(start);
    control_.set_board_time_ns(board);
    late_max_us_ = std::max(late_max_us_, static_cast<double>(start - grid) * 1e-3);
    const std::int64_t period = period_ns();
    dpr_.set_timing_a(0x0001);  // signal master to begin its servo loop
    // The master's period runs from the moment it could see the start (a descheduling of this
    // process before that point must not shorten the master's window).
    // The grace of deadline_slack_s (0 on the board) is added to both deadlines; an injected
    // miss stalls past the board's own deadline, as before (the master's link check, a few
    // cycles without an exchange, would fault first if it waited for the slack too).
    const std::int64_t announced = now_ns();
    const std::int64_t board_deadline = announced + period;
    const auto slack = static_cast<std::int64_t>(options_.deadline_slack_s * 1e9);
    std::int64_t deadline = board_deadline + slack;
    if (const std::int64_t stall = stall_next_period_ns_.exchange(0, std::memory_order_relaxed);
        stall > 0) {
      sleep_until_ns(announced + stall);  // injected (tests): descheduled before the positions
    }
    get_robot_state();
    overrun_check();  // check for overruns and end if found
    ++periods_;
    if (dpr_.error() != 0) {
      return;
    }
    if (arm_deadline_miss_) {
      // Injected: the slave itself stalls past the deadline before looking for the torques,
      // which the slave code answers with "torques late".
      arm_deadline_miss_ = false;
      sleep_until_ns(board_deadline + period / 2);
      set_error_bits(dpr7545::kErrTorquesLate);
      ++deadline_errors_;
      return;
    }
    // wait_for_torque. The slave code tests the deadline before the flag; we test the flag
    // first: this process may be descheduled past the deadline while the master's torques were
    // already there, and its own lateness must not be blamed on the master. On time, the two
    // orders are the same. The first look's gap runs from the announcement: a stall before the
    // positions were published (the master could not answer) is this process's, not the
    // master's (a soak's job paused on 0x1000 while the master woke on time every period).
    std::int64_t last_look = announced;
    for (;;) {
      if (dpr_.command() == 0) {
        return;  // the master ended control mode
      }
      if ((dpr_.timing_b() & dpr7545::kTimingBTorquesReady) != 0) {
        break;
      }
      if (absorb_own_stall(last_look, deadline) > deadline) {
        set_error_bits(dpr7545::kErrTorquesLate);
        ++deadline_errors_;
        return;
      }
      if (stopping()) {
        return;
      }
      wait_step(start);
    }
    std::array<std::uint16_t, kJoints> words{};
    for (int j = 0; j < kJoints; ++j) {
      words[static_cast<std::size_t>(j)] = dpr_.torque(j);
    }
    const std::uint16_t torque_bits = dpr7545::check_torques(words);
    if (torque_bits != 0) {
      set_error_bits(torque_bits);  // torques out of range: end with error
      return;
    }
    dpr_.set_timing_b(0);  // tell master that torques were accepted
    dac_ = words;          // torque_out: first rank, then the common strobe
    if (arm_loop_late_) {  // injected: the slave stalls after accepting the torques
      arm_loop_late_ = false;
      sleep_until_ns(board_deadline + period / 2);
      set_error_bits(dpr7545::kErrLoopLate);
      ++deadline_errors_;
      return;
    }
    // wait_for_master (flag before deadline, as above)
    const std::int64_t accepted = now_ns();
    last_look = accepted;
    for (;;) {
      if (dpr_.timing_a() == 0) {
        break;
      }
      if (absorb_own_stall(last_look, deadline) > deadline) {
        set_error_bits(dpr7545::kErrLoopLate);
        ++deadline_errors_;
        return;
      }
      if (stopping()) {
        return;
      }
      wait_step(accepted);
    }
    if (now_ns() > deadline - slack) {  // (deadline includes this process's own stalls)
      ++late_served_;  // the board would have flagged this period; the slack covered it
    }
    service_mailbox();
    publish();
    // wait_next_period; SUB TIMER2,[SAMPLE_PERIOD] keeps the grid. When this process fell
    // more than a period behind, it skips the grid points it missed but stays on the grid, so
    // that the sampling instants remain t0 + k * period for the master.
    grid += period;
    board += period;
    const std::int64_t now = now_ns();
    if (now > grid + period) {
      grid += (now - grid) / period * period;
    }
    // The grid points skipped are time the board's clock never saw: however control mode
    // ends, the clock goes on from here with the host's (board_now()).
    absorbed_ns_ = grid - board;
    sleep_until_ns(grid);
  }
}

void Slave::delay() {
  const std::int64_t until = now_ns() + static_cast<std::int64_t>(options_.delay_s * 1e9);
  (void)idle_wait([&] { return now_ns() >= until; });
}

void Slave::find_home_mode() {
  mode_ = SlaveMode::kHoming;
  homed_ = false;
  for (const auto& step : dpr7545::kHomingSequence) {
    const auto j = static_cast<std::size_t>(step.joint);
    const std::uint8_t home = static_cast<std::uint8_t>(1U << step.home_bit);
    const std::uint8_t index = static_cast<std::uint8_t>(1U << step.index_bit);
    // JBS TEMP1, home_bit, fh_1: the sensor bit set means "not at home" (active low).
    if ((read_sensor_port() & home) == 0) {
      dac_[j] = step.positive_torque;  // move the joint away from HOME
      if (!idle_wait([&] { return (read_sensor_port() & home) != 0; })) {
        return;
      }
      delay();  // keep moving away during 'delay'
      zero_dacs();
    }
    dac_[j] = step.negative_torque;  // fh_1: move the joint toward home
    if (!idle_wait([&] { return (read_sensor_port() & home) == 0; })) {  // fh_2
      return;
    }
    (void)read_sensor_port();  // forget index pulses seen before the sensor set
    if (!idle_wait([&] { return (read_sensor_port() & index) != 0; })) {  // fh_3
      return;
    }
    // The counter resets on the index (the hardware latches it at the pulse), then the torque
    // goes: the joint coasts a little past home.
    joints_[j].reset_counter_at(joints_[j].last_index_position());
    zero_dacs();
  }
  homed_ = true;
  publish();
}

void Slave::gripper_mode(bool close) {
  mode_ = SlaveMode::kGripper;
  delay();
  gripper_closed_ = close;  // ST CL_GRP,[CE_5] (close) or ST 0,[CE_5] (open)
  publish();
  delay();
}

}  // namespace cell::sim7545
