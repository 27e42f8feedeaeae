#pragma once

#include <Eigen/Geometry>
#include <cstdint>
#include <memory>
#include <optional>
#include <random>
#include <set>
#include <string>
#include <string_view>
#include <vector>

#include "cell/common/result.hpp"
#include "cell/world/footprint.hpp"
#include "cell/world/part_class.hpp"
#include "cell/world/scene.hpp"

/// The simulated world: parts on a table, on belts, in grippers, on the floor; belts with
/// encoders and photocells; capture and release by the robots' grippers. Deterministic: the
/// same scene, options and sequence of calls give the same world, bit for bit. Pure library:
/// no threads, no clock (time advances only through step()).
///
/// Frames: see scene.hpp (world), part_class.hpp (part, grasp). Each robot's base frame is
/// placed in the world by a RobotMount; a RobotState's base_T_tool becomes
/// world_T_tool = world_T_base * base_T_tool.
namespace cell::world {

/// What a part rests on.
struct Support {
  enum class Kind : std::uint8_t {
    kTable,  ///< the table top
    kBelt,   ///< a belt (id = belt id): the part moves with it
    kRobot,  ///< held by a robot's gripper (id = robot id): follows the tool
    kFloor,  ///< the floor (z = 0): fell off a belt's end or was dropped off the table
  };
  Kind kind = Kind::kTable;
  std::string id;

  /// "table", "belt/<id>", "robot/<id>", "floor" (the IDL's WorldPart.support).
  std::string name() const;
  bool operator==(const Support&) const = default;
};

/// One part in the world.
struct Part {
  std::string id;
  std::shared_ptr<const PartClass> cls;
  Eigen::Isometry3d world_T_part = Eigen::Isometry3d::Identity();
  Support support;
  std::string support_name;  ///< support.name(), kept for borrowing into IDL samples
  /// Held parts only: the part in the tool frame, fixed at capture (a pick 1.5 mm off carries
  /// the part 1.5 mm off, and it lands 1.5 mm off).
  Eigen::Isometry3d tool_T_part = Eigen::Isometry3d::Identity();
  Footprint footprint;  ///< current outline seen from above (world)
  std::string where;    ///< scene location ("file:line:col") or "" for spawned parts

  /// world_T_part * part_T_grasp.
  Eigen::Isometry3d world_T_grasp() const { return world_T_part * cls->part_T_grasp; }
};

/// Where a robot's base stands in the world.
struct RobotMount {
  std::string robot_id;
  Eigen::Isometry3d world_T_base = Eigen::Isometry3d::Identity();
};

/// Gripper state as the robots report it (mirrors the IDL cell_robot_GripperState).
enum class GripperState : std::uint8_t { kUnknown, kOpen, kClosed, kOpening, kClosing };

/// Tunables of the world (config/sim-world.yaml `physics:` and `robots:`).
struct WorldOptions {
  /// A closing gripper takes a part when its tool point is within this distance of the part's
  /// grasp point (3-D) [mm]. Digest 000 §7: recognition is good to ~0.5 mm, the robot to ~1 mm.
  double capture_tolerance_mm = 2.0;
  /// ... and its x axis within this yaw of the grasp x axis turned by one of the class's
  /// grasp_yaws_rad, modulo the class symmetry [rad].
  double capture_yaw_tolerance = 0.17453292519943295;  // 10 deg
  /// ... and its z axis within this angle of the vertical (up or down) [rad].
  double capture_tilt_tolerance = 0.17453292519943295;  // 10 deg
  /// Where each robot stands. RobotStates of robots not listed are refused by update_robot.
  std::vector<RobotMount> robots;

