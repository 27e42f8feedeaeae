#include "cell_link.hpp"

#include <algorithm>
#include <cstring>
#include <thread>

#include <fmt/format.h>

#include "cell/bus/view.hpp"
#include "cell/common/time.hpp"

namespace cell::calibration_service {
namespace {

using Clock = std::chrono::steady_clock;

std::chrono::milliseconds ms(double seconds) {
  return std::chrono::milliseconds(static_cast<long>(seconds * 1000.0));
}

Error cancelled_error() { return Error{Errc::kNotReady, "cancelled"}; }

}  // namespace

CellLink::CellLink(const bus::Participant& participant, const Timeouts& timeouts,
                   const std::atomic<bool>& cancel)
    : timeouts_(timeouts),
      cancel_(cancel),
      client_id_(bus::make_client_id("calibration")),
      motion_(participant, bus::topics::kMotionRequest, bus::topics::kMotionStatus, client_id_),
      robot_(participant, bus::topics::kRobotCommand, bus::topics::kRobotCommandReply, client_id_),
      world_(participant, bus::topics::kWorldRequest, bus::topics::kWorldReply, client_id_),
      image_request_topic_(participant, bus::topics::kImageRequest),
      image_topic_(participant, bus::topics::kImage),
      truth_topic_(participant, bus::topics::kImageTruth),
      image_requests_(participant, image_request_topic_, bus::topics::kImageRequest),
      images_(participant, image_topic_, bus::topics::kImage),
      truths_(participant, truth_topic_, bus::topics::kImageTruth) {}

Status CellLink::pause(double seconds) {
  const auto end = Clock::now() + ms(seconds);
  while (Clock::now() < end) {
    if (cancelled()) {
      return cancelled_error();
    }
    std::this_thread::sleep_for(std::min<Clock::duration>(std::chrono::milliseconds(50),
                                                          end - Clock::now()));
  }
  return ok_status();
}

Result<kinematics::JointVector> CellLink::move_joints(const std::string& robot_id,
                                                      const kinematics::JointVector& q,
                                                      double speed_scale) {
  if (cancelled()) {
    return cancelled_error();
  }
  const std::string motion_id =
      fmt::format("calibration-{}-{}", wall_time_ns(), ++motion_count_);
  std::vector<double> joints(q.data(), q.data() + q.size());
  cell_motion_MotionRequest request{};
  request.motion_id = bus::borrow(motion_id);
  request.robot_id = bus::borrow(robot_id);
  request.kind = cell_motion_MOTION_MOVE_JOINTS;
  bus::borrow(request.joints_rad_or_mm, joints);
  request.speed_scale = speed_scale;
  const std::string empty;
  request.branch = bus::borrow(empty);
  request.target.orientation.w = 1.0;
  auto seq = motion_.send(request, ms(timeouts_.discovery_s));
  if (!seq) {
    return Error{Errc::kTimeout, fmt::format("moving '{}': {} (is cell-motion running?)", robot_id,
                                             seq.error().message)};
  }
  const auto deadline = Clock::now() + ms(timeouts_.motion_s);
  for (;;) {
    if (cancelled()) {
      cell_motion_MotionRequest stop{};
      const std::string stop_id = motion_id + "-stop";
      stop.motion_id = bus::borrow(stop_id);
      stop.robot_id = bus::borrow(robot_id);
      stop.kind = cell_motion_MOTION_STOP;
      stop.branch = bus::borrow(empty);
      stop.target.orientation.w = 1.0;
      (void)motion_.send(stop, std::chrono::milliseconds(200));
      return cancelled_error();
    }
    auto status = motion_.wait_reply(
        *seq, std::min(deadline, Clock::now() + std::chrono::milliseconds(200)),
        [](const cell_motion_MotionStatus& s) {
          return s.state == cell_motion_MOTION_DONE || s.state == cell_motion_MOTION_REFUSED ||
                 s.state == cell_motion_MOTION_FAILED;
        });
    if (!status) {
      if (Clock::now() >= deadline) {
        return Error{Errc::kTimeout, fmt::format("moving '{}': motion '{}' did not end within {} s",
                                                 robot_id, motion_id, timeouts_.motion_s)};
      }
      continue;
    }
    const cell_motion_MotionStatus& s = status->get();
    if (s.state != cell_motion_MOTION_DONE) {
      return Error{Errc::kProtocol,
                   fmt::format("moving '{}': motion {} ({}): {}", robot_id,
                               s.state == cell_motion_MOTION_REFUSED ? "refused" : "failed",
                               bus::str(s.error_code), bus::str(s.reason))};
    }
    const auto final_q = bus::span(s.final_joints_rad_or_mm);
    kinematics::JointVector out(static_cast<Eigen::Index>(final_q.size()));
    for (std::size_t j = 0; j < final_q.size(); ++j) {
      out[static_cast<Eigen::Index>(j)] = final_q[j];
    }
    return out;
  }
}

Result<Frame> CellLink::grab(const std::string& camera_id) {
  if (cancelled()) {
    return cancelled_error();
  }
  const auto start = Clock::now();
  if (!image_requests_.wait_for_readers(1, ms(timeouts_.discovery_s)) ||
      !images_.wait_for_writers(1, ms(timeouts_.discovery_s))) {
    return Error{Errc::kTimeout, fmt::format("no camera service for '{}' on the bus (is "
                                             "camera.{} running?)",
                                             camera_id, camera_id)};
  }
  const std::uint64_t first = image_seq_ + 1;
  auto send = [&]() {
    cell_vision_ImageRequest r{};
    r.request_id.client_id = bus::borrow(client_id_);
    r.request_id.seq = ++image_seq_;
    r.camera_id = bus::borrow(camera_id);
    r.trigger = cell_vision_TRIGGER_NOW;
    r.with_truth = false;
    return image_requests_.write(r);
  };
  if (auto s = send(); !s) {
    return std::move(s).error();
  }
  auto mine = [&](const cell_common_RequestId& id) {
    return bus::str(id.client_id) == client_id_ && id.seq >= first && id.seq <= image_seq_;
  };
  auto resend_at = Clock::now() + std::chrono::seconds(1);
  const auto deadline = start + ms(timeouts_.image_s);
  while (Clock::now() < deadline) {
    if (cancelled()) {
      return cancelled_error();
    }
    if (auto batch = truths_.take_copies(16); batch) {
      for (auto& t : *batch) {
        if (mine(t->request_id) && !t->status.accepted) {
          return Error{Errc::kProtocol,
                       fmt::format("camera '{}' refused ({}): {}", camera_id,
                                   bus::str(t->status.error_code), bus::str(t->status.reason))};
        }
      }
    }
    if (auto batch = images_.take_copies(4); batch) {
      for (auto& i : *batch) {
        if (!mine(i->request_id)) {
          continue;
        }
        const cell_vision_Image& img = i.get();
        const std::string encoding(bus::str(img.encoding));
        const std::size_t expected = static_cast<std::size_t>(img.step_bytes) * img.height_px;
        if (encoding != "mono8" || img.data._length < expected || img.step_bytes < img.width_px ||
            img.width_px == 0 || img.height_px == 0) {
          return Error{Errc::kInvalidArgument,
                       fmt::format("camera '{}' sent a malformed image: {} x {} {} with {} bytes",
                                   camera_id, img.width_px, img.height_px, encoding,
                                   img.data._length)};
        }
        Frame f;
        f.gray = cv::Mat(static_cast<int>(img.height_px), static_cast<int>(img.width_px), CV_8UC1,
                         img.data._buffer, img.step_bytes)
                     .clone();
        f.camera_id = std::string(bus::str(img.camera_id));
        f.seq = img.header.seq;
        f.stamp_ns = img.header.stamp_ns;
        f.robot_id = std::string(bus::str(img.robot_id));
        const auto q = bus::span(img.robot_joints_rad_or_mm);
        f.joints.resize(static_cast<Eigen::Index>(q.size()));
        for (std::size_t j = 0; j < q.size(); ++j) {
          f.joints[static_cast<Eigen::Index>(j)] = q[j];
        }
        f.belt_id = std::string(bus::str(img.belt_id));
        f.belt_count = img.belt_count;
        f.request_key = fmt::format("{}#{}", client_id_, img.request_id.seq);
        return f;
      }
    }
    if (Clock::now() > resend_at) {
      // A NOW frame that has not come in a second was probably sent before the camera
      // matched this reader (images are best effort): ask again.
      (void)send();
      resend_at = Clock::now() + std::chrono::seconds(1);
    }
    (void)images_.wait_for_data(std::chrono::milliseconds(20));
  }
  return Error{Errc::kTimeout, fmt::format("no frame from camera '{}' within {} s", camera_id,
                                           timeouts_.image_s)};
}

Status CellLink::lights(const std::string& robot_id, bool halogen, bool fluorescent) {
  const std::string operator_id = "calibration";
  cell_robot_RobotCommand c{};
  c.robot_id = bus::borrow(robot_id);
  c.kind = cell_robot_CMD_LIGHTS;
  c.halogen_on = halogen;
  c.fluorescent_on = fluorescent;
  c.operator_id = bus::borrow(operator_id);
  auto reply = robot_.call(c, ms(timeouts_.discovery_s));
  if (!reply) {
    return Error{Errc::kTimeout, fmt::format("lights of '{}': {} (is gateway.{} running?)",
                                             robot_id, reply.error().message, robot_id)};
  }
  if (!(*reply)->status.accepted) {
    return Error{Errc::kProtocol, fmt::format("lights of '{}' refused: {}", robot_id,
                                              bus::str((*reply)->status.reason))};
  }
  return ok_status();
}

Status CellLink::reset_world(const std::string& scene_yaml, const std::string& name) {
  cell_world_WorldRequest r{};
  r.kind = cell_world_WORLD_RESET;
  r.scene_yaml = bus::borrow(scene_yaml);
  r.scene_name = bus::borrow(name);
  const std::string empty;
  r.belt_id = bus::borrow(empty);
  auto reply = world_.call(r, ms(timeouts_.world_s));
  if (!reply) {
    return Error{Errc::kTimeout, fmt::format("world reset: {} (is cell-sim-world running?)",
                                             reply.error().message)};
  }
  if (!(*reply)->status.accepted) {
    return Error{Errc::kProtocol,
                 fmt::format("world reset refused: {}", bus::str((*reply)->status.reason))};
  }
  return ok_status();
}

}  // namespace cell::calibration_service
