// The camera service in-process on a private bus: the test plays the world simulator, the
// gateway and the client.
#include "camera_service.hpp"

#include <atomic>
#include <thread>

#include <fmt/format.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "cell/bus/request_reply.hpp"
#include "cell/common/time.hpp"
#include "cell/geometry/angles.hpp"
#include "cell/testing/env.hpp"
#include "cell/testing/service_harness.hpp"
#include "config_fixtures.hpp"
#include "world_fixtures.hpp"

namespace cell::camera {
namespace {

using ::testing::HasSubstr;
using testing::resting;
using testing::WorldStateWire;

using namespace std::chrono_literals;
constexpr auto kWait = std::chrono::seconds(5);
using geometry::kDeg;

using testing::config_from;

CameraConfig eye_config() {
  const std::string home = cell::testing::source_dir();
  return config_from(fmt::format(
      "service: {{id: camera.eye}}\ncamera_id: ibm7545_eye\nsource: sim\n"
      "camera_file: {0}/config/cameras/ibm7545_eye.yaml\n"
      "sim: {{noise_sigma: 1.0, seed: 3, robot_config: {0}/config/robots/ibm7545.yaml}}\n",
      home));
}

CameraConfig belt_config() {
  const std::string home = cell::testing::source_dir();
  return config_from(fmt::format(
      "service: {{id: camera.belt}}\ncamera_id: belt_cam\nsource: sim\n"
      "camera_file: {0}/config/cameras/belt_cam.yaml\nbelt_id: belt1\n"
      "trigger: {{mode: photocell, photocell_edge: leave, delay_mm: 200, "
      "photocell_timeout_s: 1.0}}\n",
      home));
}

/// The test's side of the bus: a client of the camera, the world and a gateway.
class Bus {
 public:
  Bus(std::uint32_t domain, const std::string& partition)
      : participant_(domain, partition),
        request_topic_(participant_, bus::topics::kImageRequest),
        image_topic_(participant_, bus::topics::kImage),
        truth_topic_(participant_, bus::topics::kImageTruth),
        world_topic_(participant_, bus::topics::kWorldState),
        robot_topic_(participant_, bus::topics::kRobotState),
        belt_topic_(participant_, bus::topics::kBeltState),
        photocell_topic_(participant_, bus::topics::kPhotocell),
        requests(participant_, request_topic_, bus::topics::kImageRequest),
        images(participant_, image_topic_, bus::topics::kImage),
        truths(participant_, truth_topic_, bus::topics::kImageTruth),
        world(participant_, world_topic_, bus::topics::kWorldState),
        robot(participant_, robot_topic_, bus::topics::kRobotState),
        belt(participant_, belt_topic_, bus::topics::kBeltState),
        photocell(participant_, photocell_topic_, bus::topics::kPhotocell) {}

  void wait_matched() const {
    ASSERT_TRUE(requests.wait_for_readers(1, kWait));
    ASSERT_TRUE(images.wait_for_writers(1, kWait));
    ASSERT_TRUE(truths.wait_for_writers(1, kWait));
    ASSERT_TRUE(world.wait_for_readers(1, kWait));
    ASSERT_TRUE(robot.wait_for_readers(1, kWait));
  }

  std::uint64_t request(const std::string& camera, cell_vision_TriggerKind trigger, bool truth) {
    cell_vision_ImageRequest r{};
    r.request_id.client_id = bus::borrow(client_id_);
    r.request_id.seq = ++seq_;
    r.camera_id = bus::borrow(camera);
    r.trigger = trigger;
    r.with_truth = truth;
    EXPECT_TRUE(requests.write(r));
    return seq_;
  }

  void publish_robot(const std::vector<double>& joints, std::int64_t stamp_ns, bool halogen) const {
    static const std::string kId = "ibm7545";
    cell_robot_RobotState s{};
    s.robot_id = bus::borrow(kId);
    s.header.stamp_ns = stamp_ns;
    s.header.frame_id = bus::borrow(kId);
    bus::borrow(s.position_rad_or_mm, joints);
    s.base_T_tool.orientation.w = 1.0;
    s.halogen_on = halogen;
    s.fluorescent_on = true;
    EXPECT_TRUE(robot.write(s));
  }

