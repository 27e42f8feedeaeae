#include "sim_excalibur_service.hpp"

#include <fmt/format.h>

#include <cmath>
#include <numbers>
#include <stdexcept>
#include <system_error>

#include "cell/bus/view.hpp"
#include "cell/bus/waitset.hpp"
#include "cell/common/log.hpp"
#include "cell/common/time.hpp"
#include "cell/kinematics/robot_config.hpp"
#include "cell/motion/wire.hpp"
#include "cell/protocols/excalibur/angles.hpp"
#include "cell/service/paths.hpp"

namespace cell::sim_excalibur {
namespace {

namespace pe = protocols::excalibur;
constexpr double kRadPerDeg = std::numbers::pi / 180.0;
constexpr std::array<const char*, 6> kJointKeys = {"theta1", "theta2", "theta3",
                                                   "theta4", "theta5", "theta6"};

std::string resolve(const std::string& path) {
  if (path.empty() || std::filesystem::path(path).is_absolute()) {
    return path;
  }
  return (std::filesystem::path(service::cell_home()) / path).lexically_normal().string();
}

void read_noise(config::MapReader& r, pe::NoiseSettings& noise, double& not_achieved) {
  r.optional("probability_per_line", noise.probability_per_line);
  r.optional("probability_per_byte", noise.probability_per_byte);
  r.optional("move_not_achieved_probability", not_achieved);
  for (const auto& [key, value] : {std::pair{"probability_per_line", noise.probability_per_line},
                                   std::pair{"probability_per_byte", noise.probability_per_byte},
                                   std::pair{"move_not_achieved_probability", not_achieved}}) {
    if (!(value >= 0.0 && value <= 1.0)) {
      r.fail(key, fmt::format("must be a probability in [0, 1], got {}", value));
    }
  }
}

kinematics::JointVector dh_rad(const std::array<double, 6>& deg) {
  kinematics::JointVector q(6);
  for (int j = 0; j < 6; ++j) {
    q[j] = deg[static_cast<std::size_t>(j)] * kRadPerDeg;
  }
  return q;
}

cell_robot_RobotMode robot_mode(pe::Mode mode, bool moving) {
  switch (mode) {
    case pe::Mode::kManual:
      return cell_robot_MODE_MANUAL;
    case pe::Mode::kTeach:
      return cell_robot_MODE_TEACH;
    case pe::Mode::kPlayback:
      return cell_robot_MODE_PLAYBACK;
    case pe::Mode::kHost:
      break;
  }
  return moving ? cell_robot_MODE_MOVING : cell_robot_MODE_IDLE;
}

kinematics::RobotModel load_model(const SimExcaliburConfig& config) {
  auto model = kinematics::load_robot(config.robot_config);
  if (!model) {
    throw std::runtime_error(model.error().message);
  }
  if (model->excalibur() == nullptr) {
    throw std::runtime_error(
        fmt::format("{}: robot '{}' is not an Excalibur", config.robot_config, model->id()));
  }
  return std::move(*model);
}

}  // namespace

Result<SimExcaliburConfig> load_config(const config::Document& doc) {
  SimExcaliburConfig c;
  config::MapReader root(doc, doc.root, "");
  service::read_common(root, c.common);
  root.optional("robot_config", c.robot_config);
  root.optional("dialect", c.dialect);
  root.optional("link_path", c.link_path);
  root.optional("baud", c.baud);
  root.optional("emulate_baud", c.emulate_baud);
  root.optional("robot_id", c.robot_id);
  root.optional("state_rate_hz", c.state_rate_hz);
  root.optional("realtime_priority", c.realtime_priority);
  if (c.realtime_priority < 0 || c.realtime_priority > 99) {
    root.fail("realtime_priority",
              fmt::format("must be 0 (none) or a SCHED_FIFO priority 1..99, got {}",
                          c.realtime_priority));
  }
  if (!(c.baud >= 300 && c.baud <= 4'000'000)) {
    root.fail("baud", fmt::format("must be in [300, 4000000], got {}", c.baud));
  }
  if (!(c.state_rate_hz >= 0.1 && c.state_rate_hz <= 1000)) {
    root.fail("state_rate_hz", fmt::format("must be in [0.1, 1000], got {}", c.state_rate_hz));
  }
  if (c.link_path.empty() || c.robot_id.empty()) {
    root.fail(c.link_path.empty() ? "link_path" : "robot_id", "must not be empty");
  }

  config::MapReader ctl = root.child("controller", false);
  if (ctl.has("initial_deg")) {
    std::array<double, 6> v{};
    ctl.optional("initial_deg", v);
    c.initial_deg = v;
  }
  if (ctl.has("master_deg")) {
    std::array<double, 6> v{};
    ctl.optional("master_deg", v);
    c.master_deg = v;
  }
  config::MapReader limits = ctl.child("limits_deg", false);
  for (std::size_t j = 0; j < 6; ++j) {
    if (limits.has(kJointKeys[j])) {
      std::array<double, 2> v{};
      limits.optional(kJointKeys[j], v);
      if (!(v[0] < v[1])) {
        limits.fail(kJointKeys[j], fmt::format("must be [lower, upper] with lower < upper, got "
                                               "[{}, {}]",
                                               v[0], v[1]));
      }
      c.limits_deg[j] = v;
    }
  }
  ctl.absorb(limits);
  ctl.optional("speed_scale", c.speed_scale);
  ctl.optional("accuracy_deg", c.accuracy_deg);
  ctl.optional("bias_deg", c.bias_deg);
  ctl.optional("own_check", c.own_check);
  ctl.optional("min_char_interval_ms", c.min_char_interval_ms);
  ctl.optional("busy_after_line_ms", c.busy_after_line_ms);
  ctl.optional("reply_delay_ms", c.reply_delay_ms);
  ctl.optional("gripper_time_s", c.gripper_time_s);
  std::string mode = "host";
  ctl.optional("power_up_mode", mode);
  std::int64_t seed = 1;
  ctl.optional("seed", seed);
  c.seed = static_cast<std::uint64_t>(seed);
  bool mode_ok = false;
  for (std::size_t m = 0; m < pe::kModes; ++m) {
    if (pe::to_string(static_cast<pe::Mode>(m)) == mode) {
      c.power_up_mode = static_cast<pe::Mode>(m);
      mode_ok = true;
    }
  }
  if (!mode_ok) {
    ctl.fail("power_up_mode",
             fmt::format("must be host, manual, teach or playback; got '{}'", mode));
  }
  if (!(c.speed_scale > 0 && c.speed_scale <= 100)) {
    ctl.fail("speed_scale", fmt::format("must be in (0, 100], got {}", c.speed_scale));
  }
  if (!(c.accuracy_deg >= 0 && c.accuracy_deg < 10)) {
    ctl.fail("accuracy_deg", fmt::format("must be in [0, 10), got {}", c.accuracy_deg));
  }
  for (const auto& [key, value] : {std::pair{"min_char_interval_ms", c.min_char_interval_ms},
                                   std::pair{"busy_after_line_ms", c.busy_after_line_ms},
                                   std::pair{"reply_delay_ms", c.reply_delay_ms}}) {
    if (!(value >= 0 && value <= 1000)) {
      ctl.fail(key, fmt::format("must be in [0, 1000], got {}", value));
    }
  }
  if (!(c.gripper_time_s >= 0 && c.gripper_time_s <= 10)) {
    ctl.fail("gripper_time_s", fmt::format("must be in [0, 10], got {}", c.gripper_time_s));
  }
  root.absorb(ctl);

  config::MapReader noise = root.child("noise", false);
  read_noise(noise, c.noise, c.move_not_achieved_probability);
  noise.optional("control_file", c.control_file);
  root.absorb(noise);
  CELL_TRY(root.finish());
  c.robot_config = resolve(c.robot_config);
  c.dialect = resolve(c.dialect);
  c.link_path = resolve(c.link_path);
  c.control_file = resolve(c.control_file);
  return c;
}

Result<NoiseControl> load_noise_control(const std::string& path) {
  auto doc = config::load_file(path);
  if (!doc) {
    return std::move(doc).error();
  }
  NoiseControl n;
  config::MapReader root(*doc, doc->root, "");
  read_noise(root, n.noise, n.move_not_achieved_probability);
  CELL_TRY(root.finish());
  return n;
}

Result<pe::ControllerSettings> controller_settings(const SimExcaliburConfig& config,
                                                   const kinematics::RobotModel& model) {
  const kinematics::ExcaliburModel* ex = model.excalibur();
  if (ex == nullptr) {
    return Error{Errc::kConfig, fmt::format("robot '{}' is not an Excalibur", model.id())};
  }
  kinematics::JointVector lower(6);
  kinematics::JointVector upper(6);
  kinematics::JointVector speed(6);
  for (int j = 0; j < 6; ++j) {
    const auto& spec = model.joints()[static_cast<std::size_t>(j)];
    const auto& over = config.limits_deg[static_cast<std::size_t>(j)];
    lower[j] = over ? (*over)[0] * kRadPerDeg : spec.lower;
    upper[j] = over ? (*over)[1] * kRadPerDeg : spec.upper;
    speed[j] = spec.max_speed * config.speed_scale;
  }
  pe::ControllerSettings s;
  s.lower_deg = pe::to_wire(*ex, lower);
  s.upper_deg = pe::to_wire(*ex, upper);
  for (std::size_t j = 0; j < pe::kJointCount; ++j) {
    s.speed_deg_s[j] = speed[static_cast<Eigen::Index>(j)] / kRadPerDeg;  // offsets do not scale
  }
  // Default start: the controller's zero q* = 0 (digest 001 case 2: elbow up).
  s.initial_deg =
      config.initial_deg ? pe::to_wire(*ex, dh_rad(*config.initial_deg)) : pe::ControllerAngles{};
  s.master_deg = config.master_deg ? pe::to_wire(*ex, dh_rad(*config.master_deg)) : s.initial_deg;
  s.accuracy_deg = config.accuracy_deg;
  s.bias_deg = config.bias_deg;
  s.own_check = config.own_check;
  s.min_char_interval_s = config.min_char_interval_ms * 1e-3;
  s.busy_after_line_s = config.busy_after_line_ms * 1e-3;
  s.reply_delay_s = config.reply_delay_ms * 1e-3;
  s.gripper_time_s = config.gripper_time_s;
  s.move_not_achieved_probability = config.move_not_achieved_probability;
  s.power_up_mode = config.power_up_mode;
  s.seed = config.seed;
  if (auto v = s.validate(); !v) {
    return Error{Errc::kConfig, "sim-excalibur controller: " + v.error().message};
  }
  return s;
}

SimExcaliburService::SimExcaliburService(service::Context& ctx, const SimExcaliburConfig& config)
    : config_(config),
      model_(load_model(config)),
      state_topic_(ctx.participant(), bus::topics::kRobotState),
      latest_topic_(ctx.participant(), bus::topics::kRobotStateLatest),
      state_writer_(ctx.participant(), state_topic_, bus::topics::kRobotState),
      latest_writer_(ctx.participant(), latest_topic_, bus::topics::kRobotStateLatest) {
  auto dialect = pe::Dialect::load(config_.dialect);
  if (!dialect) {
    throw std::runtime_error(dialect.error().message);
  }
  auto settings = controller_settings(config_, model_);
  if (!settings) {
    throw std::runtime_error(settings.error().message);
  }
  auto sim = pe::SimulatedController::start(
      std::move(*dialect), *settings,
      {.link_path = config_.link_path,
       .baud = config_.baud,
       .emulate_baud = config_.emulate_baud,
       .realtime_priority = config_.realtime_priority},
      config_.noise);
  if (!sim) {
    throw std::runtime_error(sim.error().message);
  }
  sim_ = std::move(*sim);
  if (sim_->realtime_refused()) {
    log::warn("sim_excalibur",
              "cannot use SCHED_FIFO (not root?); the controller runs with normal scheduling",
              {{"priority", std::to_string(config_.realtime_priority)}});
  }
  check_control_file();
  log::info("sim_excalibur", "controller on a pseudo-terminal",
            {{"link", config_.link_path},
             {"slave", sim_->slave_path()},
             {"baud", std::to_string(config_.baud)},
             {"noise_per_line", fmt::format("{}", sim_->noise().probability_per_line)}});
}

void SimExcaliburService::apply(const pe::NoiseSettings& noise,
                                double not_achieved,
                                const char* source) {
  if (auto s = sim_->set_noise(noise); !s) {
    log::warn("noise", s.error().message);
    return;
  }
  sim_->set_move_not_achieved_probability(not_achieved);
  log::info("noise", "line noise set",
            {{"source", source},
             {"probability_per_line", fmt::format("{}", noise.probability_per_line)},
             {"probability_per_byte", fmt::format("{}", noise.probability_per_byte)},
             {"move_not_achieved_probability", fmt::format("{}", not_achieved)}});
}

void SimExcaliburService::check_control_file() {
  if (config_.control_file.empty()) {
    return;
  }
  std::error_code ec;
  const auto mtime = std::filesystem::last_write_time(config_.control_file, ec);
  if (ec) {
    if (control_mtime_) {  // removed: back to the config's values
      control_mtime_.reset();
      apply(config_.noise, config_.move_not_achieved_probability, "config (control file removed)");
    }
    return;
  }
  if (control_mtime_ && *control_mtime_ == mtime) {
    return;
  }
  control_mtime_ = mtime;
  auto control = load_noise_control(config_.control_file);
  if (!control) {
    log::warn("noise", "control file ignored: " + control.error().message);
    return;
  }
  apply(control->noise, control->move_not_achieved_probability, "control file");
}

void SimExcaliburService::publish(const bus::Writer<cell_robot_RobotState>& writer) {
  const pe::ControllerStatus st = sim_->status();
  const kinematics::ExcaliburModel& ex = *model_.excalibur();
  const kinematics::JointVector q = pe::from_wire(ex, st.angles_deg);
  const kinematics::JointVector target = pe::from_wire(ex, st.target_deg);
  const std::vector<double> position(q.data(), q.data() + q.size());
  const std::vector<double> setpoint(target.data(), target.data() + target.size());
  const std::vector<double> zeros(6, 0.0);
  const std::string frame = config_.robot_id + "/base";
  auto pose = model_.forward(q);
  cell_robot_RobotState m{};
  m.robot_id = bus::borrow(config_.robot_id);
  m.header.stamp_ns = wall_time_ns();
  m.header.frame_id = bus::borrow(frame);
  m.header.seq = ++seq_;
  bus::borrow(m.position_rad_or_mm, position);
  bus::borrow(m.velocity_rad_or_mm_per_s, zeros);
  bus::borrow(m.setpoint_rad_or_mm, setpoint);
  bus::borrow(m.effort_raw, zeros);
  m.base_T_tool = motion::to_idl(pose ? *pose : Eigen::Isometry3d::Identity());
  m.gripper = st.gripper_moving
                  ? (st.gripper_closed ? cell_robot_GRIPPER_CLOSING : cell_robot_GRIPPER_OPENING)
                  : (st.gripper_closed ? cell_robot_GRIPPER_CLOSED : cell_robot_GRIPPER_OPEN);
  m.mode = robot_mode(st.mode, st.moving);
  m.homed = true;
  m.moving = st.moving;
  m.cycle_count = st.counters.lines_in;
  m.cycle_period_s = 1.0 / config_.state_rate_hz;
  (void)writer.write(m);
}

void SimExcaliburService::run(service::Context& ctx) {
  constexpr dds_attach_t kStop = 1;
  bus::WaitSet waitset(ctx.participant());
  waitset.attach(ctx.stop_guard().get(), kStop);
  ctx.health().set(cell_health_HEALTH_SERVING);
  const auto period = std::chrono::duration_cast<std::chrono::nanoseconds>(
      std::chrono::duration<double>(1.0 / config_.state_rate_hz));
  auto next_latest = std::chrono::steady_clock::now();
  auto next_report = std::chrono::steady_clock::now() + std::chrono::seconds(10);
  for (;;) {
    const bus::Fired fired = waitset.wait(period);
    if (fired.contains(kStop)) {
      break;
    }
    const auto now = std::chrono::steady_clock::now();
    publish(state_writer_);
    if (now >= next_latest) {
      publish(latest_writer_);
      next_latest = now + std::chrono::milliseconds(500);
    }
    if (now >= next_control_check_) {
      check_control_file();
      next_control_check_ = now + std::chrono::milliseconds(200);
    }
    for (const std::string& rejected : sim_->take_rejections()) {
      log::warn("rejected", rejected);
    }
    if (now >= next_report) {
      next_report = now + std::chrono::seconds(10);
      const auto c = sim_->status().counters;
      log::info("counters", "controller",
                {{"lines", std::to_string(c.lines_in)},
                 {"errors_sent", std::to_string(c.errors_sent)},
                 {"overruns", std::to_string(c.overruns)},
                 {"moves", std::to_string(c.moves)},
                 {"not_achieved", std::to_string(c.not_achieved)},
                 {"resets", std::to_string(c.resets)},
                 {"noise_faults_in", std::to_string(c.noise_faults_in)},
                 {"noise_faults_out", std::to_string(c.noise_faults_out)}});
    }
    ctx.health().tick();
  }
}

}  // namespace cell::sim_excalibur
