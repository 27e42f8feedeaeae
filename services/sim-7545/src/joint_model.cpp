#include "joint_model.hpp"

#include <algorithm>
#include <cmath>

#include "cell/dpr7545/codec.hpp"

namespace cell::sim7545 {

JointModel::JointModel(const JointPlant& plant, double initial_counts, std::int32_t overrun_min,
                       std::int32_t overrun_max)
    : plant_(plant), position_(initial_counts), zero_(initial_counts) {
  const double margin = std::max(500.0, 0.02 * static_cast<double>(overrun_max - overrun_min));
  stop_min_ = static_cast<double>(overrun_min) - margin;
  stop_max_ = static_cast<double>(overrun_max) + margin;
  position_ = std::clamp(position_, stop_min_, stop_max_);
  zero_ = position_;
}

void JointModel::advance(std::uint16_t word, double dt_s) noexcept {
  if (!(dt_s > 0)) {
    return;
  }
  const int n = std::max(1, static_cast<int>(std::ceil(dt_s / 100e-6)));
  const double h = dt_s / n;
  const double drive = plant_.accel_per_dac_counts_s2 * dpr7545::torque_dac(word);
  const double friction = plant_.accel_per_dac_counts_s2 * plant_.coulomb_dac;
  for (int i = 0; i < n; ++i) {
    double a = 0.0;
    if (velocity_ == 0.0) {
      a = std::abs(drive) <= friction ? 0.0 : drive - std::copysign(friction, drive);
    } else {
      a = drive - plant_.viscous_per_s * velocity_ - std::copysign(friction, velocity_);
    }
    double v = velocity_ + a * h;
    if (velocity_ != 0.0 && v * velocity_ < 0.0 && std::abs(drive) <= friction) {
      v = 0.0;  // friction stops the joint; it cannot reverse it
    }
    const double before = position_;
    velocity_ = v;
    position_ += v * h;
    if (position_ < stop_min_ || position_ > stop_max_) {
      position_ = std::clamp(position_, stop_min_, stop_max_);
      velocity_ = 0.0;
    }
    // Index pulses at every multiple of the spacing crossed (either direction).
    const double s = plant_.index_spacing_counts;
    const double k_before = std::floor(before / s);
    const double k_after = std::floor(position_ / s);
    if (k_after != k_before) {
      ++index_pulses_;
      last_index_ = std::max(k_before, k_after) * s;
    }
  }
}

std::int64_t JointModel::encoder_counts() const noexcept {
  return static_cast<std::int64_t>(std::llround(position_ - zero_)) + offset_;
}

std::uint32_t JointModel::counter_24() const noexcept {
  return dpr7545::to_counter_24(encoder_counts());
}

void JointModel::reset_counter_here() noexcept { zero_ = position_; }

void JointModel::reset_counter_at(double position) noexcept { zero_ = position; }

void JointModel::force_encoder_counts(std::int64_t counts) noexcept {
  offset_ = 0;
  offset_ = counts - encoder_counts();
}

}  // namespace cell::sim7545
