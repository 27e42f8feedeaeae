#include "codec.hpp"

#include <cmath>

#include "cell/task/job_state.hpp"
#include "cell/bus/view.hpp"
#include "cell/geometry/idl_pose.hpp"

namespace cell::monitor {
namespace {

std::string s(const char* text) { return std::string(bus::str(text)); }

json numbers(std::span<const double> values) {
  json out = json::array();
  for (const double v : values) {
    out.push_back(number(v));
  }
  return out;
}

json vec3(const cell_common_Vector3& v) { return json::array({number(v.x), number(v.y), number(v.z)}); }

json pose2d(const cell_common_Pose2D& p) {
  return {{"x_mm", number(p.x_mm)}, {"y_mm", number(p.y_mm)}, {"rz_rad", number(p.rz_rad)}};
}

json pixel(const cell_vision_PixelPoint& p) { return json::array({number(p.u_px), number(p.v_px)}); }

}  // namespace

json number(double value) { return std::isfinite(value) ? json(value) : json(nullptr); }

std::string to_text(const json& value) {
  return value.dump(-1, ' ', false, json::error_handler_t::replace);
}

std::string_view shape_name(int shape) noexcept {
  switch (shape) {
    case cell_world_SHAPE_DIP:
      return "dip";
    case cell_world_SHAPE_RECTANGLE:
      return "rectangle";
    case cell_world_SHAPE_SQUARE:
      return "square";
    case cell_world_SHAPE_DISC:
      return "disc";
    case cell_world_SHAPE_TRIANGLE:
      return "triangle";
    case cell_world_SHAPE_BOX:
      return "box";
    case cell_world_SHAPE_POLYHEDRON:
      return "polyhedron";
    default:
      return "unknown";
  }
}

json edge_result_json(const cell_vision_EdgeResult& result) {
  return {{"camera", s(result.camera_id)},
          {"accepted", result.status.accepted},
          {"reason", s(result.status.reason)},
          {"start_px", pixel(result.start_px)},
          {"end_px", pixel(result.end_px)},
          {"residual_px", number(result.residual_px)},
          {"points", result.point_count},
          {"window_px", json::array({pixel(result.window_p1_px), pixel(result.window_p2_px),
                                     pixel(result.window_p3_px)})},
          {"image_sequence", result.image_sequence}};
}

json pose_json(const Eigen::Isometry3d& pose) {
  const Eigen::Quaterniond q(pose.linear());
  const Eigen::Vector3d t = pose.translation();
  return {{"p", {number(t.x()), number(t.y()), number(t.z())}},
          {"q", {number(q.w()), number(q.x()), number(q.y()), number(q.z())}}};
}

json pose_json(const cell_common_Pose& pose) {
  auto p = geometry::pose_from_idl(pose);
  return p ? pose_json(*p) : json(nullptr);
}

json robot_model_json(const kinematics::RobotModel& model, const Eigen::Isometry3d& world_T_base) {
  json joints = json::array();
  for (const auto& j : model.joints()) {
    joints.push_back({{"name", j.name},
                      {"type", std::string(kinematics::to_string(j.type))},
                      {"unit", std::string(j.display_unit())},
                      {"lower", number(j.lower)},
                      {"upper", number(j.upper)},
                      {"max_speed", number(j.max_speed)}});
  }
  json branches = json::array();
  for (const auto b : model.branch_names()) {
    branches.push_back(std::string(b));
  }
  json out{{"id", model.id()},
           {"description", model.description()},
           {"kind", std::string(kinematics::to_string(model.kind()))},
           {"dof", model.dof()},
           {"joints", joints},
           {"branches", branches},
           {"world_T_base", pose_json(world_T_base)}};
  if (const auto* sc = model.scara()) {
    out["scara"] = {{"link1_mm", sc->link1_mm},
                    {"link2_mm", sc->link2_mm},
                    {"z_down", sc->z_direction == kinematics::ZDirection::kDown},
                    {"z_at_zero_mm", sc->z_at_zero_mm},
                    {"roll_world", sc->roll_reference == kinematics::RollReference::kWorld},
                    {"roll_clockwise", sc->roll_sense == kinematics::RotationSense::kClockwise}};
    out["flange_T_tool"] = pose_json(sc->flange_T_tool);
  } else if (const auto* ex = model.excalibur()) {
    out["excalibur"] = {{"d1_mm", ex->d1_mm},
                        {"a2_mm", ex->a2_mm},
                        {"d4_mm", ex->d4_mm},
                        {"d6_mm", ex->d6_mm},
                        {"controller_offset_rad", numbers(ex->controller_offset)}};
    out["flange_T_tool"] = pose_json(ex->flange_T_tool);
  }
  return out;
}

json camera_json(const render::CameraDescription& camera) {
  const auto& m = camera.nominal.model;
  json out{{"id", camera.id},
           {"description", camera.description},
           {"mount", std::string(render::to_string(camera.mount))},
           {"width_px", m.width_px()},
           {"height_px", m.height_px()},
           {"fx_px", m.fx_px()},
           {"fy_px", m.fy_px()},
           {"cx_px", m.cx_px()},
           {"cy_px", m.cy_px()}};
  if (camera.mount == render::MountKind::kFixed) {
    out["world_T_camera"] = pose_json(camera.nominal.pose);
  } else {
    out["robot"] = camera.robot.robot_id;
    out["frame"] = std::string(render::to_string(camera.robot.frame));
    out["mount_T_camera"] = pose_json(camera.nominal.pose);
    out["world_T_base"] = pose_json(camera.robot.world_T_base);
  }
  return out;
}

RobotSample to_sample(const cell_robot_RobotState& state, std::int64_t received_ns) {
  RobotSample out;
  out.robot_id = s(state.robot_id);
  out.stamp_ns = state.header.stamp_ns;
  out.received_ns = received_ns;
  out.seq = state.header.seq;
  out.q = bus::to_vector(state.position_rad_or_mm);
  out.setpoint = bus::to_vector(state.setpoint_rad_or_mm);
  if (auto pose = geometry::pose_from_idl(state.base_T_tool)) {
    out.base_T_tool = *pose;
    out.pose_valid = true;
  }
  out.mode = static_cast<int>(state.mode);
  out.gripper = static_cast<int>(state.gripper);
  out.homed = state.homed;
  out.moving = state.moving;
  out.tracking = state.tracking;
  out.progress = state.trajectory_progress;
  out.trajectory_id = s(state.trajectory_id);
  out.fault_text = s(state.fault_text);
  out.jitter_max_us = state.cycle_jitter_max_us;
  out.overruns = state.cycle_overruns;
  return out;
}

json sample_json(const RobotSample& sample) {
  return {{"id", sample.robot_id},
          {"stamp_ns", sample.stamp_ns},
          {"received_ns", sample.received_ns},
          {"seq", sample.seq},
          {"q", numbers(sample.q)},
          {"setpoint", numbers(sample.setpoint)},
          {"base_T_tool", sample.pose_valid ? pose_json(sample.base_T_tool) : json(nullptr)},
          {"mode", std::string(mode_name(sample.mode))},
          {"gripper", std::string(gripper_name(sample.gripper))},
          {"homed", sample.homed},
          {"moving", sample.moving},
          {"tracking", sample.tracking},
          {"progress", number(sample.progress)},
          {"trajectory_id", sample.trajectory_id},
          {"fault", sample.fault_text},
          {"jitter_max_us", number(sample.jitter_max_us)},
          {"overruns", sample.overruns}};
}

std::string_view mode_name(int mode) noexcept {
  switch (mode) {
    case cell_robot_MODE_UNCONFIGURED:
      return "unconfigured";
    case cell_robot_MODE_IDLE:
      return "idle";
    case cell_robot_MODE_HOMING:
      return "homing";
    case cell_robot_MODE_MOVING:
      return "moving";
    case cell_robot_MODE_MANUAL:
      return "manual";
    case cell_robot_MODE_TEACH:
      return "teach";
    case cell_robot_MODE_PLAYBACK:
      return "playback";
    case cell_robot_MODE_FAULT:
      return "fault";
    case cell_robot_MODE_STOPPED:
      return "stopped";
    default:
      return "unknown";
  }
}

std::string_view gripper_name(int gripper) noexcept {
  switch (gripper) {
    case cell_robot_GRIPPER_OPEN:
      return "open";
    case cell_robot_GRIPPER_CLOSED:
      return "closed";
    case cell_robot_GRIPPER_OPENING:
      return "opening";
    case cell_robot_GRIPPER_CLOSING:
      return "closing";
    default:
      return "unknown";
  }
}

std::string_view health_name(int state) noexcept {
  switch (state) {
    case cell_health_HEALTH_STARTING:
      return "starting";
    case cell_health_HEALTH_SERVING:
      return "serving";
    case cell_health_HEALTH_DEGRADED:
      return "degraded";
    case cell_health_HEALTH_FAULT:
      return "fault";
    case cell_health_HEALTH_STOPPING:
      return "stopping";
    default:
      return "unknown";
  }
}

std::string_view severity_name(int severity) noexcept {
  switch (severity) {
    case cell_health_SEVERITY_INFO:
      return "info";
    case cell_health_SEVERITY_WARNING:
      return "warning";
    case cell_health_SEVERITY_ERROR:
      return "error";
    case cell_health_SEVERITY_FATAL:
      return "fatal";
    default:
      return "unknown";
  }
}

std::string_view motion_state_name(int state) noexcept {
  switch (state) {
    case cell_motion_MOTION_ACCEPTED:
      return "accepted";
    case cell_motion_MOTION_REFUSED:
      return "refused";
    case cell_motion_MOTION_RUNNING:
      return "running";
    case cell_motion_MOTION_DONE:
      return "done";
    case cell_motion_MOTION_FAILED:
      return "failed";
    case cell_motion_MOTION_PREVIEW:
      return "preview";
    default:
      return "unknown";
  }
}

std::string_view job_state_name(int state) noexcept { return task::job_state_name(state); }

std::string_view job_kind_name(int kind) noexcept {
  switch (kind) {
    case cell_task_JOB_TABLE_PICK_PLACE:
      return "table_pick_place";
    case cell_task_JOB_CONVEYOR_PICK:
      return "conveyor_pick";
    case cell_task_JOB_ASSEMBLY:
      return "assembly";
    case cell_task_JOB_TASK_FILE:
      return "task_file";
    default:
      return "unknown";
  }
}

// The names `cellctl job` uses (clients/cellctl/src/job_commands.cpp), so that the page and the
// command line say the same thing of a part.
std::string_view part_outcome_name(int outcome) noexcept {
  switch (outcome) {
    case cell_task_PART_PENDING:
      return "pending";
    case cell_task_PART_PLACED:
      return "placed";
    case cell_task_PART_SKIPPED_UNREACHABLE:
      return "unreachable";
    case cell_task_PART_SKIPPED_GRIP_BLOCKED:
      return "grip_blocked";
    case cell_task_PART_SKIPPED_OUTSIDE_WINDOW:
      return "outside_window";
    case cell_task_PART_LOCATE_FAILED:
      return "locate_failed";
    case cell_task_PART_MISSED:
      return "missed";
    default:
      return "unknown";
  }
}

json heartbeat_json(const cell_health_ServiceHeartbeat& hb) {
  return {{"id", s(hb.service_id)},   {"kind", s(hb.service_kind)},
          {"host", s(hb.host)},       {"pid", hb.pid},
          {"state", std::string(health_name(hb.state))},
          {"detail", s(hb.detail)},   {"uptime_s", number(hb.uptime_s)},
          {"stamp_ns", hb.stamp_ns},  {"version", s(hb.version)}};
}

json event_json(const cell_health_CellEvent& event) {
  return {{"stamp_ns", event.header.stamp_ns},
          {"source", s(event.source)},
          {"severity", std::string(severity_name(event.severity))},
          {"code", s(event.code)},
          {"text", s(event.text)},
          {"robot", s(event.robot_id)},
          {"job", s(event.job_id)}};
}

json motion_status_json(const cell_motion_MotionStatus& status) {
  return {{"motion_id", s(status.motion_id)},
          {"robot", s(status.robot_id)},
          {"state", std::string(motion_state_name(status.state))},
          {"error_code", s(status.error_code)},
          {"reason", s(status.reason)},
          {"progress", number(status.progress)},
          {"duration_s", number(status.duration_s)}};
}

json job_status_json(const cell_task_JobStatus& status) {
  json reasons = json::array();
  for (const char* r : bus::span(status.reasons)) {
    reasons.push_back(s(r));
  }
  json parts = json::array();
  for (const auto& p : bus::span(status.parts)) {
    parts.push_back({{"index", p.index},
                     {"class", s(p.class_name)},
                     {"picked_at", pose2d(p.picked_at)},
                     {"placed_at", pose2d(p.placed_at)},
                     {"outcome", std::string(part_outcome_name(p.outcome))},
                     {"detail", s(p.detail)}});
  }
  json counters = json::object();
  for (const auto& c : bus::span(status.counters)) {
    counters[s(c.name)] = c.value;
  }
  return {{"job_id", s(status.job_id)},
          {"stamp_ns", status.header.stamp_ns},
          {"kind", std::string(job_kind_name(status.kind))},
          {"state", std::string(job_state_name(status.state))},
          {"progress", number(status.progress)},
          {"step", s(status.step)},
          {"reasons", reasons},
          {"parts", parts},
          {"parts_done", status.parts_done},
          {"parts_failed", status.parts_failed},
          {"robot", s(status.robot_id)},
          {"name", s(status.name)},
          {"counters", counters},
          {"elapsed_s", number(status.elapsed_s)},
          {"accepted_stamp_ns", status.accepted_stamp_ns}};
}

json world_json(const cell_world_WorldState& world) {
  json parts = json::array();
  for (const auto& p : bus::span(world.parts)) {
    json part{{"id", s(p.part_id)},
              {"class", s(p.class_name)},
              {"shape", std::string(shape_name(static_cast<int>(p.shape)))},
              {"length_mm", number(p.length_mm)},
              {"width_mm", number(p.width_mm)},
              {"height_mm", number(p.height_mm)},
              {"pins", p.pins},
              {"reflectance", number(p.reflectance)},
              {"pose", pose_json(p.world_T_part)},
              {"support", s(p.support)}};
    auto world_T_part = geometry::pose_from_idl(p.world_T_part);
    auto part_T_grasp = geometry::pose_from_idl(p.part_T_grasp);
    part["grasp"] = world_T_part && part_T_grasp ? pose_json(*world_T_part * *part_T_grasp)
                                                 : json(nullptr);
    if (p.shape == cell_world_SHAPE_POLYHEDRON && p.mesh.vertices_mm._length > 0) {
      json vertices = json::array();
      for (const auto& v : bus::span(p.mesh.vertices_mm)) {
        vertices.push_back(vec3(v));
      }
      json sizes = json::array();
      for (const auto n : bus::span(p.mesh.face_sizes)) {
        sizes.push_back(n);
      }
      json indices = json::array();
      for (const auto i : bus::span(p.mesh.face_indices)) {
        indices.push_back(i);
      }
      part["mesh"] = {{"vertices_mm", vertices}, {"face_sizes", sizes}, {"face_indices", indices}};
    }
    parts.push_back(std::move(part));
  }
  json belts = json::array();
  for (const auto& b : bus::span(world.belts)) {
    belts.push_back({{"id", s(b.belt_id)},
                     {"travel_mm", number(b.travel_mm)},
                     {"speed_mm_per_s", number(b.speed_mm_per_s)},
                     {"encoder_count", b.encoder_count},
                     {"photocell_blocked", b.photocell_blocked},
                     {"origin_mm", vec3(b.origin_mm)},
                     {"direction", vec3(b.direction)},
                     {"length_mm", number(b.length_mm)},
                     {"width_mm", number(b.width_mm)},
                     {"photocell_at_mm", number(b.photocell_at_mm)}});
  }
  return {{"stamp_ns", world.header.stamp_ns},
          {"world_seq", world.world_seq},
          {"table_height_mm", number(world.table_height_mm)},
          {"parts", parts},
          {"belts", belts}};
}

json detections_json(const cell_vision_Detections& detections) {
  json items = json::array();
  for (const auto& d : bus::span(detections.items)) {
    json corners = json::array();
    for (const auto& c : bus::span(d.corners_px)) {
      corners.push_back(pixel(c));
    }
    items.push_back({{"id", d.id},
                     {"class", s(d.class_name)},
                     {"center_px", pixel(d.center_px)},
                     {"angle_rad", number(d.angle_rad)},
                     {"corners_px", corners},
                     {"length_mm", number(d.length_mm)},
                     {"width_mm", number(d.width_mm)},
                     {"base_pose", d.has_base_pose ? pose2d(d.base_pose) : json(nullptr)},
                     {"quality", number(d.quality)},
                     {"grip", d.grip == cell_vision_GRIP_CLEAR     ? "clear"
                              : d.grip == cell_vision_GRIP_BLOCKED ? "blocked"
                                                                   : "not_tested"},
                     {"grip_style", d.grip_style},
                     {"grip_detail", s(d.grip_detail)},
                     {"length_px", number(d.length_px)},
                     {"width_px", number(d.width_px)},
                     {"shape", s(d.shape)},
                     {"touching", d.touching}});
  }
  return {{"camera", s(detections.camera_id)},
          {"stamp_ns", detections.header.stamp_ns},
          {"image_sequence", detections.image_sequence},
          {"items", items},
          {"robot", s(detections.robot_id)},
          {"processing_ms", number(detections.processing_ms)},
          {"error", s(detections.error)},
          {"pipeline", s(detections.pipeline)},
          {"calibration", s(detections.calibration)}};
}

json camera_calibration_json(const cell_calibration_CameraCalibration& c) {
  return {{"camera", s(c.camera_id)},
          {"robot", s(c.robot_id)},
          {"stamp_ns", c.header.stamp_ns},
          {"mounting", c.mounting == cell_calibration_MOUNT_FIXED ? "fixed" : "eye_in_hand"},
          {"width_px", c.width_px},
          {"height_px", c.height_px},
          {"fx_px", number(c.fx_px)},
          {"fy_px", number(c.fy_px)},
          {"cx_px", number(c.cx_px)},
          {"cy_px", number(c.cy_px)},
          {"extrinsics", pose_json(c.extrinsics)},
          {"working_plane_z_mm", number(c.working_plane_z_mm)},
          {"rms_px", number(c.rms_px)},
          {"holdout_rms_mm", number(c.holdout_rms_mm)},
          {"sample_count", c.sample_count},
          {"version", s(c.version)},
          {"mount_frame", s(c.mount_frame)},
          {"holdout_rms_px", number(c.holdout_rms_px)},
          {"source", s(c.source)}};
}

json belt_calibration_json(const cell_calibration_BeltCalibration& c) {
  return {{"belt", s(c.belt_id)},
          {"robot", s(c.robot_id)},
          {"stamp_ns", c.header.stamp_ns},
          {"mm_per_count", number(c.mm_per_count)},
          {"direction", vec3(c.direction)},
          {"origin_mm", vec3(c.origin_mm)},
          {"rms_mm", number(c.rms_mm)},
          {"sample_count", c.sample_count},
          {"version", s(c.version)},
          {"created_utc", s(c.created_utc)},
          {"holdout_mm", number(c.holdout_mm)},
          {"camera", s(c.camera_id)}};
}

}  // namespace cell::monitor
