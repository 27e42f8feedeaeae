// The IBM 7545 end to end, as real processes on a private bus: cell-sim-7545 (the 80C196
// slave over a shared-memory DPR with a unique name per test), cell-gateway with the dpr7545
// driver (the master: 1 kHz PD loop and handshake) and cell-motion (the thesis's via-point
// paths). The test is a bus client: it homes, moves, injects faults through the simulator's
// mailbox (`cell-sim-7545 inject`), and compares the gateway's view with the simulator's truth
// (RobotState "ibm7545.sim"). Every wait is a condition with a deadline.
#include <sys/mman.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include <fmt/format.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "cell/bus/participant.hpp"
#include "cell/bus/reader.hpp"
#include "cell/bus/request_reply.hpp"
#include "cell/bus/topic.hpp"
#include "cell/bus/view.hpp"
#include "cell/kinematics/robot_config.hpp"
#include "cell/motion/planner.hpp"
#include "cell/motion/wire.hpp"
#include "cell/process/child.hpp"
#include "cell/testing/env.hpp"
#include "cell/testing/matchers.hpp"

namespace cell {
namespace {

using namespace std::chrono_literals;
using ::cell::testing::eventually;
using ::cell::testing::IsOk;
using ::testing::HasSubstr;

constexpr double kPi = 3.14159265358979323846;
constexpr double deg(double d) { return d * kPi / 180.0; }

// Maximum following error, per joint, in encoder counts: 2047 / kp (34 counts for J1, J2 and
// R with kp = 60, 37 for Z with kp = 55). Beyond it the thesis's PD word 0x800 + kp e + ...
// leaves the 12-bit DAC range and the slave aborts the move (0x100 << joint), so a loop that
// tracks the thesis's paths with the thesis's gains must stay inside it. It is 0.039 deg on
// J1, 0.077 deg on J2, 0.097 mm on Z and 0.15 deg on R: far below the thesis's accuracy
// figures (0.5 mm centre error, 1.5 deg orientation, digest 000 §7), so tracking is never
// what limits the cell's accuracy. (The simulated arm lags about 17 counts at top speed.)
constexpr std::array<double, 4> kMaxFollowingCounts = {34.0, 34.0, 37.0, 34.0};
// At rest the PD loop settles within one count of its setpoint: with Coulomb friction, the
// torque of a one-count error (kp = 55-60 DAC steps) may not break the joint free.
constexpr double kRestCounts = 1.0;
// The gateway's encoder counts against the simulator's continuous truth: one count of
// quantisation plus one for the instants at which the two processes sampled their states.
constexpr double kTruthCounts = 2.0;
constexpr std::uint32_t kDeadlineBits = 0x3000;  // torques late, loop late
constexpr std::uint32_t kTorqueBits = 0x0F00;    // a joint's torque word out of range

bool terminal(const cell_motion_MotionStatus& s) {
  return s.state == cell_motion_MOTION_REFUSED || s.state == cell_motion_MOTION_DONE ||
         s.state == cell_motion_MOTION_FAILED || s.state == cell_motion_MOTION_PREVIEW;
}

struct StateCopy {
  std::vector<double> q;
  std::vector<double> setpoint;
  std::vector<double> qd;
  std::vector<double> effort;
  cell_robot_RobotMode mode = cell_robot_MODE_UNCONFIGURED;
  cell_robot_GripperState gripper = cell_robot_GRIPPER_UNKNOWN;
  bool homed = false;
  bool moving = false;
  bool halogen = false;
  bool fluorescent = false;
  std::uint32_t fault_bits = 0;
  std::string fault_text;
  std::uint64_t overruns = 0;
  std::int64_t stamp_ns = 0;  ///< when the joints were read (wall clock, every process)
};

StateCopy copy(const cell_robot_RobotState& s) {
  StateCopy c;
  c.q = bus::to_vector(s.position_rad_or_mm);
  c.setpoint = bus::to_vector(s.setpoint_rad_or_mm);
  c.qd = bus::to_vector(s.velocity_rad_or_mm_per_s);
  c.effort = bus::to_vector(s.effort_raw);
  c.mode = s.mode;
  c.gripper = s.gripper;
  c.homed = s.homed;
  c.moving = s.moving;
  c.halogen = s.halogen_on;
  c.fluorescent = s.fluorescent_on;
  c.fault_bits = s.fault_bits;
  c.fault_text = bus::str(s.fault_text);
  c.overruns = s.cycle_overruns;
  c.stamp_ns = s.header.stamp_ns;
  return c;
}

class Gateway7545Test : public ::testing::Test {
 protected:
  Gateway7545Test()
      : domain_(cell::testing::test_domain_id()),
        partition_(cell::testing::unique_partition()),
        shm_name_(fmt::format("/cell-dpr7545-test-{}-{}", ::getpid(), ++instance_)),
        model_(*kinematics::load_robot(cell::testing::source_dir() +
                                       "/config/robots/ibm7545.yaml")),
        client_(domain_, partition_),
        state_topic_(client_, bus::topics::kRobotState),
        states_(client_, state_topic_, bus::topics::kRobotState),
        event_topic_(client_, bus::topics::kCellEvent),
        events_(client_, event_topic_, bus::topics::kCellEvent),
        motions_(client_, bus::topics::kMotionRequest, bus::topics::kMotionStatus, "t7545-m"),
        commands_(client_, bus::topics::kRobotCommand, bus::topics::kRobotCommandReply,
                  "t7545-c"),
        trajectories_(client_, bus::topics::kTrajectory, bus::topics::kRobotCommandReply,
                      "t7545-t") {
    std::string pattern = "/tmp/cell-gateway7545-XXXXXX";
    dir_ = mkdtemp(pattern.data()) != nullptr ? pattern : "/tmp/cell-gateway7545-fallback";
    env_ = cell::testing::bus_env(domain_, partition_);
    env_.push_back("CELL_HOME=" + cell::testing::source_dir());
    // SCHED_FIFO for the two real-time threads when we may (root): the slave flags 0x1000 when
    // a cycle is about a period late, which a loaded 2-core machine otherwise causes now and
    // then. Both threads sleep between their polls, so they cannot starve the machine.
    // CELL_TEST_RT_PRIORITY overrides (0: normal scheduling, to see the machine's own jitter).
    const char* rt_env = std::getenv("CELL_TEST_RT_PRIORITY");
    const int rt = rt_env != nullptr ? std::atoi(rt_env) : (::geteuid() == 0 ? 30 : 0);
    const std::string robot = cell::testing::source_dir() + "/config/robots/ibm7545.yaml";
    // The sample period: 2 ms by default, not the thesis's 1 ms. This VM's bare
    // clock_nanosleep loop wakes more than 1 ms late a few times a second at times
    // (bench/servo measures it beside the 1 kHz loop); at 1 ms those stalls are deadline
    // misses that a multi-second move rarely survives, which says nothing about the driver.
    // The protocol, the handshake and the PD law are the same at either period.
    // CELL_TEST_SAMPLE_PERIOD_US=1000 runs the thesis's period.
    const char* period_env = std::getenv("CELL_TEST_SAMPLE_PERIOD_US");
    const int period_us = period_env != nullptr ? std::atoi(period_env) : 2000;
    // The simulated board's grace past its deadlines (SimConfig::deadline_slack_us): this VM's
    // host stalls a SCHED_FIFO thread for 2-11 ms a few times a second at times (measured:
    // 45 wakes of 20,000 more than 2 ms late, the worst 11 ms), each a fault at the board's
    // strict deadlines, which left these tests nothing but resets. 20 ms covers them; the
    // deadline test injects its miss past the slack. CELL_TEST_DEADLINE_SLACK_US=0: the board.
    const char* slack_env = std::getenv("CELL_TEST_DEADLINE_SLACK_US");
    const int slack_us = slack_env != nullptr ? std::atoi(slack_env) : 20000;
    write(dir_ + "/sim.yaml",
          fmt::format("service: {{id: sim.ibm7545, heartbeat_period_s: 0.2}}\n"
                      "robot_config: {}\nshm_name: {}\nrealtime_priority: {}\n"
                      "initial_joints: [2, 3, 1, 2]\ndelay_s: 0.1\ndeadline_slack_us: {}\n",
                      robot, shm_name_, rt, slack_us));
    write(dir_ + "/gateway.yaml",
          fmt::format("service: {{id: gateway.ibm7545, heartbeat_period_s: 0.2}}\n"
                      "robot_config: {}\ncycle_hz: {}\nstate_rate_hz: 100\n"
                      "realtime_priority: {}\n"
                      "driver: {{kind: dpr7545, shm_name: {}, activate_timeout_s: 20, "
                      "lock_memory: true, sample_period_us: {}, handshake_timeout_us: {}}}\n",
                      robot, 1'000'000 / period_us, rt, shm_name_, period_us,
                      0.9 * period_us));
    write(dir_ + "/motion.yaml",
          fmt::format("service: {{id: motion, heartbeat_period_s: 0.2}}\n"
                      "robots:\n  - {{id: ibm7545, config: {}}}\n"
                      "planner: {{linear_speed_mm_s: 250, linear_accel_mm_s2: 1000, "
                      "angular_speed_deg_s: 90, angular_accel_deg_s2: 360, "
                      "knot_period_s: 0.008, gripper_dwell_s: 0.5, approach_mm: 30, "
                      "via_settle_s: 0.2}}\n"
                      "gateway_timeout_s: 2.0\nstate_timeout_s: 1.0\nstatus_rate_hz: 10\n",
                      robot));
    sim_ = spawn("cell-sim-7545", dir_ + "/sim.yaml");
    EXPECT_TRUE(eventually([&] { return pump(), sim_state_.has_value(); }, 20s))
        << "no state from cell-sim-7545:\n" << output(sim_);
    gateway_ = spawn("cell-gateway", dir_ + "/gateway.yaml");
    motion_ = spawn("cell-motion", dir_ + "/motion.yaml");
    EXPECT_TRUE(eventually([&] { return pump(), gateway_state_.has_value(); }, 20s))
        << "no state from cell-gateway:\n" << output(gateway_);
  }

