#pragma once

#include <atomic>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>

#include "calibration_config.hpp"
#include "cell/bus/reader.hpp"
#include "cell/bus/topic.hpp"
#include "cell/bus/writer.hpp"
#include "cell/calibration/store.hpp"
#include "cell/service/runtime.hpp"
#include "cell_link.hpp"
#include "procedures.hpp"

namespace cell::calibration_service {

/// The calibration service. Runs calibration procedures on request, one at a time on a
/// worker thread (the main loop keeps answering: list, show, rollback and cancel at once, and a
/// second procedure is refused as busy); keeps every accepted calibration in the versioned
/// store; publishes the current CameraCalibration of every configured camera (the nominal one
/// until one is stored) and BeltCalibration of every calibrated belt, transient-local.
///
/// Every CalibrationRequest is answered: a CalibrationProgress "accepted" and then stage
/// events, and a CalibrationResult (the outcome, or the reason it failed); or at once a
/// CalibrationResult refusing it with the reason. A failed procedure stores and publishes
/// nothing: the current calibration stays.
///
/// Topics: in cell/calibration/request (command); out cell/calibration/progress (recent),
/// cell/calibration/result (recent), cell/calibration/camera and cell/calibration/belt
/// (state). Guided procedures also talk to cell-motion, the cameras, the gateways and
/// cell-sim-world (cell_link.hpp).
class CalibrationService {
 public:
  /// Creates the store (its directory on the first write), the readers and writers, and
  /// publishes the current calibrations. Throws bus::BusError on DDS setup failures.
  CalibrationService(service::Context& ctx, const CalibrationConfig& config);
  ~CalibrationService();
  CalibrationService(const CalibrationService&) = delete;
  CalibrationService& operator=(const CalibrationService&) = delete;

  void run(service::Context& ctx);

  /// The current calibration of a configured camera: the store's, else the nominal (tests).
  calibration::CameraCalibration current_camera(const std::string& camera_id) const;
  const calibration::CalibrationStore& store() const noexcept { return store_; }

 private:
  struct Key {
    std::string client_id;
    std::uint64_t seq = 0;
  };
  void handle(const cell_calibration_CalibrationRequest& request);
  void answer_now(const Key& key, const cell_calibration_CalibrationRequest& request);
  void start(const Key& key, cell_calibration_CalibrationProcedure procedure, Request request);
  void work(Key key, cell_calibration_CalibrationProcedure procedure, Request request);
  void reap_worker();

  void publish_current();
  Status publish_camera(const calibration::CameraCalibration& calibration);
  Status publish_belt(const calibration::BeltCalibration& b);

  void progress(const Key& key, cell_calibration_CalibrationProcedure procedure,
                const std::string& device, std::string_view stage, std::size_t step,
                std::size_t total, std::string_view message);
  /// Writes a CalibrationResult. `outcome` (for an accepted one) fills the figures; `error`
  /// a refusal or failure. `procedure` is echoed as received, bytes and all (it may be a value
  /// the contract does not know: the refusal of an unknown procedure).
  void result(const Key& key,
              const cell_calibration_CalibrationProcedure& procedure,
              const std::string& device,
              const Outcome* outcome,
              const Error* error,
              const std::string& version,
              bool stored,
              double elapsed_s);

  service::Context& ctx_;
  CalibrationConfig config_;
  calibration::CalibrationStore store_;
  std::atomic<bool> cancel_{false};
  std::atomic<bool> busy_{false};
  std::atomic<bool> worker_done_{false};
  std::string running_;  ///< what the worker runs (for "busy" refusals); guarded by mutex_
  mutable std::mutex mutex_;
  std::thread worker_;

  bus::Topic<cell_calibration_CalibrationRequest> request_topic_;
  bus::Topic<cell_calibration_CalibrationProgress> progress_topic_;
  bus::Topic<cell_calibration_CalibrationResult> result_topic_;
  bus::Topic<cell_calibration_CameraCalibration> camera_topic_;
  bus::Topic<cell_calibration_BeltCalibration> belt_topic_;
  bus::Reader<cell_calibration_CalibrationRequest> requests_;
  bus::Writer<cell_calibration_CalibrationProgress> progress_writer_;
  bus::Writer<cell_calibration_CalibrationResult> result_writer_;
  bus::Writer<cell_calibration_CameraCalibration> camera_writer_;
  bus::Writer<cell_calibration_BeltCalibration> belt_writer_;
  std::unique_ptr<CellLink> link_;
};

/// "intrinsics", "hand_eye", ... for the IDL enum ("unknown" otherwise).
std::string_view procedure_name(const cell_calibration_CalibrationProcedure& field) noexcept;

}  // namespace cell::calibration_service
