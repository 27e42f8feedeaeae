// servo_bench: the gateway's 1 kHz DPR control loop (the dpr7545 driver, as the master)
// against cell-sim-7545 (the slave, a separate process), with and without SCHED_FIFO, beside a
// plain clock_nanosleep loop measured in the same run (the floor the OS gives). bench/README.md
// says what is measured and how to read it.
#include <sched.h>
#include <sys/mman.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <exception>
#include <filesystem>
#include <fstream>
#include <string>
#include <thread>
#include <vector>

#include <CLI/CLI.hpp>
#include <fmt/format.h>

#include "cell/common/log.hpp"
#include "cell/dpr7545/registers.hpp"
#include "cell/kinematics/robot_config.hpp"
#include "cell/process/child.hpp"
#include "dpr7545_driver.hpp"

#ifndef CELL_SOURCE_DIR
#define CELL_SOURCE_DIR "."
#endif

namespace {

using namespace cell;
using namespace std::chrono_literals;

constexpr int kExitFailed = 1;
constexpr int kExitUsage = 2;
constexpr double kPi = 3.14159265358979323846;

std::int64_t mono_ns() {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

void sleep_until_ns(std::int64_t t) {
  const timespec ts{static_cast<time_t>(t / 1'000'000'000), static_cast<long>(t % 1'000'000'000)};
  while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr) == EINTR) {
  }
}

struct Options {
  double duration_s = 60.0;
  bool quick = false;
  std::string modes = "both";  // both | fifo | other
  int rt_priority = 50;
  std::string source_dir = CELL_SOURCE_DIR;
  bool verbose = false;
};

/// Percentiles of a sample (microseconds).
struct Summary {
  std::size_t n = 0;
  double p50 = 0;
  double p99 = 0;
  double max = 0;
  std::size_t over_period = 0;  ///< samples above 1000 us (a whole sample period)
};

Summary summarize(std::vector<double> v) {
  Summary s;
  s.n = v.size();
  if (v.empty()) {
    return s;
  }
  std::sort(v.begin(), v.end());
  const auto at = [&](double q) {
    return v[std::min(v.size() - 1, static_cast<std::size_t>(q * static_cast<double>(v.size())))];
  };
  s.over_period = static_cast<std::size_t>(
      v.end() - std::upper_bound(v.begin(), v.end(), 1000.0));
  s.p50 = at(0.50);
  s.p99 = at(0.99);
  s.max = v.back();
  return s;
}

/// One mode's results.
struct Run {
  std::string mode;
  Summary jitter;         ///< |wake - scheduled| of the servo loop [us]
  Summary cycle;          ///< read + write duration [us]
  Summary floor;          ///< |wake - scheduled| of the plain clock_nanosleep loop [us]
  std::uint64_t cycles = 0;
  std::uint64_t exchanges = 0;
  std::uint64_t timeouts = 0;        ///< handshake waits that ran out of the budget
  std::uint64_t rephases = 0;        ///< control mode restarted for a bad phase
  std::uint64_t deadline_faults = 0;  ///< slave errors 0x1000 / 0x2000
  std::uint64_t other_faults = 0;
  std::uint64_t overruns = 0;        ///< cycles that ended after their period
  double max_following_counts = 0;
  double max_wait_us = 0;
  std::string error;
};

bool set_fifo(int priority) {
  sched_param param{};
  param.sched_priority = priority;
  return sched_setscheduler(0, SCHED_FIFO, &param) == 0;
}

void set_other() {
  sched_param param{};
  param.sched_priority = 0;
  (void)sched_setscheduler(0, SCHED_OTHER, &param);
}

/// The plain loop: clock_nanosleep to an absolute 1 ms grid, nothing else.
Summary floor_loop(double duration_s) {
  std::vector<double> jitter;
  jitter.reserve(static_cast<std::size_t>(duration_s * 1000) + 16);
  const std::int64_t period = 1'000'000;
  std::int64_t next = mono_ns() + period;
  const std::int64_t end = next + static_cast<std::int64_t>(duration_s * 1e9);
  while (next < end) {
    sleep_until_ns(next);
    jitter.push_back(static_cast<double>(std::llabs(mono_ns() - next)) * 1e-3);
    next += period;
  }
  return summarize(std::move(jitter));
}

std::string self_dir() {
  return std::filesystem::read_symlink("/proc/self/exe").parent_path().string();
}

