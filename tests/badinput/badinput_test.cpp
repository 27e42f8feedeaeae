// Bad input on the bus (issue 11): the whole simulated cell of deploy/local.yaml, started by
// the launcher on a private domain/partition from a temporary copy of the profile, is flooded
// by cell-flood with malformed samples on every topic a service reads. Afterwards no service
// may have died or restarted, every heartbeat serves, every service answers a ping, a valid
// job gets an answer within seconds, a bad job a rejection naming its problem, and no robot
// moved (the flood's trajectories and commands for real robots are all out of range).
//
// CELL_FLOOD_SECONDS sets the flood's length (default 30); CELL_RELIABILITY_OUT a directory
// where one JSON row per scenario is appended to badinput.jsonl.
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <filesystem>
#include <fstream>
#include <map>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include <fmt/format.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>
#include <yaml-cpp/yaml.h>

#include "cell/bus/participant.hpp"
#include "cell/bus/reader.hpp"
#include "cell/bus/topic.hpp"
#include "cell/bus/topics.hpp"
#include "cell/bus/view.hpp"
#include "cell/process/child.hpp"
#include "cell/testing/env.hpp"

namespace cell {
namespace {

using ::cell::testing::eventually;
using ::cell::testing::ToolRun;
using nlohmann::json;
using ::testing::HasSubstr;
using namespace std::chrono_literals;
using Clock = std::chrono::steady_clock;

/// A robot that did not move holds its joints to this (rad or mm): the 7545's PD servo and
/// the Excalibur's 0.3 deg controller accuracy settle far inside it.
constexpr double kStillTol = 2e-3;

std::string read_file(const std::string& path) {
  std::ifstream in(path);
  std::stringstream buffer;
  buffer << in.rdbuf();
  return buffer.str();
}

double seconds_since(Clock::time_point t0) {
  return std::chrono::duration<double>(Clock::now() - t0).count();
}

/// The JSON a cellctl --json run printed (from the first '{' or '[').
json parsed(const std::string& output) {
  const auto begin = output.find_first_of("{[");
  return begin == std::string::npos ? json() : json::parse(output.substr(begin), nullptr, false);
}

class BadInputTest : public ::testing::Test {
 protected:
  BadInputTest()
      : domain_(cell::testing::test_domain_id()), partition_(cell::testing::unique_partition()) {
    prctl(PR_SET_CHILD_SUBREAPER, 1);  // the detached supervisor and its services reap to us
    if (std::getenv("CELL_BIN_DIR") == nullptr) {
      const auto self = std::filesystem::read_symlink("/proc/self/exe");
      setenv("CELL_BIN_DIR", self.parent_path().c_str(), 1);
    }
    if (std::getenv("CYCLONEDDS_URI") == nullptr) {
      setenv("CYCLONEDDS_URI",
             ("file://" + cell::testing::source_dir() + "/config/dds/loopback.xml").c_str(), 1);
    }
    std::string pattern = "/tmp/cell-badinput-XXXXXX";
    dir_ = mkdtemp(pattern.data()) != nullptr ? pattern : "/tmp/cell-badinput-fallback";
    run_dir_ = dir_ + "/run";
    profile_ = dir_ + "/local.yaml";
    shm_name_ = "/cell-dpr7545-" + partition_;
    env_ = cell::testing::bus_env(domain_, partition_);
    env_.push_back("CELL_HOME=" + cell::testing::source_dir());
  }

  ~BadInputTest() override {
    try {  // a destructor must not throw: a failed cleanup is reported, not fatal
      if (std::filesystem::exists(run_dir_ + "/cell.pid")) {
        (void)cell::testing::run_tool("cell", {"down", "--profile", profile_, "--timeout", "20"},
                                      env_, 40s);
      }
      for (const auto& [name, pid] : pids()) {  // nothing may outlive the test
        if (process::pid_alive(pid)) {
          kill(-pid, SIGKILL);
          kill(pid, SIGKILL);
        }
      }
      while (waitpid(-1, nullptr, WNOHANG) > 0) {
      }
      if (HasFailure()) {
        std::error_code ec;
        for (const auto& entry : std::filesystem::directory_iterator(run_dir_ + "/logs", ec)) {
          const std::string text = read_file(entry.path());
          std::printf("---- %s (last 3000 chars)\n%s\n", entry.path().filename().c_str(),
                      text.substr(text.size() > 3000 ? text.size() - 3000 : 0).c_str());
        }
      }
      std::error_code ec;
      std::filesystem::remove(std::filesystem::path("/dev/shm") / shm_name_.substr(1), ec);
      if (const char* keep = std::getenv("CELL_BADINPUT_KEEP"); keep != nullptr && *keep == '1') {
        std::printf("kept %s (CELL_BADINPUT_KEEP=1)\n", dir_.c_str());
      } else {
        std::filesystem::remove_all(dir_, ec);
      }
    } catch (const std::exception& e) {
      std::fprintf(stderr, "BadInputTest cleanup: %s\n", e.what());
    }
  }