  ~Gateway7545Test() override {
    for (process::Child* c : {&motion_, &gateway_, &sim_}) {
      if (c->running()) {
        const process::ExitInfo e = c->stop(10s);
        EXPECT_TRUE(e.exited && e.code == 0) << e.describe() << "\n" << c->output();
      }
    }
    if (spontaneous_misses_ > 0) {
      std::printf("%d spontaneous deadline miss(es) during this test (machine stalls)\n",
                  spontaneous_misses_);
    }
    if (HasFailure()) {  // the processes' logs help more than anything else here
      std::printf("---- cell-sim-7545\n%s---- cell-gateway\n%s---- cell-motion\n%s",
                  (logs_[0] + sim_.output()).c_str(), (logs_[1] + gateway_.output()).c_str(),
                  (logs_[2] + motion_.output()).c_str());
    }
    ::shm_unlink(shm_name_.c_str());  // in case the simulator could not remove it
    std::error_code ec;
    std::filesystem::remove_all(dir_, ec);
  }

  static void write(const std::string& path, const std::string& text) {
    std::ofstream(path) << text;
  }

  process::Child spawn(const std::string& name, const std::string& config) {
    process::SpawnOptions o;
    o.executable = cell::testing::bin_path(name);
    o.args = {"--config", config};
    o.env = env_;
    auto child = process::Child::spawn(o);
    EXPECT_THAT(child, IsOk());
    return child ? std::move(*child) : process::Child();
  }

