#include "cell/dpr7545/sim_control.hpp"

#include <atomic>

#include <fmt/format.h>

#include "cell/common/check.hpp"

namespace cell::dpr7545 {
namespace {

constexpr std::size_t kMagic = 0x00;
constexpr std::size_t kOwner = 0x04;
constexpr std::size_t kRequestSeq = 0x08;
constexpr std::size_t kAckSeq = 0x0C;
constexpr std::size_t kKind = 0x10;
constexpr std::size_t kJoint = 0x14;
constexpr std::size_t kValue = 0x18;
constexpr std::size_t kResult = 0x1C;
constexpr std::size_t kSampleTime = 0x20;  // 8 bytes, 8-aligned (the window is page-aligned)
constexpr std::size_t kBoardTime = 0x28;   // 8 bytes
constexpr std::size_t kGrace = 0x30;       // 4 bytes
constexpr std::size_t kAlive = 0x38;       // 8 bytes

struct Name {
  SimFault fault;
  std::string_view name;
};
constexpr Name kNames[] = {
    {SimFault::kDeadlineMiss, "deadline-miss"}, {SimFault::kLoopLate, "loop-late"},
    {SimFault::kEncoderGlitch, "encoder-glitch"}, {SimFault::kOverrun, "overrun"},
    {SimFault::kClear, "clear"},
};

}  // namespace

std::string_view to_string(SimFault fault) noexcept {
  for (const auto& n : kNames) {
    if (n.fault == fault) {
      return n.name;
    }
  }
  return "none";
}

Result<SimFault> parse_sim_fault(std::string_view name) {
  std::string known;
  for (const auto& n : kNames) {
    if (n.name == name) {
      return n.fault;
    }
    known += fmt::format("{}{}", known.empty() ? "" : ", ", n.name);
  }
  return Error{Errc::kInvalidArgument,
               fmt::format("unknown fault '{}' (known: {})", name, known)};
}

SimControl::SimControl(std::span<std::byte> window) : base_(window.data() + kSimControlOffset) {
  CELL_CHECK(window.size() >= kWindowSize);
  CELL_CHECK(reinterpret_cast<std::uintptr_t>(window.data()) % alignof(std::int64_t) == 0);
}

std::uint32_t SimControl::load(std::size_t field) const noexcept {
  return std::atomic_ref<std::uint32_t>(*reinterpret_cast<std::uint32_t*>(base_ + field))
      .load(std::memory_order_acquire);
}

void SimControl::store(std::size_t field, std::uint32_t value) const noexcept {
  std::atomic_ref<std::uint32_t>(*reinterpret_cast<std::uint32_t*>(base_ + field))
      .store(value, std::memory_order_release);
}

std::int64_t SimControl::load64(std::size_t field) const noexcept {
  return std::atomic_ref<std::int64_t>(*reinterpret_cast<std::int64_t*>(base_ + field))
      .load(std::memory_order_acquire);
}

void SimControl::store64(std::size_t field, std::int64_t value) const noexcept {
  std::atomic_ref<std::int64_t>(*reinterpret_cast<std::int64_t*>(base_ + field))
      .store(value, std::memory_order_release);
}

void SimControl::set_sample_time_ns(std::int64_t t) const noexcept { store64(kSampleTime, t); }

std::int64_t SimControl::sample_time_ns() const noexcept { return load64(kSampleTime); }

void SimControl::set_board_time_ns(std::int64_t t) const noexcept { store64(kBoardTime, t); }

std::int64_t SimControl::board_time_ns() const noexcept { return load64(kBoardTime); }

void SimControl::set_grace_us(std::uint32_t us) const noexcept { store(kGrace, us); }

std::uint32_t SimControl::grace_us() const noexcept { return load(kGrace); }

void SimControl::set_alive_ns(std::int64_t t) const noexcept { store64(kAlive, t); }

std::int64_t SimControl::alive_ns() const noexcept { return load64(kAlive); }

void SimControl::initialise(std::uint32_t owner_pid) const noexcept {
  store(kOwner, owner_pid);
  store(kMagic, kSimControlMagic);
}

bool SimControl::valid() const noexcept { return load(kMagic) == kSimControlMagic; }

std::uint32_t SimControl::owner_pid() const noexcept { return load(kOwner); }

std::uint32_t SimControl::post(SimFault fault, int joint, std::int32_t value) const noexcept {
  store(kKind, static_cast<std::uint32_t>(fault));
  store(kJoint, static_cast<std::uint32_t>(joint));
  store(kValue, static_cast<std::uint32_t>(value));
  const std::uint32_t sequence = load(kRequestSeq) + 1;
  store(kRequestSeq, sequence);  // release: kind, joint and value before it
  return sequence;
}

std::optional<std::uint32_t> SimControl::result(std::uint32_t sequence) const noexcept {
  if (load(kAckSeq) != sequence) {
    return std::nullopt;
  }
  return load(kResult);
}

std::optional<SimRequest> SimControl::pending() const noexcept {
  const std::uint32_t sequence = load(kRequestSeq);  // acquire: the fields written before it
  if (sequence == load(kAckSeq)) {
    return std::nullopt;
  }
  SimRequest r;
  r.fault = static_cast<SimFault>(load(kKind));
  r.joint = static_cast<int>(load(kJoint));
  r.value = static_cast<std::int32_t>(load(kValue));
  r.sequence = sequence;
  return r;
}

void SimControl::acknowledge(const SimRequest& request, std::uint32_t result) const noexcept {
  store(kResult, result);
  store(kAckSeq, request.sequence);
}

}  // namespace cell::dpr7545
