#pragma once

#include <cmath>
#include <numbers>

#include <fmt/format.h>

#include "cell/trajectory/joint_trajectory.hpp"
#include "cell/trajectory/planners.hpp"
#include "cell/testing/vectors.hpp"

namespace cell::trajectory::testing {

inline double deg(double d) { return d * std::numbers::pi / 180.0; }

/// The IBM 7545's joint speed limits (digest 000 §5): 45 deg/s, 50 deg/s, 100 mm/s, 70 deg/s.
inline JointVector ibm7545_speeds() {
  JointVector v(4);
  v << deg(45), deg(50), 100.0, deg(70);
  return v;
}

/// A 3-axis Cartesian gantry (q = x, y, z in mm; tool axes parallel to the base): its
/// kinematics are exact and trivial, so trajectory behaviour is tested apart from arm
/// kinematics. Workspace: each axis within [-box, box] mm.
struct Gantry {
  JointLimits limits;
  double box_mm;
  explicit Gantry(double v_max = 2500, double a_max = 20000, double box = 1000) : box_mm(box) {
    limits.names = {"X", "Y", "Z"};
    limits.prismatic = {true, true, true};
    limits.lower = JointVector::Constant(3, -box);
    limits.upper = JointVector::Constant(3, box);
    limits.max_velocity = JointVector::Constant(3, v_max);
    limits.max_acceleration = JointVector::Constant(3, a_max);
  }
  ForwardFn forward() const {
    return [](const JointVector& q) {
      Eigen::Isometry3d t = Eigen::Isometry3d::Identity();
      t.translation() = q.head<3>();
      return t;
    };
  }
  InverseFn inverse() const {
    return [box = box_mm](const Eigen::Isometry3d& pose, const JointVector&) -> Result<JointVector> {
      const Eigen::Vector3d p = pose.translation();
      if (p.cwiseAbs().maxCoeff() > box) {
        return Error{Errc::kOutOfRange,
                     fmt::format("({:.1f}, {:.1f}, {:.1f}) mm is outside the gantry's box", p.x(),
                                 p.y(), p.z())};
      }
      JointVector q(3);
      q << p.x(), p.y(), p.z();
      return q;
    };
  }
};

inline JointVector jv(std::initializer_list<double> values) {
  return cell::testing::vec<JointVector>(values);
}

}  // namespace cell::trajectory::testing
