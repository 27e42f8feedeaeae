#include "homing_record.hpp"

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>

#include <fmt/format.h>

#include <nlohmann/json.hpp>

namespace cell::gateway {
namespace {

using nlohmann::json;
constexpr int kVersion = 1;

}  // namespace

const char* gripper_name(HomingRecord::Gripper g) noexcept {
  switch (g) {
    case HomingRecord::Gripper::kOpen:
      return "open";
    case HomingRecord::Gripper::kClosed:
      return "closed";
    case HomingRecord::Gripper::kOpening:
      return "opening";
    case HomingRecord::Gripper::kClosing:
      return "closing";
    case HomingRecord::Gripper::kUnknown:
      break;
  }
  return "unknown";
}

Result<std::optional<HomingRecord>> load_homing_record(const std::string& path) {
  std::error_code ec;
  if (!std::filesystem::exists(path, ec)) {
    return std::optional<HomingRecord>{};
  }
  std::ifstream in(path);
  if (!in) {
    return Error{Errc::kIo, fmt::format("homing record {}: cannot be read", path)};
  }
  std::stringstream text;
  text << in.rdbuf();
  const auto bad = [&](const std::string& what) {
    return Error{Errc::kInvalidArgument, fmt::format("homing record {}: {}", path, what)};
  };
  const json doc = json::parse(text.str(), nullptr, /*allow_exceptions=*/false);
  if (!doc.is_object()) {
    return bad("not a JSON object");
  }
  if (!doc.contains("version") || !doc["version"].is_number_integer() ||
      doc["version"].get<int>() != kVersion) {
    return bad(fmt::format("version must be {}", kVersion));
  }
  HomingRecord r;
  const json& pid = doc.value("board_pid", json());
  const json& counts = doc.value("counts", json());
  const json& gripper = doc.value("gripper", json());
  const json& lights = doc.value("lights", json());
  if (!pid.is_number_unsigned() || !counts.is_array() || counts.size() != dpr7545::kJoints ||
      !gripper.is_string() || !lights.is_number_unsigned() || lights.get<unsigned>() > 0xFF) {
    return bad("needs board_pid (>= 0), counts (4 integers), gripper and lights (0-255)");
  }
  r.board_pid = pid.get<std::uint32_t>();
  for (std::size_t j = 0; j < dpr7545::kJoints; ++j) {
    if (!counts[j].is_number_integer()) {
      return bad(fmt::format("counts[{}] is not an integer", j));
    }
    r.counts[j] = counts[j].get<std::int32_t>();
  }
  const std::string g = gripper.get<std::string>();
  if (g == "open") {
    r.gripper = HomingRecord::Gripper::kOpen;
  } else if (g == "closed") {
    r.gripper = HomingRecord::Gripper::kClosed;
  } else if (g == "opening") {
    r.gripper = HomingRecord::Gripper::kOpening;
  } else if (g == "closing") {
    r.gripper = HomingRecord::Gripper::kClosing;
  } else if (g != "unknown") {
    return bad(fmt::format("gripper must be open, closed, opening, closing or unknown, got '{}'",
                           g));
  }
  r.lights = static_cast<std::uint8_t>(lights.get<unsigned>());
  return std::optional<HomingRecord>(r);
}

Status save_homing_record(const std::string& path, const HomingRecord& record) {
  namespace fs = std::filesystem;
  std::error_code ec;
  const fs::path target(path);
  if (target.has_parent_path()) {
    fs::create_directories(target.parent_path(), ec);
  }
  const json doc = {{"version", kVersion},
                    {"board_pid", record.board_pid},
                    {"counts", record.counts},
                    {"gripper", gripper_name(record.gripper)},
                    {"lights", record.lights}};
  const std::string tmp = path + ".tmp";
  {
    std::ofstream out(tmp, std::ios::trunc);
    out << doc.dump() << "\n";
    if (!out.flush()) {
      return Error{Errc::kIo, fmt::format("homing record {}: cannot be written", tmp)};
    }
  }
  fs::rename(tmp, target, ec);
  if (ec) {
    return Error{Errc::kIo,
                 fmt::format("homing record: cannot rename {} to {}: {}", tmp, path, ec.message())};
  }
  return ok_status();
}

std::optional<std::string> homing_record_refusal(
    const HomingRecord& record, std::uint32_t board_pid,
    const std::array<std::int32_t, dpr7545::kJoints>& counts,
    const std::array<double, dpr7545::kJoints>& tolerance_counts) {
  if (record.board_pid != board_pid) {
    return fmt::format("it was written for the board of simulator pid {}, this board's is {}",
                       record.board_pid, board_pid);
  }
  bool all_zero = true;
  bool record_zero = true;
  for (std::size_t j = 0; j < dpr7545::kJoints; ++j) {
    all_zero = all_zero && counts[j] == 0;
    record_zero = record_zero && std::abs(record.counts[j]) <= 2;
  }
  if (all_zero && !record_zero) {
    return std::string("every counter reads 0 where the record does not: the board was reset");
  }
  for (std::size_t j = 0; j < dpr7545::kJoints; ++j) {
    const double moved = std::abs(static_cast<double>(counts[j]) - record.counts[j]);
    if (moved > tolerance_counts[j]) {
      return fmt::format("{} reads {} counts, {:.0f} from the record's {} (more than {:.0f})",
                         dpr7545::kJointNames[j], counts[j], moved, record.counts[j],
                         tolerance_counts[j]);
    }
  }
  return std::nullopt;
}

}  // namespace cell::gateway
