#pragma once

// Ceres settings and summaries shared by the solvers (private).

#include <ceres/solver.h>

#include "cell/calibration/report.hpp"

namespace cell::calibration::detail {

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

}  // namespace cell::calibration::detail
