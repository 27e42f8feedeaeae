#include "cell/dpr7545/dpr.hpp"

#include <bit>
#include <cstring>

#include "cell/common/check.hpp"

namespace cell::dpr7545 {

static_assert(std::atomic_ref<std::uint16_t>::is_always_lock_free,
              "DPR words must be lock-free (address-free) atomics");
static_assert(std::atomic_ref<std::uint8_t>::is_always_lock_free,
              "the lighting latch must be a lock-free atomic");

Dpr::Dpr(std::span<std::byte> window) : window_(window) {
  CELL_CHECK(window.size() >= kWindowSize);
  CELL_CHECK(reinterpret_cast<std::uintptr_t>(window.data()) % alignof(std::uint16_t) == 0);
}

std::uint16_t* Dpr::word(std::size_t offset) const noexcept {
  // The window is shared memory: we access it only through atomic_ref, never as plain objects.
  return reinterpret_cast<std::uint16_t*>(window_.data() + offset);
}

std::uint16_t Dpr::load(std::size_t offset) const noexcept {
  return std::atomic_ref<std::uint16_t>(*word(offset)).load(std::memory_order_acquire);
}

void Dpr::store(std::size_t offset, std::uint16_t value) const noexcept {
  std::atomic_ref<std::uint16_t>(*word(offset)).store(value, std::memory_order_release);
}

// A position's two words (low at the lower address) are one little-endian dword at a 4-byte
// aligned offset: when the window is 4-byte aligned too (the shared-memory window always is)
// the pair is read and written as one 32-bit atomic, so a simulated slave preempted between
// its two word stores never shows a torn pair. On the physical ISA card the bus still splits
// the access into two words, low first, as the slave writes them: position_consistent().
namespace {
std::uint32_t* dword_at(std::span<std::byte> window, std::size_t offset) noexcept {
  std::byte* p = window.data() + offset;
  return reinterpret_cast<std::uintptr_t>(p) % alignof(std::uint32_t) == 0
             ? reinterpret_cast<std::uint32_t*>(p)
             : nullptr;
}
static_assert(std::endian::native == std::endian::little,
              "a position dword is the low word at the lower address");
static_assert(std::atomic_ref<std::uint32_t>::is_always_lock_free);
}  // namespace

std::int32_t Dpr::position(int joint) const noexcept {
  const std::size_t at = position_offset(joint);
  if (std::uint32_t* d = dword_at(window_, at)) {
    return static_cast<std::int32_t>(
        std::atomic_ref<std::uint32_t>(*d).load(std::memory_order_acquire));
  }
  const std::uint32_t low = load(at);
  const std::uint32_t high = load(at + 2);
  return static_cast<std::int32_t>((high << 16) | low);
}

std::int32_t Dpr::position_consistent(int joint) const noexcept {
  // Two full reads (low, high) that agree: the slave writes low then high, so a read between
  // its two stores sees (new low, old high); a second read ~100 ns later sees the same only if
  // the slave is between the same two stores again, which its loop (microseconds per pass,
  // positions once per pass) never is.
  std::int32_t first = position(joint);
  for (int attempt = 0; attempt < 4; ++attempt) {
    const std::int32_t second = position(joint);
    if (second == first) {
      return second;
    }
    first = second;
  }
  return first;
}

void Dpr::set_position(int joint, std::int32_t counts) const noexcept {
  const auto value = static_cast<std::uint32_t>(counts);
  const std::size_t at = position_offset(joint);
  if (std::uint32_t* d = dword_at(window_, at)) {
    std::atomic_ref<std::uint32_t>(*d).store(value, std::memory_order_release);
    return;
  }
  store(at, static_cast<std::uint16_t>(value & 0xFFFFU));  // low word first, as the slave
  store(at + 2, static_cast<std::uint16_t>(value >> 16));
}

std::int16_t Dpr::velocity(int joint) const noexcept {
  return static_cast<std::int16_t>(load(velocity_offset(joint)));
}

void Dpr::set_velocity(int joint, std::int16_t counts_per_sample) const noexcept {
  store(velocity_offset(joint), static_cast<std::uint16_t>(counts_per_sample));
}

std::int16_t Dpr::acceleration(int joint) const noexcept {
  return static_cast<std::int16_t>(load(acceleration_offset(joint)));
}

void Dpr::set_acceleration(int joint, std::int16_t counts_per_sample2) const noexcept {
  store(acceleration_offset(joint), static_cast<std::uint16_t>(counts_per_sample2));
}

std::uint16_t Dpr::torque(int joint) const noexcept { return load(torque_offset(joint)); }

void Dpr::set_torque(int joint, std::uint16_t word) const noexcept {
  store(torque_offset(joint), word);
}

void Dpr::write_lighting(std::uint8_t latch) const noexcept {
  auto* p = reinterpret_cast<std::uint8_t*>(window_.data() + kLightingOffset);
  std::atomic_ref<std::uint8_t>(*p).store(latch, std::memory_order_release);
}

std::uint8_t Dpr::read_lighting() const noexcept {
  auto* p = reinterpret_cast<std::uint8_t*>(window_.data() + kLightingOffset);
  return std::atomic_ref<std::uint8_t>(*p).load(std::memory_order_acquire);
}

}  // namespace cell::dpr7545
