#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <string_view>

#include "cell/common/result.hpp"
#include "cell/dpr7545/registers.hpp"

namespace cell::dpr7545 {

/// Where the DPR lives: a window of kWindowSize bytes laid out like the interface card's
/// address range 0xC8000..0xC9FFF (DPR at offset 0, lighting latch at kLightingOffset).
/// Real and simulated hardware differ only in their transport (STYLE.md §8):
///
/// - shared memory (create_shm / open_shm): the simulator sim-7545 creates a POSIX shared
///   memory segment, the gateway driver opens it;
/// - physical memory (open_physical): /dev/mem mapped at the card's base address (0xC8000)
///   for a real ISA DPR card;
/// - heap (make_heap_transport): one process, for unit tests.
///
/// The window stays mapped and valid for the transport's whole life. Transports are not
/// copyable; destroying one unmaps its memory (and, for the creator of a shm segment, unlinks
/// the name). Thread-compatible: window() may be called from any thread.
class Transport {
 public:
  Transport() = default;
  Transport(const Transport&) = delete;
  Transport& operator=(const Transport&) = delete;
  virtual ~Transport() = default;

  /// The mapped window, kWindowSize bytes, page-aligned (heap: 16-byte aligned).
  virtual std::span<std::byte> window() noexcept = 0;

  /// "shm:/cell-dpr7545", "physical:/dev/mem@0xc8000" or "heap".
  virtual const std::string& describe() const noexcept = 0;

  /// True when the name this transport was opened by now refers to another object (a
  /// simulator restarted and created a new segment): the mapping is stale and the caller
  /// should open the name again. Always false for physical and heap transports. Makes a
  /// system call: not for the real-time cycle.
  virtual bool replaced() const noexcept { return false; }
};

/// A zero-filled heap window for tests (both sides in one process).
std::unique_ptr<Transport> make_heap_transport();

/// Ok when `name` is a valid POSIX shared memory name: starts with '/', no further '/', 2 to
/// 255 characters. Errors: kInvalidArgument naming the rule broken.
Status validate_shm_name(std::string_view name);

/// Simulator side: creates the segment `name` (0660, kWindowSize bytes, zero-filled), records
/// the calling process as its owner (sim_control.hpp) and unlinks the name when destroyed.
/// A segment left behind by a process that no longer runs is replaced; one whose recorded
/// owner still runs is not. Errors: kInvalidArgument (bad name), kIo ("shm segment
/// '/cell-dpr7545' is in use by process 1234", or the failing call with strerror).
Result<std::unique_ptr<Transport>> create_shm(const std::string& name);

/// Master side: opens the existing segment `name` read-write. Errors: kInvalidArgument (bad
/// name), kNotReady ("shm segment '/x' does not exist: is cell-sim-7545 running?"), kIo (a
/// segment smaller than kWindowSize, or the failing call with strerror).
Result<std::unique_ptr<Transport>> open_shm(const std::string& name);

/// Real hardware: maps kWindowSize bytes of `device` (normally "/dev/mem") at physical
/// address `base_address` (normally 0xC8000, page-aligned), read-write and synchronous, so
/// that window offset 0 is the DPR and kLightingOffset the lighting latch. Needs root or
/// CAP_SYS_RAWIO, and a kernel that lets /dev/mem reach the ISA hole (CONFIG_STRICT_DEVMEM
/// allows the legacy 0xA0000-0xFFFFF range). Untestable without the card: the tests only
/// check the errors. Errors: kInvalidArgument (base not page-aligned), kIo ("cannot open
/// /dev/mem: Permission denied (the physical DPR transport needs root or CAP_SYS_RAWIO)",
/// "cannot map ...").
Result<std::unique_ptr<Transport>> open_physical(const std::string& device,
                                                 std::uint64_t base_address);

}  // namespace cell::dpr7545
