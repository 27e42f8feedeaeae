#include "servo_limits.hpp"

#include <fmt/format.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <map>
#include <mutex>
#include <vector>

#include "cell/config/yaml.hpp"
#include "cell/dpr7545/codec.hpp"
#include "cell/kinematics/robot_config.hpp"
#include "cell/service/paths.hpp"
#include "joint_model.hpp"

namespace cell::sim7545 {
namespace {

/// A reference made of constant-acceleration phases, advanced exactly across their ends.
class Reference {
 public:
  struct Phase {
    double accel;
    double duration_s;
  };
  explicit Reference(std::vector<Phase> phases) : phases_(std::move(phases)) {}

  bool done() const noexcept { return index_ >= phases_.size(); }
  double position() const noexcept { return p_; }

  void advance(double dt) noexcept {
    while (dt > 0 && !done()) {
      const Phase& ph = phases_[index_];
      const double h = std::min(dt, ph.duration_s - in_phase_);
      p_ += v_ * h + 0.5 * ph.accel * h * h;
      v_ += ph.accel * h;
      in_phase_ += h;
      dt -= h;
      if (in_phase_ >= ph.duration_s - 1e-12) {
        ++index_;
        in_phase_ = 0.0;
      }
    }
    p_ += v_ * dt;  // after the last phase: cruise (the worst case ends at rest)
  }

