#include "sim_world_service.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <exception>
#include <stdexcept>

#include "cell/bus/view.hpp"
#include "cell/common/log.hpp"
#include "cell/common/time.hpp"

namespace cell::sim_world {
namespace {

constexpr dds_attach_t kStop = 1;
constexpr dds_attach_t kRobotState = 2;
constexpr dds_attach_t kRequest = 3;
/// Behind by more than this many steps (100 ms at 1 kHz): the rest of the backlog in coarse
/// steps of at most kCoarseStepS each, so that a stalled process costs few steps.
constexpr int kMaxCatchUpSteps = 100;
/// A coarse catch-up step (belt travel and photocell edges are exact within any step; a
/// carried part follows the robot state that stands for the whole step).
constexpr double kCoarseStepS = 0.02;
/// A scatter runs inside the loop: keep one request well under a second (bench/world: 1000
/// parts in ~6 ms).
constexpr std::uint32_t kMaxScatterCount = 10000;

using SteadyClock = std::chrono::steady_clock;

world::World load_world(const SimWorldConfig& config, const world::Catalogue& catalogue) {
  auto scene = world::load_scene_file(config.scene, catalogue);
  if (!scene) {
    throw std::runtime_error(scene.error().message);
  }
  auto built = world::World::create(*scene, catalogue, config.world);
  if (!built) {
    throw std::runtime_error(built.error().message);
  }
  return std::move(built).value();
}

std::string fmt_mm(double v) { return fmt::format("{:.2f}", v); }

}  // namespace

std::string_view to_string(cell_world_WorldRequestKind kind) noexcept {
  switch (kind) {
    case cell_world_WORLD_QUERY:
      return "query";
    case cell_world_WORLD_RESET:
      return "reset";
    case cell_world_WORLD_SPAWN:
      return "spawn";
    case cell_world_WORLD_REMOVE:
      return "remove";
    case cell_world_WORLD_SET_BELT:
      return "set_belt";
    case cell_world_WORLD_SCATTER:
      return "scatter";
  }
  return "unknown";
}

SimWorldService::SimWorldService(service::Context& ctx, const SimWorldConfig& config)
    : ctx_(ctx),
      config_(config),
      catalogue_(world::Catalogue::standard()),
      world_(load_world(config_, catalogue_)),
      robot_state_topic_(ctx.participant(), bus::topics::kRobotState),
      request_topic_(ctx.participant(), bus::topics::kWorldRequest),
      reply_topic_(ctx.participant(), bus::topics::kWorldReply),
      state_topic_(ctx.participant(), bus::topics::kWorldState),
      belt_topic_(ctx.participant(), bus::topics::kBeltState),
      photocell_topic_(ctx.participant(), bus::topics::kPhotocell),
      robot_state_reader_(ctx.participant(), robot_state_topic_, bus::topics::kRobotState),
      request_reader_(ctx.participant(), request_topic_, bus::topics::kWorldRequest),
      reply_writer_(ctx.participant(), reply_topic_, bus::topics::kWorldReply),
      state_writer_(ctx.participant(), state_topic_, bus::topics::kWorldState),
      belt_writer_(ctx.participant(), belt_topic_, bus::topics::kBeltState),
      photocell_writer_(ctx.participant(), photocell_topic_, bus::topics::kPhotocell) {
  events_.reserve(64);
  log::info("scene", "world loaded",
            {{"scene", world_.scene_name()},
             {"file", config_.scene},
             {"parts", std::to_string(world_.parts().size())},
             {"belts", std::to_string(world_.belts().size())}});
}

void SimWorldService::take_robot_states() {
  (void)robot_state_reader_.take_each([&](const cell_robot_RobotState& s,
                                          const dds_sample_info_t&) {
    std::string_view robot_id = bus::str(s.robot_id);
    // A simulated controller's own state of its arm (`<robot>.sim`: the joints and the gripper
    // latch as they physically are) is the truth for <robot>; once it is seen, the gateway's
    // report of the same robot (what its master believes, e.g. a gripper state a restarted
    // gateway cannot know) no longer moves the world.
    constexpr std::string_view kTruthSuffix = ".sim";
    if (robot_id.size() > kTruthSuffix.size() && robot_id.ends_with(kTruthSuffix)) {
      robot_id.remove_suffix(kTruthSuffix.size());
      if (truth_robots_.find(robot_id) == truth_robots_.end()) {
        truth_robots_.emplace(robot_id);
        log::info("robot_state", "following the simulator's own state of the robot",
                  {{"robot", robot_id}, {"from", bus::str(s.robot_id)}});
      }
    } else if (truth_robots_.find(robot_id) != truth_robots_.end()) {
      return;
    }
    auto pose = world::pose_from_idl(s.base_T_tool);
    if (!pose) {
      log::warn("robot_state", pose.error().message, {{"robot", robot_id}});
      return;
    }
    double age_s = 0.0;
    if (world_wall_ns_ > 0 && s.header.stamp_ns > 0) {
      age_s = static_cast<double>(world_wall_ns_ - s.header.stamp_ns) * 1e-9;
      age_s = std::abs(age_s) <= kMaxStateAgeS ? age_s : 0.0;
    }
    auto status = world_.update_robot(robot_id, *pose, world::from_idl(s.gripper), events_, age_s);
    if (!status) {
      // A robot this world does not mount (another cell's, or a config gap): say so once.
      if (unknown_robots_.insert(std::string(robot_id)).second) {
        log::warn("robot_state", status.error().message, {{"robot", robot_id}});
      }
    }
  });
}

Status SimWorldService::reset(const cell_world_WorldRequest& request) {
  const std::string text(bus::str(request.scene_yaml));
  Result<world::Scene> scene = Error{Errc::kInvalidArgument, ""};
  if (text.empty()) {
    scene = world::load_scene_file(config_.scene, catalogue_);
  } else {
    const std::string origin(bus::str(request.scene_name).empty() ? "<request>"
                                                                  : bus::str(request.scene_name));
    scene = world::parse_scene(text, origin, catalogue_);
  }
  if (!scene) {
    return std::move(scene).error();
  }
  auto built = world::World::create(*scene, catalogue_, config_.world);
  if (!built) {
    return std::move(built).error();
  }
  seq_base_ += world_.seq() + 1;
  world_ = std::move(built).value();
  unknown_robots_.clear();
  log::info("reset", "new world",
            {{"scene", world_.scene_name()}, {"parts", std::to_string(world_.parts().size())}});
  return ok_status();
}

Result<std::vector<std::string>> SimWorldService::handle(const cell_world_WorldRequest& request) {
  switch (bus::raw(request.kind)) {  // any value may come off the wire
    case cell_world_WORLD_QUERY: {
      std::vector<std::string> ids;
      for (const auto& p : world_.parts()) {
        ids.push_back(p.id);
      }
      return ids;
    }
    case cell_world_WORLD_RESET: {
      CELL_TRY(reset(request));
      std::vector<std::string> ids;
      for (const auto& p : world_.parts()) {
        ids.push_back(p.id);
      }
      return ids;
    }
    case cell_world_WORLD_SPAWN: {
      const auto parts = bus::span(request.parts);
      if (parts.empty()) {
        return Error{Errc::kInvalidArgument, "spawn: no parts given"};
      }
      world::World trial = world_;  // all or nothing
      std::vector<std::string> ids;
      for (std::size_t i = 0; i < parts.size(); ++i) {
        auto placement = world::placement_from_idl(parts[i]);
        if (!placement) {
          return with_context(std::move(placement).error(), fmt::format("spawn: part {}", i));
        }
        auto id = trial.spawn(*placement, trial.min_separation_mm());
        if (!id) {
          return with_context(std::move(id).error(), fmt::format("spawn: part {}", i));
        }
        ids.push_back(*id);
      }
      world_ = std::move(trial);
      return ids;
    }
    case cell_world_WORLD_REMOVE: {
      const auto ids = bus::span(request.part_ids);
      if (ids.empty()) {
        return Error{Errc::kInvalidArgument, "remove: no part ids given"};
      }
      world::World trial = world_;  // all or nothing
      for (const char* id : ids) {
        CELL_TRY(trial.remove(bus::str(id)));
      }
      world_ = std::move(trial);
      return std::vector<std::string>{};
    }
    case cell_world_WORLD_SET_BELT: {
      CELL_TRY(world_.set_belt_speed(bus::str(request.belt_id), request.speed_mm_per_s));
      return std::vector<std::string>{};
    }
    case cell_world_WORLD_SCATTER: {
      world::ScatterSpec spec = world_.default_scatter();
      spec.count = request.count;
      spec.seed = request.seed;
      const auto classes = bus::span(request.classes);
      if (!classes.empty()) {
        spec.classes.clear();
        for (const char* c : classes) {
          spec.classes.emplace_back(bus::str(c));
        }
      }
      if (spec.count == 0 || spec.count > kMaxScatterCount) {
        return Error{Errc::kInvalidArgument, fmt::format("scatter: count must be 1..{}, got {}",
                                                         kMaxScatterCount, spec.count)};
      }
      return world_.scatter(spec);
    }
  }
  return Error{Errc::kInvalidArgument,
               fmt::format("unknown request kind {}", bus::raw(request.kind))};
}

void SimWorldService::answer(const cell_world_WorldRequest& request,
                             ReplyStorage& storage,
                             cell_world_WorldReply& reply) {
  const std::string kind(to_string(request.kind));
  const std::uint64_t seq_before = world_seq();
  Result<std::vector<std::string>> result = [&]() -> Result<std::vector<std::string>> {
    try {
      return handle(request);
    } catch (const std::exception& e) {  // nothing escapes into the loop
      return Error{Errc::kInvalidArgument, std::string("internal error: ") + e.what()};
    }
  }();
  reply = cell_world_WorldReply{};
  reply.request_id = request.request_id;
  if (!result) {
    storage.error_code = std::string(to_string(result.error().code));
    storage.reason = result.error().message;
    reply.status.accepted = false;
    log::warn("reject", storage.reason, {{"kind", kind}});
  } else {
    reply.status.accepted = true;
    for (const auto& id : *result) {
      if (const world::Part* part = world_.find(id)) {
        storage.parts.push_back(world::part_to_idl(*part, storage.wire));
      }
    }
    log::info("request", "answered",
              {{"kind", kind}, {"parts", std::to_string(storage.parts.size())}});
  }
  reply.status.error_code = bus::borrow(storage.error_code);
  reply.status.reason = bus::borrow(storage.reason);
  reply.world_seq = world_seq();
  bus::borrow(reply.parts, storage.parts);
  if (world_seq() != seq_before) {
    publish_world_state();  // clients see an edit at once, not at the next period
  }
}

void SimWorldService::take_requests() {
  auto requests = request_reader_.take_copies(16);
  if (!requests) {
    log::warn("request", requests.error().message);
    return;
  }
  for (auto& request : *requests) {
    ReplyStorage storage;
    cell_world_WorldReply reply{};
    answer(request.get(), storage, reply);
    if (auto s = reply_writer_.write(reply); !s) {
      log::warn("reply", s.error().message);
    }
  }
}

void SimWorldService::publish_events() {
  for (const auto& e : events_) {
    switch (e.kind) {
      case world::WorldEvent::Kind::kPhotocell: {
        cell_world_PhotocellEvent m{};
        const std::string frame = "world";
        m.belt_id = bus::borrow(e.belt_id);
        // The instant of the edge: the world time of its step, on the wall clock.
        m.header.stamp_ns = world_wall_ns_ - std::llround((world_.time_s() - e.time_s) * 1e9);
        m.header.frame_id = bus::borrow(frame);
        m.header.seq = ++photocell_seq_;
        m.blocked = e.blocked;
        m.encoder_count = e.encoder_count;
        m.part_id = bus::borrow(e.part_id);
        if (auto s = photocell_writer_.write(m); !s) {
          log::warn("photocell", s.error().message);
        }
        log::debug("photocell", e.detail);
        break;
      }
      case world::WorldEvent::Kind::kMissed:
        ctx_.events().publish(cell_health_SEVERITY_WARNING, "world.pick_missed", e.detail,
                              e.robot_id);
        break;
      case world::WorldEvent::Kind::kFellOffBelt:
        ctx_.events().publish(cell_health_SEVERITY_INFO, "world.fell_off_belt", e.detail);
        break;
      case world::WorldEvent::Kind::kAttached:
      case world::WorldEvent::Kind::kReleased:
        log::info(to_string(e.kind), e.detail, {{"part", e.part_id}, {"robot", e.robot_id}});
        break;
      case world::WorldEvent::Kind::kFed:
        if (e.part_id.empty()) {
          ctx_.events().publish(cell_health_SEVERITY_WARNING, "world.feeder_jammed", e.detail);
        } else {
          log::debug("feeder", e.detail, {{"part", e.part_id}, {"belt", e.belt_id}});
        }
        break;
    }
  }
  if (!events_.empty()) {
    const bool parts_changed = std::any_of(events_.begin(), events_.end(), [](const auto& e) {
      return e.kind != world::WorldEvent::Kind::kPhotocell &&
             e.kind != world::WorldEvent::Kind::kMissed;
    });
    events_.clear();
    if (parts_changed) {
      publish_world_state();
    }
  }
}

void SimWorldService::publish_world_state() {
  world::fill_world_state(world_, world_wall_ns_, ++state_seq_, state_wire_);
  state_wire_.message.world_seq = world_seq();
  if (auto s = state_writer_.write(state_wire_.message); !s) {
    log::warn("world_state", s.error().message);
  }
}

void SimWorldService::publish_belts() {
  if (world_.belts().empty()) {
    return;
  }
  world::fill_belts(world_, world_wall_ns_, ++belt_seq_, belt_wire_);
  for (const auto& b : belt_wire_.belts) {
    if (auto s = belt_writer_.write(b); !s) {
      log::warn("belt_state", s.error().message);
    }
  }
}

void SimWorldService::run(service::Context& ctx) {
  bus::WaitSet waitset(ctx.participant());
  waitset.attach(ctx.stop_guard().get(), kStop);
  waitset.attach(robot_state_reader_.condition(), kRobotState);
  waitset.attach(request_reader_.condition(), kRequest);
  ctx.health().set(cell_health_HEALTH_SERVING);
  const double dt_s = 1.0 / config_.step_hz;
  const auto period =
      std::chrono::duration_cast<SteadyClock::duration>(std::chrono::duration<double>(dt_s));
  const auto world_every =
      std::max<std::uint64_t>(1, std::llround(config_.step_hz / config_.world_state_hz));
  const auto belt_every =
      std::max<std::uint64_t>(1, std::llround(config_.step_hz / config_.belt_state_hz));
  std::uint64_t ticks = 0;
  auto next = SteadyClock::now();
  // Each step brings the world up to the instant `next` stood for; states, belt counts and
  // photocell edges carry that instant on the wall clock, not the (later, and in a catch-up
  // burst the same) instant they were computed: a count stamped 1 ms late is 2 mm of belt at
  // 2 m/s to whoever extrapolates it (the camera's latch, ALTER).
  const auto wall_of = [](SteadyClock::time_point steady) {
    return wall_time_ns() -
           std::chrono::duration_cast<std::chrono::nanoseconds>(SteadyClock::now() - steady)
               .count();
  };
  world_wall_ns_ = wall_of(next);
  publish_world_state();
  for (;;) {
    const bus::Fired fired = waitset.wait_until(next);
    if (fired.contains(kStop) || ctx.stopping()) {
      break;
    }
    // Robot states first, so the steps below see the grippers as they are now.
    take_robot_states();
    take_requests();
    const auto now = SteadyClock::now();
    int steps = 0;
    while (now >= next && steps < kMaxCatchUpSteps) {
      world_.step(dt_s, events_);
      world_wall_ns_ = wall_of(next);
      ++ticks;
      ++steps;
      next += period;
      if (ticks % belt_every == 0) {
        publish_belts();
      }
      if (ticks % world_every == 0) {
        publish_world_state();
      }
    }
    if (steps == kMaxCatchUpSteps && now >= next) {
      // The host stalled this loop (a loaded machine) by more than the fine steps make up. A
      // belt does not stop because its simulator did: dropping the backlog left the world's
      // parts behind the wall clock that every stamp, the camera's exposure and ALTER's
      // extrapolation go by (a part 40 mm short of where the photocell's edge put it, at
      // 100 mm/s after a 0.4 s stall). So the rest is simulated too, in coarse steps.
      const double behind_s = std::chrono::duration<double>(now - next).count() + dt_s;
      if (overruns_++ % 100 == 0) {
        log::warn("overrun", "world loop fell behind; catching up in coarse steps",
                  {{"behind_ms", fmt_mm(behind_s * 1e3)}, {"overruns", std::to_string(overruns_)}});
      }
      while (now >= next) {
        const auto periods =
            std::clamp<std::int64_t>(static_cast<std::int64_t>((now - next) / period) + 1, 1,
                                     std::max<std::int64_t>(1, std::llround(kCoarseStepS / dt_s)));
        world_.step(dt_s * static_cast<double>(periods), events_);
        next += period * periods;
        world_wall_ns_ = wall_of(next - period);
        ticks += static_cast<std::uint64_t>(periods);
      }
      publish_belts();
      publish_world_state();
    }
    publish_events();
    ctx.health().tick();
  }
}

}  // namespace cell::sim_world