  /// Everything `c` printed so far.
  std::string output(process::Child& c) {
    const std::size_t i = &c == &sim_ ? 0 : &c == &gateway_ ? 1 : 2;
    if (c.output_fd() >= 0) {
      (void)c.read_available(logs_[i]);
    }
    return logs_[i] + c.output();
  }

  /// Takes every state available: the latest of the gateway and of the simulator; while
  /// `tracking_`, the worst |position - setpoint| per joint in counts and whether a fault came.
  void pump() {
    for (std::size_t i = 0; i < 3; ++i) {  // keep the pipes drained, the logs kept
      process::Child* c = std::array<process::Child*, 3>{&sim_, &gateway_, &motion_}[i];
      if (c->output_fd() >= 0) {
        (void)c->read_available(logs_[i]);
      }
    }
    auto batch = states_.take_copies(256);
    if (!batch) {
      return;
    }
    for (auto& s : *batch) {
      const std::string_view id = bus::str(s->robot_id);
      if (id == "ibm7545.sim") {
        sim_state_ = copy(s.get());
      } else if (id == "ibm7545") {
        gateway_state_ = copy(s.get());
        const StateCopy& g = *gateway_state_;
        // Every state while moving counts: the simulated board's clock stands still while it
        // waits for a late master or for its own process (the arm moves one period per
        // exchange, whatever the host does), so no stall excuses a larger error.
        if (tracking_ && g.moving && g.q.size() == 4 && g.setpoint.size() == 4) {
          TrackedState t{};
          for (std::size_t j = 0; j < 4; ++j) {
            t.error_counts[j] = std::abs(g.q[j] - g.setpoint[j]) * cpu(j);
          }
          tracked_.push_back(t);
        }
        if (g.mode == cell_robot_MODE_FAULT && (g.fault_bits & ~kDeadlineBits) != 0) {
          saw_fault_ = true;  // anything but a deadline miss (or a stall) is the loop's doing
        }
      }
    }
  }

  double cpu(std::size_t j) const { return model_.joints()[j].counts_per_unit; }

  Result<bus::Owned<cell_robot_RobotCommandReply>> command(cell_robot_RobotCommandKind kind,
                                                           bool halogen = false,
                                                           bool fluorescent = false) {
    cell_robot_RobotCommand c{};
    const std::string robot = "ibm7545";
    c.robot_id = bus::borrow(robot);
    c.kind = kind;
    c.halogen_on = halogen;
    c.fluorescent_on = fluorescent;
    return commands_.call(c, 5s);
  }

