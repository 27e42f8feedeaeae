// DIPs riding the dark belt, seen by the fixed belt camera (config/cameras/belt_cam.yaml, 0.5
// mm/px, its strobe) and located with the cell's own vision options (config/vision.yaml): the
// conveyor job picks only what vision names, so every DIP must be named, and at the right place.
#include <gtest/gtest.h>

#include <fmt/format.h>

#include <cmath>
#include <random>
#include <string>

#include "cell/calibration/camera_calibration.hpp"
#include "cell/render/camera_file.hpp"
#include "cell/render/renderer.hpp"
#include "cell/render/truth.hpp"
#include "cell/testing/env.hpp"
#include "cell/vision/locate.hpp"
#include "cell/vision/options.hpp"
#include "cell/vision/pixel_mapper.hpp"
#include "scenes.hpp"

namespace cell::vision {
namespace {

constexpr double kPi = 3.14159265358979323846;

struct BeltFrames {
  render::CameraDescription camera;
  calibration::CameraCalibration truth;
  Eigen::Isometry3d world_T_base = Eigen::Isometry3d::Identity();
};

BeltFrames belt_camera() {
  BeltFrames b;
  auto camera = render::load_camera(cell::testing::source_dir() + "/config/cameras/belt_cam.yaml");
  EXPECT_TRUE(camera) << camera.error().message;
  b.camera = *camera;
  render::CameraDescription truth = b.camera;
  truth.nominal = b.camera.truth;
  // The picker's base (config/sim-world.yaml) and belt1's surface 200 mm below it.
  b.world_T_base = Eigen::Isometry3d(Eigen::Translation3d(1000, 0, 960));
  auto c = calibration::nominal_calibration(truth, "scara_picker", b.world_T_base, -200.0);
  EXPECT_TRUE(c) << c.error().message;
  b.truth = *c;
  return b;
}

// 0.5 m/s, the slow belt (99 % must be picked): one DIP-14 or DIP-16 per frame, at a
// random place across the belt and a random yaw, where the photocell exposes it.
TEST(BeltVision, EveryDipOnTheDarkBeltIsNamedAndLocated) {
  const BeltFrames b = belt_camera();
  ASSERT_FALSE(::testing::Test::HasFailure());
  auto options = load_locate_options(cell::testing::source_dir() + "/config/vision.yaml",
                                     "belt_cam");
  ASSERT_TRUE(options) << options.error().message;
  auto locator = Locator::create(*options);
  ASSERT_TRUE(locator) << locator.error().message;
  auto mapper = PixelMapper::create(b.truth, nullptr, {});
  ASSERT_TRUE(mapper) << mapper.error().message;
  auto renderer = render::Renderer::create(b.camera.truth.model, b.camera.lighting);
  ASSERT_TRUE(renderer) << renderer.error().message;
  const testing::Cell& cell = testing::Cell::get();

  std::mt19937_64 rng(11);
  std::uniform_real_distribution<double> lateral(-60.0, 60.0);
  std::uniform_real_distribution<double> yaw(-kPi / 2, kPi / 2);
  std::uniform_real_distribution<double> along(200.0, 260.0);
  constexpr int kFrames = 60;
  int named = 0;
  int right_class = 0;
  double worst_mm = 0.0;
  std::vector<std::string> notes;
  for (int i = 0; i < kFrames; ++i) {
    render::Scene scene;
    scene.table_height_mm = 750.0;
    render::Belt belt;
    belt.id = "belt1";
    belt.origin_mm = {1350, 600, 760};
    belt.direction = {0, -1, 0};
    belt.length_mm = 1500;
    belt.width_mm = 300;
    belt.reflectance = 0.3;
    scene.belts.push_back(belt);
    const std::string cls = (i % 2 == 0) ? "dip14" : "dip16";
    render::Part part = cell.part(fmt::format("p{}", i), cls, 1350.0 + lateral(rng), along(rng),
                                  yaw(rng), true);
    part.world_T_part.translation().z() = 760.0;
    part.velocity_mm_s = {0, -500, 0};
    scene.parts.push_back(part);
    scene.lights.fluorescent_on = true;
    const Eigen::Isometry3d world_T_camera = b.camera.truth.pose;
    render::RenderOptions ro;
    ro.exposure_s = b.camera.exposure_s;
    ro.noise_sigma = 2.0;
    ro.seed = 100 + static_cast<std::uint64_t>(i);
    cv::Mat image;
    ASSERT_TRUE(renderer->render(scene, world_T_camera, ro, image));
    auto found = locator->locate(image, *mapper);
    ASSERT_TRUE(found) << found.error().message;
    const Eigen::Vector3d at = b.world_T_base.inverse() * part.world_T_part.translation();
    bool ok = false;
    for (const Detection& d : found->detections) {
      if (!d.has_base_pose) {
        continue;
      }
      const double err = std::hypot(d.base_pose.x_mm - at.x(), d.base_pose.y_mm - at.y());
      if (err > 3.0) {
        continue;
      }
      // At 0.5 mm/px the DIP-14 (19.05 mm), the DIP-16 (19.30 mm) and the thesis's 6 x 19 mm
      // IC are half a pixel apart: the belt camera names the family, with the same grasps
      // (config/vision.yaml); which of the three is counted, not required.
      if (d.class_name == "dip14" || d.class_name == "dip16" || d.class_name == "ic_6x19") {
        ok = true;
        ++named;
        right_class += d.class_name == cls ? 1 : 0;
        worst_mm = std::max(worst_mm, err);
      } else {
        notes.push_back(fmt::format("frame {} {}: '{}' length {:.2f} width {:.2f} mm q {:.2f}{}",
                                    i, cls, d.class_name, d.length_mm, d.width_mm, d.quality,
                                    d.touching ? " touching" : ""));
      }
    }
    if (!ok && notes.empty()) {
      notes.push_back(fmt::format("frame {} {}: nothing within 3 mm", i, cls));
    }
  }
  std::printf("belt DIPs: %d of %d named (%d of the right class), worst %.3f mm\n", named,
              kFrames, right_class, worst_mm);
  for (const std::string& n : notes) {
    std::printf("  %s\n", n.c_str());
  }
  EXPECT_EQ(named, kFrames);
  EXPECT_LT(worst_mm, 0.5);
}

}  // namespace
}  // namespace cell::vision
