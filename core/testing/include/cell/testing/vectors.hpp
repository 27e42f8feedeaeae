#pragma once

#include <initializer_list>

#include <Eigen/Core>

namespace cell::testing {

/// An Eigen vector (dynamic or fixed-capacity, e.g. a JointVector) from a list of values:
/// `vec<JointVector>({0.1, 0.2, 50, 0})`.
template <typename V = Eigen::VectorXd>
V vec(std::initializer_list<double> values) {
  V out(static_cast<Eigen::Index>(values.size()));
  Eigen::Index i = 0;
  for (const double x : values) {
    out[i++] = x;
  }
  return out;
}

}  // namespace cell::testing