  /// Homes and waits until the arm rests on its home counts. A spontaneous deadline miss
  /// (below) during the homing or the settling aborts it and leaves the arm wherever its
  /// unpowered joints drifted: reset and home again (up to 8 times), as an operator would.
  void home() {
    for (int attempt = 0;; ++attempt) {
      const int misses_before = spontaneous_misses_;
      auto r = command(cell_robot_CMD_HOME);
      ASSERT_THAT(r, IsOk());
      ASSERT_TRUE((*r)->status.accepted) << bus::str((*r)->status.reason);
      bool faulted = false;
      ASSERT_TRUE(eventually(
          [&] {
            pump();
            if (gateway_state_ && gateway_state_->mode == cell_robot_MODE_FAULT) {
              faulted = true;
              return true;
            }
            return gateway_state_ && gateway_state_->homed &&
                   gateway_state_->mode == cell_robot_MODE_IDLE;
          },
          60s))
          << "homing did not finish:\n" << output(gateway_) << output(sim_);
      if (faulted) {
        ASSERT_TRUE(recover_from_spontaneous_deadline_miss() && attempt < 8)
            << "homing faulted: " << gateway_state_->fault_text;
        continue;
      }
      settle();
      if (spontaneous_misses_ == misses_before || attempt == 8) {
        return;
      }
    }
  }

  /// A deadline miss nobody injected: on this 2-vCPU virtual machine the host stalls even a
  /// SCHED_FIFO thread for more than the 1 ms sample period a few times a minute under load
  /// (bench/servo measures it: "wakes > 1 ms late" of a bare clock_nanosleep loop). The slave
  /// then does what it must (0x1000/0x2000, DACs at 0 V) and so does the gateway (FAULT); the
  /// test resets, as an operator would, counts it, and goes on. Any other fault is a failure.
  bool recover_from_spontaneous_deadline_miss() {
    pump();
    if (!gateway_state_ || gateway_state_->mode != cell_robot_MODE_FAULT) {
      return false;
    }
    // Stalls come in bursts: a reset may be followed at once by the next miss.
    for (int resets = 0; resets < 5; ++resets) {
      // The fault's bits come with the state after the fault: give them a moment.
      (void)eventually([&] { return pump(), gateway_state_->fault_bits != 0; }, 200ms);
      const bool deadline = (gateway_state_->fault_bits & kDeadlineBits) != 0 &&
                            (gateway_state_->fault_bits & ~kDeadlineBits) == 0;
      // Four handshakes in a row that ran out of their budget: the same stall seen first by
      // the gateway (the slave's 0x1000 follows).
      const bool link = gateway_state_->fault_text.find("link to the controller failed") !=
                        std::string::npos;
      if (!deadline && !link) {
        std::printf("not a deadline miss: %s (bits 0x%x)\n", gateway_state_->fault_text.c_str(),
                    gateway_state_->fault_bits);
        return false;
      }
      ++spontaneous_misses_;
      std::printf("spontaneous deadline miss (%s): the machine stalled; reset\n",
                  gateway_state_->fault_text.c_str());
      auto reset = command(cell_robot_CMD_RESET);
      EXPECT_THAT(reset, IsOk());
      if (eventually([&] { return pump(), gateway_state_->mode != cell_robot_MODE_FAULT; },
                     3s)) {
        return true;
      }
    }
    return false;
  }

  /// Waits until the arm rests on its setpoint (the bumpless start and the PD loop settled):
  /// the joints within kRestCounts of the setpoint and the setpoint unchanged, over 100 ms of
  /// states. The published setpoint is the loop's applied reference: at the first period of a
  /// bumpless start it equals the measured joints, wherever they are, and then ramps to the
  /// host's setpoint; one state agreeing with it says nothing about rest.
  void settle() {
    std::vector<double> held;
    auto since = std::chrono::steady_clock::now();
    ASSERT_TRUE(eventually(
        [&] {
          pump();
          (void)recover_from_spontaneous_deadline_miss();
          const auto now = std::chrono::steady_clock::now();
          bool rests = gateway_state_ && gateway_state_->q.size() == 4 &&
                       gateway_state_->setpoint.size() == 4 &&
                       gateway_state_->mode != cell_robot_MODE_FAULT;
          for (std::size_t j = 0; rests && j < 4; ++j) {
            rests = std::abs(gateway_state_->q[j] - gateway_state_->setpoint[j]) * cpu(j) <=
                        kRestCounts &&
                    (held.size() != 4 ||
                     std::abs(gateway_state_->setpoint[j] - held[j]) * cpu(j) <= 0.01);
          }
          if (!rests || held.size() != 4) {
            held = gateway_state_ ? gateway_state_->setpoint : std::vector<double>{};
            since = now;
            return false;
          }
          return now - since >= std::chrono::milliseconds(100);
        },
        20s))
        << "the arm did not settle on its setpoint";
  }

  std::vector<double> joints() {
    pump();
    return gateway_state_ ? gateway_state_->q : std::vector<double>{};
  }

