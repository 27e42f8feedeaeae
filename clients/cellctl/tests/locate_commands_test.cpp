// `cellctl locate`: parts in image files rendered by the world simulator, with and without a
// calibration, and every bad input named.
#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <numbers>
#include <opencv2/imgcodecs.hpp>
#include <string>
#include <vector>

#include "cell/calibration/camera_calibration.hpp"
#include "cli_run.hpp"
#include "scenes.hpp"

namespace cell::cellctl {
namespace {

using nlohmann::json;
using testing::cellctl;
using testing::CliRun;
using ::testing::HasSubstr;
using vision::testing::Cell;
using vision::testing::Lights;

constexpr double kRadToDeg = 180.0 / std::numbers::pi;

class LocateCommandsTest : public ::testing::Test {
 protected:
  LocateCommandsTest() {
    std::string pattern = "/tmp/cellctl-locate-XXXXXX";
    dir_ = mkdtemp(pattern.data()) != nullptr ? pattern : "/tmp";
  }
  ~LocateCommandsTest() override {
    std::error_code ec;
    std::filesystem::remove_all(dir_, ec);
  }
  std::string path(const std::string& name) const { return dir_ + "/" + name; }

  std::string save(const std::string& name, const cv::Mat& image) {
    cv::imwrite(path(name), image);
    return path(name);
  }
  std::string save_true_calibration() {
    std::string p = path("true.yaml");
    EXPECT_TRUE(calibration::save_camera_calibration(Cell::get().true_calibration(), p));
    return p;
  }
  static json parsed(const CliRun& run) { return json::parse(run.out, nullptr, false); }

