// The slave program against a fake master in this process (a heap DPR window): the handshake
// of digest 000 §2.3, its checks and error bits (§9.2 cases 4-6), homing in the thesis's order,
// the gripper and the lighting latch (case 5), and the fault mailbox.
#include "slave.hpp"

#include <chrono>
#include <thread>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "cell/common/realtime.hpp"
#include "cell/dpr7545/transport.hpp"
#include "cell/testing/env.hpp"

namespace cell::sim7545 {
namespace {

using namespace std::chrono_literals;
using cell::testing::eventually;
namespace d = dpr7545;

// A long sample period (20 ms) keeps the fake master, an ordinary thread, far from the slave's
// deadlines on a loaded machine; the deadline tests then wait on purpose. The 1 ms loop runs
// in tests/gateway_7545 and bench/servo.
constexpr std::uint16_t kPeriodUs = 20000;

/// The SCHED_FIFO priority of the slave thread (config/sim-7545.yaml's realtime_priority) and
/// of the test thread, which plays the master (the gateway's servo thread, also 50), where
/// permitted. A master at normal priority against a slave that is never descheduled misses
/// its deadline on a loaded host (0x1000), as it would against the board.
constexpr int kSlavePriority = 50;

class SlaveTest : public ::testing::Test {
 protected:
  explicit SlaveTest(SlaveOptions options = fast_options())
      : master_fifo_(kSlavePriority),
        transport_(d::make_heap_transport()),
        dpr_(transport_->window()) {
    slave_ = std::make_unique<Slave>(transport_->window(), options);
    // The slave program at SCHED_FIFO 50 where permitted (root), as cell-sim-7545 runs it
    // (config/sim-7545.yaml): it stands for a board that is never descheduled. Under normal
    // scheduling a loaded host stalled it mid-homing while Z moved under a held torque, and Z
    // coasted 384 counts past its index into the overrun (0x20).
    thread_ = std::thread([this] {
      (void)set_thread_fifo(kSlavePriority);
      slave_->run(stop_);
    });
    dpr_.set_sample_period_us(kPeriodUs);
    // Wait until the program passed main_loop (which clears command and gripper) and runs its
    // idle loop, whose get_robot_state writes timing_A = 0xF: a command written before that
    // would be cleared, as on the real board.
    EXPECT_TRUE(eventually([&] { return dpr_.timing_a() == d::kTimingAAll; }, 2s));
  }
  ~SlaveTest() override {
    stop_ = true;
    thread_.join();
  }

  static SlaveOptions fast_options() {
    SlaveOptions o;
    o.delay_s = 0.05;
    o.idle_poll_s = 100e-6;
    return o;
  }

  /// Polls every 20 us (a master must react within the sample period) until `done` or 2 s.
  /// It sleeps between polls: at SCHED_FIFO a pure spin would keep its core from every other
  /// real-time thread of equal priority (another test's slave, under ctest -j).
  template <typename Fn>
  static bool spin_until(Fn&& done) {
    const auto deadline = std::chrono::steady_clock::now() + 2s;
    while (!done()) {
      if (std::chrono::steady_clock::now() > deadline) {
        return false;
      }
      std::this_thread::sleep_for(20us);
    }
    return true;
  }

  /// Enters control mode as the driver does (marker in timing_B, then command = control).
  void enter_control() {
    dpr_.set_timing_b(d::kTimingBEngageMarker);
    dpr_.set_command(d::kCommandControl);
    ASSERT_TRUE(spin_until([&] { return dpr_.timing_b() == 0; }));
  }

  /// One master period: wait for the slave, read positions, write `torque` to every joint,
  /// hand over, end the period. Returns false when the slave flagged an error instead.
  bool serve(std::uint16_t torque = d::kTorqueZero, bool clear_timing_a = true) {
    if (!spin_until([&] { return (dpr_.timing_a() & d::kTimingAStart) != 0 || dpr_.error(); }) ||
        !spin_until(
            [&] { return (dpr_.timing_a() & d::kTimingAPositions) != 0 || dpr_.error(); }) ||
        dpr_.error() != 0) {
      return false;
    }
    positions_.push_back(dpr_.position(0));
    boards_.push_back(control_.board_time_ns());
    samples_.push_back(control_.sample_time_ns());
    for (int j = 0; j < d::kJoints; ++j) {
      dpr_.set_torque(j, torque);
    }
    dpr_.set_timing_b(d::kTimingBTorquesReady);
    if (!spin_until([&] { return dpr_.timing_b() == 0 || dpr_.error() != 0; })) {
      return false;
    }
    if (clear_timing_a) {
      dpr_.set_timing_a(0);
    }
    return dpr_.error() == 0;
  }