/// One mode: a fresh simulator, the driver homed, then `duration_s` of a smooth motion on all
/// four joints at 75-100 % of their speed limits, cycle by cycle like the gateway's servo
/// thread; then the floor loop under the same policy.
Run run_mode(const Options& o, bool fifo, const kinematics::RobotModel& model) {
  Run r;
  r.mode = fifo ? fmt::format("SCHED_FIFO {}", o.rt_priority) : "SCHED_OTHER";
  const std::string shm = fmt::format("/cell-servo-bench-{}-{}", ::getpid(), fifo ? 1 : 0);
  const std::string dir = fmt::format("/tmp/cell-servo-bench-{}", ::getpid());
  std::filesystem::create_directories(dir);
  const std::string sim_config = dir + "/sim.yaml";
  std::ofstream(sim_config) << fmt::format(
      "service: {{id: sim.bench}}\nrobot_config: {}/config/robots/ibm7545.yaml\n"
      "shm_name: {}\nrealtime_priority: {}\ninitial_joints: [1, 1, 1, 1]\ndelay_s: 0.05\n"
      "state_rate_hz: 10\n",
      o.source_dir, shm, fifo ? o.rt_priority : 0);
  process::SpawnOptions spawn;
  spawn.executable = self_dir() + "/cell-sim-7545";
  spawn.args = {"--config", sim_config};
  // The simulator publishes its truth on DDS: keep it on a private domain and the loopback.
  spawn.env = {fmt::format("CELL_DOMAIN_ID={}", 150 + ::getpid() % 80),
               fmt::format("CELL_PARTITION=servo-bench-{}", ::getpid()),
               fmt::format("CYCLONEDDS_URI=file://{}/config/dds/loopback.xml", o.source_dir)};
  auto sim = process::Child::spawn(spawn);
  if (!sim) {
    r.error = "cannot start cell-sim-7545: " + sim.error().message;
    return r;
  }

  gateway::Dpr7545Options options;
  options.shm_name = shm;
  options.activate_timeout_s = 20;
  gateway::Dpr7545Driver driver(model, options, std::chrono::milliseconds(1),
                                [shm] { return dpr7545::open_shm(shm); });
  if (auto s = driver.on_configure(); !s) {
    r.error = s.error().message;
    return r;
  }
  if (auto s = driver.on_activate(); !s) {
    r.error = s.error().message;
    return r;
  }
  if (fifo && !set_fifo(o.rt_priority)) {
    r.error = "SCHED_FIFO refused (not root?)";
    driver.on_deactivate();
    driver.on_cleanup();
    return r;
  }

  const std::int64_t period = 1'000'000;
  gateway::JointState state;
  gateway::JointSetpoint sp;
  sp.q = gateway::JointVector::Zero(4);
  sp.qd = gateway::JointVector::Zero(4);
  // Homing (not measured): hold the setpoint at home.
  (void)driver.command(gateway::DriverCommand::kHome, {});
  std::int64_t next = mono_ns() + period;
  const std::int64_t homing_deadline = next + 60'000'000'000LL;
  bool homed = false;
  while (next < homing_deadline) {
    sleep_until_ns(next);
    const auto now = gateway::Clock::now();
    (void)driver.read(now, state);
    (void)driver.write(now, sp);
    next += period;
    if (state.homed && !state.busy) {
      homed = true;
      break;
    }
  }
  if (!homed) {
    r.error = "homing did not finish within 60 s";
    set_other();
    driver.on_deactivate();
    driver.on_cleanup();
    return r;
  }
  // The motion: q_j(t) = A_j (1 - cos(2 pi f t)), from rest at home, f = 0.4 Hz: peak speeds
  // 38 deg/s (J1, limit 45), 45 deg/s (J2, 50), 88 mm/s (Z, 100), 63 deg/s (R, 70).
  const double f = 0.4;
  const double w = 2 * kPi * f;
  const std::array<double, 4> amplitude = {15.0 * kPi / 180, 18.0 * kPi / 180, 35.0,
                                           25.0 * kPi / 180};
  std::vector<double> jitter;
  std::vector<double> cycle;
  const auto n = static_cast<std::size_t>(o.duration_s * 1000);
  jitter.reserve(n + 16);
  cycle.reserve(n + 16);
  // Control mode starts bumplessly from where homing left the arm: wait (not measured) until
  // the arm rests on the home setpoint.
  const std::int64_t settle_deadline = mono_ns() + 5'000'000'000LL;
  int settled = 0;
  while (settled < 50 && mono_ns() < settle_deadline) {
    sleep_until_ns(next);
    const auto now = gateway::Clock::now();
    if (driver.read(now, state) != gateway::CycleStatus::kFault) {
      (void)driver.write(now, sp);
    } else {
      (void)driver.command(gateway::DriverCommand::kReset, {});
    }
    bool rest = state.q.size() == 4;
    for (int j = 0; rest && j < 4; ++j) {
      rest = std::abs(state.q[j]) *
                 model.joints()[static_cast<std::size_t>(j)].counts_per_unit < 1.5;
    }
    settled = rest ? settled + 1 : 0;
    next += period;
  }
  const auto before = driver.counters();
  next = mono_ns() + period;
  std::int64_t t0 = next;  // start of the current profile
  const std::int64_t t_start = next;
  const std::int64_t end = next + static_cast<std::int64_t>(o.duration_s * 1e9);
  // After a fault, as the gateway would: hold the setpoint still, reset, let the arm settle,
  // bring the setpoint home along a half cosine (rest to rest), restart the profile.
  enum class Stage { kProfile, kHold, kReturn } stage = Stage::kProfile;
  std::int64_t stage_since = 0;
  std::array<double, 4> frozen{};
  bool faulted = false;
  constexpr double kReturnS = 1.5;
  while (next < end) {
    sleep_until_ns(next);
    const std::int64_t woke = mono_ns();
    jitter.push_back(static_cast<double>(std::llabs(woke - next)) * 1e-3);
    const auto now = gateway::Clock::now();
    if (stage == Stage::kProfile) {
      const double t = static_cast<double>(woke - t0) * 1e-9;
      for (int j = 0; j < 4; ++j) {
        sp.q[j] = amplitude[static_cast<std::size_t>(j)] * (1 - std::cos(w * t));
        sp.qd[j] = amplitude[static_cast<std::size_t>(j)] * w * std::sin(w * t);
      }
    } else if (stage == Stage::kReturn) {
      const double tau = std::min(1.0, static_cast<double>(woke - stage_since) * 1e-9 / kReturnS);
      for (int j = 0; j < 4; ++j) {
        const double a = frozen[static_cast<std::size_t>(j)];
        sp.q[j] = a * (1 + std::cos(kPi * tau)) / 2;
        sp.qd[j] = tau < 1.0 ? -a * kPi / (2 * kReturnS) * std::sin(kPi * tau) : 0.0;
      }
      if (tau >= 1.0) {
        stage = Stage::kProfile;
        t0 = woke;
      }
    } else {
      sp.qd.setZero();
    }
    const gateway::CycleStatus rs = driver.read(now, state);
    if (rs == gateway::CycleStatus::kFault) {
      if (!faulted) {  // count each fault once
        faulted = true;
        if ((state.fault_bits & dpr7545::kErrDeadlineMask) != 0) {
          ++r.deadline_faults;
        } else {
          ++r.other_faults;
        }
        if (o.verbose) {
          fmt::print(stderr, "{}: fault at {:.3f} s: {}\n", r.mode,
                     static_cast<double>(woke - t_start) * 1e-9,
                     driver.describe_faults(state.fault_bits));
        }
        if (stage != Stage::kHold) {
          for (int j = 0; j < 4; ++j) {
            frozen[static_cast<std::size_t>(j)] = sp.q[j];
          }
        }
        stage = Stage::kHold;
        stage_since = woke;
      } else if (woke - stage_since > 20 * period) {
        (void)driver.command(gateway::DriverCommand::kReset, {});
        faulted = false;
        stage_since = woke;
      }
    } else {
      (void)driver.write(now, sp);
      if (stage == Stage::kHold && woke - stage_since > 500 * period) {
        stage = Stage::kReturn;
        stage_since = woke;
      }
      if (rs == gateway::CycleStatus::kOk && stage == Stage::kProfile && state.q.size() == 4) {
        for (int j = 0; j < 4; ++j) {
          const double counts = std::abs(state.q[j] - sp.q[j]) *
                                model.joints()[static_cast<std::size_t>(j)].counts_per_unit;
          r.max_following_counts = std::max(r.max_following_counts, counts);
        }
      }
    }
    const std::int64_t done = mono_ns();
    cycle.push_back(static_cast<double>(done - woke) * 1e-3);
    ++r.cycles;
    next += period;
    if (done > next) {
      ++r.overruns;
      next = done + period - (done - next) % period;  // as the gateway: skip, do not burst
    }
  }
  const auto after = driver.counters();
  r.exchanges = after.periods - before.periods;
  r.timeouts = after.handshake_timeouts - before.handshake_timeouts;
  r.rephases = after.rephases - before.rephases;
  r.max_wait_us = static_cast<double>(after.max_wait_ns) * 1e-3;
  r.jitter = summarize(std::move(jitter));
  r.cycle = summarize(std::move(cycle));
  driver.on_deactivate();
  driver.on_cleanup();
  r.floor = floor_loop(o.duration_s);
  set_other();
  (void)sim->stop(10s);
  std::error_code ec;
  std::filesystem::remove_all(dir, ec);
  return r;
}

