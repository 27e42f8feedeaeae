#pragma once

#include <cstdint>
#include <deque>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Geometry>

#include "cell/bus/idl_types.hpp"
#include "cell/common/result.hpp"
#include "cell/kinematics/joints.hpp"
#include "cell/render/scene.hpp"

/// What the camera service knows of the world, robots and belts, and how it turns that into
/// the scene at an exposure time. No DDS calls: fed with received samples, so it is tested
/// without a bus.
namespace cell::camera {

/// IDL pose -> Isometry3d (quaternion normalised). Errors: kInvalidArgument for non-finite
/// values or a quaternion far from unit length (|q| outside [0.9, 1.1]).
Result<Eigen::Isometry3d> pose_from_idl(const cell_common_Pose& pose);
/// Isometry3d -> IDL pose.
cell_common_Pose pose_to_idl(const Eigen::Isometry3d& pose);

/// One WorldState, converted: the parts as render::Parts at the state's stamp, and how each
/// moves (belt parts ride their belt).
struct WorldSnapshot {
  std::int64_t stamp_ns = 0;
  std::uint64_t world_seq = 0;
  render::Scene scene;  ///< lights left at their defaults: the service sets them per frame
  /// Malformed parts left out, one sentence each ("part 'p3': unknown shape 9").
  std::vector<std::string> skipped;
};

/// Converts a WorldState. Never fails as a whole: a malformed part (non-finite or non-rigid
/// pose, unknown shape, bad sizes, a broken mesh) or belt is left out and listed in `skipped`.
/// Parts supported by "belt/<id>" get that belt's velocity (direction x speed).
WorldSnapshot snapshot_from_idl(const cell_world_WorldState& state);

/// The scene at `exposure_ns`: belt parts moved by their velocity over (exposure - stamp).
render::Scene scene_at(const WorldSnapshot& world, std::int64_t exposure_ns);

/// A short history of timed samples of one quantity, for values at an exposure time.
/// Samples must arrive in (mostly) increasing stamp order; older ones are dropped beyond
/// `capacity`.
class RobotHistory {
 public:
  struct Sample {
    std::int64_t stamp_ns = 0;
    kinematics::JointVector q;
    bool halogen_on = false;
    bool fluorescent_on = false;
  };
  explicit RobotHistory(std::size_t capacity = 512) : capacity_(capacity) {}

  /// Adds a RobotState. Errors: kInvalidArgument when its joints are not finite or too many.
  Status add(const cell_robot_RobotState& state);

  /// Joints at `stamp_ns`, linearly interpolated between the samples around it; before the
  /// first sample, the first; after the last, the last if it is at most `max_age_ns` older.
  /// Errors: kNotReady naming the robot when there is no sample or the last is too old.
  Result<Sample> at(std::int64_t stamp_ns, std::int64_t max_age_ns) const;

  bool empty() const noexcept { return samples_.empty(); }
  const Sample& latest() const { return samples_.back(); }

 private:
  std::size_t capacity_;
  std::deque<Sample> samples_;
};

/// Encoder counts of one belt over time (BeltState stream), for the count latched at exposure.
class BeltHistory {
 public:
  struct Sample {
    std::int64_t stamp_ns = 0;
    double travel_mm = 0.0;
    double speed_mm_per_s = 0.0;
    std::int64_t encoder_count = 0;
  };
  explicit BeltHistory(std::size_t capacity = 256) : capacity_(capacity) {}

  void add(const Sample& sample);

  /// The encoder count at `stamp_ns`: interpolated between the samples around it, or
  /// extrapolated from the last two (at most `max_age_ns` beyond the last). Errors: kNotReady
  /// when there is no sample or the last is too old.
  Result<std::int64_t> count_at(std::int64_t stamp_ns, std::int64_t max_age_ns) const;

  /// The latest speed [mm/s], or nullopt when no sample arrived.
  std::optional<double> speed() const;

 private:
  std::size_t capacity_;
  std::deque<Sample> samples_;
};

}  // namespace cell::camera
