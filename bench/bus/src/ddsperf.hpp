#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "cell/common/result.hpp"
#include "stats.hpp"

/// Running Cyclone's own latency tool, `ddsperf` (Debian package cyclonedds-tools), as the
/// reference the cell's bus wrapper is compared with, and reading its output.
namespace cell::bench {

/// One per-second latency line of `ddsperf ping`, e.g.
///   [8328] 2.000  vm:8327 size 16 mean 39.510us min 5.665us 50% 36.237us 90% 55.662us
///   99% 127.603us max 1523.776us cnt 12597
/// ddsperf prints HALF the round trip ((t_receive_pong - t_send_ping) / 2, ddsperf.c
/// process_pong), so these values are one-way estimates, in microseconds. Its percentiles cover
/// the first 20000 round trips of the interval.
struct DdsperfLine {
  double t_s = 0.0;              ///< seconds since the ddsperf process started
  std::uint32_t size_bytes = 0;  ///< payload size of the KS topic (12 + sequence length)
  double mean_us = 0.0;
  double min_us = 0.0;
  double p50_us = 0.0;
  double p90_us = 0.0;
  double p99_us = 0.0;
  double max_us = 0.0;
  std::uint64_t count = 0;  ///< round trips completed in the interval
};

/// Parses one latency line. Errors: kInvalidArgument quoting the line when it is not one.
Result<DdsperfLine> parse_ddsperf_line(std::string_view line);

/// Every latency line of a ddsperf output; other lines (rss, participants) are skipped.
std::vector<DdsperfLine> parse_ddsperf_output(std::string_view output);

/// Number of "participant ...: new" lines in a ddsperf output (itself included). A ping run
/// that sees more than 2 shares the domain with another ddsperf, and every ping then waits for
/// all pongs: its numbers are not comparable.
std::size_t ddsperf_participants(std::string_view output);

/// Round-trip statistics from ddsperf's per-second half-round-trip lines, doubled:
/// min and max exact, mean exact (count-weighted), p50/p90/p99 the count-weighted average of
/// the per-interval percentiles (ddsperf keeps no raw samples across intervals).
/// Errors: kInvalidArgument when `lines` is empty or counts nothing.
Result<Summary> round_trip_from_ddsperf(const std::vector<DdsperfLine>& lines);

/// How to run one ddsperf ping/pong pair.
struct DdsperfOptions {
  std::string executable = "ddsperf";  ///< path or name looked up in PATH
  std::uint32_t domain_id = 0;         ///< private domain (ddsperf ignores partitions)
  std::uint32_t size_bytes = 16;       ///< "size S" of the KS topic
  double duration_s = 5.0;             ///< ping's -D; the first ~1 s is discovery
  int ping_cpu = -1;                   ///< CPU of the ping process; -1: not pinned
  int pong_cpu = -1;                   ///< CPU of the pong process; -1: not pinned
};

/// Result of one ddsperf run.
struct DdsperfRun {
  std::vector<DdsperfLine> lines;  ///< the ping side's latency lines
  std::size_t participants = 0;    ///< ddsperf participants the ping saw (2 when alone)
  std::string ping_output;         ///< everything the ping printed
};

/// Starts `ddsperf -i D pong waitset`, then `ddsperf -i D -D secs ping size S waitset`, waits
/// for the ping to finish, stops the pong. Both inherit this process's environment
/// (CYCLONEDDS_URI). Errors: kIo when ddsperf cannot be started, kProtocol when the ping
/// fails or prints no latency line (the message carries its output), kTimeout when it hangs.
Result<DdsperfRun> run_ddsperf(const DdsperfOptions& options);

}  // namespace cell::bench
