// cell-calibration in-process on a private bus: config errors with file:line, the published
// calibrations (transient-local), every request answered, hand-eye from a recorded data set
// (rendered through the 7545 camera's truth) checked against that truth, and failures that
// leave the current calibration in place.
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <numbers>

#include <fmt/format.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>

#include "calibration_service.hpp"
#include "cell/bus/request_reply.hpp"
#include "cell/calibration/pixel_mapping.hpp"
#include "cell/geometry/angles.hpp"
#include "cell/render/mount.hpp"
#include "cell/testing/env.hpp"
#include "cell/testing/matchers.hpp"
#include "cell/testing/service_harness.hpp"
#include "cell/world/scene.hpp"
#include "cell/world/world.hpp"
#include "sim_views.hpp"

namespace cell::calibration_service {
namespace {

using ::cell::testing::eventually;
using ::cell::testing::IsErrWith;
using ::cell::testing::IsOk;
using ::testing::HasSubstr;
using namespace std::chrono_literals;

using geometry::kDeg;

std::string base_yaml(const std::string& store, const std::string& extra = {}) {
  const std::string home = cell::testing::source_dir();
  return fmt::format(
      "service: {{id: calibration}}\nstore_dir: {0}\nrobots_dir: {1}/config/robots\n"
      "cameras:\n"
      "  - {{camera_file: {1}/config/cameras/ibm7545_eye.yaml, working_plane_z_mm: -231.51}}\n"
      "  - {{camera_file: {1}/config/cameras/belt_cam.yaml, robot_id: scara_picker,\n"
      "     robot_world_T_base: {{xyz_mm: [1000, 0, 960]}}, working_plane_z_mm: -200}}\n"
      "belts:\n  - {{belt_id: belt1, robot_id: scara_picker, camera_id: belt_cam, "
      "surface_z_mm: -200}}\n"
      "timeouts: {{discovery_s: 1, image_s: 2, motion_s: 5, world_s: 1}}\n{2}",
      store, home, extra);
}

TEST(CalibrationConfig, ErrorsNameTheFileLineAndKey) {
  auto doc = config::load_string(base_yaml("/tmp/x", "colour: red\n"), "calibration.yaml");
  ASSERT_THAT(doc, IsOk());
  auto c = load_config(*doc);
  ASSERT_FALSE(c);
  EXPECT_EQ(c.error().code, Errc::kConfig);
  EXPECT_THAT(c.error().message, HasSubstr("colour"));
  const std::string fixed_without_robot = fmt::format(
      "cameras:\n  - {{camera_file: {}/config/cameras/belt_cam.yaml, working_plane_z_mm: 0}}\n",
      cell::testing::source_dir());
  auto d = load_config(*config::load_string(fixed_without_robot, "calibration.yaml"));
  ASSERT_FALSE(d);
  EXPECT_THAT(d.error().message, HasSubstr("calibration.yaml:2:"));
  EXPECT_THAT(d.error().message, HasSubstr("needs the robot"));
  // A procedure file's errors carry its own name and line.
  const std::string dir = fmt::format("/tmp/calib-config-{}", ::getpid());
  std::filesystem::create_directories(dir);
  std::ofstream(dir + "/bad.yaml") << "procedure: hand_eye\ncamera_id: ibm7545_eye\n"
                                      "board: {columns: 1, rows: 4, square_mm: 7}\n"
                                      "pose_set: {generate: true, count: 2, joint_ranges: []}\n";
  auto e = load_config(*config::load_string(
      base_yaml("/tmp/x", "procedures: [" + dir + "/bad.yaml]\n"), "calibration.yaml"));
  ASSERT_FALSE(e);
  EXPECT_THAT(e.error().message, HasSubstr(dir + "/bad.yaml:3:"));
  EXPECT_THAT(e.error().message, HasSubstr("2..64"));
  EXPECT_THAT(e.error().message, HasSubstr("count"));
  std::filesystem::remove_all(dir);
}

TEST(CalibrationConfig, TheShippedConfigLoads) {
  auto doc = config::load_file(cell::testing::source_dir() + "/config/calibration.yaml");
  ASSERT_THAT(doc, IsOk());
  ::setenv("CELL_HOME", cell::testing::source_dir().c_str(), 1);
  auto c = load_config(*doc);
  ASSERT_THAT(c, IsOk());
  EXPECT_EQ(c->cameras.size(), 3U);  // the 7545 eye, belt_cam, assembly_cam
  ASSERT_NE(c->hand_eye_for("ibm7545_eye"), nullptr);
  EXPECT_TRUE(c->hand_eye_for("ibm7545_eye")->options.planar);
  ASSERT_NE(c->belt_for("belt1"), nullptr);
  EXPECT_EQ(c->belt_for("belt1")->sim.markers.size(), 3U);
  // The sim scene it would load is a valid scene with the board's black squares on the table.
  const HandEyeProcedure& p = *c->hand_eye_for("ibm7545_eye");
  const std::string scene = sim_scene_yaml(p.sim, &p.capture.board);
  const world::Catalogue catalogue = world::Catalogue::standard();
  auto parsed = world::parse_scene(scene, "<calibration scene>", catalogue);
  ASSERT_THAT(parsed, IsOk());
  EXPECT_EQ(parsed->parts.size(), 15U);  // 6 x 5 squares, half black
  // The world accepts it: diagonal neighbours do not touch, nothing overlaps.
  EXPECT_THAT(world::World::create(*parsed, catalogue, {}), IsOk());
}

class CalibrationServiceTest : public ::testing::Test {
 protected:
  CalibrationServiceTest()
      : domain_(cell::testing::test_domain_id()),
        partition_(cell::testing::unique_partition()),
        dir_(std::filesystem::temp_directory_path() /
             fmt::format("calib-service-{}-{}", ::getpid(), counter_++)),
        client_(domain_, partition_) {}
  ~CalibrationServiceTest() override {
    service_.reset();
    std::error_code ec;
    std::filesystem::remove_all(dir_, ec);
  }

