#pragma once

#include <cstddef>
#include <cstdint>
#include <functional>
#include <string>
#include <string_view>

/// Pieces every calibration report shares: what happened to each view, how the solver ended,
/// and the progress callback long operations call.
namespace cell::calibration {

/// One view of a calibration (an image, a robot pose with its image, a belt sample).
struct ViewReport {
  std::string id;           ///< the caller's id (file name, "pose 7", sample id)
  std::int64_t stamp_ns = 0;  ///< when it was taken (0 when unknown)
  bool used = false;        ///< in the fit
  bool held_out = false;    ///< kept out of the fit for validation
  double rms_px = 0.0;      ///< reprojection RMS of this view [px] (belt samples: [mm])
  std::string reason;       ///< why it is neither used nor held out ("" otherwise)
};

/// How the nonlinear least squares ended (Ceres's Summary, condensed).
struct SolverSummary {
  int iterations = 0;
  bool converged = false;    ///< Ceres reported CONVERGENCE
  std::string termination;   ///< Ceres's message ("Function tolerance reached. ...")
  double initial_cost = 0.0;
  double final_cost = 0.0;
  double time_s = 0.0;
};

/// Called by long operations: `stage` is a short tag ("detect", "solve", ...), `step` of
/// `total` within it (total 0 when unknown), `message` a sentence for people. Called on the
/// caller's thread; must not throw.
using ProgressFn = std::function<void(std::string_view stage, std::size_t step, std::size_t total,
                                      std::string_view message)>;

/// Root mean square of the Euclidean reprojection errors: sqrt(sum |e_k|^2 / n) over n points,
/// the convention of cv::calibrateCamera's return value. Every `rms_px` of this library is one.
inline constexpr std::string_view kRmsConvention =
    "RMS over points of the Euclidean pixel error (cv::calibrateCamera's convention)";

}  // namespace cell::calibration
