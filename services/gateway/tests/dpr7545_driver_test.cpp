// The dpr7545 driver (the master) against an in-process fake slave: a thread playing the 80C196
// side of the handshake (digest 000 §2.3) on a heap DPR window, with a trivial plant and knobs
// to misbehave. The test thread plays the gateway's servo thread (read, write, next period).
#include "dpr7545_driver.hpp"

#include <unistd.h>

#include <atomic>
#include <chrono>
#include <filesystem>
#include <mutex>
#include <thread>
#include <vector>

#include <fmt/format.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "cell/common/realtime.hpp"
#include "cell/dpr7545/codec.hpp"
#include "cell/dpr7545/sim_control.hpp"
#include "cell/kinematics/robot_config.hpp"
#include "cell/testing/env.hpp"
#include "cell/testing/matchers.hpp"
#include "gateway_config.hpp"
#include "homing_record.hpp"

namespace cell::gateway {
namespace {

namespace d = dpr7545;
using namespace std::chrono_literals;
using ::cell::testing::IsErrWith;
using ::cell::testing::IsOk;
using ::testing::HasSubstr;

// A 20 ms sample period keeps the fake slave's deadlines far from a loaded machine's hiccups
// (these threads are not real-time); the driver's logic does not depend on the period. The
// 1 ms loop runs in tests/gateway_7545 and bench/servo.
constexpr int kPeriodUs = 20000;
constexpr double kTs = kPeriodUs * 1e-6;
constexpr auto kPeriod = std::chrono::microseconds(kPeriodUs);

std::int64_t mono_ns() {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

/// A transport viewing another transport's window (both sides in one process).
class ViewTransport final : public d::Transport {
 public:
  explicit ViewTransport(std::span<std::byte> window) : window_(window) {}
  std::span<std::byte> window() noexcept override { return window_; }
  const std::string& describe() const noexcept override { return name_; }

 private:
  std::span<std::byte> window_;
  std::string name_ = "heap-view";
};

/// The slave's side, reduced to the protocol: main_loop / idle loop / control_mode with the
/// deadlines and checks, homing (instantaneous: the joints land at `home_landing`), gripper
/// (a 20 ms dwell). Plant: each accepted torque moves the joint by gain * (word - 0x800) counts
/// per period (gain 0: the joints stay where they are).
/// SCHED_FIFO priority of the fake slave's thread and of the test's (the master's) thread where
/// permitted (root): config/gateway-ibm7545-dpr.yaml's realtime_priority. On a loaded host
/// under normal scheduling either could miss a 20 ms period and fault the exchange.
constexpr int kRealtimePriority = 50;

class FakeSlave {
 public:
  explicit FakeSlave(std::span<std::byte> window) : dpr_(window) {
    for (auto& p : position_) {
      p = 0;
    }
    thread_ = std::thread([this] {
      (void)set_thread_fifo(kRealtimePriority);  // a board is never descheduled
      run();
    });
  }
  ~FakeSlave() {
    stop_ = true;
    thread_.join();
  }

  std::atomic<double> gain{0.0};
  std::atomic<bool> stall{false};          ///< stop starting periods (the slave hangs)
  std::atomic<bool> miss_deadline{false};  ///< next period: flag 0x1000
  std::atomic<std::uint16_t> overrun_bits{0};  ///< rewritten into the low byte every pass
  std::array<std::atomic<double>, d::kJoints> position_{};
  std::array<double, d::kJoints> home_landing = {-20.0, 10.0, -30.0, 5.0};

  struct Period {
    std::array<std::int32_t, d::kJoints> reported{};
    std::array<std::uint16_t, d::kJoints> torque{};
  };
  std::vector<Period> periods() {
    std::lock_guard lock(mutex_);
    return periods_;
  }
  int gripper_actions() const { return gripper_actions_; }
  bool gripper_closed() const { return gripper_closed_; }
  int control_entries() const { return control_entries_; }
  bool saw_invalid_torque_output() const { return invalid_output_; }

 private:
  bool stopping() const { return stop_.load(); }
  void state() {
    for (int j = 0; j < d::kJoints; ++j) {
      dpr_.set_position(j, static_cast<std::int32_t>(std::lround(position_[j].load())));
    }
    dpr_.set_timing_a(0x3);
    for (int j = 0; j < d::kJoints; ++j) {
      dpr_.set_velocity(j, 0);
    }
    dpr_.set_timing_a(0x7);
    dpr_.set_timing_a(0xF);
    const std::uint16_t o = overrun_bits.load();
    dpr_.set_error(static_cast<std::uint16_t>((dpr_.error() & 0xFF00) | o));
  }
  static void nap(long ns) {
    const timespec ts{0, ns};
    nanosleep(&ts, nullptr);
  }
  void run() {
    while (!stopping()) {
      dpr_.set_command(0);  // main_loop
      dpr_.set_gripper(0);
      idle();
    }
  }
  void idle() {
    while (!stopping()) {
      if (stall) {
        nap(50'000);
        continue;
      }
      state();
      if (dpr_.error() != 0) {
        nap(50'000);
        continue;
      }
      const std::uint16_t command = dpr_.command();
      if ((command & d::kCommandControl) != 0) {
        control();
        return;
      }
      if ((command & d::kCommandFindHome) != 0) {
        std::this_thread::sleep_for(30ms);
        for (int j = 0; j < d::kJoints; ++j) {
          position_[j] = home_landing[static_cast<std::size_t>(j)];
        }
        return;
      }
      const std::uint16_t gripper = dpr_.gripper();
      if (gripper != 0) {
        std::this_thread::sleep_for(10ms);
        gripper_closed_ = (gripper & d::kGripperClose) != 0;
        ++gripper_actions_;
        std::this_thread::sleep_for(10ms);
        return;
      }
      nap(50'000);
    }
  }
  void control() {
    ++control_entries_;
    std::int64_t grid = mono_ns();
    dpr_.set_timing_a(0);
    dpr_.set_timing_b(0);
    for (;;) {
      while (stall && !stopping()) {
        nap(50'000);
      }
      if (stopping()) {
        return;
      }
      const std::int64_t start = mono_ns();
      const std::int64_t period = std::int64_t{dpr_.sample_period_us()} * 1000;
      const std::int64_t deadline = start + period;
      dpr_.set_timing_a(0x1);
      Period record;
      for (int j = 0; j < d::kJoints; ++j) {
        record.reported[static_cast<std::size_t>(j)] =
            static_cast<std::int32_t>(std::lround(position_[j].load()));
      }
      state();
      if (dpr_.error() != 0) {
        return;
      }
      if (miss_deadline.exchange(false)) {
        std::this_thread::sleep_for(std::chrono::nanoseconds(period + period / 2));
      }
      for (;;) {
        if (mono_ns() > deadline) {
          dpr_.set_error(dpr_.error() | d::kErrTorquesLate);
          return;
        }
        if (dpr_.command() == 0) {
          return;
        }
        if ((dpr_.timing_b() & 1) != 0) {
          break;
        }
        nap(20'000);
      }
      std::array<std::uint16_t, d::kJoints> words{};
      for (int j = 0; j < d::kJoints; ++j) {
        words[static_cast<std::size_t>(j)] = dpr_.torque(j);
      }
      if (const std::uint16_t bits = d::check_torques(words); bits != 0) {
        dpr_.set_error(dpr_.error() | bits);
        return;
      }
      record.torque = words;
      for (int j = 0; j < d::kJoints; ++j) {
        if (!d::torque_word_valid(words[static_cast<std::size_t>(j)])) {
          invalid_output_ = true;
        }
        position_[j] =
            position_[j].load() + gain * d::torque_dac(words[static_cast<std::size_t>(j)]);
      }
      {
        std::lock_guard lock(mutex_);
        periods_.push_back(record);  // before the acceptance, so the master sees it recorded
      }
      dpr_.set_timing_b(0);
      for (;;) {
        if (mono_ns() > deadline) {
          dpr_.set_error(dpr_.error() | d::kErrLoopLate);
          return;
        }
        if (dpr_.timing_a() == 0) {
          break;
        }
        nap(20'000);
      }
      grid += period;
      while (mono_ns() < grid) {
        nap(50'000);
      }
    }
  }

  d::Dpr dpr_;
  std::atomic<bool> stop_{false};
  std::mutex mutex_;
  std::vector<Period> periods_;
  std::atomic<int> gripper_actions_{0};
  std::atomic<bool> gripper_closed_{false};
  std::atomic<int> control_entries_{0};
  std::atomic<bool> invalid_output_{false};
  std::thread thread_;
};

kinematics::RobotModel ibm7545() {
  auto model = kinematics::load_robot(cell::testing::source_dir() + "/config/robots/ibm7545.yaml");
  EXPECT_THAT(model, IsOk());
  return *model;
}

Dpr7545Options test_options() {
  Dpr7545Options o;
  o.sample_period_us = kPeriodUs;
  o.handshake_timeout_us = 18000;
  o.engage_speed_fraction = 0.02;  // per 20 ms sample: the crude plant follows it in range
  o.activate_timeout_s = 2.0;
  o.homing_timeout_s = 5.0;
  o.gripper_timeout_s = 5.0;
  return o;
}

class Dpr7545DriverTest : public ::testing::Test {
 protected:
  explicit Dpr7545DriverTest(kinematics::RobotModel model = ibm7545(),
                             Dpr7545Options options = test_options())
      : fifo_(kRealtimePriority),
        model_(std::move(model)),
        memory_(d::make_heap_transport()),
        slave_(memory_->window()),
        driver_(model_,
                std::move(options),
                kPeriod,
                [this]() -> Result<std::unique_ptr<d::Transport>> {
                  return std::unique_ptr<d::Transport>(
                      std::make_unique<ViewTransport>(memory_->window()));
                }),
        dpr_(memory_->window()) {
    setpoint_.q = JointVector::Zero(4);
    setpoint_.qd = JointVector::Zero(4);
  }

  void activate() {
    ASSERT_THAT(driver_.on_configure(), IsOk());
    ASSERT_THAT(driver_.on_activate(), IsOk());
    next_ = Clock::now();
  }

  /// One servo cycle on the period grid: read, then write the current setpoint.
  CycleStatus cycle() {
    std::this_thread::sleep_until(next_);
    next_ += kPeriod;
    const auto now = Clock::now();
    last_read_ = driver_.read(now, state_);
    if (last_read_ == CycleStatus::kFault) {
      return last_read_;
    }
    const CycleStatus w = driver_.write(now, setpoint_);
    return last_read_ != CycleStatus::kOk ? last_read_ : w;
  }

  /// Cycles until `done` (checked after each cycle) or `n` cycles.
  template <typename Fn>
  bool cycle_until(Fn&& done, int n = 400) {
    for (int i = 0; i < n; ++i) {
      (void)cycle();
      if (done()) {
        return true;
      }
    }
    return false;
  }

  /// Encoder counts per rad (or mm) of joint j.
  double counts(int j) const { return model_.joints()[static_cast<std::size_t>(j)].counts_per_unit; }

  /// Activates, homes and runs until control mode exchanges torques.
  void home_and_engage() {
    activate();
    ASSERT_THAT(driver_.command(DriverCommand::kHome, {}), IsOk());
    ASSERT_TRUE(cycle_until([&] { return state_.homed && !state_.busy; }))
        << "homing did not finish";
    ASSERT_TRUE(cycle_until([&] { return !slave_.periods().empty(); })) << "no control mode";
  }

  /// A simulator's control block (a grace of one period), control mode engaged, then the
  /// slave stalled at a period's boundary: its liveness stamp is the test's to set.
  d::SimControl engage_then_stall_the_simulator() {
    d::SimControl control(memory_->window());
    control.initialise(static_cast<std::uint32_t>(::getpid()));
    control.set_grace_us(kPeriodUs);
    home_and_engage();
    slave_.stall = true;
    std::this_thread::sleep_for(3 * kPeriod);  // let the running period end
    return control;
  }

  ScopedThreadFifo fifo_;  // first: the master runs at SCHED_FIFO from its construction on
  kinematics::RobotModel model_;
  std::unique_ptr<d::Transport> memory_;
  FakeSlave slave_;
  Dpr7545Driver driver_;
  d::Dpr dpr_;
  JointState state_;
  JointSetpoint setpoint_;
  CycleStatus last_read_ = CycleStatus::kOk;
  Clock::time_point next_{};
};

TEST_F(Dpr7545DriverTest, StaysOutOfControlModeUntilHomedThenHomesAndServos) {
  activate();
  for (int i = 0; i < 10; ++i) {
    EXPECT_EQ(cycle(), CycleStatus::kOk);
  }
  EXPECT_EQ(slave_.control_entries(), 0);  // not homed: no control mode, the DACs stay at 0 V
  EXPECT_FALSE(state_.homed);
  EXPECT_EQ(dpr_.sample_period_us(), kPeriodUs);  // written by the master
  ASSERT_THAT(driver_.command(DriverCommand::kHome, {}), IsOk());
  (void)cycle();
  EXPECT_TRUE(state_.busy);
  EXPECT_FALSE(state_.homed);
  ASSERT_TRUE(cycle_until([&] { return state_.homed; }));
  EXPECT_FALSE(state_.busy);
  ASSERT_TRUE(cycle_until([&] { return slave_.periods().size() >= 20; }));
  // One entry into control mode, and one more per re-engagement the driver counted because the
  // slave's period grid began out of phase with ours (a slave or master descheduled as it
  // engaged: a sanitizer's build on a loaded CI host did so). Nothing else may leave it.
  const auto rephases = driver_.counters().rephases;
  EXPECT_LE(rephases, 2U);
  EXPECT_EQ(slave_.control_entries(), 1 + static_cast<int>(rephases));
  EXPECT_EQ(dpr_.error(), 0);
  EXPECT_EQ(driver_.counters().handshake_timeouts, 0U);
  // The measured joints are the slave's counts through counts_per_unit.
  EXPECT_NEAR(state_.q[0], -20.0 / model_.joints()[0].counts_per_unit, 1e-12);
}

// The card (no simulator's control block) is waited for 4 cycles; a simulator that serves a
// late master within a grace is waited for as long (its own stalls): 20 periods' worth.
TEST_F(Dpr7545DriverTest, ASimulatorsGraceSetsHowLongItsLinkIsWaitedFor) {
  activate();
  EXPECT_EQ(driver_.info().link_retries, 3);
  driver_.on_deactivate();
  driver_.on_cleanup();
  const d::SimControl control(memory_->window());
  control.initialise(static_cast<std::uint32_t>(::getpid()));
  control.set_grace_us(20 * kPeriodUs);
  activate();
  EXPECT_EQ(driver_.info().link_retries, 20);
}

// The PD law of the thesis on every exchange, cross-checked from what the slave reported and
// received; and digest 000 §9.2 case 14 (e = 3 then 5 -> 0x9F4) through the driver.
TEST_F(Dpr7545DriverTest, TorquesAreTheThesisPdLawOfTheReportedPositions) {
  slave_.home_landing = {0, 0, 0, 0};
  home_and_engage();
  const double cpu = model_.joints()[0].counts_per_unit;
  const std::size_t first = slave_.periods().size();
  setpoint_.q[0] = 3.0 / cpu;
  (void)cycle();
  setpoint_.q[0] = 5.0 / cpu;
  (void)cycle();
  const auto periods = slave_.periods();
  ASSERT_GE(periods.size(), first + 2);
  const auto& p3 = periods[first];
  const auto& p5 = periods[first + 1];
  EXPECT_EQ(p3.reported[0], 0);
  EXPECT_EQ(p5.reported[0], 0);
  EXPECT_EQ(p3.torque[0], d::torque_word(d::pd_torque(60, 0.1, kTs, 3.0 / cpu * cpu, 0.0)));
  EXPECT_EQ(p5.torque[0],
            d::torque_word(d::pd_torque(60, 0.1, kTs, 5.0 / cpu * cpu, 3.0 / cpu * cpu)));
  // At Ts = 20 ms, kv / Ts = 5: 0x800 + 60 * 5 + 5 * 2 = 2358; the digest's 2548 is at 1 ms
  // (the codec test pins it).
  EXPECT_NEAR(p5.torque[0], 2358, 1);
  EXPECT_EQ(p5.torque[1], d::kTorqueZero);  // the other joints sit on their setpoints
}

TEST_F(Dpr7545DriverTest, PdLawHoldsOnEveryExchangeWhileTheArmMoves) {
  slave_.home_landing = {0, 0, 0, 0};
  slave_.gain = 0.012;  // a crude plant: every accepted torque moves the joint a little
  home_and_engage();
  // 40 exchanges in a row, each checked. A cycle is an exchange when it returned kOk and the
  // slave recorded exactly one period in it (it records before accepting the torques). On a
  // loaded host a cycle may exchange nothing: a handshake the slave thread missed (kRetry),
  // or a re-phase to an on-time period (kOk, no exchange); it may also leave a late period in
  // the slave's record. Then the ramp goes on for a few cycles and the 40 start again.
  std::size_t first = 0;
  std::vector<JointVector> setpoints;
  int n = 0;  // the ramp's sample: continuous across tries
  const auto ramp = [&] {
    setpoint_.q[0] = 0.0001 * n;  // rad: 5 counts per sample
    setpoint_.q[2] = 0.01 * n;    // mm: 3.8 counts per sample
  };
  bool clean = false;
  for (int attempt = 0; attempt < 10 && !clean; ++attempt) {
    first = slave_.periods().size();
    setpoints.clear();
    clean = true;
    for (int k = 0; k < 40; ++k, ++n) {
      ramp();
      setpoints.push_back(setpoint_.q);
      const std::size_t recorded = slave_.periods().size();
      const CycleStatus status = cycle();
      ASSERT_NE(status, CycleStatus::kFault) << n;
      // One period recorded in this cycle and none between cycles: periods[first + k].
      if (status != CycleStatus::kOk || recorded != first + static_cast<std::size_t>(k) ||
          slave_.periods().size() != recorded + 1) {
        clean = false;
        for (int settle = 0; settle < 3; ++settle, ++n) {
          ramp();
          ASSERT_NE(cycle(), CycleStatus::kFault) << n;
        }
        break;
      }
    }
  }
  ASSERT_TRUE(clean) << "no 40 exchanges in a row in 10 tries";
  const auto periods = slave_.periods();
  ASSERT_GE(periods.size(), first + 40);
  for (int k = 1; k < 40; ++k) {
    for (int j : {0, 2}) {
      const double cpu = model_.joints()[static_cast<std::size_t>(j)].counts_per_unit;
      const auto& now = periods[first + static_cast<std::size_t>(k)];
      const auto& before = periods[first + static_cast<std::size_t>(k) - 1];
      const double e = setpoints[static_cast<std::size_t>(k)][j] * cpu - now.reported[j];
      const double e_prev = setpoints[static_cast<std::size_t>(k) - 1][j] * cpu - before.reported[j];
      const double kp = d::kDefaultKp[static_cast<std::size_t>(j)];
      EXPECT_EQ(now.torque[j], d::torque_word(d::pd_torque(kp, 0.1, kTs, e, e_prev)))
          << "sample " << k << " joint " << j;
    }
  }
  EXPECT_FALSE(slave_.saw_invalid_torque_output());
}

// The 7545's Z counts grow going down: a setpoint 1 mm lower than the arm drives positive.
TEST_F(Dpr7545DriverTest, ZDownIsPositiveCountsWithTheThesisModel) {
  slave_.home_landing = {0, 0, 0, 0};
  home_and_engage();
  setpoint_.q[2] = 0.01;  // 0.01 mm down: 3.8 counts
  (void)cycle();
  (void)cycle();
  EXPECT_GT(slave_.periods().back().torque[2], d::kTorqueZero);
  EXPECT_NEAR(state_.q[2], 0.0, 1e-9);
}

kinematics::RobotModel z_up_model() {
  kinematics::ScaraModel scara = *ibm7545().scara();
  scara.z_direction = kinematics::ZDirection::kUp;
  scara.roll_sense = kinematics::RotationSense::kCounterClockwise;
  auto model = kinematics::RobotModel::create("ibm7545_z_up", scara);
  EXPECT_THAT(model, IsOk());
  return *model;
}

class Dpr7545ZUpTest : public Dpr7545DriverTest {
 protected:
  Dpr7545ZUpTest() : Dpr7545DriverTest(z_up_model()) {}
};

// A model whose Z grows upward (and R counterclockwise) drives the same hardware: the
// driver maps its conventions onto the 7545's counters (Z down, R clockwise positive).
TEST_F(Dpr7545ZUpTest, ModelConventionsAreMappedOntoTheCounters) {
  activate();
  slave_.position_[2] = -381;  // counts: 1 mm up on the 7545
  slave_.position_[3] = 227;   // counts: about 1 deg clockwise
  ASSERT_TRUE(cycle_until([&] { return std::abs(state_.q[2]) > 0.5; }, 20));
  EXPECT_NEAR(state_.q[2], 381.0 / 380.96, 1e-9);  // +1 mm: up in this model
  EXPECT_NEAR(state_.q[3], -227.0 / model_.joints()[3].counts_per_unit, 1e-12);
  EXPECT_LT(state_.q[3], 0.0);  // clockwise is negative in a counterclockwise model
  slave_.home_landing = {0, 0, 0, 0};
  ASSERT_THAT(driver_.command(DriverCommand::kHome, {}), IsOk());
  ASSERT_TRUE(cycle_until([&] { return !slave_.periods().empty(); }));
  setpoint_.q[2] = 0.02;  // 0.02 mm up = -7.6 counts
  setpoint_.q[3] = 0.0002;  // counterclockwise = -2.6 counts
  (void)cycle();
  (void)cycle();
  EXPECT_LT(slave_.periods().back().torque[2], d::kTorqueZero);
  EXPECT_LT(slave_.periods().back().torque[3], d::kTorqueZero);
}

// After homing the arm coasted past home; the host still holds its old setpoint. Control mode
// starts at the arm (0 V), then the reference closes the gap at the engage speed: no torque
// word ever leaves the DAC range.
TEST_F(Dpr7545DriverTest, ControlModeStartsBumplessAndClosesTheGap) {
  slave_.home_landing = {-200, 150, -300, 100};
  slave_.gain = 0.012;
  home_and_engage();
  const auto first = slave_.periods().front();
  for (int j = 0; j < d::kJoints; ++j) {
    EXPECT_EQ(first.torque[static_cast<std::size_t>(j)], d::kTorqueZero) << j;
  }
  ASSERT_TRUE(cycle_until(
      [&] {
        return std::abs(state_.q[0] * counts(0)) < 3 && std::abs(state_.q[2] * counts(2)) < 3;
      },
      400));
  EXPECT_FALSE(slave_.saw_invalid_torque_output());
  EXPECT_EQ(dpr_.error(), 0);
}

// A host setpoint that steps once control mode runs (a trajectory that starts within the start
// tolerance of the arm, not at the held setpoint: 61 counts of J1 right after a homing) is not
// a path the arm can follow: the step is closed at the engage speed, like the gap at engage,
// never put into one exchange's error (a torque fault from ~25 counts on the 7545).
TEST_F(Dpr7545DriverTest, ASetpointStepIsClosedAtTheEngageSpeedNotInOneExchange) {
  slave_.home_landing = {0, 0, 0, 0};
  slave_.gain = 0.012;
  home_and_engage();
  ASSERT_FALSE(HasFatalFailure());
  for (int i = 0; i < 5; ++i) {
    ASSERT_NE(cycle(), CycleStatus::kFault);
  }
  // 1500 counts of J1 and 1000 of Z at once, at rest (qd 0): beyond what the joints' limits
  // allow over this test's 20 ms sample (J1: 1430 deg/s^2 x (20 ms)^2 = 500 counts).
  setpoint_.q[0] = 1500.0 / counts(0);
  setpoint_.q[2] = -1000.0 / counts(2);
  double worst_word = 0;
  const bool closed = cycle_until(
      [&] {
        for (const auto& p : slave_.periods()) {
          worst_word = std::max(worst_word, std::abs(static_cast<double>(p.torque[0]) - 0x800));
        }
        return std::abs(state_.q[0] * counts(0) - 1500.0) < 3 &&
               std::abs(state_.q[2] * counts(2) + 1000.0) < 3;
      },
      400);
  EXPECT_TRUE(closed) << "J1 at " << state_.q[0] * counts(0) << " counts";
  EXPECT_FALSE(slave_.saw_invalid_torque_output());
  EXPECT_EQ(dpr_.error(), 0);
  EXPECT_GE(driver_.statistics().steps_absorbed, 1U);
  // The whole step at once would be a PD word of 60 x 1500 counts.
  EXPECT_LT(worst_word, 2047.0);
}

// Digest 000 §9.2 case 6: torques late -> 0x1000: a fault with its meaning, torques zeroed,
// latched until reset; reset clears the register and restarts control mode.
TEST_F(Dpr7545DriverTest, TorquesLateFaultIsLatchedAndResetRestartsControl) {
  home_and_engage();
  slave_.miss_deadline = true;
  ASSERT_TRUE(cycle_until([&] { return last_read_ == CycleStatus::kFault; }, 50));
  EXPECT_EQ(state_.fault_bits & 0xFFFF, d::kErrTorquesLate);
  EXPECT_THAT(driver_.describe_faults(state_.fault_bits),
              HasSubstr("master did not provide torques in time (0x1000)"));
  EXPECT_EQ(driver_.counters().slave_deadline_errors, 1U);
  for (int j = 0; j < d::kJoints; ++j) {
    EXPECT_EQ(dpr_.torque(j), d::kTorqueZero);
  }
  for (int i = 0; i < 5; ++i) {
    EXPECT_EQ(cycle(), CycleStatus::kFault);  // latched
  }
  EXPECT_THAT(driver_.command(DriverCommand::kGripperClose, {}),
              IsErrWith(Errc::kNotReady, "reset first"));
  const auto entries = slave_.control_entries();
  ASSERT_THAT(driver_.command(DriverCommand::kReset, {}), IsOk());
  EXPECT_EQ(dpr_.error(), 0);
  ASSERT_TRUE(cycle_until([&] { return slave_.control_entries() > entries; }, 50));
  const std::size_t n = slave_.periods().size();
  ASSERT_TRUE(cycle_until([&] { return slave_.periods().size() >= n + 10; }));
  EXPECT_EQ(last_read_, CycleStatus::kOk);
}

// Digest 000 §9.2 case 6/14: a PD value out of range is sent as an invalid word (never clamped),
// the slave aborts with 0x100 for J1, and the fault reaches read() with its bits.
TEST_F(Dpr7545DriverTest, OutOfRangeTorqueIsNotClampedAndFaultsWithTheJointsBit) {
  slave_.home_landing = {0, 0, 0, 0};
  home_and_engage();
  setpoint_.q[0] = 40.0 / counts(0);  // e = 40 counts at once: 8448 at 1 ms, 4648 at 20 ms
  ASSERT_TRUE(cycle_until([&] { return last_read_ == CycleStatus::kFault; }, 10));
  EXPECT_EQ(state_.fault_bits, d::kErrTorqueJ1);
  EXPECT_THAT(driver_.describe_faults(state_.fault_bits), HasSubstr("J1"));
  EXPECT_FALSE(slave_.saw_invalid_torque_output());
}

TEST_F(Dpr7545DriverTest, OverrunFaultsAndComesBackAfterResetWhileTheJointIsOut) {
  home_and_engage();
  slave_.overrun_bits = d::kErrZPositiveOverrun;
  ASSERT_TRUE(cycle_until([&] { return last_read_ == CycleStatus::kFault; }, 20));
  EXPECT_EQ(state_.fault_bits, d::kErrZPositiveOverrun);
  EXPECT_THAT(driver_.describe_faults(state_.fault_bits), HasSubstr("Z positive overrun"));
  ASSERT_THAT(driver_.command(DriverCommand::kReset, {}), IsOk());
  ASSERT_TRUE(cycle_until([&] { return last_read_ == CycleStatus::kFault; }, 20));
  EXPECT_EQ(state_.fault_bits, d::kErrZPositiveOverrun);
  slave_.overrun_bits = 0;  // moved back by hand
  ASSERT_THAT(driver_.command(DriverCommand::kReset, {}), IsOk());
  const std::size_t n = slave_.periods().size();
  ASSERT_TRUE(cycle_until([&] { return slave_.periods().size() >= n + 5; }));
}

// The slave reads the gripper register only when idle: the driver leaves control mode, writes
// it, waits for the slave to clear it (busy meanwhile), then restarts control mode.
TEST_F(Dpr7545DriverTest, GripperLeavesControlModeAndComesBack) {
  home_and_engage();
  ASSERT_THAT(driver_.command(DriverCommand::kGripperClose, {}), IsOk());
  (void)cycle();
  EXPECT_TRUE(state_.busy);
  EXPECT_EQ(state_.gripper, cell_robot_GRIPPER_CLOSING);
  ASSERT_TRUE(cycle_until([&] { return state_.gripper == cell_robot_GRIPPER_CLOSED; }));
  EXPECT_TRUE(slave_.gripper_closed());
  EXPECT_EQ(slave_.gripper_actions(), 1);
  EXPECT_FALSE(state_.busy);
  ASSERT_TRUE(cycle_until([&] { return slave_.control_entries() == 2; }));
  ASSERT_THAT(driver_.command(DriverCommand::kGripperOpen, {}), IsOk());
  ASSERT_TRUE(cycle_until([&] { return state_.gripper == cell_robot_GRIPPER_OPEN; }));
  EXPECT_FALSE(slave_.gripper_closed());
  EXPECT_EQ(dpr_.error(), 0);  // leaving and re-entering never missed a deadline
  EXPECT_EQ(driver_.counters().handshake_timeouts, 0U);
}

// Digest 000 §9.2 case 5 (lighting): the latch at 0xC9000 (window offset 0x1000).
TEST_F(Dpr7545DriverTest, LightsWriteTheLatch) {
  activate();
  CommandArgs args;
  args.halogen_on = true;
  ASSERT_THAT(driver_.command(DriverCommand::kLights, args), IsOk());
  EXPECT_EQ(dpr_.read_lighting(), 0b01);
  args.fluorescent_on = true;
  ASSERT_THAT(driver_.command(DriverCommand::kLights, args), IsOk());
  EXPECT_EQ(dpr_.read_lighting(), 0b11);
  args = {};
  ASSERT_THAT(driver_.command(DriverCommand::kLights, args), IsOk());
  EXPECT_EQ(dpr_.read_lighting(), 0);
}

TEST_F(Dpr7545DriverTest, GainsAreEditableAtRunTime) {
  slave_.home_landing = {0, 0, 0, 0};
  home_and_engage();
  CommandArgs args;
  args.kp = {120, 60, 55, 60};
  args.kv = {0, 0.1, 0.1, 0.1};
  ASSERT_THAT(driver_.command(DriverCommand::kSetGains, args), IsOk());
  setpoint_.q[0] = 2.0 / counts(0);
  (void)cycle();
  (void)cycle();
  EXPECT_NEAR(slave_.periods().back().torque[0], 0x800 + 240, 1);  // 120 * 2, no D term
  args.kp = {1, 2};
  EXPECT_THAT(driver_.command(DriverCommand::kSetGains, args),
              IsErrWith(Errc::kInvalidArgument, "4 kp and 4 kv"));
  EXPECT_FALSE(driver_.supports(DriverCommand::kSetMode));
}

// A slave that stops answering costs a cycle at most its budget and is counted as a timeout
// (kRetry: the host faults after a few in a row).
TEST_F(Dpr7545DriverTest, SilentSlaveGivesBoundedRetriesNotABlockedCycle) {
  home_and_engage();
  slave_.stall = true;
  std::this_thread::sleep_for(3 * kPeriod);  // let the running period end
  int retries = 0;
  for (int i = 0; i < 4; ++i) {
    const auto t0 = std::chrono::steady_clock::now();
    const CycleStatus s = cycle();
    const auto spent = std::chrono::steady_clock::now() - t0;
    EXPECT_LT(spent, kPeriod + 2 * kPeriod);  // sleep to the grid + at most the budget
    retries += s == CycleStatus::kRetry ? 1 : 0;
    if (s == CycleStatus::kFault) {
      break;  // the slave's own 0x1000 from the period it abandoned
    }
  }
  EXPECT_GE(retries + (last_read_ == CycleStatus::kFault ? 1 : 0), 1);
  EXPECT_GE(driver_.counters().handshake_timeouts, 1U);
  slave_.stall = false;
}

// A simulated board whose process does not run (its liveness stamp stands still: a VM's CPU
// taken away) starts no period, but no board time passes and its arm stands still: the master
// waits for it without counting a link failure, and counts the cycles. One that runs and does
// not answer, one silent past the limit, and the real card (no control block) are retried.
TEST_F(Dpr7545DriverTest, AStalledSimulatorIsWaitedForAndCountedNotTakenForALostLink) {
  const d::SimControl control = engage_then_stall_the_simulator();
  const auto stalled_for = [&](std::int64_t silent_ns) {
    control.set_alive_ns(mono_ns() - silent_ns);
    return cycle();
  };
  // Silent for 10 periods: its own stall. The path stands still with the arm.
  for (int i = 0; i < 4; ++i) {
    const CycleStatus s = stalled_for(10LL * kPeriodUs * 1000);
    ASSERT_NE(s, CycleStatus::kFault) << "cycle " << i;
    EXPECT_EQ(s, CycleStatus::kOk) << "cycle " << i;
    EXPECT_EQ(state_.clock_advance_s, 0.0);
  }
  EXPECT_GE(driver_.counters().simulator_stall_cycles, 3U);
  EXPECT_GE(driver_.counters().max_simulator_silence_ns, 10LL * kPeriodUs * 1000);
  const std::uint64_t stalls = driver_.counters().simulator_stall_cycles;
  // Running (stamped just now) and not answering: a link failure.
  EXPECT_EQ(stalled_for(0), CycleStatus::kRetry);
  // Silent past the limit: hung or gone, a link failure too.
  EXPECT_EQ(stalled_for(Dpr7545Driver::kSimulatorSilentLimitNs + 1'000'000), CycleStatus::kRetry);
  EXPECT_EQ(driver_.counters().simulator_stall_cycles, stalls);
  slave_.stall = false;
}

// A procedure's timeout does not run while the simulator's process is stalled: its slave could
// not answer (a soak job faulted with 0x20000 while the simulator stalled). A slave that runs
// and does not answer still times out.
TEST_F(Dpr7545DriverTest, AProcedureWaitsOutASimulatorsStallButNotASilentRunningSlave) {
  const d::SimControl control = engage_then_stall_the_simulator();
  ASSERT_THAT(driver_.command(DriverCommand::kGripperClose, {}), IsOk());
  // Silent for 10 periods at every look, for longer than leaving control mode may take.
  constexpr int kLeaveTimeoutPeriods = 200;  // dpr7545_driver.cpp
  for (int i = 0; i < kLeaveTimeoutPeriods + 20; ++i) {
    control.set_alive_ns(mono_ns() - 10LL * kPeriodUs * 1000);
    ASSERT_NE(cycle(), CycleStatus::kFault) << "cycle " << i << ": " << state_.fault_bits;
  }
  EXPECT_GE(driver_.counters().procedure_stall_ns, kLeaveTimeoutPeriods * kPeriodUs * 1000LL);
  slave_.stall = false;
  ASSERT_TRUE(cycle_until([&] { return state_.gripper == cell_robot_GRIPPER_CLOSED; }));
  EXPECT_EQ(dpr_.error(), 0);
  ASSERT_TRUE(cycle_until([&] { return slave_.control_entries() == 2; }));

  // Stamped alive at every look, yet not answering: the leave times out.
  slave_.stall = true;
  std::this_thread::sleep_for(3 * kPeriod);
  ASSERT_THAT(driver_.command(DriverCommand::kGripperOpen, {}), IsOk());
  const std::int64_t held = driver_.counters().procedure_stall_ns;
  CycleStatus s = CycleStatus::kOk;
  for (int i = 0; i < kLeaveTimeoutPeriods + 20 && s != CycleStatus::kFault; ++i) {
    control.set_alive_ns(mono_ns());
    s = cycle();
  }
  EXPECT_EQ(s, CycleStatus::kFault);
  EXPECT_NE(state_.fault_bits & kDprFaultProcedureTimeout, 0U);
  EXPECT_EQ(driver_.counters().procedure_stall_ns, held);
  slave_.stall = false;
}

// A master that dies mid-control (it stops exchanging: the slave flags torques late and drops
// its DACs) is followed by one that re-attaches: the homing record (homing_record.hpp) matches
// the board, so the successor is homed at once, clears the stale deadline bit, and holds the
// arm where it stands, bumpless, with no homing (the slave homed once, in the first master).
class Dpr7545ReattachTest : public Dpr7545DriverTest {
 protected:
  Dpr7545ReattachTest() : Dpr7545DriverTest(ibm7545(), with_record()) {}
  ~Dpr7545ReattachTest() override {
    std::error_code ec;
    std::filesystem::remove(record_path(), ec);
  }

  static std::string record_path() {
    return (std::filesystem::temp_directory_path() /
            fmt::format("cell-dpr-homing-{}.json", ::getpid()))
        .string();
  }
  static Dpr7545Options with_record() {
    Dpr7545Options o = test_options();
    o.homing_record = record_path();
    return o;
  }

  /// A second master on the same board (the gateway started again).
  std::unique_ptr<Dpr7545Driver> successor() {
    return std::make_unique<Dpr7545Driver>(
        model_, with_record(), kPeriod, [this]() -> Result<std::unique_ptr<d::Transport>> {
          return std::unique_ptr<d::Transport>(std::make_unique<ViewTransport>(memory_->window()));
        });
  }

  /// Runs `driver` for `n` cycles on the period grid, holding `q` (nullopt: the measured
  /// joints, as the servo holds a robot it just took over). Returns the last read's status.
  CycleStatus run(Dpr7545Driver& driver, int n, JointState& state) {
    CycleStatus last = CycleStatus::kOk;
    auto next = Clock::now();
    JointSetpoint hold;
    for (int i = 0; i < n; ++i) {
      std::this_thread::sleep_until(next);
      next += kPeriod;
      const auto now = Clock::now();
      last = driver.read(now, state);
      if (last == CycleStatus::kFault) {
        return last;
      }
      if (hold.q.size() == 0 && state.q.size() == 4) {
        hold.q = state.q;  // taken over where it stands
        hold.qd = JointVector::Zero(4);
      }
      (void)driver.write(now, hold.q.size() == 4 ? hold : setpoint_);
    }
    return last;
  }
};

TEST_F(Dpr7545ReattachTest, ARestartedMasterKeepsTheHomingAndHoldsTheArmWhereItStands) {
  // The index pulses leave the arm away from 0 (so the record is not all zeros); the host
  // holds it there.
  slave_.home_landing = {1200, -800, 1500, 300};
  for (int j = 0; j < 4; ++j) {
    setpoint_.q[j] = slave_.home_landing[static_cast<std::size_t>(j)] / counts(j);
  }
  home_and_engage();
  ASSERT_FALSE(HasFatalFailure());
  ASSERT_THAT(driver_.command(DriverCommand::kGripperClose, {}), IsOk());
  // While the board works the gripper, the record says the close is under way (never "open"
  // nor "closed"): a successor completes it rather than believe a state the latch may have
  // left.
  ASSERT_TRUE(cycle_until([&] { return dpr_.gripper() != 0; }));
  auto during = load_homing_record(record_path());
  ASSERT_THAT(during, IsOk());
  ASSERT_TRUE(during->has_value());
  EXPECT_EQ((*during)->gripper, HomingRecord::Gripper::kClosing);
  ASSERT_TRUE(cycle_until([&] { return state_.gripper == cell_robot_GRIPPER_CLOSED; }));
  ASSERT_TRUE(cycle_until([&] { return slave_.control_entries() >= 2; }));
  for (int i = 0; i < 15; ++i) {  // 0.3 s: the recorder writes every 0.1 s
    (void)cycle();
  }
  auto record = load_homing_record(record_path());
  ASSERT_THAT(record, IsOk());
  ASSERT_TRUE(record->has_value()) << "no homing record written";
  EXPECT_EQ((*record)->gripper, HomingRecord::Gripper::kClosed);
  for (int j = 0; j < 4; ++j) {
    EXPECT_NEAR((*record)->counts[static_cast<std::size_t>(j)], state_.q[j] * counts(j), 2);
  }
  EXPECT_GT(std::abs((*record)->counts[0]), 1000);
  const JointVector at_death = state_.q;
  const int entries = slave_.control_entries();

  // The master dies: no more exchanges. The slave flags torques late and stops control mode.
  std::this_thread::sleep_for(kPeriod * 5);
  EXPECT_NE(dpr_.error() & d::kErrTorquesLate, 0) << "the slave did not notice the dead master";

  auto next = successor();
  ASSERT_THAT(next->on_configure(), IsOk());
  ASSERT_THAT(next->on_activate(), IsOk());
  JointState state;
  EXPECT_NE(run(*next, 1, state), CycleStatus::kFault);
  EXPECT_TRUE(state.homed) << "the successor did not keep the homing";
  EXPECT_EQ(state.gripper, cell_robot_GRIPPER_CLOSED);
  EXPECT_EQ(dpr_.error(), 0) << "the stale 0x1000 was not cleared";
  EXPECT_EQ(run(*next, 60, state), CycleStatus::kOk);
  EXPECT_GT(slave_.control_entries(), entries) << "control mode did not start again";
  for (int j = 0; j < 4; ++j) {
    EXPECT_LT(std::abs(state.q[j] - at_death[j]) * counts(j), 30) << "joint " << j;
  }
  next->on_deactivate();
}

// A predecessor that died with a gripper close under way: its successor completes the close
// (the latch is then known) before anything else.
TEST_F(Dpr7545ReattachTest, AGripperProcedureUnderWayIsCompletedByTheSuccessor) {
  activate();
  for (int i = 0; i < 3; ++i) {
    (void)cycle();
  }
  driver_.on_deactivate();
  HomingRecord record;
  record.counts = {0, 0, 0, 0};  // the fake board reads 0 everywhere: the arm at home
  record.gripper = HomingRecord::Gripper::kClosing;
  ASSERT_THAT(save_homing_record(record_path(), record), IsOk());
  auto next = successor();
  ASSERT_THAT(next->on_configure(), IsOk());
  ASSERT_THAT(next->on_activate(), IsOk());
  JointState state;
  (void)run(*next, 1, state);  // completed before the first cycle: never a busy robot
  EXPECT_TRUE(state.homed);
  EXPECT_FALSE(state.busy);
  EXPECT_EQ(state.gripper, cell_robot_GRIPPER_CLOSED);
  EXPECT_TRUE(slave_.gripper_closed());
  EXPECT_EQ(slave_.gripper_actions(), 1);
  next->on_deactivate();
}

TEST_F(Dpr7545ReattachTest, ARecordThatDoesNotMatchTheBoardIsRemovedAndTheRobotMustBeHomed) {
  activate();
  for (int i = 0; i < 3; ++i) {
    (void)cycle();
  }
  driver_.on_deactivate();
  HomingRecord stale;
  stale.counts = {50'000, 20'000, 30'000, 1'000};  // the counters read near 0: far from it
  ASSERT_THAT(save_homing_record(record_path(), stale), IsOk());
  auto next = successor();
  ASSERT_THAT(next->on_configure(), IsOk());
  ASSERT_THAT(next->on_activate(), IsOk());
  JointState state;
  (void)run(*next, 10, state);
  EXPECT_FALSE(state.homed);
  EXPECT_FALSE(std::filesystem::exists(record_path()));
  EXPECT_EQ(slave_.control_entries(), 0);
  next->on_deactivate();
}

TEST(Dpr7545Config, ParserChecksKeysWithLocations) {
  const auto load = [](const std::string& driver) {
    return load_config(*config::load_string(
        "robot_config: x.yaml\ndriver: {kind: dpr7545" + driver + "}\n", "gw.yaml"));
  };
  EXPECT_THAT(load(", transport: shm, shm_name: /cell-x, kp: [60, 60, 55, 60]"), IsOk());
  EXPECT_THAT(load(", transport: serial"),
              IsErrWith(Errc::kConfig, "key 'driver.transport': must be shm or physical"));
  EXPECT_THAT(load(", kp: [60, 60]"), IsErrWith(Errc::kConfig, "expected a list of 4 values"));
  EXPECT_THAT(load(", shm_name: nope"), IsErrWith(Errc::kConfig, "must start with '/'"));
  EXPECT_THAT(load(", handshake_timeout_us: 5000"),
              IsErrWith(Errc::kConfig, "never waits past its period"));
  EXPECT_THAT(load(", kv: [0.1, -1, 0.1, 0.1]"), IsErrWith(Errc::kConfig, "gains of joint J2"));
  EXPECT_THAT(load(", gain: 3"), IsErrWith(Errc::kConfig, "unknown key 'driver.gain'"));
}

TEST(Dpr7545Config, FactoryChecksTheRobotAndTheCycle) {
  auto config = load_config(*config::load_string(
      "robot_config: x.yaml\ndriver: {kind: dpr7545, shm_name: /cell-dpr7545-missing-test, "
      "activate_timeout_s: 0.2}\n",
      "gw.yaml"));
  ASSERT_THAT(config, IsOk());
  const auto model = ibm7545();
  auto wrong_cycle = config->make_driver(DriverSetup{model, std::chrono::milliseconds(2)});
  EXPECT_THAT(wrong_cycle, IsErrWith(Errc::kConfig, "does not match the gateway's cycle"));
  auto excalibur =
      kinematics::load_robot(cell::testing::source_dir() + "/config/robots/excalibur.yaml");
  ASSERT_THAT(excalibur, IsOk());
  EXPECT_THAT(config->make_driver(DriverSetup{*excalibur, std::chrono::milliseconds(1)}),
              IsErrWith(Errc::kConfig, "drives 4 joints"));
  auto driver = config->make_driver(DriverSetup{model, std::chrono::milliseconds(1)});
  ASSERT_THAT(driver, IsOk());
  // No simulator: configure waits activate_timeout_s for the segment, then says what is missing.
  EXPECT_THAT((*driver)->on_configure(),
              IsErrWith(Errc::kNotReady, "'/cell-dpr7545-missing-test' does not exist"));
}

TEST(Dpr7545Config, PhysicalTransportFailsClearlyWithoutTheDevice) {
  auto config = load_config(*config::load_string(
      "robot_config: x.yaml\ndriver: {kind: dpr7545, transport: physical, "
      "physical_device: /nonexistent/mem, physical_base_address: 0xC8000}\n",
      "gw.yaml"));
  ASSERT_THAT(config, IsOk());
  const auto model = ibm7545();
  auto driver = config->make_driver(DriverSetup{model, std::chrono::milliseconds(1)});
  ASSERT_THAT(driver, IsOk());
  EXPECT_THAT((*driver)->on_configure(), IsErrWith(Errc::kIo, "cannot open /nonexistent/mem"));
}

}  // namespace
}  // namespace cell::gateway
