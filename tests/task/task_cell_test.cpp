// The task service end to end (issue 9's "must hold"), on the simulated cell: real processes on
// a private DDS domain and partition, driven with cellctl as an operator would, every result
// checked against cell-sim-world's ground truth.
//  - Table: 15 ICs scattered by the simulator in the camera window, the 7545's camera
//    calibrated from scratch by cell-calibration (board images, then the guided hand-eye), the
//    thesis's job submitted: every IC in its slot within 0.5 mm and 1 degree.
//  - Conveyor: a stream of DIPs on belt1 at 0.5 m/s and at 2 m/s for 60 s: at least 99 % and
//    95 % picked by the truth, the misses counted by cause, every grasp on its part.
//  - Faults: cell-task killed (SIGKILL) 20 times during a table job; bad requests refused.
#include <csignal>
#include <random>
#include <set>
#include <thread>

#include <gmock/gmock.h>

#include "task_cell_fixture.hpp"

namespace cell::task_test {
namespace {

using ::testing::HasSubstr;

TEST_F(TaskCellTest, TableJobFromScratchPutsEveryScatteredIcInItsSlot) {
  const std::string scene = write("scene.yaml", kTableScene);
  start_cell(scene);
  ASSERT_FALSE(HasFailure());
  calibrate_7545_camera_from_scratch();
  ASSERT_FALSE(HasFailure()) << logs();
  // The guided procedure reset the world to its board scene and back: scatter the ICs now.
  ASSERT_EQ(cellctl({"world", "reset", "--scene", scene}).exit.code, 0);
  ToolRun r = cellctl({"world", "scatter", "--count", "15", "--seed", "7"});
  ASSERT_EQ(r.exit.code, 0) << r.output;
  ASSERT_EQ(world_parts().size(), 15U);
  r = cellctl({"submit", cell::testing::source_dir() + "/config/jobs/table_ics.yaml", "--id",
               "table-1", "--wait"},
              600s);
  EXPECT_EQ(r.exit.code, 0) << r.output;
  const json status = job("table-1");
  EXPECT_EQ(status["state"], "succeeded") << status.dump(2);
  EXPECT_EQ(status["parts_done"], 15) << status.dump(2);
  std::printf("table job: %s in %.1f s\n", status.value("state", "?").c_str(),
              status.value("elapsed_s", 0.0));
  expect_all_in_slots(15);
}

/// What a conveyor run left, by ground truth and by the job's counters.
// NOLINTNEXTLINE(bugprone-exception-escape): plain struct; tidy 14 blames json's members
struct BeltOutcome {
  int in_bin = 0;    ///< beside the belt at the job's slot, picker (100, -300)
  int fell_off = 0;  ///< fallen off the belt's end: missed
  int on_belt = 0;   ///< not yet past the window at the end
  int picked = 0;    ///< the job's count
  int causes = 0;    ///< the job's misses, every cause
  int locate_failed = 0;
  int grasps_missed = 0;  ///< grippers the truth saw close on nothing
  json counters;
};

class ConveyorCellTest : public TaskCellTest {
 protected:
  /// A stream of DIPs, a part every 3 s for the job's 60 s, at `speed_mm_s`, picked by
  /// `job_file`; checks that the job succeeded and that its counts add up against the truth.
  BeltOutcome run_stream(double speed_mm_s, const std::string& job_file, const std::string& id) {
    BeltOutcome out;
    const std::string scene = write(id + ".yaml", belt_scene(speed_mm_s, 3.0));
    start_cell(scene);
    if (HasFailure()) {
      return out;
    }
    // Not the subject here: the belt camera calibrated as the simulator knows it.
    (void)child("calibration")->stop(10s);
    store_truth_calibration("belt_cam", "scara_picker",
                            Eigen::Isometry3d(Eigen::Translation3d(kPickerBaseX, 0, kPickerBaseZ)),
                            -200.0);
    if (HasFailure()) {
      return out;
    }
    start("calibration2", "cell-calibration", dir_ + "/calibration.yaml");
    EXPECT_TRUE(eventually(
        [&] {
          const ToolRun show =
              cellctl({"--json", "calibration", "show", "--camera", "belt_cam"});
          return show.exit.code == 0 && show.output.find("simulator's truth") != std::string::npos;
        },
        30s));
    EXPECT_EQ(cellctl({"robot", "home", "--robot", "scara_picker"}).exit.code, 0);
    EXPECT_EQ(cellctl({"world", "reset", "--scene", scene}).exit.code, 0);
    ToolRun r = cellctl(
        {"submit", cell::testing::source_dir() + "/config/jobs/" + job_file, "--id", id, "--wait"},
        300s);
    EXPECT_EQ(r.exit.code, 0) << r.output;
    EXPECT_EQ(cellctl({"world", "belt", "--id", "belt1", "--speed", "0"}).exit.code, 0);
    const json status = job(id);
    EXPECT_EQ(status["state"], "succeeded") << status.dump(2);
    for (const json& p : world_parts()) {
      const double x = p["pose"]["x_mm"].get<double>() - kPickerBaseX;
      const double y = p["pose"]["y_mm"].get<double>();
      if (p["support"] == "floor" && std::hypot(x - 100.0, y + 300.0) < 60.0) {
        ++out.in_bin;
      } else if (p["support"] == "floor") {
        ++out.fell_off;
      } else {
        ++out.on_belt;
      }
    }
    out.counters = status.value("counters", json::object());
    out.picked = out.counters.value("picked", 0);
    for (auto it = out.counters.begin(); it != out.counters.end(); ++it) {
      if (it.key() != "picked") {
        out.causes += it.value().get<int>();
      }
    }
    out.locate_failed = out.counters.value("locate_failed", 0);
    std::printf("belt at %.1f m/s for 60 s: %d in the bin, %d fell off the end, %d on the belt; "
                "job: picked %d, %s\n",
                speed_mm_s / 1000.0, out.in_bin, out.fell_off, out.on_belt, out.picked,
                out.counters.dump().c_str());
    // How far from each part's grasp point the gripper closed, by the truth: the tracking.
    const GraspsSeen grasps = grasps_seen_by_the_world();
    std::vector<double> along;  // grasp point - tool along the belt's travel (-y), mm
    double worst = 0.0;
    for (const Eigen::Vector3d& d : grasps.taken) {
      along.push_back(-d.y());
      worst = std::max(worst, d.norm());
    }
    std::sort(along.begin(), along.end());
    out.grasps_missed = static_cast<int>(grasps.missed.size());
    std::printf("  grasps by the truth: %zu took a part (worst %.2f mm from its grasp point; the "
                "part ahead of the tool along the belt by %.2f mm median, %.2f .. %.2f), %zu "
                "closed on nothing\n",
                grasps.taken.size(), worst, along.empty() ? 0.0 : along[along.size() / 2],
                along.empty() ? 0.0 : along.front(), along.empty() ? 0.0 : along.back(),
                grasps.missed.size());
    for (const Eigen::Vector3d& d : grasps.missed) {
      std::printf("    closed on nothing: the nearest grasp point %.2f, %.2f, %.2f mm from the "
                  "tool\n", d.x(), d.y(), d.z());
    }
    // Why parts were missed, in the job's words (the first of each kind).
    std::set<std::string> seen;
    for (const json& part : status.value("parts", json::array())) {
      const std::string outcome = part.value("outcome", "");
      if (outcome != "placed" && seen.insert(outcome).second) {
        std::printf("  %s: %s\n", outcome.c_str(), part.value("detail", "").c_str());
      }
    }
    // Every pick the job counts is a part in the bin, give or take a grasp the gripper closed
    // on nothing (the simulated gripper has no part sensor).
    EXPECT_GE(out.in_bin, out.picked - 3);
    EXPECT_LE(out.in_bin, out.picked);
    // The misses add up: every part that left the belt's end is a counted cause (or one of the
    // grasps above).
    EXPECT_GE(out.causes + (out.picked - out.in_bin), out.fell_off - 3);
    EXPECT_LE(out.causes, out.fell_off + out.on_belt);
    EXPECT_GE(out.picked + out.causes, 17);  // 60 s, a part every 3 s
    // Vision names every DIP on the dark belt (core/vision/tests/belt_test.cpp: 60 of 60);
    // until the belt camera had its own locate keys one in eight was left 'unknown'.
    EXPECT_LE(out.locate_failed, 2) << out.counters.dump();
    return out;
  }

