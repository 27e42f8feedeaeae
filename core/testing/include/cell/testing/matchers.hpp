#pragma once

#include <string>

#include <Eigen/Geometry>
#include <gmock/gmock.h>

#include "cell/common/result.hpp"

namespace cell::testing {

/// Matches a Result/Status holding a value; on failure prints the error's code and message.
MATCHER(IsOk, "is ok") {
  if (arg.has_value()) {
    return true;
  }
  *result_listener << "error " << ::cell::to_string(arg.error().code) << ": "
                   << arg.error().message;
  return false;
}

/// Matches a Result/Status holding an error of code `errc`.
MATCHER_P(IsErr, errc, std::string("is error ") + std::string(::cell::to_string(errc))) {
  if (arg.has_value()) {
    *result_listener << "holds a value";
    return false;
  }
  *result_listener << "error " << ::cell::to_string(arg.error().code) << ": "
                   << arg.error().message;
  return arg.error().code == errc;
}

/// Matches a Result/Status holding an error of code `errc` whose message contains `text`.
MATCHER_P2(IsErrWith, errc, text,
           std::string("is error ") + std::string(::cell::to_string(errc)) + " mentioning \"" +
               std::string(text) + "\"") {
  if (arg.has_value()) {
    *result_listener << "holds a value";
    return false;
  }
  *result_listener << "error " << ::cell::to_string(arg.error().code) << ": "
                   << arg.error().message;
  return arg.error().code == errc &&
         arg.error().message.find(std::string(text)) != std::string::npos;
}

/// Matches an Eigen::Isometry3d within `tol_mm` in translation and `tol_mm * 1e-3` rad in
/// rotation (angle of expected^-1 * actual).
MATCHER_P2(IsNearPose, expected, tol_mm, "is near the expected pose") {
  const Eigen::Isometry3d& a = arg;
  const Eigen::Isometry3d& e = expected;
  const double dp = (a.translation() - e.translation()).norm();
  const double dr = Eigen::AngleAxisd(e.linear().transpose() * a.linear()).angle();
  if (dp <= tol_mm && dr <= tol_mm * 1e-3) {
    return true;
  }
  *result_listener << "translation differs by " << dp << " mm, rotation by " << dr << " rad";
  return false;
}

}  // namespace cell::testing
