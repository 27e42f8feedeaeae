// Vision across processes: cell-sim-world holds the thesis's 15 ICs, cell-gateway (ideal IBM
// 7545 at the image-grab pose) the joints and lights, cell-camera renders through the TRUE
// camera, cell-vision locates. The test asks for frames with their ground truth and checks the
// Detections against it: first with the nominal calibration vision starts from, then, after it
// publishes a calibration on cell/calibration/camera, re-mapped at once. Every wait is a
// condition with a deadline; every process must stop cleanly (exit 0) on SIGTERM.
#include <fmt/format.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <optional>
#include <string>
#include <vector>

#include "cell/bus/participant.hpp"
#include "cell/bus/reader.hpp"
#include "cell/bus/topic.hpp"
#include "cell/bus/topics.hpp"
#include "cell/bus/view.hpp"
#include "cell/bus/writer.hpp"
#include "cell/calibration/camera_calibration.hpp"
#include "cell/common/time.hpp"
#include "cell/process/child.hpp"
#include "cell/render/camera_file.hpp"
#include "cell/testing/env.hpp"

namespace cell {
namespace {

using ::cell::testing::eventually;
using namespace std::chrono_literals;

class VisionCellTest : public ::testing::Test {
 protected:
  VisionCellTest()
      : domain_(cell::testing::test_domain_id()), partition_(cell::testing::unique_partition()) {
    if (std::getenv("CYCLONEDDS_URI") == nullptr) {
      setenv("CYCLONEDDS_URI",
             ("file://" + cell::testing::source_dir() + "/config/dds/loopback.xml").c_str(), 1);
    }
    std::string pattern = "/tmp/cell-vision-XXXXXX";
    dir_ = mkdtemp(pattern.data()) != nullptr ? pattern : "/tmp/cell-vision-fallback";
    env_ = cell::testing::bus_env(domain_, partition_);
    env_.push_back("CELL_HOME=" + cell::testing::source_dir());
  }

  ~VisionCellTest() override {
    for (auto& [name, child] : children_) {
      if (child.running()) {
        const auto exit = child.stop(5s);
        if (!exit.exited || exit.code != 0) {
          ADD_FAILURE() << name << " ended with " << exit.describe() << ":\n" << child.output();
        }
      }
    }
    std::error_code ec;
    std::filesystem::remove_all(dir_, ec);
  }

  std::string write(const std::string& name, const std::string& text) {
    std::string p = dir_ + "/" + name;
    std::ofstream(p) << text;
    return p;
  }

  void start(const std::string& name, const std::string& exec, const std::string& config) {
    process::SpawnOptions options;
    options.executable = cell::testing::bin_path(exec);
    options.args = {"--config", config};
    options.env = env_;
    auto child = process::Child::spawn(options);
    ASSERT_TRUE(child) << child.error().message;
    children_.emplace_back(name, std::move(*child));
  }

  std::string logs() {
    std::string out;
    for (auto& [name, child] : children_) {
      std::string text;
      (void)child.read_available(text);
      out += fmt::format("--- {}\n{}{}", name, child.output(), text);
    }
    return out;
  }

  std::uint32_t domain_;
  std::string partition_;
  std::string dir_;
  std::vector<std::string> env_;
  std::vector<std::pair<std::string, process::Child>> children_;
};

/// What the test sees of the bus.
struct Bus {
  Bus(std::uint32_t domain, const std::string& partition)
      : participant(domain, partition),
        request_topic(participant, bus::topics::kImageRequest),
        truth_topic(participant, bus::topics::kImageTruth),
        detections_topic(participant, bus::topics::kDetections),
        calibration_topic(participant, bus::topics::kCameraCalibration),
        edge_topic(participant, bus::topics::kEdgeRequest),
        result_topic(participant, bus::topics::kEdgeResult),
        requests(participant, request_topic, bus::topics::kImageRequest),
        truths(participant, truth_topic, bus::topics::kImageTruth),
        detections(participant, detections_topic, bus::topics::kDetections),
        calibrations(participant, calibration_topic, bus::topics::kCameraCalibration),
        edges(participant, edge_topic, bus::topics::kEdgeRequest),
        results(participant, result_topic, bus::topics::kEdgeResult) {}