  void start(const std::string& extra = {}) {
    auto c = load_config(*config::load_string(base_yaml((dir_ / "store").string(), extra),
                                              "calibration.yaml"));
    ASSERT_THAT(c, IsOk());
    service_ = std::make_unique<cell::testing::ServiceHarness<CalibrationConfig, CalibrationService>>(
        domain_, partition_, *c, "calibration");
    requester_ = std::make_unique<
        bus::Requester<cell_calibration_CalibrationRequest, cell_calibration_CalibrationResult>>(
        client_, bus::topics::kCalibrationRequest, bus::topics::kCalibrationResult,
        bus::make_client_id("test"));
  }

  struct Req {
    cell_calibration_CalibrationProcedure procedure = cell_calibration_PROCEDURE_SHOW;
    std::string camera;
    std::string belt;
    std::string images;
    std::string version;
    std::string board_kind;
    std::uint32_t columns = 0;
    std::uint32_t rows = 0;
    double square_mm = 0.0;
  };

  std::uint64_t send(const Req& q) {
    cell_calibration_CalibrationRequest r{};
    const std::string empty;
    r.procedure = q.procedure;
    r.camera_id = bus::borrow(q.camera);
    r.belt_id = bus::borrow(q.belt);
    r.robot_id = bus::borrow(empty);
    r.images_dir = bus::borrow(q.images);
    r.version = bus::borrow(q.version);
    r.target.kind = bus::borrow(q.board_kind);
    r.target.columns = q.columns;
    r.target.rows = q.rows;
    r.target.square_mm = q.square_mm;
    r.target.dictionary = bus::borrow(empty);
    auto seq = requester_->send(r, 5s);
    EXPECT_THAT(seq, IsOk());
    return seq.value_or(0);
  }

  bus::Owned<cell_calibration_CalibrationResult> result_of(std::uint64_t seq, double wait_s = 120) {
    auto r = requester_->wait_reply(
        seq, std::chrono::steady_clock::now() + std::chrono::milliseconds(static_cast<long>(wait_s * 1000)));
    EXPECT_THAT(r, IsOk());
    return r ? std::move(*r) : bus::Owned<cell_calibration_CalibrationResult>{};
  }

