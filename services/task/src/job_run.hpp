#pragma once

#include <algorithm>
#include <functional>
#include <map>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "cell/kinematics/robot_model.hpp"
#include "cell/task/job_spec.hpp"
#include "cell/world/part_class.hpp"
#include "links.hpp"
#include "task_config.hpp"

namespace cell::task_service {

/// One part's result, as JobStatus carries it (idl/task.idl PartResult). Poses in the robot's
/// base frame [mm, rad].
struct PartRecord {
  std::uint32_t index = 0;
  std::string class_name;
  double picked_x_mm = 0, picked_y_mm = 0, picked_yaw_rad = 0;
  double placed_x_mm = 0, placed_y_mm = 0, placed_yaw_rad = 0;
  cell_task_PartOutcome outcome = cell_task_PART_PENDING;
  std::string detail;
};

nlohmann::json to_json(const PartRecord& p);
PartRecord part_from_json(const nlohmann::json& j);

/// The parts and counters a job's journaled progress carries (`_parts`, `_counters`, as
/// JobRun::step writes them). Errors: kInvalidArgument naming what could not be read (a key of
/// the wrong type, say); `parts` and `counters` are then left as they were. Never throws.
Status read_progress(const nlohmann::json& progress,
                     std::vector<PartRecord>& parts,
                     std::map<std::string, std::uint32_t>& counters);

/// How an executor ended.
struct ExecResult {
  enum class Kind : std::uint8_t { kDone, kFailed, kCancelled, kStopped };
  Kind kind = Kind::kDone;
  std::string reason;
  static ExecResult done() { return {}; }
  static ExecResult failed(std::string why) { return {Kind::kFailed, std::move(why)}; }
  static ExecResult cancelled() { return {Kind::kCancelled, "cancelled"}; }
  static ExecResult stopped() { return {Kind::kStopped, "the task service stopped"}; }
};

/// What the service gives the executor of one job: the parsed job, the cell links of its
/// worker, its control flags, and the means to report and journal. The executor keeps its
/// resumable state in progress() (JSON), which step() journals together with the parts and
/// counters: after a restart the executor gets back exactly what its last step journaled.
class JobRun {
 public:
  struct Hooks {
    /// Journals a completed step (state "running"): name, detail, the whole progress JSON.
    std::function<Status(const std::string& name, const nlohmann::json& detail,
                         const nlohmann::json& progress)>
        journal;
    /// Publishes the job's status now (step text, fraction done, parts, counters, paused).
    std::function<void(const JobRun&)> publish;
  };

  JobRun(std::string job_id, const task::JobSpec& spec, const kinematics::RobotModel& robot,
         const TaskConfig& config, const world::Catalogue& catalogue, Links& links,
         Control& control, nlohmann::json progress, Hooks hooks);

  const std::string& job_id() const noexcept { return job_id_; }
  const task::JobSpec& spec() const noexcept { return spec_; }
  const kinematics::RobotModel& robot() const noexcept { return robot_; }
  const TaskConfig& config() const noexcept { return config_; }
  const world::Catalogue& catalogue() const noexcept { return catalogue_; }
  Links& links() noexcept { return links_; }
  const Control& control() const noexcept { return control_; }

  /// The executor's resumable state ("{}" for a new job).
  nlohmann::json& progress() noexcept { return progress_; }

  /// Journals a completed step and publishes the status. Errors: the journal's (the executor
  /// must stop: what it did could not be made durable).
  Status step(const std::string& name, const nlohmann::json& detail = nlohmann::json::object());

  /// Publishes a status without journaling (progress within a step).
  void report(const std::string& step_text, double fraction);
  /// The job's done fraction [0, 1] for the statuses that follow (not published by itself).
  void set_fraction(double fraction) noexcept { fraction_ = std::clamp(fraction, 0.0, 1.0); }

  /// Parts and counters (journaled with the next step).
  std::vector<PartRecord>& parts() noexcept { return parts_; }
  const std::vector<PartRecord>& parts() const noexcept { return parts_; }
  void count(const std::string& name, std::uint32_t by = 1) { counters_[name] += by; }
  const std::map<std::string, std::uint32_t>& counters() const noexcept { return counters_; }

  const std::string& step_text() const noexcept { return step_text_; }
  double fraction() const noexcept { return fraction_; }
  bool paused() const noexcept { return paused_; }
  const std::string& pause_reason() const noexcept { return pause_reason_; }

