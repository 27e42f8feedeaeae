#include "procedures.hpp"

#include <cmath>
#include <cstdio>
#include <exception>
#include <filesystem>
#include <map>
#include <numbers>
#include <optional>

#include <fmt/format.h>
#include <opencv2/imgcodecs.hpp>
#include <yaml-cpp/yaml.h>

#include "cell/calibration/board.hpp"
#include "cell/calibration/hand_eye.hpp"
#include "cell/calibration/intrinsics.hpp"
#include "cell/calibration/marker.hpp"
#include "cell/calibration/pixel_mapping.hpp"
#include "cell/calibration/pose_set.hpp"
#include "cell/common/log.hpp"
#include "cell/config/yaml.hpp"
#include "cell/geometry/angles.hpp"
#include "cell/geometry/pose.hpp"
#include "cell/render/mount.hpp"
#include "cell/service/paths.hpp"

namespace cell::calibration_service {
namespace {

namespace cal = cell::calibration;
using geometry::kDeg;

std::string yaml_quote(const std::string& s) { return YAML::Dump(YAML::Node(s)); }

std::string views_yaml(const std::vector<cal::ViewReport>& views, std::string_view unit) {
  std::string out = "views:\n";
  for (const auto& v : views) {
    out += fmt::format("  - {{id: {}, used: {}, held_out: {}, rms_{}: {:.5f}, reason: {}}}\n",
                       yaml_quote(v.id), v.used, v.held_out, unit, v.rms_px, yaml_quote(v.reason));
  }
  return out;
}

std::string pose_yaml(const Eigen::Isometry3d& p) {
  const Eigen::Vector3d t = p.translation();
  const geometry::Rpy r = geometry::rpy_from_rotation(p.linear());
  return fmt::format("{{xyz_mm: [{:.5f}, {:.5f}, {:.5f}], rpy_deg: [{:.6f}, {:.6f}, {:.6f}]}}",
                     t.x(), t.y(), t.z(), r.roll / kDeg, r.pitch / kDeg, r.yaw / kDeg);
}

std::string describe_source(const cal::CameraCalibration& c) {
  return c.version.empty() ? c.source : c.version;
}

}  // namespace

bool intrinsics_calibrated(const cal::CameraCalibration& c) {
  return c.source.find("intrinsics") != std::string::npos;
}

Procedures::Procedures(const CalibrationConfig& config,
                       std::function<cal::CameraCalibration(const std::string&)> current,
                       CellLink* link, cal::ProgressFn progress, const std::atomic<bool>& cancel)
    : config_(config),
      current_(std::move(current)),
      link_(link),
      progress_(std::move(progress)),
      cancel_(cancel) {}

void Procedures::progress(std::string_view stage, std::size_t step, std::size_t total,
                          std::string_view message) const {
  if (progress_) {
    progress_(stage, step, total, message);
  }
}

Result<Outcome> Procedures::intrinsics(const Request& req) {
  if (!req.board) {
    return Error{Errc::kInvalidArgument,
                 "intrinsics: the board is needed (target: columns x rows of inner corners and "
                 "square_mm; cellctl: --board 9x6 --square 25)"};
  }
  if (req.images_dir.empty()) {
    return Error{Errc::kInvalidArgument, "intrinsics: images_dir is empty (cellctl: --images DIR)"};
  }
  std::optional<cal::CameraCalibration> base;
  if (!req.camera_id.empty()) {
    if (config_.camera(req.camera_id) == nullptr) {
      return Error{Errc::kInvalidArgument,
                   fmt::format("intrinsics: unknown camera '{}'", req.camera_id)};
    }
    base = current_(req.camera_id);
  }
  const std::string dir = service::resolve_path(req.images_dir);
  auto report = cal::calibrate_intrinsics_from_directory(dir, *req.board, config_.intrinsics,
                                                         progress_);
  if (!report) {
    return std::move(report).error();
  }
  if (cancelled()) {
    return Error{Errc::kNotReady, "cancelled"};
  }
  Outcome out;
  out.views = report->views;
  out.rms_px = report->rms_px;
  out.holdout_rms_px = report->holdout_rms_px;
  out.summary = report->brief();
  const render::CameraModel& m = report->camera;
  cal::CameraCalibration c;
  if (base) {
    if (base->width_px != m.width_px() || base->height_px != m.height_px()) {
      return Error{Errc::kInvalidArgument,
                   fmt::format("intrinsics: the images are {} x {} px, camera '{}' is {} x {} px",
                               m.width_px(), m.height_px(), req.camera_id, base->width_px,
                               base->height_px)};
    }
    c = *base;
    out.device_id = req.camera_id;
  } else {
    c.width_px = m.width_px();
    c.height_px = m.height_px();
  }
  c.model = cal::ModelType::kPinhole;
  c.pinhole = {m.fx_px(), m.fy_px(), m.cx_px(), m.cy_px(), m.distortion()};
  c.quality = {report->rms_px, report->holdout_rms_px, 0.0,
               static_cast<std::uint32_t>(report->views_used)};
  c.source = fmt::format("intrinsics: {} views of a {} in {} ({} held out, {} rejected)",
                         report->views_used, req.board->describe(), dir, report->views_held_out,
                         report->views_rejected);
  c.version.clear();
  c.created_utc.clear();
  out.camera = c;
  out.details = fmt::format(
      "procedure: intrinsics\nimages: {}\nboard: {}\nfx_px: {:.6f}\nfy_px: {:.6f}\ncx_px: "
      "{:.6f}\ncy_px: {:.6f}\ndistortion: [{:.8f}, {:.8f}, {:.8f}, {:.8f}, {:.8f}]\n"
      "sigma_px: [{:.4f}, {:.4f}, {:.4f}, {:.4f}]   # 1-sigma fx fy cx cy\nrms_px: {:.5f}\n"
      "holdout_rms_px: {:.5f}\ninitial_rms_px: {:.5f}\niterations: {}\n{}",
      yaml_quote(dir), yaml_quote(req.board->describe()), m.fx_px(), m.fy_px(), m.cx_px(),
      m.cy_px(), m.distortion().k1, m.distortion().k2, m.distortion().p1, m.distortion().p2,
      m.distortion().k3, report->sigma_px[0], report->sigma_px[1], report->sigma_px[2],
      report->sigma_px[3], report->rms_px, report->holdout_rms_px, report->initial_rms_px,
      report->solver.iterations, views_yaml(report->views, "px"));
  return out;
}

Status Procedures::sim_setup(const SimSetup& sim, const cal::BoardSpec* board) {
  if (!sim.enabled || link_ == nullptr) {
    return ok_status();
  }
  progress("setup", 0, 0, fmt::format("simulated world: {} with the calibration target",
                                      sim.scene_file));
  return link_->reset_world(sim_scene_yaml(sim, board), sim.scene_file);
}

void Procedures::sim_restore(const SimSetup& sim) noexcept {
  if (!sim.enabled || !sim.restore || link_ == nullptr) {
    return;
  }
  try {
    if (auto s = link_->reset_world("", ""); !s) {
      log::warn("sim_restore", s.error().message);
    }
  } catch (const std::exception& e) {  // run from a guard's destructor: report, never throw
    try {
      log::warn("sim_restore", e.what());
    } catch (...) {
      (void)std::fputs("calibration: sim_restore failed and could not log why\n", stderr);
    }
  }
}

Result<Procedures::Capture> Procedures::capture_board(const BoardCapture& capture,
                                                      const SimSetup& sim,
                                                      const cal::CameraCalibration& camera,
                                                      const kinematics::RobotModel& robot,
                                                      int pose_count,
                                                      const cal::BoardSpec& board) {
  if (link_ == nullptr) {
    return Error{Errc::kNotReady, "guided procedures need the bus (no link)"};
  }
  std::vector<kinematics::JointVector> poses = capture.poses;
  if (capture.generate) {
    cal::PoseSetOptions o;
    o.count = pose_count > 0 ? pose_count : capture.count;
    o.seed = capture.seed;
    o.joint_ranges = capture.joint_ranges;
    o.margin_px = capture.margin_px;
    auto set = cal::eye_in_hand_pose_set(robot, camera, board, capture.base_T_board_nominal, o);
    if (!set) {
      return std::move(set).error();
    }
    poses = std::move(*set);
  } else if (pose_count > 0 && pose_count < static_cast<int>(poses.size())) {
    poses.resize(static_cast<std::size_t>(pose_count));
  }
  CELL_TRY(sim_setup(sim, &board));
  struct Restore {
    Procedures* self;
    const SimSetup& sim;
    ~Restore() { self->sim_restore(sim); }
  } restore{this, sim};
  if (!capture.lights_robot_id.empty()) {
    CELL_TRY(link_->lights(capture.lights_robot_id, capture.halogen, capture.fluorescent));
    CELL_TRY(link_->pause(0.3));  // the camera learns the switch from the state stream
  }
  Capture out;
  for (std::size_t i = 0; i < poses.size(); ++i) {
    progress("move", i + 1, poses.size(), fmt::format("pose {} of {}", i + 1, poses.size()));
    auto reached = link_->move_joints(robot.id(), poses[i], capture.speed_scale);
    if (!reached) {
      return with_context(std::move(reached).error(), fmt::format("pose {}", i + 1));
    }
    CELL_TRY(link_->pause(capture.settle_s));
    progress("capture", i + 1, poses.size(), fmt::format("pose {}: frame", i + 1));
    auto frame = link_->grab(camera.camera_id);
    if (!frame) {
      return with_context(std::move(frame).error(), fmt::format("pose {}", i + 1));
    }
    cal::HandEyeSample s;
    s.id = fmt::format("pose {} (frame {})", i + 1, frame->seq);
    s.stamp_ns = frame->stamp_ns;
    s.robot_stamp_ns = frame->stamp_ns;  // the joints come with the frame, at its exposure
    kinematics::JointVector q = frame->joints;
    if (q.size() != robot.dof() || frame->robot_id != robot.id()) {
      // A fixed camera's frames carry no joints: the robot stands where the move ended.
      q = *reached;
    }
    auto mount = render::base_T_mount(robot, camera.mount_frame, q);
    if (!mount) {
      return with_context(std::move(mount).error(), fmt::format("pose {}", i + 1));
    }
    s.base_T_mount = *mount;
    auto obs = cal::detect_board(frame->gray, board);
    if (obs) {
      s.observation = std::move(*obs);
    } else {
      s.detection_error = obs.error().message;
    }
    progress("detect", i + 1, poses.size(),
             obs ? fmt::format("pose {}: {} corners", i + 1, s.observation.size())
                 : fmt::format("pose {}: {}", i + 1, s.detection_error));
    out.samples.push_back(std::move(s));
    out.joints.push_back(q);
  }
  return out;
}

Result<Procedures::Capture> Procedures::load_data_set(const std::string& dir,
                                                      const cal::CameraCalibration& camera,
                                                      const kinematics::RobotModel* robot,
                                                      const cal::BoardSpec& board) {
  const std::string path = dir + "/poses.yaml";
  auto doc = config::load_file(path);
  if (!doc) {
    return std::move(doc).error();
  }
  config::MapReader r(*doc, doc->root, "");
  std::string robot_id;
  Capture out;
  r.optional("robot_id", robot_id);
  if (r.has("target_z_mm")) {
    double z = 0.0;
    r.required("target_z_mm", z);
    out.target_z_mm = z;
  }
  if (r.has("target_level")) {
    bool level = true;
    r.required("target_level", level);
    out.target_level = level;
  }
  std::size_t k = 0;
  for (const YAML::Node& node : r.sequence("samples", true)) {
    config::MapReader s = r.element(node, "samples[]");
    std::string image;
    std::vector<double> joints;
    std::int64_t stamp = 0;
    std::int64_t robot_stamp = 0;
    s.required("image", image);
    s.optional("stamp_ns", stamp);
    s.optional("robot_stamp_ns", robot_stamp);
    s.optional("joints", joints);
    cal::HandEyeSample sample;
    sample.id = image;
    sample.stamp_ns = stamp;
    sample.robot_stamp_ns = robot_stamp;
    kinematics::JointVector q;
    if (s.has("base_T_mount")) {
      config::MapReader p = s.child("base_T_mount", true);
      std::array<double, 3> xyz{};
      std::array<double, 3> rpy{};
      p.required("xyz_mm", xyz);
      p.required("rpy_deg", rpy);
      s.absorb(p);
      sample.base_T_mount = geometry::make_pose(
          Eigen::Vector3d(xyz[0], xyz[1], xyz[2]),
          geometry::Rpy{rpy[0] * kDeg, rpy[1] * kDeg, rpy[2] * kDeg});
    } else if (robot == nullptr) {
      s.fail("joints", "no robot model to turn joints into a pose: give base_T_mount");
    } else if (static_cast<int>(joints.size()) != robot->dof()) {
      s.fail("joints", fmt::format("robot '{}' has {} joints, got {}", robot->id(), robot->dof(),
                                   joints.size()));
    } else {
      q.resize(robot->dof());
      for (int j = 0; j < robot->dof(); ++j) {
        q[j] = robot->joints()[static_cast<std::size_t>(j)].from_display(
            joints[static_cast<std::size_t>(j)]);
      }
      auto mount = render::base_T_mount(*robot, camera.mounting == cal::Mounting::kEyeInHand
                                                    ? camera.mount_frame
                                                    : render::MountFrame::kTool,
                                        q);
      if (!mount) {
        s.fail("joints", mount.error().message);
      } else {
        sample.base_T_mount = *mount;
      }
    }
    r.absorb(s);
    progress("detect", ++k, 0, image);
    cv::Mat gray;
    try {
      gray = cv::imread(fmt::format("{}/{}", dir, image), cv::IMREAD_GRAYSCALE);
    } catch (const cv::Exception&) {
      gray.release();
    }
    if (gray.empty()) {
      sample.detection_error = "cannot read " + image;
    } else if (gray.cols != camera.width_px || gray.rows != camera.height_px) {
      sample.detection_error = fmt::format("{} is {} x {} px, the camera {} x {} px", image,
                                           gray.cols, gray.rows, camera.width_px,
                                           camera.height_px);
    } else if (auto obs = cal::detect_board(gray, board); obs) {
      sample.observation = std::move(*obs);
    } else {
      sample.detection_error = obs.error().message;
    }
    out.samples.push_back(std::move(sample));
    out.joints.push_back(q);
  }
  CELL_TRY(r.finish());
  return out;
}

Result<Outcome> Procedures::hand_eye(const Request& req) {
  const CameraEntry* entry = config_.camera(req.camera_id);
  if (entry == nullptr) {
    return Error{Errc::kInvalidArgument, fmt::format("hand-eye: unknown camera '{}'", req.camera_id)};
  }
  const HandEyeProcedure* proc = config_.hand_eye_for(req.camera_id);
  const cal::CameraCalibration current = current_(req.camera_id);
  if (!intrinsics_calibrated(current)) {
    return Error{Errc::kNotReady,
                 fmt::format("camera '{}' has only its nominal intrinsics: calibrate them first "
                             "(cellctl calibrate intrinsics --camera {} --images DIR --board ...)",
                             req.camera_id, req.camera_id)};
  }
  std::string robot_id = req.robot_id;
  if (robot_id.empty()) {
    robot_id = proc != nullptr ? proc->robot_id : entry->robot_id;
  }
  if (robot_id != current.robot_id) {
    return Error{Errc::kInvalidArgument,
                 fmt::format("hand-eye: camera '{}' is calibrated against robot '{}', not '{}'",
                             req.camera_id, current.robot_id, robot_id)};
  }
  const kinematics::RobotModel* robot = config_.robot(robot_id);
  auto model = current.camera_model();
  if (!model) {
    return std::move(model).error();
  }
  std::optional<cal::BoardSpec> board = req.board;
  if (!board && proc != nullptr) {
    board = proc->capture.board;
  }
  if (!board) {
    return Error{Errc::kInvalidArgument, "hand-eye: no board given and no procedure for this camera"};
  }
  cal::HandEyeOptions options;
  if (proc != nullptr) {
    options = proc->options;
  } else {
    options.setup = current.mounting == cal::Mounting::kEyeInHand ? cal::HandEyeSetup::kEyeInHand
                                                                  : cal::HandEyeSetup::kEyeToHand;
    options.planar = robot != nullptr && robot->scara() != nullptr;
    options.planar_target_z_mm = current.working_plane_z_mm;
  }
  Result<Capture> capture = Error{Errc::kInvalidArgument, ""};
  std::string data;
  if (!req.images_dir.empty()) {
    const std::string dir = service::resolve_path(req.images_dir);
    capture = load_data_set(dir, current, robot, *board);
    data = "the data set " + dir;
  } else {
    if (proc == nullptr) {
      return Error{Errc::kInvalidArgument,
                   fmt::format("hand-eye: no guided procedure for camera '{}' in the config; give "
                               "a recorded data set (images_dir with poses.yaml)",
                               req.camera_id)};
    }
    if (robot == nullptr) {
      return Error{Errc::kInvalidArgument, fmt::format("hand-eye: no model of robot '{}'", robot_id)};
    }
    capture = capture_board(proc->capture, proc->sim, current, *robot, req.pose_count, *board);
    data = fmt::format("a guided capture of {} poses", capture ? capture->samples.size() : 0);
  }
  if (!capture) {
    return std::move(capture).error();
  }
  if (capture->target_z_mm) {
    options.planar_target_z_mm = *capture->target_z_mm;
  }
  if (capture->target_level) {
    // A board skewed on its holder, taken for level, biases the camera by millimetres.
    options.planar_target_level = *capture->target_level;
  }
  progress("solve", 0, 0, fmt::format("{} samples", capture->samples.size()));
  auto report = cal::calibrate_hand_eye(capture->samples, *model, options, progress_);
  if (!report) {
    return std::move(report).error();
  }
  if (cancelled()) {
    return Error{Errc::kNotReady, "cancelled"};
  }
  cal::CameraCalibration c = current;
  c.extrinsics = report->camera_extrinsics;
  c.quality = {report->rms_px, report->holdout_rms_px, report->holdout_mm,
               static_cast<std::uint32_t>(report->samples_used)};
  c.source = fmt::format("hand_eye: {} samples of a {} from {} ({} held out, {} rejected; {}{}); "
                         "intrinsics: {}",
                         report->samples_used, board->describe(), data, report->samples_held_out,
                         report->samples_rejected, report->planar ? "planar, " : "",
                         "init " + report->init, describe_source(current));
  c.version.clear();
  c.created_utc.clear();
  Outcome out;
  out.device_id = req.camera_id;
  out.camera = c;
  out.views = report->samples;
  out.rms_px = report->rms_px;
  out.holdout_rms_px = report->holdout_rms_px;
  out.holdout_mm = report->holdout_mm;
  out.summary = report->brief();
  std::string closed;
  for (const auto& m : report->closed_forms) {
    closed += m.ok ? fmt::format("  {}: {}\n", cal::to_string(m.method), pose_yaml(m.camera_extrinsics))
                   : fmt::format("  {}: {}\n", cal::to_string(m.method), yaml_quote(m.error));
  }
  out.details = fmt::format(
      "procedure: hand_eye\nsetup: {}\nplanar: {}\ndata: {}\n{}: {}\ntarget: {}\nrms_px: {:.5f}\n"
      "holdout_rms_px: {:.5f}\nholdout_mm: {:.5f}\nrobot_correction_rms: {{deg: {:.5f}, mm: "
      "{:.5f}}}\nmotion: {{max_rotation_deg: {:.3f}, axis_spread_deg: {:.3f}, max_translation_mm: "
      "{:.2f}, distinct_poses: {}}}\ninit: {}\nclosed_forms:   # OpenCV on the same samples\n{}{}",
      cal::to_string(report->setup), report->planar, yaml_quote(data),
      report->setup == cal::HandEyeSetup::kEyeInHand ? "mount_T_camera" : "base_T_camera",
      pose_yaml(report->camera_extrinsics), pose_yaml(report->target_pose), report->rms_px,
      report->holdout_rms_px, report->holdout_mm, report->robot_rotation_rms_deg,
      report->robot_translation_rms_mm, report->motion.max_rotation_deg,
      report->motion.axis_spread_deg, report->motion.max_translation_mm,
      report->motion.distinct_poses, report->init, closed, views_yaml(report->samples, "px"));
  return out;
}

Result<Outcome> Procedures::planar(const Request& req) {
  const PlanarProcedure* proc = config_.planar_for(req.camera_id);
  if (proc == nullptr) {
    return Error{Errc::kInvalidArgument,
                 fmt::format("planar: no planar procedure for camera '{}' in the config",
                             req.camera_id)};
  }
  const cal::CameraCalibration current = current_(req.camera_id);
  const kinematics::RobotModel* robot = config_.robot(proc->robot_id);
  if (robot == nullptr || robot->scara() == nullptr) {
    return Error{Errc::kInvalidArgument,
                 fmt::format("planar: robot '{}' is not a SCARA of the config", proc->robot_id)};
  }
  auto start = cal::planar_from_pinhole(current, proc->ref_px, robot->scara()->link1_mm,
                                        robot->scara()->link2_mm);
  if (!start) {
    return std::move(start).error();
  }
  std::string init = fmt::format("the pinhole calibration {}", describe_source(current));
  if (!req.readings.empty()) {
    auto two = cal::two_stage_calibration(*start, req.readings);
    if (!two) {
      return std::move(two).error();
    }
    start->d_t_c_mm = two->d_t_c_mm;
    start->b_angl_rad = two->b_angl_rad;
    init = fmt::format("{} two-stage readings (d_t_c {:.3f} mm, b_angl {:.3f} deg, spread {:.3f} "
                       "mm {:.3f} deg)",
                       two->readings, two->d_t_c_mm, two->b_angl_rad / kDeg, two->d_t_c_spread_mm,
                       two->b_angl_spread_rad / kDeg);
  }
  const cal::BoardSpec board = req.board.value_or(proc->capture.board);
  Result<Capture> capture =
      !req.images_dir.empty()
          ? load_data_set(service::resolve_path(req.images_dir), current, robot, board)
          : capture_board(proc->capture, proc->sim, current, *robot, req.pose_count, board);
  if (!capture) {
    return std::move(capture).error();
  }
  std::vector<cal::PlanarView> views;
  for (std::size_t i = 0; i < capture->samples.size(); ++i) {
    const auto& s = capture->samples[i];
    if (!s.detection_error.empty() || capture->joints[i].size() < 2) {
      continue;
    }
    cal::PlanarView v;
    v.id = s.id;
    v.j1_rad = capture->joints[i][0];
    v.j2_rad = capture->joints[i][1];
    for (std::size_t k = 0; k < s.observation.size(); ++k) {
      v.pixels.push_back(s.observation.image_points[k]);
      v.target_points_mm.push_back(s.observation.object_points[k].head<2>());
    }
    views.push_back(v);
  }
  cal::PlanarOptions options;
  options.refine_links = proc->refine_links;
  progress("solve", 0, 0, fmt::format("planar model over {} views", views.size()));
  auto report = cal::refine_planar(*start, views, options, progress_);
  if (!report) {
    return std::move(report).error();
  }
  cal::CameraCalibration c;
  c.camera_id = req.camera_id + ".planar";
  c.model = cal::ModelType::kPlanar7545;
  c.mounting = cal::Mounting::kEyeInHand;
  c.mount_frame = render::MountFrame::kLink2;
  c.robot_id = proc->robot_id;
  c.width_px = current.width_px;
  c.height_px = current.height_px;
  c.working_plane_z_mm = current.working_plane_z_mm;
  c.planar = report->parameters;
  c.quality = {report->rms_px, report->holdout_rms_px, report->holdout_mm,
               static_cast<std::uint32_t>(report->views_used)};
  c.source = fmt::format("planar: {} views of a {}, started from {}", report->views_used,
                         board.describe(), init);
  Outcome out;
  out.device_id = c.camera_id;
  out.camera = c;
  out.views = report->views;
  out.rms_px = report->rms_px;
  out.holdout_rms_px = report->holdout_rms_px;
  out.holdout_mm = report->holdout_mm;
  out.summary = report->brief();
  out.details = fmt::format("procedure: planar\nstart: {}\nresult: {}\n{}", yaml_quote(init),
                            yaml_quote(report->brief()), views_yaml(report->views, "px"));
  return out;
}

Result<Outcome> Procedures::belt(const Request& req) {
  const BeltEntry* entry = config_.belt_entry(req.belt_id);
  const BeltProcedure* proc = config_.belt_for(req.belt_id);
  if (entry == nullptr || proc == nullptr) {
    return Error{Errc::kInvalidArgument,
                 fmt::format("belt: no belt '{}' with a procedure in the config", req.belt_id)};
  }
  if (link_ == nullptr) {
    return Error{Errc::kNotReady, "guided procedures need the bus (no link)"};
  }
  const cal::CameraCalibration camera = current_(entry->camera_id);
  if (camera.source.find("hand_eye") == std::string::npos) {
    return Error{Errc::kNotReady,
                 fmt::format("camera '{}' has only its nominal pose in '{}''s base: calibrate it "
                             "first (cellctl calibrate hand-eye --camera {})",
                             entry->camera_id, entry->robot_id, entry->camera_id)};
  }
  if (camera.robot_id != entry->robot_id || camera.mounting != cal::Mounting::kFixed) {
    return Error{Errc::kInvalidArgument,
                 fmt::format("belt '{}': camera '{}' must be fixed in '{}''s base", req.belt_id,
                             entry->camera_id, entry->robot_id)};
  }
  auto model = camera.camera_model();
  if (!model) {
    return std::move(model).error();
  }
  CELL_TRY(sim_setup(proc->sim, nullptr));
  struct Restore {
    Procedures* self;
    const SimSetup& sim;
    ~Restore() { self->sim_restore(sim); }
  } restore{this, proc->sim};
  const double plane = entry->surface_z_mm + proc->marker_height_mm / 2.0;
  // Tracks: one a marker. Every marker rides the same belt, so once any track has moved, its
  // travel per count predicts where every other track is at a later count; until then a
  // detection joins the nearest track within the gate.
  struct Track {
    Eigen::Vector3d last;
    std::int64_t count = 0;
    int samples = 0;
  };
  std::vector<Track> tracks;
  std::optional<Eigen::Vector3d> mm_per_count_vector;  // the belt's travel per count, once seen
  const auto predicted = [&](const Track& t, std::int64_t count) -> Eigen::Vector3d {
    return mm_per_count_vector ? Eigen::Vector3d(t.last + *mm_per_count_vector *
                                                              static_cast<double>(count - t.count))
                               : t.last;
  };
  std::vector<cal::BeltObservation> samples;
  const auto t0 = std::chrono::steady_clock::now();
  int frames = 0;
  while (static_cast<int>(samples.size()) < proc->samples &&
         std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count() <
             proc->max_duration_s) {
    auto frame = link_->grab(entry->camera_id);
    if (!frame) {
      return with_context(std::move(frame).error(), "belt capture");
    }
    ++frames;
    if (frame->belt_id != req.belt_id) {
      return Error{Errc::kInvalidArgument,
                   fmt::format("camera '{}' latches belt '{}', not '{}'", entry->camera_id,
                               frame->belt_id, req.belt_id)};
    }
    auto markers = cal::locate_markers(frame->gray, proc->marker);
    if (!markers) {
      return std::move(markers).error();
    }
    for (const cal::Marker& m : *markers) {
      if (m.touches_border) {
        continue;
      }
      auto p = cal::pixel_to_plane(*model, camera.extrinsics, m.centroid_px, plane);
      if (!p) {
        continue;
      }
      // The nearest track to the detection, at its predicted place, within the gate.
      int best = -1;
      double best_d = proc->track_gate_mm;
      for (std::size_t t = 0; t < tracks.size(); ++t) {
        if (tracks[t].count == frame->belt_count) {
          continue;  // already has its detection in this frame
        }
        const double d = (predicted(tracks[t], frame->belt_count) - *p).norm();
        if (d < best_d) {
          best_d = d;
          best = static_cast<int>(t);
        }
      }
      if (best < 0) {
        tracks.push_back({*p, frame->belt_count, 0});
        best = static_cast<int>(tracks.size()) - 1;
      }
      Track& t = tracks[static_cast<std::size_t>(best)];
      if (t.samples > 0 && frame->belt_count != t.count) {
        mm_per_count_vector = (*p - t.last) / static_cast<double>(frame->belt_count - t.count);
      }
      t.last = *p;
      t.count = frame->belt_count;
      ++t.samples;
      cal::BeltObservation o;
      o.part = fmt::format("marker {}", best + 1);
      o.id = fmt::format("{} @ count {} (frame {})", o.part, frame->belt_count, frame->seq);
      o.encoder_count = frame->belt_count;
      o.stamp_ns = frame->stamp_ns;
      o.position_mm = *p;
      samples.push_back(o);
    }
    progress("capture", samples.size(), static_cast<std::size_t>(proc->samples),
             fmt::format("frame {}: {} markers, {} samples, count {}", frames, markers->size(),
                         samples.size(), frame->belt_count));
    CELL_TRY(link_->pause(proc->period_s));
  }
  progress("solve", 0, 0, fmt::format("{} samples of {} markers", samples.size(), tracks.size()));
  auto report = cal::calibrate_belt(samples, req.belt_id, entry->robot_id);
  if (!report) {
    return with_context(std::move(report).error(),
                        fmt::format("{} frames in {:.1f} s", frames,
                                    std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count()));
  }
  cal::BeltCalibration b = report->calibration;
  b.camera_id = entry->camera_id;
  b.source = fmt::format("belt: {} samples of {} markers over {:.1f} mm seen by {} ({})",
                         b.sample_count, report->parts, report->travel_mm, entry->camera_id,
                         describe_source(camera));
  Outcome out;
  out.device_id = req.belt_id;
  out.belt = b;
  out.views = report->samples;
  out.rms_px = b.rms_mm;
  out.holdout_mm = b.holdout_mm;
  out.summary = report->brief();
  out.details = fmt::format(
      "procedure: belt\nmm_per_count: {:.10f}\ndirection: [{:.8f}, {:.8f}, {:.8f}]\n"
      "elevation_deg: {:.4f}\nrms_mm: {:.5f}\nholdout_mm: {:.5f}\nframes: {}\n{}",
      b.mm_per_count, b.direction.x(), b.direction.y(), b.direction.z(), report->elevation_deg,
      b.rms_mm, b.holdout_mm, frames, views_yaml(report->samples, "mm"));
  return out;
}

}  // namespace cell::calibration_service