  /// A shipped config with each `from` text replaced by its `to` (each must occur).
  std::string patched(const std::string& config,
                      const std::vector<std::pair<std::string, std::string>>& edits) {
    std::string text = read_file(cell::testing::source_dir() + "/" + config);
    for (const auto& [from, to] : edits) {
      const auto at = text.find(from);
      EXPECT_NE(at, std::string::npos) << config << ": no '" << from << "' to replace";
      if (at != std::string::npos) {
        text.replace(at, from.size(), to);
      }
    }
    std::string path = dir_ + "/" + std::filesystem::path(config).filename().string();
    std::ofstream(path) << text;
    return path;
  }

  /// deploy/local.yaml with its run dir in the test's directory and every shared resource
  /// (DPR segment, pty, calibration store, journal, HTTP port) private to this test.
  void write_profile() {
    std::map<std::string, std::string> configs{
        {"config/sim-7545.yaml", patched("config/sim-7545.yaml",
                                         {{"shm_name: /cell-dpr7545", "shm_name: " + shm_name_}})},
        {"config/gateway-ibm7545-dpr.yaml",
         patched("config/gateway-ibm7545-dpr.yaml",
                 {{"shm_name: /cell-dpr7545", "shm_name: " + shm_name_}})},
        {"config/sim-excalibur.yaml",
         patched("config/sim-excalibur.yaml",
                 {{"link_path: run/excalibur.pty", "link_path: " + dir_ + "/excalibur.pty"},
                  {"control_file: run/excalibur-noise.yaml",
                   "control_file: " + dir_ + "/excalibur-noise.yaml"}})},
        {"config/gateway-excalibur-serial.yaml",
         patched("config/gateway-excalibur-serial.yaml",
                 {{"device: run/excalibur.pty", "device: " + dir_ + "/excalibur.pty"}})},
        {"config/calibration.yaml",
         patched("config/calibration.yaml",
                 {{"store_dir: run/calibrations", "store_dir: " + dir_ + "/calibrations"}})},
        {"config/task.yaml",
         patched("config/task.yaml", {{"journal: run/task/journal.sqlite",
                                       "journal: " + dir_ + "/task/journal.sqlite"}})},
        {"config/monitor.yaml", patched("config/monitor.yaml", {{"port: 8080", "port: 0"}})},
    };
    const std::string original = cell::testing::source_dir() + "/deploy/local.yaml";
    const YAML::Node local = YAML::LoadFile(original);
    std::ofstream out(profile_);
    out << "# deploy/local.yaml for tests/badinput: private run dir, segment, pty, store.\n"
        << "profile: badinput\n"
        << "bus: {domain_id: 0, partition: overridden-by-the-environment, cyclonedds_config: "
        << local["bus"]["cyclonedds_config"].as<std::string>() << "}\n"
        << "run_dir: " << run_dir_ << "\n"
        << "restart: {backoff_initial_s: 0.5, backoff_max_s: 30, stable_after_s: 10}\n"
        << "stop_grace_s: 5\n"
        << "services:\n";
    for (const auto& s : local["services"]) {
      const std::string name = s["name"].as<std::string>();
      std::string config = s["config"] ? s["config"].as<std::string>() : "";
      if (const auto it = configs.find(config); it != configs.end()) {
        config = it->second;
      }
      out << "  - {name: " << name << ", exec: " << s["exec"].as<std::string>();
      if (!config.empty()) {
        out << ", config: " << config;
      }
      out << "}\n";
      names_.push_back(name);
    }
  }

  ToolRun cell_tool(std::vector<std::string> args, std::chrono::milliseconds timeout = 40s) {
    args.insert(args.begin() + 1, {"--profile", profile_});
    return cell::testing::run_tool("cell", args, env_, timeout);
  }