  /// Ok, or kInvalidArgument naming the field (non-positive tolerances, duplicate robot ids,
  /// a non-rigid mount).
  Status validate() const;
};

/// A belt's moving state.
struct Belt {
  BeltSpec spec;
  double travel_mm = 0.0;          ///< since the world was created, signed
  std::int64_t encoder_count = 0;  ///< encoder_sign * floor(travel_mm / mm_per_count)
  bool photocell_blocked = false;  ///< last reported beam state
};

/// Something that happened during step() or update_robot().
struct WorldEvent {
  enum class Kind : std::uint8_t {
    kPhotocell,    ///< a beam changed: belt_id, blocked, encoder_count latched at the edge
    kAttached,     ///< a gripper took part_id (robot_id)
    kMissed,       ///< a gripper closed on nothing (detail: the nearest grasp point and why)
    kReleased,     ///< a gripper let part_id go; it now rests on `support`
    kFellOffBelt,  ///< part_id passed the end of belt_id and now rests on `support`
    kFed,          ///< a feeder put part_id on belt_id (or, with detail "jammed", could not)
  };
  Kind kind = Kind::kPhotocell;
  double time_s = 0.0;  ///< world time of the event (photocell: interpolated to the edge)
  std::string part_id;
  std::string belt_id;
  std::string robot_id;
  bool blocked = false;
  std::int64_t encoder_count = 0;
  std::string support;  ///< Support::name() after a release or fall
  std::string detail;   ///< a sentence for logs
};

/// "photocell", "attached", "missed", "released", "fell_off_belt", "fed".
std::string_view to_string(WorldEvent::Kind kind) noexcept;

/// The world. Copyable (a copy is an independent world). Not thread-safe: one thread drives it
/// (services/sim-world's loop). Nothing here allocates per step except event strings.
class World {
 public:
  /// Builds the world of `scene`: the catalogue plus the scene's classes, belts, the scene's
  /// parts (each dropped on what is below it), then each scatter generator in order. The first
  /// scatter spec (or, without one, dip14s on the table 30 mm in from its edges with the
  /// scene's min separation, seed 1) becomes default_scatter() for later scatter requests.
  /// Errors: kConfig, every problem at once, one per line, each starting with the part's
  /// "file:line:col": unknown class, duplicate id, part overlapping (or closer than
  /// min_separation_mm to) an earlier one, naming it and where it was declared; a scatter that
  /// cannot place its parts; invalid belts or options.
  static Result<World> create(const Scene& scene,
                              const Catalogue& catalogue,
                              const WorldOptions& options);

  // ---- time ----

  /// Advances the world by `dt_s` > 0 seconds: belts move (travel, encoder count), parts on a
  /// belt move with it, photocell edges are detected with the count interpolated to the edge,
  /// parts whose origin passes a belt's end fall to what is below (the floor, usually).
  /// Events are appended to `events`. A non-positive or non-finite dt does nothing.
  void step(double dt_s, std::vector<WorldEvent>& events);

  // ---- robots ----

  /// Takes one robot observation (a RobotState): the tool pose in the robot's base frame and
  /// the gripper state. Held parts follow the tool. On a transition of the gripper into
  /// kClosing or kClosed (from a known open state), the nearest free part whose grasp point is
  /// within capture_tolerance_mm of the tool point (yaw and tilt within theirs; the yaw error
  /// is the smallest over the class's grasp_yaws_rad) attaches: kAttached, or kMissed naming
  /// the nearest part, its distance and its yaw error. On a transition into
  /// kOpening or kOpen, every part the robot holds is released: it drops flat (keeping its x,
  /// y and yaw about the vertical) onto the highest surface below its origin (a belt, the table
  /// or the floor): kReleased. The first observation of a robot only records its state;
  /// kUnknown never changes it.
  /// `age_s`: how long before the world's present (time_s()) the observation was true (its
  /// stamp; negative when the state is newer than the last step). A capture compares the tool
  /// with the parts where they were at that instant: a part on a belt at v was v * age_s
  /// upstream of where the world has it now. (Without it, a state 1 ms old puts a tool that
  /// tracks a 2 m/s belt exactly 2 mm behind its part.) It must be within +-kMaxAgeS.
  /// Errors: kInvalidArgument for a robot without a mount, a non-rigid pose or an age out of
  /// range (nothing changes).
  Status update_robot(std::string_view robot_id,
                      const Eigen::Isometry3d& base_T_tool,
                      GripperState gripper,
                      std::vector<WorldEvent>& events,
                      double age_s = 0.0);
  /// The largest |age_s| update_robot takes [s].
  static constexpr double kMaxAgeS = 1.0;

  // ---- edits (every one bumps seq()) ----

  /// Adds a part. Errors: kInvalidArgument for an unknown class (naming the known ones), a
  /// duplicate id, a non-finite pose; kOutOfRange when it overlaps another part on the same
  /// support (or is closer than `min_separation_mm`), naming that part. Returns the id.
  Result<std::string> spawn(const PartPlacement& placement, double min_separation_mm = 0.0);

  /// Removes a part (held ones too). Errors: kInvalidArgument for an unknown id.
  Status remove(std::string_view part_id);

  /// Sets a belt's speed [mm/s] (signed). Errors: kInvalidArgument for an unknown belt or a
  /// non-finite speed.
  Status set_belt_speed(std::string_view belt_id, double speed_mm_s);

