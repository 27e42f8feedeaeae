#pragma once

#include <functional>
#include <string>
#include <utility>
#include <vector>

#include <CLI/CLI.hpp>

#include "session.hpp"

/// cellctl's command groups. To add one (say `kin`):
///   1. write src/kin_commands.cpp with `void add_kin_commands(CLI::App& app, Commands& commands)`
///      that adds the CLI11 subcommands (options bound to state the action captures) and binds
///      each leaf to its action with commands.add();
///   2. declare it below and append it to kCommandGroups in session.cpp;
///   3. add the file to cell_cellctl_lib in CMakeLists.txt and test it in tests/.
namespace cell::cellctl {

/// What a command does once the command line is parsed and the bus resolved: prints through
/// the session and returns the exit code. May throw bus::BusError (reported by run()).
using Action = std::function<int(Session&)>;

/// The actions of the CLI11 tree: which parsed subcommand runs what. Not thread-safe.
class Commands {
 public:
  /// Binds `action` to `subcommand`, a leaf of the tree built on the cellctl app.
  void add(const CLI::App* subcommand, Action action);

  /// The action of the deepest parsed subcommand under `app`, or nullptr when none has one.
  const Action* chosen(const CLI::App& app) const;

 private:
  std::vector<std::pair<const CLI::App*, Action>> actions_;
};

/// Registers one command group on the cellctl app.
using Registrar = void (*)(CLI::App& app, Commands& commands);

/// `cellctl ping [--rtt]`: every live service from its heartbeat (and the ping round trip).
void add_ping_commands(CLI::App& app, Commands& commands);

/// `cellctl kin fk|ik --robot <id> ...`: kinematics from config/robots/<id>.yaml (no bus).
void add_kin_commands(CLI::App& app, Commands& commands);

/// `cellctl move joints|pose|line|approach|depart|pick|place|track|stop|alter-off ...`.
void add_move_commands(CLI::App& app, Commands& commands);

/// `cellctl robot home|open|close|stop|reset|lights|state --robot <id>`.
void add_robot_commands(CLI::App& app, Commands& commands);

/// `cellctl rapt check|compile|run FILE`: the RAPT compiler and run time (core/rapt, no bus).
void add_rapt_commands(CLI::App& app, Commands& commands);

/// `cellctl world parts|reset|spawn|remove|belt|scatter ...`: the simulated world (sim-world).
void add_world_commands(CLI::App& app, Commands& commands);

/// `cellctl submit|jobs|job|cancel|pause|resume|watch`: jobs of the task service.
void add_job_commands(CLI::App& app, Commands& commands);

/// `cellctl camera grab --camera <id> -o frame.png [--truth truth.json] [--trigger now|photocell]`.
void add_camera_commands(CLI::App& app, Commands& commands);

/// `cellctl locate IMAGE [--calibration FILE] [--joints ...] [--pipeline thesis|fast]`: the
/// parts core/vision finds in an image file (no bus).
void add_locate_commands(CLI::App& app, Commands& commands);

/// `cellctl task record|play|show|delete|move|rename FILE ...`: task files (core/teach).
void add_task_commands(CLI::App& app, Commands& commands);

/// `cellctl completion bash`: a bash completion script generated from the CLI11 tree.
void add_completion_commands(CLI::App& app, Commands& commands);

/// The bash completion script of the tree under `app` (completion_commands.cpp).
std::string bash_completion(const CLI::App& app);

/// `cellctl calibrate intrinsics|hand-eye|belt|planar ...` and `cellctl calibration
/// list|show|rollback|cancel`: procedures and the store of cell-calibration.
void add_calibrate_commands(CLI::App& app, Commands& commands);

}  // namespace cell::cellctl
