#include "cell/kinematics/excalibur.hpp"

#include <algorithm>
#include <cmath>

#include <fmt/format.h>

#include "cell/geometry/angles.hpp"
#include "cell/geometry/pose.hpp"
#include "model_issues.hpp"
#include "describe.hpp"

namespace cell::kinematics {
namespace {

using geometry::kPi;
using geometry::wrap_to_pi;

constexpr double kAxisToleranceMm = 1e-10;      // wrist centre on the base axis: theta1 is free
constexpr double kShoulderToleranceMm = 1e-10;  // wrist centre at the shoulder: theta2 is free
constexpr double kWristTolerance = 1e-12;       // |sin theta5| below this: theta4 is free
constexpr double kReachTolerance = 1e-12;       // 1 -+ S3 down to -this is clamped to 0

using detail::describe_target;

// Solves all 8 branches into `out`. Allocation-free unless it fails.
Status solve(const ExcaliburModel& model,
             const Eigen::Isometry3d& base_T_tool,
             const ExcaliburJoints* reference,
             IkSolutions& out) {
  CELL_TRY(geometry::check_rigid(base_T_tool, "base_T_tool"));
  CELL_TRY(check_guards(model, base_T_tool));
  const Eigen::Isometry3d t6 = base_T_tool * model.flange_T_tool.inverse(Eigen::Isometry);
  const Eigen::Matrix3d& r = t6.linear();
  const double nx = r(0, 0), ny = r(1, 0), nz = r(2, 0);
  const double ox = r(0, 1), oy = r(1, 1), oz = r(2, 1);
  const double ax = r(0, 2), ay = r(1, 2), az = r(2, 2);
  const double d1 = model.d1_mm, a2 = model.a2_mm, d4 = model.d4_mm, d6 = model.d6_mm;

  // Wrist centre: p - d6 a (digest 001 §3.2 step 1 works with px - ax d6, py - ay d6).
  const double wx = t6.translation().x() - ax * d6;
  const double wy = t6.translation().y() - ay * d6;
  const double wz = t6.translation().z() - az * d6;
  const double rho = std::sqrt(wx * wx + wy * wy);
  const double p2 = wz - d1;

  // Step 2: S3 = -(P1^2 + P2^2 - d4^2 - a2^2) / (2 a2 d4); P1^2 = rho^2 for either shoulder.
  // 1 - S3 and 1 + S3 are formed as products of distances, not by subtracting from S3: near the
  // stretched or folded arm (|S3| -> 1) that keeps C3 = sqrt((1 - S3)(1 + S3)) accurate.
  const double dist = std::sqrt(rho * rho + p2 * p2);
  const double two_a2_d4 = 2.0 * a2 * d4;
  const double fold = std::abs(a2 - d4);
  double one_minus_s3 = (dist - fold) * (dist + fold) / two_a2_d4;
  double one_plus_s3 = (a2 + d4 - dist) * (a2 + d4 + dist) / two_a2_d4;
  if (one_minus_s3 < -kReachTolerance || one_plus_s3 < -kReachTolerance) {
    return Error{Errc::kOutOfRange,
                 fmt::format("{} is out of reach: its wrist centre ({:.3f}, {:.3f}, {:.3f}) mm is "
                             "{:.3f} mm from the shoulder (0, 0, {:.3f}) mm; the arm reaches "
                             "[{:.3f}, {:.3f}] mm (|S3| = {:.6f} > 1)",
                             describe_target(base_T_tool), wx, wy, wz, dist, d1, fold, a2 + d4,
                             std::abs(1.0 - one_minus_s3))};
  }
  one_minus_s3 = std::max(one_minus_s3, 0.0);
  one_plus_s3 = std::max(one_plus_s3, 0.0);
  const bool near_folded = one_minus_s3 < one_plus_s3;  // S3 > 0
  const double s3 = near_folded ? 1.0 - one_minus_s3 : one_plus_s3 - 1.0;
  const double c3_abs = std::sqrt(one_minus_s3 * one_plus_s3);
  // a2 - S3 d4 (step 3), formed the same way.
  const double a2_minus_s3_d4 =
      near_folded ? (a2 - d4) + d4 * one_minus_s3 : (a2 + d4) - d4 * one_plus_s3;
  // The C3 >= 0 root; the other one is theta3' = pi - theta3 (C3 -> -C3), not theta3 +- pi as
  // EXCAL did (digest 001 §3.2).
  const double theta3_c3_positive = std::atan2(s3, c3_abs);

  // Step 1: theta1 = atan2(py - ay d6, px - ax d6); the shoulder flip adds pi (never tried by
  // EXCAL). On the base axis theta1 is free: keep the reference (the current joints) or 0.
  const bool shoulder_singular = rho < kAxisToleranceMm;
  double theta1_front = 0.0;
  double c1_front = 1.0;
  double s1_front = 0.0;
  if (shoulder_singular) {
    theta1_front = reference != nullptr ? wrap_to_pi((*reference)(0)) : 0.0;
    c1_front = std::cos(theta1_front);
    s1_front = std::sin(theta1_front);
  } else {
    theta1_front = std::atan2(wy, wx);
    c1_front = wx / rho;
    s1_front = wy / rho;
  }
  const bool arm_singular = dist < kShoulderToleranceMm;

  // Only the two front-shoulder arm solutions are solved; each back-shoulder solution follows
  // without trigonometry. Mirroring the arm plane (theta1 + pi) keeps the physical elbow
  // position when theta2' = pi - theta2 and theta3' = pi - theta3 (so theta23' = -theta23, the
  // forearm keeps its direction, C3 changes sign); then R03' = R03 Rz(pi), so the wrist becomes
  // (theta4 + pi, theta5, theta6). Checked by the round-trip tests on every branch.
  const double c1 = c1_front;
  const double s1 = s1_front;
  const double p1 = c1 * wx + s1 * wy;
  // Projections of n, o, a used by steps 4-6 (rows of A1^-1).
  const double au = c1 * ax + s1 * ay, av = s1 * ax - c1 * ay;
  const double nu = c1 * nx + s1 * ny, nv = s1 * nx - c1 * ny;
  const double ou = c1 * ox + s1 * oy, ov = s1 * ox - c1 * oy;

  out.resize(8);
  for (int elbow = 0; elbow < 2; ++elbow) {
    // Elbow up = elbow above the shoulder-wrist line: C3 <= 0 in front (the thesis's elbow-up,
    // digest 001 §3.2); the back shoulder mirrors it (C3 >= 0).
    const bool up = elbow == 0;
    const double c3 = up ? -c3_abs : c3_abs;
    const double theta3 = up ? kPi - theta3_c3_positive : theta3_c3_positive;
    // Step 3 (correct as printed): S2 = [P1 C3 d4 - P2 (a2 - S3 d4)] / D,
    // C2 = [-P2 C3 d4 - P1 (a2 - S3 d4)] / D with D = -(C3 d4)^2 - (a2 - S3 d4)^2 < 0;
    // atan2 of the numerators times -1 divides by D without dividing.
    const double k1 = c3 * d4;
    const double k2 = a2_minus_s3_d4;
    double theta2 = 0.0;
    double c2 = 1.0;
    double s2 = 0.0;
    if (arm_singular) {  // wrist centre on the shoulder (a2 == d4, arm folded): theta2 is free
      theta2 = reference != nullptr ? (*reference)(1) : 0.0;
      c2 = std::cos(theta2);
      s2 = std::sin(theta2);
    } else {
      const double y2 = -(p1 * k1 - p2 * k2);
      const double x2 = p2 * k1 + p1 * k2;
      theta2 = std::atan2(y2, x2);
      const double n2 = std::sqrt(x2 * x2 + y2 * y2);
      c2 = x2 / n2;
      s2 = y2 / n2;
    }
    const double c23 = c2 * c3 - s2 * s3;
    const double s23 = s2 * c3 + c2 * s3;

    // Step 4, corrected: S4 S5 = S1 ax - C1 ay, C4 S5 = -[C23 (C1 ax + S1 ay) + S23 az]. The
    // seed (Appendix A) prints S4 = (-S1 ax + C1 ay) / S5 and C4 = (C23 (..) + S23 az) / S5, both
    // the negatives of these: that selects the flipped wrist. We follow the digest's form.
    const double s4s5 = av;
    const double c4s5 = -(c23 * au + s23 * az);
    const double abs_s5 = std::sqrt(s4s5 * s4s5 + c4s5 * c4s5);
    // The seed detects theta5 = 0 with py/px = ay/ax, which really tests S4 S5 = 0 and divides
    // by zero for px = 0; we test |S5| as the digest advises.
    const bool wrist_singular = abs_s5 < kWristTolerance;
    double theta4 = 0.0;
    double c4 = 1.0;
    double s4 = 0.0;
    if (wrist_singular) {
      // Digest 001 §3.2: the thesis sets theta4 = 0 and gives all the roll to theta6.
      theta4 = (model.wrist_singularity == WristSingularity::kKeepTheta4 && reference != nullptr)
                   ? (*reference)(3)
                   : 0.0;
      c4 = std::cos(theta4);
      s4 = std::sin(theta4);
    } else {
      theta4 = std::atan2(s4s5, c4s5);
      c4 = c4s5 / abs_s5;
      s4 = s4s5 / abs_s5;
    }
    // Step 5: S5 = -[C23 C4 (C1 ax + S1 ay) - S4 (S1 ax - C1 ay) + S23 C4 az],
    // C5 = -S23 (C1 ax + S1 ay) + C23 az.
    const double theta5 =
        std::atan2(-(c23 * c4 * au - s4 * av + s23 * c4 * az), -s23 * au + c23 * az);
    // Step 6, corrected f43: S6 = -[C23 S4 (C1 nx + S1 ny) + C4 (S1 nx - C1 ny) + S23 S4 nz],
    // C6 = the same with o. The seed's f43 has wrong signs on the C4 and S23 S4 terms; we
    // follow the digest (every branch round-trips to 1e-12 mm). Valid for any theta5, so also
    // at the wrist singularity.
    const double theta6 = std::atan2(-(c23 * s4 * nu + c4 * nv + s23 * s4 * nz),
                                     -(c23 * s4 * ou + c4 * ov + s23 * s4 * oz));
    const bool singular = shoulder_singular || arm_singular || wrist_singular;

    for (int shoulder = 0; shoulder < 2; ++shoulder) {
      const bool front = shoulder == 0;
      // At the wrist singularity only theta4 + theta6 (theta5 = 0) or theta4 - theta6
      // (theta5 = pi) matters: the back shoulder keeps the policy's theta4 and turns theta6 by
      // pi instead, which is the same modulo 2 pi in both cases.
      const double wrist4 = front || wrist_singular ? theta4 : theta4 + kPi;
      const double wrist6 = front || !wrist_singular ? theta6 : theta6 + kPi;
      // Arm joints, unwrapped into their limits (toward the reference when there is one), shared
      // by both wrists of this arm configuration.
      const double arm_raw[3] = {front ? theta1_front : theta1_front + kPi,
                                 front ? theta2 : kPi - theta2, front ? theta3 : kPi - theta3};
      double arm[3];
      int arm_violation = -1;
      for (int i = 0; i < 3; ++i) {
        const JointSpec& joint = model.joints[static_cast<std::size_t>(i)];
        const double ref = reference != nullptr ? (*reference)(i) : wrap_to_pi(arm_raw[i]);
        arm[i] = fit_revolute(joint, arm_raw[i], ref);
        if (arm_violation < 0 && !joint.within_limits(arm[i])) {
          arm_violation = i;
        }
      }
      for (int wrist = 0; wrist < 2; ++wrist) {
        // The flipped wrist: (theta4 + pi, -theta5, theta6 + pi).
        const double wrist_raw[3] = {wrist == 0 ? wrist4 : wrist4 + kPi,
                                     wrist == 0 ? theta5 : -theta5,
                                     wrist == 0 ? wrist6 : wrist6 + kPi};
        const int index = 4 * shoulder + 2 * elbow + wrist;
        IkSolution& s = out[static_cast<std::size_t>(index)];
        s.q.resize(6);
        s.q(0) = arm[0];
        s.q(1) = arm[1];
        s.q(2) = arm[2];
        int violation = arm_violation;
        for (int i = 3; i < 6; ++i) {
          const JointSpec& joint = model.joints[static_cast<std::size_t>(i)];
          const double raw = wrist_raw[i - 3];
          const double ref = reference != nullptr ? (*reference)(i) : wrap_to_pi(raw);
          s.q(i) = fit_revolute(joint, raw, ref);
          if (violation < 0 && !joint.within_limits(s.q(i))) {
            violation = i;
          }
        }
        s.branch = kExcaliburBranchNames[static_cast<std::size_t>(index)];
        s.branch_index = static_cast<std::uint8_t>(index);
        s.violated_joint = static_cast<std::int8_t>(violation);
        s.singular = singular;
      }
    }
  }
  return ok_status();
}

Status check_reference(const ExcaliburJoints& reference) {
  if (!reference.allFinite()) {
    return Error{Errc::kInvalidArgument, "reference joints are not finite"};
  }
  return ok_status();
}

}  // namespace

Status ExcaliburModel::validate() const {
  return detail::to_status(detail::excalibur_issues(*this));
}

Eigen::Isometry3d forward(const ExcaliburModel& model, const ExcaliburJoints& q) noexcept {
  // Digest 001 §3.1, every element checked against the DH product, grouped as
  // v = Rot(z, theta1) * (u, w, z): u radial, w tangential in the arm plane.
  const double c1 = std::cos(q(0)), s1 = std::sin(q(0));
  const double c2 = std::cos(q(1)), s2 = std::sin(q(1));
  const double c23 = std::cos(q(1) + q(2)), s23 = std::sin(q(1) + q(2));
  const double c4 = std::cos(q(3)), s4 = std::sin(q(3));
  const double c5 = std::cos(q(4)), s5 = std::sin(q(4));
  const double c6 = std::cos(q(5)), s6 = std::sin(q(5));

  const double k = c23 * c4 * c5 - s23 * s5;
  const double kz = s23 * c4 * c5 + c23 * s5;
  const double n_u = k * c6 - c23 * s4 * s6;
  const double n_w = s4 * c5 * c6 + c4 * s6;
  const double n_z = kz * c6 - s23 * s4 * s6;
  const double o_u = -k * s6 - c23 * s4 * c6;
  const double o_w = -s4 * c5 * s6 + c4 * c6;
  const double o_z = -kz * s6 - s23 * s4 * c6;
  const double a_u = -c23 * c4 * s5 - s23 * c5;
  const double a_w = -s4 * s5;
  const double a_z = -s23 * c4 * s5 + c23 * c5;
  const double p_u = -s23 * model.d4_mm + model.a2_mm * c2 + a_u * model.d6_mm;
  const double p_w = a_w * model.d6_mm;
  const double p_z = c23 * model.d4_mm + model.a2_mm * s2 + model.d1_mm + a_z * model.d6_mm;

  Eigen::Isometry3d t6 = Eigen::Isometry3d::Identity();
  t6.linear() << c1 * n_u - s1 * n_w, c1 * o_u - s1 * o_w, c1 * a_u - s1 * a_w,  //
      s1 * n_u + c1 * n_w, s1 * o_u + c1 * o_w, s1 * a_u + c1 * a_w,             //
      n_z, o_z, a_z;
  t6.translation() << c1 * p_u - s1 * p_w, s1 * p_u + c1 * p_w, p_z;
  return t6 * model.flange_T_tool;
}

Eigen::Vector3d wrist_centre(const ExcaliburModel& model,
                             const Eigen::Isometry3d& base_T_tool) noexcept {
  const Eigen::Isometry3d t6 = base_T_tool * model.flange_T_tool.inverse(Eigen::Isometry);
  return t6.translation() - model.d6_mm * t6.linear().col(2);
}

Status check_guards(const ExcaliburModel& model, const Eigen::Isometry3d& base_T_tool) {
  return model.cartesian_limits.check(base_T_tool.translation());
}

Result<IkSolutions> inverse_all(const ExcaliburModel& model, const Eigen::Isometry3d& base_T_tool) {
  Result<IkSolutions> out{IkSolutions{}};
  CELL_TRY(solve(model, base_T_tool, nullptr, *out));
  return out;
}

Result<IkSolutions> inverse_all(const ExcaliburModel& model,
                                const Eigen::Isometry3d& base_T_tool,
                                const ExcaliburJoints& reference) {
  CELL_TRY(check_reference(reference));
  Result<IkSolutions> out{IkSolutions{}};
  CELL_TRY(solve(model, base_T_tool, &reference, *out));
  return out;
}

Result<ExcaliburJoints> inverse(const ExcaliburModel& model,
                                const Eigen::Isometry3d& base_T_tool,
                                const ExcaliburJoints& seed) {
  CELL_TRY(check_reference(seed));
  IkSolutions all;
  CELL_TRY(solve(model, base_T_tool, &seed, all));
  const JointVector seed_v = seed;
  const IkSolution* best = all.nearest(model.joints, seed_v);
  if (best == nullptr) {
    return no_branch_within_limits(model.joints, all, describe_target(base_T_tool));
  }
  return ExcaliburJoints(best->q);
}

Result<ExcaliburJoints> inverse(const ExcaliburModel& model,
                                const Eigen::Isometry3d& base_T_tool,
                                std::string_view branch,
                                const ExcaliburJoints& seed) {
  CELL_TRY(check_reference(seed));
  IkSolutions all;
  CELL_TRY(solve(model, base_T_tool, &seed, all));
  auto q = pick_branch(model.joints, all, kExcaliburBranchNames, branch);
  if (!q) {
    return std::move(q).error();
  }
  return ExcaliburJoints(*q);
}

ExcaliburJoints to_controller(const ExcaliburModel& model, const ExcaliburJoints& q) noexcept {
  ExcaliburJoints out;
  for (int i = 0; i < 6; ++i) {
    out(i) = q(i) - model.controller_offset[static_cast<std::size_t>(i)];
  }
  return out;
}

ExcaliburJoints from_controller(const ExcaliburModel& model,
                                const ExcaliburJoints& q_controller) noexcept {
  ExcaliburJoints out;
  for (int i = 0; i < 6; ++i) {
    out(i) = q_controller(i) + model.controller_offset[static_cast<std::size_t>(i)];
  }
  return out;
}

}  // namespace cell::kinematics