  template <typename T, typename Pred>
  std::optional<bus::Owned<T>> wait_for(bus::Reader<T>& reader, Pred&& pred,
                                        std::chrono::milliseconds timeout = kWait) {
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    while (std::chrono::steady_clock::now() < deadline) {
      auto batch = reader.take_copies(16);
      if (batch) {
        for (auto& s : *batch) {
          if (pred(s.get())) {
            return std::move(s);
          }
        }
      }
      (void)reader.wait_for_data(std::chrono::milliseconds(20));
    }
    return std::nullopt;
  }

  bool mine(const cell_common_RequestId& id, std::uint64_t seq) const {
    return bus::same_request(id, client_id_, seq);
  }

 private:
  bus::Participant participant_;
  std::string client_id_ = bus::make_client_id("camera-test");
  std::uint64_t seq_ = 0;
  bus::Topic<cell_vision_ImageRequest> request_topic_;
  bus::Topic<cell_vision_Image> image_topic_;
  bus::Topic<cell_vision_ImageTruth> truth_topic_;
  bus::Topic<cell_world_WorldState> world_topic_;
  bus::Topic<cell_robot_RobotState> robot_topic_;
  bus::Topic<cell_world_BeltState> belt_topic_;
  bus::Topic<cell_world_PhotocellEvent> photocell_topic_;

