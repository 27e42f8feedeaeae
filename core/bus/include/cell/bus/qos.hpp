#pragma once

#include <cstdint>

#include "cell/bus/entity.hpp"

/// Named QoS profiles, defined in one place (STYLE.md §6). Every topic of the cell uses one.
namespace cell::bus::qos {

/// Latest value of something a late joiner needs (calibrations, job status, robot config):
/// RELIABLE + TRANSIENT_LOCAL + KEEP_LAST 1 per instance.
Qos state();

/// Periodic data where only fresh samples matter (images, 1 kHz robot state):
/// BEST_EFFORT + VOLATILE + KEEP_LAST depth.
Qos stream(std::int32_t depth = 8);

/// Reliable stream: periodic data that must not be lost on a healthy link (the 1 kHz
/// RobotState the monitor plots): RELIABLE + VOLATILE + KEEP_LAST depth.
Qos reliable_stream(std::int32_t depth = 64);

/// Requests and replies: RELIABLE + VOLATILE + KEEP_ALL. Nothing is dropped; a late joiner
/// does not see old commands (a restarted gateway must not replay a stale move).
Qos command();

/// Recent history: RELIABLE + TRANSIENT_LOCAL + KEEP_LAST depth. For replies (a reply written
/// just before the replier discovered the requester's reader still reaches it; requesters
/// filter by their own unique client id, so older replies are harmless) and for events (a
/// monitor started late sees the recent alarms).
Qos recent(std::int32_t depth = 32);

/// Service heartbeats: like state() plus LIVELINESS MANUAL_BY_TOPIC with `lease_s`, so a
/// reader sees the instance go NOT_ALIVE within the lease when a service dies or hangs.
Qos heartbeat(double lease_s = 3.0);

}  // namespace cell::bus::qos
