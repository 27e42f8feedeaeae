#pragma once

// Joint vectors written out in the motion tests.

#include <initializer_list>

#include "cell/testing/vectors.hpp"
#include "cell/trajectory/joint_trajectory.hpp"

namespace cell::motion::test {

/// A JointVector from its values (radians for revolute joints, millimetres for prismatic).
inline trajectory::JointVector jv(std::initializer_list<double> values) {
  return cell::testing::vec<trajectory::JointVector>(values);
}

}  // namespace cell::motion::test
