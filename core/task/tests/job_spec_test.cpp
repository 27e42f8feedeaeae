#include "cell/task/job_spec.hpp"

#include <fstream>
#include <iterator>
#include <numbers>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "cell/geometry/angles.hpp"
#include "cell/kinematics/robot_config.hpp"
#include "cell/testing/env.hpp"
#include "cell/testing/matchers.hpp"

namespace cell::task {
namespace {

using ::cell::testing::IsOk;
using ::testing::HasSubstr;

using geometry::kDeg;

struct Cell {
  kinematics::RobotModel ibm7545 = *kinematics::load_robot(cell::testing::source_dir() +
                                                           "/config/robots/ibm7545.yaml");
  kinematics::RobotModel picker = *kinematics::load_robot(cell::testing::source_dir() +
                                                          "/config/robots/scara_picker.yaml");
  kinematics::RobotModel excalibur = *kinematics::load_robot(cell::testing::source_dir() +
                                                             "/config/robots/excalibur.yaml");
  world::Catalogue catalogue = world::Catalogue::standard();
  RobotLookup robots() const {
    return [this](std::string_view id) -> const kinematics::RobotModel* {
      return id == "ibm7545"        ? &ibm7545
             : id == "scara_picker" ? &picker
             : id == "excalibur"    ? &excalibur
                                    : nullptr;
    };
  }
  CellFacts facts() const {
    CellFacts f;
    f.robots = robots();
    f.catalogue = &catalogue;
    f.cameras = {"ibm7545_eye", "belt_cam", "assembly_cam"};
    f.belts = {"belt1"};
    // config/sim-world.yaml: the table top lies 231.51 mm below the 7545's flange at Z = 0,
    // belt1's surface 200 mm below the picker's.
    f.working_plane_z_mm = [](std::string_view camera) -> std::optional<double> {
      return camera == "belt_cam" ? -200.0 : -231.51;
    };
    return f;
  }
};

const char* kThesisJob = R"(kind: table_pick_place
robot: ibm7545
camera: ibm7545_eye
windows:
  - joints: [45, 105, 0, 0]
classes: [dip14, ic_7x30]
place:
  pattern: column
  origin_mm: [-250, 250]
  count: 5
  pitch_mm: 30
)";

// Digest 000 §6: Out_pos is a column at X = -250 mm from Y = 250 mm, 30 mm pitch.
TEST(JobSpec, TheThesisJobParsesWithItsOutputColumn) {
  const Cell cell;
  auto job = parse_job_spec(kThesisJob, "<job>", cell.robots());
  ASSERT_THAT(job, IsOk());
  EXPECT_EQ(job->kind, JobKind::kTablePickPlace);
  const TablePickPlaceSpec* t = job->table();
  ASSERT_NE(t, nullptr);
  ASSERT_EQ(t->windows.size(), 1U);
  EXPECT_NEAR(t->windows[0][0], 45 * kDeg, 1e-12);
  EXPECT_NEAR(t->windows[0][1], 105 * kDeg, 1e-12);
  ASSERT_EQ(t->place.slots.size(), 5U);
  EXPECT_EQ(t->place.slots[4].x_mm, -250.0);
  EXPECT_EQ(t->place.slots[4].y_mm, 370.0);
  EXPECT_EQ(t->travel_z_mm, -200.0);
  EXPECT_THAT(check_job(*job, cell.facts()), IsOk());
}

TEST(JobSpec, TheShippedExampleJobsParseAndCheck) {
  const Cell cell;
  for (const char* name : {"table_ics.yaml", "conveyor_ics.yaml", "conveyor_ics_fast.yaml",
                           "assembly_blocks.yaml"}) {
    std::ifstream f(cell::testing::source_dir() + "/config/jobs/" + name);
    const std::string text((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
    auto job = parse_job_spec(text, name, cell.robots());
    ASSERT_THAT(job, IsOk()) << name;
    EXPECT_THAT(check_job(*job, cell.facts()), IsOk()) << name;
  }
}

// The assembly job's frames, method and options; its mistakes named with their lines.
TEST(JobSpec, AnAssemblyJobReadsItsFramesMethodAndOptions) {
  const Cell cell;
  auto job = parse_job_spec(R"(kind: assembly
robot: excalibur
source: "terapt;"
cameras: {cam1: assembly_cam}
base_T_world: {xyz_mm: [450, 0, 0], rpy_deg: [0, 0, 90]}
agent: grip
agent_T_tool: {xyz_mm: [0, 0, 5], rpy_deg: [180, 0, 0]}
method: two_step_destination
verify: false
max_retries: 1
camera_tolerance: {mm: 20, deg: 4}
)",
                            "asm.yaml", cell.robots());
  ASSERT_THAT(job, IsOk());
  const AssemblySpec* a = job->assembly();
  ASSERT_NE(a, nullptr);
  EXPECT_EQ(a->cameras.at("cam1"), "assembly_cam");
  EXPECT_NEAR((a->base_T_world * Eigen::Vector3d::UnitX()).y(), 1.0, 1e-12);  // turned 90 deg
  EXPECT_NEAR(a->agent_T_tool.translation().z(), 5.0, 1e-12);
  EXPECT_NEAR((a->agent_T_tool.linear() * Eigen::Vector3d::UnitZ()).z(), -1.0, 1e-12);
  EXPECT_EQ(a->method, AssemblySpec::Method::kTwoStepDestination);
  EXPECT_FALSE(a->verify);
  EXPECT_EQ(a->max_retries, 1);
  EXPECT_DOUBLE_EQ(a->camera_tolerance_mm, 20.0);
  auto bad = parse_job_spec(R"(kind: assembly
robot: excalibur
program: a.rapt
source: "terapt;"
base_T_world: {xyz_mm: [450, 0], rpy_deg: [0, 0, 0]}
method: sideways
max_retries: 99
)",
                            "asm.yaml", cell.robots());
  ASSERT_FALSE(bad);
  const std::string& m = bad.error().message;
  EXPECT_THAT(m, HasSubstr("give exactly one of program"));
  EXPECT_THAT(m, HasSubstr("asm.yaml:5:"));  // base_T_world.xyz_mm
  EXPECT_THAT(m, HasSubstr("agent_T_tool"));  // missing
  EXPECT_THAT(m, HasSubstr("must be actual, two_step_world or two_step_destination"));
  EXPECT_THAT(m, HasSubstr("max_retries"));
}

TEST(JobSpec, EveryErrorIsReportedWithItsLine) {
  const Cell cell;
  const std::string text = R"(kind: table_pick_place
robot: ibm7545
camera: ibm7545_eye
windows:
  - joints: [45, 105, 0]
speed_scale: 2
colour: red
place:
  pattern: spiral
)";
  auto job = parse_job_spec(text, "job.yaml", cell.robots());
  ASSERT_FALSE(job);
  const std::string& m = job.error().message;
  EXPECT_THAT(m, HasSubstr("job.yaml:5:"));
  EXPECT_THAT(m, HasSubstr("has 4 joints, got 3 values"));
  EXPECT_THAT(m, HasSubstr("speed_scale"));
  EXPECT_THAT(m, HasSubstr("colour"));
  EXPECT_THAT(m, HasSubstr("list, row, column or grid, got 'spiral'"));
}

