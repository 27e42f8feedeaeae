#pragma once

#include <cstring>
#include <span>
#include <string>
#include <string_view>
#include <type_traits>
#include <vector>

/// Helpers between idlc's C types and C++ (no copies, no ownership transfer).
///
/// Writing: point a sample's strings and sequences at C++ storage that outlives the write()
/// call (dds_write serialises and never keeps the pointers):
///   sample.robot_id = bus::borrow(robot_id);
///   bus::borrow(sample.position_rad_or_mm, joints);
/// Reading: view a received sample's strings and sequences without copying:
///   std::string_view id = bus::str(sample.robot_id);
///   for (double q : bus::span(sample.position_rad_or_mm)) ...
namespace cell::bus {

/// A received C string as a view; null becomes "".
inline std::string_view str(const char* s) noexcept { return s != nullptr ? s : ""; }

/// A std::string's characters as the char* an idlc string field wants (read-only use).
inline char* borrow(const std::string& s) noexcept { return const_cast<char*>(s.c_str()); }
/// Not from a temporary: it dies at the end of the statement, before the write reads it.
char* borrow(const std::string&& s) = delete;

/// An enum field of a received sample as its integer value, for the switch or comparison that
/// refuses a value the contract does not know. A sample off the wire may hold any value, and
/// idlc's C enums have no fixed underlying type: loading an out-of-range value as the enum is
/// undefined behaviour (UBSan: "load of value 9, which is not a valid value"), which lets the
/// compiler drop the very check that would refuse it. The integer is read as bytes instead.
template <typename E>
std::underlying_type_t<E> raw(const E& e) noexcept {
  static_assert(std::is_enum_v<E>, "bus::raw reads an enum field");
  std::underlying_type_t<E> v;
  std::memcpy(&v, &e, sizeof v);
  return v;
}

/// A received idlc sequence (dds_sequence_X with _length/_buffer) as a span.
template <typename Seq>
auto span(const Seq& seq) noexcept {
  using Elem = std::remove_pointer_t<decltype(seq._buffer)>;
  return std::span<const Elem>(seq._buffer, seq._buffer != nullptr ? seq._length : 0U);
}

/// Points an idlc sequence at a vector's elements (read-only use; _release = false so Cyclone
/// never frees them).
template <typename Seq, typename V>
void borrow(Seq& seq, const std::vector<V>& values) noexcept {
  using Elem = std::remove_pointer_t<decltype(seq._buffer)>;
  static_assert(std::is_same_v<Elem, V>, "sequence element type mismatch");
  seq._buffer = const_cast<Elem*>(values.data());
  seq._length = static_cast<std::uint32_t>(values.size());
  seq._maximum = seq._length;
  seq._release = false;
}
/// Not from a temporary (see borrow of a string).
template <typename Seq, typename V>
void borrow(Seq& seq, const std::vector<V>&& values) = delete;

/// A received sequence copied into a vector.
template <typename Seq>
auto to_vector(const Seq& seq) {
  const auto s = span(seq);
  return std::vector<typename decltype(s)::value_type>(s.begin(), s.end());
}

}  // namespace cell::bus
