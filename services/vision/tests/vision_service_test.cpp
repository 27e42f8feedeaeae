// The vision service in-process on a private bus: the test plays the camera, the calibration
// service and a RAPT client. Images are the world simulator's renders (core/vision/tests).
#include "vision_service.hpp"

#include <fmt/format.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <chrono>
#include <numbers>
#include <optional>

#include "cell/bus/view.hpp"
#include "cell/common/time.hpp"
#include "cell/config/yaml.hpp"
#include "cell/testing/env.hpp"
#include "cell/testing/matchers.hpp"
#include "cell/testing/service_harness.hpp"
#include "scenes.hpp"

namespace cell::vision {
namespace {

using ::cell::testing::IsErrWith;
using ::testing::HasSubstr;
using ::testing::Not;
using vision::testing::Cell;
using vision::testing::Lights;

constexpr auto kWait = std::chrono::seconds(10);

Result<VisionConfig> config_from(const std::string& yaml) {
  auto doc = config::load_string(yaml, "vision.yaml");
  if (!doc) {
    return doc.error();
  }
  return load_config(*doc);
}

VisionConfig test_config(double edge_timeout_s = 2.0) {
  const std::string home = vision::testing::Cell::get().camera().path;  // .../ibm7545_eye.yaml
  auto c = config_from(
      fmt::format("service: {{id: vision}}\n"
                  "cameras:\n"
                  "  - {{id: ibm7545_eye, camera_file: {}, working_plane_z_mm: -231.51}}\n"
                  "camera_dir: {}/config/cameras\n"
                  "robot_dir: {}/config/robots\n"
                  "history_frames: 3\n"
                  "edge_image_timeout_s: {}\n",
                  home, cell::testing::source_dir(), cell::testing::source_dir(), edge_timeout_s));
  EXPECT_TRUE(c) << c.error().message;
  return *c;
}

TEST(VisionConfig, TheShippedConfigLoads) {
  auto doc = config::load_file(cell::testing::source_dir() + "/config/vision.yaml");
  ASSERT_TRUE(doc) << doc.error().message;
  const auto c = load_config(*doc);
  ASSERT_TRUE(c) << c.error().message;
  EXPECT_EQ(c->common.service_id, "vision");
  ASSERT_NE(c->camera("ibm7545_eye"), nullptr);
  EXPECT_DOUBLE_EQ(c->camera("ibm7545_eye")->working_plane_z_mm, -231.51);
  ASSERT_NE(c->camera("belt_cam"), nullptr);
  EXPECT_EQ(c->camera("belt_cam")->robot_id, "scara_picker");
  EXPECT_NEAR(c->camera("belt_cam")->world_T_base.translation().x(), 1000.0, 1e-12);
  EXPECT_FALSE(c->locate.grasps.empty());
  // The belt camera's own locate keys over the global section; the 7545's uses the section.
  EXPECT_FALSE(c->camera("ibm7545_eye")->locate.has_value());
  ASSERT_TRUE(c->camera("belt_cam")->locate.has_value());
  EXPECT_DOUBLE_EQ(c->camera("belt_cam")->locate->max_fit_rms_px, 0.6);
  EXPECT_DOUBLE_EQ(c->locate.max_fit_rms_px, 0.35);
  EXPECT_EQ(c->camera("belt_cam")->locate->grasps.size(), c->locate.grasps.size());
}

TEST(VisionConfig, ACamerasLocateKeysGoOverTheGlobalOnesAndAreChecked) {
  const auto c = config_from(
      "service: {id: vision}\n"
      "cameras:\n"
      "  - {id: a, working_plane_z_mm: 0, locate: {max_fit_rms_px: 0.5}}\n"
      "locate: {pipeline: thesis, max_fit_rms_px: 0.3}\n");
  ASSERT_TRUE(c) << c.error().message;
  ASSERT_TRUE(c->camera("a")->locate.has_value());
  EXPECT_DOUBLE_EQ(c->camera("a")->locate->max_fit_rms_px, 0.5);
  EXPECT_EQ(c->camera("a")->locate->pipeline, vision::Pipeline::kThesis);
  const auto bad = config_from(
      "service: {id: vision}\n"
      "cameras:\n"
      "  - {id: a, working_plane_z_mm: 0, locate: {max_fit_rms: 0.5}}\n");
  ASSERT_FALSE(bad);
  EXPECT_THAT(bad.error().message, HasSubstr("vision.yaml:3:45: unknown key 'cameras[0].locate.max_fit_rms'"));
}

TEST(VisionConfig, ErrorsNameTheFileLineAndKey) {
  const auto c = config_from(
      "service: {id: vision}\n"
      "cameras:\n"
      "  - {id: a, working_plane_z_mm: 0}\n"
      "  - {id: a}\n"
      "history_frames: 0\n"
      "histroy: 3\n"
      "locate: {pipeline: slow}\n");
  ASSERT_FALSE(c);
  EXPECT_EQ(c.error().code, Errc::kConfig);
  const std::string& m = c.error().message;
  EXPECT_THAT(m, HasSubstr("camera 'a' is listed twice"));
  EXPECT_THAT(m, HasSubstr("missing required key 'cameras[1].working_plane_z_mm'"));
  EXPECT_THAT(m, HasSubstr("vision.yaml:5:17: key 'history_frames': must be in 1..256, got 0"));
  EXPECT_THAT(m, HasSubstr("vision.yaml:6:1: unknown key 'histroy'"));
  EXPECT_THAT(m, HasSubstr("unknown pipeline 'slow'"));
}

constexpr std::uint32_t kAsImage = 0xFFFFFFFF;

/// The test's side of the bus.
class Peer {
 public:
  Peer(std::uint32_t domain, const std::string& partition)
      : participant_(domain, partition),
        image_topic_(participant_, bus::topics::kImage),
        detections_topic_(participant_, bus::topics::kDetections),
        edge_request_topic_(participant_, bus::topics::kEdgeRequest),
        edge_result_topic_(participant_, bus::topics::kEdgeResult),
        calibration_topic_(participant_, bus::topics::kCameraCalibration),
        images(participant_, image_topic_, bus::topics::kImage),
        edges(participant_, edge_request_topic_, bus::topics::kEdgeRequest),
        calibrations(participant_, calibration_topic_, bus::topics::kCameraCalibration),
        detections(participant_, detections_topic_, bus::topics::kDetections),
        results(participant_, edge_result_topic_, bus::topics::kEdgeResult) {}