  bus::Owned<cell_calibration_CalibrationResult> call(const Req& q, double wait_s = 120) {
    return result_of(send(q), wait_s);
  }

  /// The latest published calibration of `camera` (a late-joining reader: transient-local).
  std::optional<calibration::CameraCalibration> published(const std::string& camera) {
    bus::Topic<cell_calibration_CameraCalibration> topic(client_, bus::topics::kCameraCalibration);
    bus::Reader<cell_calibration_CameraCalibration> reader(client_, topic,
                                                           bus::topics::kCameraCalibration);
    std::optional<calibration::CameraCalibration> out;
    (void)eventually(
        [&] {
          (void)reader.read_each([&](const cell_calibration_CameraCalibration& s, const auto&) {
            if (bus::str(s.camera_id) == camera) {
              if (auto c = calibration::from_idl(s); c) {
                out = *c;
              }
            }
          });
          return out.has_value();
        },
        5s);
    return out;
  }

  /// A recorded hand-eye data set of the 7545's camera (images + poses.yaml): the core's
  /// scenario rendered through the truth, joints in degrees as the robot file has them.
  calibration::testing::HandEyeScenario write_data_set(const std::filesystem::path& dir, bool still) {
    calibration::testing::HandEyeScenario s = calibration::testing::ibm7545_eye_in_hand(16, 0.0, 0.0, 0.0, 31);
    std::filesystem::create_directories(dir);
    std::ofstream poses(dir / "poses.yaml");
    poses << fmt::format("robot_id: ibm7545\ntarget_z_mm: {:.6f}\nsamples:\n",
                         s.options.planar_target_z_mm);
    const auto camera = render::load_camera(cell::testing::source_dir() +
                                            "/config/cameras/ibm7545_eye.yaml")
                            .value();
    for (std::size_t i = 0; i < s.samples.size(); ++i) {
      // Re-render at full quality (the scenario keeps only detections).
      const Eigen::Isometry3d world_T_camera =
          camera.robot.world_T_base * s.true_mount[i] * s.truth_extrinsics;
      render::Scene scene;
      scene.table_height_mm = 750.0;
      scene.lights.fluorescent_on = false;
      scene.lights.lamp_on = false;
      scene.targets.push_back(
          calibration::testing::chessboard_target(s.board, camera.robot.world_T_base * s.truth_target));
      render::Lighting light;
      light.ambient = 0.9;
      const cv::Mat image = calibration::testing::render_view(s.camera, light, scene, world_T_camera, 1.0, i);
      const std::string name = fmt::format("pose{:02d}.png", i);
      cv::imwrite((dir / name).string(), image);
      const auto& q = still ? s.joints[0] : s.joints[i];
      poses << fmt::format("  - {{image: {}, stamp_ns: {}, robot_stamp_ns: {}, joints: [{:.9f}, "
                           "{:.9f}, 0, 0]}}\n",
                           name, 1000000000LL * (i + 1), 1000000000LL * (i + 1), q[0] / kDeg,
                           q[1] / kDeg);
    }
    return s;
  }

  /// Puts calibrated intrinsics (the truth's) in the store, as an intrinsics run would.
  void store_true_intrinsics() {
    const auto camera = render::load_camera(cell::testing::source_dir() +
                                            "/config/cameras/ibm7545_eye.yaml")
                            .value();
    calibration::CameraCalibration c = service_->service().current_camera("ibm7545_eye");
    const auto& m = camera.truth.model;
    c.pinhole = {m.fx_px(), m.fy_px(), m.cx_px(), m.cy_px(), m.distortion()};
    c.source = "intrinsics: the truth (test)";
    calibration::CalibrationStore store((dir_ / "store").string());
    ASSERT_THAT(store.add_camera(c), IsOk());
  }

