#include "cell/trajectory/executor.hpp"

#include <algorithm>

namespace cell::trajectory {
namespace {

/// 3x^2 - 2x^3: 0 -> 1 with zero slope at both ends.
double smoothstep(double x) {
  x = std::clamp(x, 0.0, 1.0);
  return x * x * (3.0 - 2.0 * x);
}

}  // namespace

TrajectoryExecutor::TrajectoryExecutor(ForwardFn forward, InverseFn inverse, JointLimits limits)
    : forward_(std::move(forward)), inverse_(std::move(inverse)), limiter_(std::move(limits)) {}

void TrajectoryExecutor::load(JointTrajectory trajectory, double start_s, bool alter_enabled,
                              AlterMode mode) {
  trajectory_ = std::move(trajectory);
  start_s_ = start_s;
  last_now_s_ = start_s;
  alter_enabled_ = alter_enabled;
  alter_ = AlterState(mode);
  state_ = trajectory_.knots().empty() ? ExecState::kIdle : ExecState::kMoving;
  has_last_ = false;
  has_ref_ = false;
  max_lag_mm_ = 0.0;
  // Setpoints still moving (tracking, braking after ALTOFF) join the new path through the
  // limiter; at rest the path starts where they are, as planned.
  limiting_ = limiter_live_ && limiter_.bounded() && limiter_.qd().size() > 0 &&
              limiter_.qd().cwiseAbs().maxCoeff() > 0.0;
  if (!limiting_) {
    limiter_live_ = false;
  }
}

void TrajectoryExecutor::submit_alter(const AlterCorrection& correction) noexcept {
  if (alter_enabled_) {
    alter_.submit(correction);
  }
}

void TrajectoryExecutor::alter_off() noexcept {
  if (!alter_enabled_) {
    return;
  }
  // Freeze where destination + total correction put the robot: a trajectory that holds it.
  // With limits, where the arm comes to rest braked from its tracking speed at its limits.
  if (has_last_) {
    const bool brake = limiter_live_ && limiter_.bounded();
    JointVector rest = brake ? limiter_.stopping_point(last_dt_s_) : last_q_;
    std::vector<Knot> hold{Knot{0.0, std::move(rest), JointVector::Zero(last_q_.size())}};
    if (auto t = JointTrajectory::from_knots(std::move(hold))) {
      trajectory_ = std::move(*t);
      start_s_ = last_now_s_;
      limiting_ = brake;
    }
  }
  alter_enabled_ = false;
}

void TrajectoryExecutor::stop() noexcept {
  alter_enabled_ = false;
  if (has_last_) {
    std::vector<Knot> hold{Knot{0.0, last_q_, JointVector::Zero(last_q_.size())}};
    if (auto t = JointTrajectory::from_knots(std::move(hold))) {
      trajectory_ = std::move(*t);
    }
  }
  state_ = has_last_ ? ExecState::kArrived : ExecState::kIdle;
  // A stop holds the last setpoint at once (as it did without limits).
  limiting_ = false;
  limiter_live_ = false;
}

void TrajectoryExecutor::clear() noexcept {
  alter_enabled_ = false;
  has_last_ = false;
  limiting_ = false;
  limiter_live_ = false;
  state_ = ExecState::kIdle;
}

double TrajectoryExecutor::progress() const noexcept {
  const double d = trajectory_.duration_s();
  if (d <= 0) {
    return state_ == ExecState::kIdle ? 0.0 : 1.0;
  }
  return std::clamp((last_now_s_ - start_s_) / d, 0.0, 1.0);
}

ExecState TrajectoryExecutor::step(double now_s, JointSample& out) {
  if (state_ == ExecState::kIdle) {
    return state_;
  }
  last_now_s_ = now_s;
  const double t = now_s - start_s_;
  trajectory_.sample(t, nominal_);
  if (state_ == ExecState::kFailed) {
    out.q = last_q_;
    out.qd.setZero(last_q_.size());
    out.qdd.setZero(last_q_.size());
    return state_;
  }
  bool arrived = t >= trajectory_.duration_s();
  if (!alter_enabled_) {
    out = nominal_;
  } else {
    alter_.begin_cycle();
    const AlterCorrection c = alter_.effective_at(now_s);
    const double d = trajectory_.duration_s();
    const double blend = d > 0 ? smoothstep(t / d) : 1.0;
    AlterCorrection scaled = c;
    scaled.translation_mm *= blend;
    scaled.rotation_rad *= blend;
    const Eigen::Isometry3d target = alter_.apply(forward_(nominal_.q), scaled);
    const JointVector& seed = has_ref_ ? last_ref_q_ : has_last_ ? last_q_ : nominal_.q;
    auto q = inverse_(target, seed);
    if (!q) {
      failure_ = q.error();
      state_ = ExecState::kFailed;
      out.q = seed;
      out.qd.setZero(seed.size());
      out.qdd.setZero(seed.size());
      return state_;
    }
    out.q = *q;
    // The altered path's velocity: a backward difference of its points (the correction's rate
    // makes the nominal velocity wrong once tracking).
    const double dt = now_s - last_step_s_;
    if (has_ref_ && dt > 0) {
      out.qd = (out.q - last_ref_q_) / dt;
    } else {
      out.qd = nominal_.qd;
    }
    out.qdd = nominal_.qdd;
    last_ref_q_ = out.q;
    has_ref_ = true;
  }
  if (limiter_.bounded()) {
    if (!limiter_live_) {
      limiter_.reset(out.q, out.qd);
      limiter_live_ = true;
      limiter_s_ = now_s;
    }
    const double dt = now_s - limiter_s_;
    if (alter_enabled_ || limiting_) {
      // The altered path (or a path the setpoints have not yet joined), through the limits.
      const bool held_off = limiter_.step(out.q, out.qd, dt);
      if (held_off) {  // how far the tool is off the path there
        const double lag =
            (forward_(limiter_.q()).translation() - forward_(out.q).translation()).norm();
        max_lag_mm_ = std::max(max_lag_mm_, lag);
      }
      limiting_ = alter_enabled_ || held_off;
      out.q = limiter_.q();
      out.qd = limiter_.qd();
      out.qdd = limiter_.qdd();
      // Tracking arrives with its path (the limiter follows it); a path not yet joined, or
      // ALTOFF's braking, arrives when the setpoints rest on it.
      arrived = arrived && (alter_enabled_ || !held_off);
    } else {
      limiter_.reset(out.q, out.qd);
    }
    if (dt > 0) {
      last_dt_s_ = dt;
    }
    limiter_s_ = now_s;
  }
  last_step_s_ = now_s;
  last_q_ = out.q;
  has_last_ = true;
  state_ = arrived ? ExecState::kArrived : ExecState::kMoving;
  return state_;
}

}  // namespace cell::trajectory