  void wait_matched() const {
    ASSERT_TRUE(images.wait_for_readers(1, kWait));
    ASSERT_TRUE(edges.wait_for_readers(1, kWait));
    ASSERT_TRUE(calibrations.wait_for_readers(1, kWait));
    ASSERT_TRUE(detections.wait_for_writers(1, kWait));
    ASSERT_TRUE(results.wait_for_writers(1, kWait));
  }

  /// Publishes a mono8 image; returns its sequence number.
  std::uint64_t publish(const cv::Mat& image,
                        const std::vector<double>& joints,
                        const std::string& camera = "ibm7545_eye",
                        const std::string& encoding = "mono8",
                        std::uint32_t width = kAsImage,
                        std::uint32_t height = kAsImage,
                        std::size_t truncate_to = SIZE_MAX) {
    static const std::string kRobot = "ibm7545";
    static const std::string kEmpty;
    cell_vision_Image img{};
    img.camera_id = bus::borrow(camera);
    img.request_id.client_id = bus::borrow(kEmpty);
    img.header.stamp_ns = wall_time_ns();
    img.header.frame_id = bus::borrow(camera);
    img.header.seq = ++seq_;
    img.width_px = width != kAsImage ? width : static_cast<std::uint32_t>(image.cols);
    img.height_px = height != kAsImage ? height : static_cast<std::uint32_t>(image.rows);
    img.encoding = bus::borrow(encoding);
    img.step_bytes = static_cast<std::uint32_t>(image.step[0]);
    img.data._buffer = image.data;
    img.data._length = static_cast<std::uint32_t>(
        std::min<std::size_t>(truncate_to, image.step[0] * static_cast<std::size_t>(image.rows)));
    img.data._maximum = img.data._length;
    img.data._release = false;
    bus::borrow(img.robot_joints_rad_or_mm, joints);
    img.robot_id = bus::borrow(kRobot);
    img.belt_id = bus::borrow(kEmpty);
    img.belt_count = 42;
    EXPECT_TRUE(images.write(img));
    return seq_;
  }

  void publish(const calibration::CameraCalibration& c) const {
    calibration::IdlHolder holder;
    const auto sample = calibration::to_idl(c, holder, wall_time_ns());
    EXPECT_TRUE(calibrations.write(sample));
  }