void print(const std::vector<Run>& runs, const Options& o) {
  fmt::print("\nservo_bench: the dpr7545 master loop against cell-sim-7545, 1 kHz, {:.0f} s per "
             "mode\n\n",
             o.duration_s);
  fmt::print("| loop | policy | cycles (exchanges) | wake jitter p50 / p99 / max [us] | wakes > "
             "1 ms late | read+write p50 / p99 / max [us] | deadline misses 0x1000/0x2000 | "
             "handshake timeouts | other faults | rephases | max following error [counts] |\n");
  fmt::print("|---|---|---|---|---|---|---|---|---|---|---|\n");
  fmt::print("| thesis: 486 PC master under DOS, busy-waiting on the DPR | none (DOS) | - | not "
             "reported | - | not reported | not reported | - | - | - | not reported |\n");
  for (const Run& r : runs) {
    if (!r.error.empty()) {
      fmt::print("| dpr7545 driver + cell-sim-7545 | {} | failed: {} |\n", r.mode, r.error);
      continue;
    }
    fmt::print("| dpr7545 driver + cell-sim-7545 | {} | {} ({}) | {:.1f} / {:.1f} / {:.1f} | {} | "
               "{:.1f} / {:.1f} / {:.1f} | {} | {} | {} | {} | {:.1f} |\n",
               r.mode, r.cycles, r.exchanges, r.jitter.p50, r.jitter.p99, r.jitter.max,
               r.jitter.over_period, r.cycle.p50, r.cycle.p99, r.cycle.max, r.deadline_faults,
               r.timeouts, r.other_faults, r.rephases, r.max_following_counts);
    fmt::print("| clock_nanosleep floor (same run) | {} | {} | {:.1f} / {:.1f} / {:.1f} | {} | - | "
               "- | - | - | - | - |\n",
               r.mode, r.floor.n, r.floor.p50, r.floor.p99, r.floor.max, r.floor.over_period);
  }
  fmt::print("\nSample period 1000 us in every row (the thesis's). A deadline miss is a slave "
             "error 0x1000/0x2000 (the run resets and goes on); a handshake timeout is a cycle "
             "whose wait for the slave ran out of its 900 us budget; a wake more than 1 ms late "
             "is a miss whatever the loop does. The thesis gives no timing figures for its "
             "loop.\n");
}

}  // namespace