  bus::Participant participant;
  bus::Topic<cell_vision_ImageRequest> request_topic;
  bus::Topic<cell_vision_ImageTruth> truth_topic;
  bus::Topic<cell_vision_Detections> detections_topic;
  bus::Topic<cell_calibration_CameraCalibration> calibration_topic;
  bus::Topic<cell_vision_EdgeRequest> edge_topic;
  bus::Topic<cell_vision_EdgeResult> result_topic;
  bus::Writer<cell_vision_ImageRequest> requests;
  bus::Reader<cell_vision_ImageTruth> truths;
  bus::Reader<cell_vision_Detections> detections;
  bus::Writer<cell_calibration_CameraCalibration> calibrations;
  bus::Writer<cell_vision_EdgeRequest> edges;
  bus::Reader<cell_vision_EdgeResult> results;
  std::vector<bus::Owned<cell_vision_Detections>> seen;
  std::string client = "vision_cell_test";
  std::uint64_t seq = 0;

  /// Asks the camera for a frame with its truth; the accepted truth, or nullopt.
  std::optional<bus::Owned<cell_vision_ImageTruth>> grab() {
    static const std::string kCamera = "ibm7545_eye";
    cell_vision_ImageRequest r{};
    r.request_id.client_id = bus::borrow(client);
    r.request_id.seq = ++seq;
    r.camera_id = bus::borrow(kCamera);
    r.trigger = cell_vision_TRIGGER_NOW;
    r.with_truth = true;
    if (!requests.write(r)) {
      return std::nullopt;
    }
    const auto deadline = std::chrono::steady_clock::now() + 5s;
    while (std::chrono::steady_clock::now() < deadline) {
      (void)truths.wait_for_data(100ms);
      auto batch = truths.take_copies(8);
      if (batch) {
        for (auto& t : *batch) {
          if (t.get().request_id.seq == seq && bus::str(t.get().request_id.client_id) == client) {
            if (!t.get().status.accepted) {
              return std::nullopt;
            }
            return std::move(t);
          }
        }
      }
    }
    return std::nullopt;
  }

