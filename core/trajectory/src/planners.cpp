#include "cell/trajectory/planners.hpp"

#include <algorithm>
#include <cmath>

#include <fmt/format.h>

namespace cell::trajectory {
namespace {

bool all_finite(const JointVector& v) { return v.allFinite(); }

/// A trapezoidal (or triangular) profile of a path parameter s from 0 to 1.
struct Profile {
  double v = 0;   // cruise speed of s
  double a = 0;   // acceleration of s
  double ta = 0;  // acceleration time
  double tc = 0;  // cruise time
  double duration() const { return 2 * ta + tc; }

  static Profile make(double v_max, double a_max) {
    Profile p;
    p.a = a_max;
    if (v_max * v_max / a_max >= 1.0) {  // cannot reach v_max within s in [0, 1]: triangle
      p.ta = std::sqrt(1.0 / a_max);
      p.v = a_max * p.ta;
      p.tc = 0;
    } else {
      p.v = v_max;
      p.ta = v_max / a_max;
      p.tc = 1.0 / v_max - p.ta;
    }
    return p;
  }

  /// s and ds/dt at time t.
  void at(double t, double& s, double& sd) const {
    const double T = duration();
    if (t <= 0) {
      s = 0;
      sd = 0;
    } else if (t < ta) {
      s = 0.5 * a * t * t;
      sd = a * t;
    } else if (t < ta + tc) {
      s = 0.5 * a * ta * ta + v * (t - ta);
      sd = v;
    } else if (t < T) {
      const double r = T - t;
      s = 1.0 - 0.5 * a * r * r;
      sd = a * r;
    } else {
      s = 1;
      sd = 0;
    }
  }
};

Status check_sizes(const JointVector& a, const JointVector& b, const char* what) {
  if (a.size() != b.size()) {
    return Error{Errc::kInvalidArgument,
                 fmt::format("{}: {} joints against {}", what, a.size(), b.size())};
  }
  if (!all_finite(a) || !all_finite(b)) {
    return Error{Errc::kInvalidArgument, fmt::format("{}: a joint value is not finite", what)};
  }
  return ok_status();
}

Status check_position(const JointVector& q, const JointLimits& limits, const char* which) {
  for (Eigen::Index j = 0; j < q.size(); ++j) {
    const auto js = static_cast<std::size_t>(j);
    if (q[j] < limits.lower[j] - 1e-9 || q[j] > limits.upper[j] + 1e-9) {
      return Error{Errc::kOutOfRange,
                   fmt::format("{}: joint {} at {} is beyond its limit [{}, {}]", which,
                               limits.names[js], format_joint(q[j], limits.prismatic[js]),
                               format_joint(limits.lower[j], limits.prismatic[js]),
                               format_joint(limits.upper[j], limits.prismatic[js]))};
    }
  }
  return ok_status();
}

}  // namespace

Result<JointTrajectory> plan_via_points(const std::vector<JointVector>& points,
                                        const ViaPointOptions& options) {
  if (points.size() < 2) {
    return Error{Errc::kInvalidArgument, "a via-point path needs at least 2 points"};
  }
  const Eigen::Index n = points[0].size();
  if (options.speed.size() != n) {
    return Error{Errc::kInvalidArgument,
                 fmt::format("{} speeds given for {} joints", options.speed.size(), n)};
  }
  for (Eigen::Index j = 0; j < n; ++j) {
    if (!(options.speed[j] > 0) || !std::isfinite(options.speed[j])) {
      return Error{Errc::kInvalidArgument, fmt::format("speed of joint {} must be > 0", j)};
    }
  }
  if (options.settle_s < 0 || options.min_segment_s < 0) {
    return Error{Errc::kInvalidArgument, "settle_s and min_segment_s must be >= 0"};
  }
  for (std::size_t i = 1; i < points.size(); ++i) {
    CELL_TRY(check_sizes(points[0], points[i], "via point"));
  }
  const std::size_t m = points.size() - 1;  // segments
  std::vector<double> duration(m);
  for (std::size_t i = 0; i < m; ++i) {
    double t = 0;
    for (Eigen::Index j = 0; j < n; ++j) {
      t = std::max(t, std::abs(points[i + 1][j] - points[i][j]) / options.speed[j]);
    }
    duration[i] = std::max(t + options.settle_s, options.min_segment_s);
    if (!(duration[i] > 0)) {
      return Error{Errc::kInvalidArgument,
                   fmt::format("segment {} has zero length and zero settle time", i)};
    }
  }
  std::vector<Knot> knots(points.size());
  double t = 0;
  for (std::size_t i = 0; i < points.size(); ++i) {
    knots[i].t_s = t;
    knots[i].q = points[i];
    knots[i].qd = JointVector::Zero(n);
    if (i > 0 && i < m) {
      // Digest 000 §5: mean of adjacent slopes if they have the same sign (cmp_sign returns 1
      // when either is 0), else 0.
      for (Eigen::Index j = 0; j < n; ++j) {
        const double before = (points[i][j] - points[i - 1][j]) / duration[i - 1];
        const double after = (points[i + 1][j] - points[i][j]) / duration[i];
        const bool same = before == 0.0 || after == 0.0 || (before > 0) == (after > 0);
        knots[i].qd[j] = same ? 0.5 * (before + after) : 0.0;
      }
    }
    if (i < m) {
      t += duration[i];
    }
  }
  return JointTrajectory::from_knots(std::move(knots));
}

Result<JointTrajectory> plan_joint_move(const JointVector& q0, const JointVector& q1,
                                        const JointLimits& limits, double speed_scale) {
  CELL_TRY(limits.validate());
  CELL_TRY(check_sizes(q0, q1, "joint move"));
  if (q0.size() != limits.dof()) {
    return Error{Errc::kInvalidArgument,
                 fmt::format("joint move has {} joints, the robot {}", q0.size(), limits.dof())};
  }
  if (!(speed_scale > 0 && speed_scale <= 1)) {
    return Error{Errc::kInvalidArgument,
                 fmt::format("speed_scale must be in (0, 1], got {}", speed_scale)};
  }
  // The start may lie outside a limit (check_limits: the path leads back in); the target not.
  CELL_TRY(check_position(q1, limits, "target"));
  const JointVector delta = q1 - q0;
  double v_s = std::numeric_limits<double>::infinity();
  double a_s = std::numeric_limits<double>::infinity();
  for (Eigen::Index j = 0; j < delta.size(); ++j) {
    const double d = std::abs(delta[j]);
    if (d > 0) {
      v_s = std::min(v_s, speed_scale * limits.max_velocity[j] / d);
      a_s = std::min(a_s, speed_scale * speed_scale * limits.max_acceleration[j] / d);
    }
  }
  std::vector<Knot> knots;
  const Eigen::Index n = q0.size();
  if (!std::isfinite(v_s)) {  // already there
    knots.push_back(Knot{0.0, q0, JointVector::Zero(n)});
    return JointTrajectory::from_knots(std::move(knots));
  }
  const Profile p = Profile::make(v_s, a_s);
  std::vector<double> times = {0.0, p.ta};
  if (p.tc > 1e-12) {
    times.push_back(p.ta + p.tc);
  }
  times.push_back(p.duration());
  for (const double t : times) {
    double s = 0;
    double sd = 0;
    p.at(t, s, sd);
    knots.push_back(Knot{t, q0 + s * delta, sd * delta});
  }
  return JointTrajectory::from_knots(std::move(knots));
}

Eigen::Isometry3d offset_along_tool_z(const Eigen::Isometry3d& base_T_tool, double distance_mm) {
  Eigen::Isometry3d out = base_T_tool;
  out.translation() += base_T_tool.linear().col(2) * distance_mm;
  return out;
}

Result<JointTrajectory> plan_linear_move(const JointVector& q0, const Eigen::Isometry3d& base_T_goal,
                                         const ForwardFn& forward, const InverseFn& inverse,
                                         const JointLimits& limits,
                                         const LinearMoveOptions& options) {
  CELL_TRY(limits.validate());
  if (q0.size() != limits.dof() || !all_finite(q0)) {
    return Error{Errc::kInvalidArgument, "linear move: start joints malformed"};
  }
  if (!(options.max_speed_mm_s > 0 && options.max_accel_mm_s2 > 0 &&
        options.max_angular_speed_rad_s > 0 && options.max_angular_accel_rad_s2 > 0 &&
        options.knot_period_s > 0 && options.speed_scale > 0 && options.speed_scale <= 1)) {
    return Error{Errc::kInvalidArgument,
                 "linear move: speeds, accelerations and knot period must be > 0 and "
                 "speed_scale in (0, 1]"};
  }
  if (!base_T_goal.matrix().allFinite()) {
    return Error{Errc::kInvalidArgument, "linear move: target pose is not finite"};
  }
  CELL_TRY(check_position(q0, limits, "start"));
  const Eigen::Isometry3d start = forward(q0);
  const Eigen::Vector3d p0 = start.translation();
  const Eigen::Vector3d p1 = base_T_goal.translation();
  const Eigen::Quaterniond r0(start.linear());
  Eigen::Quaterniond r1(base_T_goal.linear());
  if (r0.dot(r1) < 0) {
    r1.coeffs() = -r1.coeffs();  // shortest rotation
  }
  const double length = (p1 - p0).norm();
  const double angle = r0.angularDistance(r1);
  const double k = options.speed_scale;
  double v_s = std::numeric_limits<double>::infinity();
  double a_s = std::numeric_limits<double>::infinity();
  if (length > 1e-9) {
    v_s = std::min(v_s, k * options.max_speed_mm_s / length);
    a_s = std::min(a_s, k * k * options.max_accel_mm_s2 / length);
  }
  if (angle > 1e-12) {
    v_s = std::min(v_s, k * options.max_angular_speed_rad_s / angle);
    a_s = std::min(a_s, k * k * options.max_angular_accel_rad_s2 / angle);
  }
  const Eigen::Index n = q0.size();
  if (!std::isfinite(v_s)) {
    std::vector<Knot> single{Knot{0.0, q0, JointVector::Zero(n)}};
    return JointTrajectory::from_knots(std::move(single));
  }
  auto pose_at = [&](double s) {
    Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
    pose.linear() = r0.slerp(s, r1).toRotationMatrix();
    pose.translation() = p0 + s * (p1 - p0);
    return pose;
  };
  auto where = [&](double s) {
    const Eigen::Vector3d p = p0 + s * (p1 - p0);
    return fmt::format("{:.0f}% along the line, at ({:.1f}, {:.1f}, {:.1f}) mm", s * 100, p.x(),
                       p.y(), p.z());
  };
  // Joint positions along the line: IK at evenly spaced s, each seeded with the previous.
  // Spacing: fine enough that the joint path between samples is smooth; refined later by time.
  constexpr double kDs = 1e-4;
  for (int attempt = 0; attempt < 8; ++attempt) {
    const Profile profile = Profile::make(v_s, a_s);
    const double T = profile.duration();
    const int segments = std::max(2, static_cast<int>(std::ceil(T / options.knot_period_s)));
    std::vector<Knot> knots;
    knots.reserve(static_cast<std::size_t>(segments) + 1);
    JointVector seed = q0;
    double worst_ratio = 0;
    for (int i = 0; i <= segments; ++i) {
      const double t = T * i / segments;
      double s = 0;
      double sd = 0;
      profile.at(t, s, sd);
      if (i == segments) {
        s = 1;
        sd = 0;
      }
      Knot knot;
      knot.t_s = t;
      if (i == 0) {
        knot.q = q0;
      } else {
        auto q = inverse(pose_at(s), seed);
        if (!q) {
          return Error{Errc::kOutOfRange, fmt::format("straight line leaves the workspace {}: {}",
                                                      where(s), q.error().message)};
        }
        knot.q = *q;
      }
      // Joint velocity = dq/ds * ds/dt by a central difference of IK along the line.
      knot.qd = JointVector::Zero(n);
      if (sd > 0) {
        const double sa = std::max(0.0, s - kDs);
        const double sb = std::min(1.0, s + kDs);
        auto qa = inverse(pose_at(sa), knot.q);
        auto qb = inverse(pose_at(sb), knot.q);
        if (!qa || !qb) {
          return Error{Errc::kOutOfRange,
                       fmt::format("straight line leaves the workspace {}", where(s))};
        }
        knot.qd = (*qb - *qa) / (sb - sa) * sd;
      }
      // A branch flip shows as a joint jump that the velocities at both ends cannot explain.
      if (i > 0) {
        const double dt = T / segments;
        const Knot& prev = knots.back();
        for (Eigen::Index j = 0; j < n; ++j) {
          const double jump = std::abs(knot.q[j] - prev.q[j]);
          const double explained =
              2.0 * std::max(std::abs(knot.qd[j]), std::abs(prev.qd[j])) * dt + 1e-3;
          if (jump > explained && jump > 1e-2) {
            const auto js = static_cast<std::size_t>(j);
            return Error{Errc::kOutOfRange,
                         fmt::format("straight line passes through a singularity {}: joint {} "
                                     "would jump by {}",
                                     where(s), limits.names[js],
                                     format_joint(jump, limits.prismatic[js]))};
          }
        }
      }
      for (Eigen::Index j = 0; j < n; ++j) {
        worst_ratio = std::max(worst_ratio, std::abs(knot.qd[j]) / limits.max_velocity[j]);
      }
      seed = knot.q;
      knots.push_back(std::move(knot));
    }
    if (worst_ratio > 1.0) {
      // Too fast for a joint somewhere: slow the whole profile and plan again.
      const double f = 1.0 / (worst_ratio * 1.02);
      v_s *= f;
      a_s *= f * f;
      continue;
    }
    auto trajectory = JointTrajectory::from_knots(std::move(knots));
    if (!trajectory) {
      return trajectory;
    }
    // Joint accelerations (at the Hermite segments' ends, where a cubic's are largest): a
    // time scaling by f scales them by f^2.
    double worst_accel = 0;
    const auto& built = trajectory->knots();
    for (std::size_t i = 0; i + 1 < built.size(); ++i) {
      const double h = built[i + 1].t_s - built[i].t_s;
      for (Eigen::Index j = 0; j < n; ++j) {
        const double dq = built[i + 1].q[j] - built[i].q[j];
        const double a0 = (6 * dq / h - 4 * built[i].qd[j] - 2 * built[i + 1].qd[j]) / h;
        const double a1 = (-6 * dq / h + 2 * built[i].qd[j] + 4 * built[i + 1].qd[j]) / h;
        worst_accel = std::max(worst_accel, std::max(std::abs(a0), std::abs(a1)) /
                                                limits.max_acceleration[j]);
      }
    }
    if (worst_accel > 1.0) {
      const double f = 1.0 / std::sqrt(worst_accel * 1.02);
      v_s *= f;
      a_s *= f * f;
      continue;
    }
    CELL_TRY(check_limits(*trajectory, limits, 0.05));
    return trajectory;
  }
  return Error{Errc::kOutOfRange,
               "straight line needs joint speeds or accelerations beyond the limits even when "
               "slowed down 8 times (it passes too close to a singularity)"};
}

}  // namespace cell::trajectory
