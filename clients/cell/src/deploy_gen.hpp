#pragma once

#include <string>
#include <utility>
#include <vector>

#include "profile.hpp"

/// What a multi-host profile generates for one of its hosts: the Cyclone DDS configuration
/// every service of that host joins with, and systemd units that run its services without the
/// `cell up` supervisor (deploy/README.md, "Several PCs").
namespace cell::launcher {

struct LaunchPlan;

/// The Cyclone DDS 0.10 configuration of `host` (a key of profile.hosts):
/// - the one interface with the host's address (a multi-homed PC never picks the wrong one);
/// - multicast off unless bus.multicast, and a unicast peer list of every host's address (SPDP
///   reaches each PC's participant ports directly: no multicast needed on the cell network);
/// - a socket receive buffer of bus.receive_buffer_mib (asked for up to; the kernel's
///   net.core.rmem_max caps it), 64 kB datagrams;
/// - unless bus.images_across_hosts, on a host without a camera service the raw image topic
///   (cell/vision/image in the profile's partition) is ignored (Partitioning/IgnoredPartitions):
///   its readers there are never matched, so no image leaves the camera's PC for it.
std::string host_dds_config(const Profile& profile, const std::string& host);

/// One generated file: its name and content.
struct GeneratedFile {
  std::string name;
  std::string text;
};

/// systemd units for `plan` (a plan for one host): `cell-<service>.service` per service
/// (ExecStart, environment and working directory exactly as `cell up` would run it,
/// Restart=always with the profile's initial back-off, no restart after exit 2 (configuration
/// error), stop by SIGTERM with the profile's grace, resource limits) and `cell-<host>.target`
/// that pulls them all in (`systemctl start cell-<host>.target`).
std::vector<GeneratedFile> systemd_units(const LaunchPlan& plan);

}  // namespace cell::launcher
