#pragma once

#include <chrono>
#include <cstdint>
#include <set>
#include <string>
#include <vector>

#include "cell/bus/reader.hpp"
#include "cell/bus/topic.hpp"
#include "cell/bus/writer.hpp"
#include "cell/service/runtime.hpp"
#include "cell/world/wire.hpp"
#include "cell/world/world.hpp"
#include "sim_world_config.hpp"

namespace cell::sim_world {

/// The world simulator: runs a core/world World at a fixed step (1 kHz by default), moves the
/// parts the robots' grippers take and release (from their RobotStates), and publishes the
/// ground truth. Every WorldRequest gets a WorldReply; a bad scene or edit is refused with the
/// reason and leaves the current world as it was.
///
/// Topics: in cell/robot/state (stream), cell/world/request (command); out cell/world/state
/// (stream, keep-last 1, world_state_hz), cell/world/belt (stream, belt_state_hz),
/// cell/world/photocell (command, one per beam edge), cell/world/reply (recent),
/// cell/health/event (missed picks, parts falling off a belt).
class SimWorldService {
 public:
  /// Loads the configured scene. Throws std::runtime_error when it cannot (main reports it,
  /// exit 1); bus::BusError when a reader or writer cannot be made (exit 3).
  SimWorldService(service::Context& ctx, const SimWorldConfig& config);
  void run(service::Context& ctx);

 private:
  /// Storage the reply's strings and sequences point into while it is written.
  struct ReplyStorage {
    std::string error_code;
    std::string reason;
    world::WorldStateWire wire;
    std::vector<cell_world_WorldPart> parts;
  };

  void take_robot_states();
  void take_requests();
  /// The boundary: never throws; every failure becomes a refused reply.
  void answer(const cell_world_WorldRequest& request,
              ReplyStorage& storage,
              cell_world_WorldReply& reply);
  Result<std::vector<std::string>> handle(const cell_world_WorldRequest& request);
  Status reset(const cell_world_WorldRequest& request);
  void step_once();
  void publish_events();
  void publish_world_state();
  void publish_belts();
  std::uint64_t world_seq() const noexcept { return seq_base_ + world_.seq(); }

  service::Context& ctx_;
  SimWorldConfig config_;
  world::Catalogue catalogue_;
  world::World world_;
  std::uint64_t seq_base_ = 0;  // world_seq keeps growing across resets
  std::vector<world::WorldEvent> events_;
  world::WorldStateWire state_wire_;
  world::WorldStateWire belt_wire_;
  std::uint64_t state_seq_ = 0;
  std::uint64_t belt_seq_ = 0;
  std::uint64_t photocell_seq_ = 0;
  std::set<std::string> unknown_robots_;  // warned about once each
  /// Robots whose simulator publishes their physical state as `<robot>.sim` (cell-sim-7545's
  /// state_robot_id): the world follows that, not the gateway's report of it.
  std::set<std::string, std::less<>> truth_robots_;
  std::uint64_t overruns_ = 0;
  /// The wall-clock instant world_.time_s() stands for (its last step's), so that a robot
  /// state (stamped when its joints were read) is compared with the parts at its instant; the
  /// stamp of every state, belt reading and photocell edge published.
  std::int64_t world_wall_ns_ = 0;
  /// A robot state older or newer than this is taken as of now (another clock, a bad stamp).
  static constexpr double kMaxStateAgeS = 0.1;

  bus::Topic<cell_robot_RobotState> robot_state_topic_;
  bus::Topic<cell_world_WorldRequest> request_topic_;
  bus::Topic<cell_world_WorldReply> reply_topic_;
  bus::Topic<cell_world_WorldState> state_topic_;
  bus::Topic<cell_world_BeltState> belt_topic_;
  bus::Topic<cell_world_PhotocellEvent> photocell_topic_;
  bus::Reader<cell_robot_RobotState> robot_state_reader_;
  bus::Reader<cell_world_WorldRequest> request_reader_;
  bus::Writer<cell_world_WorldReply> reply_writer_;
  bus::Writer<cell_world_WorldState> state_writer_;
  bus::Writer<cell_world_BeltState> belt_writer_;
  bus::Writer<cell_world_PhotocellEvent> photocell_writer_;
};

/// "query", "reset", "spawn", "remove", "set_belt", "scatter".
std::string_view to_string(cell_world_WorldRequestKind kind) noexcept;

}  // namespace cell::sim_world
