#include "cell/trajectory/joint_limiter.hpp"

#include <algorithm>
#include <cmath>
#include <utility>

namespace cell::trajectory {

JointLimiter::JointLimiter(JointLimits limits) : limits_(std::move(limits)) {}

void JointLimiter::reset(const JointVector& q, const JointVector& qd) {
  q_ = q;
  qd_ = qd;
  qdd_.setZero(q.size());
}

bool JointLimiter::step(const JointVector& q_ref, const JointVector& qd_ref, double dt_s) {
  const auto n = q_ref.size();
  if (q_.size() != n) {
    reset(q_ref, qd_ref);
    return false;
  }
  if (!bounded() || dt_s <= 0.0) {
    // No bounds, or no time passed: nothing can move, and nothing is sampled.
    if (!bounded()) {
      qdd_ = dt_s > 0.0 ? JointVector((qd_ref - qd_) / dt_s) : JointVector::Zero(n);
      q_ = q_ref;
      qd_ = qd_ref;
    }
    return false;
  }
  bool limited = false;
  for (Eigen::Index j = 0; j < n; ++j) {
    const double a = limits_.max_acceleration[j];
    const double vmax = limits_.max_velocity[j];
    // The error this step must close besides following the reference's own motion.
    const double e = q_ref[j] - q_[j] - qd_ref[j] * dt_s;
    const double abs_e = std::abs(e);
    const double brake = a * dt_s * (std::sqrt(0.25 + 2.0 * abs_e / (a * dt_s * dt_s)) - 0.5);
    const double feedback = std::copysign(std::min(abs_e / dt_s, brake), e);
    double v = std::clamp(qd_ref[j] + feedback, -vmax, vmax);
    const double dv = std::clamp(v - qd_[j], -a * dt_s, a * dt_s);
    v = qd_[j] + dv;
    qdd_[j] = dv / dt_s;
    qd_[j] = v;
    q_[j] += v * dt_s;
    // Rounding aside, the output is the reference unless a clamp or the braking curve acted.
    const double scale = std::max({1.0, std::abs(q_ref[j])});
    if (std::abs(q_[j] - q_ref[j]) > 1e-9 * scale) {
      limited = true;
    }
  }
  if (limited) {
    ++limited_steps_;
  }
  return limited;
}

JointVector JointLimiter::stopping_point(double dt_s) const {
  JointVector out = q_;
  if (!bounded()) {
    return out;
  }
  for (Eigen::Index j = 0; j < q_.size(); ++j) {
    const double v = qd_[j];
    out[j] +=
        std::copysign(v * v / (2.0 * limits_.max_acceleration[j]) + std::abs(v) * dt_s / 2.0, v);
  }
  return out;
}

}  // namespace cell::trajectory
