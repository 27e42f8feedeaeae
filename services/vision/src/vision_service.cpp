#include "vision_service.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <stdexcept>

#include "cell/bus/view.hpp"
#include "cell/common/log.hpp"
#include "cell/common/time.hpp"
#include "cell/kinematics/robot_config.hpp"
#include "cell/render/camera_file.hpp"
#include "cell/vision/edge.hpp"
#include "cell/vision/image.hpp"

namespace cell::vision {
namespace {

using std::chrono::steady_clock;

constexpr dds_attach_t kStop = 1;
constexpr dds_attach_t kImages = 2;
constexpr dds_attach_t kEdges = 3;
constexpr dds_attach_t kCalibrations = 4;
constexpr auto kIdlePeriod = std::chrono::milliseconds(200);
constexpr auto kWarnEvery = std::chrono::seconds(10);

Locator make_locator(const LocateOptions& options) {
  auto locator = Locator::create(options);
  if (!locator) {
    throw std::runtime_error("locate options: " + locator.error().message);
  }
  return std::move(*locator);
}

cell_vision_GripClearance to_idl(GripVerdict v) {
  switch (v) {
    case GripVerdict::kClear:
      return cell_vision_GRIP_CLEAR;
    case GripVerdict::kBlocked:
      return cell_vision_GRIP_BLOCKED;
    case GripVerdict::kNotTested:
      break;
  }
  return cell_vision_GRIP_NOT_TESTED;
}

std::string calibration_label(const calibration::CameraCalibration& c) {
  return c.version.empty() ? c.source : c.version;
}

/// The strings and sequences a Detections sample borrows: they live until it is written.
struct DetectionsHolder {
  std::vector<std::string> classes;
  std::vector<std::string> shapes;
  std::vector<std::string> details;
  std::vector<std::vector<cell_vision_PixelPoint>> corners;
  /// Per item; the names are borrowed from the located Detections, which outlive the write.
  std::vector<std::vector<cell_vision_GraspPose>> grasps;
  std::vector<cell_vision_Detection> items;
};

}  // namespace

VisionService::VisionService(service::Context& ctx, const VisionConfig& config)
    : ctx_(ctx),
      config_(config),
      locator_(make_locator(config.locate)),
      image_topic_(ctx.participant(), bus::topics::kImage),
      detections_topic_(ctx.participant(), bus::topics::kDetections),
      edge_request_topic_(ctx.participant(), bus::topics::kEdgeRequest),
      edge_result_topic_(ctx.participant(), bus::topics::kEdgeResult),
      calibration_topic_(ctx.participant(), bus::topics::kCameraCalibration),
      images_reader_(ctx.participant(), image_topic_, bus::topics::kImage),
      edge_reader_(ctx.participant(), edge_request_topic_, bus::topics::kEdgeRequest),
      calibration_reader_(ctx.participant(), calibration_topic_, bus::topics::kCameraCalibration),
      detections_writer_(ctx.participant(), detections_topic_, bus::topics::kDetections),
      edge_writer_(ctx.participant(), edge_result_topic_, bus::topics::kEdgeResult) {
  for (const CameraEntry& entry : config_.cameras) {
    if (entry.locate) {
      camera_locators_.emplace(entry.id, make_locator(*entry.locate));
    }
  }
  // The configured cameras start with their nominal calibrations (logged one by one).
  for (const CameraEntry& entry : config_.cameras) {
    std::string why;
    (void)camera(entry.id, why);
  }
  log::info("vision", "vision ready",
            {{"pipeline", to_string(config_.locate.pipeline)},
             {"cameras", std::to_string(config_.cameras.size())},
             {"grasp_models", std::to_string(config_.locate.grasps.size())}});
}

// ---------------------------------------------------------------------------------------------
// Cameras, calibrations, robots.

VisionService::Camera* VisionService::camera(const std::string& id, std::string& why) {
  if (auto it = cameras_.find(id); it != cameras_.end()) {
    return &it->second;
  }
  if (id.empty()) {
    why = "the sample names no camera (camera_id is empty)";
    return nullptr;
  }
  const CameraEntry* entry = config_.camera(id);
  const std::string file =
      entry != nullptr ? entry->camera_file : config_.camera_dir + "/" + id + ".yaml";
  std::error_code ec;
  if (entry == nullptr && !std::filesystem::exists(file, ec)) {
    std::string known;
    for (const CameraEntry& c : config_.cameras) {
      known += (known.empty() ? "" : ", ") + c.id;
    }
    why = fmt::format(
        "unknown camera '{}': not in the vision config, no camera file {}, no "
        "calibration published (configured cameras: {})",
        id, file, known.empty() ? "none" : known);
    return nullptr;
  }
  Camera cam;
  cam.id = id;
  auto description = render::load_camera(file);
  if (!description) {
    cam.nominal_problem = description.error().message;
  } else if (entry == nullptr) {
    cam.nominal_problem = fmt::format(
        "camera '{}' has a camera file but no entry in the vision "
        "config (its working plane is unknown)",
        id);
  } else {
    auto nominal = calibration::nominal_calibration(*description, entry->robot_id,
                                                    entry->world_T_base, entry->working_plane_z_mm);
    if (nominal) {
      cam.nominal = std::move(*nominal);
    } else {
      cam.nominal_problem = nominal.error().message;
    }
  }
  if (cam.nominal) {
    log::info("calibration",
              "using the NOMINAL calibration of the camera file until a calibration is "
              "published on cell/calibration/camera",
              {{"camera", id}, {"file", file}, {"robot", cam.nominal->robot_id}});
  } else {
    log::warn("calibration", "no nominal calibration: pixels only until one is published",
              {{"camera", id}, {"reason", cam.nominal_problem}});
  }
  auto [it, inserted] = cameras_.emplace(id, std::move(cam));
  (void)inserted;
  rebuild_mapper(it->second);
  return &it->second;
}

const kinematics::RobotModel* VisionService::robot(const std::string& id, std::string& why) {
  if (id.empty()) {
    return nullptr;
  }
  auto it = robots_.find(id);
  if (it == robots_.end()) {
    auto loaded = kinematics::load_robot(config_.robot_dir + "/" + id + ".yaml");
    if (!loaded) {
      robot_problems_[id] = loaded.error().message;
      log::warn("robot", "cannot load the robot model: no robot poses for its cameras",
                {{"robot", id}, {"reason", loaded.error().message}});
      it = robots_.emplace(id, std::nullopt).first;
    } else {
      it = robots_.emplace(id, std::move(*loaded)).first;
    }
  }
  if (!it->second) {
    why = robot_problems_[id];
    return nullptr;
  }
  return &*it->second;
}

void VisionService::rebuild_mapper(Camera& cam) {
  const calibration::CameraCalibration* c =
      cam.published ? &*cam.published : (cam.nominal ? &*cam.nominal : nullptr);
  cam.mapper.reset();
  cam.mapper_problem.clear();
  if (c == nullptr) {
    cam.mapper_problem = cam.nominal_problem;
    return;
  }
  std::string why;
  const kinematics::RobotModel* rob = robot(c->robot_id, why);
  auto m = PixelMapper::create(*c, rob, {});
  if (!m) {
    cam.mapper_problem = m.error().message;
    log::warn("calibration", "calibration cannot map this camera: pixels only",
              {{"camera", cam.id}, {"reason", m.error().message}});
    return;
  }
  cam.mapper = std::move(*m);
}

void VisionService::take_calibrations() {
  (void)calibration_reader_.take_each(
      [&](const cell_calibration_CameraCalibration& sample, const dds_sample_info_t&) {
        try {
          const std::string id(bus::str(sample.camera_id));
          auto c = calibration::from_idl(sample);
          if (!c) {
            log::warn("calibration", "refused a published calibration",
                      {{"camera", id}, {"reason", c.error().message}});
            ctx_.events().publish(cell_health_SEVERITY_WARNING, "vision.bad_calibration",
                                  fmt::format("camera '{}': {}", id, c.error().message));
            return;
          }
          Camera* cam = nullptr;
          if (auto it = cameras_.find(id); it != cameras_.end()) {
            cam = &it->second;
          } else {
            std::string why;
            cam = camera(id, why);
            if (cam == nullptr) {  // no file, no entry: the published calibration is all
              Camera fresh;
              fresh.id = id;
              fresh.nominal_problem = why;
              cam = &cameras_.emplace(id, std::move(fresh)).first->second;
            }
          }
          cam->published = *c;
          rebuild_mapper(*cam);
          log::info("calibration", "published calibration in use: re-mapping at once",
                    {{"camera", id},
                     {"version", calibration_label(*c)},
                     {"model", calibration::to_string(c->model)}});
          if (!cam->history.empty()) {
            process(*cam, cam->history.back());  // its last image, mapped again
          }
        } catch (const std::exception& e) {
          log::error("calibration", fmt::format("internal error: {}", e.what()));
        }
      });
}

// ---------------------------------------------------------------------------------------------
// Images and detections.

void VisionService::take_images() {
  (void)images_reader_.take_each([&](const cell_vision_Image& image, const dds_sample_info_t&) {
    try {
      handle_image(image);
    } catch (const std::exception& e) {  // the boundary: an image never kills the service
      publish_error(image, std::string(bus::str(image.camera_id)),
                    Error{Errc::kInvalidArgument, fmt::format("internal error: {}", e.what())});
    }
  });
}

void VisionService::handle_image(const cell_vision_Image& image) {
  const std::string id(bus::str(image.camera_id));
  std::string why;
  Camera* cam = camera(id, why);
  if (cam == nullptr) {
    publish_error(image, id, Error{Errc::kInvalidArgument, why});
    return;
  }
  const auto data = bus::span(image.data);
  auto mat =
      image_from_raw(image.width_px, image.height_px, image.step_bytes, bus::str(image.encoding),
                     std::span<const std::uint8_t>(data.data(), data.size()));
  if (!mat) {
    publish_error(image, id, mat.error());
    return;
  }
  Frame frame;
  frame.seq = image.header.seq;
  frame.stamp_ns = image.header.stamp_ns;
  frame.image = std::move(*mat);
  frame.joints = bus::to_vector(image.robot_joints_rad_or_mm);
  frame.robot_id = std::string(bus::str(image.robot_id));
  frame.belt_count = image.belt_count;
  frame.belt_id = std::string(bus::str(image.belt_id));
  frame.request_client = std::string(bus::str(image.request_id.client_id));
  frame.request_seq = image.request_id.seq;
  process(*cam, frame);
  cam->history.push_back(std::move(frame));
  while (static_cast<int>(cam->history.size()) > config_.history_frames) {
    cam->history.pop_front();
  }
  serve_pending(*cam, cam->history.back());
}

Locator& VisionService::locator_for(const std::string& camera_id) {
  const auto it = camera_locators_.find(camera_id);
  return it == camera_locators_.end() ? locator_ : it->second;
}

void VisionService::process(Camera& cam, const Frame& frame) {
  const auto started = steady_clock::now();
  ++images_;
  // The mapper for this frame: the camera's calibration at the joints of the exposure.
  PixelMapper mapper;
  std::string mapping_note;
  if (cam.mapper) {
    mapper = *cam.mapper;
    const auto& c = *cam.mapper->calibration();
    const bool needs_joints = c.mounting == calibration::Mounting::kEyeInHand ||
                              c.model == calibration::ModelType::kPlanar7545;
    if (needs_joints) {
      std::string why;
      const kinematics::RobotModel* rob = robot(c.robot_id, why);
      if (!frame.robot_id.empty() && frame.robot_id != c.robot_id) {
        mapping_note = fmt::format("; the image's joints are robot '{}', the calibration's '{}'",
                                   frame.robot_id, c.robot_id);
      } else if (!frame.joints.empty()) {
        auto bound = cam.mapper->rebind(rob, frame.joints);
        if (bound) {
          mapper = std::move(*bound);
        } else {
          mapping_note = "; " + bound.error().message;
        }
      }
    }
  }
  Locator& locator = locator_for(cam.id);
  auto located = locator.locate(frame.image, mapper);
  const double ms =
      std::chrono::duration<double, std::milli>(steady_clock::now() - started).count();
  const std::string pipeline(to_string(locator.options().pipeline));
  std::string calibration = cam.mapper ? mapper.describe() + mapping_note
                                       : "none: pixels only (" + cam.mapper_problem + ")";
  if (cam.mapper && !cam.published) {
    calibration = "NOMINAL " + calibration;
  }
  const std::string frame_id =
      mapper.world() ? mapper.robot_id() + "/base" : cam.id;  // the frame of base poses
  std::string error;
  DetectionsHolder h;
  if (!located) {
    error = located.error().message;
    const std::string key = cam.id + "/locate";
    const auto now = steady_clock::now();
    if (now - last_warned_[key] > kWarnEvery) {
      last_warned_[key] = now;
      log::warn("reject", error, {{"camera", cam.id}, {"seq", std::to_string(frame.seq)}});
    }
  } else {
    const auto& dets = located->detections;
    h.classes.reserve(dets.size());
    h.shapes.reserve(dets.size());
    h.details.reserve(dets.size());
    h.corners.reserve(dets.size());
    h.grasps.reserve(dets.size());
    h.items.reserve(dets.size());
    for (std::size_t i = 0; i < dets.size(); ++i) {
      const Detection& d = dets[i];
      h.classes.push_back(d.class_name);
      h.shapes.emplace_back(to_string(d.shape));
      h.details.push_back(d.grip.detail);
      auto& corners = h.corners.emplace_back();
      for (const auto& c : d.corners_px) {
        corners.push_back({c.x(), c.y()});
      }
      auto& grasps = h.grasps.emplace_back();
      for (const BaseGrasp& g : d.base_grasps) {
        cell_vision_GraspPose pose{};
        pose.style = g.style;
        pose.name = bus::borrow(g.name);
        pose.base_pose = {g.tool.x_mm, g.tool.y_mm, g.tool.rz_rad};
        grasps.push_back(pose);
      }
      cell_vision_Detection item{};
      item.id = static_cast<std::uint32_t>(i);
      item.class_name = bus::borrow(h.classes.back());
      item.center_px = {d.center_px.x(), d.center_px.y()};
      item.angle_rad = d.angle_rad;
      bus::borrow(item.corners_px, corners);
      item.length_mm = d.length_mm;
      item.width_mm = d.width_mm;
      item.base_pose.x_mm = d.base_pose.x_mm;
      item.base_pose.y_mm = d.base_pose.y_mm;
      item.base_pose.rz_rad = d.base_pose.rz_rad;
      item.has_base_pose = d.has_base_pose;
      item.quality = d.quality;
      item.grip = to_idl(d.grip.verdict);
      item.grip_style = d.grip.style;
      item.grip_detail = bus::borrow(h.details.back());
      item.length_px = d.length_px;
      item.width_px = d.width_px;
      item.shape = bus::borrow(h.shapes.back());
      item.touching = d.touching;
      bus::borrow(item.clear_grasps, grasps);
      h.items.push_back(item);
    }
  }
  cell_vision_Detections msg{};
  msg.camera_id = bus::borrow(cam.id);
  msg.header.stamp_ns = frame.stamp_ns;
  msg.header.frame_id = bus::borrow(frame_id);
  msg.header.seq = ++detections_seq_;
  msg.image_sequence = frame.seq;
  bus::borrow(msg.items, h.items);
  bus::borrow(msg.robot_joints_rad_or_mm, frame.joints);
  msg.robot_id = bus::borrow(frame.robot_id);
  msg.belt_count = frame.belt_count;
  msg.belt_id = bus::borrow(frame.belt_id);
  msg.processing_ms = ms;
  msg.error = bus::borrow(error);
  msg.pipeline = bus::borrow(pipeline);
  msg.calibration = bus::borrow(calibration);
  msg.request_id.client_id = bus::borrow(frame.request_client);  // whose request it answers
  msg.request_id.seq = frame.request_seq;
  if (auto s = detections_writer_.write(msg); !s) {
    log::warn("detections", s.error().message, {{"camera", cam.id}});
  }
  log::debug("detections", fmt::format("{} parts in {:.2f} ms", h.items.size(), ms),
             {{"camera", cam.id}, {"seq", std::to_string(frame.seq)}});
}

void VisionService::publish_error(const cell_vision_Image& image,
                                  const std::string& camera_id,
                                  const Error& error) {
  const auto now = steady_clock::now();
  const std::string key = camera_id + "/" + std::string(to_string(error.code));
  if (now - last_warned_[key] > kWarnEvery) {
    last_warned_[key] = now;
    log::warn("reject", error.message,
              {{"camera", camera_id.empty() ? "-" : camera_id},
               {"seq", std::to_string(image.header.seq)}});
  }
  static const std::string kNone;
  const std::string pipeline(to_string(locator_for(camera_id).options().pipeline));
  const std::string robot_id(bus::str(image.robot_id));
  const std::string belt_id(bus::str(image.belt_id));
  cell_vision_Detections msg{};
  msg.camera_id = bus::borrow(camera_id);
  msg.header.stamp_ns = image.header.stamp_ns;
  msg.header.frame_id = bus::borrow(camera_id);
  msg.header.seq = ++detections_seq_;
  msg.image_sequence = image.header.seq;
  msg.robot_id = bus::borrow(robot_id);
  msg.belt_count = image.belt_count;
  msg.belt_id = bus::borrow(belt_id);
  msg.error = bus::borrow(error.message);
  msg.pipeline = bus::borrow(pipeline);
  msg.calibration = bus::borrow(kNone);
  msg.request_id = image.request_id;  // a refusal answers the request too
  if (auto s = detections_writer_.write(msg); !s) {
    log::warn("detections", s.error().message, {{"camera", camera_id}});
  }
}

// ---------------------------------------------------------------------------------------------
// Edge requests: every one gets an EdgeResult.

void VisionService::take_edge_requests() {
  (void)edge_reader_.take_each([&](const cell_vision_EdgeRequest& request,
                                   const dds_sample_info_t&) {
    PendingEdge edge;
    edge.client_id = std::string(bus::str(request.request_id.client_id));
    edge.camera_id = std::string(bus::str(request.camera_id));
    edge.request = request;
    edge.request.request_id.client_id = nullptr;  // the loan ends here: strings are copied
    edge.request.camera_id = nullptr;
    edge.image_sequence = request.image_sequence;
    try {
      std::string why;
      Camera* cam = camera(edge.camera_id, why);
      if (cam == nullptr) {
        const Error e{Errc::kInvalidArgument, why};
        answer(edge, nullptr, &e);
        return;
      }
      const std::uint64_t latest = cam->history.empty() ? 0 : cam->history.back().seq;
      if (edge.image_sequence != 0) {
        for (const Frame& f : cam->history) {
          if (f.seq == edge.image_sequence) {
            answer(edge, &f, nullptr);
            return;
          }
        }
        if (edge.image_sequence < latest) {
          const Error e{
              Errc::kOutOfRange,
              fmt::format("image {} of camera '{}' is no longer held (holding {}..{})",
                          edge.image_sequence, edge.camera_id, cam->history.front().seq, latest)};
          answer(edge, nullptr, &e);
          return;
        }
      }
      if (static_cast<int>(pending_.size()) >= config_.max_pending_edges) {
        const Error e{Errc::kOutOfRange,
                      fmt::format("{} edge requests already wait for images", pending_.size())};
        answer(edge, nullptr, &e);
        return;
      }
      edge.after_seq = latest;
      edge.deadline =
          steady_clock::now() + std::chrono::duration_cast<steady_clock::duration>(
                                    std::chrono::duration<double>(config_.edge_image_timeout_s));
      pending_.push_back(std::move(edge));
    } catch (const std::exception& e) {
      const Error err{Errc::kInvalidArgument, fmt::format("internal error: {}", e.what())};
      answer(edge, nullptr, &err);
    }
  });
}

void VisionService::serve_pending(const Camera& cam, const Frame& frame) {
  for (auto it = pending_.begin(); it != pending_.end();) {
    const bool mine =
        it->camera_id == cam.id && ((it->image_sequence == 0 && frame.seq != it->after_seq) ||
                                    it->image_sequence == frame.seq);
    if (mine) {
      answer(*it, &frame, nullptr);
      it = pending_.erase(it);
    } else {
      ++it;
    }
  }
}

void VisionService::expire_edges() {
  const auto now = steady_clock::now();
  for (auto it = pending_.begin(); it != pending_.end();) {
    if (now >= it->deadline) {
      const Error e{
          Errc::kTimeout,
          it->image_sequence == 0
              ? fmt::format("no image from camera '{}' within {} s", it->camera_id,
                            config_.edge_image_timeout_s)
              : fmt::format("image {} of camera '{}' did not come within {} s", it->image_sequence,
                            it->camera_id, config_.edge_image_timeout_s)};
      answer(*it, nullptr, &e);
      it = pending_.erase(it);
    } else {
      ++it;
    }
  }
}

void VisionService::answer(const PendingEdge& edge, const Frame* frame, const Error* error) {
  const cell_vision_EdgeRequest& r = edge.request;
  std::optional<Error> failure;
  if (error != nullptr) {
    failure = *error;
  }
  EdgeWindow window;
  EdgeMeasurement measured;
  if (!failure && frame != nullptr) {
    try {
      auto w = suggest_window({r.predicted_start_px.u_px, r.predicted_start_px.v_px},
                              {r.predicted_end_px.u_px, r.predicted_end_px.v_px},
                              r.search_halfwidth_px, frame->image.cols, frame->image.rows);
      if (!w) {
        failure = w.error();
      } else {
        window = *w;
        auto m = find_edge(frame->image, window, config_.edges);
        if (!m) {
          failure = m.error();
        } else {
          measured = *m;
        }
      }
    } catch (const std::exception& e) {
      failure = Error{Errc::kInvalidArgument, fmt::format("internal error: {}", e.what())};
    }
  }
  const std::string code = failure ? std::string(to_string(failure->code)) : std::string();
  const std::string reason = failure ? failure->message : std::string();
  cell_vision_EdgeResult out{};
  out.request_id.client_id = bus::borrow(edge.client_id);
  out.request_id.seq = r.request_id.seq;
  out.status.accepted = !failure;
  out.status.error_code = bus::borrow(code);
  out.status.reason = bus::borrow(reason);
  out.camera_id = bus::borrow(edge.camera_id);
  out.start_px = {measured.start_px.x(), measured.start_px.y()};
  out.end_px = {measured.end_px.x(), measured.end_px.y()};
  out.residual_px = measured.residual_px;
  out.point_count = static_cast<std::uint32_t>(measured.point_count);
  out.window_p1_px = {window.p1.x(), window.p1.y()};
  out.window_p2_px = {window.p2.x(), window.p2.y()};
  out.window_p3_px = {window.p3.x(), window.p3.y()};
  out.image_sequence = frame != nullptr ? frame->seq : 0;
  if (failure) {
    log::info("reject", reason,
              {{"camera", edge.camera_id.empty() ? "-" : edge.camera_id},
               {"client", edge.client_id},
               {"seq", std::to_string(r.request_id.seq)}});
  }
  ++edge_replies_;
  if (auto s = edge_writer_.write(out); !s) {
    log::warn("edge_result", s.error().message, {{"camera", edge.camera_id}});
  }
}

// ---------------------------------------------------------------------------------------------

void VisionService::run(service::Context& ctx) {
  bus::WaitSet waitset(ctx.participant());
  waitset.attach(ctx.stop_guard().get(), kStop);
  waitset.attach(images_reader_.condition(), kImages);
  waitset.attach(edge_reader_.condition(), kEdges);
  waitset.attach(calibration_reader_.condition(), kCalibrations);
  ctx.health().set(cell_health_HEALTH_SERVING);
  for (;;) {
    auto wake = steady_clock::now() + kIdlePeriod;
    for (const PendingEdge& p : pending_) {
      wake = std::min(wake, p.deadline);
    }
    const bus::Fired fired = waitset.wait_until(wake);
    if (fired.contains(kStop)) {
      break;
    }
    // Calibrations first: an image that arrives with its calibration is mapped with it.
    take_calibrations();
    take_edge_requests();  // before images: a request waiting for "the next image" gets it
    take_images();
    expire_edges();
    ctx.health().tick();
  }
  // Nobody waits forever: what is still pending is refused at shutdown.
  for (const PendingEdge& p : pending_) {
    const Error e{Errc::kNotReady, "vision is stopping"};
    answer(p, nullptr, &e);
  }
  pending_.clear();
}

}  // namespace cell::vision
