#include "cell/calibration/pose_set.hpp"

#include <cmath>
#include <limits>
#include <random>

#include <fmt/format.h>

#include "cell/render/mount.hpp"

namespace cell::calibration {

Result<std::vector<kinematics::JointVector>> eye_in_hand_pose_set(
    const kinematics::RobotModel& robot, const CameraCalibration& camera, const BoardSpec& board,
    const Eigen::Isometry3d& base_T_board, const PoseSetOptions& o) {
  if (camera.mounting != Mounting::kEyeInHand) {
    return Error{Errc::kInvalidArgument,
                 fmt::format("camera '{}' is fixed: an eye-in-hand pose set needs a camera on the "
                             "robot",
                             camera.camera_id)};
  }
  if (static_cast<int>(o.joint_ranges.size()) != robot.dof() || o.count < 1) {
    return Error{Errc::kInvalidArgument,
                 fmt::format("pose set: {} joint ranges for a robot of {} joints, count {}",
                             o.joint_ranges.size(), robot.dof(), o.count)};
  }
  CELL_TRY(board.validate());
  auto model = camera.camera_model();
  if (!model) {
    return std::move(model).error();
  }
  const double w = (board.columns + 1) * board.square_mm;
  const double h = (board.rows + 1) * board.square_mm;
  const std::vector<Eigen::Vector3d> outline = {{0, 0, 0}, {w, 0, 0}, {w, h, 0}, {0, h, 0}};
  std::mt19937_64 rng(o.seed);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  struct Candidate {
    kinematics::JointVector q;
    Eigen::Vector3d feature;  // heading [rad], board centre in the image [normalised]
  };
  std::vector<Candidate> good;
  for (int n = 0; n < o.candidates; ++n) {
    kinematics::JointVector q(robot.dof());
    for (int j = 0; j < robot.dof(); ++j) {
      const auto& [lo, hi] = o.joint_ranges[static_cast<std::size_t>(j)];
      q[j] = lo + (hi - lo) * unit(rng);
    }
    if (!robot.check_limits(q)) {
      continue;
    }
    auto mount = render::base_T_mount(robot, camera.mount_frame, q);
    if (!mount) {
      return std::move(mount).error();
    }
    const Eigen::Isometry3d camera_T_board = (*mount * camera.extrinsics).inverse() * base_T_board;
    bool inside = true;
    for (const auto& c : outline) {
      auto px = model->project(camera_T_board * c);
      inside = inside && px && px->x() > o.margin_px && px->y() > o.margin_px &&
               px->x() < model->width_px() - 1 - o.margin_px &&
               px->y() < model->height_px() - 1 - o.margin_px;
    }
    if (!inside) {
      continue;
    }
    auto centre = model->project(camera_T_board * Eigen::Vector3d(w / 2, h / 2, 0));
    const Eigen::Matrix3d r = mount->linear();
    good.push_back({q, Eigen::Vector3d(std::atan2(r(1, 0), r(0, 0)),
                                       centre->x() / model->width_px(),
                                       centre->y() / model->height_px())});
  }
  if (static_cast<int>(good.size()) < o.count) {
    return Error{Errc::kOutOfRange,
                 fmt::format("pose set: only {} of {} candidate poses see the whole board at "
                             "{} px from the edges, {} wanted (widen the joint ranges or move the "
                             "board)",
                             good.size(), o.candidates, o.margin_px, o.count)};
  }
  // Farthest-point selection: start with the widest heading, add the candidate farthest from
  // every chosen one (heading in rad weighs like the image position in image widths).
  std::vector<kinematics::JointVector> out;
  std::vector<double> dist(good.size(), std::numeric_limits<double>::infinity());
  std::size_t next = 0;
  for (std::size_t i = 1; i < good.size(); ++i) {
    if (good[i].feature.x() < good[next].feature.x()) {
      next = i;
    }
  }
  for (int k = 0; k < o.count; ++k) {
    out.push_back(good[next].q);
    std::size_t far = next;
    double best = -1.0;
    for (std::size_t i = 0; i < good.size(); ++i) {
      dist[i] = std::min(dist[i], (good[i].feature - good[next].feature).norm());
      if (dist[i] > best) {
        best = dist[i];
        far = i;
      }
    }
    next = far;
  }
  return out;
}

}  // namespace cell::calibration
