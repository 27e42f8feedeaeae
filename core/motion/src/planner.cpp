#include "cell/motion/planner.hpp"

#include <algorithm>
#include <cmath>
#include <optional>

#include <fmt/format.h>

#include "cell/motion/robot_adapters.hpp"
#include "cell/trajectory/alter.hpp"

namespace cell::motion {
namespace {

Status check_scale(double speed_scale) {
  if (!(speed_scale > 0 && speed_scale <= 1)) {
    return Error{Errc::kInvalidArgument,
                 fmt::format("speed_scale must be in (0, 1], got {}", speed_scale)};
  }
  return ok_status();
}

/// A trajectory that holds q for dwell_s (two identical knots).
trajectory::JointTrajectory hold(const trajectory::JointVector& q, double dwell_s) {
  const trajectory::JointVector zero = trajectory::JointVector::Zero(q.size());
  std::vector<trajectory::Knot> knots{{0.0, q, zero}};
  if (dwell_s > 0) {
    knots.push_back({dwell_s, q, zero});
  }
  return *trajectory::JointTrajectory::from_knots(std::move(knots));
}

Result<trajectory::JointTrajectory> join(const trajectory::JointTrajectory& a,
                                         const trajectory::JointTrajectory& b) {
  return a.then(b);
}

}  // namespace

Planner::Planner(kinematics::RobotModel model, PlannerOptions options)
    : model_(std::move(model)), options_(options), limits_(joint_limits(model_)) {}

trajectory::JointVector Planner::start_within_limits(const trajectory::JointVector& q) const {
  trajectory::JointVector out = q;
  for (Eigen::Index j = 0; j < out.size() && j < limits_.lower.size(); ++j) {
    const double tolerance = limits_.prismatic[static_cast<std::size_t>(j)]
                                 ? options_.start_bounds_tolerance_mm
                                 : options_.start_bounds_tolerance_rad;
    if (out[j] < limits_.lower[j] && out[j] >= limits_.lower[j] - tolerance) {
      out[j] = limits_.lower[j];
    } else if (out[j] > limits_.upper[j] && out[j] <= limits_.upper[j] + tolerance) {
      out[j] = limits_.upper[j];
    }
  }
  return out;
}

Status Planner::check_pose(const Eigen::Isometry3d& base_T_tool, const char* what) const {
  if (!base_T_tool.matrix().allFinite()) {
    return Error{Errc::kInvalidArgument, fmt::format("{}: pose is not finite", what)};
  }
  if (auto s = model_.cartesian_limits().check(base_T_tool.translation()); !s) {
    return with_context(s.error(), what);
  }
  return ok_status();
}

Eigen::Isometry3d Planner::above(const Eigen::Isometry3d& base_T_tool, double distance_mm) const {
  if (model_.kind() == kinematics::RobotKind::kScara) {
    Eigen::Isometry3d out = base_T_tool;
    out.translation().z() += distance_mm;
    return out;
  }
  return trajectory::offset_along_tool_z(base_T_tool, -distance_mm);
}

Result<Plan> Planner::move_joints(const trajectory::JointVector& q0,
                                  const trajectory::JointVector& q1, double speed_scale) const {
  CELL_TRY(check_scale(speed_scale));
  CELL_TRY(model_.check_limits(q1));
  auto traj = trajectory::plan_joint_move(q0, q1, limits_, speed_scale);
  if (!traj) {
    return std::move(traj).error();
  }
  // The tool must stay inside the Cartesian limits all along (e.g. above the table).
  for (double t = 0; t <= traj->duration_s() + 1e-9; t += 0.01) {
    const auto q = traj->sample(std::min(t, traj->duration_s())).q;
    auto pose = model_.forward(q);
    if (pose) {
      if (auto s = model_.cartesian_limits().check(pose->translation()); !s) {
        return Error{Errc::kOutOfRange, fmt::format("joint move at t={:.2f} s: {}", t,
                                                    s.error().message)};
      }
    }
  }
  Plan plan;
  plan.trajectory = std::move(*traj);
  return plan;
}

Result<Plan> Planner::move_pose(const trajectory::JointVector& q0,
                                const Eigen::Isometry3d& base_T_tool, const std::string& branch,
                                double speed_scale) const {
  CELL_TRY(check_pose(base_T_tool, "target"));
  auto q1 = branch.empty() ? model_.inverse(base_T_tool, q0)
                           : model_.inverse(base_T_tool, branch, q0);
  if (!q1) {
    return with_context(std::move(q1).error(), "target");
  }
  return move_joints(q0, *q1, speed_scale);
}

Result<trajectory::JointTrajectory> Planner::line(const trajectory::JointVector& q0,
                                                  const Eigen::Isometry3d& goal,
                                                  double speed_scale, const char* step) const {
  if (auto s = check_pose(goal, step); !s) {
    return std::move(s).error();
  }
  trajectory::LinearMoveOptions o = options_.linear;
  o.speed_scale = speed_scale;
  auto traj = trajectory::plan_linear_move(q0, goal, forward_fn(model_), inverse_fn(model_),
                                           limits_, o);
  if (!traj) {
    return with_context(std::move(traj).error(), step);
  }
  return traj;
}

Result<Plan> Planner::move_linear(const trajectory::JointVector& q0,
                                  const Eigen::Isometry3d& base_T_tool, double speed_scale) const {
  CELL_TRY(check_scale(speed_scale));
  auto traj = line(q0, base_T_tool, speed_scale, "straight line");
  if (!traj) {
    return std::move(traj).error();
  }
  Plan plan;
  plan.trajectory = std::move(*traj);
  return plan;
}

Result<Plan> Planner::via_path(const trajectory::JointVector& q0,
                               const std::vector<Eigen::Isometry3d>& via,
                               const Eigen::Isometry3d& target, double speed_scale) const {
  CELL_TRY(check_scale(speed_scale));
  std::vector<trajectory::JointVector> points{q0};
  trajectory::JointVector seed = q0;
  for (std::size_t i = 0; i <= via.size(); ++i) {
    const Eigen::Isometry3d& pose = i < via.size() ? via[i] : target;
    const std::string what = i < via.size() ? fmt::format("via point {}", i) : "target";
    CELL_TRY(check_pose(pose, what.c_str()));
    auto q = model_.inverse(pose, seed);
    if (!q) {
      return with_context(std::move(q).error(), what);
    }
    points.push_back(*q);
    seed = *q;
  }
  // The thesis sizes each segment as max |dq|/v + 0.2 s, but a cubic with zero end velocities
  // peaks at 1.5x its mean speed, so its paths exceed the very speeds they were sized with
  // (home -> image window: J2 peaks at 68.5 deg/s against 50 deg/s). We keep its sizing rule
  // and via velocities and lower the sizing speeds until the peaks respect the limits.
  trajectory::ViaPointOptions o;
  o.speed = limits_.max_velocity * speed_scale;
  o.settle_s = options_.via_settle_s;
  Result<trajectory::JointTrajectory> traj = Error{Errc::kOutOfRange, "no via path planned"};
  for (int attempt = 0; attempt < 8; ++attempt) {
    traj = trajectory::plan_via_points(points, o);
    if (!traj) {
      return std::move(traj).error();
    }
    double worst = 0;
    for (const auto& k : traj->knots()) {
      for (Eigen::Index j = 0; j < k.qd.size(); ++j) {
        worst = std::max(worst, std::abs(k.qd[j]) / (limits_.max_velocity[j] * speed_scale));
      }
    }
    for (double t = 0; t <= traj->duration_s(); t += 0.005) {
      const auto s = traj->sample(t);
      for (Eigen::Index j = 0; j < s.qd.size(); ++j) {
        worst = std::max(worst, std::abs(s.qd[j]) / (limits_.max_velocity[j] * speed_scale));
      }
    }
    if (worst <= 1.0) {
      break;
    }
    o.speed /= worst * 1.01;
  }
  // The thesis sizes its segments for speed only; the robot's accelerations bound it too. Too
  // sharp a path (short segments, a start between via points after a reset) is stretched in
  // time as a whole, which keeps its shape and divides its accelerations by the factor^2.
  const double accel = trajectory::peak_acceleration_ratio(*traj, limits_);
  if (accel > 1.0) {
    traj = traj->time_scaled(std::sqrt(accel * 1.01));
  }
  CELL_TRY(trajectory::check_limits(*traj, limits_, 0.02));
  Plan plan;
  plan.trajectory = std::move(*traj);
  return plan;
}

Result<Plan> Planner::approach(const trajectory::JointVector& q0, const Eigen::Isometry3d& target,
                               double distance_mm, double speed_scale) const {
  const double d = distance_mm > 0 ? distance_mm : options_.default_approach_mm;
  return move_pose(q0, above(target, d), "", speed_scale);
}

Result<Plan> Planner::depart(const trajectory::JointVector& q0, double distance_mm,
                             double speed_scale) const {
  CELL_TRY(check_scale(speed_scale));
  auto here = model_.forward(q0);
  if (!here) {
    return std::move(here).error();
  }
  const double d = distance_mm > 0 ? distance_mm : options_.default_approach_mm;
  auto traj = line(q0, above(*here, d), speed_scale, "depart");
  if (!traj) {
    return std::move(traj).error();
  }
  Plan plan;
  plan.trajectory = std::move(*traj);
  return plan;
}

Result<Plan> Planner::pick_or_place(const trajectory::JointVector& q0,
                                    const Eigen::Isometry3d& target, double distance_mm,
                                    bool close, double speed_scale) const {
  CELL_TRY(check_scale(speed_scale));
  const double d = distance_mm > 0 ? distance_mm : options_.default_approach_mm;
  const char* what = close ? "pick" : "place";
  CELL_TRY(check_pose(target, what));
  auto to_above = approach(q0, target, d, speed_scale);
  if (!to_above) {
    return with_context(std::move(to_above).error(), fmt::format("{}: approach", what));
  }
  auto down = line(to_above->trajectory.end(), target, speed_scale,
                   close ? "pick: descent" : "place: descent");
  if (!down) {
    return std::move(down).error();
  }
  const trajectory::JointTrajectory dwell = hold(down->end(), options_.gripper_dwell_s);
  auto up = line(down->end(), above(target, d), speed_scale, close ? "pick: depart" : "place: depart");
  if (!up) {
    return std::move(up).error();
  }
  auto first = join(to_above->trajectory, *down);
  if (!first) {
    return std::move(first).error();
  }
  const double event_t = first->duration_s();
  auto second = join(*first, dwell);
  if (!second) {
    return std::move(second).error();
  }
  auto all = join(*second, *up);
  if (!all) {
    return std::move(all).error();
  }
  Plan plan;
  plan.trajectory = std::move(*all);
  plan.events.push_back(GripperEvent{event_t, close, options_.gripper_dwell_s});
  return plan;
}

Result<Plan> Planner::track(const trajectory::JointVector& q0, const Eigen::Isometry3d& target,
                            bool cumulative, bool world_frame, double speed_scale,
                            bool joint_interpolated) const {
  auto plan = joint_interpolated ? move_pose(q0, target, "", speed_scale)
                                 : move_linear(q0, target, speed_scale);
  if (!plan) {
    return plan;
  }
  plan->alter_enabled = true;
  plan->alter_cumulative = cumulative;
  plan->alter_world_frame = world_frame;
  return plan;
}

namespace {

/// How far following a moving target from a wait point along a meeting ramp asks the joints:
/// the largest sampled (1 ms) joint speed and acceleration as a fraction of their limits, and
/// which joint and where.
struct FollowDemand {
  double share = 0.0;  ///< the largest ratio / the share of its limit a meeting may use
  double ratio = 0.0;  ///< that joint's speed or acceleration / its limit
  int joint = -1;
  bool acceleration = false;
  double at_mm = 0.0;  ///< the target's travel past the wait point there
};

/// The share of each limit a meeting may use: all of the speed; half of the acceleration, as
/// the ALTER corrections come every few ms, each with a rate, so between them the path's speed
/// steps by the ramp's acceleration times their period, and the gateway's limiter smooths
/// those steps with a lag the other half keeps small (PlannerIntercept tests: under 0.1 mm).
constexpr double kFollowSpeedShare = 1.0;
constexpr double kFollowAccelShare = 0.5;

Result<FollowDemand> follow_demand(const kinematics::RobotModel& model,
                                   const trajectory::JointLimits& limits,
                                   const trajectory::JointVector& q_wait,
                                   const Eigen::Isometry3d& wait,
                                   const Eigen::Vector3d& velocity,
                                   const trajectory::MeetingRamp& ramp,
                                   double follow_s) {
  constexpr double kDt = 0.001;
  const double speed = velocity.norm();
  const Eigen::Vector3d direction = velocity / speed;
  const double d0 = -ramp.length_mm;
  const double d1 = ramp.length_mm + speed * follow_s;
  const int n = static_cast<int>(std::ceil((d1 - d0) / (speed * kDt)));
  FollowDemand worst;
  trajectory::JointVector q_prev2 = q_wait;
  trajectory::JointVector q_prev = q_wait;
  for (int k = 1; k <= n; ++k) {
    const double d = d0 + speed * kDt * k;
    Eigen::Isometry3d pose = wait;
    pose.pretranslate(direction * ramp.displacement(d));
    auto q = model.inverse(pose, q_prev);
    if (!q) {
      return Error{q.error().code,
                   fmt::format("following the target {:.0f} mm past the meeting point: {}", d,
                               q.error().message)};
    }
    for (Eigen::Index j = 0; j < q->size(); ++j) {
      const double v = std::abs((*q)[j] - q_prev[j]) / kDt / limits.max_velocity[j];
      const double a = k >= 2 ? std::abs((*q)[j] - 2 * q_prev[j] + q_prev2[j]) / (kDt * kDt) /
                                    limits.max_acceleration[j]
                              : 0.0;
      const bool by_accel = a / kFollowAccelShare >= v / kFollowSpeedShare;
      const double share = by_accel ? a / kFollowAccelShare : v / kFollowSpeedShare;
      if (share > worst.share) {
        worst = {share, by_accel ? a : v, static_cast<int>(j), by_accel, d};
      }
    }
    q_prev2 = q_prev;
    q_prev = *q;
  }
  return worst;
}

}  // namespace

Result<Intercept> Planner::intercept(const trajectory::JointVector& q0,
                                     const MovingTarget& target, bool cumulative,
                                     bool world_frame, double speed_scale) const {
  CELL_TRY(check_scale(speed_scale));
  const double speed = target.velocity_mm_s.norm();
  if (!std::isfinite(speed) || speed <= 0.0) {
    return Error{Errc::kInvalidArgument,
                 "intercept: the target's velocity must be finite and non-zero"};
  }
  if (!std::isfinite(target.start_s) || target.start_s < 0 || !std::isfinite(target.margin_s) ||
      target.margin_s < 0 || !std::isfinite(target.follow_s) || target.follow_s < 0 ||
      !std::isfinite(target.min_travel_mm) || !std::isfinite(target.max_travel_mm)) {
    return Error{
        Errc::kInvalidArgument,
        "intercept: start, margin, follow time and travels must be finite, start, margin and "
        "follow time >= 0"};
  }
  if (!target.at_stamp.matrix().allFinite()) {
    return Error{Errc::kInvalidArgument, "intercept: the target's pose is not finite"};
  }
  constexpr double kHorizonS = 5.0;  // a meeting further off than this is not worth planning
  // Meeting times [s from the stamp]: never before the robot could be there at all.
  const double t_first = std::max(target.start_s + target.margin_s, target.min_travel_mm / speed);
  const double t_last = target.max_travel_mm > 0.0 ? target.max_travel_mm / speed
                                                   : target.start_s + kHorizonS;
  if (t_last < t_first) {
    return Error{Errc::kOutOfRange,
                 fmt::format("the target leaves the window ({:.0f} mm along its path) before the "
                             "robot can start ({:.0f} mm along it)",
                             target.max_travel_mm, speed * t_first)};
  }
  int candidates = 0;
  std::string last_failure;              // the last meeting point the robot cannot reach
  std::string follow_failure;            // the last one it cannot follow the target from
  double late_s = -1.0;                  // how late at the last one it reaches (-1: none)
  double late_travel_mm = 0.0;
  // The meeting ramp: the shortest of D0, 2 D0, 4 D0, 8 D0 along which the joints can take
  // up the target's pace at the meeting point and follow it within the shares of their limits
  // above. D0: the tool's acceleration along the path that the joints' share allows at the
  // wait point (their rates per mm along it), velocity terms aside: the arm's own limits, not
  // the planner's choice for straight-line moves.
  const trajectory::JointLimits limits = joint_limits(model_);
  const Eigen::Vector3d direction = target.velocity_mm_s / speed;
  struct ShortestRamp {
    double length_mm = 0.0;
    int joint = -1;      ///< the joint whose acceleration limit sets it (-1: the planner's)
    double accel = 0.0;  ///< the tool's acceleration along the path it allows [mm/s^2]
  };
  const auto shortest_ramp = [&](const trajectory::JointVector& q_wait,
                                 const Eigen::Isometry3d& wait) {
    Eigen::Isometry3d ahead = wait;
    ahead.pretranslate(direction);  // 1 mm on
    ShortestRamp out;
    out.accel = 1e300;
    if (auto q = model_.inverse(ahead, q_wait); q) {
      for (Eigen::Index j = 0; j < q->size(); ++j) {
        const double per_mm = std::abs((*q)[j] - q_wait[j]);
        if (per_mm > 1e-12 && kFollowAccelShare * limits.max_acceleration[j] / per_mm < out.accel) {
          out.accel = kFollowAccelShare * limits.max_acceleration[j] / per_mm;
          out.joint = static_cast<int>(j);
        }
      }
    }
    if (out.joint < 0) {  // no joint moves along the path there (or 1 mm on is out of reach)
      out.accel = options_.linear.max_accel_mm_s2;
    }
    out.length_mm = speed * speed / (2.0 * out.accel);
    return out;
  };
  // The ramp from the wait point, or none: follow_failure says what the joints could not do,
  // last_failure where the following left the reach.
  auto ramp_at = [&](const trajectory::JointVector& q_wait,
                     const Eigen::Isometry3d& wait) -> std::optional<trajectory::MeetingRamp> {
    FollowDemand least;
    least.share = 1e300;
    const ShortestRamp shortest = shortest_ramp(q_wait, wait);
    for (int k = 0; k < 4; ++k) {
      const trajectory::MeetingRamp ramp{shortest.length_mm * (1 << k)};
      auto followed =
          follow_demand(model_, limits, q_wait, wait, target.velocity_mm_s, ramp, target.follow_s);
      if (!followed) {
        if (k == 0) {
          follow_failure = fmt::format(
              "taking up the target's pace at {:.0f} mm/s from ({:.0f}, {:.0f}, {:.0f}) mm "
              "needs a ramp of {:.0f} mm at least ({:.0f} mm/s^2 along its path: {}), and {}",
              speed, wait.translation().x(), wait.translation().y(), wait.translation().z(),
              ramp.length_mm, shortest.accel,
              shortest.joint >= 0
                  ? fmt::format("{} at {:.0f} % of its acceleration limit",
                                limits.names[static_cast<std::size_t>(shortest.joint)],
                                100.0 * kFollowAccelShare)
                  : std::string("the planner's linear acceleration"),
              followed.error().message);
        } else {
          last_failure = followed.error().message;
        }
        break;  // a longer ramp runs further
      }
      if (followed->share <= 1.0) {
        return ramp;
      }
      if (followed->share < least.share) {
        least = *followed;
      }
    }
    if (least.joint >= 0) {
      follow_failure = fmt::format(
          "following the target at {:.0f} mm/s from ({:.0f}, {:.0f}, {:.0f}) mm needs {} at "
          "{:.2f} times its {} limit {:.0f} mm past it (a meeting may use {:.0f} % of it)",
          speed, wait.translation().x(), wait.translation().y(), wait.translation().z(),
          limits.names[static_cast<std::size_t>(least.joint)], least.ratio,
          least.acceleration ? "acceleration" : "speed", least.at_mm,
          100.0 * (least.acceleration ? kFollowAccelShare : kFollowSpeedShare));
    }
    return std::nullopt;
  };
  // Plans the meeting at time t (the target at the wait point); true when the robot is there in
  // time (before the target comes within the ramp) and the ramp and the following fit.
  auto meet_at = [&](double t, Intercept& out) {
    ++candidates;
    Eigen::Isometry3d pose = target.at_stamp;
    pose.pretranslate(target.velocity_mm_s * t);
    auto plan = track(q0, pose, cumulative, world_frame, speed_scale, target.joint_interpolated);
    if (!plan) {
      last_failure = plan.error().message;
      return false;
    }
    const double arrive_s = target.start_s + plan->trajectory.duration_s();
    const auto late_by = [&](double ramp_mm) {
      return arrive_s + target.margin_s - (t - ramp_mm / speed);
    };
    if (late_by(0.0) > 0.0) {  // late even without a ramp: no need to try them
      late_s = late_by(0.0);
      late_travel_mm = speed * t;
      return false;
    }
    const auto ramp = ramp_at(plan->trajectory.end(), pose);
    if (!ramp) {
      return false;
    }
    if (target.max_travel_mm > 0.0 && speed * t + ramp->length_mm > target.max_travel_mm) {
      last_failure = fmt::format(
          "the meeting ramp ({:.0f} mm) from {:.0f} mm runs past the "
          "window's end",
          ramp->length_mm, speed * t);
      return false;
    }
    if (late_by(ramp->length_mm) > 0.0) {
      late_s = late_by(ramp->length_mm);
      late_travel_mm = speed * t;
      return false;
    }
    out.plan = std::move(*plan);
    out.meet = pose;
    out.meet_s = t;
    out.travel_mm = speed * t;
    out.ramp_mm = ramp->length_mm;
    return true;
  };
  const double step_s = 10.0 / speed;  // 10 mm of the target's travel
  double before = -1.0;                // the last time that could not be met
  for (double t = t_first;; t += step_s) {
    const bool last = t >= t_last;
    t = std::min(t, t_last);
    Intercept found;
    if (meet_at(t, found)) {
      // The earliest meeting lies in (before, t]: halve it down to 0.2 mm of travel.
      double lo = before;
      double hi = t;
      while (lo >= 0.0 && (hi - lo) * speed > 0.2) {
        const double mid = 0.5 * (lo + hi);
        Intercept earlier;
        if (meet_at(mid, earlier)) {
          hi = mid;
          found = std::move(earlier);
        } else {
          lo = mid;
        }
      }
      found.candidates = candidates;
      return found;
    }
    before = t;
    if (last) {
      break;
    }
  }
  const std::string window = fmt::format(
      "cannot meet the target at {:.0f} mm/s within its window ({:.0f} to {:.0f} mm along its "
      "path)",
      speed, speed * t_first, speed * t_last);
  const std::string follow =
      follow_failure.empty()
          ? ""
          : fmt::format("{}{}", late_s >= 0.0 || !last_failure.empty() ? "; " : "", follow_failure);
  if (late_s >= 0.0) {
    return Error{Errc::kOutOfRange,
                 fmt::format("{}: at {:.0f} mm, the last point the robot reaches, it would be "
                             "{:.0f} ms late{}{}",
                             window, late_travel_mm, late_s * 1e3,
                             last_failure.empty() ? "" : "; beyond: " + last_failure, follow)};
  }
  return Error{Errc::kOutOfRange, fmt::format("{}: {}{}", window, last_failure, follow)};
}

}  // namespace cell::motion
