#pragma once

#include <cstdint>
#include <random>
#include <string>

#include "cell/common/result.hpp"

namespace cell::protocols::excalibur {

/// Injected line noise, for tests of the driver's recovery (the thesis's line errors, digest 001
/// §1.3). Each fault is one of: a flipped bit in a byte, a dropped byte, a duplicated byte,
/// equally likely. Terminators can be hit too (two lines then run together).
struct NoiseSettings {
  /// Probability that a line (in either direction, judged separately) carries one fault at a
  /// random byte, terminator included. "1 % line noise" in the system test means 0.01 here.
  double probability_per_line = 0.0;
  /// Probability of a fault at every byte, independently (a harsher, rate-based model).
  double probability_per_byte = 0.0;

  /// Ok, or kInvalidArgument naming the field (each must be in [0, 1]).
  Status validate() const;
  bool active() const noexcept { return probability_per_line > 0 || probability_per_byte > 0; }
};

/// Applies NoiseSettings to lines. Deterministic for a seed. Not thread-safe (one per link
/// direction or guarded by its owner).
class LineNoise {
 public:
  explicit LineNoise(std::uint64_t seed = 1) : rng_(seed) {}

  void set(const NoiseSettings& settings) noexcept { settings_ = settings; }
  const NoiseSettings& settings() const noexcept { return settings_; }

  /// Damages `bytes` (a whole line with its terminator) in place; returns the number of faults.
  int corrupt_line(std::string& bytes);
  /// Applies only the per-byte faults to a chunk of a stream; returns the number of faults.
  int corrupt_bytes(std::string& bytes);

  /// Faults injected so far.
  std::uint64_t faults() const noexcept { return faults_; }

 private:
  void fault_at(std::string& bytes, std::size_t index);
  NoiseSettings settings_;
  std::mt19937_64 rng_;
  std::uint64_t faults_ = 0;
};

}  // namespace cell::protocols::excalibur
