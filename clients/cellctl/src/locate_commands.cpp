// `cellctl locate IMAGE [--calibration FILE] [--joints ...] [--pipeline thesis|fast]`: the parts
// core/vision finds in an image file, locally (no bus): class, centre and corners [px], angle
// [deg, 0..180 for 2-fold symmetric parts], size [px] and, with a calibration, size [mm] and
// the pose in the robot's base frame [mm, deg].
#include <fmt/format.h>

#include <cmath>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <numbers>
#include <optional>
#include <string>

#include "cell/calibration/camera_calibration.hpp"
#include "cell/geometry/angles.hpp"
#include "cell/service/paths.hpp"
#include "cell/vision/image.hpp"
#include "cell/vision/locate.hpp"
#include "cell/vision/options.hpp"
#include "commands.hpp"
#include "robot_args.hpp"

namespace cell::cellctl {
namespace {

using nlohmann::json;

using geometry::kDeg;

struct LocateArgs {
  std::string image;
  std::string calibration;
  std::string joints;
  std::string pipeline;
  std::string config;
};

double round3(double v) { return std::round(v * 1000.0) / 1000.0; }

json detection_json(const vision::Detection& d) {
  json corners = json::array();
  for (const auto& c : d.corners_px) {
    corners.push_back(json::array({round3(c.x()), round3(c.y())}));
  }
  json part{{"class", d.class_name},
            {"shape", std::string(vision::to_string(d.shape))},
            {"center_px", json::array({round3(d.center_px.x()), round3(d.center_px.y())})},
            {"angle_deg", round3(d.angle_rad / kDeg)},
            {"corners_px", corners},
            {"length_px", round3(d.length_px)},
            {"width_px", round3(d.width_px)},
            {"quality", round3(d.quality)},
            {"touching", d.touching}};
  if (d.metric) {
    part["length_mm"] = round3(d.length_mm);
    part["width_mm"] = round3(d.width_mm);
  }
  if (d.has_base_pose) {
    part["world"] = {{"x_mm", round3(d.base_pose.x_mm)},
                     {"y_mm", round3(d.base_pose.y_mm)},
                     {"rz_deg", round3(d.base_pose.rz_rad / kDeg)}};
  }
  if (d.grip.verdict != vision::GripVerdict::kNotTested) {
    part["grip"] = {{"verdict", std::string(vision::to_string(d.grip.verdict))},
                    {"style", d.grip.style},
                    {"style_name", d.grip.style_name},
                    {"detail", d.grip.detail}};
    // Every clear style, where the tool goes in the robot's base frame (fingers along tool y).
    json clear = json::array();
    for (const auto& g : d.base_grasps) {
      clear.push_back({{"style", g.style},
                       {"name", g.name},
                       {"x_mm", round3(g.tool.x_mm)},
                       {"y_mm", round3(g.tool.y_mm)},
                       {"yaw_deg", round3(g.tool.rz_rad / kDeg)}});
    }
    part["grip"]["clear"] = clear;
  }
  return part;
}

int run_locate(Session& s, const LocateArgs& args) {
  // Options: the vision service's `locate:` section, so the command sees what the cell sees.
  vision::LocateOptions options;
  std::string config = args.config;
  if (config.empty()) {
    const std::string shipped = service::cell_home() + "/config/vision.yaml";
    std::error_code ec;
    if (std::filesystem::exists(shipped, ec)) {
      config = shipped;
    }
  }
  if (!config.empty()) {
    auto loaded = vision::load_locate_options(config);
    if (!loaded) {
      return s.fail(loaded.error().message, kExitUsage);
    }
    options = std::move(*loaded);
  }
  if (!args.pipeline.empty()) {
    auto p = vision::pipeline_from_string(args.pipeline);
    if (!p) {
      return s.fail("--pipeline: " + p.error().message, kExitUsage);
    }
    options.pipeline = *p;
  }
  auto image = vision::load_image_file(args.image);
  if (!image) {
    return s.fail(image.error().message);
  }
  // The mapping: none (pixels), or the calibration at the robot's joints.
  vision::PixelMapper mapper;
  std::string note;
  if (!args.calibration.empty()) {
    auto c = calibration::load_camera_calibration(args.calibration);
    if (!c) {
      return s.fail(c.error().message);
    }
    const bool needs_robot = c->mounting == calibration::Mounting::kEyeInHand ||
                             c->model == calibration::ModelType::kPlanar7545;
    std::optional<kinematics::RobotModel> robot;
    std::vector<double> joints;
    if (needs_robot && !c->robot_id.empty()) {
      auto r = load_robot_by_id(c->robot_id);
      if (!r) {
        return s.fail(r.error().message);
      }
      robot = std::move(*r);
      if (!args.joints.empty()) {
        auto values = parse_numbers(args.joints, "--joints");
        if (!values) {
          return s.fail(values.error().message, kExitUsage);
        }
        auto q = joints_from_display(*robot, *values, "--joints");
        if (!q) {
          return s.fail(q.error().message, kExitUsage);
        }
        joints.assign(q->data(), q->data() + q->size());
      } else {
        note = fmt::format("no --joints: the eye-in-hand camera on '{}' has no robot pose",
                           c->robot_id);
      }
    }
    auto m = vision::PixelMapper::create(*c, robot ? &*robot : nullptr, joints);
    if (!m) {
      return s.fail(m.error().message);
    }
    mapper = std::move(*m);
  }
  auto locator = vision::Locator::create(options);
  if (!locator) {
    return s.fail(locator.error().message, kExitUsage);
  }
  auto result = locator->locate(*image, mapper);
  if (!result) {
    return s.fail(fmt::format("{}: {}", args.image, result.error().message));
  }
  if (s.json()) {
    json parts = json::array();
    for (const auto& d : result->detections) {
      parts.push_back(detection_json(d));
    }
    json out{{"image", args.image},
             {"width_px", image->cols},
             {"height_px", image->rows},
             {"pipeline", std::string(vision::to_string(options.pipeline))},
             {"mapping", mapper.describe()},
             {"parts", parts},
             {"blobs", result->report.blobs},
             {"at_border", result->report.at_border},
             {"split", result->report.split},
             {"unresolved", result->report.unresolved}};
    if (!note.empty()) {
      out["note"] = note;
    }
    s.out() << out.dump(2) << "\n";
    return kExitOk;
  }
  s.out() << fmt::format("{}: {} x {} px, {} pipeline, {} part{}\nmapping: {}\n", args.image,
                         image->cols, image->rows, vision::to_string(options.pipeline),
                         result->detections.size(), result->detections.size() == 1 ? "" : "s",
                         mapper.describe());
  if (!note.empty()) {
    s.out() << "note: " << note << "\n";
  }
  for (std::size_t i = 0; i < result->detections.size(); ++i) {
    const auto& d = result->detections[i];
    s.out() << fmt::format(
        "{:3d} {:<10} centre ({:8.3f}, {:8.3f}) px  angle {:7.3f} deg  size "
        "{:.2f} x {:.2f} px  q {:.2f}{}",
        i, d.class_name, d.center_px.x(), d.center_px.y(), d.angle_rad / kDeg, d.length_px,
        d.width_px, d.quality, d.touching ? "  touching" : "");
    if (d.metric) {
      s.out() << fmt::format("  {:.2f} x {:.2f} mm", d.length_mm, d.width_mm);
    }
    if (d.has_base_pose) {
      s.out() << fmt::format("  world ({:.2f}, {:.2f}) mm {:.2f} deg", d.base_pose.x_mm,
                             d.base_pose.y_mm, d.base_pose.rz_rad / kDeg);
    }
    if (d.grip.verdict != vision::GripVerdict::kNotTested) {
      s.out() << fmt::format("  grip {}{}", vision::to_string(d.grip.verdict),
                             d.grip.style >= 0 ? fmt::format(" ({})", d.grip.style_name) : "");
    }
    s.out() << "\n";
  }
  return kExitOk;
}

}  // namespace

void add_locate_commands(CLI::App& app, Commands& commands) {
  auto args = std::make_shared<LocateArgs>();
  CLI::App* locate = app.add_subcommand(
      "locate", "find and locate the parts in an image file (core/vision, no bus)");
  locate->add_option("image", args->image, "image file (PNG, JPEG, BMP, PGM/PPM, TIFF)")
      ->required();
  locate->add_option("--calibration", args->calibration,
                     "camera calibration file (core/calibration format): sizes in mm and the "
                     "pose in the robot base frame");
  locate->add_option("--joints", args->joints,
                     "the carrying robot's joints at the exposure (deg / mm, comma-separated) "
                     "for an eye-in-hand calibration");
  locate->add_option("--pipeline", args->pipeline, "fast (default) or thesis");
  locate->add_option("--config", args->config,
                     "vision config whose `locate:` section to use (default: "
                     "$CELL_HOME/config/vision.yaml)");
  commands.add(locate, [args](Session& s) { return run_locate(s, *args); });
}

}  // namespace cell::cellctl