  /// Adds spec.count parts (all or nothing). Errors: kInvalidArgument for an invalid spec or an
  /// unknown class; kOutOfRange when a part cannot be placed within max_attempts_per_part
  /// (the message says how many were placed before giving up). Returns the new ids in order.
  Result<std::vector<std::string>> scatter(const ScatterSpec& spec);

  // ---- queries ----

  const std::vector<Part>& parts() const noexcept { return parts_; }
  /// The part called `id`, or nullptr.
  const Part* find(std::string_view part_id) const noexcept;
  const std::vector<Belt>& belts() const noexcept { return belts_; }
  /// The belt called `id`, or nullptr.
  const Belt* find_belt(std::string_view belt_id) const noexcept;
  const Table& table() const noexcept { return table_; }
  const Catalogue& catalogue() const noexcept { return catalogue_; }
  const WorldOptions& options() const noexcept { return options_; }
  const std::string& scene_name() const noexcept { return scene_name_; }
  /// The scene's min_separation_mm (spawn requests are held to it too).
  double min_separation_mm() const noexcept { return min_separation_mm_; }
  /// The generator scatter requests use when they give only count, classes and seed.
  const ScatterSpec& default_scatter() const noexcept { return default_scatter_; }
  /// Parts fed and jammed so far by the feeder of `belt_id` (0, 0 without one).
  std::pair<std::uint32_t, std::uint64_t> feeder_counts(std::string_view belt_id) const;
  /// World time [s]: the sum of every step's dt.
  double time_s() const noexcept { return time_s_; }
  /// Increments on every change of the part set or of a part's support (spawn, remove,
  /// scatter, attach, release, fall).
  std::uint64_t seq() const noexcept { return seq_; }
  /// The last known world_T_tool of a robot (nullopt before its first observation).
  std::optional<Eigen::Isometry3d> world_T_tool(std::string_view robot_id) const;

  /// The support below world point (x, y) for a part whose base is at height `z` [mm]: the
  /// highest belt or table surface containing (x, y) that is not more than 50 mm above z (a
  /// part pushed a little into a surface rests on it), else the floor (z = 0). Returns the
  /// support and its surface height. z = +infinity gives the highest surface at (x, y).
  std::pair<Support, double> support_below(double x, double y, double z) const;

 private:
  struct RobotSlot {
    RobotMount mount;
    std::optional<Eigen::Isometry3d> world_T_tool;
    GripperState gripper = GripperState::kUnknown;  // last known, never kUnknown once known
  };

  World() = default;
  Result<Part> make_part(const PartPlacement& placement) const;
  void set_pose(Part& part, const Eigen::Isometry3d& world_T_part);
  void set_support(Part& part, Support support);
  /// Index of a part on `support` that `footprint` overlaps (or comes closer than
  /// min_separation_mm to), or -1.
  std::ptrdiff_t find_conflict(const Footprint& footprint,
                               const Support& support,
                               double min_separation_mm,
                               std::ptrdiff_t ignore = -1) const;
  std::string next_id();
  void capture(RobotSlot& robot, double age_s, std::vector<WorldEvent>& events);
  /// The velocity of a part's support in the world frame [mm/s] (a belt's; else zero).
  Eigen::Vector3d support_velocity(const Part& part) const;
  void release(RobotSlot& robot, std::vector<WorldEvent>& events);
  void drop(Part& part);
  void step_belt(std::size_t belt_index, double dt_s, std::vector<WorldEvent>& events);

  struct Crossing {  // a part's edge crossing a photocell beam during one step
    double offset;   // belt travel from the step's start [mm], >= 0
    int delta;       // +1 enters the beam, -1 leaves it
    std::size_t part;
  };

  Catalogue catalogue_;
  WorldOptions options_;
  std::string scene_name_;
  Table table_;
  std::vector<Belt> belts_;
  std::vector<Part> parts_;
  std::vector<RobotSlot> robots_;
  ScatterSpec default_scatter_;
  struct FeederState {
    FeederSpec spec;
    double next_s = 0.0;       // world time of the next part
    std::uint32_t fed = 0;
    std::uint64_t jammed = 0;
    std::mt19937_64 rng;       // seeded with spec.seed: the same stream every run
  };
  std::vector<FeederState> feeders_;
  void step_feeders(std::vector<WorldEvent>& events);
  double min_separation_mm_ = 0.0;
  double time_s_ = 0.0;
  std::uint64_t seq_ = 0;
  std::uint64_t next_auto_id_ = 1;
  std::vector<Crossing> crossings_;     // scratch of step_belt (kept to avoid reallocating)
  std::set<std::string> reserved_ids_;  // a scene's explicit ids while create() assigns others
};

}  // namespace cell::world
