// The browser's forward kinematics against the digests' test cases (node --test).
import { test } from 'node:test';
import assert from 'node:assert/strict';
import { forward, column, position, scaraFrames } from '../src/kinematics.js';

const deg = (d) => d * Math.PI / 180;
const identityPose = { p: [0, 0, 0], q: [1, 0, 0, 0] };

const ibm7545 = {
  id: 'ibm7545', kind: 'scara', flange_T_tool: identityPose,
  scara: { link1_mm: 400, link2_mm: 250, z_down: true, z_at_zero_mm: 0, roll_world: true,
           roll_clockwise: true },
};
// Placeholder lengths of digest 001 §8.2 (cm there, mm here).
const excalibur = {
  id: 'excalibur', kind: 'excalibur', flange_T_tool: identityPose,
  excalibur: { d1_mm: 254, a2_mm: 304.8, d4_mm: 304.8, d6_mm: 152.4 },
};

function near(a, b, tol, what) {
  assert.ok(Math.abs(a - b) <= tol, `${what}: ${a} vs ${b}`);
}

test('7545 home stretches along +x to 650 mm (digest 000 §9.2 case 3)', () => {
  const p = position(forward(ibm7545, [0, 0, 0, 0]));
  near(p[0], 650, 1e-9, 'x');
  near(p[1], 0, 1e-9, 'y');
});

test('7545 image-grab pose and the down-growing Z and world-referenced clockwise R', () => {
  const t = forward(ibm7545, [deg(45), deg(105), 120, deg(30)]);
  near(t[3], 66.336362, 1e-6, 'x');
  near(t[7], 407.842712, 1e-6, 'y');
  near(t[11], -120, 1e-9, 'z');
  const n = column(t, 0);
  near(Math.atan2(n[1], n[0]), deg(-30), 1e-12, 'yaw');
  const f = scaraFrames(ibm7545, [deg(45), deg(105), 120, deg(30)]);
  near(f.link2[3], t[3], 1e-9, 'link2 end x');  // the camera mount: on the R axis at Z = 0
  near(f.link2[11], 0, 1e-9, 'link2 end z');
});

test('Excalibur q = 0: p = (a2, 0, d1 + d4 + d6), identity rotation (case 1)', () => {
  const t = forward(excalibur, [0, 0, 0, 0, 0, 0]);
  near(t[3], 304.8, 1e-9, 'px');
  near(t[11], 254 + 304.8 + 152.4, 1e-9, 'pz');
  near(t[0], 1, 1e-12, 'nx');
  near(t[10], 1, 1e-12, 'az');
});

test('Excalibur case 3: q = (30, 45, -120, 20, -40, 60) deg', () => {
  const t = forward(excalibur, [30, 45, -120, 20, -40, 60].map(deg));
  const n = column(t, 0), o = column(t, 1), a = column(t, 2), p = position(t);
  [-0.7270, 0.6712, -0.1447].forEach((v, i) => near(n[i], v, 5e-5, `n${i}`));
  [0.1661, 0.3764, 0.9114].forEach((v, i) => near(o[i], v, 5e-5, `o${i}`));
  [0.6663, 0.6385, -0.3852].forEach((v, i) => near(a[i], v, 5e-5, `a${i}`));
  [543.16, 352.28, 489.71].forEach((v, i) => near(p[i], v, 0.01, `p${i}`));
});

test('Excalibur case 2: controller zero, elbow up', () => {
  const t = forward(excalibur, [0, 30, -150, 0, 0, 0].map(deg));
  const p = position(t);
  near(p[0], 659.91, 0.01, 'px');
  near(p[2], 177.80, 0.01, 'pz');
});
