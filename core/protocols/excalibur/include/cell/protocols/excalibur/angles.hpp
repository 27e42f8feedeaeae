#pragma once

#include "cell/common/result.hpp"
#include "cell/kinematics/excalibur.hpp"
#include "cell/kinematics/joints.hpp"
#include "cell/protocols/excalibur/dialect.hpp"

/// The controller's angle convention on the wire (digest 001 §2.3): the controller's angles q*
/// are in degrees and differ from the DH angles q of core/kinematics by fixed offsets,
///
///   theta2 = theta2* + 30 deg,   theta3 = theta3* - 150 deg   (theta1, theta4..6 identical),
///
/// taken from the robot model (config/robots/excalibur.yaml `controller_offsets_deg`) through
/// kinematics::to_controller / from_controller. EXCAL converted on every command and every
/// query; the driver and the simulator do the same through these two functions only.
/// Pure, allocation-free, thread-safe.
namespace cell::protocols::excalibur {

/// Controller angles q* [deg] of DH joint angles q [rad] (6 entries: precondition, checked by
/// the caller's model). Not wrapped.
ControllerAngles to_wire(const kinematics::ExcaliburModel& model,
                         const kinematics::JointVector& q) noexcept;

/// DH joint angles q [rad] (size 6) of controller angles q* [deg].
kinematics::JointVector from_wire(const kinematics::ExcaliburModel& model,
                                  const ControllerAngles& q_controller_deg) noexcept;

/// Largest |a - b| over the joints [deg], and the joint index where it occurs.
double max_difference_deg(const ControllerAngles& a,
                          const ControllerAngles& b,
                          std::size_t* joint = nullptr) noexcept;

}  // namespace cell::protocols::excalibur