TEST(JobSpec, LightsAndTheReadyPoseAreReadAndChecked) {
  const Cell cell;
  std::string text = kThesisJob;
  text += "lights: both\n";
  auto job = parse_job_spec(text, "job.yaml", cell.robots());
  ASSERT_THAT(job, IsOk());
  EXPECT_EQ(job->table()->lights, TablePickPlaceSpec::Lights::kBoth);
  text.replace(text.find("lights: both"), 12, "lights: disco");
  job = parse_job_spec(text, "job.yaml", cell.robots());
  ASSERT_FALSE(job);
  EXPECT_THAT(job.error().message, HasSubstr("keep, off, fluorescent, halogen or both, got 'disco'"));
  // The conveyor's ready pose: two numbers, and reachable.
  std::ifstream f(cell::testing::source_dir() + "/config/jobs/conveyor_ics.yaml");
  std::string belt((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
  const auto at = belt.find("ready_mm: [350, 50]");
  ASSERT_NE(at, std::string::npos);
  auto conveyor = parse_job_spec(belt, "belt.yaml", cell.robots());
  ASSERT_THAT(conveyor, IsOk());
  ASSERT_TRUE(conveyor->conveyor()->ready_mm.has_value());
  EXPECT_DOUBLE_EQ(conveyor->conveyor()->ready_mm->y(), 50.0);
  std::string far = belt;
  far.replace(at, 19, "ready_mm: [350, 900]");
  conveyor = parse_job_spec(far, "belt.yaml", cell.robots());
  ASSERT_THAT(conveyor, IsOk());
  const Status s = check_job(*conveyor, cell.facts());
  ASSERT_FALSE(s);
  EXPECT_THAT(s.error().message, HasSubstr("ready_mm"));
  std::string bad = belt;
  bad.replace(at, 19, "ready_mm: [350]");
  EXPECT_FALSE(parse_job_spec(bad, "belt.yaml", cell.robots()));
  // How the arm goes to meet a part: a joint move unless the job says line.
  EXPECT_TRUE(conveyor->conveyor()->track_joint_interpolated);
  auto line = parse_job_spec(belt + "track_motion: line\n", "belt.yaml", cell.robots());
  ASSERT_THAT(line, IsOk());
  EXPECT_FALSE(line->conveyor()->track_joint_interpolated);
  auto wobble = parse_job_spec(belt + "track_motion: wobble\n", "belt.yaml", cell.robots());
  ASSERT_FALSE(wobble);
  EXPECT_THAT(wobble.error().message, HasSubstr("track_motion"));
  EXPECT_THAT(wobble.error().message, HasSubstr("must be joint or line, got 'wobble'"));
}

TEST(JobSpec, AnUnknownRobotOrKindIsNamed) {
  const Cell cell;
  auto job = parse_job_spec("kind: juggling\nrobot: r2d2\n", "job.yaml", cell.robots());
  ASSERT_FALSE(job);
  EXPECT_THAT(job.error().message, HasSubstr("unknown robot 'r2d2'"));
  EXPECT_THAT(job.error().message, HasSubstr("got 'juggling'"));
  EXPECT_FALSE(parse_job_spec("- not\n- a map\n", "job.yaml", cell.robots()));
  EXPECT_FALSE(parse_job_spec("kind: [unterminated\n", "job.yaml", cell.robots()));
}

TEST(CheckJob, UnreachableSlotsUnknownClassesAndCamerasAreAllReported) {
  const Cell cell;
  std::string text = kThesisJob;
  text.replace(text.find("[dip14, ic_7x30]"), 16, "[dip14, dip99]");
  text.replace(text.find("[-250, 250]"), 11, "[600, 300]");  // beyond 650 mm of reach
  text.replace(text.find("camera: ibm7545_eye"), 19, "camera: cam9");
  auto job = parse_job_spec(text, "job.yaml", cell.robots());
  ASSERT_THAT(job, IsOk());
  const Status s = check_job(*job, cell.facts());
  ASSERT_FALSE(s);
  EXPECT_THAT(s.error().message, HasSubstr("unknown part class 'dip99'"));
  EXPECT_THAT(s.error().message, HasSubstr("unknown camera 'cam9'"));
  EXPECT_THAT(s.error().message, HasSubstr("place slot 0 at (600.0, 300.0"));
}

TEST(CheckJob, AWindowOutsideTheJointLimitsIsRefused) {
  const Cell cell;
  std::string text = kThesisJob;
  text.replace(text.find("[45, 105, 0, 0]"), 15, "[45, 105, 400, 0]");  // Z beyond 250 mm
  auto job = parse_job_spec(text, "job.yaml", cell.robots());
  ASSERT_THAT(job, IsOk());
  EXPECT_THAT(check_job(*job, cell.facts()).error().message, HasSubstr("window 0"));
}

TEST(GraspPose, AScaraToolPointsUpAndASixAxisToolDown) {
  const Cell cell;
  const auto p = grasp_pose(cell.ibm7545, 100, 200, -227.7, 30 * kDeg);
  EXPECT_NEAR(p.linear().col(2).z(), 1.0, 1e-12);
  EXPECT_NEAR(std::atan2(p.linear()(1, 0), p.linear()(0, 0)), 30 * kDeg, 1e-12);
  EXPECT_EQ(p.translation().z(), -227.7);
}

}  // namespace
}  // namespace cell::task
