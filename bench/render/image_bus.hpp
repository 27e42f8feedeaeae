#pragma once

#include <cstdint>
#include <string>

/// Does a 1024 x 1024 mono8 image (1 MiB) cross the bus? One process publishes Images on
/// cell/vision/image (topic QoS, or RELIABLE for comparison) at a rate, another takes them and
/// counts what arrived and how late (bench/README.md, render section).
namespace cell::bench {

struct ImageBusOptions {
  int count = 100;               ///< images published
  double rate_hz = 10.0;
  int width = 1024;
  int height = 1024;
  bool reliable = false;         ///< RELIABLE KEEP_LAST 2 instead of the topic's best-effort
  std::uint32_t domain = 0;
  std::string partition;
  std::string self_exe;          ///< to spawn the publisher
};

struct ImageBusResult {
  int sent = 0;
  int received = 0;
  double latency_p50_ms = 0.0;
  double latency_p99_ms = 0.0;
  double latency_max_ms = 0.0;
  std::string error;  ///< non-empty when the run broke (no match, the publisher failed)
};

/// Runs the measurement (this process subscribes; a child publishes).
ImageBusResult run_image_bus(const ImageBusOptions& options);

/// The publisher's side (`render_bench --role image-pub ...`); returns the exit code.
int image_publisher(const ImageBusOptions& options);

}  // namespace cell::bench
