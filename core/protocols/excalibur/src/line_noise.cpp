#include "cell/protocols/excalibur/line_noise.hpp"

#include <fmt/format.h>

namespace cell::protocols::excalibur {

Status NoiseSettings::validate() const {
  if (!(probability_per_line >= 0 && probability_per_line <= 1)) {
    return Error{
        Errc::kInvalidArgument,
        fmt::format("probability_per_line must be in [0, 1], got {}", probability_per_line)};
  }
  if (!(probability_per_byte >= 0 && probability_per_byte <= 1)) {
    return Error{
        Errc::kInvalidArgument,
        fmt::format("probability_per_byte must be in [0, 1], got {}", probability_per_byte)};
  }
  return ok_status();
}

void LineNoise::fault_at(std::string& bytes, std::size_t index) {
  std::uniform_int_distribution<int> kind(0, 2);
  switch (kind(rng_)) {
    case 0: {
      std::uniform_int_distribution<int> bit(0, 7);
      bytes[index] =
          static_cast<char>(static_cast<unsigned char>(bytes[index]) ^ (1U << bit(rng_)));
      break;
    }
    case 1:
      bytes.erase(index, 1);
      break;
    default:
      bytes.insert(index, 1, bytes[index]);
      break;
  }
  ++faults_;
}

int LineNoise::corrupt_bytes(std::string& bytes) {
  if (settings_.probability_per_byte <= 0 || bytes.empty()) {
    return 0;
  }
  std::bernoulli_distribution hit(settings_.probability_per_byte);
  int n = 0;
  std::size_t i = 0;
  while (i < bytes.size()) {
    if (!hit(rng_)) {
      ++i;
      continue;
    }
    const std::size_t before = bytes.size();
    fault_at(bytes, i);
    ++n;
    if (bytes.size() > before) {
      i += 2;  // the byte and its duplicate
    } else if (bytes.size() == before) {
      ++i;  // a flipped bit
    }       // a dropped byte: the next one moved into slot i
  }
  return n;
}

int LineNoise::corrupt_line(std::string& bytes) {
  int n = corrupt_bytes(bytes);
  if (settings_.probability_per_line > 0 && !bytes.empty()) {
    std::bernoulli_distribution hit(settings_.probability_per_line);
    if (hit(rng_)) {
      std::uniform_int_distribution<std::size_t> where(0, bytes.size() - 1);
      fault_at(bytes, where(rng_));
      ++n;
    }
  }
  return n;
}

}  // namespace cell::protocols::excalibur
