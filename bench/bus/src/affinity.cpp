#include "affinity.hpp"

#include <cerrno>
#include <cstring>

#include <fmt/format.h>

namespace cell::bench {

std::string_view to_string(Placement placement) noexcept {
  switch (placement) {
    case Placement::kNone:
      return "none";
    case Placement::kSame:
      return "same";
    case Placement::kSplit:
      return "split";
  }
  return "none";
}

Result<Placement> parse_placement(std::string_view text) {
  for (const Placement p : {Placement::kNone, Placement::kSame, Placement::kSplit}) {
    if (text == to_string(p)) {
      return p;
    }
  }
  return Error{Errc::kInvalidArgument,
               fmt::format("unknown placement '{}' (expected none, same or split)", text)};
}

Result<CpuPlan> plan_cpus(Placement placement, const std::vector<int>& allowed) {
  if (placement == Placement::kNone) {
    return CpuPlan{};
  }
  if (allowed.empty()) {
    return Error{Errc::kInvalidArgument, "no CPU allowed for this process"};
  }
  if (placement == Placement::kSame) {
    return CpuPlan{allowed.back(), allowed.back()};
  }
  if (allowed.size() < 2) {
    return Error{
        Errc::kInvalidArgument,
        fmt::format("placement 'split' needs two CPUs, this process may use {}", allowed.size())};
  }
  return CpuPlan{allowed.front(), allowed.back()};
}

cpu_set_t save_affinity() {
  cpu_set_t set;
  CPU_ZERO(&set);
  if (sched_getaffinity(0, sizeof set, &set) != 0) {
    for (int cpu = 0; cpu < CPU_SETSIZE; ++cpu) {
      CPU_SET(cpu, &set);
    }
  }
  return set;
}

std::vector<int> allowed_cpus() {
  const cpu_set_t set = save_affinity();
  std::vector<int> cpus;
  for (int cpu = 0; cpu < CPU_SETSIZE; ++cpu) {
    if (CPU_ISSET(cpu, &set)) {
      cpus.push_back(cpu);
    }
  }
  return cpus;
}

Status pin_thread(int cpu, const cpu_set_t& restore) {
  cpu_set_t set = restore;
  if (cpu >= 0) {
    if (cpu >= CPU_SETSIZE) {
      return Error{Errc::kInvalidArgument, fmt::format("CPU {} out of range", cpu)};
    }
    CPU_ZERO(&set);
    CPU_SET(cpu, &set);
  }
  if (sched_setaffinity(0, sizeof set, &set) != 0) {
    return Error{Errc::kInvalidArgument,
                 fmt::format("sched_setaffinity to CPU {}: {}", cpu, std::strerror(errno))};
  }
  return ok_status();
}

}  // namespace cell::bench
