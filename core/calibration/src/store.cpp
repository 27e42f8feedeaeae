#include "cell/calibration/store.hpp"

#include <algorithm>
#include <cerrno>
#include <charconv>
#include <cstring>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <sstream>

#include <fmt/format.h>
#include <fmt/ranges.h>

#include "cell/common/time.hpp"
#include "file_util.hpp"

namespace cell::calibration {
namespace {

namespace fs = std::filesystem;

bool valid_id(const std::string& id) {
  return !id.empty() && id != "." && id != ".." &&
         std::all_of(id.begin(), id.end(), [](unsigned char c) {
           return std::isalnum(c) != 0 || c == '_' || c == '-' || c == '.';
         });
}

Status check_id(const std::string& id) {
  if (!valid_id(id)) {
    return Error{Errc::kInvalidArgument,
                 fmt::format("device id '{}' must be letters, digits, '_', '-' or '.'", id)};
  }
  return ok_status();
}

Status write_atomically(const fs::path& path, const std::string& text) {
  return detail::write_atomically(path.string(), text);
}

std::string file_name(int number) { return fmt::format("{:04d}.yaml", number); }

/// The number of a version string: "...#3", "#3" or "3"; -1 if none.
int number_of(const std::string& version) {
  const auto hash = version.rfind('#');
  const std::string digits = hash == std::string::npos ? version : version.substr(hash + 1);
  int n = -1;
  const auto r = std::from_chars(digits.data(), digits.data() + digits.size(), n);
  return (r.ec == std::errc() && r.ptr == digits.data() + digits.size() && n > 0) ? n : -1;
}

}  // namespace

std::string_view to_string(DeviceKind kind) noexcept {
  return kind == DeviceKind::kCamera ? "camera" : "belt";
}

std::string utc_seconds(std::int64_t wall_ns) {
  const std::time_t t = static_cast<std::time_t>(wall_ns / 1'000'000'000LL);
  std::tm tm{};
  gmtime_r(&t, &tm);
  return fmt::format("{:04d}-{:02d}-{:02d}T{:02d}:{:02d}:{:02d}Z", tm.tm_year + 1900,
                     tm.tm_mon + 1, tm.tm_mday, tm.tm_hour, tm.tm_min, tm.tm_sec);
}

CalibrationStore::CalibrationStore(std::string directory) : directory_(std::move(directory)) {}

std::string CalibrationStore::device_dir(DeviceKind kind, const std::string& id) const {
  return (fs::path(directory_) / std::string(to_string(kind)) / id).string();
}

Result<int> CalibrationStore::current_number(DeviceKind kind, const std::string& id) const {
  const fs::path p = fs::path(device_dir(kind, id)) / "current";
  std::ifstream f(p);
  if (!f) {
    return Error{Errc::kNotReady,
                 fmt::format("no {} calibration of '{}' in the store {}", to_string(kind), id,
                             directory_)};
  }
  std::string text;
  std::getline(f, text);
  const int n = number_of(text);
  if (n < 0) {
    return Error{Errc::kIo, fmt::format("{}: not a version number: '{}'", p.string(), text)};
  }
  return n;
}

Result<int> CalibrationStore::next_number(DeviceKind kind, const std::string& id) const {
  int last = 0;
  std::error_code ec;
  const fs::path dir(device_dir(kind, id));
  if (!fs::exists(dir, ec)) {
    return 1;
  }
  if (fs::is_directory(dir, ec)) {
    for (const auto& e : fs::directory_iterator(dir, ec)) {
      const std::string name = e.path().filename().string();
      if (name.size() == 9 && name.substr(4) == ".yaml") {
        last = std::max(last, number_of(name.substr(0, 4)));
      }
    }
  }
  if (ec) {
    return Error{Errc::kIo, fmt::format("{}: cannot list: {}", dir.string(), ec.message())};
  }
  return last + 1;
}

Status CalibrationStore::write_current(DeviceKind kind, const std::string& id, int number) {
  return write_atomically(fs::path(device_dir(kind, id)) / "current", fmt::format("{}\n", number));
}

Result<int> CalibrationStore::resolve(DeviceKind kind, const std::string& id,
                                      const std::string& version) const {
  const int n = number_of(version);
  const fs::path p = fs::path(device_dir(kind, id)) / file_name(std::max(n, 0));
  std::error_code ec;
  if (n < 0 || !fs::exists(p, ec)) {
    std::vector<std::string> known;
    if (auto all = list_unlocked(kind, id); all) {
      for (const StoredVersion& v : *all) {
        known.push_back(v.version);
      }
    }
    return Error{Errc::kInvalidArgument,
                 fmt::format("{} '{}' has no version '{}' (known: {})", to_string(kind), id,
                             version, known.empty() ? "none" : fmt::format("{}", fmt::join(known, ", ")))};
  }
  return n;
}

Result<CameraCalibration> CalibrationStore::add_camera(CameraCalibration c,
                                                       const std::string& details) {
  CELL_TRY(check_id(c.camera_id));
  std::lock_guard lock(mutex_);
  auto n = next_number(DeviceKind::kCamera, c.camera_id);
  if (!n) {
    return std::move(n).error();
  }
  if (c.created_utc.empty()) {
    c.created_utc = utc_seconds(wall_time_ns());
  }
  c.version = fmt::format("{}#{}", c.created_utc, *n);
  CELL_TRY(c.validate());
  const fs::path dir(device_dir(DeviceKind::kCamera, c.camera_id));
  if (!details.empty()) {
    CELL_TRY(write_atomically(dir / fmt::format("{:04d}.details.yaml", *n), details));
  }
  CELL_TRY(write_atomically(dir / file_name(*n), format_camera_calibration(c)));
  CELL_TRY(write_current(DeviceKind::kCamera, c.camera_id, *n));
  return c;
}

Result<BeltCalibration> CalibrationStore::add_belt(BeltCalibration calibration,
                                                   const std::string& details_yaml) {
  CELL_TRY(check_id(calibration.belt_id));
  std::lock_guard lock(mutex_);
  auto n = next_number(DeviceKind::kBelt, calibration.belt_id);
  if (!n) {
    return std::move(n).error();
  }
  if (calibration.created_utc.empty()) {
    calibration.created_utc = utc_seconds(wall_time_ns());
  }
  calibration.version = fmt::format("{}#{}", calibration.created_utc, *n);
  CELL_TRY(calibration.validate());
  const fs::path dir(device_dir(DeviceKind::kBelt, calibration.belt_id));
  if (!details_yaml.empty()) {
    CELL_TRY(write_atomically(dir / fmt::format("{:04d}.details.yaml", *n), details_yaml));
  }
  CELL_TRY(write_atomically(dir / file_name(*n), format_belt_calibration(calibration)));
  CELL_TRY(write_current(DeviceKind::kBelt, calibration.belt_id, *n));
  return calibration;
}

Result<CameraCalibration> CalibrationStore::current_camera(const std::string& id) const {
  CELL_TRY(check_id(id));
  std::lock_guard lock(mutex_);
  auto n = current_number(DeviceKind::kCamera, id);
  if (!n) {
    return std::move(n).error();
  }
  return load_camera_calibration(
      (fs::path(device_dir(DeviceKind::kCamera, id)) / file_name(*n)).string());
}

Result<BeltCalibration> CalibrationStore::current_belt(const std::string& id) const {
  CELL_TRY(check_id(id));
  std::lock_guard lock(mutex_);
  auto n = current_number(DeviceKind::kBelt, id);
  if (!n) {
    return std::move(n).error();
  }
  return load_belt_calibration((fs::path(device_dir(DeviceKind::kBelt, id)) / file_name(*n)).string());
}

Result<CameraCalibration> CalibrationStore::camera(const std::string& id,
                                                   const std::string& version) const {
  CELL_TRY(check_id(id));
  std::lock_guard lock(mutex_);
  auto n = resolve(DeviceKind::kCamera, id, version);
  if (!n) {
    return std::move(n).error();
  }
  return load_camera_calibration(
      (fs::path(device_dir(DeviceKind::kCamera, id)) / file_name(*n)).string());
}

Result<BeltCalibration> CalibrationStore::belt(const std::string& id,
                                               const std::string& version) const {
  CELL_TRY(check_id(id));
  std::lock_guard lock(mutex_);
  auto n = resolve(DeviceKind::kBelt, id, version);
  if (!n) {
    return std::move(n).error();
  }
  return load_belt_calibration((fs::path(device_dir(DeviceKind::kBelt, id)) / file_name(*n)).string());
}

Result<std::vector<StoredVersion>> CalibrationStore::list(std::optional<DeviceKind> kind,
                                                          const std::string& device_id) const {
  std::lock_guard lock(mutex_);
  return list_unlocked(kind, device_id);
}

Result<std::vector<StoredVersion>> CalibrationStore::list_unlocked(
    std::optional<DeviceKind> kind, const std::string& device_id) const {
  std::vector<StoredVersion> out;
  std::error_code ec;
  for (const DeviceKind k : {DeviceKind::kCamera, DeviceKind::kBelt}) {
    if (kind && *kind != k) {
      continue;
    }
    const fs::path root = fs::path(directory_) / std::string(to_string(k));
    std::error_code missing;
    if (!fs::is_directory(root, missing)) {
      continue;
    }
    std::vector<std::string> ids;
    for (const auto& e : fs::directory_iterator(root, ec)) {
      if (e.is_directory()) {
        ids.push_back(e.path().filename().string());
      }
    }
    std::sort(ids.begin(), ids.end());
    for (const std::string& id : ids) {
      if (!device_id.empty() && id != device_id) {
        continue;
      }
      const auto current = current_number(k, id);
      std::vector<StoredVersion> versions;
      for (const auto& e : fs::directory_iterator(fs::path(root) / id, ec)) {
        const std::string name = e.path().filename().string();
        if (name.size() != 9 || name.substr(4) != ".yaml" || number_of(name.substr(0, 4)) < 0) {
          continue;
        }
        StoredVersion v;
        v.kind = k;
        v.device_id = id;
        v.number = number_of(name.substr(0, 4));
        v.path = e.path().string();
        v.current = current && *current == v.number;
        if (k == DeviceKind::kCamera) {
          auto c = load_camera_calibration(v.path);
          if (!c) {
            v.source = "unreadable: " + c.error().message;
          } else {
            v.version = c->version;
            v.created_utc = c->created_utc;
            v.source = c->source;
            v.rms_px = c->quality.rms_px;
            v.holdout_rms_px = c->quality.holdout_rms_px;
            v.holdout_mm = c->quality.holdout_mm;
          }
        } else {
          auto b = load_belt_calibration(v.path);
          if (!b) {
            v.source = "unreadable: " + b.error().message;
          } else {
            v.version = b->version;
            v.created_utc = b->created_utc;
            v.source = b->source;
            v.rms_px = b->rms_mm;
            v.holdout_mm = b->holdout_mm;
          }
        }
        versions.push_back(v);
      }
      std::sort(versions.begin(), versions.end(),
                [](const StoredVersion& a, const StoredVersion& b) { return a.number < b.number; });
      out.insert(out.end(), versions.begin(), versions.end());
    }
  }
  if (ec) {
    return Error{Errc::kIo, fmt::format("{}: cannot list: {}", directory_, ec.message())};
  }
  return out;
}

std::vector<std::string> CalibrationStore::devices(DeviceKind kind) const {
  std::lock_guard lock(mutex_);
  std::vector<std::string> out;
  std::error_code ec;
  const fs::path root = fs::path(directory_) / std::string(to_string(kind));
  if (!fs::is_directory(root, ec)) {
    return out;
  }
  for (const auto& e : fs::directory_iterator(root, ec)) {
    const std::string id = e.path().filename().string();
    if (e.is_directory() && current_number(kind, id)) {
      out.push_back(id);
    }
  }
  std::sort(out.begin(), out.end());
  return out;
}

Result<StoredVersion> CalibrationStore::rollback(DeviceKind kind, const std::string& id,
                                                 const std::string& version) {
  CELL_TRY(check_id(id));
  std::lock_guard lock(mutex_);
  auto n = resolve(kind, id, version);
  if (!n) {
    return std::move(n).error();
  }
  CELL_TRY(write_current(kind, id, *n));
  auto all = list_unlocked(kind, id);
  if (!all) {
    return std::move(all).error();
  }
  for (const StoredVersion& v : *all) {
    if (v.current) {
      return v;
    }
  }
  return Error{Errc::kIo, "rollback: the current version vanished"};
}

}  // namespace cell::calibration
