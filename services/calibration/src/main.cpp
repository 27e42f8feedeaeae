#include "calibration_service.hpp"

int main(int argc, char** argv) {
  return cell::service::run<cell::calibration_service::CalibrationConfig,
                            cell::calibration_service::CalibrationService>(
      argc, argv,
      {.kind = "calibration",
       .summary = "cell calibration service: camera intrinsics, hand-eye, the 7545's planar "
                  "model and belts, on request; a versioned store; the current calibrations "
                  "published transient-local",
       .default_config = "config/calibration.yaml"},
      &cell::calibration_service::load_config);
}
