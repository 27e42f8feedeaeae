#include "camera_service.hpp"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <stdexcept>

#include <fmt/format.h>

#include "cell/bus/view.hpp"
#include "cell/common/log.hpp"
#include "cell/common/time.hpp"
#include "cell/service/paths.hpp"

namespace cell::camera {
namespace {

constexpr dds_attach_t kStop = 1;
constexpr dds_attach_t kInput = 2;
constexpr auto kIdlePeriod = std::chrono::milliseconds(50);
constexpr std::size_t kMaxPending = 64;

using std::chrono::steady_clock;

std::int64_t to_ns(double seconds) { return static_cast<std::int64_t>(std::llround(seconds * 1e9)); }

/// The steady-clock instant of a wall-clock time (for waiting on it).
steady_clock::time_point steady_at(std::int64_t wall_ns) {
  return steady_clock::now() + std::chrono::nanoseconds(wall_ns - wall_time_ns());
}

/// Ids of the cell's cameras: the stems of config/cameras/*.yaml.
std::set<std::string> cell_cameras() {
  namespace fs = std::filesystem;
  std::set<std::string> ids;
  std::error_code ec;
  for (const auto& entry : fs::directory_iterator(service::cell_home() + "/config/cameras", ec)) {
    if (entry.path().extension() == ".yaml") {
      ids.insert(entry.path().stem().string());
    }
  }
  return ids;
}

std::string join(const std::set<std::string>& items) {
  std::string out;
  for (const auto& s : items) {
    out += (out.empty() ? "" : ", ") + s;
  }
  return out.empty() ? "none" : out;
}

}  // namespace

CameraService::CameraService(service::Context& ctx, const CameraConfig& config)
    : config_(config),
      frame_id_(config.camera_id),
      known_cameras_(cell_cameras()),
      next_free_(steady_clock::now()),
      request_topic_(ctx.participant(), bus::topics::kImageRequest),
      image_topic_(ctx.participant(), bus::topics::kImage),
      preview_topic_(ctx.participant(), bus::topics::kImagePreview),
      truth_topic_(ctx.participant(), bus::topics::kImageTruth),
      world_topic_(ctx.participant(), bus::topics::kWorldState),
      robot_topic_(ctx.participant(), bus::topics::kRobotState),
      belt_topic_(ctx.participant(), bus::topics::kBeltState),
      photocell_topic_(ctx.participant(), bus::topics::kPhotocell),
      request_reader_(ctx.participant(), request_topic_, bus::topics::kImageRequest),
      image_writer_(ctx.participant(), image_topic_, bus::topics::kImage),
      preview_writer_(ctx.participant(), preview_topic_, bus::topics::kImagePreview),
      truth_writer_(ctx.participant(), truth_topic_, bus::topics::kImageTruth),
      world_reader_(ctx.participant(), world_topic_, bus::topics::kWorldState),
      robot_reader_(ctx.participant(), robot_topic_, bus::topics::kRobotState),
      belt_reader_(ctx.participant(), belt_topic_, bus::topics::kBeltState),
      photocell_reader_(ctx.participant(), photocell_topic_, bus::topics::kPhotocell) {
  auto source = make_source(config_);
  if (!source) {
    throw std::runtime_error(source.error().message);
  }
  source_ = std::move(*source);
  robot_id_ = config_.robot_id.empty() ? source_->mount_robot_id() : config_.robot_id;
  if (const auto* sim = dynamic_cast<const SimSource*>(source_.get()); sim != nullptr) {
    lights_robot_id_ = sim->camera().lights_robot_id;
    default_lights_ = sim->camera().lights;
  }
  known_cameras_.insert(config_.camera_id);
  for (const std::string& id : {robot_id_, lights_robot_id_}) {
    if (!id.empty()) {
      robots_.try_emplace(id);
    }
  }
  log::info("camera", "camera ready",
            {{"camera", config_.camera_id},
             {"source", to_string(config_.source)},
             {"robot", robot_id_.empty() ? "-" : robot_id_},
             {"belt", config_.belt_id.empty() ? "-" : config_.belt_id}});
}

void CameraService::take_inputs() {
  (void)world_reader_.take_each([&](const cell_world_WorldState& s, const dds_sample_info_t&) {
    if (world_ && s.header.stamp_ns < world_->stamp_ns) {
      return;  // an older state overtaken on the best-effort stream
    }
    world_ = snapshot_from_idl(s);
    if (world_->world_seq != logged_world_seq_) {
      logged_world_seq_ = world_->world_seq;
      for (const std::string& why : world_->skipped) {
        log::warn("world_part_skipped", why, {{"camera", config_.camera_id}});
      }
    }
  });
  (void)robot_reader_.take_each([&](const cell_robot_RobotState& s, const dds_sample_info_t&) {
    auto it = robots_.find(std::string(bus::str(s.robot_id)));
    if (it != robots_.end()) {
      if (auto st = it->second.add(s); !st) {
        log::warn("robot_state", st.error().message);
      }
    }
  });
  (void)belt_reader_.take_each([&](const cell_world_BeltState& s, const dds_sample_info_t&) {
    if (!config_.belt_id.empty() && bus::str(s.belt_id) == config_.belt_id) {
      belt_.add({s.header.stamp_ns, s.travel_mm, s.speed_mm_per_s, s.encoder_count});
    }
  });
  (void)photocell_reader_.take_each(
      [&](const cell_world_PhotocellEvent& e, const dds_sample_info_t&) { handle_photocell(e); });
  (void)request_reader_.take_each(
      [&](const cell_vision_ImageRequest& r, const dds_sample_info_t&) { handle_request(r); });
}

void CameraService::handle_request(const cell_vision_ImageRequest& request) {
  const std::string camera(bus::str(request.camera_id));
  const RequestKey key{std::string(bus::str(request.request_id.client_id)),
                       request.request_id.seq};
  try {
    if (camera != config_.camera_id) {
      if (camera.empty()) {
        refuse(key, Error{Errc::kInvalidArgument, "image request names no camera (camera_id "
                                                  "is empty)"});
      } else if (config_.refuse_unknown_cameras && known_cameras_.count(camera) == 0) {
        refuse(key, Error{Errc::kInvalidArgument,
                          fmt::format("unknown camera '{}' (the cell's cameras: {})", camera,
                                      join(known_cameras_))});
      }
      return;  // another camera's request
    }
    switch (bus::raw(request.trigger)) {  // any value may come off the wire
      case cell_vision_TRIGGER_NOW:
        take(wall_time_ns(), key, request.with_truth);
        return;
      case cell_vision_TRIGGER_PHOTOCELL:
        if (config_.belt_id.empty()) {
          refuse(key, Error{Errc::kInvalidArgument,
                            fmt::format("camera '{}' has no photocell (no belt_id configured)",
                                        config_.camera_id)});
          return;
        }
        if (pending_.size() >= kMaxPending) {
          refuse(key, Error{Errc::kOutOfRange,
                            fmt::format("{} photocell requests already wait", pending_.size())});
          return;
        }
        pending_.push_back(
            {key, static_cast<bool>(request.with_truth), wall_time_ns(),
             steady_clock::now() + std::chrono::nanoseconds(
                                       to_ns(config_.trigger.photocell_timeout_s))});
        return;
    }
    refuse(key, Error{Errc::kInvalidArgument,
                      fmt::format("unknown trigger {}", bus::raw(request.trigger))});
  } catch (const std::exception& e) {  // the boundary: never let a request kill the service
    refuse(key, Error{Errc::kInvalidArgument, fmt::format("internal error: {}", e.what())});
  }
}

void CameraService::handle_photocell(const cell_world_PhotocellEvent& event) {
  if (config_.belt_id.empty() || bus::str(event.belt_id) != config_.belt_id) {
    return;
  }
  if (static_cast<bool>(event.blocked) == config_.trigger.on_leave) {
    return;  // the other edge
  }
  const bool triggered_mode = config_.trigger.mode == TriggerMode::kPhotocell;
  const bool waiting = std::any_of(pending_.begin(), pending_.end(), [&](const auto& p) {
    return p.received_ns <= event.header.stamp_ns;
  });
  if (!triggered_mode && !waiting) {
    return;
  }
  double delay_s = config_.trigger.delay_s;
  if (config_.trigger.delay_mm > 0.0) {
    const auto speed = belt_.speed();
    if (!speed || !(std::abs(*speed) > 1e-6)) {
      log::warn("photocell", "belt speed unknown or zero: the delay_mm cannot be timed",
                {{"camera", config_.camera_id}, {"belt", config_.belt_id}});
      for (auto it = pending_.begin(); it != pending_.end();) {
        if (it->received_ns <= event.header.stamp_ns) {
          refuse(it->key, Error{Errc::kNotReady,
                                fmt::format("belt '{}' speed unknown or zero at the photocell "
                                            "edge: delay_mm {} cannot be timed",
                                            config_.belt_id, config_.trigger.delay_mm)});
          it = pending_.erase(it);
        } else {
          ++it;
        }
      }
      return;
    }
    delay_s = config_.trigger.delay_mm / std::abs(*speed);
  }
  const std::int64_t exposure = event.header.stamp_ns + to_ns(delay_s);
  if (triggered_mode && !waiting) {  // else a requested frame is this edge's frame
    scheduled_.push_back({exposure, std::nullopt, false});
  }
  for (auto it = pending_.begin(); it != pending_.end();) {
    if (it->received_ns <= event.header.stamp_ns) {
      scheduled_.push_back({exposure, it->key, it->with_truth});
      it = pending_.erase(it);
    } else {
      ++it;
    }
  }
}

void CameraService::expire_pending() {
  const auto now = steady_clock::now();
  for (auto it = pending_.begin(); it != pending_.end();) {
    if (now >= it->deadline) {
      refuse(it->key, Error{Errc::kTimeout,
                            fmt::format("no photocell edge on belt '{}' within {} s",
                                        config_.belt_id, config_.trigger.photocell_timeout_s)});
      it = pending_.erase(it);
    } else {
      ++it;
    }
  }
}

void CameraService::take_due_exposures() {
  const std::int64_t now = wall_time_ns();
  std::sort(scheduled_.begin(), scheduled_.end(),
            [](const Scheduled& a, const Scheduled& b) { return a.exposure_ns < b.exposure_ns; });
  while (!scheduled_.empty() && scheduled_.front().exposure_ns <= now) {
    const Scheduled s = scheduled_.front();
    scheduled_.erase(scheduled_.begin());
    take(s.exposure_ns, s.key, s.with_truth);
  }
}

void CameraService::take(std::int64_t exposure_ns, const std::optional<RequestKey>& key,
                         bool with_truth) {
  const std::int64_t robot_age_ns = to_ns(config_.robot_state_timeout_s);
  auto fail = [&](const Error& error) {
    if (key) {
      refuse(*key, error);
      return;
    }
    if (steady_clock::now() - last_failure_log_ > std::chrono::seconds(5)) {
      last_failure_log_ = steady_clock::now();
      log::warn("grab_failed", error.message, {{"camera", config_.camera_id}});
    }
  };
  GrabContext ctx;
  ctx.exposure_ns = exposure_ns;
  ctx.frame_index = image_seq_ + 1;
  ctx.want_truth = with_truth && source_->has_truth();
  std::vector<double> joints;
  if (!robot_id_.empty()) {
    auto sample = robots_.at(robot_id_).at(exposure_ns, robot_age_ns);
    if (sample) {
      ctx.joints = sample->q;
      joints.assign(sample->q.data(), sample->q.data() + sample->q.size());
    } else if (source_->mount_robot_id() == robot_id_) {  // the camera rides it: no pose
      fail(Error{Errc::kNotReady, fmt::format("robot '{}' carries camera '{}': {}", robot_id_,
                                              config_.camera_id, sample.error().message)});
      return;
    }
  }
  render::Scene scene;
  if (source_->kind() == SourceKind::kSim) {
    if (!world_) {
      fail(Error{Errc::kNotReady, "no world state received yet (is sim-world running?)"});
      return;
    }
    const double age_s = static_cast<double>(exposure_ns - world_->stamp_ns) * 1e-9;
    if (std::abs(age_s) > config_.world_state_timeout_s) {
      fail(Error{Errc::kNotReady,
                 fmt::format("the latest world state is {:.3f} s from the exposure (limit "
                             "world_state_timeout_s = {} s): is sim-world running?",
                             age_s, config_.world_state_timeout_s)});
      return;
    }
    scene = scene_at(*world_, exposure_ns);
    scene.lights = default_lights_;
    if (!lights_robot_id_.empty()) {
      if (auto lit = robots_.at(lights_robot_id_).at(exposure_ns, robot_age_ns); lit) {
        scene.lights.lamp_on = lit->halogen_on;
        scene.lights.fluorescent_on = lit->fluorescent_on;
        const bool dark = !lit->halogen_on && !lit->fluorescent_on;
        if (dark && !warned_dark_) {
          log::warn("lights", fmt::format("every light of robot '{}' is off: frames will be dark "
                                          "(cellctl robot lights --robot {} --fluorescent)",
                                          lights_robot_id_, lights_robot_id_),
                    {{"camera", config_.camera_id}});
        }
        warned_dark_ = dark;
      }
    }
    ctx.scene = &scene;
  }
  auto frame = source_->grab(ctx);
  if (!frame) {
    fail(frame.error());
    return;
  }
  std::int64_t belt_count = 0;
  if (!config_.belt_id.empty()) {
    auto count = belt_.count_at(frame->exposure_ns, robot_age_ns);
    if (count) {
      belt_count = *count;
    } else if (steady_clock::now() - last_failure_log_ > std::chrono::seconds(5)) {
      last_failure_log_ = steady_clock::now();
      log::warn("belt_count", fmt::format("belt '{}': {}; belt_count 0", config_.belt_id,
                                          count.error().message));
    }
  }
  ++image_seq_;
  publish_image(*frame, key, joints, belt_count);
  if (key && with_truth) {
    if (frame->truth) {
      publish_truth(*frame, *key);
    } else {
      refuse(*key, Error{Errc::kInvalidArgument,
                         fmt::format("camera '{}' reads {}: its frames have no ground truth "
                                     "(the image was published)",
                                     config_.camera_id, to_string(source_->kind()))});
    }
  }
}

void CameraService::publish_image(const Frame& frame, const std::optional<RequestKey>& key,
                                  const std::vector<double>& joints, std::int64_t belt_count) {
  static const std::string kMono8 = "mono8";
  static const std::string kNone;
  cell_vision_Image img{};
  img.camera_id = bus::borrow(config_.camera_id);
  if (key) {
    img.request_id.client_id = bus::borrow(key->client_id);
    img.request_id.seq = key->seq;
  } else {
    img.request_id.client_id = bus::borrow(kNone);
  }
  img.header.stamp_ns = frame.exposure_ns;
  img.header.frame_id = bus::borrow(frame_id_);
  img.header.seq = image_seq_;
  img.width_px = static_cast<std::uint32_t>(frame.image.cols);
  img.height_px = static_cast<std::uint32_t>(frame.image.rows);
  img.encoding = bus::borrow(kMono8);
  img.step_bytes = static_cast<std::uint32_t>(frame.image.step[0]);
  img.data._buffer = frame.image.data;
  img.data._length = static_cast<std::uint32_t>(frame.image.step[0] * frame.image.rows);
  img.data._maximum = img.data._length;
  img.data._release = false;
  bus::borrow(img.robot_joints_rad_or_mm, joints);
  img.robot_id = bus::borrow(robot_id_);
  img.belt_count = belt_count;
  img.belt_id = bus::borrow(config_.belt_id);
  if (auto s = image_writer_.write(img); !s) {
    log::warn("image", s.error().message, {{"camera", config_.camera_id}});
  }
  const auto now = steady_clock::now();
  if (config_.preview_hz > 0.0 && now >= next_preview_ && preview_writer_.matched_readers() > 0) {
    next_preview_ = now + std::chrono::duration_cast<steady_clock::duration>(
                              std::chrono::duration<double>(1.0 / config_.preview_hz));
    if (auto s = preview_writer_.write(img); !s) {
      log::warn("image_preview", s.error().message, {{"camera", config_.camera_id}});
    }
  }
}

void CameraService::publish_truth(const Frame& frame, const RequestKey& key) {
  const FrameTruth& t = *frame.truth;
  static const std::string kEmpty;
  std::vector<std::vector<cell_vision_PixelPoint>> corners;
  corners.reserve(t.parts.size());
  std::vector<cell_vision_TruthPart> parts;
  parts.reserve(t.parts.size());
  for (const auto& p : t.parts) {
    auto& c = corners.emplace_back();
    for (const auto& px : p.corners_px) {
      c.push_back({px.x(), px.y()});
    }
    cell_vision_TruthPart tp{};
    tp.part_id = bus::borrow(p.part_id);
    tp.class_name = bus::borrow(p.class_name);
    tp.center_px = {p.center_px.x(), p.center_px.y()};
    tp.angle_rad = p.angle_rad;
    bus::borrow(tp.corners_px, c);
    tp.world_T_part = pose_to_idl(p.world_T_part);
    tp.visible_fraction = p.visible_fraction;
    parts.push_back(tp);
  }
  const auto dist = t.model.distortion().as_array();
  const std::vector<double> distortion(dist.begin(), dist.end());
  cell_vision_ImageTruth msg{};
  msg.request_id.client_id = bus::borrow(key.client_id);
  msg.request_id.seq = key.seq;
  msg.status.accepted = true;
  msg.status.error_code = bus::borrow(kEmpty);
  msg.status.reason = bus::borrow(kEmpty);
  msg.camera_id = bus::borrow(config_.camera_id);
  msg.image_seq = image_seq_;
  msg.world_T_camera = pose_to_idl(t.world_T_camera);
  msg.fx_px = t.model.fx_px();
  msg.fy_px = t.model.fy_px();
  msg.cx_px = t.model.cx_px();
  msg.cy_px = t.model.cy_px();
  bus::borrow(msg.distortion, distortion);
  bus::borrow(msg.parts, parts);
  if (auto s = truth_writer_.write(msg); !s) {
    log::warn("image_truth", s.error().message, {{"camera", config_.camera_id}});
  }
}

void CameraService::refuse(const RequestKey& key, const Error& error) {
  const std::string code(to_string(error.code));
  log::info("reject", error.message,
            {{"camera", config_.camera_id}, {"client", key.client_id},
             {"seq", std::to_string(key.seq)}});
  cell_vision_ImageTruth msg{};
  msg.request_id.client_id = bus::borrow(key.client_id);
  msg.request_id.seq = key.seq;
  msg.status.accepted = false;
  msg.status.error_code = bus::borrow(code);
  msg.status.reason = bus::borrow(error.message);
  msg.camera_id = bus::borrow(config_.camera_id);
  msg.world_T_camera.orientation.w = 1.0;
  if (auto s = truth_writer_.write(msg); !s) {
    log::warn("image_truth", s.error().message, {{"camera", config_.camera_id}});
  }
}

steady_clock::time_point CameraService::next_wakeup() const {
  auto next = steady_clock::now() + kIdlePeriod;
  for (const Scheduled& s : scheduled_) {
    next = std::min(next, steady_at(s.exposure_ns));
  }
  for (const PendingPhotocell& p : pending_) {
    next = std::min(next, p.deadline);
  }
  if (config_.trigger.mode == TriggerMode::kFree) {
    next = std::min(next, next_free_);
  }
  return next;
}

void CameraService::run(service::Context& ctx) {
  bus::WaitSet waitset(ctx.participant());
  waitset.attach(ctx.stop_guard().get(), kStop);
  for (const dds_entity_t condition :
       {request_reader_.condition(), world_reader_.condition(), robot_reader_.condition(),
        belt_reader_.condition(), photocell_reader_.condition()}) {
    waitset.attach(condition, kInput);
  }
  const auto period = std::chrono::nanoseconds(to_ns(1.0 / config_.trigger.rate_hz));
  ctx.health().set(cell_health_HEALTH_SERVING);
  for (;;) {
    const bus::Fired fired = waitset.wait_until(next_wakeup());
    if (fired.contains(kStop)) {
      break;
    }
    take_inputs();
    take_due_exposures();
    expire_pending();
    if (config_.trigger.mode == TriggerMode::kFree && steady_clock::now() >= next_free_) {
      take(wall_time_ns(), std::nullopt, false);
      next_free_ += period;
      if (next_free_ < steady_clock::now()) {
        next_free_ = steady_clock::now() + period;
      }
    }
    ctx.health().tick();
  }
  for (const PendingPhotocell& p : pending_) {
    refuse(p.key, Error{Errc::kNotReady, "the camera service stopped before the photocell fired"});
  }
  for (const Scheduled& s : scheduled_) {
    if (s.key) {
      refuse(*s.key, Error{Errc::kNotReady, "the camera service stopped before the exposure"});
    }
  }
}

}  // namespace cell::camera
