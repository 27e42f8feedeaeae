#pragma once

#include <cstdint>
#include <functional>
#include <map>
#include <optional>
#include <string>
#include <string_view>
#include <variant>
#include <vector>

#include "cell/common/result.hpp"
#include "cell/kinematics/robot_model.hpp"
#include "cell/world/part_class.hpp"

/// Job descriptions: what a remote client asks the cell to do (`JobRequest.spec_yaml`,
/// idl/task.idl; example files in config/jobs/). A spec is parsed strictly (every unknown key and
/// every bad value is reported with "<origin>:line:col: key ..."), then checked against the cell
/// (check_job: the robot exists, every place and window is reachable, part classes are known).
///
/// Frames and units. Positions are in the BASE frame of the job's robot, mm; yaw is about the
/// base's +z, from the base's +x, rad inside and `_deg` in the file. Heights (`*_z_mm`) are the
/// z of the robot's tool point in its base frame (for the 7545 with Z positive down that is
/// minus Z: the thesis's pick depth Z = 227.7 mm is `pick_z_mm: -227.7`). Joint vectors in a file
/// are in each joint's display unit (deg for revolute, mm for prismatic joints), in the robot's
/// joint order, and are converted to rad / mm by the parser.
namespace cell::task {

enum class JobKind : std::uint8_t { kTablePickPlace, kConveyorPick, kAssembly };

/// "table_pick_place", "conveyor_pick", "assembly".
std::string_view to_string(JobKind kind) noexcept;

/// Where a placed part's grasp point goes: x, y in the robot base [mm], the part's x axis at
/// yaw_rad about the base's +z.
struct Slot {
  double x_mm = 0.0;
  double y_mm = 0.0;
  double yaw_rad = 0.0;
};

/// A place pattern (`place:`): `list` of slots, a `row` (along +x) or `column` (along +y) of
/// `count` slots `pitch_mm` apart from `origin`, or a `grid` of `columns` x `rows` slots
/// (pitch_x_mm, pitch_y_mm), filled row by row. Every slot of a row/column/grid has `yaw_deg`.
struct PlacePattern {
  enum class Kind : std::uint8_t { kList, kRow, kColumn, kGrid };
  Kind kind = Kind::kList;
  std::vector<Slot> slots;  ///< expanded, in fill order
};

/// The 1994 thesis's job (digest 000 §1.3, §5.3): the eye-in-hand camera looks from each window
/// in turn; every part found is picked and placed at the next free slot.
struct TablePickPlaceSpec {
  std::string camera;  ///< camera id (its Image and Detections)
  /// Image-grab poses, joints [rad, mm], in visiting order (the thesis: J1 45 deg, J2 105 deg).
  std::vector<kinematics::JointVector> windows;
  std::vector<std::string> classes;  ///< classes to pick; empty: every class found
  int max_parts = 0;                 ///< 0: as many as there are slots
  double travel_z_mm = -200.0;       ///< tool height between pick and place (Z = 200 mm)
  std::optional<double> pick_z_mm;   ///< grasp height; default: from the part class and plane
  std::optional<double> place_z_mm;  ///< default: the pick height of the part's class
  double dwell_s = 0.5;              ///< gripper dwell (the thesis's 0.5 s)
  double settle_s = 0.3;             ///< still time at a window before the grab
  int max_retries = 2;               ///< extra attempts for a missed grasp (re-locate first)
  bool return_home = true;
  double speed_scale = 1.0;
  /// The cell's lights for the grabs (the thesis's halogen lamp and fluorescent tubes), switched
  /// through the robot's gateway before the first window; `keep` leaves them as they are.
  enum class Lights : std::uint8_t { kKeep, kOff, kFluorescent, kHalogen, kBoth };
  Lights lights = Lights::kFluorescent;
  PlacePattern place;
};

/// The conveyor chapter's job (digest 002 §1.3): a fixed camera over a belt, the photocell
/// triggers it, each part located is tracked with ALTER and picked on the fly.
struct ConveyorPickSpec {
  std::string camera;
  std::string belt;
  double duration_s = 60.0;  ///< stop taking new parts after this long (0: no limit)
  int max_parts = 0;         ///< stop after this many picks (0: no limit)
  /// The conveyor belt window, along the belt's travel direction, measured from the point of
  /// the belt nearest the robot base [mm]: a part is taken only if its grasp point at the
  /// predicted grasp time lies between upstream_mm and downstream_mm (the chapter's
  /// `downstr_lim`, checked before the robot moves).
  double upstream_mm = -250.0;
  double downstream_mm = 250.0;
  double travel_z_mm = 0.0;         ///< tool height between belt and place
  std::optional<double> pick_z_mm;  ///< default: from the part class and the belt's surface
  std::optional<double> place_z_mm;
  double dwell_s = 0.1;             ///< gripper closing time while tracking
  double alter_period_s = 0.004;    ///< ALTER cycle (the chapter's 16 ms; aim 1-4 ms)
  /// How the robot goes to the meeting point (`track_motion: joint | line`): a joint move
  /// (default: a SCARA gets there sooner, its path a slight arc over the belt) or a straight
  /// line (V+ MOVES).
  bool track_joint_interpolated = true;
  /// Where the tool waits between picks, x-y in the robot's base frame at travel_z_mm
  /// (default: above the belt, halfway from the point nearest the robot to the upstream limit).
  std::optional<Eigen::Vector2d> ready_mm;
  double speed_scale = 1.0;
  PlacePattern place;  ///< a bin: one slot, or several (filled cyclically)
};

/// The 1984 thesis's job: a RAPT program run by a robot, its LOOKs measured by the cameras.
///
/// Frames: the program's world frame W is placed in the robot's base frame by `base_T_world`
/// (mm, base frame); the agent body's frame is related to the robot's tool frame by
/// `agent_T_tool` (for a 6-axis arm whose tool z points down and a gripper body whose z is
/// up: rpy (180, 0, 0)). A body pose world_T_agent of the program becomes the tool target
/// base_T_tool = base_T_world * world_T_agent * agent_T_tool.
struct AssemblySpec {
  std::string program_path;  ///< the program (relative to CELL_HOME) or ...
  std::string program_text;  ///< ... its text inline (`source:`); one of the two
  std::map<std::string, std::string> cameras;  ///< RAPT camera name -> camera id
  /// How each move is executed (digest 003 §4.2): the actual action TA in one step (7.13);
  /// method 1, the correction TC then the nominal action TN (the nominal approach direction
  /// in the world, 7.15); method 2, through PN' (7.17), keeping the nominal approach relative
  /// to the destination (e.g. a shaft along its hole's axis).
  enum class Method : std::uint8_t { kActual, kTwoStepWorld, kTwoStepDestination };
  Method method = Method::kActual;
  double speed_scale = 1.0;
  std::string agent;  ///< the program's AGENT body the robot carries ("": its only one)
  Eigen::Isometry3d base_T_world = Eigen::Isometry3d::Identity();
  Eigen::Isometry3d agent_T_tool = Eigen::Isometry3d::Identity();
  /// false: the vision packages are not measured (every FM stays the identity: the nominal
  /// program, to see what the LOOKs correct).
  bool verify = true;
  /// A grasp the camera shows did not take its body (still where it was after the next move)
  /// is retried this many times from the vision package that verified the body.
  int max_retries = 2;
  /// Largest distance [mm] / lens-axis angle [deg] between a program camera's declared pose
  /// and its cell camera's calibrated one; beyond, the job fails before moving.
  double camera_tolerance_mm = 50.0;
  double camera_tolerance_deg = 10.0;
};

/// A parsed job.
struct JobSpec {
  JobKind kind = JobKind::kTablePickPlace;
  std::string robot;   ///< robot id
  std::string name;    ///< free text for people (`name:`), may be empty
  std::variant<TablePickPlaceSpec, ConveyorPickSpec, AssemblySpec> body;