  cell_motion_MotionRequest request(cell_motion_MotionKind kind, const std::string& robot) {
    robot_storage_ = robot;
    cell_motion_MotionRequest r{};
    r.robot_id = bus::borrow(robot_storage_);
    r.kind = kind;
    return r;
  }

  /// Sends a motion request; returns its sequence for wait_motion.
  std::uint64_t send(cell_motion_MotionRequest& r) {
    motion_id_ = fmt::format("m{}", ++motion_counter_);
    r.motion_id = bus::borrow(motion_id_);
    auto seq = motions_.send(r, 10s);
    EXPECT_THAT(seq, IsOk());
    return seq ? *seq : 0;
  }

  /// Pumps states until the motion's terminal status (or the timeout).
  std::optional<bus::Owned<cell_motion_MotionStatus>> wait_motion(std::uint64_t seq,
                                                                 std::chrono::seconds timeout) {
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    while (std::chrono::steady_clock::now() < deadline) {
      pump();
      auto status = motions_.wait_reply(seq, std::chrono::steady_clock::now() + 20ms,
                                        [](const cell_motion_MotionStatus& s) {
                                          return terminal(s);
                                        });
      if (status) {
        pump();
        return std::move(*status);
      }
    }
    return std::nullopt;
  }

  /// Sends `make()`'s request and waits for its end; a motion that failed on a spontaneous
  /// deadline miss is retried (up to 20 times) after the reset, with tracking statistics started
  /// afresh, so they describe the run that completed.
  template <typename Make>
  std::optional<bus::Owned<cell_motion_MotionStatus>> run_motion(Make&& make,
                                                                std::chrono::seconds timeout) {
    for (int attempt = 0;; ++attempt) {
      tracked_.clear();
      auto r = make();
      saw_fault_ = false;  // of the run that completes
      auto status = wait_motion(send(r), timeout);
      // After a reset the arm may still creep onto its held setpoint while the next plan is
      // made from its measured joints: the gateway's start check refuses that plan; again.
      const bool refused_after_reset =
          status && attempt > 0 &&
          std::string(bus::str((*status)->reason)).find("trajectory starts with") !=
              std::string::npos;
      if (!status || (*status)->state != cell_motion_MOTION_FAILED || attempt == 20 ||
          !(refused_after_reset || recover_from_spontaneous_deadline_miss())) {
        return status;
      }
      settle();
    }
  }

  /// A MOVE_JOINTS to `q` (rad, mm), run to its end by run_motion.
  std::optional<bus::Owned<cell_motion_MotionStatus>> move_joints(const std::vector<double>& q) {
    return run_motion(
        [&] {
          auto r = request(cell_motion_MOTION_MOVE_JOINTS, "ibm7545");
          bus::borrow(r.joints_rad_or_mm, q);
          return r;
        },
        60s);
  }

  /// A VIA_PATH request through the FK poses of `via` to that of `target` (joints).
  cell_motion_MotionRequest via_path(const std::vector<double>& via_joints,
                                     const std::vector<double>& target_joints) {
    const auto pose = [&](const std::vector<double>& q) {
      kinematics::JointVector v(4);
      for (int j = 0; j < 4; ++j) {
        v[j] = q[static_cast<std::size_t>(j)];
      }
      return motion::to_idl(*model_.forward(v));
    };
    via_storage_ = {pose(via_joints)};
    auto r = request(cell_motion_MOTION_VIA_PATH, "ibm7545");
    r.target = pose(target_joints);
    r.via._buffer = via_storage_.data();
    r.via._length = static_cast<std::uint32_t>(via_storage_.size());
    r.via._maximum = r.via._length;
    r.via._release = false;
    return r;
  }

  /// |gateway - simulator truth| per joint at rest, in counts (both must be present). The two
  /// processes publish independently: wait (up to 2 s) for a truth that is at rest too, so a
  /// truth sampled while the arm still coasted is not compared with a later gateway state.
  double truth_gap() {
    (void)eventually(
        [&] {
          pump();
          for (std::size_t j = 0; j < 4; ++j) {
            if (sim_state_->qd[j] != 0.0) {
              return false;
            }
          }
          return true;
        },
        2s);
    double worst = 0;
    for (std::size_t j = 0; j < 4; ++j) {
      worst = std::max(worst, std::abs(gateway_state_->q[j] - sim_state_->q[j]) * cpu(j));
    }
    return worst;
  }