 private:
  std::vector<Phase> phases_;
  std::size_t index_ = 0;
  double in_phase_ = 0.0;
  double p_ = 0.0;
  double v_ = 0.0;
};

}  // namespace

Result<std::array<PdLaw, dpr7545::kJoints>> load_pd_laws(const std::string& gateway_config) {
  auto doc = config::load_file(gateway_config);
  if (!doc) {
    return std::move(doc).error();
  }
  const auto bad = [&](const std::string& what) {
    return Error{Errc::kConfig, fmt::format("{}: {}", gateway_config, what)};
  };
  const YAML::Node driver = doc->root["driver"];
  if (!driver.IsMap()) {
    return bad("no 'driver' section");
  }
  std::array<PdLaw, dpr7545::kJoints> laws{};
  try {
    const YAML::Node kp = driver["kp"];
    const YAML::Node kv = driver["kv"];
    if (!kp.IsSequence() || kp.size() != dpr7545::kJoints || !kv.IsSequence() ||
        kv.size() != dpr7545::kJoints) {
      return bad("key 'driver.kp' and 'driver.kv' must be lists of 4 numbers (J1, J2, Z, R)");
    }
    const double period_s =
        driver["sample_period_us"] ? driver["sample_period_us"].as<double>() * 1e-6 : 0.001;
    for (std::size_t j = 0; j < dpr7545::kJoints; ++j) {
      laws[j] = PdLaw{kp[j].as<double>(), kv[j].as<double>(), period_s};
    }
  } catch (const YAML::Exception& e) {
    return bad(fmt::format("driver.kp, driver.kv or driver.sample_period_us: {}", e.what()));
  }
  return laws;
}

FollowResult simulate_follow(const JointPlant& plant,
                             const PdLaw& law,
                             double speed_counts_s,
                             double accel_counts_s2) {
  const double v = speed_counts_s;
  const double a = accel_counts_s2;
  const double ramp = v / a;  // 0 -> v
  constexpr double kCruise = 0.1;
  Reference reference({
      {a, ramp},         // 1. up to +v: (a + b v) / g + coulomb at its end
      {0.0, kCruise},    //    full speed
      {-a, 2 * ramp},    // 2. +v -> -v: the friction turns over at 0
      {0.0, kCruise},    //    full speed backwards
      {a, ramp},         //    back to rest
      {0.0, kCruise},    //
      {-a, 0.5 * ramp},  // 3. to -v/2
      {a, ramp},         //    a jump of 2a, up to +v/2
      {-a, 0.5 * ramp},  //    a jump of 2a, back to rest
      {0.0, kCruise},    //    settle
  });
  // The plant far from its stops; the encoder reads 0 at the start.
  JointModel joint(plant, 0.0, -1'000'000'000, 1'000'000'000);
  const double ts = law.period_s;
  double e_prev = 0.0;
  FollowResult r;
  while (!reference.done()) {
    const double e = reference.position() - static_cast<double>(joint.encoder_counts());
    const double torque = dpr7545::pd_torque(law.kp, law.kv, ts, e, e_prev);
    e_prev = e;
    r.peak_dac = std::max(r.peak_dac, std::abs(torque - dpr7545::kTorqueZero));
    r.peak_error_counts = std::max(r.peak_error_counts, std::abs(e));
    // The DAC saturates where the board would fault: the run goes on so the peak is measured.
    const auto word = static_cast<std::uint16_t>(
        std::clamp(std::round(torque), 0.0, static_cast<double>(dpr7545::kTorqueMax)));
    joint.advance(word, ts);
    reference.advance(ts);
  }
  return r;
}

namespace {
FollowableLimits scan_limits(const JointPlant& plant,
                             const PdLaw& law,
                             double speed_counts_s,
                             double margin);
}  // namespace

FollowableLimits derive_limits(const JointPlant& plant,
                               const PdLaw& law,
                               double speed_counts_s,
                               double margin) {
  // The scan runs ~1000 worst cases (~1.5 s): each derivation once per process.
  using Key = std::array<double, 8>;
  static std::mutex mutex;
  static std::map<Key, FollowableLimits> done;
  const Key key = {plant.accel_per_dac_counts_s2, plant.viscous_per_s, plant.coulomb_dac,
                   law.kp, law.kv, law.period_s, speed_counts_s, margin};
  {
    const std::lock_guard lock(mutex);
    if (const auto it = done.find(key); it != done.end()) {
      return it->second;
    }
  }
  FollowableLimits out = scan_limits(plant, law, speed_counts_s, margin);
  const std::lock_guard lock(mutex);
  done.emplace(key, out);
  return out;
}

namespace {

FollowableLimits scan_limits(const JointPlant& plant,
                             const PdLaw& law,
                             double speed_counts_s,
                             double margin) {
  FollowableLimits out;
  out.usable_dac = (1.0 - margin) * static_cast<double>(dpr7545::kTorqueMax - dpr7545::kTorqueZero);
  out.speed_ceiling_counts_s =
      (out.usable_dac - plant.coulomb_dac) * plant.accel_per_dac_counts_s2 / plant.viscous_per_s;
  const auto fits = [&](double accel) {
    return simulate_follow(plant, law, speed_counts_s, accel).peak_dac <= out.usable_dac;
  };
  // From full speed in 10 s (always gentle) up towards full speed in one sample period: the
  // first acceleration that does not fit ends the scan. The peak is not monotonic in the
  // acceleration (the encoder's one-count quantisation through the derivative term: up to
  // kv / Ts per count), so a bisection could land on a value with a failing one just below it;
  // the scan's result has every step below it fitting.
  double lo = speed_counts_s / 10.0;
  const double hi = speed_counts_s / law.period_s;
  if (!fits(lo)) {
    out.at_limits = simulate_follow(plant, law, speed_counts_s, lo);
    return out;
  }
  while (lo * 1.005 <= hi && fits(lo * 1.005)) {
    lo *= 1.005;
  }
  out.accel_counts_s2 = lo;
  out.at_limits = simulate_follow(plant, law, speed_counts_s, lo);
  return out;
}

}  // namespace

}  // namespace cell::sim7545

