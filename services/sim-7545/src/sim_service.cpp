#include "sim_service.hpp"

#include <unistd.h>

#include <chrono>
#include <stdexcept>
#include <thread>

#include <CLI/CLI.hpp>
#include <fmt/format.h>

#include "cell/bus/view.hpp"
#include "cell/common/log.hpp"
#include "cell/common/realtime.hpp"
#include "cell/common/time.hpp"
#include "cell/dpr7545/sim_control.hpp"
#include "cell/kinematics/robot_config.hpp"
#include "cell/motion/wire.hpp"

namespace cell::sim7545 {
namespace {

kinematics::RobotModel load_model(const SimConfig& config) {
  auto model = kinematics::load_robot(config.robot_config);
  if (!model) {
    throw std::runtime_error(model.error().message);
  }
  if (model->dof() != dpr7545::kJoints) {
    throw std::runtime_error(fmt::format("{}: robot '{}' has {} joints; the 7545 slave drives {}",
                                         config.robot_config, model->id(), model->dof(),
                                         dpr7545::kJoints));
  }
  for (const auto& joint : model->joints()) {
    if (!(joint.counts_per_unit > 0)) {
      throw std::runtime_error(fmt::format("{}: joint '{}' has no encoder scale (counts_per_*)",
                                           config.robot_config, joint.name));
    }
  }
  return std::move(*model);
}

SlaveOptions slave_options(const SimConfig& config, const kinematics::RobotModel& model) {
  SlaveOptions o;
  o.plants = config.plants;
  o.idle_poll_s = config.idle_poll_us * 1e-6;
  o.delay_s = config.delay_s;
  o.deadline_slack_s = config.deadline_slack_us * 1e-6;
  o.fault_injection = config.fault_injection_enabled;
  o.deadline_miss_after_s = config.deadline_miss_after_s;
  for (int j = 0; j < dpr7545::kJoints; ++j) {
    const auto i = static_cast<std::size_t>(j);
    const auto& spec = model.joints()[i];
    o.initial_counts[i] = spec.from_display(config.initial_joints[i]) * spec.counts_per_unit;
    if (spec.overrun_counts) {
      o.limits[i] = {static_cast<std::int32_t>((*spec.overrun_counts)[0]),
                     static_cast<std::int32_t>((*spec.overrun_counts)[1])};
    }
  }
  return o;
}

std::unique_ptr<dpr7545::Transport> create_segment(const SimConfig& config) {
  auto t = dpr7545::create_shm(config.shm_name);
  if (!t) {
    throw std::runtime_error(t.error().message);
  }
  return std::move(*t);
}

cell_robot_RobotMode mode_of(const SlaveSnapshot& s) {
  if (s.error != 0) {
    return cell_robot_MODE_FAULT;
  }
  switch (s.mode) {
    case SlaveMode::kControl:
      return cell_robot_MODE_MOVING;
    case SlaveMode::kHoming:
      return cell_robot_MODE_HOMING;
    default:
      return cell_robot_MODE_IDLE;
  }
}

}  // namespace

SimService::SimService(service::Context& ctx, const SimConfig& config)
    : config_(config),
      model_(load_model(config)),
      transport_(create_segment(config)),
      slave_(std::make_unique<Slave>(transport_->window(), slave_options(config_, model_))),
      state_topic_(ctx.participant(), bus::topics::kRobotState),
      state_writer_(ctx.participant(), state_topic_, bus::topics::kRobotState) {
  thread_ = std::thread([this] {
    if (!set_thread_fifo(config_.realtime_priority)) {
      log::warn("slave", "cannot use SCHED_FIFO (not root?); running with normal scheduling",
                {{"priority", std::to_string(config_.realtime_priority)}});
    }
    slave_->run(stop_);
  });
  log::info("slave", "7545 slave simulator ready",
            {{"shm", config_.shm_name}, {"robot", model_.id()},
             {"state_robot_id", config_.state_robot_id}});
}

SimService::~SimService() {
  stop_ = true;
  if (thread_.joinable()) {
    thread_.join();
  }
}

void SimService::publish(const SlaveSnapshot& s) {
  std::vector<double> q(dpr7545::kJoints);
  std::vector<double> qd(dpr7545::kJoints);
  std::vector<double> effort(dpr7545::kJoints);
  kinematics::JointVector joints(dpr7545::kJoints);
  for (int j = 0; j < dpr7545::kJoints; ++j) {
    const auto i = static_cast<std::size_t>(j);
    const double scale = model_.joints()[i].counts_per_unit;
    q[i] = s.position_counts[i] / scale;
    qd[i] = s.velocity_counts_s[i] / scale;
    effort[i] = s.dac[i];
    joints[j] = q[i];
  }
  const auto pose = model_.forward(joints);
  const std::string frame = model_.id() + "/base";
  const std::string fault_text = dpr7545::describe_errors(s.error);
  cell_robot_RobotState m{};
  m.robot_id = bus::borrow(config_.state_robot_id);
  m.header.stamp_ns = wall_time_ns();
  m.header.frame_id = bus::borrow(frame);
  m.header.seq = ++seq_;
  bus::borrow(m.position_rad_or_mm, q);
  bus::borrow(m.velocity_rad_or_mm_per_s, qd);
  bus::borrow(m.effort_raw, effort);
  m.base_T_tool = motion::to_idl(pose ? *pose : Eigen::Isometry3d::Identity());
  m.gripper = s.gripper_closed ? cell_robot_GRIPPER_CLOSED : cell_robot_GRIPPER_OPEN;
  m.mode = mode_of(s);
  m.homed = s.homed;
  m.moving = s.mode == SlaveMode::kControl;
  m.halogen_on = dpr7545::halogen_on(s.lights);
  m.fluorescent_on = dpr7545::fluorescent_on(s.lights);
  m.fault_bits = s.error;
  m.fault_text = bus::borrow(fault_text);
  static const std::string kNoTrajectory;  // the board runs no trajectory of the cell's
  m.trajectory_id = bus::borrow(kNoTrajectory);
  m.cycle_count = s.periods;
  m.cycle_period_s = (s.sample_period_us == 0 ? dpr7545::kDefaultSamplePeriodUs
                                              : s.sample_period_us) *
                     1e-6;
  m.cycle_jitter_max_us = s.late_max_us;
  m.cycle_overruns = s.deadline_errors + s.late_served;
  (void)state_writer_.write(m);  // best-effort stream
}

void SimService::run(service::Context& ctx) {
  bus::WaitSet waitset(ctx.participant());
  constexpr dds_attach_t kStop = 1;
  waitset.attach(ctx.stop_guard().get(), kStop);
  ctx.health().set(cell_health_HEALTH_SERVING);
  const auto period = std::chrono::duration_cast<std::chrono::nanoseconds>(
      std::chrono::duration<double>(1.0 / config_.state_rate_hz));
  auto next = std::chrono::steady_clock::now() + period;
  std::uint16_t last_error = 0;
  std::uint64_t stalls_logged = 0;
  bool was_homed = false;
  for (;;) {
    const auto now = std::chrono::steady_clock::now();
    const auto timeout = next > now ? std::chrono::duration_cast<std::chrono::milliseconds>(
                                          next - now)
                                    : std::chrono::milliseconds(0);
    const bus::Fired fired = waitset.wait(timeout);
    if (fired.contains(kStop)) {
      break;
    }
    if (std::chrono::steady_clock::now() < next) {
      continue;
    }
    next += period;
    if (next < std::chrono::steady_clock::now()) {
      next = std::chrono::steady_clock::now() + period;
    }
    const SlaveSnapshot s = slave_->take_snapshot();
    publish(s);
    if (s.error != last_error) {
      if (s.error != 0) {
        log::warn("slave", "error register set",
                  {{"bits", fmt::format("0x{:04x}", s.error)},
                   {"meaning", dpr7545::describe_errors(s.error)}});
      } else {
        log::info("slave", "error register cleared");
      }
      last_error = s.error;
    }
    if (s.homed != was_homed) {
      // Each homing of the board, once (tests count them: a master that re-attached after
      // its predecessor died must not have needed one).
      if (s.homed) {
        log::info("slave", "homed: every counter zeroed at its index pulse");
      } else {
        log::info("slave", "homing started");
      }
      was_homed = s.homed;
    }
    if (s.stalls_absorbed != stalls_logged) {
      log::info("slave", "this process stalled inside a handshake wait; the deadline moved by "
                "the stall",
                {{"stalls_absorbed", std::to_string(s.stalls_absorbed)},
                 {"late_served", std::to_string(s.late_served)},
                 {"board_clock_behind_s", fmt::format("{:.3f}", s.absorbed_s)}});
      stalls_logged = s.stalls_absorbed;
    }
    ctx.health().tick();
  }
}

int run_inject(int argc, char** argv) {
  CLI::App app{"cell-sim-7545 inject: ask a running 7545 slave simulator to inject a fault"};
  std::string fault_name;
  std::string joint_name = "J1";
  std::int32_t value = 0;
  std::string shm = "/cell-dpr7545";
  double timeout_s = 2.0;
  app.add_option("fault", fault_name,
                 "deadline-miss (0x1000), loop-late (0x2000), encoder-glitch (--value counts), "
                 "overrun (--value sign: > 0 positive), clear")
      ->required();
  app.add_option("--joint", joint_name, "J1, J2, Z, R (or 0..3)");
  app.add_option("--value", value, "counts (encoder-glitch) or direction (overrun)");
  app.add_option("--shm", shm, "the simulator's shm_name");
  app.add_option("--timeout", timeout_s, "seconds to wait for the acknowledgement");
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e) == 0 ? 0 : 2;
  }
  const auto fault = dpr7545::parse_sim_fault(fault_name);
  if (!fault) {
    fmt::print(stderr, "cell-sim-7545 inject: {}\n", fault.error().message);
    return 2;
  }
  int joint = -1;
  for (int j = 0; j < dpr7545::kJoints; ++j) {
    const auto name = dpr7545::kJointNames[static_cast<std::size_t>(j)];
    if (joint_name == name || joint_name == std::to_string(j) ||
        (joint_name.size() == name.size() &&
         std::equal(name.begin(), name.end(), joint_name.begin(),
                    [](char a, char b) { return std::tolower(a) == std::tolower(b); }))) {
      joint = j;
    }
  }
  if (joint < 0) {
    fmt::print(stderr, "cell-sim-7545 inject: unknown joint '{}' (J1, J2, Z, R or 0..3)\n",
               joint_name);
    return 2;
  }
  auto transport = dpr7545::open_shm(shm);
  if (!transport) {
    fmt::print(stderr, "cell-sim-7545 inject: {}\n", transport.error().message);
    return 1;
  }
  const dpr7545::SimControl control((*transport)->window());
  if (!control.valid()) {
    fmt::print(stderr, "cell-sim-7545 inject: shm segment '{}' has no simulator control block\n",
               shm);
    return 1;
  }
  const std::uint32_t sequence = control.post(*fault, joint, value);
  const auto deadline =
      std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
  while (std::chrono::steady_clock::now() < deadline) {
    if (const auto result = control.result(sequence)) {
      switch (*result) {
        case 0:
          fmt::print("injected {} (joint {}, value {}) into {}\n", fault_name,
                     dpr7545::kJointNames[static_cast<std::size_t>(joint)], value, shm);
          return 0;
        case 1:
          fmt::print(stderr, "cell-sim-7545 inject: refused: bad joint\n");
          return 1;
        case 3:
          fmt::print(stderr, "cell-sim-7545 inject: refused: the slave is not in control mode "
                             "(nothing to miss)\n");
          return 1;
        case 4:
          fmt::print(stderr, "cell-sim-7545 inject: refused: fault injection is disabled in the "
                             "simulator's config (fault_injection.enabled)\n");
          return 1;
        default:
          fmt::print(stderr, "cell-sim-7545 inject: refused: unknown fault\n");
          return 1;
      }
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  fmt::print(stderr, "cell-sim-7545 inject: no acknowledgement within {} s (is the simulator "
                     "running and its slave thread alive?)\n",
             timeout_s);
  return 1;
}

}  // namespace cell::sim7545
