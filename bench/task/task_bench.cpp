// task_bench: the task service on the simulated cell (bench/README.md, section task).
//  - submission -> acceptance: a JobRequest written on the bus until its JobStatus (validated,
//    journaled with fsync, answered), for valid conveyor jobs (cancelled at once);
//  - the table job: 15 ICs of the thesis's table, picks per minute;
//  - the belt at 0.5 m/s: picks per minute at a part every 2 s and every 1.2 s, and the time
//    from the exposure to the tracking motion under way (the chapter's major cycle: 16 ms);
//  - the belt at 2 m/s, the same (the picker cannot follow it within its joints' limits: the
//    parts are refused, each with its reason; tests/task checks that).
// Calibrations are the simulator's truth (the subject is the task service). Run:
//   build/bin/task_bench            (about 5 minutes)      build/bin/task_bench --quick
//   build/bin/task_bench --only belt-20-2   (one measure: accept, table, belt-05-2, belt-05-12,
//                                            belt-20-2)
#include <sqlite3.h>

#include <algorithm>
#include <cstdlib>
#include <cstring>
#include <numeric>

#include "cell/bus/request_reply.hpp"
#include "cell/bus/topics.hpp"
#include "cell/common/time.hpp"
#include "task_cell_fixture.hpp"

namespace cell::task_test {
namespace {

bool g_quick = false;
std::string g_only;  ///< --only ID: that measure alone

bool wanted(const std::string& id) { return g_only.empty() || g_only == id; }

struct Stats {
  std::vector<double> v;
  double q(double p) const {
    if (v.empty()) {
      return 0.0;
    }
    std::vector<double> s = v;
    std::sort(s.begin(), s.end());
    return s[static_cast<std::size_t>(p * static_cast<double>(s.size() - 1))];
  }
};

/// `field` (exposure_to_track_ms, exposure_to_frame_ms) of every "gripped" step of `job` in
/// the journal.
Stats gripped_field(const std::string& journal, const std::string& job, const char* field) {
  Stats out;
  sqlite3* db = nullptr;
  if (sqlite3_open_v2(journal.c_str(), &db, SQLITE_OPEN_READONLY, nullptr) != SQLITE_OK) {
    sqlite3_close(db);
    return out;
  }
  sqlite3_stmt* st = nullptr;
  if (sqlite3_prepare_v2(db, "SELECT detail_json FROM steps WHERE job_id = ? AND name = 'gripped'",
                         -1, &st, nullptr) == SQLITE_OK) {
    sqlite3_bind_text(st, 1, job.c_str(), -1, SQLITE_TRANSIENT);
    while (sqlite3_step(st) == SQLITE_ROW) {
      const auto* text = reinterpret_cast<const char*>(sqlite3_column_text(st, 0));
      const json d = json::parse(text != nullptr ? text : "{}", nullptr, false);
      if (d.is_object() && d.value(field, -1.0) > 0) {
        out.v.push_back(d[field].get<double>());
      }
    }
  }
  sqlite3_finalize(st);
  sqlite3_close(db);
  return out;
}

class TaskBench : public TaskCellTest {
 protected:
  // NOLINTNEXTLINE(bugprone-exception-escape): plain struct; tidy 14 blames json's members
  struct BeltRun {
    double speed = 0, period = 0;
    int in_bin = 0, fell_off = 0, picked = 0;
    json counters;
    double elapsed_s = 0;
    Stats latency;        ///< exposure -> the tracking motion accepted
    Stats frame_latency;  ///< exposure -> the located parts taken by the task service
    Stats vision;         ///< the vision service's time on the frame
  };