  double picked_fraction(const BeltOutcome& o) const {
    return static_cast<double>(o.in_bin) / std::max(1, o.in_bin + o.fell_off);
  }
};

// The bounds. The test runs alone (RUN_SERIAL): on this 2-core machine both runs pick
// every part (19 of 19 and 20 of 20, every grasp within 0.17 mm of its grasp point by the
// truth); with two CPU hogs beside them they fall to about half, the misses still counted.
TEST_F(ConveyorCellTest, StreamAtHalfAMetrePerSecondIsPickedAndTheMissesAddUp) {
  // A part every 3 s: the picker's cycle is about 1.9 s (track, grip, depart, place, back to
  // its ready pose); bench/task measures it at a part every 2 and 1.2 s as well.
  const BeltOutcome o = run_stream(500.0, "conveyor_ics.yaml", "belt-05");
  EXPECT_GE(picked_fraction(o), 0.99);
  EXPECT_EQ(o.grasps_missed, 0);
}

// config/jobs/conveyor_ics_fast.yaml at 2 m/s: the picker cannot follow a part that fast on
// belt1 within its joints' limits (its J1 would pass its published speed over most of the
// window, its J2 its acceleration near the reach; core/motion's PlannerIntercept tests), so
// the motion service refuses every meeting, naming the joint, before the arm moves; the job
// counts each part outside the window and says why, and no gripper closes on nothing. (Until
// the gateways kept the arm's limits, the ideal picker followed at any speed and this test
// counted 19 or 20 parts of 20 in the bin.)
TEST_F(ConveyorCellTest, StreamAtTwoMetresPerSecondIsRefusedWithinTheArmsLimitsAndSaysWhy) {
  const BeltOutcome o = run_stream(2000.0, "conveyor_ics_fast.yaml", "belt-2");
  EXPECT_EQ(o.picked, 0);
  EXPECT_EQ(o.in_bin, 0);
  EXPECT_EQ(o.grasps_missed, 0);
  EXPECT_GE(o.counters.value("outside_window", 0), 17) << o.counters.dump();
  const json status = job("belt-2");
  int refused = 0;
  for (const json& part : status.value("parts", json::array())) {
    const std::string detail = part.value("detail", "");
    if (detail.find("2000 mm/s") != std::string::npos &&
        detail.find("of its acceleration limit") != std::string::npos) {
      ++refused;
    }
  }
  EXPECT_GE(refused, 17) << status.dump(2);
}

TEST_F(TaskCellTest, KilledTwentyTimesTheTableJobStillPlacesEveryPartOnce) {
  start_cell(cell::testing::source_dir() + "/config/scenes/table_ics.yaml");
  ASSERT_FALSE(HasFailure());
  (void)child("calibration")->stop(10s);
  store_truth_calibration("ibm7545_eye", "", Eigen::Isometry3d::Identity(), -231.51);
  ASSERT_FALSE(HasFailure());
  start("calibration2", "cell-calibration", dir_ + "/calibration.yaml");
  ASSERT_TRUE(eventually(
      [&] {
        const ToolRun show = cellctl({"--json", "calibration", "show", "--camera", "ibm7545_eye"});
        return show.exit.code == 0 && show.output.find("simulator's truth") != std::string::npos;
      },
      30s));
  // Bad requests first: refused with their reasons, nothing else affected.
  const std::string bad = write("bad.yaml", "kind: table_pick_place\nrobot: ibm7545\n"
                                            "camera: ibm7545_eye\nwindows: [{joints: [45]}]\n"
                                            "plaec: {pattern: row}\n");
  ToolRun r = submit(bad, "bad-1");
  EXPECT_NE(r.exit.code, 0);
  EXPECT_THAT(r.output, HasSubstr("plaec"));
  std::ifstream f(cell::testing::source_dir() + "/config/jobs/table_ics.yaml");
  std::string text((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
  std::string other = text;
  other.replace(other.find("robot: ibm7545"), 14, "robot: ibm9999");
  r = submit(write("unknown-robot.yaml", other), "bad-2");
  EXPECT_NE(r.exit.code, 0);
  EXPECT_THAT(r.output, HasSubstr("unknown robot 'ibm9999'"));
  EXPECT_EQ(job("bad-1").value("state", ""), "rejected");

  r = submit(cell::testing::source_dir() + "/config/jobs/table_ics.yaml", "durable-1");
  ASSERT_EQ(r.exit.code, 0) << r.output;
  const int kills = kill_task_during("durable-1", 20, 20261201, 1500, 5000);
  EXPECT_GE(kills, 15);  // most of them while the job ran
  const json status = wait_end("durable-1", 600s);
  EXPECT_EQ(status["state"], "succeeded") << status.dump(2) << logs();
  expect_all_in_slots(15);
  // No part picked twice: the simulator saw exactly one grasp per part.
  EXPECT_EQ(grasps_in_world_log(), 15U);
  // One job, one id: the journal did not duplicate it.
  const json jobs = parsed(cellctl({"--json", "jobs"}));
  int durable = 0;
  for (const json& j : jobs) {
    durable += j.value("job_id", "") == "durable-1" ? 1 : 0;
  }
  EXPECT_EQ(durable, 1);
}

}  // namespace
}  // namespace cell::task_test
