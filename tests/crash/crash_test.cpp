// Issue 11, "killed services": the simulated cell run under the launcher (`cell up`, which
// restarts a service that dies), a table job of six ICs, and kill -9 of each service the job
// needs twice, in turn, while it runs: task, motion, camera.ibm7545_eye, vision, calibration on
// the ideal 7545 (the gateway: see the test's comment). The job must
// succeed, every IC must lie in its own slot (cell-sim-world's truth), every IC must have been
// grasped exactly once (the world's log), and the journal must hold the job once.
//
// The simulators (sim-world, sim-7545) are left alone: they are the physical world (the table
// with its parts, the arm and its slave board). Killing them would not be a software crash the
// cell could survive but the world itself vanishing (parts gone, the arm's joints reset).
#include <unistd.h>

#include <chrono>
#include <csignal>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <random>
#include <set>
#include <string>
#include <thread>
#include <vector>

#include <fmt/format.h>
#include <fmt/ranges.h>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "cell/calibration/camera_calibration.hpp"
#include "cell/calibration/store.hpp"
#include "cell/render/camera_file.hpp"
#include "cell/testing/env.hpp"

namespace cell::crash_test {
namespace {

using ::cell::testing::eventually;
using ::cell::testing::ToolRun;
using nlohmann::json;
using namespace std::chrono_literals;
using SteadyClock = std::chrono::steady_clock;

constexpr std::size_t kParts = 6;
constexpr double kSlotTolMm = 0.5;
constexpr double kSlotTolDeg = 1.0;

std::string read_text(const std::string& path) {
  std::ifstream f(path);
  return std::string((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
}

std::string replaced(std::string text, const std::string& from, const std::string& to) {
  const auto at = text.find(from);
  EXPECT_NE(at, std::string::npos) << "'" << from << "' not in the shipped config";
  if (at != std::string::npos) {
    text.replace(at, from.size(), to);
  }
  return text;
}

double wrap_deg(double d, double period) {
  d = std::fmod(d, period);
  if (d > period / 2) {
    d -= period;
  } else if (d < -period / 2) {
    d += period;
  }
  return d;
}

/// One kill and what followed.
struct Kill {
  std::string service;
  double at_s = 0;             ///< since the job was submitted
  int old_pid = 0;
  double restart_delay_s = -1; ///< kill -> the launcher shows a new pid running; -1: never
  std::string step_at_kill;
  int steps_at_kill = 0;
  int steps_after = 0;  ///< the job's journaled steps once it progressed again
  std::string state_after;
};

class CrashTest : public ::testing::Test {
 protected:
  CrashTest()
      : domain_(cell::testing::test_domain_id()), partition_(cell::testing::unique_partition()) {
    std::string pattern = "/tmp/cell-crash-test-XXXXXX";
    dir_ = mkdtemp(pattern.data()) != nullptr ? pattern : "/tmp/cell-crash-test-fallback";
    env_ = cell::testing::bus_env(domain_, partition_);
    env_.push_back("CELL_HOME=" + cell::testing::source_dir());
  }

  ~CrashTest() override {
    if (up_) {
      const ToolRun down = cell::testing::run_tool("cell", {"down", "--profile", profile_}, env_,
                                                   60s);
      EXPECT_EQ(down.exit.code, 0) << down.output;
    }
    if (HasFailure()) {
      for (const char* name : {"task", "motion", "gateway.ibm7545", "sim-7545", "sim-world"}) {
        const std::string log = read_text(dir_ + "/run/logs/" + name + ".log");
        std::printf("---- %s (last 6000 chars)\n%s\n", name,
                    log.substr(log.size() > 6000 ? log.size() - 6000 : 0).c_str());
      }
    } else {
      std::error_code ec;
      std::filesystem::remove_all(dir_, ec);
    }
  }

  std::string write(const std::string& name, const std::string& text) {
    std::string path = dir_ + "/" + name;
    std::ofstream(path) << text;
    return path;
  }

  std::string shipped(const std::string& config) {
    return read_text(cell::testing::source_dir() + "/" + config);
  }

  /// The profile: deploy/local.yaml's services the table job needs, configs in the temp dir
  /// (journal, calibration store). `dpr`: the 7545 as on the real cell, its slave board
  /// simulated (cell-sim-7545, a private shared-memory name so a concurrent 7545 test never
  /// shares it) and the DPR driver at the thesis's 1 ms sample period, as shipped; otherwise
  /// the ideal driver (tests/task, tests/netlab).
  void write_profile(bool dpr) {
    std::string robots;
    if (dpr) {
      const std::string shm = fmt::format("/cell-dpr7545-crash-{}", ::getpid());
      write("sim-7545.yaml", replaced(shipped("config/sim-7545.yaml"), "shm_name: /cell-dpr7545",
                                      "shm_name: " + shm));
      std::string gw = replaced(shipped("config/gateway-ibm7545-dpr.yaml"),
                                "shm_name: /cell-dpr7545", "shm_name: " + shm);
      write("gateway.yaml", gw);
      robots = "  - {name: sim-7545, exec: cell-sim-7545, config: " + dir_ + "/sim-7545.yaml}\n";
    } else {
      // The ideal driver: the DPR handshake's deadline misses on a loaded machine ("loop
      // late") would stall the job for an operator reset; that is tests/gateway_7545's subject.
      write("gateway.yaml",
            "service: {id: gateway.ibm7545}\n"
            "robot_config: config/robots/ibm7545.yaml\n"
            "supervisors: [task]\n"
            "driver: {kind: ideal, initial_joints: [45, 105, 0, 0], gripper_time_s: 0.2}\n");
    }
    write("sim-world.yaml",
          "service: {id: sim-world}\nscene: " + write("scene.yaml", R"(name: scatter_table
table: {height_mm: 750, x_mm: [-600, 600], y_mm: [-150, 750], reflectance: 0.9}
min_separation_mm: 5.7
scatter:
  - {count: 0, classes: [ic_7x30, ic_6x19, dip14, dip8], x_mm: [88, 182], y_mm: [452, 548],
     yaw_deg: [-180, 180], min_separation_mm: 6.0, seed: 1994}
)") + "\nrobots:\n  - {id: ibm7545, xyz_mm: [0, 0, 981.51]}\n");
    write("calibration.yaml", replaced(shipped("config/calibration.yaml"),
                                       "store_dir: run/calibrations", "store_dir: " + dir_ + "/store"));
    write("task.yaml", replaced(shipped("config/task.yaml"), "journal: run/task/journal.sqlite",
                                "journal: " + dir_ + "/journal.sqlite"));
    const std::string src = cell::testing::source_dir();
    profile_ = write("crash.yaml", fmt::format(R"(profile: crash
bus: {{domain_id: {}, partition: {}, cyclonedds_config: config/dds/loopback.xml}}
run_dir: {}/run
restart: {{backoff_initial_s: 0.5, backoff_max_s: 4, stable_after_s: 5}}
stop_grace_s: 5
services:
{robots}  - {{name: gateway.ibm7545, exec: cell-gateway, config: {d}/gateway.yaml}}
  - {{name: motion, exec: cell-motion, config: {s}/config/motion.yaml}}
  - {{name: sim-world, exec: cell-sim-world, config: {d}/sim-world.yaml}}
  - {{name: camera.ibm7545_eye, exec: cell-camera, config: {s}/config/camera-ibm7545.yaml}}
  - {{name: vision, exec: cell-vision, config: {s}/config/vision.yaml}}
  - {{name: calibration, exec: cell-calibration, config: {d}/calibration.yaml}}
  - {{name: task, exec: cell-task, config: {d}/task.yaml}}
)",
                                               domain_, partition_, dir_, fmt::arg("d", dir_),
                                               fmt::arg("s", src), fmt::arg("robots", robots)));
  }

  /// The simulator's truth as the eye-in-hand camera's calibration, in the store before the
  /// calibration service starts (the subject here is not calibration; tests/task does that).
  void store_truth_calibration() {
    auto camera =
        render::load_camera(cell::testing::source_dir() + "/config/cameras/ibm7545_eye.yaml");
    ASSERT_TRUE(camera) << camera.error().message;
    render::CameraDescription truth = *camera;
    truth.nominal = camera->truth;
    auto c = calibration::nominal_calibration(truth, "", Eigen::Isometry3d::Identity(), -231.51);
    ASSERT_TRUE(c) << c.error().message;
    c->source = "the simulator's truth (test)";
    calibration::CalibrationStore store(dir_ + "/store");
    auto stored = store.add_camera(*c);
    ASSERT_TRUE(stored) << stored.error().message;
  }

  ToolRun cellctl(std::vector<std::string> args, std::chrono::milliseconds timeout = 30s) {
    args.insert(args.begin(), {"--timeout", "5"});
    return cell::testing::run_tool("cellctl", args, env_, timeout);
  }

  static json parsed(const ToolRun& run) {
    const auto begin = run.output.find_first_of("{[");
    return begin == std::string::npos ? json()
                                      : json::parse(run.output.substr(begin), nullptr, false);
  }

  json job(const std::string& id) {
    json j = parsed(cellctl({"--json", "job", id}));
    return j.is_object() ? j : json::object();
  }

  /// The launcher's view of one service (status.json).
  json service_status(const std::string& name) {
    const json doc = json::parse(read_text(dir_ + "/run/status.json"), nullptr, false);
    if (doc.is_object() && doc.contains("services")) {
      for (const json& s : doc["services"]) {
        if (s.value("name", "") == name) {
          return s;
        }
      }
    }
    return json::object();
  }

  void run_with_kills(bool dpr, const std::vector<std::string>& order, const std::string& label,
                      int rounds = 2, std::size_t part_count = kParts);

  std::uint32_t domain_;
  std::string partition_;
  std::string dir_;
  std::string profile_;
  std::vector<std::string> env_;
  bool up_ = false;
};

/// Runs a table job under the launcher and kill -9s each of `order` `rounds` times, in turn,
/// while it runs, each kill at a random moment (0-2 s after the previous one's successor let
/// the job progress); checks that nothing was lost or done twice. `label` names the scenario's
/// rows.
void CrashTest::run_with_kills(bool dpr, const std::vector<std::string>& order,
                               const std::string& label, int rounds, std::size_t part_count) {
  write_profile(dpr);
  store_truth_calibration();
  ASSERT_FALSE(HasFailure());
  const ToolRun up =
      cell::testing::run_tool("cell", {"up", "--profile", profile_, "--detach"}, env_, 60s);
  ASSERT_EQ(up.exit.code, 0) << up.output;
  up_ = true;
  ASSERT_TRUE(eventually([&] { return cellctl({"jobs"}).exit.code == 0; }, 60s));
  ASSERT_TRUE(eventually(
      [&] {
        const ToolRun show = cellctl({"--json", "calibration", "show", "--camera", "ibm7545_eye"});
        return show.exit.code == 0 && show.output.find("simulator's truth") != std::string::npos;
      },
      60s));
  ToolRun r = cellctl({"world", "scatter", "--count", std::to_string(part_count), "--seed", "7"});
  ASSERT_EQ(r.exit.code, 0) << r.output;
  const json before = parsed(cellctl({"--json", "world", "parts"}));
  ASSERT_EQ(before.value("parts", json::array()).size(), part_count);

  r = cellctl({"submit", cell::testing::source_dir() + "/config/jobs/table_ics.yaml", "--id",
               "crash-1"});
  ASSERT_EQ(r.exit.code, 0) << r.output;
  const auto submitted = SteadyClock::now();
  const auto since = [&] {
    return std::chrono::duration<double>(SteadyClock::now() - submitted).count();
  };
  // Let it start (the 7545 homes first) before the first kill.
  ASSERT_TRUE(eventually([&] { return job("crash-1").value("steps", 0) >= 2; }, 120s));

  std::vector<Kill> kills;
  bool ended_early = false;
  const auto seed = static_cast<std::uint32_t>(SteadyClock::now().time_since_epoch().count());
  std::printf("kill moments: seed %u\n", seed);
  std::mt19937 random(seed);
  std::uniform_real_distribution<double> jitter_s(0.0, 2.0);
  for (int round = 0; round < rounds && !ended_early; ++round) {
    for (const std::string& name : order) {
      std::this_thread::sleep_for(std::chrono::duration<double>(jitter_s(random)));
      Kill k;
      k.service = name;
      const json st = service_status(name);
      k.old_pid = st.value("pid", 0);
      ASSERT_GT(k.old_pid, 0) << name << " has no pid in status.json: " << st.dump();
      const json before_kill = job("crash-1");
      k.step_at_kill = before_kill.value("step", "");
      k.steps_at_kill = before_kill.value("steps", 0);
      const std::string state = before_kill.value("state", "");
      if (state == "succeeded" || state == "failed" || state == "cancelled") {
        ended_early = true;
        break;
      }
      if (name == "motion") {
        // The motion service dies while the arm runs one of its pick trajectories (seen on
        // the robot's state): its successor takes the request again, the gateway is busy with
        // the first run, and the job must verify what that run did, not redo it. Without this
        // wait the kill landed there only by chance (a CI run once: a pick redone from above
        // the held part, the part reported unreachable, two parts in one slot).
        (void)eventually(
            [&] {
              const json robot =
                  parsed(cellctl({"--json", "robot", "state", "--robot", "ibm7545"}));
              return robot.is_object() && robot.value("moving", false) &&
                     robot.value("trajectory_id", "").find("/pick") != std::string::npos;
            },
            60s);
      }
      k.at_s = since();
      const auto killed = SteadyClock::now();
      ASSERT_EQ(::kill(k.old_pid, SIGKILL), 0) << name;
      if (eventually(
              [&] {
                const json s = service_status(name);
                return s.value("pid", 0) > 0 && s.value("pid", 0) != k.old_pid &&
                       s.value("state", "") != "backoff";
              },
              30s)) {
        k.restart_delay_s = std::chrono::duration<double>(SteadyClock::now() - killed).count();
      }
      // Spaced so the job keeps progressing: the next kill only once it journaled a step
      // more (or ended), and at least 4 s after this one; `rounds` kills of one service come
      // at least 5.5 s after its restart, so that each finds the launcher's back-off reset
      // (stable_after_s 5 in the profile: each restart within 0.5 s, as after a lone crash;
      // kills 5 s apart grew it to 4 s, longer than the task waits for a robot's state).
      const double settle_s = rounds > 2 ? std::max(0.0, k.restart_delay_s) + 5.5 : 4.0;
      (void)eventually(
          [&] {
            const json j = job("crash-1");
            k.steps_after = j.value("steps", 0);
            k.state_after = j.value("state", "");
            return (k.steps_after > k.steps_at_kill &&
                    std::chrono::duration<double>(SteadyClock::now() - killed).count() >
                        settle_s) ||
                   k.state_after == "succeeded" || k.state_after == "failed";
          },
          120s);
      kills.push_back(k);
    }
  }
  const json status = [&] {
    json last;
    (void)eventually(
        [&] {
          last = job("crash-1");
          const std::string s = last.value("state", "");
          return s == "succeeded" || s == "failed" || s == "cancelled";
        },
        400s);
    return last;
  }();
  const double job_s = since();

  std::printf("\n%-20s %8s %10s %7s %7s  %s\n", "killed", "at [s]", "restart[s]", "steps",
              "after", "job step at the kill");
  for (const Kill& k : kills) {
    std::printf("%-20s %8.1f %10.2f %7d %7d  %s\n", k.service.c_str(), k.at_s, k.restart_delay_s,
                k.steps_at_kill, k.steps_after, k.step_at_kill.c_str());
  }
  std::printf("job: %s after %.1f s, %d parts placed, counters %s\n",
              status.value("state", "?").c_str(), job_s, status.value("parts_done", 0),
              status.value("counters", json::object()).dump().c_str());

  // Every service killed twice while the job ran, and restarted by the launcher each time.
  EXPECT_FALSE(ended_early) << "the job ended before every kill was made";
  std::map<std::string, int> killed_count;
  for (const Kill& k : kills) {
    ++killed_count[k.service];
    EXPECT_GE(k.restart_delay_s, 0.0) << k.service << " was not restarted within 30 s";
  }
  for (const std::string& name : order) {
    EXPECT_EQ(killed_count[name], rounds) << name;
    EXPECT_GE(service_status(name).value("restarts", 0), rounds) << service_status(name).dump();
  }
  // The job: succeeded, every part placed once.
  EXPECT_EQ(status.value("state", ""), "succeeded") << status.dump(2);
  EXPECT_EQ(status.value("parts_done", 0), static_cast<int>(part_count)) << status.dump(2);
  EXPECT_EQ(status["counters"].value("placed", 0), static_cast<int>(part_count)) << status.dump(2);
  // The world's truth: every IC in its own slot.
  const json parts = parsed(cellctl({"--json", "world", "parts"})).value("parts", json::array());
  ASSERT_EQ(parts.size(), part_count);
  std::vector<Eigen::Vector2d> slots;
  for (int row = 0; row < 5; ++row) {
    for (int col = 0; col < 3; ++col) {
      slots.emplace_back(-310.0 + 30.0 * col, 250.0 + 30.0 * row);
    }
  }
  std::set<std::size_t> used;
  double worst_mm = 0;
  for (const json& p : parts) {
    const Eigen::Vector2d at(p["pose"]["x_mm"].get<double>(), p["pose"]["y_mm"].get<double>());
    std::size_t best = 0;
    double best_d = 1e9;
    for (std::size_t i = 0; i < slots.size(); ++i) {
      if ((slots[i] - at).norm() < best_d) {
        best_d = (slots[i] - at).norm();
        best = i;
      }
    }
    EXPECT_LT(best_d, kSlotTolMm) << p.dump();
    EXPECT_TRUE(used.insert(best).second) << "two parts in slot " << best << ": " << p.dump();
    EXPECT_LT(std::abs(wrap_deg(p["pose"]["yaw_deg"].get<double>() - 90.0, 180.0)), kSlotTolDeg)
        << p.dump();
    EXPECT_EQ(p["support"], "table") << p.dump();
    worst_mm = std::max(worst_mm, best_d);
  }
  // Nothing done twice: the world attached each part to the gripper exactly once.
  const std::string world_log = read_text(dir_ + "/run/logs/sim-world.log");
  std::map<std::string, int> grasps;
  std::size_t lines = 0;
  for (std::size_t at = world_log.find("event=attached"); at != std::string::npos;
       at = world_log.find("event=attached", at + 1)) {
    const auto eol = world_log.find('\n', at);
    const std::string line = world_log.substr(at, eol == std::string::npos ? eol : eol - at);
    const auto p = line.find("part=");
    ++grasps[p == std::string::npos ? "?" : line.substr(p, line.find(' ', p) - p)];
    ++lines;
  }
  EXPECT_EQ(lines, part_count) << "grasps that took a part, by part: " << json(grasps).dump();
  for (const auto& [part, n] : grasps) {
    EXPECT_EQ(n, 1) << part << " was grasped " << n << " times";
  }
  // The board homed once, for the job's start: every restarted gateway re-attached to it.
  if (dpr) {
    const std::string board_log = read_text(dir_ + "/run/logs/sim-7545.log");
    std::size_t homings = 0;
    for (auto at = board_log.find("msg=\"homed:"); at != std::string::npos;
         at = board_log.find("msg=\"homed:", at + 1)) {
      ++homings;
    }
    EXPECT_EQ(homings, 1U) << "the board was homed again after a gateway restart";
    // The simulator's stalls each gateway waited out (reported, not judged).
    const std::string gateway_log = read_text(dir_ + "/run/logs/gateway.ibm7545.log");
    std::size_t stall_lines = 0;
    for (auto at = gateway_log.find("simulated board stalled"); at != std::string::npos;
         at = gateway_log.find("simulated board stalled", at + 1)) {
      ++stall_lines;
    }
    std::printf("the gateways reported %zu episodes of the simulated board's stalls\n",
                stall_lines);
  }
  // One job, one id in the journal.
  int jobs_with_id = 0;
  for (const json& j : parsed(cellctl({"--json", "jobs"}))) {
    jobs_with_id += j.value("job_id", "") == "crash-1" ? 1 : 0;
  }
  EXPECT_EQ(jobs_with_id, 1);

  if (const char* out = std::getenv("CELL_RELIABILITY_OUT"); out != nullptr && *out != '\0') {
    std::filesystem::create_directories(out);
    std::ofstream f(std::string(out) + "/crash.jsonl", std::ios::app);
    for (const Kill& k : kills) {
      f << json{{"suite", "crash"},
                {"scenario", "kill -9 " + k.service + " during a table job (" + label + ")"},
                {"load", fmt::format("table job crash-1, {} ICs, under cell up", part_count)},
                {"faults", fmt::format("SIGKILL {} at {:.1f} s (pid {}), during '{}'", k.service,
                                       k.at_s, k.old_pid, k.step_at_kill)},
                {"outcome", fmt::format("{}: restarted after {:.2f} s; job {} ({} -> {} steps)",
                                        k.restart_delay_s >= 0 ? "passed" : "failed",
                                        k.restart_delay_s, k.state_after, k.steps_at_kill,
                                        k.steps_after)},
                {"lost", HasFailure() ? "see the job's result row" : "nothing lost"},
                {"duration_s", 0.0}}
                  .dump()
        << "\n";
    }
    f << json{{"suite", "crash"},
              {"scenario", fmt::format("table job through {} kills, each service twice ({})",
                                       kills.size(), label)},
              {"load", fmt::format("table job, {} ICs, under cell up", part_count)},
              {"faults", fmt::format("{} kill -9 ({}): {}", kills.size(), label,
                                     fmt::join(order, ", "))},
              {"outcome", fmt::format("{}: job {}, {} of {} placed, worst slot error {:.3f} mm, "
                                      "{} grasps",
                                      HasFailure() ? "failed" : "passed",
                                      status.value("state", "?"), status.value("parts_done", 0),
                                      part_count, worst_mm, lines)},
              {"lost", HasFailure() ? "see the test's failures" : "nothing lost, nothing twice"},
              {"duration_s", job_s}}
                .dump()
      << "\n";
  }
}


// Every service the job needs except the robot's gateway, on the ideal 7545. The ideal driver
// is the arm itself: killing its gateway would make the arm vanish (the next test kills the
// gateway of the 7545 on its DPR board, whose arm outlives its master).
TEST_F(CrashTest, EveryServiceKilledTwiceDuringATableJobLosesNothingAndDoesNothingTwice) {
  // Ten ICs: with the 7545's derived accelerations (faster than the placeholders were) a job of
  // six ended before the tenth kill.
  run_with_kills(false, {"motion", "camera.ibm7545_eye", "vision", "task", "calibration"},
                 "ideal 7545", 2, 10);
}

// The 7545 on its simulated DPR board at the thesis's 1 kHz, its gateway (the master) killed
// ten times at random moments of a table job of ten ICs: each successor re-attaches to the board (its
// homing record, services/gateway/src/homing_record.hpp), holds the arm where the dead master
// left it, and the job goes on: every part in its slot, none grasped twice, the board homed
// only once.
TEST_F(CrashTest, TheDprGatewayKilledTenTimesDuringATableJobReattachesAndLosesNothing) {
  run_with_kills(true, {"gateway.ibm7545"}, "7545 on its DPR board", 10, 10);
}

}  // namespace
}  // namespace cell::crash_test
