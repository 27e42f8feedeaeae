#include "cell/trajectory/joint_trajectory.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>

#include <fmt/format.h>

namespace cell::trajectory {
namespace {

/// Cubic Hermite basis on s in [0, 1] with segment length h.
struct Hermite {
  double p0, v0, p1, v1, h;

  double pos(double s) const {
    const double s2 = s * s;
    const double s3 = s2 * s;
    return (2 * s3 - 3 * s2 + 1) * p0 + (s3 - 2 * s2 + s) * h * v0 + (-2 * s3 + 3 * s2) * p1 +
           (s3 - s2) * h * v1;
  }
  double vel(double s) const {
    const double s2 = s * s;
    return ((6 * s2 - 6 * s) * p0 + (3 * s2 - 4 * s + 1) * h * v0 + (-6 * s2 + 6 * s) * p1 +
            (3 * s2 - 2 * s) * h * v1) /
           h;
  }
  double acc(double s) const {
    return ((12 * s - 6) * p0 + (6 * s - 4) * h * v0 + (-12 * s + 6) * p1 + (6 * s - 2) * h * v1) /
           (h * h);
  }
  /// Polynomial p(s) = c0 + c1 s + c2 s^2 + c3 s^3.
  void coefficients(double& c1, double& c2, double& c3) const {
    c1 = h * v0;
    c2 = -3 * p0 - 2 * h * v0 + 3 * p1 - h * v1;
    c3 = 2 * p0 + h * v0 - 2 * p1 + h * v1;
  }
};

}  // namespace

std::string format_joint(double value, bool prismatic) {
  return prismatic ? fmt::format("{:.2f} mm", value)
                   : fmt::format("{:.2f} deg", value * 180.0 / std::numbers::pi);
}

Result<JointTrajectory> JointTrajectory::from_knots(std::vector<Knot> knots) {
  if (knots.empty()) {
    return Error{Errc::kInvalidArgument, "a trajectory needs at least one knot"};
  }
  const auto n = knots[0].q.size();
  if (n == 0) {
    return Error{Errc::kInvalidArgument, "knot 0 has no joints"};
  }
  if (knots[0].t_s != 0.0) {
    return Error{Errc::kInvalidArgument,
                 fmt::format("the first knot must be at t = 0 s, got {} s", knots[0].t_s)};
  }
  for (std::size_t i = 0; i < knots.size(); ++i) {
    const Knot& k = knots[i];
    if (k.q.size() != n || k.qd.size() != n) {
      return Error{Errc::kInvalidArgument,
                   fmt::format("knot {} has {} positions and {} velocities, expected {}", i,
                               k.q.size(), k.qd.size(), n)};
    }
    if (!std::isfinite(k.t_s)) {
      return Error{Errc::kInvalidArgument, fmt::format("knot {} has a non-finite time", i)};
    }
    for (Eigen::Index j = 0; j < n; ++j) {
      if (!std::isfinite(k.q[j]) || !std::isfinite(k.qd[j])) {
        return Error{Errc::kInvalidArgument,
                     fmt::format("knot {} joint {} is not a finite number", i, j)};
      }
    }
    if (i > 0 && !(k.t_s > knots[i - 1].t_s)) {
      return Error{Errc::kInvalidArgument,
                   fmt::format("knot times must increase: knot {} at {} s follows {} s", i, k.t_s,
                               knots[i - 1].t_s)};
    }
  }
  return JointTrajectory(std::move(knots));
}

std::size_t JointTrajectory::segment_at(double t_s) const noexcept {
  // Last knot with time <= t (segments are [k_i, k_i+1)).
  auto it = std::upper_bound(knots_.begin(), knots_.end(), t_s,
                             [](double t, const Knot& k) { return t < k.t_s; });
  const auto index = static_cast<std::size_t>(std::distance(knots_.begin(), it));
  return index == 0 ? 0 : index - 1;
}

void JointTrajectory::sample(double t_s, JointSample& out) const {
  const Eigen::Index n = dof();
  out.q.resize(n);
  out.qd.resize(n);
  out.qdd.resize(n);
  if (knots_.empty()) {
    return;
  }
  if (knots_.size() == 1 || t_s >= duration_s()) {
    out.q = knots_.back().q;
    out.qd.setZero();
    out.qdd.setZero();
    if (knots_.size() > 1 && t_s == duration_s()) {
      out.qd = knots_.back().qd;
    }
    return;
  }
  if (t_s <= 0.0) {
    t_s = 0.0;
  }
  const std::size_t i = segment_at(t_s);
  const Knot& a = knots_[i];
  const Knot& b = knots_[i + 1];
  const double h = b.t_s - a.t_s;
  const double s = (t_s - a.t_s) / h;
  for (Eigen::Index j = 0; j < n; ++j) {
    const Hermite c{a.q[j], a.qd[j], b.q[j], b.qd[j], h};
    out.q[j] = c.pos(s);
    out.qd[j] = c.vel(s);
    out.qdd[j] = c.acc(s);
  }
}

JointSample JointTrajectory::sample(double t_s) const {
  JointSample out;
  sample(t_s, out);
  return out;
}

Result<JointTrajectory> JointTrajectory::then(const JointTrajectory& next) const {
  if (knots_.empty()) {
    return next;
  }
  if (next.knots_.empty()) {
    return *this;
  }
  if (next.dof() != dof()) {
    return Error{Errc::kInvalidArgument,
                 fmt::format("cannot join trajectories of {} and {} joints", dof(), next.dof())};
  }
  for (Eigen::Index j = 0; j < dof(); ++j) {
    if (std::abs(next.start()[j] - end()[j]) > 1e-6) {
      return Error{Errc::kInvalidArgument,
                   fmt::format("cannot join trajectories: joint {} ends at {} but the next starts "
                               "at {}",
                               j, end()[j], next.start()[j])};
    }
  }
  std::vector<Knot> joined = knots_;
  const double offset = duration_s();
  joined.back().qd = next.knots_.front().qd;  // the junction's velocity is shared
  for (std::size_t i = 1; i < next.knots_.size(); ++i) {
    Knot k = next.knots_[i];
    k.t_s += offset;
    joined.push_back(std::move(k));
  }
  return JointTrajectory(std::move(joined));
}

JointTrajectory JointTrajectory::time_scaled(double factor) const {
  std::vector<Knot> knots = knots_;
  for (Knot& k : knots) {
    k.t_s *= factor;
    k.qd /= factor;
  }
  return JointTrajectory(std::move(knots));
}

double peak_acceleration_ratio(const JointTrajectory& trajectory, const JointLimits& limits) {
  const auto& knots = trajectory.knots();
  double worst = 0;
  for (std::size_t i = 0; i + 1 < knots.size(); ++i) {
    const Knot& a = knots[i];
    const Knot& b = knots[i + 1];
    for (Eigen::Index j = 0; j < trajectory.dof(); ++j) {
      const Hermite c{a.q[j], a.qd[j], b.q[j], b.qd[j], b.t_s - a.t_s};
      worst = std::max({worst, std::abs(c.acc(0.0)) / limits.max_acceleration[j],
                        std::abs(c.acc(1.0)) / limits.max_acceleration[j]});
    }
  }
  return worst;
}

Status JointLimits::validate() const {
  const std::size_t n = lower.size();
  if (n == 0 || upper.size() != static_cast<Eigen::Index>(n) ||
      max_velocity.size() != static_cast<Eigen::Index>(n) ||
      max_acceleration.size() != static_cast<Eigen::Index>(n) || names.size() != n ||
      prismatic.size() != n) {
    return Error{Errc::kInvalidArgument, "joint limits: names, prismatic, lower, upper, "
                                         "max_velocity and max_acceleration differ in size"};
  }
  for (std::size_t j = 0; j < n; ++j) {
    const auto i = static_cast<Eigen::Index>(j);
    if (!(lower[i] < upper[i])) {
      return Error{Errc::kInvalidArgument,
                   fmt::format("joint {}: lower limit {} is not below upper limit {}", names[j],
                               format_joint(lower[i], prismatic[j]),
                               format_joint(upper[i], prismatic[j]))};
    }
    if (!(max_velocity[i] > 0) || !(max_acceleration[i] > 0)) {
      return Error{Errc::kInvalidArgument,
                   fmt::format("joint {}: velocity and acceleration limits must be > 0", names[j])};
    }
  }
  return ok_status();
}

Status check_limits(const JointTrajectory& trajectory, const JointLimits& limits,
                    double velocity_tolerance) {
  CELL_TRY(limits.validate());
  if (trajectory.dof() != limits.dof()) {
    return Error{Errc::kInvalidArgument,
                 fmt::format("trajectory has {} joints, the robot {}", trajectory.dof(),
                             limits.dof())};
  }
  const auto& knots = trajectory.knots();
  const double kPosTol = 1e-9;
  // A path may start outside a position limit (an arm that sagged past it while its torques
  // were off after a fault, or was pushed there unpowered) and lead back in, but it never goes
  // farther out than it started: the bounds widen to include the start, joint by joint.
  const JointVector& q_start = knots.front().q;
  const JointVector lower = limits.lower.cwiseMin(q_start);
  const JointVector upper = limits.upper.cwiseMax(q_start);
  auto check_point = [&](std::size_t segment, double t, Eigen::Index j, double q,
                         double qd) -> Status {
    const auto js = static_cast<std::size_t>(j);
    if (q < lower[j] - kPosTol || q > upper[j] + kPosTol) {
      return Error{Errc::kOutOfRange,
                   fmt::format("segment {} at t={:.3f} s: joint {} at {} beyond its limit [{}, {}]",
                               segment, t, limits.names[js], format_joint(q, limits.prismatic[js]),
                               format_joint(limits.lower[j], limits.prismatic[js]),
                               format_joint(limits.upper[j], limits.prismatic[js]))};
    }
    if (std::abs(qd) > limits.max_velocity[j] * (1.0 + velocity_tolerance)) {
      return Error{Errc::kOutOfRange,
                   fmt::format("segment {} at t={:.3f} s: joint {} speed {}/s exceeds its limit "
                               "{}/s",
                               segment, t, limits.names[js],
                               format_joint(std::abs(qd), limits.prismatic[js]),
                               format_joint(limits.max_velocity[j], limits.prismatic[js]))};
    }
    return ok_status();
  };
  if (knots.size() == 1) {
    for (Eigen::Index j = 0; j < trajectory.dof(); ++j) {
      CELL_TRY(check_point(0, 0.0, j, knots[0].q[j], knots[0].qd[j]));
    }
    return ok_status();
  }
  for (std::size_t i = 0; i + 1 < knots.size(); ++i) {
    const Knot& a = knots[i];
    const Knot& b = knots[i + 1];
    const double h = b.t_s - a.t_s;
    for (Eigen::Index j = 0; j < trajectory.dof(); ++j) {
      const Hermite c{a.q[j], a.qd[j], b.q[j], b.qd[j], h};
      // A cubic's acceleration is linear in time: its extremes are at the segment's ends.
      for (const double s : {0.0, 1.0}) {
        const double qdd = c.acc(s);
        if (std::abs(qdd) > limits.max_acceleration[j] * (1.0 + velocity_tolerance) + 1e-9) {
          const auto js = static_cast<std::size_t>(j);
          return Error{Errc::kOutOfRange,
                       fmt::format("segment {} at t={:.3f} s: joint {} acceleration {}/s^2 exceeds "
                                   "its limit {}/s^2",
                                   i, a.t_s + s * h, limits.names[js],
                                   format_joint(std::abs(qdd), limits.prismatic[js]),
                                   format_joint(limits.max_acceleration[j], limits.prismatic[js]))};
        }
      }
      double c1 = 0;
      double c2 = 0;
      double c3 = 0;
      c.coefficients(c1, c2, c3);
      // Candidates: ends, position extrema (roots of c1 + 2 c2 s + 3 c3 s^2), velocity
      // extremum (6 c3 s + 2 c2 = 0).
      double candidates[5] = {0.0, 1.0, -1.0, -1.0, -1.0};
      if (std::abs(c3) > 1e-15) {
        const double disc = 4 * c2 * c2 - 12 * c3 * c1;
        if (disc >= 0) {
          const double r = std::sqrt(disc);
          candidates[2] = (-2 * c2 + r) / (6 * c3);
          candidates[3] = (-2 * c2 - r) / (6 * c3);
        }
        candidates[4] = -c2 / (3 * c3);
      } else if (std::abs(c2) > 1e-15) {
        candidates[2] = -c1 / (2 * c2);
      }
      for (const double s : candidates) {
        if (s < 0.0 || s > 1.0) {
          continue;
        }
        CELL_TRY(check_point(i, a.t_s + s * h, j, c.pos(s), c.vel(s)));
      }
    }
  }
  return ok_status();
}

}  // namespace cell::trajectory