  static inline int instance_ = 0;
  std::uint32_t domain_;
  std::string partition_;
  std::string shm_name_;
  std::string dir_;
  std::vector<std::string> env_;
  kinematics::RobotModel model_;
  bus::Participant client_;
  bus::Topic<cell_robot_RobotState> state_topic_;
  bus::Reader<cell_robot_RobotState> states_;
  bus::Topic<cell_health_CellEvent> event_topic_;
  bus::Reader<cell_health_CellEvent> events_;
  bus::Requester<cell_motion_MotionRequest, cell_motion_MotionStatus> motions_;
  bus::Requester<cell_robot_RobotCommand, cell_robot_RobotCommandReply> commands_;
  bus::Requester<cell_motion_Trajectory, cell_robot_RobotCommandReply> trajectories_;
  process::Child sim_;
  process::Child gateway_;
  process::Child motion_;
  std::optional<StateCopy> gateway_state_;
  std::optional<StateCopy> sim_state_;
  bool tracking_ = false;
  bool saw_fault_ = false;
  int spontaneous_misses_ = 0;
  /// A gateway state sampled while tracking: |measured - setpoint| per joint.
  struct TrackedState {
    std::array<double, 4> error_counts;
  };
  std::vector<TrackedState> tracked_;  ///< of the motion run last (run_motion clears it)