 public:
  bus::Writer<cell_vision_ImageRequest> requests;
  bus::Reader<cell_vision_Image> images;
  bus::Reader<cell_vision_ImageTruth> truths;
  bus::Writer<cell_world_WorldState> world;
  bus::Writer<cell_robot_RobotState> robot;
  bus::Writer<cell_world_BeltState> belt;
  bus::Writer<cell_world_PhotocellEvent> photocell;
};

class CameraServiceTest : public ::testing::Test {
 protected:
  std::uint32_t domain_ = cell::testing::test_domain_id();
  std::string partition_ = cell::testing::unique_partition();
};

const std::vector<double> kGrabPose = {45.0 * kDeg, 105.0 * kDeg, 0.0, 0.0};

TEST_F(CameraServiceTest, GrabsOnRequestWithTruthWhereTheImageShowsThePart) {
  cell::testing::ServiceHarness<CameraConfig, CameraService> camera(domain_, partition_,
                                                                     eye_config(), "camera");
  Bus b(domain_, partition_);
  b.wait_matched();
  // No robot state yet: the camera riding it cannot say where it is.
  std::uint64_t seq = b.request("ibm7545_eye", cell_vision_TRIGGER_NOW, true);
  auto refused = b.wait_for(b.truths, [&](const auto& t) { return b.mine(t.request_id, seq); });
  ASSERT_TRUE(refused);
  EXPECT_FALSE((*refused)->status.accepted);
  EXPECT_THAT(bus::str((*refused)->status.reason), HasSubstr("robot 'ibm7545' carries camera"));
  EXPECT_EQ(bus::str((*refused)->status.error_code), "not_ready");
  // The robot, but no world yet.
  b.publish_robot(kGrabPose, wall_time_ns(), false);
  seq = b.request("ibm7545_eye", cell_vision_TRIGGER_NOW, true);
  refused = b.wait_for(b.truths, [&](const auto& t) { return b.mine(t.request_id, seq); });
  ASSERT_TRUE(refused);
  EXPECT_FALSE((*refused)->status.accepted);
  EXPECT_THAT(bus::str((*refused)->status.reason), HasSubstr("no world state"));

  // The world: one DIP in the middle of the grab window (digest 000 §9.2 case 9).
  WorldStateWire w;
  w.add_part("ic8", "dip20", cell_world_SHAPE_DIP, 26.16, 6.35, 3.81, 20, 0.1,
             resting(134.39, 501.25, 750.0, -116.0), "table");
  const std::int64_t t0 = wall_time_ns();
  ASSERT_TRUE(b.world.write(w.finish(t0, 1, 750.0)));
  b.publish_robot(kGrabPose, t0, false);
  seq = b.request("ibm7545_eye", cell_vision_TRIGGER_NOW, true);
  auto image = b.wait_for(b.images, [&](const auto& i) { return b.mine(i.request_id, seq); });
  auto truth = b.wait_for(b.truths, [&](const auto& t) { return b.mine(t.request_id, seq); });
  const std::int64_t t1 = wall_time_ns();
  ASSERT_TRUE(image);
  ASSERT_TRUE(truth);
  ASSERT_TRUE((*truth)->status.accepted) << bus::str((*truth)->status.reason);
  const cell_vision_Image& img = image->get();
  EXPECT_EQ(bus::str(img.camera_id), "ibm7545_eye");
  EXPECT_EQ(img.width_px, 512U);
  EXPECT_EQ(img.height_px, 484U);
  EXPECT_EQ(bus::str(img.encoding), "mono8");
  EXPECT_EQ(img.step_bytes, 512U);
  ASSERT_EQ(img.data._length, 512U * 484U);
  EXPECT_GE(img.header.stamp_ns, t0);
  EXPECT_LE(img.header.stamp_ns, t1);
  EXPECT_EQ(bus::str(img.robot_id), "ibm7545");
  ASSERT_EQ(img.robot_joints_rad_or_mm._length, 4U);
  EXPECT_NEAR(img.robot_joints_rad_or_mm._buffer[1], 105.0 * kDeg, 1e-12);
  EXPECT_EQ((*truth)->image_seq, img.header.seq);
  EXPECT_DOUBLE_EQ((*truth)->fx_px, 1502.3);
  EXPECT_NEAR((*truth)->world_T_camera.position_mm.z, 1170.0, 5.0);
  ASSERT_EQ((*truth)->distortion._length, 5U);
  ASSERT_EQ((*truth)->parts._length, 1U);
  const cell_vision_TruthPart& part = (*truth)->parts._buffer[0];
  EXPECT_EQ(bus::str(part.part_id), "ic8");
  EXPECT_DOUBLE_EQ(part.visible_fraction, 1.0);
  EXPECT_EQ(part.corners_px._length, 4U);
  // The part is where the truth says: the dark body's centroid in the image.
  const cv::Mat pixels(484, 512, CV_8UC1, img.data._buffer);
  double su = 0.0;
  double sv = 0.0;
  double n = 0.0;
  const int cu = static_cast<int>(part.center_px.u_px);
  const int cv_ = static_cast<int>(part.center_px.v_px);
  for (int v = cv_ - 60; v <= cv_ + 60; ++v) {
    for (int u = cu - 60; u <= cu + 60; ++u) {
      if (u >= 0 && v >= 0 && u < 512 && v < 484 && pixels.at<std::uint8_t>(v, u) < 60) {
        su += u;
        sv += v;
        n += 1.0;
      }
    }
  }
  ASSERT_GT(n, 500.0);  // 26 x 6 mm at ~3.5 px/mm: ~2000 px
  EXPECT_NEAR(su / n, part.center_px.u_px, 2.0);
  EXPECT_NEAR(sv / n, part.center_px.v_px, 2.0);
  EXPECT_GE(camera.service().images_published(), 1U);
}

TEST_F(CameraServiceTest, PreviewsFollowTheFramesAtTheReducedRateForWhoeverReadsThem) {
  CameraConfig config = eye_config();
  config.preview_hz = 2.0;
  cell::testing::ServiceHarness<CameraConfig, CameraService> camera(domain_, partition_,
                                                                     config, "camera");
  Bus b(domain_, partition_);
  bus::Participant viewer(domain_, partition_);
  bus::Topic<cell_vision_Image> preview_topic(viewer, bus::topics::kImagePreview);
  bus::Reader<cell_vision_Image> previews(viewer, preview_topic, bus::topics::kImagePreview);
  b.wait_matched();
  ASSERT_TRUE(previews.wait_for_writers(1, kWait));
  WorldStateWire w;
  w.add_part("ic8", "dip20", cell_world_SHAPE_DIP, 26.16, 6.35, 3.81, 20, 0.1,
             resting(134.39, 501.25, 750.0, -116.0), "table");
  // Frames for 1.6 s, one every 100 ms: every one on cell/vision/image, at most one preview
  // per 0.5 s (the first frame, then one per period: 4 at most). The preview reader keeps one
  // sample (depth 1): count as they come.
  int frames = 0;
  int seen = 0;
  const auto count_previews = [&] {
    if (auto taken = previews.take_copies(64); taken) {
      for (const auto& image : *taken) {
        EXPECT_EQ(bus::str(image->camera_id), "ibm7545_eye");
        EXPECT_EQ(image->data._length, 512U * 484U);
        ++seen;
      }
    }
  };
  const auto t0 = std::chrono::steady_clock::now();
  while (std::chrono::steady_clock::now() - t0 < 1600ms) {
    ASSERT_TRUE(b.world.write(w.finish(wall_time_ns(), 1, 750.0)));
    b.publish_robot(kGrabPose, wall_time_ns(), false);
    const std::uint64_t seq = b.request("ibm7545_eye", cell_vision_TRIGGER_NOW, false);
    if (b.wait_for(b.images, [&](const auto& i) { return b.mine(i.request_id, seq); })) {
      ++frames;
    }
    std::this_thread::sleep_for(50ms);
    count_previews();
    std::this_thread::sleep_for(50ms);
  }
  std::this_thread::sleep_for(200ms);
  count_previews();
  EXPECT_GE(frames, 8);
  EXPECT_GE(seen, 2);
  EXPECT_LE(seen, 4) << "previews are not rate-limited: " << seen << " for " << frames
                     << " frames";
}

TEST_F(CameraServiceTest, EveryRequestIsAnsweredEvenTheImpossibleOnes) {
  cell::testing::ServiceHarness<CameraConfig, CameraService> camera(domain_, partition_,
                                                                     eye_config(), "camera");
  Bus b(domain_, partition_);
  b.wait_matched();
  std::uint64_t seq = b.request("nope", cell_vision_TRIGGER_NOW, false);
  auto r = b.wait_for(b.truths, [&](const auto& t) { return b.mine(t.request_id, seq); });
  ASSERT_TRUE(r);
  EXPECT_FALSE((*r)->status.accepted);
  EXPECT_THAT(bus::str((*r)->status.reason), HasSubstr("unknown camera 'nope'"));
  EXPECT_THAT(bus::str((*r)->status.reason), HasSubstr("belt_cam"));
  seq = b.request("", cell_vision_TRIGGER_NOW, false);
  r = b.wait_for(b.truths, [&](const auto& t) { return b.mine(t.request_id, seq); });
  ASSERT_TRUE(r);
  EXPECT_THAT(bus::str((*r)->status.reason), HasSubstr("names no camera"));
  seq = b.request("ibm7545_eye", cell_vision_TRIGGER_PHOTOCELL, false);
  r = b.wait_for(b.truths, [&](const auto& t) { return b.mine(t.request_id, seq); });
  ASSERT_TRUE(r);
  EXPECT_THAT(bus::str((*r)->status.reason), HasSubstr("has no photocell"));
  // Another known camera's request is left to that camera.
  seq = b.request("belt_cam", cell_vision_TRIGGER_NOW, false);
  r = b.wait_for(b.truths, [&](const auto& t) { return b.mine(t.request_id, seq); },
                 std::chrono::milliseconds(300));
  EXPECT_FALSE(r);
}

TEST_F(CameraServiceTest, ThePhotocellFiresTheBeltCameraAndTheCountIsLatched) {
  cell::testing::ServiceHarness<CameraConfig, CameraService> camera(domain_, partition_,
                                                                     belt_config(), "camera");
  Bus b(domain_, partition_);
  ASSERT_TRUE(b.requests.wait_for_readers(1, kWait));
  ASSERT_TRUE(b.belt.wait_for_readers(1, kWait));
  ASSERT_TRUE(b.photocell.wait_for_readers(1, kWait));
  ASSERT_TRUE(b.images.wait_for_writers(1, kWait));
  constexpr double kSpeed = 1000.0;       // mm/s toward -y
  constexpr double kMmPerCount = 0.03835;  // digest 002 T9, x4 quadrature on a 50 mm roller
  const std::int64_t start = wall_time_ns();
  const std::string belt_id = "belt1";
  // The world simulator: belt states at 200 Hz and the world at 50 Hz, from a thread.
  std::atomic<bool> stop{false};
  std::thread world([&] {
    int k = 0;
    while (!stop.load()) {
      const std::int64_t now = wall_time_ns();
      const double travel = kSpeed * static_cast<double>(now - start) * 1e-9;
      cell_world_BeltState s{};
      s.belt_id = bus::borrow(belt_id);
      s.header.stamp_ns = now;
      s.travel_mm = travel;
      s.speed_mm_per_s = kSpeed;
      s.encoder_count = static_cast<std::int64_t>(travel / kMmPerCount);
      s.origin_mm = {1350, 600, 760};
      s.direction = {0, -1, 0};
      s.length_mm = 1500;
      s.width_mm = 300;
      (void)b.belt.write(s);
      if (k++ % 4 == 0) {
        WorldStateWire w;
        w.add_belt("belt1", {1350, 600, 760}, {0, -1, 0}, 1500, 300, kSpeed, now);
        w.add_part("la1", "la_part", cell_world_SHAPE_RECTANGLE, 80, 40, 8, 0, 0.8,
                   resting(1350, 300 - travel, 760, -90), "belt/belt1");
        (void)b.world.write(w.finish(now, 1, 750.0));
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
    }
  });
  std::this_thread::sleep_for(std::chrono::milliseconds(100));
  const std::uint64_t seq = b.request("belt_cam", cell_vision_TRIGGER_PHOTOCELL, true);
  std::this_thread::sleep_for(std::chrono::milliseconds(50));
  // The part clears the beam: the on->off edge, with the count latched at it.
  const std::int64_t edge = wall_time_ns();
  cell_world_PhotocellEvent e{};
  e.belt_id = bus::borrow(belt_id);
  e.header.stamp_ns = edge;
  e.blocked = false;
  ASSERT_TRUE(b.photocell.write(e));
  auto image = b.wait_for(b.images, [&](const auto& i) { return b.mine(i.request_id, seq); });
  auto truth = b.wait_for(b.truths, [&](const auto& t) { return b.mine(t.request_id, seq); });
  stop = true;
  world.join();
  ASSERT_TRUE(image);
  ASSERT_TRUE(truth);
  // 200 mm at 1 m/s after the edge.
  const std::int64_t exposure = edge + 200'000'000;
  EXPECT_EQ((*image)->header.stamp_ns, exposure);
  EXPECT_EQ((*image)->width_px, 1024U);
  EXPECT_EQ(bus::str((*image)->belt_id), "belt1");
  const double expected_count =
      kSpeed * static_cast<double>(exposure - start) * 1e-9 / kMmPerCount;
  EXPECT_NEAR(static_cast<double>((*image)->belt_count), expected_count, 3.0);
  ASSERT_TRUE((*truth)->status.accepted) << bus::str((*truth)->status.reason);
  ASSERT_EQ((*truth)->parts._length, 1U);
  const double travel_at_exposure = kSpeed * static_cast<double>(exposure - start) * 1e-9;
  EXPECT_NEAR((*truth)->parts._buffer[0].world_T_part.position_mm.y, 300 - travel_at_exposure,
              0.05);

  // No edge: the request is refused when its photocell timeout (1 s) passes.
  const std::uint64_t lonely = b.request("belt_cam", cell_vision_TRIGGER_PHOTOCELL, false);
  auto refused = b.wait_for(b.truths, [&](const auto& t) { return b.mine(t.request_id, lonely); });
  ASSERT_TRUE(refused);
  EXPECT_FALSE((*refused)->status.accepted);
  EXPECT_THAT(bus::str((*refused)->status.reason), HasSubstr("no photocell edge on belt 'belt1'"));
}

}  // namespace
}  // namespace cell::camera