  ToolRun cellctl(const std::vector<std::string>& args, std::chrono::milliseconds timeout = 30s) {
    return cell::testing::run_tool("cellctl", args, env_, timeout);
  }

  json status() const {
    const std::string text = read_file(run_dir_ + "/status.json");
    return text.empty() ? json() : json::parse(text, nullptr, false);
  }

  /// name -> pid of every service in status.json.
  std::map<std::string, pid_t> pids() const {
    std::map<std::string, pid_t> out;
    const json s = status();
    if (s.is_object() && s.contains("services")) {
      for (const auto& svc : s["services"]) {
        out[svc["name"].get<std::string>()] = svc.value("pid", 0);
      }
    }
    return out;
  }

  /// The latest joints of every real robot (cell/robot/state_latest), by robot id.
  std::map<std::string, std::vector<double>> robot_joints() {
    bus::Participant p(domain_, partition_);
    bus::Topic<cell_robot_RobotState> topic(p, bus::topics::kRobotStateLatest);
    bus::Reader<cell_robot_RobotState> reader(p, topic, bus::topics::kRobotStateLatest);
    std::map<std::string, std::vector<double>> out;
    const std::set<std::string> robots{"ibm7545", "scara_picker", "excalibur"};
    const auto deadline = Clock::now() + 10s;
    while (out.size() < robots.size() && Clock::now() < deadline) {
      (void)reader.wait_for_data(100ms);
      auto batch = reader.take_copies(64);
      if (!batch) {
        ADD_FAILURE() << "read cell/robot/state_latest: " << batch.error().message;
        break;
      }
      for (auto& s : *batch) {
        const std::string id(bus::str(s->robot_id));
        if (robots.count(id) != 0) {
          out[id] = bus::to_vector(s->position_rad_or_mm);
        }
      }
    }
    return out;
  }

  /// Appends one scenario's row to $CELL_RELIABILITY_OUT/badinput.jsonl when it is set.
  void reliability_row(const std::string& scenario, const std::string& load,
                       const std::string& faults, const std::string& outcome,
                       const std::string& lost, double duration_s) {
    const char* dir = std::getenv("CELL_RELIABILITY_OUT");
    if (dir == nullptr || *dir == '\0') {
      return;
    }
    std::filesystem::create_directories(dir);
    std::ofstream out(std::string(dir) + "/badinput.jsonl", std::ios::app);
    out << json{{"suite", "badinput"},   {"scenario", scenario}, {"load", load},
                {"faults", faults},      {"outcome", outcome},   {"lost", lost},
                {"duration_s", duration_s}}
               .dump()
        << "\n";
    EXPECT_TRUE(out.good()) << "cannot append to " << dir << "/badinput.jsonl";
  }