  std::uint64_t request_edge(const Eigen::Vector2d& a,
                             const Eigen::Vector2d& b,
                             double tol,
                             std::uint64_t image_sequence,
                             const std::string& camera = "ibm7545_eye") {
    cell_vision_EdgeRequest r{};
    r.request_id.client_id = bus::borrow(client_);
    r.request_id.seq = ++request_seq_;
    r.camera_id = bus::borrow(camera);
    r.predicted_start_px = {a.x(), a.y()};
    r.predicted_end_px = {b.x(), b.y()};
    r.search_halfwidth_px = tol;
    r.image_sequence = image_sequence;
    EXPECT_TRUE(edges.write(r));
    return request_seq_;
  }

  /// Waits for a sample matching `pred`; samples that do not match are kept for later calls.
  template <typename T, typename Pred>
  std::optional<bus::Owned<T>> wait_for(bus::Reader<T>& reader,
                                        std::vector<bus::Owned<T>>& kept,
                                        Pred&& pred,
                                        std::chrono::milliseconds timeout = kWait) {
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    for (;;) {
      for (auto it = kept.begin(); it != kept.end(); ++it) {
        if (pred(it->get())) {
          auto found = std::move(*it);
          kept.erase(it);
          return found;
        }
      }
      if (std::chrono::steady_clock::now() >= deadline) {
        return std::nullopt;
      }
      (void)reader.wait_for_data(std::chrono::milliseconds(50));
      auto batch = reader.take_copies(16);
      if (batch) {
        for (auto& sample : *batch) {
          kept.push_back(std::move(sample));
        }
      }
    }
  }

  std::optional<bus::Owned<cell_vision_Detections>> detections_of(
      std::uint64_t seq, const std::string& calib_has = "") {
    return wait_for(detections, kept_detections_, [&](const cell_vision_Detections& d) {
      return d.image_sequence == seq &&
             std::string(bus::str(d.calibration)).find(calib_has) != std::string::npos;
    });
  }

  std::optional<bus::Owned<cell_vision_EdgeResult>> result_of(
      std::uint64_t request, std::chrono::milliseconds timeout = kWait) {
    return wait_for(
        results, kept_results_,
        [&](const cell_vision_EdgeResult& r) {
          return r.request_id.seq == request && bus::str(r.request_id.client_id) == client_;
        },
        timeout);
  }

 private:
  bus::Participant participant_;
  bus::Topic<cell_vision_Image> image_topic_;
  bus::Topic<cell_vision_Detections> detections_topic_;
  bus::Topic<cell_vision_EdgeRequest> edge_request_topic_;
  bus::Topic<cell_vision_EdgeResult> edge_result_topic_;
  bus::Topic<cell_calibration_CameraCalibration> calibration_topic_;

 public:
  bus::Writer<cell_vision_Image> images;
  bus::Writer<cell_vision_EdgeRequest> edges;
  bus::Writer<cell_calibration_CameraCalibration> calibrations;
  bus::Reader<cell_vision_Detections> detections;
  bus::Reader<cell_vision_EdgeResult> results;

 private:
  std::vector<bus::Owned<cell_vision_Detections>> kept_detections_;
  std::vector<bus::Owned<cell_vision_EdgeResult>> kept_results_;
  std::uint64_t seq_ = 0;
  std::uint64_t request_seq_ = 0;
  std::string client_ = "vision_service_test";
};

class VisionServiceTest : public ::testing::Test {
 protected:
  VisionServiceTest()
      : domain_(cell::testing::test_domain_id()), partition_(cell::testing::unique_partition()) {}

  void start(VisionConfig config) {
    harness_.emplace(domain_, partition_, std::move(config), "vision");
    peer_.emplace(domain_, partition_);
    peer_->wait_matched();
  }

  double world_error_mm(const cell_vision_Detections& d, const vision::testing::RenderedScene& f) {
    double worst = 0.0;
    const Cell& cell = Cell::get();
    for (const auto& t : f.truth) {
      const Eigen::Vector3d base = cell.world_T_base().inverse() * t.world_T_part.translation();
      double best = 1e9;
      for (const auto& item : bus::span(d.items)) {
        if (item.has_base_pose) {
          best = std::min(
              best, std::hypot(item.base_pose.x_mm - base.x(), item.base_pose.y_mm - base.y()));
        }
      }
      worst = std::max(worst, best);
    }
    return worst;
  }

