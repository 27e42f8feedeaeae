#pragma once

// Ceres settings and summaries shared by the solvers (private).

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <set>
#include <string_view>
#include <vector>

#include <ceres/solver.h>
#include <fmt/format.h>

#include "cell/calibration/report.hpp"
#include "cell/common/result.hpp"

namespace cell::calibration::detail {

/// Calls `progress` (when set) with one step of a long solve.
inline void report_progress(const ProgressFn& progress, std::string_view stage, std::size_t step,
                            std::size_t total, std::string_view message) {
  if (progress) {
    progress(stage, step, total, message);
  }
}

/// Single-threaded (the cell's PCs share their cores), deterministic, tight tolerances:
/// calibrations are small problems solved once.
inline ceres::Solver::Options solver_options(int max_iterations) {
  ceres::Solver::Options o;
  o.max_num_iterations = max_iterations;
  o.function_tolerance = 1e-12;
  o.gradient_tolerance = 1e-14;
  o.parameter_tolerance = 1e-12;
  o.num_threads = 1;
  o.logging_type = ceres::SILENT;
  o.minimizer_progress_to_stdout = false;
  return o;
}

inline SolverSummary condense(const ceres::Solver::Summary& s) {
  SolverSummary out;
  out.iterations = static_cast<int>(s.iterations.size());
  out.converged = s.termination_type == ceres::CONVERGENCE;
  out.termination = s.message;
  out.initial_cost = s.initial_cost;
  out.final_cost = s.final_cost;
  out.time_s = s.total_time_in_seconds;
  return out;
}

/// The usable views (or samples) of a fit split into those it fits and those it holds out for
/// the hold-out figure; indices into the caller's input.
struct HoldoutSplit {
  std::vector<std::size_t> fit;
  std::vector<std::size_t> held;
};

/// Holds out `fraction` of `usable` (at least `min_holdout` and 1 when fraction > 0, fewer
/// only to leave `min_fit` to fit), spread evenly over them. Errors: kInvalidArgument "too few
/// <what>: N given, U usable (R rejected), K needed (F to fit and H to hold out)".
inline Result<HoldoutSplit> split_holdout(const std::vector<std::size_t>& usable,
                                          std::size_t given, int min_fit_count, int min_holdout,
                                          double fraction, std::string_view what) {
  const auto min_fit = static_cast<std::size_t>(min_fit_count);
  std::size_t holdout = 0;
  if (fraction > 0.0) {
    holdout = std::max<std::size_t>(
        {static_cast<std::size_t>(min_holdout), 1,
         static_cast<std::size_t>(std::floor(fraction * static_cast<double>(usable.size())))});
    if (usable.size() >= min_fit + 1 && usable.size() < min_fit + holdout) {
      holdout = usable.size() - min_fit;
    }
  }
  if (usable.size() < min_fit + holdout) {
    return Error{Errc::kInvalidArgument,
                 fmt::format("too few {}: {} given, {} usable ({} rejected), {} needed ({} to "
                             "fit{})",
                             what, given, usable.size(), given - usable.size(), min_fit + holdout,
                             min_fit,
                             holdout > 0 ? fmt::format(" and {} to hold out", holdout) : "")};
  }
  const std::size_t n = usable.size();
  std::set<std::size_t> held;
  for (std::size_t k = 0; k < holdout; ++k) {
    held.insert(std::min(n - 1, static_cast<std::size_t>((static_cast<double>(k) + 0.5) *
                                                         static_cast<double>(n) /
                                                         static_cast<double>(holdout))));
  }
  HoldoutSplit out;
  for (std::size_t k = 0; k < n; ++k) {
    (held.count(k) != 0 ? out.held : out.fit).push_back(usable[k]);
  }
  return out;
}

}  // namespace cell::calibration::detail