  /// The worst following error over the tracked states, and how many there were.
  struct Tracking {
    std::array<double, 4> worst{};
    int states = 0;
  };
  Tracking tracking_statistics() const {
    Tracking out;
    for (const auto& t : tracked_) {
      for (std::size_t j = 0; j < 4; ++j) {
        out.worst[j] = std::max(out.worst[j], t.error_counts[j]);
      }
      ++out.states;
    }
    return out;
  }
  std::string robot_storage_;
  std::string motion_id_;
  int motion_counter_ = 0;
  std::vector<cell_common_Pose> via_storage_;
  std::array<std::string, 3> logs_;  ///< what sim, gateway and motion printed (pump drains)
};

// Homing (digest 000 §2.4) moves the arm to its index-defined home, where the gateway's counts
// and the simulator's truth agree; then the thesis's cubic via-point path (through one via
// point) is tracked within kMaxFollowingCounts on every sampled cycle and ends on its target.
TEST_F(Gateway7545Test, HomesThenTracksAViaPointPathWithinTheFollowingErrorBound) {
  ASSERT_TRUE(gateway_state_.has_value());
  EXPECT_FALSE(gateway_state_->homed);
  home();
  ASSERT_TRUE(eventually([&] { return pump(), sim_state_->homed; }, 5s));
  for (std::size_t j = 0; j < 4; ++j) {
    EXPECT_LE(std::abs(gateway_state_->q[j]) * cpu(j), kRestCounts) << "joint " << j;
  }
  EXPECT_LE(truth_gap(), kTruthCounts);

  // Long segments, so that the joints approach their speed limits (0.8 of them); the planner
  // stretches a segment whose acceleration would pass config/robots/ibm7545.yaml's limits.
  const std::vector<double> via = {deg(40), deg(50), 100.0, deg(30)};
  const std::vector<double> target = {deg(90), deg(100), 180.0, deg(60)};
  tracking_ = true;
  auto status = run_motion(
      [&] {
        auto r = via_path(via, target);
        r.speed_scale = 0.8;
        return r;
      },
      60s);
  tracking_ = false;
  ASSERT_TRUE(status.has_value()) << "no terminal motion status";
  ASSERT_EQ((*status)->state, cell_motion_MOTION_DONE) << bus::str((*status)->reason);
  EXPECT_FALSE(saw_fault_);
  // A 100 Hz stream over a move of seconds.
  const Tracking stats = tracking_statistics();
  EXPECT_GT(stats.states, 50);
  std::printf("worst following error over %d states [counts]: J1 %.1f, J2 %.1f, Z %.1f, R %.1f\n",
              stats.states, stats.worst[0], stats.worst[1], stats.worst[2], stats.worst[3]);
  for (std::size_t j = 0; j < 4; ++j) {
    EXPECT_LE(stats.worst[j], kMaxFollowingCounts[j]) << "joint " << j;
    EXPECT_GT(stats.worst[j], 0.0) << "joint " << j << " (a real PD loop lags)";
  }
  settle();
  const std::vector<double> q = joints();
  for (std::size_t j = 0; j < 4; ++j) {
    EXPECT_LE(std::abs(q[j] - target[j]) * cpu(j), 1.0) << "joint " << j;
  }
  EXPECT_LE(truth_gap(), kTruthCounts);
  // A stall of the machine after the move (a deadline bit only) is reset and counted like the
  // others; any other fault stays and fails here.
  (void)recover_from_spontaneous_deadline_miss();
  pump();
  EXPECT_EQ(gateway_state_->fault_bits, 0U);
}

// Digest 000 §9.2 case 6 end to end: the slave misses a sample deadline (injected), flags
// 0x1000; the gateway faults with the bit's meaning, the motion fails, the slave's DACs are at
// 0 V and the arm comes to rest; RESET clears it and a new trajectory runs.
TEST_F(Gateway7545Test, DeadlineMissStopsSafelyAndResetRecovers) {
  home();
  const std::vector<double> far = {deg(80), deg(90), 150.0, deg(60)};
  std::uint64_t seq = 0;
  bool injected = false;
  for (int attempt = 0; attempt < 12 && !injected; ++attempt) {
    // Start a long move and inject while it runs (a spontaneous miss first: reset, again).
    auto r = request(cell_motion_MOTION_MOVE_JOINTS, "ibm7545");
    bus::borrow(r.joints_rad_or_mm, far);
    seq = send(r);
    const bool moving = eventually(
        [&] {
          pump();
          return gateway_state_->mode == cell_robot_MODE_FAULT ||
                 (gateway_state_->moving && std::abs(gateway_state_->q[0]) > deg(5));
        },
        20s);
    ASSERT_TRUE(moving) << "the move did not start";
    if (gateway_state_->mode != cell_robot_MODE_FAULT) {
      const auto run = cell::testing::run_tool(
          "cell-sim-7545", {"inject", "deadline-miss", "--shm", shm_name_}, env_, 10s);
      injected = run.exit.code == 0;
    }
    if (!injected) {
      (void)wait_motion(seq, 20s);
      ASSERT_TRUE(recover_from_spontaneous_deadline_miss()) << "could not inject";
      settle();
    }
  }
  ASSERT_TRUE(injected);

  ASSERT_TRUE(eventually([&] { return pump(), gateway_state_->mode == cell_robot_MODE_FAULT; },
                         10s));
  EXPECT_EQ(gateway_state_->fault_bits & 0x1000U, 0x1000U);
  EXPECT_THAT(gateway_state_->fault_text, HasSubstr("torques late"));
  EXPECT_FALSE(gateway_state_->moving);
  auto status = wait_motion(seq, 20s);
  ASSERT_TRUE(status.has_value());
  EXPECT_EQ((*status)->state, cell_motion_MOTION_FAILED);
  EXPECT_THAT(std::string(bus::str((*status)->reason)), HasSubstr("faulted"));
  // The slave's side: DACs at 0 V and the arm at rest (friction stops it).
  ASSERT_TRUE(eventually(
      [&] {
        pump();
        bool rest = true;
        for (std::size_t j = 0; j < 4; ++j) {
          rest = rest && sim_state_->effort[j] == 2048.0 && sim_state_->qd[j] == 0.0;
        }
        return rest;
      },
      5s))
      << "the arm did not come to rest with its DACs at 0 V";
  EXPECT_EQ(sim_state_->fault_bits & 0x1000U, 0x1000U);
  // The fault reached the operator as a CellEvent naming the bit.
  bool event = false;
  ASSERT_TRUE(eventually(
      [&] {
        for (auto& e : *events_.take_copies(64)) {
          event = event || (std::string_view(bus::str(e->code)) == "robot.fault" &&
                            std::string_view(bus::str(e->text)).find("0x1000") !=
                                std::string_view::npos);
        }
        return event;
      },
      5s));
  // Nothing moves while faulted: a trajectory is refused.
  auto refused = request(cell_motion_MOTION_MOVE_JOINTS, "ibm7545");
  const std::vector<double> near = {deg(10), deg(10), 10.0, 0.0};
  bus::borrow(refused.joints_rad_or_mm, near);
  auto refusal = wait_motion(send(refused), 10s);
  ASSERT_TRUE(refusal.has_value());
  EXPECT_NE((*refusal)->state, cell_motion_MOTION_DONE);

  auto reset = command(cell_robot_CMD_RESET);
  ASSERT_THAT(reset, IsOk());
  ASSERT_TRUE((*reset)->status.accepted) << bus::str((*reset)->status.reason);
  ASSERT_TRUE(eventually(
      [&] {
        pump();
        return gateway_state_->mode == cell_robot_MODE_IDLE && gateway_state_->fault_bits == 0 &&
               sim_state_->fault_bits == 0;
      },
      10s));
  settle();  // control mode restarted bumplessly and closed the coasting gap
  saw_fault_ = false;
  auto done = move_joints(near);
  ASSERT_TRUE(done.has_value());
  EXPECT_EQ((*done)->state, cell_motion_MOTION_DONE) << bus::str((*done)->reason);
  EXPECT_FALSE(saw_fault_);
  settle();
  const std::vector<double> q = joints();
  for (std::size_t j = 0; j < 4; ++j) {
    EXPECT_LE(std::abs(q[j] - near[j]) * cpu(j), 1.0) << "joint " << j;
  }
}

// Bad input is answered with the reason and nothing moves; the gateway keeps serving; the
// gripper and the lights reach the slave's latches (digest 000 §9.2 case 5).
TEST_F(Gateway7545Test, BadInputIsRefusedNothingMovesAndTheGatewayKeepsServing) {
  home();
  settle();
  const std::vector<double> before = joints();
  ASSERT_EQ(before.size(), 4U);
  const std::vector<double> held = gateway_state_->setpoint;  // what the loop holds
  ASSERT_EQ(held.size(), 4U);

  // Outside J2's limits [0, 135] deg.
  auto beyond = request(cell_motion_MOTION_MOVE_JOINTS, "ibm7545");
  const std::vector<double> bad = {deg(10), deg(170), 10.0, 0.0};
  bus::borrow(beyond.joints_rad_or_mm, bad);
  auto refused = wait_motion(send(beyond), 10s);
  ASSERT_TRUE(refused.has_value());
  EXPECT_EQ((*refused)->state, cell_motion_MOTION_REFUSED);
  EXPECT_THAT(std::string(bus::str((*refused)->reason)), HasSubstr("j2"));

  // A robot nobody plans for.
  auto unknown = request(cell_motion_MOTION_MOVE_JOINTS, "puma560");
  bus::borrow(unknown.joints_rad_or_mm, before);
  auto unknown_status = wait_motion(send(unknown), 10s);
  ASSERT_TRUE(unknown_status.has_value());
  EXPECT_EQ((*unknown_status)->state, cell_motion_MOTION_REFUSED);
  EXPECT_THAT(std::string(bus::str((*unknown_status)->reason)), HasSubstr("unknown robot"));

  // A trajectory straight to the gateway, beyond J1's limit (bypassing the planner's checks).
  motion::Plan plan;
  trajectory::JointVector q0(4);
  trajectory::JointVector q1(4);
  for (int j = 0; j < 4; ++j) {
    q0[j] = before[static_cast<std::size_t>(j)];
  }
  q1 = q0;
  q1[0] = deg(250);
  plan.trajectory = *trajectory::JointTrajectory::from_knots(
      {{0.0, q0, trajectory::JointVector::Zero(4)}, {20.0, q1, trajectory::JointVector::Zero(4)}});
  motion::TrajectoryWire wire;
  motion::to_idl(plan, "ibm7545", "too-far", "test", wire);
  auto reply = trajectories_.call(wire.message, 5s);
  ASSERT_THAT(reply, IsOk());
  EXPECT_FALSE((*reply)->status.accepted);
  EXPECT_THAT(std::string(bus::str((*reply)->status.reason)), HasSubstr("limit"));

  // A command this driver does not have.
  auto mode = command(cell_robot_CMD_SET_MODE);
  ASSERT_THAT(mode, IsOk());
  EXPECT_FALSE((*mode)->status.accepted);
  EXPECT_THAT(std::string(bus::str((*mode)->status.reason)), HasSubstr("not supported"));

  // Nothing moved: the loop holds the same setpoint, the arm rests on it (within the one-count
  // band a PD loop with Coulomb friction rests in: two readings may differ by two counts, one
  // on each side, which compared with each other failed once under load), and the simulator's
  // truth agrees.
  std::this_thread::sleep_for(300ms);
  const std::vector<double> after = joints();
  ASSERT_EQ(gateway_state_->setpoint.size(), 4U);
  for (std::size_t j = 0; j < 4; ++j) {
    EXPECT_LE(std::abs(gateway_state_->setpoint[j] - held[j]) * cpu(j), 0.01)
        << "joint " << j << ": the setpoint moved";
    EXPECT_LE(std::abs(after[j] - held[j]) * cpu(j), kRestCounts) << "joint " << j;
  }
  EXPECT_LE(truth_gap(), kTruthCounts);
  EXPECT_TRUE(gateway_.running());
  (void)recover_from_spontaneous_deadline_miss();  // a stall is not the bad input's doing
  EXPECT_NE(gateway_state_->mode, cell_robot_MODE_FAULT);

  // Still serving: the gripper (leaves control mode, the slave's latch, back) and the lights.
  auto close = command(cell_robot_CMD_GRIPPER_CLOSE);
  ASSERT_THAT(close, IsOk());
  ASSERT_TRUE((*close)->status.accepted) << bus::str((*close)->status.reason);
  ASSERT_TRUE(eventually(
      [&] {
        pump();
        return gateway_state_->gripper == cell_robot_GRIPPER_CLOSED &&
               sim_state_->gripper == cell_robot_GRIPPER_CLOSED;
      },
      10s));
  auto lights = command(cell_robot_CMD_LIGHTS, /*halogen=*/true, /*fluorescent=*/false);
  ASSERT_THAT(lights, IsOk());
  ASSERT_TRUE((*lights)->status.accepted);
  ASSERT_TRUE(eventually(
      [&] { return pump(), sim_state_->halogen && !sim_state_->fluorescent; }, 5s));
  settle();
  EXPECT_EQ(gateway_state_->mode, cell_robot_MODE_IDLE);
  EXPECT_FALSE(saw_fault_);
}

}  // namespace
}  // namespace cell