  std::uint32_t domain_;
  std::string partition_;
  std::optional<cell::testing::ServiceHarness<VisionConfig, VisionService>> harness_;
  std::optional<Peer> peer_;
};

// Until a calibration is published the camera file's nominal one maps the parts (a few mm
// off the truth: the mount really differs); a published calibration re-maps the last image at
// once and the poses land on the truth.
TEST_F(VisionServiceTest, DetectsWithTheNominalCalibrationThenRemapsWithThePublishedOne) {
  start(test_config());
  const Cell& cell = Cell::get();
  vision::testing::ScatterRequest req;
  req.count = 15;
  req.seed = 5;
  const auto frame = cell.scatter(req);
  const std::uint64_t seq = peer_->publish(frame.image, frame.joints);
  auto nominal = peer_->detections_of(seq);
  ASSERT_TRUE(nominal);
  const cell_vision_Detections& d = nominal->get();
  EXPECT_EQ(bus::str(d.error), "");
  EXPECT_EQ(bus::span(d.items).size(), 15U);
  EXPECT_THAT(std::string(bus::str(d.calibration)), HasSubstr("NOMINAL"));
  EXPECT_EQ(bus::str(d.pipeline), "fast");
  EXPECT_EQ(bus::str(d.robot_id), "ibm7545");
  EXPECT_EQ(d.belt_count, 42);
  EXPECT_EQ(bus::str(d.header.frame_id), "ibm7545/base");
  EXPECT_EQ(bus::span(d.robot_joints_rad_or_mm).size(), 4U);
  const double nominal_error = world_error_mm(d, frame);
  EXPECT_GT(nominal_error, 3.0);
  for (const auto& item : bus::span(d.items)) {
    EXPECT_TRUE(item.has_base_pose);
    EXPECT_EQ(bus::span(item.corners_px).size(), 4U);
    EXPECT_GT(item.quality, 0.3);
    EXPECT_EQ(bus::str(item.shape), "rectangle");
  }
  // The calibration service publishes what it found (here: the truth).
  peer_->publish(cell.true_calibration());
  auto remapped = peer_->detections_of(seq, "calibration truth");
  ASSERT_TRUE(remapped) << "no re-mapped detections of image " << seq;
  EXPECT_EQ(bus::span(remapped->get().items).size(), 15U);
  EXPECT_THAT(std::string(bus::str(remapped->get().calibration)), Not(HasSubstr("NOMINAL")));
  EXPECT_LT(world_error_mm(remapped->get(), frame), 0.1);
  // And the next image uses it too.
  const std::uint64_t next = peer_->publish(frame.image, frame.joints);
  auto after = peer_->detections_of(next, "calibration truth");
  ASSERT_TRUE(after);
  EXPECT_LT(world_error_mm(after->get(), frame), 0.1);
}

// Bad images are answered with Detections carrying the reason, and the service keeps serving.
TEST_F(VisionServiceTest, MalformedImagesGetAnErrorAndTheServiceKeepsServing) {
  start(test_config());
  const Cell& cell = Cell::get();
  const auto frame = cell.render("one", {cell.part("a", "dip14", 45.0, 404.0, 0.5, true)},
                                 cell.aligned_joints(), Lights::kTubes, 3);
  // (One at a time: the image stream keeps the last 2 frames per camera, as a camera's should.)
  auto expect_error = [&](std::uint64_t seq, const std::string& expect) {
    auto d = peer_->detections_of(seq);
    ASSERT_TRUE(d) << expect;
    EXPECT_THAT(std::string(bus::str(d->get().error)), HasSubstr(expect));
    EXPECT_EQ(bus::span(d->get().items).size(), 0U);
  };
  expect_error(
      peer_->publish(frame.image, frame.joints, "ibm7545_eye", "mono8", kAsImage, kAsImage, 1000),
      "image data truncated: 1000 of 247808 bytes");
  expect_error(peer_->publish(frame.image, frame.joints, "ibm7545_eye", "yuv422"),
               "encoding 'yuv422' is not supported");
  expect_error(peer_->publish(frame.image, frame.joints, "ibm7545_eye", "mono8", 0, 484),
               "image size 0 x 484 px");
  const cv::Mat small = frame.image(cv::Rect(0, 0, 320, 240)).clone();
  expect_error(peer_->publish(small, frame.joints),
               "image is 320 x 240 px but the calibration of 'ibm7545_eye' is for 512 x 484");
  expect_error(peer_->publish(frame.image, frame.joints, "no_such_camera"),
               "unknown camera 'no_such_camera'");
  expect_error(peer_->publish(frame.image, frame.joints, ""), "names no camera");
  // Still serving: a good frame, and an empty one.
  const std::uint64_t good = peer_->publish(frame.image, frame.joints);
  auto d = peer_->detections_of(good);
  ASSERT_TRUE(d);
  EXPECT_EQ(bus::str(d->get().error), "");
  ASSERT_EQ(bus::span(d->get().items).size(), 1U);
  EXPECT_EQ(bus::str(bus::span(d->get().items)[0].class_name), "dip14");
  const auto empty = cell.render("empty", {}, cell.aligned_joints(), Lights::kTubes, 4);
  const std::uint64_t none = peer_->publish(empty.image, empty.joints);
  auto e = peer_->detections_of(none);
  ASSERT_TRUE(e);
  EXPECT_EQ(bus::str(e->get().error), "");
  EXPECT_EQ(bus::span(e->get().items).size(), 0U);
}

// Detections carry every clear grasp style in the robot's base frame: a lone dip14 both its
// styles ("across": the tool where base_pose is, yaw along the part; "ends": turned by -90 deg),
// a dip14 with a dip8 in its "across" fingerprint only "ends"; a class with no grasp model none.
TEST_F(VisionServiceTest, DetectionsListEveryClearGraspInTheBaseFrame) {
  constexpr double kDeg = std::numbers::pi / 180.0;
  VisionConfig config = test_config();
  config.locate.grasps = {vision::testing::dip14_grasp_model()};
  start(config);
  const Cell& cell = Cell::get();
  const auto scenes = cell.clear_grasp_scenes();
  for (std::size_t k = 0; k < scenes.size(); ++k) {
    const std::vector<std::string>& expected = scenes[k].clear;
    const auto frame = cell.render(fmt::format("grasps {}", k), scenes[k].parts,
                                   cell.aligned_joints(), Lights::kTubes, 50 + k);
    auto d = peer_->detections_of(peer_->publish(frame.image, frame.joints));
    ASSERT_TRUE(d);
    ASSERT_EQ(bus::span(d->get().items).size(), scenes[k].parts.size());
    for (const auto& item : bus::span(d->get().items)) {
      const auto grasps = bus::span(item.clear_grasps);
      if (bus::str(item.class_name) != "dip14") {
        EXPECT_EQ(item.grip, cell_vision_GRIP_NOT_TESTED);
        EXPECT_TRUE(grasps.empty());
        continue;
      }
      ASSERT_TRUE(item.has_base_pose);
      EXPECT_EQ(item.grip, cell_vision_GRIP_CLEAR) << bus::str(item.grip_detail);
      EXPECT_EQ(item.grip_style, k == 0 ? 0 : 1);
      ASSERT_EQ(grasps.size(), expected.size()) << bus::str(item.grip_detail);
      EXPECT_EQ(grasps[0].style, item.grip_style);
      for (std::size_t i = 0; i < grasps.size(); ++i) {
        const auto& g = grasps[i];
        EXPECT_EQ(bus::str(g.name), expected[i]);
        EXPECT_EQ(g.style, expected[i] == "across" ? 0 : 1);
        const double turn = expected[i] == "across" ? 0.0 : -90.0 * kDeg;
        EXPECT_NEAR(g.base_pose.x_mm, item.base_pose.x_mm, 1e-9);
        EXPECT_NEAR(g.base_pose.y_mm, item.base_pose.y_mm, 1e-9);
        EXPECT_NEAR(angle_error(g.base_pose.rz_rad, item.base_pose.rz_rad + turn, 2), 0.0, 1e-9)
            << bus::str(g.name);
      }
    }
  }
}

// Every EdgeRequest gets an EdgeResult: measured on a held image, on the next image, or refused
// with the reason.
TEST_F(VisionServiceTest, EveryEdgeRequestIsAnswered) {
  start(test_config(0.5));
  const Cell& cell = Cell::get();
  const Eigen::Vector2d c = cell.window(30.0).center();
  const auto frame = cell.render("edge", {cell.part("r", "rectangle", c.x(), c.y(), 0.35, false)},
                                 cell.aligned_joints(), Lights::kTubes, 7);
  const auto& k = frame.truth[0].corners_px;
  const Eigen::Vector2d n = Eigen::Vector2d(-(k[1] - k[0]).y(), (k[1] - k[0]).x()).normalized();
  const Eigen::Vector2d a = k[0] + 1.5 * n;
  const Eigen::Vector2d b = k[1] + 1.5 * n;
  const std::uint64_t seq = peer_->publish(frame.image, frame.joints);
  ASSERT_TRUE(peer_->detections_of(seq));
  // On the held image, by sequence.
  auto r = peer_->result_of(peer_->request_edge(a, b, 5.0, seq));
  ASSERT_TRUE(r);
  EXPECT_TRUE(r->get().status.accepted) << bus::str(r->get().status.reason);
  EXPECT_EQ(r->get().image_sequence, seq);
  const Eigen::Vector2d s(r->get().start_px.u_px, r->get().start_px.v_px);
  const Eigen::Vector2d e(r->get().end_px.u_px, r->get().end_px.v_px);
  EXPECT_LT(std::abs((s - k[0]).dot(n)), 0.1);
  EXPECT_LT(std::abs((e - k[0]).dot(n)), 0.1);
  EXPECT_GT(r->get().point_count, 20U);
  EXPECT_GT(std::abs(r->get().window_p3_px.u_px - r->get().window_p1_px.u_px) +
                std::abs(r->get().window_p3_px.v_px - r->get().window_p1_px.v_px),
            50.0);
  // A window off the image.
  r = peer_->result_of(peer_->request_edge({600, 50}, {700, 60}, 4.0, seq));
  ASSERT_TRUE(r);
  EXPECT_FALSE(r->get().status.accepted);
  EXPECT_EQ(bus::str(r->get().status.error_code), "out_of_range");
  EXPECT_THAT(std::string(bus::str(r->get().status.reason)), HasSubstr("entirely outside"));
  // No edge where predicted.
  r = peer_->result_of(peer_->request_edge({20, 20}, {120, 30}, 4.0, seq));
  ASSERT_TRUE(r);
  EXPECT_FALSE(r->get().status.accepted);
  EXPECT_THAT(std::string(bus::str(r->get().status.reason)), HasSubstr("no edge in the window"));
  // An unknown camera.
  r = peer_->result_of(peer_->request_edge(a, b, 5.0, 0, "cam9"));
  ASSERT_TRUE(r);
  EXPECT_FALSE(r->get().status.accepted);
  EXPECT_THAT(std::string(bus::str(r->get().status.reason)), HasSubstr("unknown camera 'cam9'"));
  // The next image: answered when it comes.
  // (Images keep coming until the answer does: whichever arrives after the request is it.)
  const std::uint64_t waiting = peer_->request_edge(a, b, 5.0, 0);
  std::uint64_t last = seq;
  std::optional<bus::Owned<cell_vision_EdgeResult>> next;
  for (int i = 0; i < 20 && !next; ++i) {
    last = peer_->publish(frame.image, frame.joints);
    next = peer_->result_of(waiting, std::chrono::milliseconds(100));
  }
  ASSERT_TRUE(next);
  EXPECT_TRUE(next->get().status.accepted) << bus::str(next->get().status.reason);
  EXPECT_GT(next->get().image_sequence, seq);
  EXPECT_LE(next->get().image_sequence, last);
  // No image in time: refused when the timeout (0.5 s here) passes.
  r = peer_->result_of(peer_->request_edge(a, b, 5.0, 0));
  ASSERT_TRUE(r);
  EXPECT_FALSE(r->get().status.accepted);
  EXPECT_EQ(bus::str(r->get().status.error_code), "timeout");
  EXPECT_THAT(std::string(bus::str(r->get().status.reason)), HasSubstr("no image from camera"));
  // An image no longer held (history_frames: 3).
  for (int i = 0; i < 3; ++i) {
    ASSERT_TRUE(peer_->detections_of(peer_->publish(frame.image, frame.joints)));
  }
  r = peer_->result_of(peer_->request_edge(a, b, 5.0, seq));
  ASSERT_TRUE(r);
  EXPECT_FALSE(r->get().status.accepted);
  EXPECT_THAT(std::string(bus::str(r->get().status.reason)), HasSubstr("no longer held"));
}

}  // namespace
}  // namespace cell::vision
