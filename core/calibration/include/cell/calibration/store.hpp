#pragma once

#include <cstdint>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include "cell/calibration/belt_calibration.hpp"
#include "cell/calibration/camera_calibration.hpp"
#include "cell/common/result.hpp"

/// The versioned calibration store: data, not source (default run/calibrations/, never
/// committed). Every calibration ever accepted stays; one version per device is current.
///
/// Layout under the store's directory:
///   camera/<camera_id>/0003.yaml          a CameraCalibration file (camera_calibration.hpp)
///   camera/<camera_id>/0003.details.yaml  the procedure's full report (views, figures, ...)
///   camera/<camera_id>/current            "3": the current version's number
///   belt/<belt_id>/...                    the same for BeltCalibrations
/// Version strings are "<created_utc>#<number>", e.g. "2026-12-01T10:00:00Z#3"; lookups take
/// the whole string, "#3" or "3". Files are written atomically (temporary, then rename), the
/// version file before the current pointer, so a crash never leaves a pointer to nothing.
/// Thread-safe (one mutex); several processes must not share a store.
namespace cell::calibration {

enum class DeviceKind : std::uint8_t { kCamera, kBelt };
std::string_view to_string(DeviceKind kind) noexcept;  ///< "camera" / "belt"

/// One stored version, as listed.
struct StoredVersion {
  DeviceKind kind = DeviceKind::kCamera;
  std::string device_id;
  std::string version;
  int number = 0;
  std::string created_utc;
  std::string source;
  bool current = false;
  double rms_px = 0.0;          ///< camera: fit RMS [px]; belt: fit RMS [mm]
  double holdout_rms_px = 0.0;  ///< camera only
  double holdout_mm = 0.0;
  std::string path;
};

/// "2026-12-01T10:00:00Z" for a wall-clock time [ns since the epoch].
std::string utc_seconds(std::int64_t wall_ns);

class CalibrationStore {
 public:
  /// A store rooted at `directory` (created on the first write).
  explicit CalibrationStore(std::string directory);
  CalibrationStore(const CalibrationStore&) = delete;
  CalibrationStore& operator=(const CalibrationStore&) = delete;

  const std::string& directory() const noexcept { return directory_; }

  /// Adds a new version and makes it current. Sets `version` and, when empty, `created_utc`
  /// (now). Returns what was stored. Errors: kInvalidArgument from validate() or an id that
  /// is not a file name ([A-Za-z0-9_.-]+); kIo when a file cannot be written.
  Result<CameraCalibration> add_camera(CameraCalibration calibration,
                                       const std::string& details_yaml = {});
  Result<BeltCalibration> add_belt(BeltCalibration calibration,
                                   const std::string& details_yaml = {});

  /// The current version. Errors: kNotReady when the device has none; kConfig / kIo when its
  /// file is unreadable (naming it).
  Result<CameraCalibration> current_camera(const std::string& camera_id) const;
  Result<BeltCalibration> current_belt(const std::string& belt_id) const;

  /// A given version. Errors: kInvalidArgument for an unknown version (listing the known).
  Result<CameraCalibration> camera(const std::string& camera_id, const std::string& version) const;
  Result<BeltCalibration> belt(const std::string& belt_id, const std::string& version) const;

  /// Every stored version (of one kind and device when given), oldest first per device.
  /// Errors: kIo when the directory cannot be read.
  Result<std::vector<StoredVersion>> list(std::optional<DeviceKind> kind = std::nullopt,
                                          const std::string& device_id = {}) const;

  /// Devices of a kind with a current version.
  std::vector<std::string> devices(DeviceKind kind) const;

  /// Makes `version` current again; later versions stay in the store. Errors: as camera() /
  /// belt(); kIo when the pointer cannot be written.
  Result<StoredVersion> rollback(DeviceKind kind, const std::string& device_id,
                                 const std::string& version);

 private:
  std::string device_dir(DeviceKind kind, const std::string& id) const;
  Result<int> resolve(DeviceKind kind, const std::string& id, const std::string& version) const;
  Result<int> current_number(DeviceKind kind, const std::string& id) const;
  Result<int> next_number(DeviceKind kind, const std::string& id) const;
  Status write_current(DeviceKind kind, const std::string& id, int number);
  Result<std::vector<StoredVersion>> list_unlocked(std::optional<DeviceKind> kind,
                                                   const std::string& device_id) const;

  std::string directory_;
  mutable std::mutex mutex_;
};

}  // namespace cell::calibration