  const TablePickPlaceSpec* table() const { return std::get_if<TablePickPlaceSpec>(&body); }
  const ConveyorPickSpec* conveyor() const { return std::get_if<ConveyorPickSpec>(&body); }
  const AssemblySpec* assembly() const { return std::get_if<AssemblySpec>(&body); }
};

/// Finds a robot's model by id (nullptr: unknown). The parser needs it to read joint vectors in
/// their display units.
using RobotLookup = std::function<const kinematics::RobotModel*(std::string_view robot_id)>;

/// Parses a job spec. Errors: kConfig listing EVERY problem, one per line, each
/// "<origin>:line:col: key 'a.b': what" (unknown keys, missing keys, wrong types, values out of
/// range, an unknown robot, a joint vector of the wrong size).
Result<JobSpec> parse_job_spec(const std::string& yaml, const std::string& origin,
                               const RobotLookup& robots);

/// What check_job needs to know about the cell.
struct CellFacts {
  RobotLookup robots;
  const world::Catalogue* catalogue = nullptr;
  std::vector<std::string> cameras;  ///< known camera ids
  std::vector<std::string> belts;    ///< known belt ids
  /// The working plane (table or belt top) of a camera in its robot's base frame [mm], used to
  /// derive grasp heights; nullopt when unknown (then pick_z_mm must be given).
  std::function<std::optional<double>(std::string_view camera_id)> working_plane_z_mm;
};

/// Checks a parsed job against the cell: robot, camera, belt and classes exist; every window
/// is within the robot's limits; every place slot is reachable (IK within limits at the place
/// and travel heights, for every class the job may carry); max_parts fits the slots (table).
/// Assembly programs are checked by the task service (core/rapt). Errors: kInvalidArgument or
/// kOutOfRange with EVERY reason, one per line.
Status check_job(const JobSpec& job, const CellFacts& cell);

/// The tool pose that puts a part's grasp point at (x, y, z) with the part's x axis at `yaw`
/// (base frame): for a SCARA the tool z is up, for a 6-axis arm it points down.
Eigen::Isometry3d grasp_pose(const kinematics::RobotModel& robot, double x_mm, double y_mm,
                             double z_mm, double yaw_rad);

}  // namespace cell::task
