#include "cell/kinematics/joints.hpp"

#include <cmath>
#include <limits>

#include <fmt/format.h>

#include "cell/geometry/angles.hpp"

namespace cell::kinematics {

using geometry::kPi;

std::string_view to_string(JointType type) noexcept {
  return type == JointType::kRevolute ? "revolute" : "prismatic";
}

std::string_view JointSpec::display_unit() const noexcept {
  return type == JointType::kRevolute ? "deg" : "mm";
}

double JointSpec::to_display(double value) const noexcept {
  return type == JointType::kRevolute ? geometry::rad_to_deg(value) : value;
}

double JointSpec::from_display(double value) const noexcept {
  return type == JointType::kRevolute ? geometry::deg_to_rad(value) : value;
}

std::string format_joint_value(const JointSpec& joint, double value) {
  return fmt::format("{:.3f} {}", joint.to_display(value), joint.display_unit());
}

Status check_joint_vector(std::span<const JointSpec> joints, const JointVector& q) {
  if (static_cast<std::size_t>(q.size()) != joints.size()) {
    return Error{
        Errc::kInvalidArgument,
        fmt::format("joint vector has {} entries, robot has {} joints", q.size(), joints.size())};
  }
  for (std::size_t i = 0; i < joints.size(); ++i) {
    const double v = q(static_cast<Eigen::Index>(i));
    if (!std::isfinite(v)) {
      return Error{Errc::kInvalidArgument,
                   fmt::format("joint '{}' is not finite ({})", joints[i].name, v)};
    }
  }
  return ok_status();
}

int first_limit_violation(std::span<const JointSpec> joints, const JointVector& q) noexcept {
  for (std::size_t i = 0; i < joints.size(); ++i) {
    if (!joints[i].within_limits(q(static_cast<Eigen::Index>(i)))) {
      return static_cast<int>(i);
    }
  }
  return -1;
}

namespace {

std::string limit_message(const JointSpec& joint, double value) {
  return fmt::format("joint '{}' = {} is outside its limits [{:.3f}, {:.3f}] {}", joint.name,
                     format_joint_value(joint, value), joint.to_display(joint.lower),
                     joint.to_display(joint.upper), joint.display_unit());
}

}  // namespace

Status check_limits(std::span<const JointSpec> joints, const JointVector& q) {
  CELL_TRY(check_joint_vector(joints, q));
  const int bad = first_limit_violation(joints, q);
  if (bad >= 0) {
    return Error{Errc::kOutOfRange, limit_message(joints[static_cast<std::size_t>(bad)], q(bad))};
  }
  return ok_status();
}

Result<CountVector> to_counts(std::span<const JointSpec> joints, const JointVector& q) {
  CELL_TRY(check_joint_vector(joints, q));
  CountVector counts(q.size());
  for (std::size_t i = 0; i < joints.size(); ++i) {
    if (joints[i].counts_per_unit <= 0.0) {
      return Error{Errc::kInvalidArgument,
                   fmt::format("joint '{}' has no encoder scale (counts_per_{})", joints[i].name,
                               joints[i].display_unit())};
    }
    const double counts_f = q(static_cast<Eigen::Index>(i)) * joints[i].counts_per_unit;
    if (std::abs(counts_f) > 9.0e18) {
      return Error{Errc::kOutOfRange,
                   fmt::format("joint '{}' = {} does not fit a 64-bit count", joints[i].name,
                               format_joint_value(joints[i], q(static_cast<Eigen::Index>(i))))};
    }
    counts(static_cast<Eigen::Index>(i)) = std::llround(counts_f);
  }
  return counts;
}

Result<JointVector> from_counts(std::span<const JointSpec> joints, const CountVector& counts) {
  if (static_cast<std::size_t>(counts.size()) != joints.size()) {
    return Error{Errc::kInvalidArgument,
                 fmt::format("count vector has {} entries, robot has {} joints", counts.size(),
                             joints.size())};
  }
  JointVector q(counts.size());
  for (std::size_t i = 0; i < joints.size(); ++i) {
    if (joints[i].counts_per_unit <= 0.0) {
      return Error{Errc::kInvalidArgument,
                   fmt::format("joint '{}' has no encoder scale (counts_per_{})", joints[i].name,
                               joints[i].display_unit())};
    }
    const auto index = static_cast<Eigen::Index>(i);
    q(index) = static_cast<double>(counts(index)) / joints[i].counts_per_unit;
  }
  return q;
}

double min_move_time(std::span<const JointSpec> joints,
                     const JointVector& from,
                     const JointVector& to) noexcept {
  double worst = 0.0;
  for (std::size_t i = 0; i < joints.size(); ++i) {
    const auto index = static_cast<Eigen::Index>(i);
    const double t = std::abs(to(index) - from(index)) / joints[i].max_speed;
    worst = std::max(worst, t);
  }
  return worst;
}

namespace detail {

double fit_revolute_outside(const JointSpec& joint, double base, double reference) noexcept {
  // `base`, the equivalent nearest the reference, is outside the limits. Try the equivalents one
  // turn further out on each side, nearest first. Limits spanning more than a few turns are not
  // meaningful for a real joint; four turns cover any sane config.
  for (int k = 1; k <= 4; ++k) {
    const double up = base + 2.0 * kPi * k;
    const double down = base - 2.0 * kPi * k;
    const bool up_ok = joint.within_limits(up);
    const bool down_ok = joint.within_limits(down);
    if (up_ok && down_ok) {
      return std::abs(up - reference) <= std::abs(down - reference) ? up : down;
    }
    if (up_ok) {
      return up;
    }
    if (down_ok) {
      return down;
    }
  }
  return base;
}

}  // namespace detail

const IkSolution* IkSolutions::find(std::string_view name) const noexcept {
  for (const IkSolution& s : *this) {
    if (s.branch == name) {
      return &s;
    }
  }
  return nullptr;
}

const IkSolution* IkSolutions::nearest(std::span<const JointSpec> joints,
                                       const JointVector& seed) const noexcept {
  double inv_speed[kMaxDof];
  const std::size_t n = std::min<std::size_t>(joints.size(), kMaxDof);
  for (std::size_t i = 0; i < n; ++i) {
    inv_speed[i] = 1.0 / joints[i].max_speed;
  }
  const IkSolution* best = nullptr;
  double best_time = std::numeric_limits<double>::infinity();
  double best_sum = std::numeric_limits<double>::infinity();
  for (const IkSolution& s : *this) {
    if (!s.within_limits()) {
      continue;
    }
    // Time of the joint-interpolated move (min_move_time), and as a tie-break the summed
    // normalised motion, so that, e.g., the wrist does not flip for free when a shoulder joint
    // dominates the time.
    double t = 0.0;
    double sum = 0.0;
    for (std::size_t i = 0; i < n; ++i) {
      const auto index = static_cast<Eigen::Index>(i);
      const double joint_time = std::abs(s.q(index) - seed(index)) * inv_speed[i];
      t = std::max(t, joint_time);
      sum += joint_time;
    }
    if (t < best_time - 1e-12 || (t <= best_time + 1e-12 && sum < best_sum)) {
      best = &s;
      best_time = t;
      best_sum = sum;
    }
  }
  return best;
}

void IkSolutions::push_back(const IkSolution& solution) noexcept {
  if (size_ < kCapacity) {
    items_[size_++] = solution;
  }
}

Error no_branch_within_limits(std::span<const JointSpec> joints,
                              const IkSolutions& solutions,
                              std::string_view what) {
  std::string message = fmt::format("{}: no IK branch is within the joint limits", what);
  for (const IkSolution& s : solutions) {
    const auto bad = static_cast<std::size_t>(static_cast<std::uint8_t>(s.violated_joint));
    message += fmt::format("; {}: {}", s.branch,
                           limit_message(joints[bad], s.q(static_cast<Eigen::Index>(bad))));
  }
  return Error{Errc::kOutOfRange, std::move(message)};
}

Result<JointVector> pick_branch(std::span<const JointSpec> joints,
                                const IkSolutions& solutions,
                                std::span<const std::string_view> branch_names,
                                std::string_view name) {
  const IkSolution* s = solutions.find(name);
  if (s == nullptr) {
    std::string valid;
    for (const std::string_view n : branch_names) {
      valid += valid.empty() ? "" : ", ";
      valid += n;
    }
    return Error{Errc::kInvalidArgument,
                 fmt::format("unknown IK branch '{}'; valid branches: {}", name, valid)};
  }
  if (!s->within_limits()) {
    const auto bad = static_cast<std::size_t>(static_cast<std::uint8_t>(s->violated_joint));
    return Error{Errc::kOutOfRange,
                 fmt::format("branch {}: {}", s->branch,
                             limit_message(joints[bad], s->q(static_cast<Eigen::Index>(bad))))};
  }
  return s->q;
}

}  // namespace cell::kinematics