namespace cell::sim7545 {

Result<std::vector<JointJudgement>> judge_robot_limits(const std::string& robot_config,
                                                       const std::string& sim_config,
                                                       const std::string& gateway_config,
                                                       double margin) {
  auto model = kinematics::load_robot(robot_config);
  if (!model) {
    return std::move(model).error();
  }
  auto sim_doc = config::load_file(sim_config);
  if (!sim_doc) {
    return std::move(sim_doc).error();
  }
  auto sim = load_config(*sim_doc);
  if (!sim) {
    return std::move(sim).error();
  }
  auto laws = load_pd_laws(gateway_config);
  if (!laws) {
    return std::move(laws).error();
  }
  const auto& joints = model->joints();
  if (joints.size() != dpr7545::kJoints) {
    return Error{Errc::kInvalidArgument,
                 fmt::format("{}: {} joints; the 7545 board drives {}", robot_config, joints.size(),
                             dpr7545::kJoints)};
  }
  std::vector<JointJudgement> out;
  for (std::size_t j = 0; j < joints.size(); ++j) {
    const kinematics::JointSpec& spec = joints[j];
    if (!(spec.counts_per_unit > 0)) {
      return Error{Errc::kInvalidArgument,
                   fmt::format("{}: joint {} has no encoder scale (counts_per_deg / _mm)",
                               robot_config, spec.name)};
    }
    JointJudgement jj;
    jj.joint = spec.name;
    const bool prismatic = spec.type == kinematics::JointType::kPrismatic;
    jj.unit = prismatic ? "mm" : "deg";
    // counts_per_unit is per rad for a revolute joint: per degree for the messages.
    jj.counts_per_unit = prismatic ? spec.counts_per_unit : spec.counts_per_unit * M_PI / 180.0;
    jj.speed_counts_s = spec.max_speed * spec.counts_per_unit;
    jj.accel_counts_s2 = spec.max_accel * spec.counts_per_unit;
    jj.derived = derive_limits(sim->plants[j], (*laws)[j], jj.speed_counts_s, margin);
    jj.at_file_limits =
        simulate_follow(sim->plants[j], (*laws)[j], jj.speed_counts_s, jj.accel_counts_s2);
    // Above the derived acceleration some lower one does not fit (the peak is not monotonic):
    // a plan may use any acceleration up to the file's.
    jj.ok = jj.at_file_limits.peak_dac <= jj.derived.usable_dac &&
            jj.accel_counts_s2 <= jj.derived.accel_counts_s2 * (1.0 + 1e-9);
    out.push_back(std::move(jj));
  }
  return out;
}

int run_limits(int argc, char** argv) {
  CLI::App app{
      "cell-sim-7545 limits: the speeds and accelerations the 7545's joints can follow under "
      "the master's PD law with the torque word kept inside its range, derived from the "
      "simulator's joint model, and whether the robot file's limits fit"};
  std::string robot = "config/robots/ibm7545.yaml";
  std::string sim = "config/sim-7545.yaml";
  std::string gateway = "config/gateway-ibm7545-dpr.yaml";
  double margin = kDefaultMargin;
  app.add_option("--robot", robot, "robot file whose limits are judged");
  app.add_option("--sim", sim, "simulator config: the joints' plants");
  app.add_option("--gateway", gateway, "dpr7545 gateway config: the PD gains and period");
  app.add_option("--margin", margin, "share of the torque word's range kept in reserve")
      ->check(CLI::Range(0.0, 0.95));
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e) == 0 ? 0 : 2;
  }
  for (std::string* path : {&robot, &sim, &gateway}) {
    *path = service::resolve_path(*path);
  }
  auto judged = judge_robot_limits(robot, sim, gateway, margin);
  if (!judged) {
    fmt::print(stderr, "cell-sim-7545 limits: {}\n", judged.error().message);
    return 1;
  }
  fmt::print(
      "Torque word kept within {:.0f} % of its range: |word - 0x800| <= {:.0f} DAC units.\n"
      "Worst case: simulate_follow (services/sim-7545/src/servo_limits.hpp).\n\n",
      100 * (1 - margin), judged->front().derived.usable_dac);
  fmt::print(
      "| joint | speed (file) | speed ceiling | accel derived at that speed | accel (file) "
      "| peak DAC at the file's limits | peak error [counts] | fits |\n"
      "|---|---|---|---|---|---|---|---|\n");
  bool all = true;
  for (const JointJudgement& j : *judged) {
    const double c = j.counts_per_unit;
    fmt::print(
        "| {} | {:.1f} {}/s | {:.1f} {}/s | {:.0f} {}/s^2 | {:.0f} {}/s^2 | {:.0f} | {:.1f} "
        "| {} |\n",
        j.joint, j.speed_counts_s / c, j.unit, j.derived.speed_ceiling_counts_s / c, j.unit,
        j.derived.accel_counts_s2 / c, j.unit, j.accel_counts_s2 / c, j.unit,
        j.at_file_limits.peak_dac, j.at_file_limits.peak_error_counts, j.ok ? "yes" : "NO");
    all = all && j.ok;
  }
  return all ? 0 : 1;
}

}  // namespace cell::sim7545