  std::string dir_;
};

// With the true calibration and the joints at the exposure: every part, its class, its centre
// to a fraction of a pixel, its angle in degrees in [0, 180), its pose in the base frame.
TEST_F(LocateCommandsTest, LocatesEveryPartWithItsWorldPose) {
  const Cell& cell = Cell::get();
  vision::testing::ScatterRequest req;
  req.count = 5;
  req.seed = 77;
  const auto frame = cell.scatter(req);
  const std::string image = save("frame.png", frame.image);
  const CliRun run = cellctl({"locate", image, "--calibration", save_true_calibration(), "--joints",
                              "45,135,0,0", "--json"});
  ASSERT_EQ(run.code, 0) << run.err;
  const json out = parsed(run);
  ASSERT_TRUE(out.is_object()) << run.out;
  EXPECT_EQ(out["width_px"], 512);
  EXPECT_EQ(out["pipeline"], "fast");
  ASSERT_EQ(out["parts"].size(), frame.truth.size());
  int clear_grips = 0;
  for (const auto& t : frame.truth) {
    const json* best = nullptr;
    double best_d = 1e9;
    for (const json& p : out["parts"]) {
      const double d = std::hypot(p["center_px"][0].get<double>() - t.center_px.x(),
                                  p["center_px"][1].get<double>() - t.center_px.y());
      if (d < best_d) {
        best_d = d;
        best = &p;
      }
    }
    ASSERT_NE(best, nullptr);
    EXPECT_LT(best_d, 0.3) << t.part_id;
    EXPECT_EQ((*best)["class"], t.class_name);
    const double angle = (*best)["angle_deg"].get<double>();
    EXPECT_GE(angle, 0.0);
    EXPECT_LT(angle, 180.0);
    double e = std::fmod(std::abs(angle - t.angle_rad * kRadToDeg), 180.0);
    EXPECT_LT(std::min(e, 180.0 - e), 0.3) << t.part_id;
    EXPECT_EQ((*best)["corners_px"].size(), 4U);
    ASSERT_TRUE(best->contains("world"));
    const Eigen::Vector3d base = cell.world_T_base().inverse() * t.world_T_part.translation();
    EXPECT_NEAR((*best)["world"]["x_mm"].get<double>(), base.x(), 0.1);
    EXPECT_NEAR((*best)["world"]["y_mm"].get<double>(), base.y(), 0.1);
    EXPECT_GT((*best)["length_mm"].get<double>(), 5.0);
    // A clear grip lists every clear style with where the tool goes (config/vision.yaml's
    // styles grip the centre: across the body, or on its ends a quarter turn away).
    if (best->contains("grip") && (*best)["grip"]["verdict"] == "clear") {
      ++clear_grips;
      const json& clear = (*best)["grip"]["clear"];
      ASSERT_FALSE(clear.empty()) << best->dump();
      EXPECT_EQ(clear[0]["style"], (*best)["grip"]["style"]);
      for (const json& g : clear) {
        EXPECT_NEAR(g["x_mm"].get<double>(), base.x(), 0.1) << g.dump();
        EXPECT_NEAR(g["y_mm"].get<double>(), base.y(), 0.1) << g.dump();
      }
    }
  }
  EXPECT_GT(clear_grips, 0);
  // The text form says the same in one line per part.
  const CliRun text =
      cellctl({"locate", image, "--calibration", path("true.yaml"), "--joints", "45,135,0,0"});
  ASSERT_EQ(text.code, 0) << text.err;
  EXPECT_THAT(text.out, HasSubstr("5 parts"));
  EXPECT_THAT(text.out, HasSubstr("world ("));
}

TEST_F(LocateCommandsTest, WithoutACalibrationItWorksInPixelsAndTheThesisPipelineToo) {
  const Cell& cell = Cell::get();
  const Eigen::Vector2d c = cell.window(30.0).center();
  const auto frame = cell.render("one", {cell.part("a", "ic_7x30", c.x(), c.y(), 0.6, true)},
                                 cell.aligned_joints(), Lights::kTubes, 8);
  const std::string image = save("one.png", frame.image);
  for (const std::string pipeline : {"fast", "thesis"}) {
    const CliRun run = cellctl({"locate", image, "--pipeline", pipeline, "--json"});
    ASSERT_EQ(run.code, 0) << run.err;
    const json out = parsed(run);
    EXPECT_EQ(out["pipeline"], pipeline);
    ASSERT_EQ(out["parts"].size(), 1U);
    const json& p = out["parts"][0];
    EXPECT_FALSE(p.contains("world"));
    EXPECT_FALSE(p.contains("length_mm"));
    EXPECT_LT(std::hypot(p["center_px"][0].get<double>() - frame.truth[0].center_px.x(),
                         p["center_px"][1].get<double>() - frame.truth[0].center_px.y()),
              pipeline == "fast" ? 1.0 : 2.0);
  }
  const auto empty = cell.render("empty", {}, cell.aligned_joints(), Lights::kTubes, 9);
  const CliRun none = cellctl({"locate", save("empty.png", empty.image), "--json"});
  ASSERT_EQ(none.code, 0) << none.err;
  EXPECT_TRUE(parsed(none)["parts"].empty());
}

TEST_F(LocateCommandsTest, BadFilesAndArgumentsGetClearErrors) {
  const Cell& cell = Cell::get();
  const auto frame = cell.render("empty", {}, cell.aligned_joints(), Lights::kTubes, 10);
  // Missing, empty, not an image, truncated.
  CliRun run = cellctl({"locate", path("nope.png")});
  EXPECT_EQ(run.code, 1);
  EXPECT_THAT(run.err, HasSubstr("nope.png: cannot open"));
  std::ofstream(path("empty.png")).close();
  run = cellctl({"locate", path("empty.png")});
  EXPECT_EQ(run.code, 1);
  EXPECT_THAT(run.err, HasSubstr("empty file (0 bytes)"));
  std::ofstream(path("notes.png")) << "not a picture\n";
  run = cellctl({"locate", path("notes.png")});
  EXPECT_EQ(run.code, 1);
  EXPECT_THAT(run.err, HasSubstr("not an image"));
  std::vector<std::uint8_t> png;
  cv::imencode(".png", frame.image, png);
  png.resize(png.size() / 3);
  std::ofstream(path("cut.png"), std::ios::binary)
      .write(reinterpret_cast<const char*>(png.data()), static_cast<std::streamsize>(png.size()));
  run = cellctl({"locate", path("cut.png")});
  EXPECT_EQ(run.code, 1);
  EXPECT_THAT(run.err, HasSubstr("truncated PNG"));
  // The wrong size for the calibration.
  const std::string small = save("small.png", frame.image(cv::Rect(0, 0, 300, 200)).clone());
  run = cellctl({"locate", small, "--calibration", save_true_calibration()});
  EXPECT_EQ(run.code, 1);
  EXPECT_THAT(run.err, HasSubstr("image is 300 x 200 px but the calibration of 'ibm7545_eye' is "
                                 "for 512 x 484"));
  // Bad options.
  run = cellctl({"locate", small, "--pipeline", "quick"});
  EXPECT_EQ(run.code, 2);
  EXPECT_THAT(run.err, HasSubstr("unknown pipeline 'quick'"));
  run = cellctl({"locate", small, "--calibration", path("nope.yaml")});
  EXPECT_EQ(run.code, 1);
  EXPECT_THAT(run.err, HasSubstr("nope.yaml"));
  run = cellctl({"locate", save("full.png", frame.image), "--calibration", path("true.yaml"),
                 "--joints", "45,135"});
  EXPECT_EQ(run.code, 2);
  EXPECT_THAT(run.err, HasSubstr("--joints"));
}

}  // namespace
}  // namespace cell::cellctl