  BeltRun belt_run(const std::string& id, double speed, double period, double duration_s,
                   const std::string& job_file) {
    BeltRun r;
    r.speed = speed;
    r.period = period;
    const std::string scene = write(id + ".yaml", belt_scene(speed, period));
    std::ifstream f(job_file);
    std::string text((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
    const auto at = text.find("duration_s: 60");
    if (at != std::string::npos) {
      text.replace(at, 14, fmt::format("duration_s: {}", duration_s));
    }
    const std::string job = write(id + "-job.yaml", text);
    (void)cellctl({"world", "reset", "--scene", scene});
    (void)cellctl({"submit", job, "--id", id, "--wait"}, 600s);
    (void)cellctl({"world", "belt", "--id", "belt1", "--speed", "0"});
    const json status = this->job(id);
    r.counters = status.value("counters", json::object());
    r.picked = r.counters.value("picked", 0);
    r.elapsed_s = status.value("elapsed_s", 0.0);
    for (const json& p : world_parts()) {
      const double x = p["pose"]["x_mm"].get<double>() - kPickerBaseX;
      const double y = p["pose"]["y_mm"].get<double>();
      const bool floor = p["support"] == "floor";
      if (floor && (std::hypot(x - 100.0, y + 300.0) < 60.0 || std::hypot(x - 100.0, y + 250.0) < 60.0)) {
        ++r.in_bin;
      } else if (floor) {
        ++r.fell_off;
      }
    }
    r.latency = gripped_field(dir_ + "/journal.sqlite", id, "exposure_to_track_ms");
    r.frame_latency = gripped_field(dir_ + "/journal.sqlite", id, "exposure_to_frame_ms");
    r.vision = gripped_field(dir_ + "/journal.sqlite", id, "vision_ms");
    std::map<std::string, int> why;
    for (const json& p : status.value("parts", json::array())) {
      const std::string d = p.value("detail", "");
      if (!d.empty()) {
        ++why[d.substr(0, 100)];
      }
    }
    for (const auto& [d, n] : why) {
      std::printf("task_bench: %s: %d x %s\n", id.c_str(), n, d.c_str());
    }
    return r;
  }
};

TEST_F(TaskBench, Table) {
  start_cell(cell::testing::source_dir() + "/config/scenes/table_ics.yaml");
  ASSERT_FALSE(HasFailure());
  (void)child("calibration")->stop(10s);
  store_truth_calibration("ibm7545_eye", "", Eigen::Isometry3d::Identity(), -231.51);
  store_truth_calibration("belt_cam", "scara_picker",
                          Eigen::Isometry3d(Eigen::Translation3d(kPickerBaseX, 0, kPickerBaseZ)),
                          -200.0);
  start("calibration2", "cell-calibration", dir_ + "/calibration.yaml");
  ASSERT_EQ(cellctl({"robot", "home", "--robot", "scara_picker"}, 30s).exit.code, 0);

  // Submission -> acceptance, through the bus as a remote client does.
  Stats accept;
  {
    bus::Participant participant(domain_, partition_);
    bus::Requester<cell_task_JobRequest, cell_task_JobStatus> requester(
        participant, bus::topics::kJobRequest, bus::topics::kJobStatus,
        bus::make_client_id("task_bench"));
    std::ifstream f(cell::testing::source_dir() + "/config/jobs/conveyor_ics.yaml");
    const std::string spec((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
    const int n = !wanted("accept") ? 0 : g_quick ? 5 : 40;
    for (int i = 0; i < n; ++i) {
      const std::string id = fmt::format("accept-{}", i);
      cell_task_JobRequest r{};
      r.job_id = bus::borrow(id);
      r.kind = cell_task_JOB_CONVEYOR_PICK;
      const std::string robot = "scara_picker";
      r.robot_id = bus::borrow(robot);
      r.spec_yaml = bus::borrow(spec);
      const auto t0 = std::chrono::steady_clock::now();
      auto reply = requester.call(r, 5s);
      const auto t1 = std::chrono::steady_clock::now();
      if (!reply || reply->get().state == cell_task_JOB_REJECTED) {
        std::printf("task_bench: submission %d refused: %s\n", i,
                    reply ? (bus::span(reply->get().reasons).empty()
                                 ? "(no reason)"
                                 : bus::str(bus::span(reply->get().reasons)[0]))
                                .data()
                          : reply.error().message.c_str());
      }
      if (reply && reply->get().state != cell_task_JOB_REJECTED && i > 0) {  // 0: discovery
        accept.v.push_back(std::chrono::duration<double, std::milli>(t1 - t0).count());
      }
      (void)cellctl({"cancel", id});
    }
  }

  // A cancel stops the robot at once (STOPPED until reset, as after any stop).
  (void)cellctl({"robot", "reset", "--robot", "scara_picker"});
  // The table job.
  double table_s = 0.0;
  int table_parts = 0;
  if (wanted("table")) {
    (void)cellctl({"world", "reset"});
    const auto t0 = std::chrono::steady_clock::now();
    (void)cellctl({"submit", cell::testing::source_dir() + "/config/jobs/table_ics.yaml", "--id",
                   "table", "--wait"},
                  600s);
    table_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    table_parts = job("table").value("parts_done", 0);
  }

  // The belt.
  const std::string conveyor = cell::testing::source_dir() + "/config/jobs/conveyor_ics.yaml";
  const double d = g_quick ? 10.0 : 60.0;
  std::vector<BeltRun> runs;
  if (wanted("belt-05-2")) {
    runs.push_back(belt_run("belt-05-2", 500, 2.0, d, conveyor));
  }
  if (!g_quick && wanted("belt-05-12")) {
    runs.push_back(belt_run("belt-05-12", 500, 1.2, d, conveyor));
  }
  if (wanted("belt-20-2")) {
    runs.push_back(belt_run("belt-20-2", 2000, 2.0, d,
                            cell::testing::source_dir() + "/config/jobs/conveyor_ics_fast.yaml"));
  }

  std::printf("\ntask_bench: the task service on the simulated cell (ideal gateways, truth "
              "calibrations)\n\n");
  std::printf("| measure | value | peer |\n|---|---|---|\n");
  std::printf("| submission -> acceptance (JobRequest -> JobStatus, validated + journaled), "
              "median / p90 / max [ms] | %.2f / %.2f / %.2f (n = %zu) | - |\n",
              accept.q(0.5), accept.q(0.9), accept.q(1.0), accept.v.size());
  std::printf("| table job (the thesis's 15 ICs, 7545) | %d parts in %.1f s: %.1f picks/min | "
              "the thesis gives no cycle time (digest 000 §8) |\n",
              table_parts, table_s, table_parts * 60.0 / std::max(1.0, table_s));
  for (const BeltRun& r : runs) {
    std::printf("| belt %.1f m/s, a part every %.1f s, %.0f s | %d picked by truth of %d "
                "(%.1f%%), %.1f picks/min; job counters %s | - |\n",
                r.speed / 1000, r.period, d, r.in_bin, r.in_bin + r.fell_off,
                100.0 * r.in_bin / std::max(1, r.in_bin + r.fell_off),
                r.in_bin * 60.0 / std::max(1.0, r.elapsed_s), r.counters.dump().c_str());
    std::printf("| belt %.1f m/s: exposure -> tracking motion under way, median / p90 / max "
                "[ms] | %.1f / %.1f / %.1f (n = %zu) | the chapter's major cycle 16 ms |\n",
                r.speed / 1000, r.latency.q(0.5), r.latency.q(0.9), r.latency.q(1.0),
                r.latency.v.size());
    std::printf("| ... of which exposure -> located parts taken by the task (render, image, "
                "vision; and the queue while the arm is busy), median / p90 [ms] | %.1f / %.1f "
                "| - |\n",
                r.frame_latency.q(0.5), r.frame_latency.q(0.9));
    std::printf("| ... of which the vision service's locate (1024 x 1024), median / p90 [ms] | "
                "%.1f / %.1f | - |\n",
                r.vision.q(0.5), r.vision.q(0.9));
  }
  std::printf("task_bench: done\n");
}

}  // namespace
}  // namespace cell::task_test

int main(int argc, char** argv) {
  for (int i = 1; i < argc; ++i) {
    if (std::strcmp(argv[i], "--quick") == 0) {
      cell::task_test::g_quick = true;
    } else if (std::strcmp(argv[i], "--only") == 0 && i + 1 < argc) {
      cell::task_test::g_only = argv[++i];
    }
  }
  // The checkout and the binaries this bench was built from, unless the caller says otherwise.
  setenv("CELL_SOURCE_DIR", CELL_BENCH_SOURCE_DIR, 0);
  setenv("CELL_BIN_DIR", CELL_BENCH_BIN_DIR, 0);
  // This process's own participant (the submissions) on the cell's loopback configuration.
  setenv("CYCLONEDDS_URI", "file://" CELL_BENCH_SOURCE_DIR "/config/dds/loopback.xml", 0);
  ::testing::InitGoogleTest(&argc, argv);
  return RUN_ALL_TESTS();
}
