#pragma once

#include <sched.h>

#include <cstdint>
#include <string_view>
#include <type_traits>
#include <utility>
#include <vector>

#include "cell/common/result.hpp"

/// CPU placement of the two processes of a round-trip measurement. On a small VM the round
/// trip depends mostly on whether the two sides share a CPU (a wake-up on the same CPU is a
/// context switch; across CPUs it is an inter-processor interrupt, which costs a VM exit),
/// and an unpinned run flips between the two as the scheduler moves threads. Pinning both the
/// cell and ddsperf runs the same way makes them comparable. See bench/README.md.
namespace cell::bench {

/// Where the ping and pong processes run.
enum class Placement : std::uint8_t {
  kNone,   ///< wherever the scheduler puts them
  kSame,   ///< both processes, all their threads, on one CPU
  kSplit,  ///< ping process on one CPU, pong process on another
};

/// "none", "same", "split".
std::string_view to_string(Placement placement) noexcept;

/// Parses "none" / "same" / "split". Errors: kInvalidArgument naming the text.
Result<Placement> parse_placement(std::string_view text);

/// CPUs chosen for the ping and pong sides; -1 means not pinned.
struct CpuPlan {
  int ping_cpu = -1;
  int pong_cpu = -1;
};

/// Picks CPUs from `allowed` (ascending CPU numbers): kSame uses the last allowed CPU for both,
/// kSplit the first for ping and the last for pong. Errors: kInvalidArgument when kSplit
/// has fewer than two CPUs or `allowed` is empty.
Result<CpuPlan> plan_cpus(Placement placement, const std::vector<int>& allowed);

/// The CPUs the calling thread may run on (ascending).
std::vector<int> allowed_cpus();

/// Restricts the calling thread to `cpu`, or, with -1, to `restore` (a set saved earlier by
/// save_affinity()). Threads this thread creates afterwards (Cyclone creates its threads with
/// the first participant of a domain) and processes it forks inherit the mask.
/// Errors: kInvalidArgument when the kernel refuses (cpu not allowed).
Status pin_thread(int cpu, const cpu_set_t& restore);

/// The calling thread's current mask, for pin_thread(-1, saved).
cpu_set_t save_affinity();

/// Calls fn() (which returns a Result) with the calling thread pinned to `cpu` so that what
/// fn starts (a child process) inherits that CPU, then restores the thread's mask. With
/// cpu < 0 just calls fn(). A failure to pin is returned as fn's error type.
template <typename Fn>
std::invoke_result_t<Fn> on_cpu(int cpu, Fn&& fn) {
  if (cpu < 0) {
    return fn();
  }
  const cpu_set_t saved = save_affinity();
  if (auto pinned = pin_thread(cpu, saved); !pinned) {
    return std::move(pinned).error();
  }
  auto result = fn();
  (void)pin_thread(-1, saved);
  return result;
}

}  // namespace cell::bench