  ScopedThreadFifo master_fifo_;  // first: the master runs at SCHED_FIFO from the start
  std::unique_ptr<d::Transport> transport_;
  d::Dpr dpr_;
  std::atomic<bool> stop_{false};
  std::unique_ptr<Slave> slave_;
  std::thread thread_;
  std::vector<std::int32_t> positions_;  ///< J1's encoder at each period served
  d::SimControl control_{transport_->window()};
  std::vector<std::int64_t> boards_;   ///< the board's clock at each period served [ns]
  std::vector<std::int64_t> samples_;  ///< the host's instant of each period's sample [ns]
};

TEST_F(SlaveTest, HandshakeRunsPeriodAfterPeriodWithoutErrors) {
  enter_control();
  for (int k = 0; k < 20; ++k) {
    ASSERT_TRUE(serve()) << "period " << k << " error 0x" << std::hex << dpr_.error();
  }
  EXPECT_EQ(dpr_.error(), 0);
  EXPECT_EQ(dpr_.timing_a(), 0);  // we ended the last period
  ASSERT_TRUE(eventually([&] { return slave_->take_snapshot().periods >= 20U; }, 1s));
  EXPECT_EQ(slave_->take_snapshot().mode, SlaveMode::kControl);
  // The master ends control mode by clearing command: no error.
  dpr_.set_command(0);
  ASSERT_TRUE(eventually([&] { return slave_->take_snapshot().mode == SlaveMode::kIdle; }, 2s));
  EXPECT_EQ(dpr_.error(), 0);
}

// Digest 000 §9.2 case 6: no torques before the sample deadline -> 0x1000.
TEST_F(SlaveTest, TorquesLateSetErrorAndEndControlMode) {
  enter_control();
  ASSERT_TRUE(eventually([&] { return dpr_.error() != 0; }, 2s));
  EXPECT_EQ(dpr_.error(), d::kErrTorquesLate);
  // Back in main_loop: command cleared, DACs zero, and it will not take commands meanwhile.
  ASSERT_TRUE(eventually([&] { return dpr_.command() == 0; }, 1s));
  dpr_.set_command(d::kCommandFindHome);
  std::this_thread::sleep_for(50ms);
  EXPECT_EQ(slave_->take_snapshot().mode, SlaveMode::kIdle);
  EXPECT_EQ(slave_->take_snapshot().dac[0], d::kTorqueZero);
  EXPECT_EQ(slave_->take_snapshot().deadline_errors, 1U);
}

// Digest 000 §9.2 case 6: master never clears timing_A -> 0x2000.
TEST_F(SlaveTest, MasterThatNeverEndsItsLoopSetsLoopLate) {
  enter_control();
  EXPECT_TRUE(serve(d::kTorqueZero, /*clear_timing_a=*/false));
  ASSERT_TRUE(eventually([&] { return dpr_.error() != 0; }, 2s));
  EXPECT_EQ(dpr_.error(), d::kErrLoopLate);
}

// Digest 000 §9.2 case 6: torque 0x1000 or a negative torque -> 0x100 (J1); never clamped.
TEST_F(SlaveTest, OutOfRangeTorqueIsRejectedNotClamped) {
  enter_control();
  ASSERT_TRUE(serve());
  ASSERT_TRUE(spin_until([&] { return (dpr_.timing_a() & d::kTimingAPositions) != 0; }));
  dpr_.set_torque(0, 0x1000);
  dpr_.set_torque(1, d::kTorqueZero);
  dpr_.set_torque(2, d::torque_word(-5.0));
  dpr_.set_torque(3, d::kTorqueZero);
  dpr_.set_timing_b(d::kTimingBTorquesReady);
  ASSERT_TRUE(eventually([&] { return dpr_.error() != 0; }, 2s));
  EXPECT_EQ(dpr_.error(), d::kErrTorqueJ1 | d::kErrTorqueZ);
  EXPECT_EQ(dpr_.timing_b(), d::kTimingBTorquesReady);  // never accepted
  EXPECT_EQ(slave_->take_snapshot().dac[0], d::kTorqueZero);
}

// Digest 000 §9.2 case 4 through the slave: an overrun trips the low byte, which the idle loop
// rewrites on every pass, so it clears only when the joint is back.
TEST_F(SlaveTest, OverrunSetsTheJointsBitUntilTheJointIsBack) {
  d::SimControl control(transport_->window());
  const auto seq = control.post(d::SimFault::kOverrun, 0, -1);  // J1 one count below MIN
  ASSERT_TRUE(eventually([&] { return control.result(seq).has_value(); }, 2s));
  ASSERT_TRUE(eventually([&] { return dpr_.error() == d::kErrJ1NegativeOverrun; }, 2s));
  EXPECT_EQ(dpr_.position_consistent(0), -4362);
  dpr_.set_error(0);  // the master clears it: the next pass sets it again
  ASSERT_TRUE(eventually([&] { return dpr_.error() == d::kErrJ1NegativeOverrun; }, 2s));
  const auto clear = control.post(d::SimFault::kClear, 0, 0);
  ASSERT_TRUE(eventually([&] { return control.result(clear).has_value(); }, 2s));
  ASSERT_TRUE(eventually([&] { return dpr_.error() == 0; }, 2s));
}

TEST_F(SlaveTest, InjectedDeadlineMissSetsTorquesLate) {
  d::SimControl control(transport_->window());
  // Refused while idle: there is no deadline to miss.
  auto seq = control.post(d::SimFault::kDeadlineMiss, 0, 0);
  ASSERT_TRUE(eventually([&] { return control.result(seq).has_value(); }, 2s));
  EXPECT_EQ(*control.result(seq), 3U);
  enter_control();
  ASSERT_TRUE(serve());
  seq = control.post(d::SimFault::kDeadlineMiss, 0, 0);
  bool ok = true;
  for (int k = 0; k < 200 && ok; ++k) {
    ok = serve();
  }
  EXPECT_FALSE(ok);
  EXPECT_EQ(*control.result(seq), 0U);
  EXPECT_EQ(dpr_.error(), d::kErrTorquesLate);
}

/// The slave with SimConfig::deadline_slack_us = 10 periods (200 ms).
class SlackSlaveTest : public SlaveTest {
 protected:
  SlackSlaveTest() : SlaveTest(slack_options()) {}
  static SlaveOptions slack_options() {
    SlaveOptions o = fast_options();
    o.deadline_slack_s = 0.200;
    return o;
  }
};

// A master 5 periods late (a stalled host) is served when the slack covers it; one that never
// answers still gets 0x1000, at period + slack after the period started, not before. (The
// slave sees the lateness only if it looks at the period's deadline before the master answers:
// with 1.5 periods of lateness, a loaded host that woke the slave 10 ms late hid it.)
TEST_F(SlackSlaveTest, AMasterLateWithinTheSlackIsServedAndOneThatNeverAnswersIsNot) {
  enter_control();
  ASSERT_TRUE(serve());
  ASSERT_TRUE(spin_until([&] { return (dpr_.timing_a() & d::kTimingAStart) != 0; }));
  std::this_thread::sleep_for(100ms);  // 5 periods: the board of Appendix C flags 0x1000
  ASSERT_TRUE(serve()) << "error 0x" << std::hex << dpr_.error();
  ASSERT_TRUE(serve()) << "error 0x" << std::hex << dpr_.error();
  EXPECT_EQ(dpr_.error(), 0);
  EXPECT_EQ(slave_->take_snapshot().deadline_errors, 0U);
  EXPECT_GE(slave_->take_snapshot().late_served, 1U);  // counted: the board would have faulted
  // Now the master stops answering. The next period starts within one period of t0 and its
  // deadline is a period plus the slack after that start: >= 220 ms from t0 (the board: <= 40).
  const auto t0 = std::chrono::steady_clock::now();
  ASSERT_TRUE(eventually([&] { return dpr_.error() != 0; }, 2s));
  const auto waited = std::chrono::steady_clock::now() - t0;
  EXPECT_EQ(dpr_.error(), d::kErrTorquesLate);
  EXPECT_GE(waited, 215ms);
}

// This process stalled (descheduled) after announcing a period and before its positions, for
// longer than the period and the slack: the master could not answer meanwhile, so the stall is
// the slave's own and moves the deadline; the master answering as soon as it sees the
// positions is served. (A soak's job paused on 0x1000 while the gateway woke on time.)
TEST_F(SlackSlaveTest, AStallOfThisProcessBeforeItsPositionsIsNotChargedToTheMaster) {
  enter_control();
  ASSERT_TRUE(serve());
  const std::uint64_t stalls = slave_->take_snapshot().stalls_absorbed;
  slave_->stall_next_period(300'000'000);  // > period (20 ms) + slack (200 ms)
  ASSERT_TRUE(serve()) << "error 0x" << std::hex << dpr_.error();
  ASSERT_TRUE(serve()) << "error 0x" << std::hex << dpr_.error();
  EXPECT_EQ(dpr_.error(), 0);
  const SlaveSnapshot s = slave_->take_snapshot();
  EXPECT_EQ(s.deadline_errors, 0U);
  EXPECT_GT(s.stalls_absorbed, stalls);
}

// The board's clock, on which the arm moves, advances exactly one period per period, also
// through a master 5 periods late that the slack covers: the arm moves as under an on-time
// master (J1's encoder, period by period, is a JointModel's advanced one period at a time under
// the same torque), and the time the board did not see is reported, not lost.
TEST_F(SlackSlaveTest, TheArmMovesOnePeriodPerPeriodThroughALateMaster) {
  enter_control();
  const auto torque = static_cast<std::uint16_t>(d::kTorqueZero + 200);
  for (int k = 0; k < 8; ++k) {
    if (k == 4) {
      ASSERT_TRUE(spin_until([&] { return (dpr_.timing_a() & d::kTimingAStart) != 0; }));
      std::this_thread::sleep_for(100ms);
    }
    ASSERT_TRUE(serve(torque)) << "period " << k << " error 0x" << std::hex << dpr_.error();
  }
  ASSERT_EQ(boards_.size(), 8U);
  for (std::size_t k = 1; k < boards_.size(); ++k) {
    EXPECT_EQ(boards_[k] - boards_[k - 1], std::int64_t{kPeriodUs} * 1000) << "period " << k;
  }
  EXPECT_GE(samples_[5] - samples_[4], 100'000'000) << "the host's clock saw the late master";
  JointModel model(SimConfig::default_plants()[0], 0.0, d::kThesisOverrunLimits[0].min_counts,
                   d::kThesisOverrunLimits[0].max_counts);
  const double dt = static_cast<double>(std::int64_t{kPeriodUs} * 1000) * 1e-9;
  for (std::size_t k = 0; k < positions_.size(); ++k) {
    EXPECT_NEAR(positions_[k], d::sign_extend_24(model.counter_24()), 1) << "period " << k;
    model.advance(torque, dt);  // the torque written in period k, held for one period
  }
  EXPECT_GT(positions_.back(), 100) << "the torque moved J1";
  EXPECT_EQ(control_.grace_us(), 200000U) << "the grace, published for the master";
  const SlaveSnapshot s = slave_->take_snapshot();
  EXPECT_GE(s.late_served, 1U);
  // 100 ms late: the next period started 4 or 5 periods of 20 ms off the grid, which the
  // board's clock never saw (less the few hundred nanoseconds between the two clocks' reads
  // at entry).
  EXPECT_GE(s.absorbed_s, 0.0799);
  EXPECT_LT(s.absorbed_s, 0.5);
}

TEST_F(SlaveTest, GripperClosesThenOpensAndTheRegisterReadsZeroWhenDone) {
  // Digest 000 §9.2 case 5: 0x0080 -> closed (latch 1); 0x0001 -> open (latch 0).
  EXPECT_FALSE(slave_->take_snapshot().gripper_closed);
  dpr_.set_gripper(d::kGripperClose);
  ASSERT_TRUE(eventually([&] { return slave_->take_snapshot().gripper_closed; }, 2s));
  EXPECT_NE(dpr_.gripper(), 0);  // the second delay is still running
  ASSERT_TRUE(eventually([&] { return dpr_.gripper() == 0; }, 2s));
  dpr_.set_gripper(d::kGripperOpen);
  ASSERT_TRUE(eventually([&] { return dpr_.gripper() == 0; }, 2s));
  EXPECT_FALSE(slave_->take_snapshot().gripper_closed);
}

TEST_F(SlaveTest, LightingLatchIsReadBackFromItsOwnAddress) {
  dpr_.write_lighting(d::lighting_latch(false, true));
  ASSERT_TRUE(eventually([&] { return slave_->take_snapshot().lights == 0b10; }, 2s));
  dpr_.write_lighting(d::lighting_latch(true, true));
  ASSERT_TRUE(eventually([&] { return slave_->take_snapshot().lights == 0b11; }, 2s));
}

class HomingTest : public SlaveTest {
 protected:
  HomingTest() : SlaveTest(options()) {}
  static SlaveOptions options() {
    SlaveOptions o = fast_options();
    // Physical pose at power-up: a little away from home on every joint (Z at the top, on its
    // home sensor, as the arm normally rests).
    o.initial_counts = {3000.0, 2500.0, 0.0, -1500.0};
    return o;
  }
};

TEST_F(HomingTest, HomesZThenJ1ThenJ2ThenRAndClearsTheCommand) {
  EXPECT_EQ(dpr_.position_consistent(0), 0);  // counters read 0 where the arm powered up
  std::vector<int> order;
  dpr_.set_command(d::kCommandFindHome);
  const auto deadline = std::chrono::steady_clock::now() + 20s;
  while (dpr_.command() != 0 && std::chrono::steady_clock::now() < deadline) {
    const SlaveSnapshot s = slave_->take_snapshot();
    for (int j = 0; j < d::kJoints; ++j) {
      if (s.dac[static_cast<std::size_t>(j)] != d::kTorqueZero &&
          (order.empty() || order.back() != j)) {
        order.push_back(j);
      }
    }
    std::this_thread::sleep_for(200us);
  }
  ASSERT_EQ(dpr_.command(), 0) << "homing did not finish";
  EXPECT_THAT(order, ::testing::ElementsAre(2, 0, 1, 3));  // Z, 1, 2, R
  ASSERT_TRUE(eventually([&] { return slave_->take_snapshot().homed; }, 1s));
  const SlaveSnapshot s = slave_->take_snapshot();
  for (int j = 0; j < d::kJoints; ++j) {
    const auto i = static_cast<std::size_t>(j);
    // Home is the index pulse; the joint coasts a little past it once the torque goes, and
    // the counter now reads the physical position.
    EXPECT_NEAR(s.position_counts[i], 0.0, 250.0) << "joint " << j;
    EXPECT_NEAR(static_cast<double>(s.encoder[i]), s.position_counts[i], 1.0) << "joint " << j;
  }
  EXPECT_EQ(dpr_.error(), 0);
}

TEST_F(HomingTest, SensorPortIsActiveLowForHomeAndLatchesIndexPulses) {
  stop_ = true;  // stop the program: read the port from this thread alone
  thread_.join();
  thread_ = std::thread([] {});
  const std::uint8_t port = slave_->read_sensor_port();
  // Z (bit 4) rests on its sensor: bit clear. J1 (7), J2 (6) beyond their edges: set.
  // R (5) at -1500 counts: below its edge, sensor active: clear.
  EXPECT_EQ(port & 0xF0, (1 << 7) | (1 << 6));
  EXPECT_EQ(port & 0x0F, 0);  // no index pulse yet
}

}  // namespace
}  // namespace cell::sim7545
