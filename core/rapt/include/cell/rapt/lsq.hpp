#pragma once

#include <array>
#include <string>
#include <vector>

#include "cell/common/result.hpp"
#include "cell/rapt/model.hpp"
#include "cell/rapt/vision.hpp"

/// Beyond the thesis: a least-squares evaluation of a vision package that uses EVERY measured
/// end point of every LOOK (the symbolic route uses one plane per LOOK and only the origin of
/// the last edge, and ignores redundant LOOKs, digest §3.3), and reports the residuals so a user
/// can see when the measurements disagree with each other.
///
/// The pose keeps the INVIOLATE constraints exactly: it varies only within the freedom they
/// leave (one AGPP, or several parallel ones: a rotation about the reference normal and a
/// translation in the plane; two independent ones: a translation along their line; three:
/// none), starting from the thesis's solution. The residual of an end point is its signed
/// distance, in image units, from the image of the model edge's infinite line. Solved with
/// Ceres (autodiff, Levenberg-Marquardt).
namespace cell::rapt {

/// The outcome of a least-squares evaluation.
struct LsqReport {
  Pose verified = Pose::Identity();  ///< world_T_body minimising the image residuals
  int free_parameters = 0;           ///< 3, 1 or 0 (see above)
  int residual_count = 0;            ///< 2 per measured LOOK
  double initial_rms = 0.0;          ///< at the thesis's solution, image units
  double final_rms = 0.0;            ///< at the least-squares solution, image units
  double max_abs = 0.0;              ///< largest final residual, image units
  /// Final residuals of each LOOK's two end points (same order as the package's LOOKs; NaN
  /// when a LOOK has no reading).
  std::vector<std::array<double, 2>> residuals;
  double shift_mm = 0.0;   ///< |translation| between the two solutions
  double shift_rad = 0.0;  ///< rotation angle between the two solutions
  int iterations = 0;
  bool converged = false;  ///< Ceres reported convergence
  std::string message;     ///< Ceres's termination message

  /// "rms 0.42 (was 0.55) over 4 end points; 0.3 mm / 0.1 deg from the thesis's solution".
  std::string brief() const;
};

/// Least-squares evaluation of `package` from `inputs` (the same inputs as evaluate_route),
/// starting at `initial` (the route's result). Errors: kInvalidArgument when no LOOK has a
/// reading or a model edge projects behind a camera at the start.
Result<LsqReport> least_squares(const Program& program,
                                const CompiledPackage& package,
                                const RouteInputs& inputs,
                                const Pose& initial);

}  // namespace cell::rapt
