#pragma once

// Small helpers the vision sources share (internal).

#include <string>
#include <utility>

#include <Eigen/Core>

#include "cell/common/result.hpp"

namespace cell::vision::detail {

/// A kInvalidArgument error saying `what`.
inline Error invalid(std::string what) { return Error{Errc::kInvalidArgument, std::move(what)}; }

/// `v` turned by +90 degrees in its own plane: (-y, x).
inline Eigen::Vector2d perp(const Eigen::Vector2d& v) { return Eigen::Vector2d(-v.y(), v.x()); }

}  // namespace cell::vision::detail
