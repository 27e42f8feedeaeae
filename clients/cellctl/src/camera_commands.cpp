// `cellctl camera grab`: one frame from a camera service (cell/vision/image_request, answered
// on cell/vision/image, refusals and ground truth on cell/vision/image_truth), saved with
// cv::imwrite, plus the frame's ground truth as JSON for simulated cameras.
#include <cmath>
#include <fstream>
#include <optional>

#include <fmt/format.h>
#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include "cell/bus/reader.hpp"
#include "cell/bus/request_reply.hpp"
#include "cell/bus/view.hpp"
#include "cell/bus/writer.hpp"
#include "cell/common/time.hpp"
#include "cell/geometry/angles.hpp"
#include "cell/motion/wire.hpp"
#include "commands.hpp"
#include "robot_args.hpp"

namespace cell::cellctl {
namespace {

using nlohmann::json;
using std::chrono::steady_clock;

struct GrabArgs {
  std::string camera;
  std::string output;
  std::string truth;
  std::string trigger = "now";
};

using geometry::kDeg;

json pixel_json(const cell_vision_PixelPoint& p) { return json{{"u_px", p.u_px}, {"v_px", p.v_px}}; }

/// The ground truth of a frame as JSON: the true camera, and per part its centre, angle and
/// corners in pixels and its pose in the world (mm, deg).
json truth_json(const cell_vision_ImageTruth& t, const cell_vision_Image& image) {
  json parts = json::array();
  for (const auto& p : bus::span(t.parts)) {
    json corners = json::array();
    for (const auto& c : bus::span(p.corners_px)) {
      corners.push_back(pixel_json(c));
    }
    json part{{"part_id", std::string(bus::str(p.part_id))},
              {"class", std::string(bus::str(p.class_name))},
              {"center_px", pixel_json(p.center_px)},
              {"angle_rad", p.angle_rad},
              {"angle_deg", p.angle_rad / kDeg},
              {"corners_px", corners},
              {"visible_fraction", p.visible_fraction}};
    if (auto pose = motion::from_idl(p.world_T_part); pose) {
      part["world_T_part"] = pose_json(*pose);
    }
    parts.push_back(part);
  }
  json camera{{"fx_px", t.fx_px},
              {"fy_px", t.fy_px},
              {"cx_px", t.cx_px},
              {"cy_px", t.cy_px},
              {"distortion_k1_k2_p1_p2_k3", bus::to_vector(t.distortion)}};
  if (auto pose = motion::from_idl(t.world_T_camera); pose) {
    camera["world_T_camera"] = pose_json(*pose);
  }
  return json{{"camera_id", std::string(bus::str(t.camera_id))},
              {"image_seq", t.image_seq},
              {"stamp_ns", image.header.stamp_ns},
              {"stamp", format_iso8601(image.header.stamp_ns)},
              {"pixel_convention", "u right, v down, (0, 0) at the centre of the top-left pixel"},
              {"true_camera", camera},
              {"parts", parts}};
}

int grab(Session& session, const GrabArgs& args) {
  if (args.trigger != "now" && args.trigger != "photocell") {
    return session.fail(fmt::format("--trigger must be now or photocell, got '{}'", args.trigger),
                        kExitUsage);
  }
  if (!cv::haveImageWriter(args.output)) {
    return session.fail(fmt::format("-o {}: OpenCV cannot write this image format (use .png, "
                                    ".pgm, .bmp, .tif or .jpg)",
                                    args.output),
                        kExitUsage);
  }
  const bool photocell = args.trigger == "photocell";
  const bool want_truth = !args.truth.empty();
  const bus::Participant& participant = session.participant();
  bus::Topic<cell_vision_ImageRequest> request_topic(participant, bus::topics::kImageRequest);
  bus::Topic<cell_vision_Image> image_topic(participant, bus::topics::kImage);
  bus::Topic<cell_vision_ImageTruth> truth_topic(participant, bus::topics::kImageTruth);
  bus::Writer<cell_vision_ImageRequest> requests(participant, request_topic,
                                                 bus::topics::kImageRequest);
  bus::Reader<cell_vision_Image> images(participant, image_topic, bus::topics::kImage);
  bus::Reader<cell_vision_ImageTruth> truths(participant, truth_topic, bus::topics::kImageTruth);
  const auto deadline = steady_clock::now() + session.timeout();
  // Images are a best-effort stream: ask only once the camera's image writer is matched, or
  // the answer may leave before it knows this reader.
  if (!requests.wait_for_readers(1, session.timeout()) ||
      !images.wait_for_writers(1, std::chrono::duration_cast<std::chrono::milliseconds>(
                                      deadline - steady_clock::now()))) {
    return session.fail(fmt::format("no camera service on {} (is camera.{} running?)",
                                    session.describe_bus(), args.camera));
  }
  const std::string client_id = bus::make_client_id("cellctl");
  std::uint64_t seq = 0;
  auto send = [&]() {
    cell_vision_ImageRequest r{};
    r.request_id.client_id = bus::borrow(client_id);
    r.request_id.seq = ++seq;
    r.camera_id = bus::borrow(args.camera);
    r.trigger = photocell ? cell_vision_TRIGGER_PHOTOCELL : cell_vision_TRIGGER_NOW;
    r.with_truth = want_truth;
    return requests.write(r);
  };
  if (auto s = send(); !s) {
    return session.fail(s.error().message);
  }
  // A NOW frame that does not come within a second was probably sent before the camera
  // matched this reader: ask again (every request is answered; extra frames are harmless).
  auto resend_at = steady_clock::now() + std::chrono::seconds(1);
  std::optional<bus::Owned<cell_vision_Image>> image;
  std::optional<bus::Owned<cell_vision_ImageTruth>> truth;
  std::optional<std::string> refusal;
  std::optional<steady_clock::time_point> refusal_grace;
  auto mine = [&](const cell_common_RequestId& id) {
    return bus::str(id.client_id) == client_id && id.seq >= 1 && id.seq <= seq;
  };
  while (steady_clock::now() < deadline) {
    if (auto batch = images.take_copies(4); batch) {
      for (auto& i : *batch) {
        if (!image && mine(i->request_id)) {
          image = std::move(i);
        }
      }
    }
    if (auto batch = truths.take_copies(16); batch) {
      for (auto& t : *batch) {
        if (!mine(t->request_id)) {
          continue;
        }
        if (t->status.accepted) {
          if (!truth) {
            truth = std::move(t);
          }
        } else if (!refusal) {
          refusal = fmt::format("camera '{}' refused ({}): {}", args.camera,
                                bus::str(t->status.error_code), bus::str(t->status.reason));
          // A source without ground truth refuses the truth but still sends its image.
          refusal_grace = steady_clock::now() + std::chrono::milliseconds(500);
        }
      }
    }
    const bool complete = image && (!want_truth || truth);
    if (complete || (refusal && (image || steady_clock::now() > *refusal_grace))) {
      break;
    }
    if (!photocell && !image && !refusal && steady_clock::now() > resend_at) {
      (void)send();
      resend_at = steady_clock::now() + std::chrono::seconds(1);
    }
    (void)images.wait_for_data(std::chrono::milliseconds(20));
  }
  if (!image) {
    if (refusal) {
      return session.fail(*refusal);
    }
    return session.fail(fmt::format(
        "no frame from camera '{}' within {:.1f} s (is camera.{} running on {}?{})", args.camera,
        std::chrono::duration<double>(session.timeout()).count(), args.camera,
        session.describe_bus(), photocell ? " did a part pass the photocell?" : ""));
  }
  const cell_vision_Image& img = image->get();
  const std::string encoding(bus::str(img.encoding));
  const std::size_t expected = static_cast<std::size_t>(img.step_bytes) * img.height_px;
  if ((encoding != "mono8" && encoding != "rgb8") || img.data._length < expected ||
      img.step_bytes < img.width_px * (encoding == "rgb8" ? 3U : 1U)) {
    return session.fail(fmt::format("camera '{}' sent a malformed image: {} x {} {} with {} "
                                    "bytes, step {}",
                                    args.camera, img.width_px, img.height_px, encoding,
                                    img.data._length, img.step_bytes));
  }
  cv::Mat view(static_cast<int>(img.height_px), static_cast<int>(img.width_px),
               encoding == "mono8" ? CV_8UC1 : CV_8UC3, img.data._buffer, img.step_bytes);
  try {
    if (!cv::imwrite(args.output, view)) {
      return session.fail(fmt::format("-o {}: cannot write the image", args.output));
    }
  } catch (const cv::Exception& e) {
    return session.fail(fmt::format("-o {}: {}", args.output, e.what()));
  }
  json report{{"camera", args.camera},
              {"saved", args.output},
              {"width_px", img.width_px},
              {"height_px", img.height_px},
              {"encoding", encoding},
              {"seq", img.header.seq},
              {"stamp_ns", img.header.stamp_ns},
              {"stamp", format_iso8601(img.header.stamp_ns)}};
  std::string robot_line;
  if (const std::string robot(bus::str(img.robot_id)); !robot.empty()) {
    report["robot_id"] = robot;
    const auto q = bus::to_vector(img.robot_joints_rad_or_mm);
    auto model = load_robot_by_id(robot);
    if (model && static_cast<int>(q.size()) == model->dof()) {
      kinematics::JointVector jq(model->dof());
      for (int j = 0; j < model->dof(); ++j) {
        jq[j] = q[static_cast<std::size_t>(j)];
      }
      report["robot_joints"] = joints_json(*model, jq);
      robot_line = fmt::format(", robot {} at {}", robot, joints_text(*model, jq));
    } else {
      report["robot_joints_rad_or_mm"] = q;
      robot_line = fmt::format(", robot {}", robot);
    }
  }
  std::string belt_line;
  if (const std::string belt(bus::str(img.belt_id)); !belt.empty()) {
    report["belt_id"] = belt;
    report["belt_count"] = img.belt_count;
    belt_line = fmt::format(", belt {} count {}", belt, img.belt_count);
  }
  int code = kExitOk;
  std::string truth_line;
  if (want_truth) {
    if (truth) {
      std::ofstream out(args.truth);
      out << truth_json(truth->get(), img).dump(2) << "\n";
      if (!out) {
        return session.fail(fmt::format("--truth {}: cannot write the file", args.truth));
      }
      report["truth"] = args.truth;
      report["parts"] = (*truth)->parts._length;
      truth_line = fmt::format("; truth in {} ({} visible parts)", args.truth,
                               (*truth)->parts._length);
    } else {
      report["truth"] = nullptr;
      report["truth_refused"] = refusal.value_or("no ground truth came in time");
      code = session.fail(fmt::format("frame saved, but no truth: {}",
                                      refusal.value_or("no ground truth came in time")));
    }
  }
  if (session.json()) {
    session.out() << report.dump(2) << "\n";
  } else {
    session.out() << fmt::format("saved {}: {} x {} {}, camera {}, exposure {}, seq {}{}{}{}\n",
                                 args.output, img.width_px, img.height_px, encoding, args.camera,
                                 format_iso8601(img.header.stamp_ns), img.header.seq, robot_line,
                                 belt_line, truth_line);
  }
  return code;
}

}  // namespace

void add_camera_commands(CLI::App& app, Commands& commands) {
  CLI::App* camera = app.add_subcommand("camera", "cameras: grab a frame (and its ground truth)");
  camera->require_subcommand(1);
  auto args = std::make_shared<GrabArgs>();
  CLI::App* g = camera->add_subcommand(
      "grab", "save one frame of a camera; --truth also saves what a simulated frame shows");
  g->add_option("--camera", args->camera, "camera id, e.g. ibm7545_eye, belt_cam")->required();
  g->add_option("-o,--output", args->output, "image file to write (.png, .pgm, .tif, ...)")
      ->required();
  g->add_option("--truth", args->truth,
                "JSON file for the ground truth: every visible part's centre, angle and corners "
                "[px] and pose in the world [mm, deg] (simulated cameras)");
  g->add_option("--trigger", args->trigger,
                "now (default) or photocell: the next photocell edge of the camera's belt");
  commands.add(g, [args](Session& session) { return grab(session, *args); });
}

}  // namespace cell::cellctl
