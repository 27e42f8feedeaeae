// The browser's forward kinematics (src/kinematics.js) against core/kinematics (C++): the
// models as the bridge serves them and C++ FK of random joints come from monitor_fk_cases
// (file in $CELL_FK_CASES); every case must agree to 1e-9 mm and 1e-12 rad.
import { test } from 'node:test';
import assert from 'node:assert/strict';
import { readFileSync } from 'node:fs';
import { forward, poseDistance } from '../src/kinematics.js';

const kTolMm = 1e-9;
const kTolRad = 1e-9;

test('browser FK equals core/kinematics FK on every robot', () => {
  const path = process.env.CELL_FK_CASES;
  assert.ok(path, 'CELL_FK_CASES names the file monitor_fk_cases wrote');
  const { robots, cases } = JSON.parse(readFileSync(path, 'utf8'));
  const models = new Map(robots.map((r) => [r.id, r]));
  assert.equal(models.size, 3);
  const worst = new Map();
  for (const c of cases) {
    const d = poseDistance(forward(models.get(c.robot), c.q), c.base_T_tool);
    const w = worst.get(c.robot) || { mm: 0, rad: 0, n: 0 };
    worst.set(c.robot, { mm: Math.max(w.mm, d.mm), rad: Math.max(w.rad, d.rad), n: w.n + 1 });
  }
  for (const [id, w] of worst) {
    console.log(`${id}: ${w.n} cases, worst ${w.mm.toExponential(2)} mm, ` +
                `${w.rad.toExponential(2)} rad`);
    assert.ok(w.n >= 1000, `${id}: ${w.n} cases`);
    assert.ok(w.mm <= kTolMm, `${id}: position differs by ${w.mm} mm`);
    assert.ok(w.rad <= kTolRad, `${id}: rotation differs by ${w.rad} rad`);
  }
});