  /// Blocks while the job is paused by an operator (returns at once otherwise). Returns the
  /// interrupt that ended the wait, if any.
  Interrupt hold_if_paused();

  /// The robot faulted (or was stopped) during a step: the job pauses with the reason until
  /// the robot is reset (its mode leaves FAULT/STOPPED), then continues. Returns an interrupt
  /// when cancelled or stopped meanwhile.
  Interrupt pause_for_robot(const std::string& reason);

  /// Service ids a motion of this job needs: the robot's gateway and the motion service.
  std::vector<std::string> motion_peers() const;
  /// Service ids locating with `camera_id` needs: the camera's service and the vision service.
  std::vector<std::string> locate_peers(const std::string& camera_id) const;

  /// Blocks while any of `ids` has no live heartbeat (lost, or absent from the bus): the job
  /// is PAUSED meanwhile with a step text naming them ("waiting for motion: no heartbeat"),
  /// and resumes by itself when they are back. Returns the interrupt that ended it, if any.
  Interrupt wait_for_peers(const std::vector<std::string>& ids);

  /// True when any of `ids` was lost, vanished or restarted since `generations` were taken
  /// (Peers::generations), or is missing now.
  bool peers_changed(const std::vector<std::string>& ids,
                     const std::vector<std::uint64_t>& generations);

  /// Sleeps `seconds`, interruptible.
  Interrupt sleep(double seconds);

  /// A motion id unique to this job and deterministic across restarts: "<job>/<tag>".
  std::string motion_id(const std::string& tag) const { return job_id_ + "/" + tag; }

  /// Runs one motion with the job's control and timeout; robot faults pause the job (the
  /// outcome says robot_fault, the executor redoes its step); progress is reported. It first
  /// waits for the motion service and the gateway (wait_for_peers). When either is lost or
  /// restarted while the motion runs, the wait ends at once (not after the motion timeout):
  /// the job waits for them and for the robot to rest, asks the motion service for the
  /// motion's last status, and returns it when it says done; otherwise the outcome is marked
  /// `unseen` (and robot_fault when the robot is stopped or faulted) and the executor verifies
  /// what the robot did before it redoes its step. Never fails a job for a lost service.
  Result<MotionOutcome> move(cell_motion_MotionRequest& request, const std::string& step_text);

  /// Before the job's first motion (and after a fault): waits for the robot to rest (a motion
  /// sent before a restart may still run), pauses while it is in a fault or stopped, and homes
  /// it if it is not homed (the thesis's first menu entry, done by the job). nullopt: ready.
  std::optional<ExecResult> ready_robot();

 private:
  /// After a motion whose outcome was not seen: waits for the services and the robot's rest,
  /// then re-checks the motion's status (motion status is transient-local).
  MotionOutcome recover_unseen(const std::string& motion_id, const std::string& why);
  std::string gateway_id_;
  std::string job_id_;
  const task::JobSpec& spec_;
  const kinematics::RobotModel& robot_;
  const TaskConfig& config_;
  const world::Catalogue& catalogue_;
  Links& links_;
  Control& control_;
  nlohmann::json progress_;
  Hooks hooks_;
  std::vector<PartRecord> parts_;
  std::map<std::string, std::uint32_t> counters_;
  std::string step_text_ = "starting";
  double fraction_ = 0.0;
  bool paused_ = false;
  std::string pause_reason_;
};

/// The non-empty lines of `text`.
std::vector<std::string> split_lines(const std::string& text);

/// A motion tag unique across restarts: "<what><seq>-<24 random bits>" (a restarted job's
/// motions never reuse the id of one its predecessor sent).
std::string fresh_tag(const char* what, int seq);

/// Cancel and stop as the executor's result; nullopt for none.
std::optional<ExecResult> interrupted_result(Interrupt i);

/// The executors (table_job.cpp, conveyor_job.cpp, assembly_job.cpp).
ExecResult run_table_job(JobRun& run);
ExecResult run_conveyor_job(JobRun& run);
ExecResult run_assembly_job(JobRun& run);

/// Checks an assembly job before it is accepted (assembly_job.cpp): the program compiles, its
/// agent is an AGENT that every MOVE carries, every LOOK's camera is an immovable camera
/// mapped to a cell camera, and the agent's nominal tool pose in every situation is inside
/// the robot's limits. Every reason, one per line (kInvalidArgument).
Status check_assembly(const task::AssemblySpec& spec, const kinematics::RobotModel& robot);

}  // namespace cell::task_service