  static inline int counter_ = 0;
  std::uint32_t domain_;
  std::string partition_;
  std::filesystem::path dir_;
  bus::Participant client_;
  std::unique_ptr<cell::testing::ServiceHarness<CalibrationConfig, CalibrationService>> service_;
  std::unique_ptr<
      bus::Requester<cell_calibration_CalibrationRequest, cell_calibration_CalibrationResult>>
      requester_;
};

TEST_F(CalibrationServiceTest, PublishesTheNominalCalibrationsToLateJoiners) {
  start();
  std::this_thread::sleep_for(300ms);  // publish, then join late
  auto eye = published("ibm7545_eye");
  ASSERT_TRUE(eye);
  EXPECT_EQ(eye->pinhole.fx_px, 1495.2);  // the camera file's nominal
  EXPECT_THAT(eye->source, HasSubstr("nominal"));
  auto belt = published("belt_cam");
  ASSERT_TRUE(belt);
  EXPECT_EQ(belt->robot_id, "scara_picker");
  EXPECT_NEAR(belt->extrinsics.translation().z(), 800.0, 1e-9);
}

TEST_F(CalibrationServiceTest, EveryRequestIsAnsweredWithTheReason) {
  start();
  // An enum value no enumerator has never leaves a writer (Cyclone refuses to serialise it);
  // the service names any it would receive.
  EXPECT_EQ(procedure_name(cell_calibration_PROCEDURE_CANCEL), "cancel");
  Req cam;
  cam.procedure = cell_calibration_PROCEDURE_HAND_EYE;
  cam.camera = "nope";
  auto r = call(cam, 10);
  EXPECT_FALSE(r->status.accepted);
  EXPECT_THAT(std::string(bus::str(r->status.reason)), HasSubstr("unknown camera 'nope'"));
  Req belt;
  belt.procedure = cell_calibration_PROCEDURE_BELT;
  belt.belt = "belt1";
  r = call(belt, 10);
  EXPECT_FALSE(r->status.accepted);
  EXPECT_THAT(std::string(bus::str(r->status.reason)), HasSubstr("no procedure for belt 'belt1'"));
  Req bad_board;
  bad_board.procedure = cell_calibration_PROCEDURE_INTRINSICS;
  bad_board.images = "/tmp";
  bad_board.columns = 1;
  bad_board.rows = 6;
  bad_board.square_mm = 10;
  r = call(bad_board, 10);
  EXPECT_FALSE(r->status.accepted);
  EXPECT_THAT(std::string(bus::str(r->status.reason)), HasSubstr("target: board: 1x6"));
  Req rollback;
  rollback.procedure = cell_calibration_PROCEDURE_ROLLBACK;
  rollback.camera = "ibm7545_eye";
  rollback.version = "3";
  r = call(rollback, 10);
  EXPECT_FALSE(r->status.accepted);
  EXPECT_THAT(std::string(bus::str(r->status.reason)), HasSubstr("has no version '3'"));
}

// The full chain from a recorded data set, against the camera file's truth: the calibrated
// camera maps the table at the thesis's grab pose to 0.2 mm.
TEST_F(CalibrationServiceTest, HandEyeFromADataSetStoresPublishesAndMapsTheTable) {
  start();
  store_true_intrinsics();
  const calibration::testing::HandEyeScenario s = write_data_set(dir_ / "data", false);
  Req q;
  q.procedure = cell_calibration_PROCEDURE_HAND_EYE;
  q.camera = "ibm7545_eye";
  q.images = (dir_ / "data").string();
  q.board_kind = "chessboard";
  q.columns = static_cast<std::uint32_t>(s.board.columns);
  q.rows = static_cast<std::uint32_t>(s.board.rows);
  q.square_mm = s.board.square_mm;
  auto r = call(q, 180);
  ASSERT_TRUE(r->status.accepted) << bus::str(r->status.reason);
  EXPECT_TRUE(r->stored);
  EXPECT_THAT(std::string(bus::str(r->version)), ::testing::EndsWith("#2"));
  EXPECT_GT(r->holdout_mm, 0.0);
  EXPECT_THAT(std::string(bus::str(r->details)), HasSubstr("closed_forms"));
  auto c = published("ibm7545_eye");
  ASSERT_TRUE(c);
  EXPECT_EQ(c->version, std::string(bus::str(r->version)));
  // The table at the grab pose through the published calibration and through the truth.
  const auto robot = calibration::testing::robot_file("ibm7545.yaml");
  kinematics::JointVector grab(4);
  grab << 45.0 * kDeg, 105.0 * kDeg, 0.0, 0.0;
  const Eigen::Isometry3d mount =
      render::base_T_mount(robot, render::MountFrame::kLink2, grab).value();
  double worst = 0.0;
  for (int i = 0; i <= 8; ++i) {
    for (int j = 0; j <= 8; ++j) {
      const Eigen::Vector2d px(511.0 * i / 8, 483.0 * j / 8);
      auto mine = calibration::pixel_to_base(*c, &robot, grab, px);
      auto truth = calibration::pixel_to_plane(s.camera, mount * s.truth_extrinsics, px, -231.51);
      ASSERT_THAT(mine, IsOk());
      ASSERT_THAT(truth, IsOk());
      worst = std::max(worst, (*mine - *truth).norm());
    }
  }
  EXPECT_LT(worst, 0.2);
  ::testing::Test::RecordProperty("grab_pose_table_mapping_mm", fmt::format("{:.3f}", worst));
}

TEST_F(CalibrationServiceTest, ARobotThatNeverMovedFailsAndTheCurrentCalibrationStays) {
  start();
  store_true_intrinsics();
  write_data_set(dir_ / "still", true);
  auto before = published("ibm7545_eye");
  ASSERT_TRUE(before);
  Req q;
  q.procedure = cell_calibration_PROCEDURE_HAND_EYE;
  q.camera = "ibm7545_eye";
  q.images = (dir_ / "still").string();
  q.board_kind = "chessboard";
  q.columns = 5;
  q.rows = 4;
  q.square_mm = 7.0;
  auto r = call(q, 120);
  EXPECT_FALSE(r->status.accepted);
  EXPECT_THAT(std::string(bus::str(r->status.reason)), HasSubstr("the robot never moved"));
  EXPECT_FALSE(r->stored);
  EXPECT_EQ(service_->service().store().list()->size(), 1U);  // only the intrinsics
  auto after = published("ibm7545_eye");
  ASSERT_TRUE(after);
  EXPECT_EQ(after->version, before->version);
}

// A guided procedure with nobody to move the robot: a second request meanwhile is refused as
// busy, and a cancel ends the first with a failure (no motion service: it times out anyway).
TEST_F(CalibrationServiceTest, OneProcedureAtATimeAndCancel) {
  const std::string proc = (dir_ / "he.yaml").string();
  std::filesystem::create_directories(dir_);
  std::ofstream(proc) << "procedure: hand_eye\ncamera_id: ibm7545_eye\nrobot_id: ibm7545\n"
                         "board: {columns: 5, rows: 4, square_mm: 7}\n"
                         "board_nominal: {xyz_mm: [305, 547.5, -231.31], rpy_deg: [0, 0, 24]}\n"
                         "pose_set: {poses: [[40, 20, 0, 0], [45, 25, 0, 0], [50, 20, 0, 0]]}\n";
  start("procedures: [" + proc + "]\n");
  store_true_intrinsics();
  Req q;
  q.procedure = cell_calibration_PROCEDURE_HAND_EYE;
  q.camera = "ibm7545_eye";
  const std::uint64_t first = send(q);
  std::this_thread::sleep_for(200ms);
  auto busy = call(q, 10);
  EXPECT_FALSE(busy->status.accepted);
  EXPECT_THAT(std::string(bus::str(busy->status.reason)), HasSubstr("busy: hand_eye of 'ibm7545_eye'"));
  Req cancel;
  cancel.procedure = cell_calibration_PROCEDURE_CANCEL;
  auto c = call(cancel, 10);
  EXPECT_TRUE(c->status.accepted) << bus::str(c->status.reason);
  auto r = result_of(first, 30);
  EXPECT_FALSE(r->status.accepted);
  const std::string reason(bus::str(r->status.reason));
  EXPECT_TRUE(reason.find("cancelled") != std::string::npos ||
              reason.find("is cell-motion running") != std::string::npos)
      << reason;
  EXPECT_EQ(service_->service().store().list()->size(), 1U);
}

}  // namespace
}  // namespace cell::calibration_service
