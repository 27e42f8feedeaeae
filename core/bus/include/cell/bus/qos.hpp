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

/// Requests: RELIABLE + KEEP_ALL + TRANSIENT_LOCAL with a LIFESPAN of `lifespan_s`. Nothing
/// is dropped, and a server whose reader matches a moment after the request was written (one
/// of several gateways still being discovered) still receives it; but a request older than
/// its lifespan expires, so a restarted gateway never replays a stale move. Requesters time out
/// no sooner than the lifespan, so an expired request has always been reported as failed.
Qos command(double lifespan_s = 2.0);

/// Recent history: RELIABLE + TRANSIENT_LOCAL + KEEP_LAST depth. For replies (a reply written
/// just before the replier discovered the requester's reader still reaches it; requesters
/// filter by their own unique client id, so older replies are harmless) and for events (a
/// monitor started late sees the recent alarms).
Qos recent(std::int32_t depth = 32);

/// Service heartbeats: like state() plus LIVELINESS MANUAL_BY_TOPIC with `lease_s`, so a
/// reader sees the instance go NOT_ALIVE within the lease when a service dies or hangs.
Qos heartbeat(double lease_s = 3.0);

}  // namespace cell::bus::qos