  /// The Detections of image `image_seq` whose calibration text contains `has`.
  const cell_vision_Detections* detections_of(std::uint64_t image_seq,
                                              const std::string& has,
                                              std::chrono::milliseconds timeout = 10s) {
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    for (;;) {
      for (const auto& d : seen) {
        if (d.get().image_sequence == image_seq &&
            std::string(bus::str(d.get().calibration)).find(has) != std::string::npos) {
          return &d.get();
        }
      }
      if (std::chrono::steady_clock::now() >= deadline) {
        return nullptr;
      }
      (void)detections.wait_for_data(100ms);
      auto batch = detections.take_copies(16);
      if (batch) {
        for (auto& d : *batch) {
          seen.push_back(std::move(d));
        }
      }
    }
  }
};

/// The largest distance between a truth part and the nearest detection, in pixels and (base
/// poses against the truth's part origins; the 7545's base is the world's x-y) in mm.
struct Errors {
  double pixel = 0.0;
  double world = 0.0;
  std::size_t parts = 0;
};

Errors compare(const cell_vision_Detections& d, const cell_vision_ImageTruth& t) {
  Errors e;
  for (const auto& p : bus::span(t.parts)) {
    if (p.visible_fraction < 0.999) {
      continue;
    }
    ++e.parts;
    double best_px = 1e9;
    double best_mm = 1e9;
    for (const auto& item : bus::span(d.items)) {
      const double px = std::hypot(item.center_px.u_px - p.center_px.u_px,
                                   item.center_px.v_px - p.center_px.v_px);
      if (px < best_px) {
        best_px = px;
        best_mm = item.has_base_pose
                      ? std::hypot(item.base_pose.x_mm - p.world_T_part.position_mm.x,
                                   item.base_pose.y_mm - p.world_T_part.position_mm.y)
                      : 1e9;
      }
    }
    e.pixel = std::max(e.pixel, best_px);
    e.world = std::max(e.world, best_mm);
  }
  return e;
}

TEST_F(VisionCellTest, LocatesTheThesisTableAndRemapsWhenACalibrationIsPublished) {
  start("sim-world", "cell-sim-world",
        write("sim-world.yaml",
              "service: {id: sim-world}\n"
              "scene: config/scenes/table_ics.yaml\n"
              "robots:\n"
              "  - {id: ibm7545, xyz_mm: [0, 0, 981.51]}\n"));
  start("gateway", "cell-gateway",
        write("gateway.yaml",
              "service: {id: gateway.ibm7545}\n"
              "robot_config: config/robots/ibm7545.yaml\n"
              "driver: {kind: ideal, initial_joints: [45, 105, 0, 0]}\n"));
  start("camera", "cell-camera", "config/camera-ibm7545.yaml");
  start("vision", "cell-vision",
        write("vision.yaml",
              "service: {id: vision}\n"
              "cameras:\n"
              "  - {id: ibm7545_eye, working_plane_z_mm: -231.51}\n"));
  ASSERT_TRUE(eventually(
      [&] {
        return cell::testing::run_tool(
                   "cellctl",
                   {"--timeout", "5", "robot", "lights", "--robot", "ibm7545", "--fluorescent"},
                   env_, 60s)
                   .exit.code == 0;
      },
      30s))
      << logs();
  Bus bus(domain_, partition_);
  ASSERT_TRUE(bus.requests.wait_for_readers(1, 30s)) << logs();
  ASSERT_TRUE(bus.calibrations.wait_for_readers(1, 30s)) << logs();
  ASSERT_TRUE(bus.detections.wait_for_writers(1, 30s)) << logs();
  // A lit frame of the 15 ICs, and vision's Detections of it, with the nominal calibration.
  std::optional<bus::Owned<cell_vision_ImageTruth>> truth;
  const cell_vision_Detections* nominal = nullptr;
  ASSERT_TRUE(eventually(
      [&] {
        truth = bus.grab();
        if (!truth) {
          return false;
        }
        nominal = bus.detections_of(truth->get().image_seq, "NOMINAL", 5s);
        return nominal != nullptr && bus::span(nominal->items).size() == 15;
      },
      60s))
      << logs();
  EXPECT_EQ(bus::str(nominal->error), "");
  EXPECT_EQ(bus::str(nominal->robot_id), "ibm7545");
  Errors e = compare(*nominal, truth->get());
  EXPECT_EQ(e.parts, 15U);
  EXPECT_LT(e.pixel, 0.5);  // the nominal lens is none: a little off at the corners
  EXPECT_GT(e.world, 2.0);  // the mount really is a few mm elsewhere
  EXPECT_LT(e.world, 25.0);
  // The calibration service's result (here: the truth) on the bus: the last image re-mapped.
  auto camera =
      render::load_camera(cell::testing::source_dir() + "/config/cameras/ibm7545_eye.yaml");
  ASSERT_TRUE(camera);
  render::CameraDescription truth_camera = *camera;
  truth_camera.nominal = camera->truth;
  auto calib =
      calibration::nominal_calibration(truth_camera, "", camera->robot.world_T_base, -231.51);
  ASSERT_TRUE(calib);
  calib->version = "test#1";
  calibration::IdlHolder holder;
  ASSERT_TRUE(bus.calibrations.write(calibration::to_idl(*calib, holder, wall_time_ns())));
  const cell_vision_Detections* remapped =
      bus.detections_of(truth->get().image_seq, "calibration test#1");
  ASSERT_NE(remapped, nullptr) << logs();
  e = compare(*remapped, truth->get());
  EXPECT_LT(e.pixel, 0.3);
  EXPECT_LT(e.world, 0.2);
  // A RAPT LOOK on that image: the first part's first side, predicted 1.5 px out.
  const auto& part = bus::span(truth->get().parts)[0];
  const auto corners = bus::span(part.corners_px);
  ASSERT_EQ(corners.size(), 4U);
  static const std::string kCamera = "ibm7545_eye";
  cell_vision_EdgeRequest r{};
  r.request_id.client_id = bus::borrow(bus.client);
  r.request_id.seq = 1000;
  r.camera_id = bus::borrow(kCamera);
  r.predicted_start_px = corners[0];
  r.predicted_end_px = corners[1];
  r.search_halfwidth_px = 5.0;
  r.image_sequence = truth->get().image_seq;
  ASSERT_TRUE(bus.results.wait_for_writers(1, 10s));
  ASSERT_TRUE(bus.edges.wait_for_readers(1, 10s));
  ASSERT_TRUE(bus.edges.write(r));
  std::optional<bus::Owned<cell_vision_EdgeResult>> result;
  ASSERT_TRUE(eventually(
      [&] {
        auto batch = bus.results.take_copies(8);
        if (batch) {
          for (auto& s : *batch) {
            if (s.get().request_id.seq == 1000) {
              result = std::move(s);
            }
          }
        }
        return result.has_value();
      },
      10s));
  EXPECT_TRUE(result->get().status.accepted) << bus::str(result->get().status.reason);
  EXPECT_EQ(result->get().image_sequence, truth->get().image_seq);
  EXPECT_GT(result->get().point_count, 10U);
}

}  // namespace
}  // namespace cell
