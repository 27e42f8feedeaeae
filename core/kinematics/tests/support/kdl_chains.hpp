#pragma once

// Orocos KDL chains built from the same parameters as our models: the peer for the FK
// cross-check (tests/kdl_test.cpp) and for the speed comparison (bench/kinematics). Test and
// bench support only; production code never links KDL.

#include <cmath>

#include <Eigen/Geometry>
#include <kdl/chain.hpp>
#include <kdl/frames.hpp>
#include <kdl/jntarray.hpp>

#include "cell/kinematics/excalibur.hpp"
#include "cell/kinematics/scara.hpp"

namespace cell::kinematics::peer {

/// KDL frame of an Eigen pose; lengths multiplied by `scale` (1 for mm, 1e-3 for metres).
inline KDL::Frame to_kdl(const Eigen::Isometry3d& pose, double scale = 1.0) {
  const Eigen::Matrix3d& r = pose.linear();
  const Eigen::Vector3d p = pose.translation() * scale;
  return KDL::Frame(KDL::Rotation(r(0, 0), r(0, 1), r(0, 2), r(1, 0), r(1, 1), r(1, 2), r(2, 0),
                                  r(2, 1), r(2, 2)),
                    KDL::Vector(p.x(), p.y(), p.z()));
}

/// Eigen pose of a KDL frame; lengths divided by `scale`.
inline Eigen::Isometry3d from_kdl(const KDL::Frame& f, double scale = 1.0) {
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) {
      pose.linear()(i, j) = f.M(i, j);
    }
    pose.translation()(i) = f.p(i) / scale;
  }
  return pose;
}

/// The Excalibur as a KDL chain of six revolute joints with standard DH frames (Frame::DH is
/// Rot(z, theta) Trans(z, d) Trans(x, a) Rot(x, alpha)), then the tool E.
inline KDL::Chain excalibur_chain(const ExcaliburModel& m, double scale = 1.0) {
  const double half_pi = M_PI / 2.0;
  KDL::Chain chain;
  chain.addSegment(KDL::Segment(KDL::Joint(KDL::Joint::RotZ),
                                KDL::Frame::DH(0.0, half_pi, m.d1_mm * scale, 0.0)));
  chain.addSegment(
      KDL::Segment(KDL::Joint(KDL::Joint::RotZ), KDL::Frame::DH(m.a2_mm * scale, 0.0, 0.0, 0.0)));
  chain.addSegment(
      KDL::Segment(KDL::Joint(KDL::Joint::RotZ), KDL::Frame::DH(0.0, -half_pi, 0.0, 0.0)));
  chain.addSegment(KDL::Segment(KDL::Joint(KDL::Joint::RotZ),
                                KDL::Frame::DH(0.0, half_pi, m.d4_mm * scale, 0.0)));
  chain.addSegment(
      KDL::Segment(KDL::Joint(KDL::Joint::RotZ), KDL::Frame::DH(0.0, -half_pi, 0.0, 0.0)));
  chain.addSegment(KDL::Segment(
      KDL::Joint(KDL::Joint::RotZ),
      KDL::Frame::DH(0.0, 0.0, m.d6_mm * scale, 0.0) * to_kdl(m.flange_T_tool, scale)));
  return chain;
}

/// A SCARA as a KDL chain: fixed offset to z_at_zero, J1 and J2 about z with links along x, a
/// prismatic z (scale -1 when Z grows downward), and a roll about z measured from link 2, then
/// the tool. KDL has no world-referenced roll; scara_kdl_joints converts R.
inline KDL::Chain scara_chain(const ScaraModel& m, double scale = 1.0) {
  KDL::Chain chain;
  chain.addSegment(KDL::Segment(KDL::Joint(KDL::Joint::Fixed),
                                KDL::Frame(KDL::Vector(0.0, 0.0, m.z_at_zero_mm * scale))));
  chain.addSegment(KDL::Segment(KDL::Joint(KDL::Joint::RotZ),
                                KDL::Frame(KDL::Vector(m.link1_mm * scale, 0.0, 0.0))));
  chain.addSegment(KDL::Segment(KDL::Joint(KDL::Joint::RotZ),
                                KDL::Frame(KDL::Vector(m.link2_mm * scale, 0.0, 0.0))));
  const double z_scale = m.z_direction == ZDirection::kDown ? -scale : scale;
  chain.addSegment(KDL::Segment(KDL::Joint(KDL::Joint::TransZ, z_scale), KDL::Frame::Identity()));
  chain.addSegment(KDL::Segment(KDL::Joint(KDL::Joint::RotZ), to_kdl(m.flange_T_tool, scale)));
  return chain;
}

/// KDL joint values for SCARA joints q: J1, J2, Z unchanged; the roll written independently of
/// our tool_yaw_from_roll: link-referenced roll = s R, world-referenced = s R - J1 - J2, with
/// s = -1 for a clockwise-positive R.
inline KDL::JntArray scara_kdl_joints(const ScaraModel& m, const ScaraJoints& q) {
  KDL::JntArray out(4);
  const double s = m.roll_sense == RotationSense::kClockwise ? -1.0 : 1.0;
  out(0) = q(0);
  out(1) = q(1);
  out(2) = q(2);
  out(3) = m.roll_reference == RollReference::kWorld ? s * q(3) - q(0) - q(1) : s * q(3);
  return out;
}

/// KDL joint values of Excalibur joints (identical: both are DH angles).
inline KDL::JntArray excalibur_kdl_joints(const ExcaliburJoints& q) {
  KDL::JntArray out(6);
  for (unsigned i = 0; i < 6; ++i) {
    out(i) = q(static_cast<Eigen::Index>(i));
  }
  return out;
}

}  // namespace cell::kinematics::peer
