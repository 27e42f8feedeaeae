// Forward kinematics of the cell's robots in the browser, from the models the bridge serves
// (/api/config: the same config/robots/*.yaml that core/kinematics loads). Units: mm and rad.
// Matrices are 4x4 row-major arrays of 16 numbers (m[4*r + c]), frames named a_T_b.
//
// SCARA: the same equations as core/kinematics/scara.hpp (eq. 4.11/4.12 of the 7545 thesis).
// Excalibur: the plain product A1...A6 of the DH table in core/kinematics/excalibur.hpp (digest
// 001 §3), an independent computation from the C++ closed form; the browser test compares
// both on the live robot (RobotState.base_T_tool).

export function identity() {
  return [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1];
}

export function multiply(a, b) {
  const out = new Array(16).fill(0);
  for (let r = 0; r < 4; ++r) {
    for (let c = 0; c < 4; ++c) {
      let s = 0;
      for (let k = 0; k < 4; ++k) s += a[4 * r + k] * b[4 * k + c];
      out[4 * r + c] = s;
    }
  }
  return out;
}

export function translation(x, y, z) {
  return [1, 0, 0, x, 0, 1, 0, y, 0, 0, 1, z, 0, 0, 0, 1];
}

export function rotZ(t) {
  const c = Math.cos(t), s = Math.sin(t);
  return [c, -s, 0, 0, s, c, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1];
}

export function rotX(t) {
  const c = Math.cos(t), s = Math.sin(t);
  return [1, 0, 0, 0, 0, c, -s, 0, 0, s, c, 0, 0, 0, 0, 1];
}

/// {p: [x, y, z], q: [w, x, y, z]} (the bridge's pose JSON) -> matrix.
export function fromPose(pose) {
  const [x, y, z] = pose.p;
  let [w, i, j, k] = pose.q;
  const n = Math.hypot(w, i, j, k) || 1;
  w /= n; i /= n; j /= n; k /= n;
  return [
    1 - 2 * (j * j + k * k), 2 * (i * j - k * w), 2 * (i * k + j * w), x,
    2 * (i * j + k * w), 1 - 2 * (i * i + k * k), 2 * (j * k - i * w), y,
    2 * (i * k - j * w), 2 * (j * k + i * w), 1 - 2 * (i * i + j * j), z,
    0, 0, 0, 1,
  ];
}

export function position(m) {
  return [m[3], m[7], m[11]];
}

export function column(m, c) {
  return [m[c], m[4 + c], m[8 + c]];
}

/// Translation difference [mm] and rotation angle difference [rad] of two poses. The angle
/// comes from the Frobenius norm of Ra - Rb = 2 sqrt(2) sin(theta / 2), which, unlike acos of
/// the trace, stays accurate for tiny angles.
export function poseDistance(a, b) {
  const dp = Math.hypot(a[3] - b[3], a[7] - b[7], a[11] - b[11]);
  let f = 0;
  for (let r = 0; r < 3; ++r) {
    for (let c = 0; c < 3; ++c) f += (a[4 * r + c] - b[4 * r + c]) ** 2;
  }
  const s = Math.min(1, Math.sqrt(f) / (2 * Math.SQRT2));
  return { mm: dp, rad: 2 * Math.asin(s) };
}

function scaraYaw(sc, q) {
  const link = sc.roll_world ? 0 : q[0] + q[1];
  return link + (sc.roll_clockwise ? -1 : 1) * q[3];
}

/// Frames of a SCARA for drawing: base, the elbow (J2 axis), link 2's end (R axis at the
/// flange height with Z = 0, x along link 2: the 7545 camera's mount) and base_T_tool.
export function scaraFrames(model, q) {
  const sc = model.scara;
  const shoulder = rotZ(q[0]);
  const elbow = multiply(multiply(shoulder, translation(sc.link1_mm, 0, 0)), rotZ(q[1]));
  const link2End = multiply(elbow, translation(sc.link2_mm, 0, 0));
  const z = sc.z_down ? sc.z_at_zero_mm - q[2] : sc.z_at_zero_mm + q[2];
  const yaw = scaraYaw(sc, q);
  const j12 = q[0] + q[1];
  const flange = multiply(
    translation(sc.link1_mm * Math.cos(q[0]) + sc.link2_mm * Math.cos(j12),
                sc.link1_mm * Math.sin(q[0]) + sc.link2_mm * Math.sin(j12), z),
    rotZ(yaw));
  const link2 = multiply(translation(link2End[3], link2End[7], sc.z_at_zero_mm), rotZ(j12));
  const tool = multiply(flange, fromPose(model.flange_T_tool));
  return { shoulder, elbow, link2, flange, tool };
}

// DH table of the Excalibur (digest 001 §3): alpha [deg], a, d.
function excaliburDh(ex) {
  return [
    [90, 0, ex.d1_mm],
    [0, ex.a2_mm, 0],
    [-90, 0, 0],
    [90, 0, ex.d4_mm],
    [-90, 0, 0],
    [0, 0, ex.d6_mm],
  ];
}

/// A_n = Rot(z, theta) Trans(0, 0, d) Trans(a, 0, 0) Rot(x, alpha).
function dhLink(theta, alphaDeg, a, d) {
  return multiply(multiply(multiply(rotZ(theta), translation(0, 0, d)), translation(a, 0, 0)),
                  rotX(alphaDeg * Math.PI / 180));
}

/// Frames 0..6 of the Excalibur (frames[0] = base, frames[6] = T6) and base_T_tool.
export function excaliburFrames(model, q) {
  const dh = excaliburDh(model.excalibur);
  const frames = [identity()];
  let t = identity();
  for (let i = 0; i < 6; ++i) {
    t = multiply(t, dhLink(q[i], dh[i][0], dh[i][1], dh[i][2]));
    frames.push(t);
  }
  const tool = multiply(t, fromPose(model.flange_T_tool));
  return { frames, tool };
}

/// base_T_tool for joints q (rad / mm) of `model` (a robot of /api/config).
export function forward(model, q) {
  if (model.kind === 'scara') return scaraFrames(model, q).tool;
  if (model.kind === 'excalibur') return excaliburFrames(model, q).tool;
  throw new Error(`robot '${model.id}': unknown kind '${model.kind}'`);
}

/// A joint value in its display unit: revolute rad -> deg, prismatic mm -> mm.
export function toDisplay(joint, value) {
  return joint.type === 'revolute' ? value * 180 / Math.PI : value;
}

export function fromDisplay(joint, value) {
  return joint.type === 'revolute' ? value * Math.PI / 180 : value;
}

/// Inverse of a rigid transform (rotation transposed, translation -R^T p).
export function invert(m) {
  const out = identity();
  for (let r = 0; r < 3; ++r) {
    for (let c = 0; c < 3; ++c) out[4 * r + c] = m[4 * c + r];
  }
  for (let r = 0; r < 3; ++r) {
    out[4 * r + 3] = -(out[4 * r] * m[3] + out[4 * r + 1] * m[7] + out[4 * r + 2] * m[11]);
  }
  return out;
}

/// Roll, pitch, yaw [rad] of a rotation with R = Rz(yaw) Ry(pitch) Rx(roll), the convention of
/// core/geometry and cellctl.
export function rpy(m) {
  const pitch = Math.asin(Math.max(-1, Math.min(1, -m[8])));
  if (Math.abs(m[8]) < 1 - 1e-12) {
    return [Math.atan2(m[9], m[10]), pitch, Math.atan2(m[4], m[0])];
  }
  return [0, pitch, Math.atan2(-m[1], m[5])];
}