  std::uint32_t domain_;
  std::string partition_;
  std::string dir_;
  std::string run_dir_;
  std::string profile_;
  std::string shm_name_;
  std::vector<std::string> env_;
  std::vector<std::string> names_;
};

TEST_F(BadInputTest, EveryServiceSurvivesAFloodOfMalformedSamplesAndStillAnswers) {
  const auto t0 = Clock::now();
  double flood_seconds = 30.0;
  if (const char* s = std::getenv("CELL_FLOOD_SECONDS"); s != nullptr && *s != '\0') {
    flood_seconds = std::atof(s);
    ASSERT_GT(flood_seconds, 0.0) << "CELL_FLOOD_SECONDS must be > 0, got '" << s << "'";
  }
  write_profile();
  ASSERT_FALSE(HasFailure());

  // 1. The whole cell, serving.
  const ToolRun up = cell_tool({"up", "--detach"});
  ASSERT_TRUE(up.exit.exited && up.exit.code == 0) << up.output;
  ASSERT_TRUE(eventually([&] { return cell_tool({"status"}, 20s).exit.code == 0; }, 90s))
      << "the cell never served: " << cell_tool({"status"}).output;
  const double startup_s = seconds_since(t0);
  const std::map<std::string, pid_t> pids_before = pids();
  ASSERT_EQ(pids_before.size(), names_.size()) << status().dump(2);
  const auto joints_before = robot_joints();
  ASSERT_EQ(joints_before.size(), 3U) << "not every robot publishes its state";

  // 2. The flood.
  const std::string flood_json = dir_ + "/flood.json";
  process::SpawnOptions options;
  options.executable = cell::testing::bin_path("cell-flood");
  options.args = {"--seconds", fmt::format("{}", flood_seconds), "--seed", "11", "--json",
                  flood_json};
  options.env = env_;
  auto flood = process::Child::spawn(options);
  ASSERT_TRUE(flood) << flood.error().message;
  const auto flood_exit =
      flood->wait_for(std::chrono::milliseconds(static_cast<int>(flood_seconds * 1000)) + 60s);
  ASSERT_TRUE(flood_exit.has_value()) << "cell-flood did not finish:\n" << flood->output();
  ASSERT_TRUE(flood_exit->exited && flood_exit->code == 0)
      << "cell-flood " << flood_exit->describe() << ":\n" << flood->output();
  std::printf("cell-flood:\n%s", flood->output().c_str());
  const json report = json::parse(read_file(flood_json), nullptr, false);
  ASSERT_TRUE(report.is_object()) << flood_json << " is not JSON";
  std::string rates;
  for (const auto& topic : report["topics"]) {
    rates += fmt::format("{} {:.0f}/s; ", topic["topic"].get<std::string>(),
                         topic["rate_hz"].get<double>());
    EXPECT_GT(topic["written"].get<std::uint64_t>(), 0U)
        << "nothing was written on " << topic["topic"];
    EXPECT_EQ(topic["failed"].get<std::uint64_t>(), 0U)
        << "writes on " << topic["topic"] << " failed for another reason than flow control "
        << "or the serializer refusing an out-of-range enum (see cell-flood's output)";
  }
  const double total_rate = report["rate_hz"].get<double>();
  RecordProperty("flood_rate_hz", fmt::format("{:.0f}", total_rate));
  std::printf("flood: %.0f samples/s in total over %.1f s: %s\n", total_rate,
              report["seconds"].get<double>(), rates.c_str());
  // The rate is the load held (reported; docs/reliability.md): ~2,300/s on an idle 2-core VM,
  // ~500/s on a loaded CI machine. The bound only catches a flood that barely ran.
  EXPECT_GT(total_rate, 100.0) << "the flood barely ran: the survival checks below prove little";

  // 3. Nobody died or restarted.
  const auto after = Clock::now();
  const json st = status();
  std::vector<std::string> casualties;
  for (const auto& svc : st["services"]) {
    const std::string name = svc["name"].get<std::string>();
    const pid_t pid = svc.value("pid", 0);
    const int restarts = svc.value("restarts", 0);
    if (restarts != 0 || pid != pids_before.at(name) || !process::pid_alive(pid)) {
      casualties.push_back(fmt::format("{} (pid {} -> {}, restarts {}, last exit '{}')", name,
                                       pids_before.at(name), pid, restarts,
                                       svc.value("last_exit", json()).dump()));
    }
  }
  EXPECT_THAT(casualties, ::testing::IsEmpty()) << st.dump(2);

  // 4. Every heartbeat serves (degraded only with a reason) and every service answers a ping.
  ToolRun serving;
  const bool all_serving = eventually(
      [&] {
        serving = cell_tool({"status"}, 20s);
        return serving.exit.code == 0;
      },
      20s);
  EXPECT_TRUE(all_serving) << serving.output;
  const ToolRun ping = cellctl({"--json", "--timeout", "5", "ping", "--rtt"});
  EXPECT_EQ(ping.exit.code, 0) << ping.output;
  const json pinged = parsed(ping.output);
  std::set<std::string> answered;
  if (pinged.is_object() && pinged.contains("services")) {
    for (const auto& s : pinged["services"]) {
      const std::string id = s.value("id", "");
      const std::string state = s.value("state", "");
      if (state == "degraded") {
        EXPECT_FALSE(s.value("detail", "").empty()) << id << " degraded without a reason";
      } else {
        EXPECT_EQ(state, "serving") << id << ": " << s.dump();
      }
      answered.insert(id);
    }
  }
  for (const auto& name : names_) {
    EXPECT_EQ(answered.count(name), 1U) << name << " missing from cellctl ping:\n"
                                        << ping.output;
  }

  // 5. A valid job gets an answer within seconds; a bad one a rejection naming its problem.
  const auto job_t0 = Clock::now();
  const ToolRun good = cellctl({"--json", "--timeout", "5", "submit",
                                cell::testing::source_dir() + "/config/jobs/table_ics.yaml",
                                "--id", "after-flood"},
                               30s);
  const double good_answer_s = seconds_since(job_t0);
  const json good_status = parsed(good.output);
  ASSERT_TRUE(good_status.is_object()) << "no answer to a valid job:\n" << good.output;
  const std::string good_state = good_status.value("state", "");
  EXPECT_TRUE(good.exit.code == 0 || good.exit.code == 1) << good.output;
  EXPECT_FALSE(good_state.empty()) << good.output;
  if (good.exit.code == 1) {  // refused: it must say why
    EXPECT_FALSE(good_status.value("reasons", json::array()).empty()) << good.output;
  }
  EXPECT_LT(good_answer_s, 10.0) << "the valid job's answer took " << good_answer_s << " s";
  const std::string bad_job = dir_ + "/bad_job.yaml";
  std::ofstream(bad_job) << read_file(cell::testing::source_dir() + "/config/jobs/table_ics.yaml")
                         << "\n";
  {
    std::string text = read_file(bad_job);
    const auto at = text.find("robot: ibm7545");
    ASSERT_NE(at, std::string::npos) << "config/jobs/table_ics.yaml names no robot ibm7545";
    text.replace(at, std::string("robot: ibm7545").size(), "robot: no_such_robot_9");
    std::ofstream(bad_job) << text;
  }
  const ToolRun bad = cellctl({"--json", "--timeout", "5", "submit", bad_job, "--id",
                               "bad-after-flood"},
                              30s);
  EXPECT_EQ(bad.exit.code, 1) << bad.output;
  const json bad_status = parsed(bad.output);
  ASSERT_TRUE(bad_status.is_object()) << bad.output;
  EXPECT_EQ(bad_status.value("state", ""), "rejected") << bad.output;
  EXPECT_THAT(bad_status.value("reasons", json::array()).dump(), HasSubstr("no_such_robot_9"));

  // 6. No robot moved: every trajectory and command the flood sent a real robot was refusable.
  const auto joints_after = robot_joints();
  for (const auto& [robot, q0] : joints_before) {
    ASSERT_EQ(joints_after.count(robot), 1U) << robot << " stopped publishing its state";
    const auto& q1 = joints_after.at(robot);
    ASSERT_EQ(q1.size(), q0.size()) << robot;
    for (std::size_t j = 0; j < q0.size(); ++j) {
      EXPECT_NEAR(q1[j], q0[j], kStillTol) << robot << " joint " << j + 1 << " moved";
    }
  }
  const double checks_s = seconds_since(after);

  // What each service made of it: its log's size and warning/error lines (a service that
  // logs every rejected sample in full grows its log by the flood's volume).
  for (const auto& name : names_) {
    const std::string text = read_file(run_dir_ + "/logs/" + name + ".log");
    std::size_t warns = 0;
    std::size_t errors = 0;
    std::size_t longest = 0;
    std::istringstream lines(text);
    for (std::string line; std::getline(lines, line);) {
      // The level sits right after the timestamp; further on it is quoted flood text.
      warns += line.find(" lvl=warn ") < 40 ? 1 : 0;
      errors += line.find(" lvl=error ") < 40 ? 1 : 0;
      longest = std::max(longest, line.size());
    }
    std::printf("log %-20s %8.1f KiB, %6zu warn, %6zu error lines, longest line %zu chars\n",
                name.c_str(), static_cast<double>(text.size()) / 1024.0, warns, errors, longest);
  }

  std::printf("badinput: startup %.1f s, flood %.1f s at %.0f/s, valid job answered in %.2f s "
              "(%s), checks %.1f s\n",
              startup_s, report["seconds"].get<double>(), total_rate, good_answer_s,
              good_state.c_str(), checks_s);
  reliability_row(
      "flood_malformed_samples",
      fmt::format("deploy/local.yaml's {} services via cell up", names_.size()),
      fmt::format("cell-flood seed 11 for {:.0f} s on {} topics, {:.0f} samples/s in total ({})",
                  report["seconds"].get<double>(), report["topics"].size(), total_rate, rates),
      fmt::format("{}: {} casualties, valid job answered '{}' in {:.2f} s, bad job {}",
                  HasFailure() ? "failed" : "passed", casualties.size(), good_state,
                  good_answer_s, bad_status.value("state", "?")),
      casualties.empty() ? "nothing lost" : fmt::format("services restarted: {}",
                                                        fmt::join(casualties, "; ")),
      seconds_since(t0));
}

}  // namespace
}  // namespace cell