static int main_body(int argc, char** argv) {
  Options o;
  CLI::App app{"servo_bench: the 7545 DPR control loop against cell-sim-7545 (bench/README.md)"};
  app.add_option("--duration", o.duration_s, "seconds of control per mode (default 60)");
  app.add_flag("--quick", o.quick, "3 s per mode (ctest smoke run)");
  app.add_option("--modes", o.modes, "both | fifo | other")
      ->check(CLI::IsMember({"both", "fifo", "other"}));
  app.add_option("--rt-priority", o.rt_priority, "SCHED_FIFO priority of the fifo mode (50)");
  app.add_option("--source-dir", o.source_dir, "the checkout (config/robots, config/dds)");
  app.add_flag("--verbose", o.verbose, "print every fault with its time and meaning");
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e) == 0 ? 0 : kExitUsage;
  }
  if (o.quick) {
    o.duration_s = 3.0;
  }
  log::init("servo_bench", log::Level::kWarn);
  auto model = kinematics::load_robot(o.source_dir + "/config/robots/ibm7545.yaml");
  if (!model) {
    fmt::print(stderr, "servo_bench: {}\n", model.error().message);
    return kExitFailed;
  }
  std::vector<Run> runs;
  const bool can_fifo = ::geteuid() == 0;
  if (o.modes != "fifo") {
    fmt::print(stderr, "servo_bench: SCHED_OTHER, {:.0f} s...\n", o.duration_s);
    runs.push_back(run_mode(o, false, *model));
  }
  if (o.modes != "other") {
    if (can_fifo) {
      fmt::print(stderr, "servo_bench: SCHED_FIFO {}, {:.0f} s...\n", o.rt_priority, o.duration_s);
      runs.push_back(run_mode(o, true, *model));
    } else {
      Run r;
      r.mode = "SCHED_FIFO";
      r.error = "not permitted (run as root for this mode)";
      runs.push_back(r);
    }
  }
  print(runs, o);
  for (const Run& r : runs) {
    if (!r.error.empty() && r.error.find("not permitted") == std::string::npos) {
      return kExitFailed;
    }
  }
  return 0;
}

// Nothing escapes main: an exception is printed and fails the run.
int main(int argc, char** argv) {
  try {
    return main_body(argc, argv);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "servo_bench: %s\n", e.what());
  } catch (...) {
    std::fprintf(stderr, "servo_bench: an exception not derived from std::exception\n");
  }
  return 1;
}
